"""The VQF wrapper: agreement with the vqf package, conventions, continuity, restarts, settings."""

from __future__ import annotations

import importlib.util
import sys
from functools import cache

import numpy as np
import pytest

vqf = pytest.importorskip("vqf")

from app.core import quaternion as quat  # noqa: E402
from app.core.evaluation import concatenate_blocks, split_block  # noqa: E402
from app.core.filters import vqf_filter  # noqa: E402
from app.core.filters.vqf_filter import VQFFilter  # noqa: E402
from app.core.orientation import (  # noqa: E402
    inclination_error_deg,
    quaternion_from_roll_pitch,
    up_in_sensor_frame,
)
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock  # noqa: E402
from app.services.simulation import simulator_blocks  # noqa: E402

G = STANDARD_GRAVITY_M_S2


@cache
def wobble(seconds: float = 12.0) -> SampleBlock:
    """A hand-held stream from the simulator (static errors compensated), cached per length."""
    return concatenate_blocks(simulator_blocks("sim://wobble?odr=208&seed=3", seconds))


def piece(block: SampleBlock, start: int, stop: int) -> SampleBlock:
    ref = block.reference_quat
    return SampleBlock(
        block.t_s[start:stop], block.accel_m_s2[start:stop], block.gyro_rad_s[start:stop],
        block.temp_degc[start:stop], block.gap[start:stop],
        None if ref is None else ref[start:stop],
    )


def static_block(t: np.ndarray, roll: float, pitch: float, gyro=(0.0, 0.0, 0.0)) -> SampleBlock:
    n = len(t)
    accel = np.tile(up_in_sensor_frame(quaternion_from_roll_pitch(roll, pitch)) * G, (n, 1))
    gyro = np.tile(np.asarray(gyro, dtype=float), (n, 1))
    return SampleBlock(np.asarray(t, float), accel, gyro, np.full(n, 25.0), np.zeros(n, bool))


def run(f: VQFFilter, blocks) -> np.ndarray:
    return np.concatenate([f.process(b).quat for b in blocks])


def direct(ts: float, block: SampleBlock, **params) -> np.ndarray:
    engine = vqf.VQF(ts, **params)
    return engine.updateBatch(
        np.ascontiguousarray(block.gyro_rad_s), np.ascontiguousarray(block.accel_m_s2)
    )["quat6D"]


def irregular_cuts(n: int, sizes=(1, 2, 37, 133, 500, 1, 999)) -> list[tuple[int, int]]:
    cuts, start, i = [], 0, 0
    while start < n:
        stop = min(n, start + sizes[i % len(sizes)])
        cuts.append((start, stop))
        start, i = stop, i + 1
    return cuts


def test_matches_vqf_called_directly_whatever_the_block_sizes():
    stream = wobble()
    f = VQFFilter()
    out = run(f, [piece(stream, a, b) for a, b in irregular_cuts(len(stream))])
    odr = 1.0 / np.median(np.diff(stream.t_s))
    assert f.sample_period_s == pytest.approx(1.0 / odr, rel=1e-12)
    expected = direct(f.sample_period_s, stream)
    # The stream opens with a lone sample: it is answered on a provisional Ts, then replayed
    # at the right one, so everything after it is VQF's own output, and it has VQF's tilt.
    np.testing.assert_allclose(out[1:], expected[1:], rtol=0, atol=1e-12)
    assert inclination_error_deg(out[0], expected[0]) < 1e-9
    one_block = VQFFilter().process(stream).quat
    np.testing.assert_allclose(one_block, expected, rtol=0, atol=1e-12)


def test_live_sized_blocks_continue_exactly():
    stream = wobble()
    whole = VQFFilter().process(stream).quat
    live = run(VQFFilter(), split_block(stream, 133))
    # Ts comes from the first block's median step, which may differ from the whole stream's
    # in the last bit: hence not bit-for-bit.
    np.testing.assert_allclose(live, whole, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("roll", "pitch"),
    [(0.0, 0.0), (30.0, 0.0), (0.0, -45.0), (20.0, 60.0), (180.0, 0.0), (0.0, 90.0), (-120, 30)],
)
def test_known_static_poses(roll, pitch):
    t = np.arange(500) * 0.01
    out = VQFFilter().process(static_block(t, roll, pitch)).quat
    truth = quaternion_from_roll_pitch(roll, pitch)
    assert inclination_error_deg(out[0], truth) < 1e-9  # the first sample snaps to gravity
    # Then VQF's motion bias estimator wanders by a few thousandths of a degree, even on
    # perfect data (the vqf package does the same; see the test against it above).
    assert np.max(inclination_error_deg(out, truth)) < 0.02
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-12)


