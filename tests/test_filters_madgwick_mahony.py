"""Gyro integration, Madgwick and Mahony: against the ``ahrs`` package, known poses, continuity.

Test data come from the simulator's scenarios (analytic orientation and body rate, no GUI), or
from the simulated device itself. The ``ahrs`` package (a test-only dependency) is the
independent reference; its quirks and how they are matched are noted at each comparison.
"""

from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.filters.base import OrientationFilter
from app.core.filters.gyro_integration import GyroIntegration
from app.core.filters.madgwick import MadgwickFilter
from app.core.filters.mahony import MahonyFilter
from app.core.orientation import (
    angles_from_up,
    inclination_error_deg,
    quaternion_from_roll_pitch,
    up_in_sensor_frame,
)
from app.core.samples import SampleBlock, convert_raw_block
from drivers.registry import open_device
from drivers.sim.scenarios import SCENARIOS

ahrs_filters = pytest.importorskip("ahrs.filters")

G = 9.80665
FILTER_CLASSES = (GyroIntegration, MadgwickFilter, MahonyFilter)
FUSION_CLASSES = (MadgwickFilter, MahonyFilter)


def make_block(t, accel, gyro=None, gap=None) -> SampleBlock:
    t = np.asarray(t, dtype=float)
    n = len(t)
    accel = np.broadcast_to(np.asarray(accel, dtype=float), (n, 3)).copy()
    gyro = np.zeros((n, 3)) if gyro is None else np.broadcast_to(gyro, (n, 3)).astype(float)
    gap = np.zeros(n, bool) if gap is None else np.asarray(gap, bool)
    return SampleBlock(t, accel, gyro, np.full(n, 25.0), gap)


def accel_for(q: np.ndarray) -> np.ndarray:
    """What an ideal accelerometer at rest reads at sensor-to-earth attitude ``q``."""
    return up_in_sensor_frame(q) * G


def scenario_data(name: str, t: np.ndarray, gyro_bias=(0.0, 0.0, 0.0), seed: int = 3, **params):
    """(true quaternions, specific force, gyro) of a simulator scenario at times ``t``."""
    motion = SCENARIOS[name](np.random.default_rng(seed), **params).motion(t)
    q = motion.orientation_quat
    accel = accel_for(q) + quat.rotate_inverse(q, motion.linear_accel_m_s2)
    gyro = motion.angular_rate_rad_s + np.asarray(gyro_bias)
    return q, accel, gyro


