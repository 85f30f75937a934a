"""The simulated LSM6DSOX: URL options, physics consistency, error model, timing, failures.

Expected values are derived from the model's parameters (drivers.lsm6dsox figures and the
device's ``unit_errors``), never typed in.
"""

from __future__ import annotations

import math
import re
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from app import __version__
from app.core import quaternion as quat
from app.core.orientation import angles_from_quaternion, up_in_sensor_frame
from app.core.samples import RawBlock
from drivers import lsm6dsox
from drivers.errors import DeviceClosedError, DeviceError, DeviceIOError, DeviceUrlError
from drivers.registry import available_devices, create_device
from drivers.sim.device import SimulatedDevice
from drivers.sim.error_model import MeasurementModel, RandomWalk, UnitErrors
from drivers.sim.scenarios import SCENARIOS, Tour

G = lsm6dsox.STANDARD_GRAVITY_M_S2


class FakeClock:
    """A wall clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def collect(device: SimulatedDevice, n: int) -> RawBlock:
    """Open (if needed) and read at least ``n`` samples in realtime=0 mode, as one block."""
    if not device.is_open:
        device.open()
    blocks: list[RawBlock] = []
    total = 0
    while total < n:
        block = device.read(0.0)
        assert block is not None
        blocks.append(block)
        total += len(block)

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(b, name) for b in blocks])

    return RawBlock(
        t_s=cat("t_s"),
        accel_raw=cat("accel_raw"),
        gyro_raw=cat("gyro_raw"),
        temp_raw=cat("temp_raw"),
        scale=blocks[0].scale,
        gap=cat("gap"),
        lost_samples=sum(b.lost_samples for b in blocks),
        reference_quat=cat("reference_quat"),
    )


def true_times(device: SimulatedDevice, block: RawBlock) -> np.ndarray:
    """True (physical) times of a block's samples: sample index / true rate."""
    index = np.rint(block.t_s * device.odr_hz)
    return index / device.true_odr_hz


def expected_readings(
    unit: UnitErrors, true: np.ndarray, temp_degc: np.ndarray, kind: str
) -> np.ndarray:
    """The documented model without noise: (1 + stc dT) (M @ true) + b + btc dT,
    with M = (I + diag(scale)) @ (I + cross-axis)."""
    d_t = (temp_degc - 25.0)[:, None]
    if kind == "accel":
        scale, cross = unit.accel_scale_error, unit.accel_cross_axis
        bias = unit.accel_bias_m_s2
        bias_tc, scale_tc = unit.accel_bias_tc_m_s2_per_degc, unit.accel_scale_tc_per_degc
    else:
        scale, cross = unit.gyro_scale_error, unit.gyro_cross_axis
        bias = unit.gyro_bias_rad_s
        bias_tc, scale_tc = unit.gyro_bias_tc_rad_s_per_degc, unit.gyro_scale_tc_per_degc
    assert np.all(np.diag(cross) == 0.0) and np.any(cross)
    matrix = (np.eye(3) + np.diag(scale)) @ (np.eye(3) + cross)
    return (1.0 + scale_tc * d_t) * (true @ matrix.T) + bias + bias_tc * d_t


def noise_rms(info_odr_hz: float, accel_fs_g: int) -> tuple[float, float]:
    """White-noise RMS per axis from the datasheet densities: density x sqrt(ODR / 2)."""
    accel_density = (
        lsm6dsox.ACCEL_NOISE_G_PER_SQRT_HZ_16G
        if accel_fs_g == 16
        else lsm6dsox.ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS
    )
    bandwidth = math.sqrt(info_odr_hz / 2.0)
    return (
        accel_density * G * bandwidth,
        math.radians(lsm6dsox.GYRO_NOISE_DPS_PER_SQRT_HZ) * bandwidth,
    )


