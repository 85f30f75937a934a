"""Display units: the conversions and texts of app.core.readout (1:n and in/ft included)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.orientation import quaternion_from_roll_pitch
from app.core.readout import (
    LEVEL_RATIO_TEXT,
    SLOPE_UNITS,
    UNDEFINED,
    averaged_angles,
    compare_to_truth,
    format_direction,
    format_slope,
    reading_text,
    slope_from_angle,
    tilt_is_zero,
)


def test_inches_per_foot_is_twelve_times_the_rise():
    # 1 in 12 (one inch per foot) is atan(1/12) = 4.7636°.
    assert slope_from_angle(math.degrees(math.atan(1 / 12)), "in/ft") == pytest.approx(1.0)
    assert slope_from_angle(-45.0, "in/ft") == pytest.approx(-12.0)


def test_ratio_is_the_run_per_unit_rise_signed_like_the_angle():
    assert slope_from_angle(45.0, "ratio") == pytest.approx(1.0)
    assert slope_from_angle(math.degrees(math.atan(1 / 50)), "ratio") == pytest.approx(50.0)
    assert slope_from_angle(-math.degrees(math.atan(1 / 200)), "ratio") == pytest.approx(-200.0)
    assert slope_from_angle(0.0, "ratio") == math.inf
    assert slope_from_angle(-0.0, "ratio") == math.inf  # level has no sign
    both = slope_from_angle(np.array([0.0, 45.0]), "ratio")
    np.testing.assert_allclose(both, [np.inf, 1.0])


def test_ratio_text_near_level_and_steep():
    assert format_slope(slope_from_angle(0.0, "ratio"), "ratio") == LEVEL_RATIO_TEXT == "1:∞"
    assert format_slope(slope_from_angle(0.001, "ratio"), "ratio") == "1:∞"  # 1:57296
    assert format_slope(slope_from_angle(0.01, "ratio"), "ratio") == "1:5730"
    assert format_slope(slope_from_angle(1.0, "ratio"), "ratio") == "1:57.3"
    assert format_slope(slope_from_angle(-10.0, "ratio"), "ratio", signed=True) == "-1:5.67"
    assert format_slope(slope_from_angle(10.0, "ratio"), "ratio", signed=True) == "+1:5.67"
    assert format_slope(slope_from_angle(60.0, "ratio"), "ratio") == "1:0.58"
    assert format_slope(math.nan, "ratio") == ""


def test_decimal_texts_have_two_decimals_and_no_negative_zero():
    assert format_slope(1.234, "deg", signed=True) == "+1.23"
    assert format_slope(-0.001, "mm/m", signed=True) == "+0.00"
    assert format_slope(-0.001, "percent") == "0.00"
    assert format_slope(-0.456, "in/ft") == "-0.46"
    assert format_slope(math.nan, "deg") == ""


def test_reading_text_for_the_clipboard():
    assert reading_text(1.234, -0.454, 1.31, "deg") == "Roll 1.23° Pitch -0.45° Tilt 1.31°"
    assert reading_text(2.0, 0.0, 2.0, "mm/m") == "Roll 2.00 mm/m Pitch 0.00 mm/m Tilt 2.00 mm/m"
    roll, pitch, tilt = (slope_from_angle(a, "ratio") for a in (1.0, 0.0, 1.0))
    assert reading_text(roll, pitch, tilt, "ratio") == "Roll 1:57.3 Pitch 1:∞ Tilt 1:57.3"


def test_every_unit_converts_and_has_a_title():
    for key, unit in SLOPE_UNITS.items():
        assert unit.key == key and unit.title
        assert math.isfinite(slope_from_angle(5.0, key))
    with pytest.raises(ValueError, match="unknown slope unit"):
        slope_from_angle(1.0, "furlongs")


def test_readouts_show_ratios_and_copy_what_they_show(qtbot):
    from app.gui.readouts import TiltReadouts

    readouts = TiltReadouts()
    qtbot.addWidget(readouts)
    readouts.setValid(True)
    roll, pitch, tilt = (slope_from_angle(a, "ratio") for a in (-1.0, 0.0, 1.0))
    readouts.setValues(roll, pitch, tilt, 270.0, "ratio")
    assert readouts.readoutText("roll") == "−1:57.3"
    assert readouts.readoutText("pitch") == "1:∞"
    assert readouts.readoutText("tilt") == "1:57.3"
    assert readouts.reading() == "Roll -1:57.3 Pitch 1:∞ Tilt 1:57.3"
    readouts.setValues(1.0, 12.0, 12.04, 85.0, "in/ft")
    assert readouts.readoutText("pitch") == "+12.00 in/ft"
    assert readouts.reading() == "Roll 1.00 in/ft Pitch 12.00 in/ft Tilt 12.04 in/ft"
    readouts.setValues(math.nan, 0.0, 0.0, 0.0, "ratio")
    assert readouts.reading() == ""
    readouts.setValid(False)
    assert readouts.reading() == ""


def test_a_slope_too_steep_for_its_unit_reads_over():
    assert format_slope(999.99, "mm/m") == "999.99"
    assert format_slope(slope_from_angle(60.0, "mm/m"), "mm/m", signed=True) == "+OVER"
    assert format_slope(slope_from_angle(-89.99, "in/ft"), "in/ft") == "-OVER"
    assert format_slope(slope_from_angle(85.0, "percent"), "percent") == "OVER"
    assert format_slope(math.inf, "mm/m") == "OVER"
    assert format_slope(180.0, "deg") == "180.00"  # degrees never overflow


def test_direction_is_undefined_while_the_tilt_reads_zero():
    """After a tare the tilt is noise around zero: its direction is a random bearing."""
    assert tilt_is_zero("0.00") and tilt_is_zero("+0.00") and tilt_is_zero(LEVEL_RATIO_TEXT)
    assert not tilt_is_zero("0.01") and not tilt_is_zero("1:9999") and not tilt_is_zero("")
    for unit in SLOPE_UNITS:
        level = format_slope(slope_from_angle(0.0001, unit), unit)
        assert format_direction(217.3, level) == UNDEFINED, unit
    assert format_direction(217.34, format_slope(0.01, "deg")) == "217.3"
    assert format_direction(359.97, "1.00") == "0.0"
    assert format_direction(math.nan, "1.00") == ""
    # The resolution is the unit's: 0.004° reads 0.00° but 0.07 mm/m.
    tilt = 0.004
    assert format_direction(90.0, format_slope(tilt, "deg")) == UNDEFINED
    assert format_direction(90.0, format_slope(slope_from_angle(tilt, "mm/m"), "mm/m")) == "90.0"


def test_the_truth_is_averaged_over_the_readouts_rows():
    """During a turn the truth's newest row and the averaged reading are far apart; averaged
    over the same rows, they agree as well as the estimate does."""
    roll = np.linspace(0.0, 54.0, 50)  # turning at 108°/s over a 0.5 s window
    pitch = np.zeros_like(roll)
    estimate = quaternion_from_roll_pitch(roll + 0.05, pitch)
    truth = compare_to_truth(estimate, roll, pitch, np.full(len(roll), 0.05))
    shown = averaged_angles(estimate)
    assert truth is not None and shown is not None
    assert abs(truth.roll_deg - 27.0) < 0.5  # the middle of the window, not its end (54)
    assert abs(shown.roll_deg - truth.roll_deg) == pytest.approx(0.05, abs=1e-6)
    assert truth.reading_error_deg == pytest.approx(0.05, abs=1e-6)
    assert truth.sample_rms_deg == pytest.approx(0.05)
    # Rows without a truth (not a simulator) are left out; none at all: no truth line.
    nan = np.full(len(roll), np.nan)
    assert compare_to_truth(estimate, nan, nan, nan) is None
    half = roll.copy()
    half[:25] = np.nan
    partial = compare_to_truth(estimate, half, pitch, np.full(len(roll), 0.05))
    assert partial is not None and partial.roll_deg > 35.0


def test_after_a_tare_the_reading_error_is_measured_in_the_tared_frame():
    """The readouts show the tared attitude (q * conj(T)); the truth is absolute. Turned into
    the same frame, a perfect estimate has no error (not the tare's 1.58°)."""
    from app.core import quaternion as quat

    roll, pitch = np.full(20, 1.5), np.full(20, 0.5)
    estimate = quaternion_from_roll_pitch(roll, pitch)
    tare = quaternion_from_roll_pitch(1.5, 0.5)  # tared where it lies
    shown = quat.normalize(quat.multiply(estimate, quat.conjugate(tare)))
    assert averaged_angles(shown).tilt_deg == pytest.approx(0.0, abs=1e-9)
    zero = np.zeros(20)
    untared = compare_to_truth(shown, roll, pitch, zero)
    tared = compare_to_truth(shown, roll, pitch, zero, tare_quat=tare)
    assert untared.reading_error_deg == pytest.approx(1.58, abs=0.01)  # the wrong comparison
    assert tared.reading_error_deg == pytest.approx(0.0, abs=1e-6)
    assert (tared.roll_deg, tared.pitch_deg) == pytest.approx((1.5, 0.5))  # the simulator's


def test_the_filter_panel_writes_angles_and_rates_with_the_degree_sign(qtbot):
    from PySide6.QtWidgets import QAbstractSpinBox

    from app.core.readout import unit_symbol
    from app.gui.filter_panel import FilterPanel

    assert (unit_symbol("dps"), unit_symbol("deg/s"), unit_symbol("deg")) == ("°/s", "°/s", "°")
    assert unit_symbol("mdps/√Hz") == "mdps/√Hz"  # the datasheet's own unit stays
    panel = FilterPanel()
    qtbot.addWidget(panel)
    panel.show_filter("ekf", {})
    suffixes = [spin.suffix() for spin in panel.findChildren(QAbstractSpinBox)
                if hasattr(spin, "suffix")]
    assert any(s.endswith("°/s") for s in suffixes), suffixes
    assert not [s for s in suffixes if s.strip() in ("dps", "deg", "deg/s")], suffixes