def test_quaternion_convention_is_ours_not_its_inverse():
    """(w, x, y, z), sensor to earth: roll 30 is Rx(30), pitch 40 is Ry(-40) (from level)."""
    t = np.arange(3) * 0.01
    roll = VQFFilter().process(static_block(t, 30.0, 0.0)).quat[0]
    np.testing.assert_allclose(roll, quaternion_from_roll_pitch(30.0, 0.0), atol=1e-12)
    pitch = VQFFilter().process(static_block(t, 0.0, 40.0)).quat[0]
    np.testing.assert_allclose(pitch, [np.cos(np.radians(20)), 0, -np.sin(np.radians(20)), 0],
                               atol=1e-12)


def test_body_rate_convention():
    """Rolling at +20 deg/s about sensor x: the estimate follows the true roll at once."""
    dt, rate = 0.005, 20.0
    t = np.arange(800) * dt
    roll = rate * t
    truth = quaternion_from_roll_pitch(roll, 0.0)
    accel = up_in_sensor_frame(truth) * G
    gyro = np.tile([np.radians(rate), 0.0, 0.0], (len(t), 1))
    block = SampleBlock(t, accel, gyro, np.full(len(t), 25.0), np.zeros(len(t), bool))
    out = VQFFilter().process(block).quat
    assert np.max(inclination_error_deg(out, truth)) < 0.05


def test_gap_restarts_from_the_accelerometer_and_keeps_the_bias():
    stream = wobble()
    n = len(stream)
    cut, lost = n // 2, 300
    keep = np.r_[0:cut, cut + lost : n]
    gap = np.zeros(n, bool)
    gap[cut + lost] = True
    gapped = SampleBlock(stream.t_s[keep], stream.accel_m_s2[keep], stream.gyro_rad_s[keep],
                         stream.temp_degc[keep], gap[keep], stream.reference_quat[keep])
    f = VQFFilter()
    out = run(f, split_block(gapped, 1000))
    ts = f.sample_period_s
    before, after = piece(gapped, 0, cut), piece(gapped, cut, len(gapped))
    first = vqf.VQF(ts)
    first.updateBatch(np.ascontiguousarray(before.gyro_rad_s),
                      np.ascontiguousarray(before.accel_m_s2))
    second = vqf.VQF(ts)
    state = second.state
    state["bias"], state["biasP"] = first.state["bias"], first.state["biasP"]
    second.state = state
    expected = second.updateBatch(np.ascontiguousarray(after.gyro_rad_s),
                                  np.ascontiguousarray(after.accel_m_s2))["quat6D"]
    np.testing.assert_allclose(out[cut:], expected, rtol=0, atol=1e-10)
    # ... which starts on the accelerometer's tilt.
    up = after.accel_m_s2[0] / np.linalg.norm(after.accel_m_s2[0])
    assert np.degrees(np.arccos(np.clip(up @ up_in_sensor_frame(out[cut]), -1, 1))) < 1e-6


def test_a_long_step_restarts_like_a_gap():
    t = np.r_[np.arange(100) * 0.01, 5.0 + np.arange(100) * 0.01]
    block = static_block(t, 10.0, 0.0)
    block.accel_m_s2[100:] = up_in_sensor_frame(quaternion_from_roll_pitch(-25.0, 5.0)) * G
    out = VQFFilter().process(block).quat
    assert inclination_error_deg(out[100], quaternion_from_roll_pitch(-25.0, 5.0)) < 1e-9


def test_a_rate_change_over_5_percent_recreates_vqf_and_continues():
    f = VQFFilter()
    t1 = np.arange(300) * 0.01
    f.process(static_block(t1, 10.0, -5.0))
    assert f.sample_period_s == pytest.approx(0.01)
    last = f.quaternion
    # 3 % slower: same Ts, same object.
    t2 = t1[-1] + (1 + np.arange(200)) * 0.0103
    f.process(static_block(t2, 10.0, -5.0))
    assert f.sample_period_s == pytest.approx(0.01)
    # Twice as fast: a new Ts, continuing from where it was.
    t3 = t2[-1] + (1 + np.arange(200)) * 0.005
    out = f.process(static_block(t3, 10.0, -5.0)).quat
    assert f.sample_period_s == pytest.approx(0.005)
    assert quat.angle_between(last, out[0]) < np.radians(0.01)
    assert np.max(inclination_error_deg(out, quaternion_from_roll_pitch(10.0, -5.0))) < 0.02


