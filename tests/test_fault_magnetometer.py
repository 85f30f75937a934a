"""Fault detection on the magnetometer's axes: stuck, dead, spike and saturation on its own,
slower samples (NaN rows between), no false alarm on a clean field, a magnet going by, held
values, or the BROAD trials' field."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.devices import DeviceInfo, MagnetometerInfo
from app.core.faults import FaultDetector, SensorSpec
from app.core.faults.magnetometer import MagnetometerCheck
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock
from tests.broad_trials import trial_path

ODR = 104.0
MAG_ODR = 26.0  # every 4th row
LSB_UT = 100.0 / 6842  # LIS3MDL at +-4 gauss
NOISE_UT = 0.32  # its RMS noise in ultra-high-performance mode


def clean_field(seconds: float = 20.0, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Times at the accelerometer's rate and a turning earth field (uT) with the LIS3MDL's
    noise and quantisation on every 4th row, NaN between."""
    rng = np.random.default_rng(seed)
    n = int(seconds * ODR)
    t = np.arange(n) / ODR
    heading = 0.8 * np.sin(2 * np.pi * 0.1 * t)  # slow turns, +-46 degrees
    field = np.column_stack([19.0 * np.sin(heading), 19.0 * np.cos(heading), np.full(n, -46.0)])
    field += rng.normal(0.0, NOISE_UT, field.shape)
    field = np.round(field / LSB_UT) * LSB_UT
    field[np.arange(n) % 4 != 0] = np.nan
    return t, field


def run(check: MagnetometerCheck, t: np.ndarray, mag: np.ndarray, block: int = 26,
        gap: np.ndarray | None = None, counts: np.ndarray | None = None):
    gap = np.zeros(len(t), bool) if gap is None else gap
    events = []
    for a in range(0, len(t), block):
        events += check.update(t[a:a + block], mag[a:a + block], gap[a:a + block],
                               None if counts is None else counts[a:a + block])
    return events


def lis3mdl() -> MagnetometerCheck:
    return MagnetometerCheck(range_ut=400.0, ut_per_lsb=LSB_UT, odr_hz=MAG_ODR)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_clean_field_raises_nothing(seed):
    t, mag = clean_field(seed=seed)
    assert run(lis3mdl(), t, mag) == []
    assert run(MagnetometerCheck(), t, mag) == []  # nothing known about the chip


def test_a_magnet_going_by_is_no_fault():
    t, mag = clean_field()
    # 150 uT on x rising and falling over 1.5 s: a field that builds up, not a spike.
    mag[:, 0] += 150.0 * np.exp(-0.5 * ((t - 10.0) / 0.3) ** 2)
    assert run(lis3mdl(), t, mag) == []


def test_held_values_between_samples_are_no_stuck_axis():
    t, mag = clean_field()
    rows = np.flatnonzero(np.isfinite(mag[:, 0]))
    held = mag.copy()
    for a, b in zip(rows, [*rows[1:], len(t)], strict=True):
        held[a:b] = mag[a]  # a source that repeats the last sample on the rows between
    assert run(MagnetometerCheck(), t, held) == []


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_a_stuck_axis_is_named(axis):
    t, mag = clean_field()
    frozen = (t >= 8.0) & np.isfinite(mag[:, axis])
    mag[frozen, axis] = mag[np.flatnonzero(frozen)[0], axis]
    events = run(lis3mdl(), t, mag)
    assert [(e.channel, e.kind) for e in events] == [(("mx", "my", "mz")[axis], "stuck")]
    assert 8.9 <= events[0].t <= 9.5  # after 1 s (26 samples)
    assert events[0].severity == "fault" and "frozen" in events[0].message


def test_a_dead_axis_and_a_silent_chip():
    t, mag = clean_field()
    mag[(t >= 5.0) & np.isfinite(mag[:, 1]), 1] = 0.0
    events = run(lis3mdl(), t, mag)
    assert [(e.channel, e.kind) for e in events] == [("my", "dead")]
    t, mag = clean_field()
    mag[t >= 12.0] = np.nan  # the chip stops delivering; the accelerometer goes on
    events = run(lis3mdl(), t, mag)
    assert [(e.channel, e.kind) for e in events] == [("mag", "dead")]
    assert 12.9 <= events[0].t <= 13.3 and "no magnetometer sample" in events[0].message


def test_a_spike_is_found_on_its_axis_at_its_time():
    t, mag = clean_field()
    row = np.flatnonzero(np.isfinite(mag[:, 2]) & (t >= 7.0))[0]
    mag[row, 2] += 15.0
    events = run(lis3mdl(), t, mag)
    assert [(e.channel, e.kind, e.t) for e in events] == [("mz", "spike", round(t[row], 6))]


