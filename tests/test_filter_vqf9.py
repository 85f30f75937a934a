"""VQF with the magnetometer (9D): against the vqf package called directly, a slow
magnetometer, the frame (ENU, y toward magnetic north), parameters, restarts; offline VQF 9D."""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest

vqf = pytest.importorskip("vqf")

from app.core import quaternion as quat  # noqa: E402
from app.core.evaluation import concatenate_blocks, split_block  # noqa: E402
from app.core.filters.offline import OfflineVQF  # noqa: E402
from app.core.filters.vqf_filter import VQFFilter  # noqa: E402
from app.core.heading_metrics import (  # noqa: E402
    PROJECT_TURN_DEG,
    heading_error_deg,
    turn_block,
    turn_quaternion,
)
from app.core.samples import SampleBlock  # noqa: E402
from app.services.simulation import simulator_blocks  # noqa: E402

EARTH_FIELD_UT = np.array([0.0, 19.0, -45.0])  # ENU: north and down


@cache
def wobble(seconds: float = 12.0) -> SampleBlock:
    """A hand-held stream from the simulator with an ideal field on every row (from its true
    orientation, ENU with y north)."""
    stream = concatenate_blocks(simulator_blocks("sim://wobble?odr=208&seed=3", seconds))
    field = quat.rotate_inverse(stream.reference_quat, EARTH_FIELD_UT)
    return dataclasses.replace(stream, mag_ut=field)


def every_nth_field(block: SampleBlock, n: int) -> SampleBlock:
    field = block.mag_ut.copy()
    field[np.arange(len(field)) % n != 0] = np.nan
    return dataclasses.replace(block, mag_ut=field)


def arrays(block: SampleBlock) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    field = np.where(np.isfinite(block.mag_ut), block.mag_ut, 0.0)
    return (np.ascontiguousarray(block.gyro_rad_s), np.ascontiguousarray(block.accel_m_s2),
            np.ascontiguousarray(field))


def run(f, blocks) -> np.ndarray:
    return np.concatenate([f.process(b).quat for b in blocks])


def test_9d_matches_vqf_called_directly_in_live_sized_blocks():
    stream = wobble()
    f = VQFFilter()
    out = run(f, split_block(stream, 133))
    expected = vqf.VQF(f.sample_period_s).updateBatch(*arrays(stream))["quat9D"]
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
    assert f.field_period_s == pytest.approx(f.sample_period_s, rel=1e-9)
    # 9D: the estimate has the true heading (the 6D one would not).
    assert heading_error_deg(out, stream.reference_quat)[-200:].max() < 1.0


def test_a_slow_magnetometer_runs_vqf_at_its_own_period_on_its_own_samples():
    """A field every 4th row, NaN between: VQF gets (0, 0, 0) there (its updateMag skips it)
    and magTs = 4 Ts, exactly as VQF(gyrTs, accTs, magTs) fed per sample."""
    stream = every_nth_field(wobble(), 4)
    f = VQFFilter()
    out = run(f, split_block(stream, 133))
    assert f.field_period_s == pytest.approx(4 * f.sample_period_s, rel=1e-9)
    engine = vqf.VQF(f.sample_period_s, f.sample_period_s, f.field_period_s)
    expected = engine.updateBatch(*arrays(stream))["quat9D"]
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
    # Holding the last sample instead would run VQF's field filters four times too fast.
    held = vqf.VQF(f.sample_period_s).updateBatch(*arrays(wobble()))["quat9D"]
    assert not np.allclose(out, held, atol=1e-9)


def test_a_magnetometer_at_a_rate_that_is_no_fraction_of_the_accelerometers():
    """80 Hz beside 208 Hz: field rows 2, 3, 2, 3... apart; the period is the mean step."""
    stream = wobble()
    t = stream.t_s
    rows = np.unique(np.searchsorted(t, np.arange(t[0], t[-1], 1.0 / 80.0)))
    field = np.full_like(stream.mag_ut, np.nan)
    field[rows] = stream.mag_ut[rows]
    f = VQFFilter()
    out = f.process(dataclasses.replace(stream, mag_ut=field)).quat
    assert f.field_period_s == pytest.approx(1.0 / 80.0, rel=0.01)
    assert heading_error_deg(out, stream.reference_quat)[-200:].max() < 1.0


