"""The gyro bias test in motion with the magnetometer (issue 33): the gyro carries the earth's
field as well as gravity, so a bias about the vertical, which gravity cannot see while the
attitude is held, is found; a disturbed field is kept out. Synthetic streams, a few seconds."""

from __future__ import annotations

import math

import numpy as np

from app.core.calibration import MagnetometerCalibration
from app.core.faults import FaultDetector, SensorSpec
from app.core.faults import detector as detector_module
from app.core.faults.carry import GravityCarry
from app.core.faults.evaluation import sample_rows
from app.core.magnetometer.disturbance import OK
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

ODR = 100.0
FIELD_ENU = np.array([0.0, 15.0, -40.0])
"""An earth field (uT) in ENU: north and down, 69 deg of dip."""


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _stream(bias_dps: float, axis: int, onset_s: float, seconds: float = 26.0,
            magnet_from_s: float | None = None, seed: int = 3) -> SampleBlock:
    """At rest for 8 s (the gyro's bias and the field's reference are learnt), then a hand's
    wobble that keeps the attitude within ~10 deg (rates up to ~25 dps) and the sensor's z
    axis near the vertical; the earth's field, white noise. ``magnet_from_s``: a magnet
    comes near from then on (an extra field of 32 uT, fixed in the room, growing over 10 s:
    slowly enough that the field seems to turn, as a bias would make it)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * ODR)
    t = np.arange(n) / ODR
    omega = np.stack([np.radians(a) * np.sin(2 * np.pi * f * t + p)
                      for a, f, p in ((20, 0.37, 0.0), (25, 0.29, 1.0), (15, 0.23, 2.0))],
                     axis=1)
    omega[t < 8.0] = 0.0
    gravity = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
    rot = np.eye(3)
    accel = np.empty((n, 3))
    field = np.empty((n, 3))
    for i in range(n):
        world = FIELD_ENU.copy()
        if magnet_from_s is not None and t[i] >= magnet_from_s:
            world += np.array([30.0, -10.0, 5.0]) * min(1.0, (t[i] - magnet_from_s) / 10.0)
        accel[i] = rot.T @ gravity
        field[i] = rot.T @ world
        w = omega[i] / ODR
        angle = float(np.linalg.norm(w))
        if angle > 0:
            k = _skew(w / angle)
            rot = rot @ (np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k)
    gyro = omega + rng.standard_normal((n, 3)) * 0.002
    gyro[t >= onset_s, axis] += math.radians(bias_dps)
    accel = accel + rng.standard_normal((n, 3)) * 0.02
    field = field + rng.standard_normal((n, 3)) * 0.3
    return SampleBlock(t, accel, gyro, np.full(n, 25.0), np.zeros(n, dtype=bool), None, field)


def _without_field(samples: SampleBlock) -> SampleBlock:
    return SampleBlock(samples.t_s, samples.accel_m_s2, samples.gyro_rad_s, samples.temp_degc,
                       samples.gap)


def _bias_events(samples: SampleBlock, calibration: MagnetometerCalibration | None = None,
                 calibrated: bool = True) -> list:
    """The bias events; the field as calibrated (``calibrated``) or through ``calibration``."""
    detector = FaultDetector(SensorSpec(odr_hz=ODR))
    detector.field_calibrated = calibrated
    detector.field_calibration = calibration
    events = []
    for start in range(0, len(samples), 10):
        events += detector.update(sample_rows(samples, start, min(len(samples), start + 10)))
    return [e for e in events if e.kind == "bias"]


def test_a_vertical_bias_gravity_misses_is_found_by_the_field() -> None:
    faulty = _stream(2.0, 2, 14.0)
    assert _bias_events(_without_field(faulty)) == []  # gravity alone: the vertical is blind
    events = _bias_events(faulty)
    assert events and events[0].channel == "gz", events
    assert 14.0 < events[0].t <= 24.0
    size = float(events[0].message.split("by ")[1].split(" dps")[0])
    assert 1.4 <= size <= 2.6
    assert "field" in events[0].message


def test_an_uncalibrated_field_is_used_only_through_its_calibration() -> None:
    """A board's hard iron does not turn with the earth's field: the field part waits for the
    magnetometer's calibration, then finds the vertical bias through it."""
    faulty = _stream(2.0, 2, 14.0)
    hard_iron = np.array([20.0, -35.0, 12.0])
    assert faulty.mag_ut is not None
    with_iron = SampleBlock(faulty.t_s, faulty.accel_m_s2, faulty.gyro_rad_s, faulty.temp_degc,
                            faulty.gap, None, faulty.mag_ut + hard_iron)
    assert _bias_events(with_iron, calibrated=False) == []  # gravity alone: blind
    calibration = MagnetometerCalibration(hard_iron_ut=hard_iron)
    events = _bias_events(with_iron, calibration, calibrated=False)
    assert events and events[0].channel == "gz" and "field" in events[0].message, events


