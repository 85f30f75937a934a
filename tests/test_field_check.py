"""The field's strength, its dip against gravity and the disturbance check (app.core.field_check),
and the pipeline's field ring that carries them to the views."""

from __future__ import annotations

import math
from datetime import date

import numpy as np
import pytest

from app.core.calibration import MagnetometerCalibration, SensorCalibration
from app.core.earth_field import DEFAULT_PLACE, Place, earth_field
from app.core.field_check import (
    FieldMonitor,
    ReferenceSettings,
    check_disturbance,
    dip_deg,
    field_norm,
    learn_at_rest,
    learned_reference,
    wmm_reference,
)
from app.core.orientation import quaternion_from_roll_pitch
from app.core.pipeline import Pipeline
from app.core.quaternion import from_axis_angle, multiply, rotate_inverse
from app.core.samples import STANDARD_GRAVITY_M_S2, RawBlock, ScaleFactors

G = STANDARD_GRAVITY_M_S2
WHEN = 2026.5
EARTH = earth_field(DEFAULT_PLACE, WHEN)
ENU_FIELD = EARTH.enu_magnetic_ut()  # (0, H, -Z): earth frame, z up
UP = np.array([0.0, 0.0, G])


def sensor_readings(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Accelerometer and field a sensor at rest in orientation ``q`` (sensor -> earth) reads."""
    return rotate_inverse(q, UP), rotate_inverse(q, ENU_FIELD)


def test_level_sensor_reads_the_wmm_strength_and_dip():
    accel, mag = sensor_readings(np.array([1.0, 0, 0, 0]))
    assert field_norm(mag[None])[0] == pytest.approx(EARTH.total_ut)
    assert dip_deg(mag[None], accel[None])[0] == pytest.approx(EARTH.dip_deg, abs=1e-9)
    assert EARTH.dip_deg > 60  # Berlin: the field points well below the horizon


@pytest.mark.parametrize("roll, pitch, heading", [(30, -20, 0), (-75, 10, 130), (170, 5, -60)])
def test_dip_does_not_depend_on_the_orientation(roll, pitch, heading):
    q = multiply(from_axis_angle(np.array([0, 0, 1.0]), math.radians(heading)),
                 quaternion_from_roll_pitch(roll, pitch))
    accel, mag = sensor_readings(q)
    assert dip_deg(mag[None], accel[None])[0] == pytest.approx(EARTH.dip_deg, abs=1e-9)


def test_a_field_pointing_up_has_a_negative_dip():
    # Southern-hemisphere-like: the field points above the horizon.
    accel = UP[None]
    mag = np.array([[0.0, 20.0, 20.0]])
    assert dip_deg(mag, accel)[0] == pytest.approx(-45.0)


def steady_stream(n: int = 200, odr: float = 100.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A level sensor at rest, a field sample on every 4th row."""
    t = np.arange(n) / odr
    accel = np.tile(UP, (n, 1))
    mag = np.full((n, 3), np.nan)
    mag[::4] = ENU_FIELD
    return t, accel, mag


def test_monitor_returns_only_field_rows_with_strength_and_dip():
    t, accel, mag = steady_stream()
    rows = FieldMonitor().update(t, accel, mag)
    assert len(rows) == 50
    np.testing.assert_array_equal(rows.rows, np.arange(0, 200, 4))
    np.testing.assert_allclose(rows.t_s, t[::4])
    np.testing.assert_allclose(rows.norm_ut, EARTH.total_ut)
    np.testing.assert_allclose(rows.dip_deg, EARTH.dip_deg, atol=1e-9)


def test_dip_is_refused_while_the_sensor_accelerates():
    t, accel, mag = steady_stream()
    # A push along x for 0.2 s: not gravity alone. (A push held for long enough reads as a
    # tilt, to this as to any accelerometer-only attitude.)
    accel[100:120] += np.array([3.0, 0.0, 0.0])
    rows = FieldMonitor().update(t, accel, mag)
    moving = (rows.t_s >= 1.0) & (rows.t_s < 1.2)
    assert np.all(np.isnan(rows.dip_deg[moving]))
    assert np.all(np.isfinite(rows.dip_deg[~moving & (rows.t_s < 1.0)]))
    np.testing.assert_allclose(rows.norm_ut, EARTH.total_ut)  # |m| is valid in motion


def test_the_low_pass_keeps_its_state_between_blocks():
    t, accel, mag = steady_stream(400)
    accel[200:] = rotate_inverse(quaternion_from_roll_pitch(20.0, 0.0), UP)
    whole = FieldMonitor().update(t, accel, mag)
    split = FieldMonitor()
    parts = [split.update(t[a:b], accel[a:b], mag[a:b]) for a, b in ((0, 203), (203, 400))]
    np.testing.assert_allclose(np.concatenate([p.dip_deg for p in parts]), whole.dip_deg,
                               equal_nan=True)
    # After the tilt the low-pass lags: refused until it has caught up.
    after = whole.t_s >= 2.0
    assert np.isnan(whole.dip_deg[after][0])
    assert np.isfinite(whole.dip_deg[after][-1])


def test_wmm_reference_is_the_model_value():
    reference = wmm_reference(DEFAULT_PLACE, WHEN)
    assert reference.total_ut == pytest.approx(EARTH.total_ut)
    assert reference.dip_deg == pytest.approx(EARTH.dip_deg)
    assert "WMM" in reference.source
    with pytest.raises(ValueError, match="outside"):
        wmm_reference(DEFAULT_PLACE, 2040.0)


def test_disturbance_check_flags_a_magnet_and_passes_the_clean_field():
    reference = wmm_reference(DEFAULT_PLACE, WHEN)
    n = 100
    norm = np.full(n, EARTH.total_ut) + np.random.default_rng(1).normal(0, 0.3, n)
    dip = np.full(n, EARTH.dip_deg)
    clean = check_disturbance(norm, dip, reference)
    assert not clean.disturbed.any() and clean.message == "" and clean.fraction == 0.0
    norm[40:60] += 25.0  # a magnet passing by
    dip[70:75] = np.nan  # not steady: unknown dip is not a disturbance
    result = check_disturbance(norm, dip, reference)
    np.testing.assert_array_equal(np.flatnonzero(result.disturbed), np.arange(40, 60))
    assert result.fraction == pytest.approx(0.2)
    assert "20%" in result.message and "µT" in result.message


def test_dip_alone_can_show_a_disturbance():
    reference = wmm_reference(DEFAULT_PLACE, WHEN)
    result = check_disturbance(np.array([EARTH.total_ut]), np.array([EARTH.dip_deg - 20]),
                               reference)
    assert result.disturbed.all() and "dip" in result.message


def test_learned_reference_is_tighter_and_needs_steady_samples():
    norm = np.array([40.0, 41.0, 40.5, np.nan])
    dip = np.array([60.0, np.nan, 61.0, 60.5])
    reference = learned_reference(norm, dip)
    assert reference.total_ut == pytest.approx(40.25)
    assert reference.dip_deg == pytest.approx(60.5)
    assert reference.field_tolerance < wmm_reference(DEFAULT_PLACE, WHEN).field_tolerance
    assert check_disturbance(np.array([43.0]), np.array([60.5]), reference).disturbed.all()
    with pytest.raises(ValueError, match="no steady"):
        learned_reference(norm, np.full(4, np.nan))


# -- the pipeline's field ring -------------------------------------------------------------------
SCALE = ScaleFactors(0.122e-3 * G, math.radians(8.75e-3), 1 / 256, 25.0, mag_ut_per_lsb=0.1)


def raw_with_field(start: int, count: int, every: int = 4, odr: float = 104.0,
                   field: bool = True) -> RawBlock:
    rows = start + np.arange(count)
    mag = None
    if field:
        mag = np.full((count, 3), np.nan)
        on = rows % every == 0
        mag[on] = np.round(ENU_FIELD / 0.1) + np.array([100.0, 0.0, 0.0])  # 10 uT hard iron
    return RawBlock(
        t_s=rows / odr,
        accel_raw=np.tile(np.round(UP / SCALE.accel_m_s2_per_lsb), (count, 1)).astype(np.int16),
        gyro_raw=np.zeros((count, 3), np.int16), temp_raw=np.full(count, 0, np.int16),
        scale=SCALE, mag_raw=mag,
    )


def test_pipeline_buffers_calibrated_field_samples_with_strength_and_dip():
    pipeline = Pipeline(odr_hz=104.0)
    pipeline.set_calibration(SensorCalibration(name="mag").with_magnetometer(
        MagnetometerCalibration(hard_iron_ut=np.array([10.0, 0.0, 0.0]))))
    for start in range(0, 416, 52):
        pipeline.process(raw_with_field(start, 52))
    assert pipeline.has_field
    rows = pipeline.field.latest(1000)
    assert len(rows["t"]) == 104  # a field sample every 4th of 416 rows
    np.testing.assert_allclose(rows["t"], np.arange(0, 416, 4) / 104.0)
    np.testing.assert_allclose(rows["raw_mag"][:, 0], np.round(ENU_FIELD[0] / 0.1) * 0.1 + 10.0)
    np.testing.assert_allclose(rows["mag"], np.tile(np.round(ENU_FIELD / 0.1) * 0.1, (104, 1)),
                               atol=1e-9)
    np.testing.assert_allclose(rows["norm"], EARTH.total_ut, atol=0.1)
    assert np.nanmean(np.abs(rows["dip"] - EARTH.dip_deg)) < 0.1
    assert not rows["gap"].any()


def test_field_ring_marks_the_first_field_sample_after_lost_data():
    pipeline = Pipeline(odr_hz=104.0)
    pipeline.process(raw_with_field(0, 40))
    lost = raw_with_field(41, 2)  # rows 41, 42: no field sample, but data were lost before
    lost.gap = np.array([True, False])
    pipeline.process(lost)
    pipeline.process(raw_with_field(43, 20))
    rows = pipeline.field.latest(1000)
    np.testing.assert_array_equal(rows["t"][rows["gap"] > 0.5], [44 / 104.0])
    assert np.count_nonzero(rows["gap"]) == 1


def test_source_without_a_magnetometer_leaves_the_field_ring_empty():
    pipeline = Pipeline(odr_hz=104.0)
    pipeline.process(raw_with_field(0, 52, field=False))
    assert pipeline.counters.samples == 52
    assert not pipeline.has_field and len(pipeline.field) == 0


def test_learning_at_rest_refuses_a_moving_field():
    still = learn_at_rest(np.full(20, 48.0) + 0.1 * np.sin(np.arange(20)), np.full(20, 66.0))
    assert still.total_ut == pytest.approx(48.0, abs=0.1)
    with pytest.raises(ValueError, match="moved"):
        learn_at_rest(np.linspace(40, 60, 20), np.full(20, 66.0))
    with pytest.raises(ValueError, match="hold the sensor still"):
        learn_at_rest(np.full(5, 48.0), np.full(5, np.nan))


def test_reference_settings_round_trip_and_refuse_bad_input():
    settings = ReferenceSettings(Place(-33.9, 151.2, 10.0), date(2027, 3, 1))
    again = ReferenceSettings.from_dict(settings.to_dict())
    assert again == settings
    assert again.reference().dip_deg < 0  # Sydney: the field points up
    assert ReferenceSettings.from_dict({}).place == DEFAULT_PLACE
    for bad, words in (({"latitude_deg": "north"}, "latitude_deg"),
                       ({"latitude_deg": 95.0}, "latitude"),
                       ({"date": "yesterday"}, "YYYY-MM-DD"),
                       ({"date": "2031-01-01"}, "outside")):
        with pytest.raises(ValueError, match=words):
            ReferenceSettings.from_dict(bad)