def test_a_level_sensor_pointing_30_degrees_east_of_north_reads_so():
    """Written without quaternions (see test_filters_marg): ENU, y toward magnetic north."""
    n = 300
    field = np.array([19.0 * np.cos(np.radians(120.0)), 19.0 * np.cos(np.radians(30.0)), -45.0])
    block = SampleBlock(np.arange(n) * 0.01, np.tile([0.0, 0.0, 9.80665], (n, 1)),
                        np.zeros((n, 3)), np.full(n, 25.0), np.zeros(n, bool), None,
                        np.tile(field, (n, 1)))
    out = VQFFilter().process(block).quat
    for q in (out[0], out[-1]):
        y_earth = quat.rotate(q, np.array([0.0, 1.0, 0.0]))
        np.testing.assert_allclose(y_earth, [0.5, np.cos(np.radians(30.0)), 0.0], atol=1e-6)


def test_without_a_field_or_switched_off_it_is_the_6d_filter_unchanged():
    stream = wobble()
    six = VQFFilter().process(dataclasses.replace(stream, mag_ut=None)).quat
    off = VQFFilter(magnetometer=False).process(stream).quat
    np.testing.assert_array_equal(six, off)
    expected = vqf.VQF(VQFFilter().process(stream).quat.shape[0] and
                       float(np.median(np.diff(stream.t_s)))).updateBatch(
        *arrays(stream)[:2])["quat6D"]
    np.testing.assert_allclose(six, expected, rtol=0, atol=1e-12)


def test_magnetic_parameters_reach_vqf_and_change_mid_stream_as_vqf_does():
    stream = wobble()
    half = len(stream) // 2
    f = VQFFilter(tau_mag_s=4.0)
    first = f.process(dataclasses.replace(stream, **{
        k: None if v is None else v[:half] for k, v in _columns(stream).items()})).quat
    f.set_parameter("mag_disturbance_rejection", False)
    f.set_parameter("tau_mag_s", 12.0)
    second = f.process(dataclasses.replace(stream, **{
        k: None if v is None else v[half:] for k, v in _columns(stream).items()})).quat
    gyro, accel, field = arrays(stream)
    engine = vqf.VQF(f.sample_period_s, tauMag=4.0)
    expected_first = engine.updateBatch(gyro[:half], accel[:half], field[:half])["quat9D"]
    engine.setMagDistRejectionEnabled(False)
    engine.setTauMag(12.0)
    expected_second = engine.updateBatch(gyro[half:], accel[half:], field[half:])["quat9D"]
    np.testing.assert_allclose(first, expected_first, rtol=0, atol=1e-12)
    np.testing.assert_allclose(second, expected_second, rtol=0, atol=1e-12)


def _columns(block: SampleBlock) -> dict:
    return {f.name: getattr(block, f.name) for f in dataclasses.fields(block)}


def magnet_stream() -> tuple[np.ndarray, SampleBlock]:
    """(truth, block): turning at 30 deg/s about the vertical for 20 s, then 10 s with a field
    40 % stronger and turned 30 deg."""
    n = 3000
    t = np.arange(n) * 0.01
    rate = np.radians(30.0)
    truth = quat.from_rotation_vector(np.outer(rate * t, [0.0, 0.0, 1.0]))
    earth = np.tile(EARTH_FIELD_UT, (n, 1))
    earth[2000:] = quat.rotate(quat.from_axis_angle(np.array([0.0, 0.0, 1.0]),
                                                    np.radians(30.0)), EARTH_FIELD_UT) * 1.4
    block = SampleBlock(t, np.tile([0.0, 0.0, 9.80665], (n, 1)), np.tile([0.0, 0.0, rate], (n, 1)),
                        np.full(n, 25.0), np.zeros(n, bool), None,
                        quat.rotate_inverse(truth, earth))
    return truth, block