def integrate_gyro(q0: np.ndarray, gyro_rad_s: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """Orientation after integrating body rates (trapezoid rule), one rotation per step."""
    mean_rate = 0.5 * (gyro_rad_s[1:] + gyro_rad_s[:-1])
    steps = quat.from_rotation_vector(mean_rate * dt_s[:, None])
    # The ordered product q0 * s0 * s1 * ..., taken pairwise (a tree) to stay vectorised.
    while len(steps) > 1:
        if len(steps) % 2:
            steps = np.vstack([steps, quat.IDENTITY])
        steps = quat.multiply(steps[0::2], steps[1::2])
    return quat.multiply(q0, steps[0])


# -- URL, discovery, identity ------------------------------------------------------------------
def test_discover_lists_every_scenario_and_each_opens() -> None:
    found = [d for d in available_devices() if d.kind == "simulator"]
    # Every scenario, then the interactive one with a magnetometer (issue 31).
    assert [d.url for d in found] == [
        *(f"sim://{name}" for name in SCENARIOS), "sim://interactive?mag=lis3mdl"]
    for descriptor in found:
        device = create_device(descriptor.url)
        assert isinstance(device, SimulatedDevice)
        chip = device.mag_chip
        label = "Simulated LSM6DSOX" + (f" + {chip.name}" if chip else "")
        assert descriptor.description.startswith(f"{label}: ")
        device = SimulatedDevice(descriptor.url, realtime=False, block=64)
        with device:
            info = device.info
            assert info is not None
            scenario = descriptor.url.removeprefix("sim://").partition("?")[0]
            assert scenario in info.name and info.extra["scenario"] == scenario
            assert (info.magnetometer is None) == (chip is None)
            assert info.sensor == "LSM6DSOX"
            assert info.firmware == f"simulator {__version__}"
            assert re.fullmatch(r"SIM-[0-9A-F]{24}", info.unique_id)
            block = device.read(1.0)
            assert block is not None and len(block) == 64
            assert block.accel_raw.shape == block.gyro_raw.shape == (64, 3)
            assert block.accel_raw.dtype == block.gyro_raw.dtype == np.int16
            assert block.temp_raw.dtype == np.int16 and block.reference_quat.shape == (64, 4)


def test_every_odr_and_full_scale_opens() -> None:
    for odr in lsm6dsox.ODR_LABELS_HZ.values():
        for accel_fs in lsm6dsox.ACCEL_MG_PER_LSB:
            for gyro_fs in lsm6dsox.GYRO_MDPS_PER_LSB:
                url = f"sim://static?odr={odr}&accel_fs={accel_fs}&gyro_fs={gyro_fs}&realtime=0"
                with SimulatedDevice(url, block=8) as device:
                    info = device.info
                    assert info.odr_nominal_hz == odr
                    assert (info.accel_fs_g, info.gyro_fs_dps) == (accel_fs, gyro_fs)
                    block = device.read(0.0)
                    assert block.scale.accel_m_s2_per_lsb == lsm6dsox.accel_m_s2_per_lsb(accel_fs)
                    assert block.scale.gyro_rad_s_per_lsb == lsm6dsox.gyro_rad_s_per_lsb(gyro_fs)


@pytest.mark.parametrize("asked", [1.0, 100.0, 150.0, 3000.0, 7000.0, 8000.0])
def test_odr_snaps_to_nearest_chip_rate(asked: float) -> None:
    rates = list(lsm6dsox.ODR_LABELS_HZ.values())
    nearest = min(rates, key=lambda r: abs(r - asked))
    assert SimulatedDevice(f"sim://static?odr={asked}").options.odr_nominal_hz == nearest


@pytest.mark.parametrize("asked", ["0.5", "8001", "1e6", "1e9", "1e300", "9" * 400])
def test_an_odr_far_from_any_chip_rate_is_refused_not_clamped(asked: str) -> None:
    """Issue 36: odr=1e9 used to become 6667 Hz without a word."""
    with pytest.raises(DeviceUrlError, match=r"odr=.*(outside the LSM6DSOX's rates|finite)"):
        SimulatedDevice(f"sim://static?odr={asked}")


@pytest.mark.parametrize(
    ("url", "words"),
    [
        ("sim://static?odr=fast", ["odr", "fast", "not a number"]),
        ("sim://static?odr=-5", ["odr", "positive"]),
        ("sim://static?accel_fs=3", ["accel_fs", "2, 4, 8, 16"]),
        ("sim://static?gyro_fs=300", ["gyro_fs", "125, 250, 500, 1000, 2000"]),
        ("sim://static?colour=red", ["colour", "allowed", "odr", "roll"]),
        ("sim://static?jitter=1", ["jitter", "allowed", "yaw"]),
        ("sim://nowhere", ["nowhere", ", ".join(SCENARIOS)]),
        ("sim://static?seed=-1", ["seed", "-1"]),
        ("sim://static?seed=1.5", ["seed", "whole number"]),
        ("sim://static?realtime=maybe", ["realtime", "maybe", "1 or 0"]),
        ("sim://static?block=0", ["block", "0"]),
        ("sim://static?fail_after=0", ["fail_after", "positive"]),
        ("sim://static?roll=500", ["roll", "500", "range"]),
        ("sim://interactive?jitter=2", ["jitter", "1 or 0"]),
        ("sim://strokes?strokes=2.5", ["strokes", "whole number"]),
        ("sim://static?odr=", ["odr", "needs a value"]),
        ("sim://static?odr=104&odr=208", ["odr", "twice"]),
    ],
)
def test_bad_url_options_name_the_problem(url: str, words: list[str]) -> None:
    with pytest.raises(DeviceUrlError) as caught:
        create_device(url)
    for word in words:
        assert word in str(caught.value)


def test_keyword_overrides_win_over_the_url() -> None:
    device = SimulatedDevice("sim://wobble?odr=104&seed=3", odr=833, seed=5, realtime=False)
    assert device.options.odr_nominal_hz == 833.0
    assert device.options.seed == 5 and not device.options.realtime
    with pytest.raises(DeviceUrlError, match="accel_fs"):
        SimulatedDevice("sim://wobble", accel_fs=3)


def test_same_seed_is_the_same_unit_and_stream() -> None:
    a = SimulatedDevice("sim://wobble?seed=3&realtime=0")
    b = SimulatedDevice("sim://wobble?seed=3&realtime=0&block=1000")
    c = SimulatedDevice("sim://wobble?seed=4&realtime=0")
    assert a.unique_id == b.unique_id != c.unique_id
    assert a.unit_errors.as_dict() == b.unit_errors.as_dict()
    assert not np.allclose(a.unit_errors.accel_bias_m_s2, c.unit_errors.accel_bias_m_s2)
    assert a.unit_errors.as_dict() != c.unit_errors.as_dict()
    # Same seed: the same data, however the stream is cut into blocks.
    n = 3000
    ra, rb, rc = collect(a, n), collect(b, n), collect(c, n)
    assert np.array_equal(ra.accel_raw[:n], rb.accel_raw[:n])
    assert np.array_equal(ra.gyro_raw[:n], rb.gyro_raw[:n])
    assert np.array_equal(ra.reference_quat[:n], rb.reference_quat[:n])
    assert not np.array_equal(ra.accel_raw[:n], rc.accel_raw[:n])


def test_errors_off_gives_an_ideal_unit_with_the_same_id() -> None:
    real = SimulatedDevice("sim://static?seed=9")
    ideal = SimulatedDevice("sim://static?seed=9&errors=0")
    assert ideal.unique_id == real.unique_id
    assert np.array_equal(ideal.unit_errors.accel_matrix, np.eye(3))
    assert not np.any(ideal.unit_errors.gyro_bias_rad_s)
    # The label is 104 Hz; an ideal chip runs at 6666.67 / 64 = 104.17 Hz, no trim, no residual.
    assert ideal.options.odr_nominal_hz == 104.0
    assert ideal.odr_hz == ideal.true_odr_hz == pytest.approx(20000 / 3 / 64, rel=1e-15)
    assert np.any(real.unit_errors.accel_bias_m_s2)


# -- noise, quantisation, error model ----------------------------------------------------------
@pytest.mark.parametrize(("errors", "accel_fs", "odr"), [(0, 4, 104), (1, 4, 1667), (1, 16, 416)])
def test_white_noise_matches_the_datasheet_density(errors: int, accel_fs: int, odr: int) -> None:
    url = f"sim://static?roll=10&pitch=-20&errors={errors}&accel_fs={accel_fs}&odr={odr}"
    device = SimulatedDevice(url, realtime=False, block=4096, seed=11)
    block = collect(device, 16384)
    accel_rms, gyro_rms = noise_rms(device.info.odr_hz, accel_fs)
    for raw, rms, lsb in (
        (block.accel_raw, accel_rms, block.scale.accel_m_s2_per_lsb),
        (block.gyro_raw, gyro_rms, block.scale.gyro_rad_s_per_lsb),
    ):
        # Differences remove the constant truth and slow drifts; quantisation adds lsb^2/12.
        measured = np.std(np.diff(raw.astype(np.float64) * lsb, axis=0), axis=0) / math.sqrt(2)
        expected = math.sqrt(rms**2 + lsb**2 / 12.0)
        np.testing.assert_allclose(measured, expected, rtol=0.04)


def test_noise_off_leaves_only_quantisation() -> None:
    device = SimulatedDevice("sim://static?roll=10&noise=0&errors=0&realtime=0", block=512)
    block = collect(device, 512)
    assert np.all(block.accel_raw == block.accel_raw[0])
    assert np.all(block.gyro_raw == 0)


@pytest.mark.parametrize("scenario", ["tour?hold=0.5&transition=1", "static?roll=30&pitch=-50"])
def test_readings_follow_the_unit_error_model(scenario: str) -> None:
    url = f"sim://{scenario}&seed=7&odr=416&gyro_fs=500&realtime=0"
    device = SimulatedDevice(url, block=4096)
    block = collect(device, 4 * 4096)
    unit = device.unit_errors
    t_true = true_times(device, block)
    temp = unit.temperature_degc(t_true)
    np.testing.assert_allclose(block.temp_raw / 256.0 + 25.0, temp, atol=1.0 / 512 + 1e-12)
    motion = device.scenario.motion(t_true)
    np.testing.assert_allclose(motion.orientation_quat, block.reference_quat, atol=1e-12)
    force = quat.rotate_inverse(
        motion.orientation_quat, motion.linear_accel_m_s2 + np.array([0.0, 0.0, G])
    )
    accel_rms, gyro_rms = noise_rms(device.info.odr_hz, device.options.accel_fs_g)
    n = len(block)
    duration = t_true[-1]
    for kind, raw, lsb, truth, rms, walk in (
        (
            "accel",
            block.accel_raw,
            block.scale.accel_m_s2_per_lsb,
            force,
            accel_rms,
            unit.accel_bias_walk_m_s2_per_sqrt_s,
        ),
        (
            "gyro",
            block.gyro_raw,
            block.scale.gyro_rad_s_per_lsb,
            motion.angular_rate_rad_s,
            gyro_rms,
            unit.gyro_bias_walk_rad_s_per_sqrt_s,
        ),
    ):
        measured = raw * lsb
        residual = measured - expected_readings(unit, truth, temp, kind)
        # Mean within 5 sigma of the noise's standard error plus the random walk's reach.
        tolerance = 5.0 * rms / math.sqrt(n) + 5.0 * walk * math.sqrt(duration) + 0.05 * lsb
        assert np.all(np.abs(residual.mean(axis=0)) < tolerance), kind
        np.testing.assert_allclose(residual.std(axis=0), math.sqrt(rms**2 + lsb**2 / 12), rtol=0.05)
        # ... and the errors are large enough that an ideal model would fail that test.
        ideal_residual = measured - truth
        assert np.any(np.abs(ideal_residual.mean(axis=0)) > 20 * tolerance), kind


def test_measurement_model_applies_temperature_terms_and_random_walk() -> None:
    # Exaggerated random walks so that they span many LSB in a short record.
    unit = replace(
        UnitErrors.draw(5),
        accel_bias_walk_m_s2_per_sqrt_s=0.05,
        gyro_bias_walk_rad_s_per_sqrt_s=0.01,
    )
    model = MeasurementModel(unit, 8, 1000, 104.0, white_noise=False)
    rng = np.random.default_rng(0)
    n = 640
    force = rng.uniform(-3.0 * G, 3.0 * G, (n, 3))
    rate = rng.uniform(-5.0, 5.0, (n, 3))
    temp = np.linspace(-20.0, 70.0, n)
    accel, gyro = model.measure(0, force, rate, temp)
    for raw, truth, kind, lsb, walk in (
        (accel, force, "accel", model.accel_lsb_m_s2, model.accel_walk),
        (gyro, rate, "gyro", model.gyro_lsb_rad_s, model.gyro_walk),
    ):
        expected = expected_readings(unit, truth, temp, kind) + walk.values(0, n)
        assert np.all(np.abs(raw - expected / lsb) <= 0.5 + 1e-6), kind
        # Each term matters: leaving one out moves some readings by many LSB.
        at_25 = expected_readings(unit, truth, np.full(n, 25.0), kind)
        no_scale_tc = expected_readings(
            replace(unit, accel_scale_tc_per_degc=np.zeros(3), gyro_scale_tc_per_degc=np.zeros(3)),
            truth,
            temp,
            kind,
        )
        for partial in (at_25, no_scale_tc, expected - walk.values(0, n)):
            assert np.max(np.abs(partial - expected)) > 3 * lsb, kind


def test_random_walk_grows_like_the_square_root_of_time() -> None:
    sigma = 1e-3
    knot = RandomWalk.KNOT
    n = 50 * knot
    ends = np.array(
        [RandomWalk(sigma, np.random.default_rng(k)).values(0, n + 1)[-1] for k in range(1000)]
    )
    np.testing.assert_allclose(ends.std(axis=0), sigma * math.sqrt(n), rtol=0.08)
    np.testing.assert_allclose(ends.mean(axis=0), 0.0, atol=5 * sigma * math.sqrt(n / 3000))
    # Cut into blocks or not, the walk is the same (to rounding).
    whole = RandomWalk(sigma, np.random.default_rng(1)).values(0, 1000)
    cut = RandomWalk(sigma, np.random.default_rng(1))
    parts = np.vstack([cut.values(0, 130), cut.values(130, 1), cut.values(131, 869)])
    np.testing.assert_allclose(whole, parts, rtol=0, atol=1e-15)
    # Jumping ahead (lost samples) continues the walk.
    jumped = cut.values(100_000, 10)
    assert np.all(np.isfinite(jumped)) and not np.allclose(jumped, parts[-1])


def test_quantisation_and_saturation_at_2g() -> None:
    url = "sim://strokes?g=3&accel_fs=2&errors=0&noise=0&realtime=0&odr=833"
    device = SimulatedDevice(url, block=2048)
    block = collect(device, 4096)
    lsb = lsm6dsox.accel_m_s2_per_lsb(2)
    assert block.scale.accel_m_s2_per_lsb == lsb
    motion = device.scenario.motion(true_times(device, block))
    force = quat.rotate_inverse(
        motion.orientation_quat, motion.linear_accel_m_s2 + np.array([0.0, 0.0, G])
    )
    expected = np.clip(np.rint(force / lsb), -32768, 32767)
    np.testing.assert_array_equal(block.accel_raw, expected)
    over = np.abs(force) > 32767 * lsb
    assert over.sum() > 10, "the scenario must exceed +-2 g"
    assert np.all(np.abs(block.accel_raw[over].astype(int)) >= 32767)
    assert block.accel_raw.max() == 32767 and block.accel_raw.min() == -32768


def test_gyro_quantisation_is_to_the_lsb_of_the_full_scale() -> None:
    device = SimulatedDevice("sim://wobble?errors=0&noise=0&realtime=0&gyro_fs=125", block=2048)
    block = collect(device, 2048)
    rate = device.scenario.motion(true_times(device, block)).angular_rate_rad_s
    lsb = lsm6dsox.gyro_rad_s_per_lsb(125)
    np.testing.assert_array_equal(block.gyro_raw, np.rint(rate / lsb))


# -- clock -------------------------------------------------------------------------------------
def _seed_with_trim() -> int:
    return next(
        s
        for s in range(1, 100)
        if UnitErrors.draw(s).freq_fine != 0 and UnitErrors.draw(s).clock_residual != 0
    )


def test_trimmed_odr_is_reported_and_sets_the_timestamps() -> None:
    seed = _seed_with_trim()
    unit = UnitErrors.draw(seed)
    device = SimulatedDevice(f"sim://static?odr=208&seed={seed}&realtime=0", block=1000)
    info = device.open()
    trimmed = 20000 / 3 / 32 * (1.0 + lsm6dsox.FREQ_FINE_STEP * unit.freq_fine)  # "208" = 208.33
    assert info.odr_nominal_hz == 208.0
    assert info.odr_hz == pytest.approx(trimmed, rel=1e-12) and info.odr_hz != 208.0
    block = collect(device, 2000)
    np.testing.assert_allclose(np.diff(block.t_s), 1.0 / info.odr_hz, rtol=1e-9)
    assert block.t_s[0] == 0.0


def test_an_ideal_chip_at_12_5_hz_reports_and_produces_13_02_hz() -> None:
    device = SimulatedDevice("sim://static?odr=12.5&errors=0&realtime=0", block=100)
    info = device.open()
    assert info.odr_nominal_hz == 12.5  # the datasheet's label, for people
    assert info.odr_hz == pytest.approx(13.0208, abs=1e-4)  # 6666.67 Hz / 512
    block = collect(device, 200)
    rate = (len(block.t_s) - 1) / (block.t_s[-1] - block.t_s[0])
    assert rate == pytest.approx(20000 / 3 / 512, rel=1e-9)
    device.close()


def test_realtime_pacing_follows_the_true_clock() -> None:
    seed = _seed_with_trim()
    clock = FakeClock()
    device = SimulatedDevice(f"sim://static?odr=833&seed={seed}", clock=clock)
    info = device.open()
    true_rate = info.odr_hz * (1.0 + device.unit_errors.clock_residual)
    assert device.true_odr_hz == pytest.approx(true_rate, rel=1e-12)
    delivered = 0
    for elapsed in (0.1, 0.25, 0.5, 0.75):
        clock.now = 1000.0 + elapsed
        block = device.read(0.0)
        due = math.floor(elapsed * true_rate) + 1
        assert block is not None and len(block) == due - delivered
        assert block.t_s[0] == pytest.approx(delivered / info.odr_hz)
        assert not block.gap.any() and block.lost_samples == 0
        delivered = due
    # Device time runs off true (wall) time by the untrimmed residual.
    true_t = (due - 1) / true_rate
    assert block.t_s[-1] / true_t - 1.0 == pytest.approx(device.unit_errors.clock_residual)


def test_falling_behind_loses_data_like_a_full_fifo() -> None:
    clock = FakeClock()
    device = SimulatedDevice("sim://wobble?odr=416", clock=clock)
    device.open()
    clock.now += 0.1
    first = device.read(0.0)
    clock.now += 3.0
    late = device.read(0.0)
    capacity = round(device.true_odr_hz)  # about 1 s of samples
    assert len(late) == capacity
    due = math.floor(3.1 * device.true_odr_hz) + 1 - len(first)
    assert late.lost_samples == due - capacity
    assert late.gap[0] and not late.gap[1:].any()
    # The time axis stays real: it jumps over the lost samples.
    jump = late.t_s[0] - first.t_s[-1]
    assert jump == pytest.approx((late.lost_samples + 1) / device.odr_hz)
    clock.now += 0.05
    after = device.read(0.0)
    assert after.lost_samples == 0 and not after.gap.any()
    assert after.t_s[0] == pytest.approx(late.t_s[-1] + 1.0 / device.odr_hz)


# -- physical consistency ----------------------------------------------------------------------
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_analytic_rate_is_the_derivative_of_the_orientation(name: str) -> None:
    params = {"jitter": True} if name == "interactive" else {}
    scenario = SCENARIOS[name](np.random.default_rng(3), **params)
    if name == "interactive":
        scenario.set_target(1.0, quat.from_axis_angle(np.array([1.0, 1.0, 0.2]), 1.2))
        scenario.set_target(3.0, quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), -2.5))
    t = np.sort(np.random.default_rng(5).uniform(0.01, 30.0, 3000))
    analytic = scenario.angular_rate(t)
    numeric = scenario.numerical_angular_rate(t)
    # float32 trigonometry in the multi-sine scenarios leaves ~1e-4 rad/s in the difference
    # quotient; the rates themselves are up to ~1 rad/s.
    np.testing.assert_allclose(analytic, numeric, atol=2e-4, rtol=1e-5)
    norms = np.linalg.norm(scenario.orientation(t), axis=-1)
    np.testing.assert_allclose(norms, 1.0, atol=1e-12)