@pytest.mark.parametrize(
    ("name", "value", "apply"),
    [
        ("tau_acc_s", 0.7, lambda v: v.setTauAcc(0.7)),
        ("motion_bias_estimation", False, lambda v: v.setMotionBiasEstEnabled(False)),
        ("rest_bias_estimation", False, lambda v: v.setRestBiasEstEnabled(False)),
    ],
)
def test_parameter_change_keeps_the_state_as_vqf_does(name, value, apply):
    stream = wobble()
    half = len(stream) // 2
    f = VQFFilter()
    first = f.process(piece(stream, 0, half)).quat
    f.set_parameter(name, value)
    second = f.process(piece(stream, half, len(stream))).quat
    engine = vqf.VQF(f.sample_period_s)
    gyro, accel = np.ascontiguousarray(stream.gyro_rad_s), np.ascontiguousarray(stream.accel_m_s2)
    expected_first = engine.updateBatch(gyro[:half], accel[:half])["quat6D"]
    apply(engine)
    expected_second = engine.updateBatch(gyro[half:], accel[half:])["quat6D"]
    np.testing.assert_allclose(first, expected_first, rtol=0, atol=1e-12)
    np.testing.assert_allclose(second, expected_second, rtol=0, atol=1e-12)


def test_initial_bias_uncertainty_change_carries_the_whole_state():
    stream = wobble()
    half = len(stream) // 2
    f = VQFFilter()
    f.process(piece(stream, 0, half))
    f.set_parameter("bias_sigma_init_dps", 2.0)
    second = f.process(piece(stream, half, len(stream))).quat
    gyro, accel = np.ascontiguousarray(stream.gyro_rad_s), np.ascontiguousarray(stream.accel_m_s2)
    old = vqf.VQF(f.sample_period_s)
    old.updateBatch(gyro[:half], accel[:half])
    new = vqf.VQF(f.sample_period_s, biasSigmaInit=2.0)
    new.state = old.state
    expected = new.updateBatch(gyro[half:], accel[half:])["quat6D"]
    np.testing.assert_allclose(second, expected, rtol=0, atol=1e-12)


def test_parameters_at_construction_reach_vqf():
    stream = wobble()
    f = VQFFilter(tau_acc_s=1.5, rest_bias_estimation=False, bias_sigma_init_dps=0.2)
    out = f.process(stream).quat
    expected = direct(f.sample_period_s, stream, tauAcc=1.5, restBiasEstEnabled=False,
                      biasSigmaInit=0.2)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)


def test_rest_bias_estimation_finds_a_gyro_bias():
    bias = np.radians([0.5, -0.3, 0.2])
    t = np.arange(2000) * 0.01
    f = VQFFilter()
    f.process(static_block(t, 5.0, 5.0, gyro=bias))
    np.testing.assert_allclose(f.bias_estimate_rad_s, bias, atol=np.radians(0.01))
    off = VQFFilter(motion_bias_estimation=False, rest_bias_estimation=False)
    off.process(static_block(t, 5.0, 5.0, gyro=bias))
    np.testing.assert_array_equal(off.bias_estimate_rad_s, 0.0)


def test_reset_with_a_quaternion_continues_from_it_heading_included():
    q = quaternion_from_roll_pitch(10.0, 20.0, yaw_deg=50.0)
    f = VQFFilter()
    f.reset(q, last_time_s=0.0)
    out = f.process(static_block(0.01 + np.arange(200) * 0.01, 10.0, 20.0)).quat
    assert np.max(quat.angle_between(out, q)) < np.radians(0.01)


def test_warm_up_leaves_the_state_alone():
    stream = wobble()
    half = len(stream) // 2
    plain = VQFFilter()
    expected = run(plain, [piece(stream, 0, half), piece(stream, half, len(stream))])
    warmed = VQFFilter()
    warmed.warm_up()
    first = warmed.process(piece(stream, 0, half)).quat
    warmed.warm_up()
    second = warmed.process(piece(stream, half, len(stream))).quat
    np.testing.assert_array_equal(np.concatenate([first, second]), expected)


def test_without_the_package_the_module_imports_and_creating_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "vqf", None)  # makes `import vqf` fail
    spec = importlib.util.spec_from_file_location("vqf_filter_without_vqf", vqf_filter.__file__)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert not module.VQF_AVAILABLE
    with pytest.raises(ImportError, match=r"needs the 'vqf' package: pip install vqf"):
        module.VQFFilter()
    with pytest.raises(ValueError):  # what the GUI worker reports instead of crashing
        module.VQFFilter()
