"""Run the fault detector over a source: a recording file or a device URL (``diagnose``).

:func:`diagnose_events` yields :class:`~app.core.faults.FaultEvent` s as they are declared
(for ``--json`` they are printed at once). Recordings are read whole and fed in the blocks
they were recorded in (``block_start``) or in 0.1 s blocks; devices are opened through the
driver registry and read through the acquisition session until ``seconds`` of device time,
as fast as the driver can deliver (:meth:`drivers.base.Device.unpaced_url`: a simulator without
``realtime`` pacing unless the URL says otherwise).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.core.faults import FaultDetector, FaultEvent, SensorSpec
from app.core.faults.recording import recorded_field_calibration
from app.core.recording.errors import RecordingError
from app.core.recording.format import KEY_MAGNETOMETER
from app.core.recording.reader import Recording, read_recording
from app.core.sample_checks import implausible_message, implausible_rows
from app.core.samples import RawBlock, convert_raw_block
from app.services.acquisition import Acquisition, Until, head
from app.services.connection import Connection

DEFAULT_DEVICE_SECONDS = 10.0
READ_TIMEOUT_S = 0.5


@dataclass(slots=True)
class Diagnosis:
    """What a run saw: the detector (events, health) and how much it read."""

    detector: FaultDetector | None = None
    samples: int = 0
    duration_s: float = 0.0
    source: str = ""
    events: list[FaultEvent] = field(default_factory=list)
    first_t_s: float | None = None


def is_recording(source: str) -> bool:
    """True for an existing file (anything else is taken as a device URL)."""
    return "://" not in source and Path(source).is_file()


def recording_spec(recording: Recording) -> SensorSpec:
    """The detector's view of a recording's sensor (device metadata and measured rate)."""
    device = recording.device if isinstance(recording.device, dict) else {}
    magnetometer = recording.metadata.get(KEY_MAGNETOMETER)
    return SensorSpec.from_device_dict(device, recording.rate_hz).with_magnetometer(
        magnetometer if isinstance(magnetometer, dict) else None)


def recording_blocks(recording: Recording, seconds: float | None = None) -> Iterator[RawBlock]:
    """A recording's raw blocks (as recorded when it knows them), up to ``seconds``."""
    n = len(recording)
    if seconds is not None and n:
        t = recording.t_s
        n = int(np.searchsorted(t, t[0] + seconds, side="right"))
    size = max(1, round(0.1 * recording.rate_hz)) if recording.block_start is None else None
    for block in recording.raw_blocks(size):
        if n <= 0:
            return
        if len(block) > n:
            yield head(block, n)
            return
        n -= len(block)
        yield block


def diagnose_events(
    source: str, seconds: float | None = None, result: Diagnosis | None = None
) -> Iterator[FaultEvent]:
    """Events of ``source`` (recording path or device URL) as they are declared.

    ``seconds`` limits the time read (a device defaults to :data:`DEFAULT_DEVICE_SECONDS`).
    ``result``, if given, is filled in as the run goes (detector, sample count, duration).

    Raises
    ------
    RecordingError, DeviceError
        When the source cannot be read.
    """
    result = result if result is not None else Diagnosis()
    result.source = source
    if is_recording(source):
        recording = read_recording(source)
        _refuse_implausible(recording)
        detector = FaultDetector(recording_spec(recording))
        detector.field_calibration = recorded_field_calibration(
            recording.metadata.get(KEY_MAGNETOMETER))
        result.detector = detector
        for raw in recording_blocks(recording, seconds):
            block = convert_raw_block(raw)
            # a recording holds SI values, not counts: its scale is no LSB size
            events = detector.update(block, raw if _is_counts(raw) else None)
            _account(result, block.t_s)
            result.events.extend(events)
            yield from events
        return
    yield from _device_events(source, DEFAULT_DEVICE_SECONDS if seconds is None else seconds,
                              result)


def _refuse_implausible(recording: Recording) -> None:
    """RecordingError for NaN, infinite or absurd samples: the detector's running sums would
    turn them into NaN statistics or an overflow instead of fault events."""
    bad = implausible_rows(recording.accel_m_s2, recording.gyro_rad_s)
    message = implausible_message(recording.t_s, bad, "the accelerometer or gyroscope")
    if message is not None:
        raise RecordingError(f"{recording.path or 'the recording'}: {message}",
                             recording.path)


def _is_counts(raw: RawBlock) -> bool:
    return bool(np.issubdtype(np.asarray(raw.accel_raw).dtype, np.integer))


def _account(result: Diagnosis, t: np.ndarray) -> None:
    if len(t):
        if result.first_t_s is None:
            result.first_t_s = float(t[0])
        result.samples += len(t)
        result.duration_s = float(t[-1]) - result.first_t_s


def _device_events(url: str, seconds: float, result: Diagnosis) -> Iterator[FaultEvent]:
    from drivers.registry import create_device, driver_class, scheme_of

    device = create_device(driver_class(scheme_of(url)).unpaced_url(url))
    pending: list[FaultEvent] = []
    session = Acquisition(Connection(), on_events=pending.extend, check_lookalike=False)
    session.attach(device)
    try:
        for block in session.stream(Until(duration_s=seconds), READ_TIMEOUT_S):
            result.detector = session.health.detector
            _account(result, block.raw.t_s)
            events, pending[:] = list(pending), []
            result.events.extend(events)
            yield from events
    finally:
        session.close()
    if session.ended.error is not None:
        raise session.ended.error
    if session.ended.reason == "interrupted":
        raise KeyboardInterrupt