@pytest.mark.parametrize(
    ("scenario", "seconds"),
    [
        ("slow-tilt?roll_period=4&pitch_period=6", 6.0),
        ("tour?hold=0.3&transition=1", 5.0),
        ("wobble", 4.0),
        ("vibration?angular=1", 2.0),
        ("interactive?jitter=1", 3.0),
        ("translation", 4.0),
        ("handheld?level=0", 4.0),
    ],
)
def test_integrated_gyro_reproduces_the_reference_orientation(
    scenario: str, seconds: float
) -> None:
    device = SimulatedDevice(
        f"sim://{scenario}", errors=0, noise=0, odr=6667, gyro_fs=500, realtime=0, block=4096
    )
    device.open()
    if device.is_interactive:
        device.set_target_attitude(35.0, -20.0, 40.0)
    block = collect(device, round(seconds * device.odr_hz))
    ref = block.reference_quat
    gyro = block.gyro_raw * block.scale.gyro_rad_s_per_lsb
    q_end = integrate_gyro(ref[0], gyro, np.diff(block.t_s))
    turned = np.degrees(quat.angle_between(ref[0], ref[-1]))
    max_turn = np.degrees(np.max(quat.angle_between(ref[0], ref)))
    assert max_turn > 0.5, "the scenario must rotate for the test to mean something"
    # Quantisation (uniform, +-lsb/2 per sample) accumulates like a random walk.
    lsb_deg = math.degrees(block.scale.gyro_rad_s_per_lsb)
    tolerance = 6.0 * lsb_deg / math.sqrt(12) * math.sqrt(len(block)) / device.odr_hz + 1e-3
    error = np.degrees(quat.angle_between(q_end, ref[-1]))
    assert error < tolerance, f"turned {turned:.2f} deg, gyro integral off by {error:.2e} deg"