def same_sign_as(reference: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``q`` with each row's sign flipped to match ``reference`` (q and -q are one rotation)."""
    return q * np.sign(np.sum(q * reference, axis=-1, keepdims=True))


def slice_block(block: SampleBlock, start: int, stop: int) -> SampleBlock:
    return SampleBlock(
        block.t_s[start:stop], block.accel_m_s2[start:stop], block.gyro_rad_s[start:stop],
        block.temp_degc[start:stop], block.gap[start:stop],
    )


def run_from(f: OrientationFilter, q0: np.ndarray, block: SampleBlock, dt: float | None = None):
    """Start ``f`` at ``q0`` one step (``dt``, else the block's first) before the block, and run.

    So the first sample is an ordinary update, not a start from the accelerometer.
    """
    step = float(block.t_s[1] - block.t_s[0]) if dt is None else dt
    f.reset(q0, last_time_s=float(block.t_s[0]) - step)
    return f.process(block).quat


# -- the ahrs package as the reference ---------------------------------------------------------
# ahrs.filters.Madgwick/Mahony run Q[t] = update(Q[t-1], gyr[t], acc[t]) from Q[0] = q0 with a
# fixed Dt. Both return q unchanged, skipping the accelerometer too, when the gyro sample is
# exactly zero; the wobble data below never is (asserted). Their quaternion is ours: f and v are
# R(q)^T e_z, the body rate multiplies on the right. They do not force w >= 0; we do, hence
# same_sign_as. Everything else is the same arithmetic in a different order, so what remains is
# rounding: ~1e-15 per update (checked to 1e-12), ~2e-14 over 3072 samples where the trajectory
# is well conditioned (checked to 1e-9).
DT = 1.0 / 256.0  # a power of two: t = k * DT and its differences are exact


@pytest.fixture(scope="module")
def wobble():
    """12 s of hand-held wobble (8 deg tremor, 0.2 m/s^2 shake) with a gyro bias, 256 Hz."""
    t = np.arange(1, 3073) * DT
    q_true, accel, gyro = scenario_data(
        "wobble", t, gyro_bias=(0.01, -0.02, 0.015), amplitude=8.0, shake=0.2
    )
    assert np.all(np.linalg.norm(gyro, axis=1) > 0.0)
    # Start 40 deg off (36 deg of it in tilt, the rest heading), so the correction matters.
    q0 = quat.multiply(q_true[0], quat.from_axis_angle([1.0, 2.0, 0.5], np.radians(40.0)))
    return make_block(t, accel, gyro), q_true, q0


def ahrs_reference(cls, block: SampleBlock, q0: np.ndarray, **gains) -> tuple[np.ndarray, object]:
    # Row 0 is a placeholder: ahrs starts at Q[0] = q0 and updates from row 1 on.
    gyr = np.vstack([block.gyro_rad_s[:1], block.gyro_rad_s])
    acc = np.vstack([block.accel_m_s2[:1], block.accel_m_s2])
    ref = cls(gyr=gyr, acc=acc, q0=q0, Dt=DT, **gains)
    return ref.Q[1:], ref


@pytest.mark.parametrize("beta", [0.041, 0.5, 3.0])
def test_each_madgwick_update_matches_ahrs(wobble, beta):
    """One update at a time, each from ahrs's previous quaternion."""
    block, _, q0 = wobble
    expected, _ = ahrs_reference(ahrs_filters.Madgwick, block, q0, gain=beta)
    previous = np.vstack([q0, expected[:-1]])
    f = MadgwickFilter(beta=beta)
    ours = np.empty_like(expected)
    for k in range(len(block)):
        ours[k] = run_from(f, previous[k], slice_block(block, k, k + 1), DT)[0]
    np.testing.assert_allclose(ours, same_sign_as(ours, expected), rtol=0, atol=1e-12)


def test_a_madgwick_run_matches_ahrs_while_its_gradient_is_well_conditioned(wobble):
    """The whole trajectory, as long as the step direction J^T f / |J^T f| is well defined.

    Once the estimate sits within about beta dt of the accelerometer's answer, |f| becomes tiny
    and the unit step direction amplifies rounding (1e-16) by about 1 / |f| at every sample:
    with beta = 0.5 here two correct implementations part by 3e-3 after 500 samples. That is
    the algorithm's sliding-mode chatter, not a difference in the equations (tested above).
    """
    block, q_true, q0 = wobble
    beta = 0.041
    ours = run_from(MadgwickFilter(beta=beta), q0, block)
    expected, _ = ahrs_reference(ahrs_filters.Madgwick, block, q0, gain=beta)
    up = block.accel_m_s2 / np.linalg.norm(block.accel_m_s2, axis=1, keepdims=True)
    f_norm = np.linalg.norm(up_in_sensor_frame(np.vstack([q0, expected[:-1]])) - up, axis=1)
    assert f_norm.min() > 1e-4  # the precondition
    np.testing.assert_allclose(ours, same_sign_as(ours, expected), rtol=0, atol=1e-9)
    # Not a trivial agreement: the tilt started 36 deg off and was pulled in at up to 2 beta
    # rad/s (4.7 deg/s); the shake still tilts the accelerometer by up to 4 deg.
    error = inclination_error_deg(ours, q_true)
    assert error[0] > 30.0
    assert error[-256:].max() < 3.0


def test_mahony_matches_ahrs_with_the_first_order_step(wobble):
    """ahrs integrates q + 0.5 q (0, w) dt like Mahony's code: our exact_integration=False."""
    block, q_true, q0 = wobble
    f = MahonyFilter(kp=1.0, ki=0.3, exact_integration=False)
    ours = run_from(f, q0, block)
    expected, ref = ahrs_reference(ahrs_filters.Mahony, block, q0, k_P=1.0, k_I=0.3)
    np.testing.assert_allclose(ours, same_sign_as(ours, expected), rtol=0, atol=1e-9)
    # ahrs keeps b = -ki * integral(e dt), the bias estimate, exactly as we do.
    np.testing.assert_allclose(f.gyro_bias_rad_s, ref.b, rtol=0, atol=1e-9)
    error = inclination_error_deg(ours, q_true)
    assert error[0] > 30.0
    assert error[-256:].max() < 3.0


def test_mahony_exact_step_differs_from_ahrs_only_at_third_order(wobble):
    """With the exact exponential, each step differs from Euler by about |w dt|^3 / 12 rad."""
    block, _, q0 = wobble
    ours = run_from(MahonyFilter(kp=1.0, ki=0.3), q0, block)
    expected, _ = ahrs_reference(ahrs_filters.Mahony, block, q0, k_P=1.0, k_I=0.3)
    difference = quat.angle_between(ours, expected)
    # The per-step differences add up at most (the feedback undoes the tilt part); the rates
    # here reach 4.6 rad/s. A genuine difference, far below anything a tilt meter shows.
    bound = np.sum(np.linalg.norm(block.gyro_rad_s * DT, axis=1) ** 3 / 12.0)
    assert 1e-8 < difference.max() < bound < 1e-3


def test_exact_integration_is_exact_and_euler_lags_by_the_predicted_amount():
    rate, dt, n = 20.0, 0.02, 50  # 0.4 rad a step: a fast spin at a low rate
    block = make_block(np.arange(1, n + 1) * dt, [0.0, 0.0, 0.0], [rate, 0.0, 0.0])
    start = quat.IDENTITY
    exact = run_from(MahonyFilter(kp=0.0, ki=0.0), start, block)
    euler = run_from(MahonyFilter(kp=0.0, ki=0.0, exact_integration=False), start, block)
    k = np.arange(1, n + 1)
    truth = quat.normalize(quat.from_axis_angle([1.0, 0.0, 0.0], rate * dt * k))
    np.testing.assert_allclose(exact, truth, atol=1e-12)
    # Euler then normalise rotates by 2 atan(w dt / 2) per step instead of w dt.
    euler_truth = quat.normalize(
        quat.from_axis_angle([1.0, 0.0, 0.0], 2.0 * np.arctan(rate * dt / 2.0) * k)
    )
    np.testing.assert_allclose(euler, euler_truth, atol=1e-12)


# -- known poses -------------------------------------------------------------------------------
POSES = [(0.0, 0.0), (30.0, -20.0), (180.0, 0.0), (-179.9, 0.0), (0.0, 89.9), (0.0, -89.9),
         (-120.0, 45.0)]


@pytest.mark.parametrize("cls", FILTER_CLASSES)
@pytest.mark.parametrize(("roll", "pitch"), POSES)
def test_the_first_sample_takes_the_accelerometer_tilt(cls, roll, pitch):
    truth = quaternion_from_roll_pitch(roll, pitch)
    out = cls().process(make_block([0.0, 0.01], accel_for(truth)))
    assert inclination_error_deg(out.quat[0], truth) < 1e-9
    if abs(pitch) < 89.0:  # roll is ill-conditioned next to +-90 deg pitch
        assert out.angles.roll_deg[0] == pytest.approx(roll, abs=1e-9)
    assert out.angles.pitch_deg[0] == pytest.approx(pitch, abs=1e-9)


@pytest.mark.parametrize("cls", FUSION_CLASSES)
@pytest.mark.parametrize(("roll", "pitch"), POSES)
def test_a_wrong_start_converges_to_a_static_pose(cls, roll, pitch):
    """From 15 deg off (about a horizontal axis), at rest, with an arbitrary heading."""
    dt, n = 0.01, 3000
    truth = quaternion_from_roll_pitch(roll, pitch, 37.0)
    start = quat.multiply(quat.from_axis_angle([1.0, 1.0, 0.0], np.radians(15.0)), truth)
    f = cls()
    out = run_from(f, start, make_block(np.arange(1, n + 1) * dt, accel_for(truth)))
    error = inclination_error_deg(out, truth)
    assert error[0] > 14.0
    if cls is MadgwickFilter:
        # The normalised gradient step moves the attitude by about 2 beta dt every sample:
        # the estimate chatters within that of the truth instead of settling.
        bound = np.degrees(2.0 * f.get_parameter("beta") * dt) + 1e-6
    else:
        bound = 1e-4  # 15 deg e^(-kp t) after 30 s, plus the ki loop: far below this
    assert error[-100:].max() < bound
    angles = angles_from_up(up_in_sensor_frame(out[-1]))
    assert float(angles.pitch_deg) == pytest.approx(pitch, abs=bound)
    if abs(pitch) < 89.0:  # a tilt error shows in roll magnified by up to 1 / cos(pitch)
        wrapped = (float(angles.roll_deg) - roll + 180.0) % 360.0 - 180.0
        assert abs(wrapped) < 2 * bound


def test_madgwick_rejects_a_gyro_bias_below_about_two_beta_and_drifts_above():
    """The unit step direction makes the correction a slew of at most 2 beta rad/s."""
    dt, n, beta = 0.01, 6000, 0.041
    t = np.arange(n) * dt
    below = MadgwickFilter(beta=beta).process(make_block(t, [0.0, 0.0, G], [0.07, 0.0, 0.0]))
    assert below.angles.tilt_deg[1000:].max() < 0.1  # chatter, biased a little by the bias
    above = MadgwickFilter(beta=beta).process(make_block(t, [0.0, 0.0, G], [0.09, 0.0, 0.0]))
    assert above.angles.tilt_deg[-1000:].min() > 10.0


# -- gyro integration --------------------------------------------------------------------------
def test_gyro_integration_drifts_linearly_with_a_constant_bias():
    bias, dt, n = np.radians(0.5), 0.01, 2001  # 0.5 deg/s about x, lying level and still
    t = np.arange(n) * dt
    out = GyroIntegration().process(make_block(t, [0.0, 0.0, G], [bias, 0.0, 0.0]))
    np.testing.assert_allclose(out.angles.roll_deg, np.degrees(bias) * t, rtol=0, atol=1e-9)
    # The thesis's alpha(t) = alpha(t-1) + G dt: the accelerometer is ignored after the start.
    assert out.angles.roll_deg[-1] == pytest.approx(10.0, abs=1e-9)


def test_gyro_integration_is_the_running_sum_of_rate_times_dt_about_a_fixed_axis():
    dt, n = 0.005, 4000
    t = np.arange(1, n + 1) * dt
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    rate = 2.0 * np.sin(1.3 * t) + 0.4  # rad/s, varying, about a fixed sensor axis
    start = quaternion_from_roll_pitch(20.0, -35.0, 10.0)
    block = make_block(t, accel_for(start), rate[:, None] * axis)
    out = run_from(GyroIntegration(), start, block)
    expected = quat.multiply(start, quat.from_axis_angle(axis, np.cumsum(rate * dt)))
    np.testing.assert_allclose(out, same_sign_as(out, expected), rtol=0, atol=1e-12)


def test_gyro_integration_without_the_accelerometer_starts_level_and_holds_across_gaps():
    f = GyroIntegration(init_from_accel=False)
    out = f.process(make_block([0.0, 0.1], accel_for(quaternion_from_roll_pitch(30.0, 0.0)),
                               [0.2, 0.0, 0.0]))
    np.testing.assert_allclose(out.quat[0], quat.IDENTITY, atol=1e-15)
    assert out.angles.roll_deg[1] == pytest.approx(np.degrees(0.02), abs=1e-9)
    later = f.process(make_block([9.0, 9.1], [0.0, G, 0.0], gap=[True, False]))
    np.testing.assert_allclose(later.quat, np.tile(out.quat[1], (2, 1)), atol=1e-15)


# -- Mahony's bias estimate --------------------------------------------------------------------
def test_mahony_learns_a_constant_gyro_bias_and_removes_the_tilt_error_it_causes():
    dt, n = 0.01, 6000  # 60 s lying level and still
    bias = np.array([0.02, -0.01, 0.0])  # rad/s; yaw bias is not observable from gravity
    block = make_block(np.arange(n) * dt, [0.0, 0.0, G], bias)
    with_ki = MahonyFilter(kp=1.0, ki=0.3)
    out = with_ki.process(block)
    np.testing.assert_allclose(with_ki.gyro_bias_rad_s, bias, atol=1e-8)
    assert out.angles.tilt_deg[-1] < 1e-6
    # Without the integral, the bias holds a steady error where kp sin(error) = |bias|.
    without = MahonyFilter(kp=1.0, ki=0.0)
    out = without.process(block)
    np.testing.assert_array_equal(without.gyro_bias_rad_s, np.zeros(3))
    steady = np.degrees(np.arcsin(np.linalg.norm(bias) / 1.0))
    assert out.angles.tilt_deg[-1] == pytest.approx(steady, rel=1e-6)


def test_mahony_bias_survives_blocks_gaps_and_parameter_changes_and_reset_clears_it():
    f = MahonyFilter(kp=2.0, ki=1.0)
    bias = np.array([0.0, 0.03, 0.0])
    f.process(make_block(np.arange(2000) * 0.01, [0.0, 0.0, G], bias))
    learnt = f.gyro_bias_rad_s
    assert learnt[1] == pytest.approx(0.03, abs=1e-4)
    f.set_parameter("ki", 0.0)  # freezes the estimate
    f.process(make_block([30.0, 30.01], [0.0, 0.0, G], bias, gap=[True, False]))
    np.testing.assert_array_equal(f.gyro_bias_rad_s, learnt)
    f.reset()
    np.testing.assert_array_equal(f.gyro_bias_rad_s, np.zeros(3))


# -- every filter: continuity, parameters, restarts, bad samples -------------------------------
def noisy_stream(n: int = 4000):
    """Wobble at 200 Hz with noise, a gap, a long step, and unusable accelerometer samples."""
    t = np.arange(n) * 0.005
    t[2500:] += 1.0  # a 1 s hole: a restart
    q, accel, gyro = scenario_data(
        "wobble", t, gyro_bias=(0.02, 0.0, -0.01), seed=5, shake=0.05
    )
    rng = np.random.default_rng(11)
    accel = accel + rng.normal(0.0, 0.05, accel.shape)
    gyro = gyro + rng.normal(0.0, 0.01, gyro.shape)
    accel[[100, 101, 2500]] = 0.0  # including the restart sample itself
    accel[300] = np.nan
    gyro[400] = [np.inf, 0.0, 0.0]
    gap = np.zeros(n, bool)
    gap[1200] = True
    return make_block(t, accel, gyro, gap), q


@pytest.mark.parametrize("cls", FILTER_CLASSES)
def test_a_stream_cut_into_blocks_anywhere_gives_the_same_output(cls):
    block, _ = noisy_stream()
    whole = cls().process(block).quat
    f = cls()
    cuts = [0, 1, 2, 3, 100, 101, 102, 777, 1200, 1201, 2499, 2500, 2501, 3999, len(block)]
    pieces = [f.process(slice_block(block, a, b)).quat for a, b in itertools.pairwise(cuts)]
    np.testing.assert_array_equal(np.concatenate(pieces), whole)


@pytest.mark.parametrize("cls", FILTER_CLASSES)
def test_bad_samples_give_no_nan_and_the_estimate_recovers(cls):
    block, q_true = noisy_stream()
    out = cls().process(block)
    assert np.all(np.isfinite(out.quat))
    assert np.all(np.isfinite(out.angles.roll_deg))
    error = inclination_error_deg(out.quat, q_true)
    # The restart sample (2500) had no accelerometer: the next sample (2501) restarts instead.
    assert error[2501] < 2.0
    if cls is not GyroIntegration:  # the fusion filters also stay close in between
        assert np.median(error[500:]) < 1.0


@pytest.mark.parametrize("cls", FILTER_CLASSES)
def test_a_zero_accelerometer_on_the_first_sample_defers_the_start(cls):
    truth = quaternion_from_roll_pitch(25.0, -10.0)
    accel = np.tile(accel_for(truth), (4, 1))
    accel[0] = 0.0
    f = cls()
    first = f.process(make_block([0.0], accel[:1]))
    np.testing.assert_allclose(first.quat[0], quat.IDENTITY, atol=1e-15)
    f.warm_up()  # must not clear the pending start
    rest = f.process(make_block([0.01, 0.02, 0.03], accel[1:]))  # pending across blocks
    assert inclination_error_deg(rest.quat[0], truth) < 1e-9


@pytest.mark.parametrize("cls", FILTER_CLASSES)
@pytest.mark.parametrize("how", ["gap", "long step", "time going back"])
def test_a_restart_takes_the_accelerometer_tilt_and_keeps_the_heading(cls, how):
    f = cls()
    level = [0.0, 0.0, G]
    # Turn 90 deg about the vertical, lying level: the heading is now 90 deg.
    f.process(make_block(np.arange(101) * 0.01, level, [0.0, 0.0, np.pi / 2]))
    t_next = {"gap": 1.01, "long step": 1.6, "time going back": 0.5}[how]
    truth = quaternion_from_roll_pitch(20.0, 0.0, 90.0)
    out = f.process(
        make_block([t_next, t_next + 0.01], accel_for(truth), gap=[how == "gap", False])
    )
    assert inclination_error_deg(out.quat[0], truth) < 1e-9
    # The heading too (Madgwick's first-order step turned a little less than 90 deg).
    assert quat.angle_between(out.quat[0], truth) < 1e-4


@pytest.mark.parametrize(
    ("cls", "name", "value"),
    [(GyroIntegration, "init_from_accel", False), (MadgwickFilter, "beta", 0.2),
     (MahonyFilter, "kp", 3.0), (MahonyFilter, "exact_integration", False)],
)
def test_changing_a_parameter_mid_stream_keeps_the_state(cls, name, value):
    block, _ = noisy_stream()
    f = cls()
    f.process(slice_block(block, 0, 600))
    before = f.quaternion
    state = {key: copy.copy(getattr(f, key)) for key in cls._extra_state}
    f.set_parameter(name, value)
    assert f.get_parameter(name) == value
    np.testing.assert_array_equal(f.quaternion, before)
    continued = f.process(slice_block(block, 600, 1000)).quat
    # The same as a filter with the new value started from the saved state.
    g = cls(**{name: value})
    g.reset(before, last_time_s=float(block.t_s[599]))
    for key, saved in state.items():
        setattr(g, key, saved)
    np.testing.assert_array_equal(g.process(slice_block(block, 600, 1000)).quat, continued)


def test_parameter_schemas():
    for cls in FILTER_CLASSES:
        assert cls.name and cls.title and cls.description
    assert [GyroIntegration.name, MadgwickFilter.name, MahonyFilter.name] == [
        "gyro", "madgwick", "mahony"
    ]
    beta = MadgwickFilter.parameter_spec("beta")
    assert (beta.unit, beta.default, beta.minimum, beta.maximum) == ("rad/s", 0.041, 0.0, 10.0)
    assert MahonyFilter().parameter_values() == {
        "kp": 1.0, "ki": 0.3, "exact_integration": True, "magnetometer": True
    }
    with pytest.raises(ValueError, match="outside"):
        MadgwickFilter(beta=-0.1)


# -- the simulated device ----------------------------------------------------------------------
def test_every_filter_tracks_the_simulator_reference_within_its_discretisation_error():
    device = open_device("sim://slow-tilt?realtime=0&errors=0&noise=0&block=4096")
    try:
        blocks = [convert_raw_block(device.read(1.0)) for _ in range(3)]  # ~118 s at 104 Hz
    finally:
        device.close()
    dt = float(np.median(np.diff(blocks[0].t_s)))
    max_rate = max(np.linalg.norm(b.gyro_rad_s, axis=1).max() for b in blocks)
    # Each sample's rate is applied over the step before it: the attitude leads the truth by
    # up to max_rate * dt (0.11 deg here); quantisation adds a little.
    lead_deg = np.degrees(max_rate * dt) + 0.01
    for f in (GyroIntegration(), MadgwickFilter(), MahonyFilter()):
        errors = np.concatenate(
            [inclination_error_deg(f.process(b).quat, b.reference_quat) for b in blocks]
        )
        chatter = np.degrees(2 * f.get_parameter("beta") * dt) if f.name == "madgwick" else 0.0
        assert errors.max() < lead_deg + chatter, f.name