def test_a_magnet_is_flagged_and_the_gyro_carries_the_heading_while_rejected():
    """VQF accepts a field as its reference only while the sensor turns faster than 20 deg/s:
    the turning teaches it; the magnet is flagged, and with rejection the heading holds,
    without it follows the magnet."""
    truth, block = magnet_stream()
    on = VQFFilter()
    rejected = on.process(block).quat
    assert on.magnetic_disturbance
    assert heading_error_deg(rejected, truth)[1999] < 1e-6
    assert heading_error_deg(rejected, truth)[-1] < 0.5
    off = VQFFilter(mag_disturbance_rejection=False).process(block).quat
    assert heading_error_deg(off, truth)[-1] > 15.0


def test_a_gap_restarts_the_heading_but_keeps_the_learnt_field_reference():
    truth, block = magnet_stream()
    columns = _columns(block)
    f = VQFFilter()
    f.process(dataclasses.replace(block, **{k: None if v is None else v[:1500]
                                            for k, v in columns.items()}))
    learnt = f._vqf.state["magRefNorm"]
    assert learnt == pytest.approx(np.linalg.norm(EARTH_FIELD_UT), rel=1e-3)
    rest = {k: None if v is None else v[1500:2000] for k, v in columns.items()}
    rest["gap"] = np.r_[True, np.zeros(499, bool)]
    out = f.process(dataclasses.replace(block, **rest)).quat
    assert f._vqf.state["magRefNorm"] == pytest.approx(learnt, rel=1e-3)
    # The restart took tilt from the accelerometer and heading from the next field samples.
    assert heading_error_deg(out, truth[1500:2000]).max() < 0.5


def test_offline_vqf_9d_is_the_packages_and_holds_a_slow_field():
    stream = turn_block(wobble(6.0), turn_quaternion(PROJECT_TURN_DEG))  # heading not by luck
    ts = float(np.median(np.diff(stream.t_s)))
    out = OfflineVQF().process(stream).quat
    expected = quat.normalize(vqf.offlineVQF(*arrays(stream)[:2], arrays(stream)[2], ts,
                                             {})["quat9D"])
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
    slow = every_nth_field(stream, 4)
    held = slow.mag_ut.copy()
    for k in range(len(held)):
        if not np.isfinite(held[k, 0]):
            held[k] = held[k - 1]
    expected = quat.normalize(vqf.offlineVQF(*arrays(stream)[:2], np.ascontiguousarray(held),
                                             ts, {})["quat9D"])
    np.testing.assert_allclose(OfflineVQF().process(slow).quat, expected, rtol=0, atol=1e-12)
    six = OfflineVQF(magnetometer=False).process(stream).quat
    assert heading_error_deg(six, stream.reference_quat).max() > 5.0
    assert heading_error_deg(out, stream.reference_quat)[200:].max() < 1.0


def test_disturbance_thresholds_reach_vqf_and_change_mid_stream_with_the_whole_state():
    truth, block = magnet_stream()
    f = VQFFilter(mag_norm_threshold=0.5, mag_dip_threshold_deg=40.0)
    columns = _columns(block)
    first = f.process(dataclasses.replace(block, **{k: None if v is None else v[:1000]
                                                    for k, v in columns.items()})).quat
    f.set_parameter("mag_norm_threshold", 0.05)
    second = f.process(dataclasses.replace(block, **{k: None if v is None else v[1000:]
                                                     for k, v in columns.items()})).quat
    gyro, accel, field = arrays(block)
    old = vqf.VQF(0.01, magNormTh=0.5, magDipTh=40.0)
    expected_first = old.updateBatch(gyro[:1000], accel[:1000], field[:1000])["quat9D"]
    new = vqf.VQF(0.01, magNormTh=0.05, magDipTh=40.0)
    new.state = old.state
    expected_second = new.updateBatch(gyro[1000:], accel[1000:], field[1000:])["quat9D"]
    np.testing.assert_allclose(first, expected_first, rtol=0, atol=1e-12)
    np.testing.assert_allclose(second, expected_second, rtol=0, atol=1e-12)
    # A 40 % stronger field is no disturbance with a 50 % threshold: the magnet wins.
    loose = VQFFilter(mag_norm_threshold=0.5, mag_dip_threshold_deg=40.0)
    assert heading_error_deg(loose.process(block).quat, truth)[-1] > 15.0
    assert not loose.magnetic_disturbance
