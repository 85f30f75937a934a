"""The foundation filters: hand-computed cases, continuity across blocks, robustness."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_blocks import G, accel_for, block

from app.core.filters import FILTERS, create_filter
from app.core.filters.base import ParameterSpec
from app.core.orientation import (
    inclination_error_deg,
    quaternion_from_roll_pitch,
    up_in_sensor_frame,
)


def test_complementary_matches_the_thesis_formula_for_small_angles():
    """alpha(t) = K (alpha(t-1) + g dt) + (1 - K) alpha_acc, K = tau / (tau + dt)."""
    dt, tau = 0.01, 0.5
    k = tau / (tau + dt)
    gyro_x = np.radians(0.5)  # rad/s about x
    acc_roll = 0.2  # degrees, what the accelerometer says
    f = create_filter("complementary", tau_s=tau)
    n = 5
    out = f.process(block(np.arange(n) * dt, accel_for(acc_roll, 0.0), [gyro_x, 0, 0]))
    expected = [acc_roll]  # the first sample starts from the accelerometer
    for _ in range(n - 1):
        expected.append(k * (expected[-1] + np.degrees(gyro_x) * dt) + (1 - k) * acc_roll)
    np.testing.assert_allclose(out.angles.roll_deg, expected, atol=1e-6)


def test_complementary_converges_to_the_accelerometer_with_time_constant_tau():
    dt, tau = 0.001, 0.2
    f = create_filter("complementary", tau_s=tau)
    f.process(block([0.0], accel_for(0.0, 0.0)))
    t = np.arange(1, 2001) * dt
    out = f.process(block(t, accel_for(0.0, 10.0)))
    # After one tau, the estimate has covered 1 - 1/e of the step.
    at_tau = out.angles.pitch_deg[int(tau / dt) - 1]
    assert at_tau == pytest.approx(10.0 * (1 - np.exp(-1)), rel=0.01)
    assert out.angles.pitch_deg[-1] == pytest.approx(10.0, abs=1e-3)


@pytest.mark.parametrize(("roll", "pitch"), [(179.9, 0.0), (-179.9, 0.0), (0.0, 89.99), (120, 60)])
def test_complementary_holds_at_the_wrap_and_at_large_tilts(roll, pitch):
    f = create_filter("complementary", tau_s=0.1)
    t = np.arange(3000) * 0.002
    rng = np.random.default_rng(0)
    accel = accel_for(roll, pitch) + rng.normal(0, 0.02, (3000, 3))
    out = f.process(block(t, accel))
    assert np.all(np.isfinite(out.quat))
    truth = quaternion_from_roll_pitch(roll, pitch)
    assert inclination_error_deg(out.quat[-1], truth) < 0.2


def test_gyro_integration_tracks_rotation_between_blocks():
    dt = 0.01
    f = create_filter("complementary", tau_s=100.0)  # almost pure gyro
    f.process(block([0.0], accel_for(0.0, 0.0)))
    rate = np.radians(10.0)  # 10 deg/s about x for 2 s, in two blocks
    t = np.arange(1, 201) * dt
    first = f.process(block(t[:77], accel_for(0.0, 0.0), [rate, 0, 0]))
    second = f.process(block(t[77:], accel_for(0.0, 0.0), [rate, 0, 0]))
    roll = np.concatenate([first.angles.roll_deg, second.angles.roll_deg])
    # Pure integration would give 20 deg; the weak accelerometer pull removes a little.
    assert roll[-1] == pytest.approx(20.0, rel=0.02)
    assert np.all(np.diff(roll) > 0)


def test_a_gap_restarts_from_the_accelerometer():
    f = create_filter("complementary", tau_s=100.0)
    f.process(block(np.arange(10) * 0.01, accel_for(0.0, 0.0)))
    out = f.process(block([5.0, 5.01], accel_for(30.0, 0.0), gap=[True, False]))
    assert out.angles.roll_deg[0] == pytest.approx(30.0, abs=1e-9)


def test_accelerometer_moving_average_spans_blocks():
    f = create_filter("accel", average_samples=4)
    values = np.array([0.0, 0.0, 0.0, 0.0, 4.0, 4.0])
    accel = np.stack([values, np.zeros(6), np.full(6, G)], axis=1)
    a = f.process(block(np.arange(3) * 0.01, accel[:3]))
    b = f.process(block(np.arange(3, 6) * 0.01, accel[3:]))
    ax = np.concatenate(
        [up_in_sensor_frame(a.quat)[:, 0], up_in_sensor_frame(b.quat)[:, 0]]
    )
    mean_x = np.array([0, 0, 0, 0, 1, 2], float)
    expected = mean_x / np.hypot(mean_x, G)
    np.testing.assert_allclose(ax, expected, atol=1e-12)


def test_parameters_are_validated_and_changes_keep_the_state():
    f = create_filter("complementary")
    f.process(block(np.arange(100) * 0.01, accel_for(5.0, 0.0)))
    before = f.quaternion
    f.set_parameter("tau_s", 2.0)
    assert f.get_parameter("tau_s") == 2.0
    np.testing.assert_array_equal(f.quaternion, before)
    with pytest.raises(ValueError, match="outside"):
        f.set_parameter("tau_s", -1.0)
    with pytest.raises(KeyError, match="no parameter"):
        f.set_parameter("beta", 1.0)


@pytest.mark.parametrize("name", list(FILTERS))
def test_every_filter_has_a_complete_schema_and_handles_empty_blocks(name):
    cls = FILTERS[name]
    assert cls.title and cls.description
    for spec in cls.parameters:
        assert isinstance(spec, ParameterSpec)
        assert spec.minimum <= spec.default <= spec.maximum
        assert spec.help and spec.label
    out = create_filter(name).process(block(np.empty(0), np.empty((0, 3))))
    assert out.quat.shape == (0, 4)


def test_unknown_filter_names_are_reported():
    with pytest.raises(KeyError, match="available"):
        create_filter("nonsense")


def test_complementary_survives_non_finite_samples():
    f = create_filter("complementary")
    accel = np.tile(accel_for(5.0, 0.0), (10, 1))
    accel[3] = np.nan
    gyro = np.zeros((10, 3))
    gyro[6] = np.inf
    out = f.process(block(np.arange(10) * 0.01, accel, gyro))
    assert np.all(np.isfinite(out.quat))
    assert out.angles.roll_deg[-1] == pytest.approx(5.0, abs=0.01)


def test_warm_up_leaves_no_trace_in_the_filter_state():
    f = create_filter("accel", average_samples=4)
    f.warm_up()
    out = f.process(block([0.0], [G, 0.0, 0.0]))  # +x straight up
    assert out.angles.pitch_deg[0] == pytest.approx(90.0, abs=1e-9)