def test_saturation_at_full_scale_and_at_the_chips_overflow():
    t, mag = clean_field()
    near = (t >= 4.0) & (t < 4.5)
    mag[near, 0] = np.where(np.isfinite(mag[near, 0]), 400.0, np.nan)  # a magnet on the chip
    events = run(lis3mdl(), t, mag)
    assert [(e.channel, e.kind, e.severity) for e in events] == [("mx", "saturation",
                                                                   "warning")]
    assert "±400 uT" in events[0].message
    # A chip whose range is not known: its raw count at the int16 limit still shows it.
    t, mag = clean_field()
    counts = np.round(mag / LSB_UT)
    counts[near & np.isfinite(counts[:, 1]), 1] = 32767
    mag[:, 1] = counts[:, 1] * LSB_UT
    events = run(MagnetometerCheck(ut_per_lsb=LSB_UT), t, mag, counts=counts)
    assert [(e.channel, e.kind) for e in events] == [("my", "saturation")]
    assert "overflow" in events[0].message


def test_lost_data_restart_the_runs():
    t, mag = clean_field()
    frozen = (t >= 8.0) & (t < 8.9) & np.isfinite(mag[:, 0])
    mag[frozen, 0] = 30.0
    after = (t >= 8.9) & (t < 9.6) & np.isfinite(mag[:, 0])
    mag[after, 0] = 30.0  # 1.6 s of one value, but data were lost at 8.9 s
    gap = np.zeros(len(t), bool)
    gap[np.searchsorted(t, 8.9)] = True
    assert run(lis3mdl(), t, mag, gap=gap) == []


def test_the_detector_reports_the_magnetometer_with_the_other_channels():
    t, mag = clean_field(10.0)
    mag[(t >= 3.0) & np.isfinite(mag[:, 0]), 0] = 0.0
    n = len(t)
    info = DeviceInfo(url="sim://x", name="sim", unique_id="1", sensor="LSM6DSOX",
                      odr_hz=ODR, odr_nominal_hz=ODR,
                      accel_fs_g=4, gyro_fs_dps=250,
                      magnetometer=MagnetometerInfo("LIS3MDL", MAG_ODR, 400.0, LSB_UT))
    spec = SensorSpec.from_device_info(info)
    assert (spec.mag_range_ut, spec.mag_ut_per_lsb, spec.mag_odr_hz) == (400.0, LSB_UT, MAG_ODR)
    detector = FaultDetector(spec)
    rng = np.random.default_rng(5)
    accel = np.array([0, 0, STANDARD_GRAVITY_M_S2]) + rng.normal(0, 0.01, (n, 3))
    gyro = rng.normal(0, math.radians(0.05), (n, 3))
    events = []
    for a in range(0, n, 26):
        s = slice(a, a + 26)
        events += detector.update(SampleBlock(t[s], accel[s], gyro[s], np.full(len(t[s]), 25.0),
                                              np.zeros(len(t[s]), bool), None, mag[s]))
    assert [(e.channel, e.kind) for e in events] == [("mx", "dead")]
    health = detector.health()
    assert health["mx"] == "fault" and health["my"] == "ok" and health["ax"] == "ok"
    detector.reset()
    assert "mx" not in detector.health()  # no field seen since


@pytest.mark.parametrize("stem", ["06_undisturbed_fast_rotation_A",
                                  "28_disturbed_stationary_magnet_A"])
def test_broad_trials_field_raises_no_magnetometer_fault(stem):
    from app.services.diagnosis import Diagnosis, diagnose_events

    result = Diagnosis()
    events = list(diagnose_events(str(trial_path(stem)), seconds=40.0, result=result))
    assert "mx" in result.detector.health()  # the field was tested
    assert [e for e in events if e.channel in ("mx", "my", "mz", "mag")] == []


@pytest.mark.parametrize("query, expected", [
    ("handheld?mag=lis3mdl&seed=3", []),
    ("wobble?mag=lis2mdl&seed=4", []),
    ("static?mag=lis3mdl&seed=2&magdist=magnet@3,motor", []),
    ("handheld?mag=lis3mdl&seed=3&fault=stuck:mx@4", [("mx", "stuck")]),
    ("handheld?mag=lis3mdl&seed=3&fault=spike:my:40@4", [("my", "spike")]),
    ("static?mag=lis3mdl&seed=3&fault=spike:mz:10@6", [("mz", "spike")]),
    ("static?mag=lis3mdl&seed=2&magdist=magnet:700@3", [("my", "saturation"),
                                                         ("mz", "saturation")]),
])
def test_simulated_magnetometer_faults_and_clean_streams(query, expected):
    from app.services.diagnosis import diagnose_events

    events = list(diagnose_events(f"sim://{query}&realtime=0", seconds=8.0))
    found = sorted({(e.channel, e.kind) for e in events
                    if e.channel in ("mx", "my", "mz", "mag")})
    assert found == expected