def test_accelerometer_at_rest_points_up() -> None:
    url = "sim://static?roll=-35&pitch=55&yaw=120&errors=0&realtime=0&odr=416"
    device = SimulatedDevice(url, block=4096)
    block = collect(device, 4096)
    mean = block.accel_raw.mean(axis=0) * block.scale.accel_m_s2_per_lsb
    up = up_in_sensor_frame(block.reference_quat[0])
    accel_rms, _ = noise_rms(device.odr_hz, device.options.accel_fs_g)
    tolerance_rad = 6.0 * accel_rms / math.sqrt(len(block)) / G
    angle = math.atan2(np.linalg.norm(np.cross(mean, up)), mean @ up)
    assert angle < tolerance_rad
    assert np.linalg.norm(mean) == pytest.approx(G, rel=1e-3)
    angles = angles_from_quaternion(block.reference_quat[0])
    assert (float(angles.roll_deg), float(angles.pitch_deg)) == pytest.approx((-35.0, 55.0))


def test_tour_visits_the_six_calibration_orientations() -> None:
    url = "sim://tour?hold=1&transition=0.5&errors=0&noise=0&realtime=0&odr=208"
    device = SimulatedDevice(url, block=4096)
    block = collect(device, round(6 * 1.5 * 208) + 1)
    t_true = true_times(device, block)
    face = device.scenario.face_at(t_true)
    accel = block.accel_raw * block.scale.accel_m_s2_per_lsb
    for index, label in enumerate(Tour.FACES):
        held = face == index
        assert held.sum() > 100, label
        axis = "xyz".index(label[1])
        direction = np.zeros(3)
        direction[axis] = 1.0 if label[0] == "+" else -1.0
        np.testing.assert_allclose(accel[held].mean(axis=0) / G, direction, atol=2e-3)
        np.testing.assert_allclose(
            up_in_sensor_frame(block.reference_quat[held]),
            np.tile(direction, (held.sum(), 1)),
            atol=1e-9,
        )
        assert np.all(block.gyro_raw[held] == 0), "held still: noise-free gyro reads 0"