def test_the_clean_stream_with_its_field_raises_nothing() -> None:
    assert _bias_events(_stream(0.0, 2, 14.0)) == []


def test_a_horizontal_bias_is_still_found_on_its_axis_with_the_field() -> None:
    events = _bias_events(_stream(2.0, 0, 14.0))
    assert events and events[0].channel == "gx" and 14.0 < events[0].t <= 24.0, events


def test_a_disturbed_field_raises_no_alarm(monkeypatch) -> None:
    # a magnet brought near while the sensor wobbles: the field turns and grows, which a
    # field taken as the earth's reads as a gyro bias; the disturbance detector keeps it out
    samples = _stream(0.0, 2, 14.0, magnet_from_s=12.0)
    assert _bias_events(samples) == []
    monkeypatch.setattr(detector_module, "detector_step", lambda *args: OK)  # no gate
    assert [e.channel for e in _bias_events(samples)] == ["gz"]


def test_a_stuck_magnetometer_is_named_and_raises_no_gyro_bias() -> None:
    # a frozen field while the sensor turns: carried by the gyro it turns the other way,
    # which the bias test would read as a bias were the magnetometer's own check not first
    samples = _stream(0.0, 2, 14.0)
    frozen = samples.mag_ut.copy()
    frozen[samples.t_s >= 14.0] = frozen[int(14.0 * ODR)]
    detector = FaultDetector(SensorSpec(odr_hz=ODR))
    detector.field_calibrated = True
    events = []
    for start in range(0, len(samples), 10):
        block = sample_rows(samples, start, min(len(samples), start + 10))
        events += detector.update(SampleBlock(block.t_s, block.accel_m_s2, block.gyro_rad_s,
                                              block.temp_degc, block.gap, None,
                                              frozen[start:start + 10]))
    assert {e.channel for e in events if e.kind == "stuck"} >= {"mx", "my", "mz"}
    assert [e for e in events if e.kind == "bias"] == []


def test_without_a_field_the_carry_solves_as_before() -> None:
    # gravity alone: the vertical bias is held at zero by the ridge, not guessed
    carry = GravityCarry()
    rng = np.random.default_rng(1)
    half = math.radians(2.0) * 0.25 / 2.0
    rotation = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])  # a 2 dps bias on z
    for _ in range(40):
        accel = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2]) + rng.standard_normal(3) * 0.01
        assert carry.push(rotation, accel, 0.25) is None
    assert carry.field_windows == 0
    assert abs(math.degrees(carry.estimate[2])) < 0.1
    field = np.array([0.0, 15.0, -40.0])
    carry.restart()
    found = None
    for _ in range(40):
        accel = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2]) + rng.standard_normal(3) * 0.01
        # the sensor holds still: its field is constant; the gyro says it turns about z
        found = found or carry.push(rotation, accel, 0.25, field + rng.standard_normal(3) * 0.2)
    assert found is not None and found[0] == 2
    assert 1.6 <= math.degrees(found[1][2]) <= 2.4


def test_the_evaluation_carries_a_recordings_field_and_not_a_simulators_raw_one() -> None:
    """``evaluate-faults`` takes a recording's field as calibrated (BROAD's is, by its
    authors), or through the recording's own calibration, and a simulator's raw field (its
    board's hard iron in it) not at all: every detector it makes for a source is told so."""
    from app.core.faults.evaluation import clean_events
    from app.services.fault_evaluation import (
        CleanStream,
        FaultEvaluationSettings,
        resolve_fault_sources,
    )
    from tests.broad_trials import trial_path

    faulty = _stream(2.0, 2, 14.0)
    spec = SensorSpec(odr_hz=ODR)

    def bias_events(stream: CleanStream) -> list:
        return [e for e in clean_events(stream.clean, spec, stream.detector_for())
                if e.kind == "bias"]

    found = bias_events(CleanStream(faulty, faulty, spec, None, field_calibrated=True))
    assert found and found[0].channel == "gz" and "field" in found[0].message, found
    assert bias_events(CleanStream(faulty, faulty, spec, None)) == []  # raw: gravity alone
    hard_iron = np.array([20.0, -35.0, 12.0])
    assert faulty.mag_ut is not None
    with_iron = SampleBlock(faulty.t_s, faulty.accel_m_s2, faulty.gyro_rad_s, faulty.temp_degc,
                            faulty.gap, None, faulty.mag_ut + hard_iron)
    through = bias_events(CleanStream(with_iron, with_iron, spec, None, field_calibration=(
        MagnetometerCalibration(hard_iron_ut=hard_iron))))
    assert through and through[0].channel == "gz", through
    # a BROAD trial (no calibration of its own) is loaded as calibrated
    source = resolve_fault_sources([str(trial_path("01_undisturbed_slow_rotation_A"))])[0]
    stream = source.load(FaultEvaluationSettings())
    assert stream.field_calibrated and stream.field_calibration is None
    assert stream.detector_for()(stream.spec).field_calibrated
