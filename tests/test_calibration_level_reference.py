"""Level reference: tare as a relative rotation, and the reversal procedure."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.calibration_procedures import (
    TareReference,
    reversal,
    reversal_first_order,
    reversal_from_angles,
)
from app.core.calibration_procedures.level_reference import up_from_roll_pitch
from app.core.orientation import (
    angles_from_quaternion,
    angles_from_up,
    quaternion_from_roll_pitch,
    up_in_sensor_frame,
)
from app.core.samples import convert_raw_block
from drivers.registry import open_device

Z = np.array([0.0, 0.0, 1.0])


def rz(deg: float) -> np.ndarray:
    return quat.from_axis_angle(Z, math.radians(deg))


def test_tare_at_30_degrees_reads_zero_and_relative_angles():
    tare = TareReference.from_angles(30.0, 0.0)
    zero = tare.apply_angles(30.0, 0.0)
    assert zero.roll_deg == pytest.approx(0.0, abs=1e-12)
    assert zero.pitch_deg == pytest.approx(0.0, abs=1e-12)
    assert zero.tilt_deg == pytest.approx(0.0, abs=1e-6)
    five_more = tare.apply_angles(35.0, 0.0)
    assert five_more.roll_deg == pytest.approx(5.0, abs=1e-12)
    assert five_more.pitch_deg == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(
        [tare.reference_angles.roll_deg, tare.reference_angles.pitch_deg], [30.0, 0.0], atol=1e-12
    )
    pitched = TareReference.from_angles(0.0, 30.0).apply_angles(0.0, 20.0)
    assert pitched.pitch_deg == pytest.approx(-10.0, abs=1e-12)


def test_tare_corrects_a_sensor_mounted_30_degrees_askew_at_any_platform_tilt():
    """Sensor tipped 30 degrees on a platform; tared with the platform level (any heading)."""
    axis = np.array([math.cos(math.radians(20.0)), math.sin(math.radians(20.0)), 0.0])
    mount = quat.from_axis_angle(axis, math.radians(30.0))  # sensor -> platform, a pure tilt
    tare = TareReference.from_quaternion(quat.multiply(rz(70.0), mount))
    offset = tare.reference_angles
    worst_naive = 0.0
    for roll, pitch in [(0, 0), (10, 5), (45, -20), (-60, 30), (20, 60), (-35, -50)]:
        platform = quaternion_from_roll_pitch(roll, pitch, 25.0)
        sensor = quat.multiply(platform, mount)
        # Relative rotation, via up vectors, angles and quaternions alike:
        from_up = angles_from_up(tare.apply_up(up_in_sensor_frame(sensor)))
        raw = angles_from_quaternion(sensor)
        from_angles = tare.apply_angles(raw.roll_deg, raw.pitch_deg)
        from_quat = angles_from_quaternion(tare.apply_quaternion(sensor))
        for got in (from_up, from_angles, from_quat):
            assert got.roll_deg == pytest.approx(roll, abs=1e-9)
            assert got.pitch_deg == pytest.approx(pitch, abs=1e-9)
        # Subtracting roll/pitch offsets instead is wrong at these tilts.
        naive_roll = raw.roll_deg - offset.roll_deg
        naive_pitch = raw.pitch_deg - offset.pitch_deg
        worst_naive = max(worst_naive, abs(naive_roll - roll), abs(naive_pitch - pitch))
    assert worst_naive > 5.0


def test_tare_cannot_see_a_heading_offset_but_keeps_the_tilt():
    """A mount that also turns the sensor about the vertical mixes roll and pitch."""
    mount = quat.multiply(rz(4.0), quaternion_from_roll_pitch(30.0, -12.0))
    tare = TareReference.from_quaternion(mount)
    platform = quaternion_from_roll_pitch(40.0, 15.0)
    got = angles_from_up(tare.apply_up(up_in_sensor_frame(quat.multiply(platform, mount))))
    want = angles_from_quaternion(platform)
    assert got.tilt_deg == pytest.approx(want.tilt_deg, abs=1e-9)  # the tilt is exact
    assert abs(got.direction_deg - want.direction_deg) > 0.5  # the heading part is unseen


def test_tare_from_the_simulator_at_30_degrees():
    dev = open_device("sim://static?roll=30&pitch=0&odr=104&realtime=0&block=300&seed=1&errors=0")
    block = convert_raw_block(dev.read(1.0))
    tare = TareReference.from_up(block.accel_m_s2.mean(axis=0))
    assert tare.apply_angles(30.0, 0.0).roll_deg == pytest.approx(0.0, abs=0.01)
    tilted = open_device(
        "sim://static?roll=40&pitch=0&odr=104&realtime=0&block=300&seed=1&errors=0"
    )
    reading = convert_raw_block(tilted.read(1.0)).accel_m_s2.mean(axis=0)
    relative = angles_from_up(tare.apply_up(reading))
    assert relative.roll_deg == pytest.approx(10.0, abs=0.01)
    assert relative.pitch_deg == pytest.approx(0.0, abs=0.01)


def test_tare_edge_cases_and_round_trip():
    assert TareReference.from_up([0.0, 0.0, 5.0]).is_identity
    flipped = TareReference.from_up([0.0, 0.0, -1.0])
    np.testing.assert_allclose(flipped.apply_up([0.0, 0.0, -1.0]), Z, atol=1e-12)
    tare = TareReference.from_angles(12.0, -7.0)
    again = TareReference.from_list(tare.to_list())
    np.testing.assert_allclose(again.quaternion, tare.quaternion)
    with pytest.raises(ValueError):
        TareReference.from_up([0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        TareReference.from_list([1.0, 0.0, math.nan, 0.0])


def surface_readings(offset, slope, heading_deg=35.0):
    """Up vectors seen by a sensor (offset = its mounting on its base) in two positions."""
    surface = quaternion_from_roll_pitch(*slope)  # the surface's tilt
    mount = quaternion_from_roll_pitch(*offset)  # sensor -> instrument base
    first = quat.multiply(quat.multiply(surface, rz(heading_deg)), mount)
    second = quat.multiply(quat.multiply(surface, rz(heading_deg + 180.0)), mount)
    return first, second


def test_reversal_separates_offset_from_slope_exactly():
    offset, slope = (0.8, -0.5), (1.5, 2.0)
    first, second = surface_readings(offset, slope, heading_deg=0.0)
    result = reversal(up_in_sensor_frame(first), up_in_sensor_frame(second))
    assert result.offset_roll_deg == pytest.approx(offset[0], abs=1e-9)
    assert result.offset_pitch_deg == pytest.approx(offset[1], abs=1e-9)
    assert result.slope_deg == pytest.approx(math.degrees(math.acos(
        up_in_sensor_frame(quaternion_from_roll_pitch(*slope))[2])), abs=1e-9)
    # Slope in the instrument's first-position axes (heading 0: the surface's own axes).
    assert result.slope_roll_deg == pytest.approx(slope[0], abs=0.02)
    assert result.slope_pitch_deg == pytest.approx(slope[1], abs=0.02)
    # The first-order formulas agree to a few thousandths of a degree at these angles.
    a1, a2 = angles_from_quaternion(first), angles_from_quaternion(second)
    (off_r, off_p), (sl_r, sl_p) = reversal_first_order(
        (a1.roll_deg, a1.pitch_deg), (a2.roll_deg, a2.pitch_deg)
    )
    assert (off_r, off_p) == pytest.approx(offset, abs=0.01)
    assert (sl_r, sl_p) == pytest.approx(slope, abs=0.05)
    # Both slope components flip sign in the second position; the offset does not.
    assert np.sign(a1.pitch_deg - off_p) == -np.sign(a2.pitch_deg - off_p)
    assert np.sign(a1.roll_deg - off_r) == -np.sign(a2.roll_deg - off_r)
    # The tare from the reversal makes a level surface read zero.
    level = up_in_sensor_frame(quaternion_from_roll_pitch(*offset))
    np.testing.assert_allclose(angles_from_up(result.tare.apply_up(level)).tilt_deg, 0.0,
                               atol=1e-6)


def test_reversal_with_the_simulator_and_any_heading():
    """Known offset (0.6, -0.4) and slope (1.2, 0.8) in degrees, measured with noise."""
    offset, slope = (0.6, -0.4), (1.2, 0.8)
    ups = []
    for q in surface_readings(offset, slope, heading_deg=35.0):
        angles = angles_from_quaternion(q)
        x_axis = quat.rotate(q, np.array([1.0, 0.0, 0.0]))
        yaw = math.degrees(math.atan2(x_axis[1], x_axis[0]))
        np.testing.assert_allclose(
            quat.normalize(quaternion_from_roll_pitch(angles.roll_deg, angles.pitch_deg, yaw)),
            quat.normalize(q), atol=1e-9,
        )
        dev = open_device(
            f"sim://static?roll={angles.roll_deg:.9f}&pitch={angles.pitch_deg:.9f}&yaw={yaw:.9f}"
            "&odr=104&realtime=0&block=1040&seed=1&errors=0"
        )
        ups.append(convert_raw_block(dev.read(1.0)).accel_m_s2.mean(axis=0))
    result = reversal(*ups)
    assert result.offset_roll_deg == pytest.approx(offset[0], abs=0.005)
    assert result.offset_pitch_deg == pytest.approx(offset[1], abs=0.005)
    assert result.slope_deg == pytest.approx(math.hypot(*slope), abs=0.005)
    via_angles = reversal_from_angles(
        *[float(v) for u in ups for v in (angles_from_up(u).roll_deg, angles_from_up(u).pitch_deg)]
    )
    assert via_angles.offset_roll_deg == pytest.approx(result.offset_roll_deg, abs=1e-9)


def test_reversal_rejects_opposite_readings():
    with pytest.raises(ValueError, match="turned over"):
        reversal(up_from_roll_pitch(0.0, 0.0), -up_from_roll_pitch(0.0, 0.0))