# -- interactive -------------------------------------------------------------------------------
def test_interactive_target_is_reached_smoothly() -> None:
    device = SimulatedDevice("sim://interactive?realtime=0&odr=208&noise=0&errors=0", block=32)
    start = collect(device, 64)
    glide = device.set_target_attitude(20.0, -10.0)
    assert device.scenario.MIN_GLIDE_S <= glide <= device.scenario.MAX_GLIDE_S
    block = collect(device, round((glide + 0.5) * device.odr_hz))
    ref = np.vstack([start.reference_quat, block.reference_quat])
    # Smooth: no step between consecutive samples larger than the peak glide rate allows.
    steps = quat.angle_between(ref[1:], ref[:-1])
    total = quat.angle_between(ref[0], ref[-1])
    assert steps.max() < 2.0 * total / glide / device.odr_hz
    final = angles_from_quaternion(ref[-1])
    assert (float(final.roll_deg), float(final.pitch_deg)) == pytest.approx((20.0, -10.0))
    accel = block.accel_raw[-20:].mean(axis=0) * block.scale.accel_m_s2_per_lsb
    up = up_in_sensor_frame(ref[-1])
    angle = math.atan2(np.linalg.norm(np.cross(accel, up)), accel @ up)
    lsb_angle = block.scale.accel_m_s2_per_lsb / G
    assert angle < 2.0 * lsb_angle
    assert np.all(block.gyro_raw[-20:] == 0), "at rest after the glide"


def test_a_new_target_during_a_glide_keeps_the_rate_continuous() -> None:
    device = SimulatedDevice("sim://interactive", errors=0, noise=0, odr=833, realtime=0, block=8)
    device.open()
    device.set_target_attitude(30.0, 0.0)
    before = collect(device, round(0.15 * device.odr_hz))
    device.set_target_attitude(-10.0, 20.0)
    after = collect(device, 8)
    rate_before = before.gyro_raw[-1] * before.scale.gyro_rad_s_per_lsb
    rate_after = after.gyro_raw[0] * after.scale.gyro_rad_s_per_lsb
    speed = np.linalg.norm(rate_before)
    assert speed > math.radians(20.0), "mid-glide"
    assert np.linalg.norm(rate_after - rate_before) < 0.05 * speed


def test_targets_from_another_thread_keep_gyro_and_orientation_consistent() -> None:
    device = SimulatedDevice(
        "sim://interactive", errors=0, noise=0, odr=1667, gyro_fs=500, realtime=0, block=64
    )
    device.open()
    done = threading.Event()
    targets = [(30.0 * math.sin(k), 20.0 * math.cos(k)) for k in range(300)]

    def tilt() -> None:
        for roll, pitch in targets:
            device.set_target_attitude(roll, pitch)
        done.set()

    worker = threading.Thread(target=tilt)
    worker.start()
    blocks = []
    while not done.is_set() or len(blocks) < 20:
        blocks.append(device.read(0.0))
    worker.join()
    blocks.append(collect(device, round(device.scenario.MAX_GLIDE_S * device.odr_hz) + 1))
    t_s = np.concatenate([b.t_s for b in blocks])
    ref = np.vstack([b.reference_quat for b in blocks])
    gyro_raw = np.vstack([b.gyro_raw for b in blocks])
    assert np.abs(gyro_raw).max() < 32767, "no saturation"
    # A target slipped in at the wrong time would make the orientation jump without the
    # gyroscope seeing it; the integrated gyro would then miss the reference.
    scale = blocks[0].scale.gyro_rad_s_per_lsb
    q_end = integrate_gyro(ref[0], gyro_raw * scale, np.diff(t_s))
    lsb_deg = math.degrees(scale)
    tolerance = 6.0 * lsb_deg / math.sqrt(12) * math.sqrt(len(t_s)) / device.odr_hz + 1e-3
    assert np.degrees(quat.angle_between(q_end, ref[-1])) < tolerance
    final = angles_from_quaternion(ref[-1])
    assert (float(final.roll_deg), float(final.pitch_deg)) == pytest.approx(targets[-1])


def test_only_the_interactive_scenario_can_be_tilted() -> None:
    with pytest.raises(DeviceError, match="interactive"):
        SimulatedDevice("sim://static").set_target_attitude(1.0, 2.0)


# -- failures and realtime ---------------------------------------------------------------------
def test_fail_after_raises_like_an_unplugged_cable() -> None:
    device = SimulatedDevice("sim://wobble?fail_after=0.5&realtime=0&odr=104", block=16)
    device.open()
    delivered = []
    with pytest.raises(DeviceIOError, match="unplugged"):
        for _ in range(1000):
            delivered.append(device.read(0.0))
    t = np.concatenate([b.t_s for b in delivered])
    assert len(t) == math.ceil(0.5 * device.odr_hz) and t[-1] < 0.5
    with pytest.raises(DeviceIOError):
        device.read(0.0)
    device.close()


def test_fail_after_in_realtime_delivers_up_to_the_failure() -> None:
    clock = FakeClock()
    device = SimulatedDevice("sim://static?fail_after=0.3&odr=208", clock=clock)
    device.open()
    clock.now += 2.0
    block = device.read(0.0)
    assert len(block) == math.ceil(0.3 * device.odr_hz)
    with pytest.raises(DeviceIOError):
        device.read(0.0)


def test_realtime_read_returns_within_the_timeout_and_close_works() -> None:
    device = SimulatedDevice("sim://wobble?odr=833")
    device.open()
    started = time.monotonic()
    block = device.read(0.5)
    assert time.monotonic() - started < 0.5 + 0.2
    assert block is not None and len(block) >= 1 and block.t_s[0] == 0.0
    started = time.monotonic()
    quick = device.read(0.0)
    assert time.monotonic() - started < 0.1
    assert quick is None or len(quick) >= 1
    device.close()
    with pytest.raises(DeviceClosedError):
        device.read(0.1)
    device.close()


def test_realtime_read_returns_none_when_nothing_is_due() -> None:
    clock = FakeClock()
    device = SimulatedDevice("sim://static?odr=12.5", clock=clock)
    device.open()
    assert len(device.read(0.0)) == 1  # the sample at t = 0
    assert device.read(0.01) is None


def test_close_from_another_thread_interrupts_a_waiting_read() -> None:
    clock = FakeClock()
    device = SimulatedDevice("sim://static?odr=12.5", clock=clock)
    device.open()
    device.read(0.0)
    clock.now -= 10.0  # frozen 10 s before the next sample: a read would wait its full timeout
    closer = threading.Timer(0.05, device.close)
    started = time.monotonic()
    closer.start()
    assert device.read(5.0) is None
    assert time.monotonic() - started < 1.0
    closer.join()
    assert not device.is_open


def test_reopening_restarts_the_stream() -> None:
    device = SimulatedDevice("sim://wobble?realtime=0", block=128)
    first = collect(device, 128)
    device.close()
    again = collect(device, 128)
    assert np.array_equal(first.accel_raw, again.accel_raw)
    assert np.array_equal(first.t_s, again.t_s)


def test_speed_option_runs_the_device_clock_faster_than_the_wall_clock():
    now = [100.0]
    device = SimulatedDevice("sim://static?odr=104&speed=10", clock=lambda: now[0])
    device.open()
    try:
        now[0] += 0.5  # half a wall-clock second = five seconds of data
        total = 0
        while True:
            block = device.read(0.0)
            if block is None:
                break
            total += len(block)
            assert block.lost_samples == 0
        assert abs(total - 5 * device.odr_hz) <= 2
    finally:
        device.close()
    with pytest.raises(DeviceUrlError, match="speed"):
        SimulatedDevice("sim://static?speed=1000").open()


def test_a_simulator_url_without_a_scenario_starts_the_interactive_one():
    device = SimulatedDevice("sim://?odr=52")
    try:
        info = device.open()
        assert "interactive" in info.name and info.odr_nominal_hz == 52.0
        assert device.is_interactive
        assert len(device.read(1.0)) > 0
    finally:
        device.close()


def test_settling_models_the_turn_on_transient_and_the_discard_removes_it() -> None:
    url = "sim://static?odr=833&errors=0&noise=0&realtime=0"
    plain = collect(SimulatedDevice(url, block=200), 200)
    settling = collect(SimulatedDevice(url + "&settling=1", block=200), 200)
    skip = lsm6dsox.turn_on_discard(833)  # 5 accelerometer, 72 gyroscope samples
    accel_g = np.linalg.norm(settling.accel_raw, axis=1) * lsm6dsox.ACCEL_MG_PER_LSB[4] / 1e3
    gyro_dps = np.abs(settling.gyro_raw).max(axis=1) * lsm6dsox.GYRO_MDPS_PER_LSB[250] / 1e3
    assert accel_g[0] < 0.5 and gyro_dps[0] > 10.0  # the first samples are wrong ...
    assert np.all(gyro_dps[:skip - 2] > 0.1)        # ... for the whole settling figure
    # ... and after the discard count the stream is the chip's true output, sample for sample.
    np.testing.assert_array_equal(settling.accel_raw[skip:], plain.accel_raw[skip:])
    np.testing.assert_array_equal(settling.gyro_raw[skip:], plain.gyro_raw[skip:])
