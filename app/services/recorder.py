"""Headless recording: read a device, run the pipeline, write every block (``record`` command).

The loop is the window's: the :class:`~app.services.acquisition.Acquisition` session reads the
device, records every raw block, runs the pipeline, the look-alike check, the alarms and the
fault detector; fault events and alarm crossings go to ``on_faults`` / ``on_alarms`` as they
happen and into the file's metadata when it is closed, as the window stores them. It ends after
``duration_s`` of device time, when ``stop`` is set, on Ctrl-C (KeyboardInterrupt), when the
device fails or ends (a replay), or when the writer fails (a full disk); the file is closed
cleanly in every case and keeps every row written. A board that reports its health (STATUS)
has its counters stored at the start and, once the file is closed, at the end.

An unplugged board (a USB serial number, samples already recorded) is awaited as the window
awaits it, through the same :class:`~app.services.connection.Connection`: found again by its
USB serial number on any port, its time axis carried on, the first sample after the outage
flagged ``gap`` (the hole in ``t`` spans it). It records into the same file; after
``reconnect_timeout_s`` without it the recording ends as a device failure.
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.core.alarms import AlarmEvent, AlarmMonitor
from app.core.calibration import SensorCalibration
from app.core.faults import FaultEvent
from app.core.faults.warm_up import warm_up_detector
from app.core.filters import DEFAULT_FILTER, DEFAULT_FILTER_9AXIS, create_filter
from app.core.pipeline import Pipeline, require_online
from app.core.recording.errors import RecordingWriteError
from app.core.recording.writer import WriterStatus
from app.core.safe_output import OutputLock, OutputRefused, interrupts_held
from app.services.acquisition import Acquisition, Reconnection, RunEnd, Until
from app.services.connection import Connection
from app.services.lsl_outlet import LslCounts, LslOutlet

READ_TIMEOUT_S = 0.1
RECONNECT_POLL_S = 0.1
"""How often an unplugged board is looked for (a port listing; cheap)."""
DEFAULT_RECONNECT_TIMEOUT_S = 300.0
"""How long headless ``record`` waits for an unplugged board by default."""


@dataclass(frozen=True, slots=True)
class DeviceOutage:
    """An unplugged board during a recording: reported when lost, and again once back."""

    lost_at_s: float
    """Recording time (from the first sample) of the last sample before the loss."""
    reason: str
    back_after_s: float | None = None
    """Time from the last sample before to the first after (None while it is awaited)."""
    samples_lost: int = 0
    """Samples the board would have delivered meanwhile (at its rate)."""


@dataclass
class RecordOutcome:
    """How a headless recording ended.

    ``reason`` is ``"duration"``, ``"stopped"`` (``stop`` was set), ``"interrupted"``
    (Ctrl-C), ``"device"`` (the device failed: ``message`` says how), ``"lost"`` (an
    unplugged board did not come back in time: ``message``), ``"end"`` (a replay reached its
    end) or ``"write"`` (the writer failed: ``message``).
    """

    status: WriterStatus
    reason: str
    message: str = ""
    pipeline: Pipeline | None = field(default=None, repr=False)
    alarm_events: list[AlarmEvent] = field(default_factory=list)
    """The alarms' crossings (stored in the file's ``alarm_events`` when there are any)."""
    closing_error: str = ""
    """Why the closing metadata (alarm crossings, the board's closing counters) is not in
    the file, and where it went instead; empty when it was stored (or there was none)."""
    held_signal: bool = False
    """Ctrl-C (or SIGTERM) came while the file was being closed: it was finished first."""
    outages: list[DeviceOutage] = field(default_factory=list)
    """The board's outages, each as reported when it came back (the last one, if it never
    did, with ``back_after_s`` None)."""
    fault_events: list[FaultEvent] = field(default_factory=list)
    """The fault detector's events (stored in the file's ``fault_events``)."""
    lsl: LslCounts | None = None
    """What went out over Lab Streaming Layer (``lsl=True``), else None."""


def warm_up_kernels(filter_name: str | None, comparisons: Sequence[str] = ()) -> None:
    """Load the filters' and the fault detector's compiled kernels; call it before the device
    is opened. The first block would otherwise wait for them (0.3 s from numba's cache,
    seconds on a cold one or a busy machine) while the sensor's FIFO overflows
    (benchmarks/soak-results: three of four losses were this). ``filter_name`` None: both
    source defaults (which one runs depends on the device). Loaded once per process: a
    second call costs nothing."""
    warm_up_detector()
    defaults = (DEFAULT_FILTER, DEFAULT_FILTER_9AXIS)  # which one depends on the device
    for name in {*([filter_name] if filter_name else defaults), *(comparisons or ())}:
        with contextlib.suppress(ValueError):  # unknown or offline: refused further on
            require_online(name)
            create_filter(name).warm_up()


def record_device(
    device: Any,
    path: str | os.PathLike[str],
    *,
    duration_s: float | None = None,
    note: str = "",
    filter_name: str | None = None,
    filter_parameters: dict[str, Any] | None = None,
    comparisons: Sequence[str] = (),
    calibration: SensorCalibration | None = None,
    overwrite: bool = False,
    stop: threading.Event | None = None,
    on_flush: Callable[[WriterStatus], None] | None = None,
    pipeline: Pipeline | None = None,
    extra_metadata: dict[str, Any] | None = None,
    alarms: AlarmMonitor | None = None,
    on_alarms: Callable[[list[AlarmEvent]], None] | None = None,
    reconnect_timeout_s: float | None = None,
    on_outage: Callable[[DeviceOutage], None] | None = None,
    on_faults: Callable[[list[FaultEvent]], None] | None = None,
    on_message: Callable[[int, str], None] | None = None,
    lsl: bool = False,
) -> RecordOutcome:
    """Record ``device`` (a :class:`drivers.base.Device`) into ``path``.

    The device is opened if needed and always closed at the end. ``duration_s`` counts device
    time from the first sample (the last block is cut there); None records until ``stop`` is
    set or Ctrl-C. Raises :class:`~app.core.recording.errors.RecordingWriteError` when the
    file cannot be created, and the device's ``DeviceError`` when it cannot be opened.

    ``alarms`` watch the filtered angles of every block; ``on_alarms`` gets each block's
    crossings as they happen, ``on_faults`` the fault detector's events, ``on_message`` the
    device's messages and the look-alike warning; the file stores the crossings and the
    events when it is closed.

    ``reconnect_timeout_s`` (None: never) is how long an unplugged board is awaited;
    ``on_outage`` hears of it when it is lost and again when it is back.

    ``lsl``: stream the calibrated samples and the filtered orientation over Lab Streaming
    Layer while recording (:class:`~app.services.lsl_outlet.LslOutlet`, a subscriber of the
    same session); :class:`~app.services.lsl_outlet.LslUnavailable` before anything is
    recorded when pylsl cannot be used.
    """
    warm_up_kernels(pipeline.filter.name if pipeline else filter_name, comparisons)
    info = device.open()
    lock = OutputLock(path)
    try:
        try:
            lock.acquire()
        except OutputRefused as exc:
            raise RecordingWriteError(str(exc), Path(path)) from None
        if pipeline is None:
            pipeline = Pipeline(info.odr_hz, filter_name,
                                has_magnetometer=info.magnetometer is not None)
        elif filter_name is not None and pipeline.filter.name != filter_name:
            pipeline.set_filter(filter_name)
        for key, value in (filter_parameters or {}).items():
            pipeline.set_filter_parameter(key, value)
        if comparisons:
            pipeline.set_comparisons(list(comparisons))
        if calibration is not None:
            pipeline.set_calibration(calibration)
        session = Acquisition(Connection(), pipeline, on_message=on_message,
                              on_events=on_faults, alarms=alarms or AlarmMonitor(),
                              on_alarms=on_alarms)
        session.attach(device)
        outlet = LslOutlet(
            lambda: None if session.connection.device is None else session.connection.device.info,
            pipeline) if lsl else None
        if outlet is not None:
            session.subscribe(outlet)
        session.start_recording(path, note, extra=extra_metadata, overwrite=overwrite,
                                lock=lock, on_flush=on_flush)
    except BaseException:
        lock.release()
        device.close()
        raise
    session.reconnection = _Reconnect(reconnect_timeout_s, on_outage, info.odr_hz)
    try:
        outcome = _record_and_close(session, duration_s, stop)
    finally:
        lock.release()
        if outlet is not None:
            outlet.close()
    if outlet is not None:
        outcome.lsl = outlet.counts
    return outcome


class _Reconnect(Reconnection):
    """Headless reconnection: the board's outage in progress and the deadline to give up."""

    def __init__(self, timeout_s: float | None,
                 on_outage: Callable[[DeviceOutage], None] | None, odr_hz: float) -> None:
        self.timeout_s = timeout_s
        self._on_outage = on_outage
        self._odr_hz = odr_hz
        self.outages: list[DeviceOutage] = []
        self.pending: DeviceOutage | None = None
        """Lost and not yet back (no block since)."""
        self._last_t: float | None = None
        self._deadline = 0.0

    def lost(self, connection: Connection, reason: str, first_t: float | None,
             last_t: float | None) -> bool:
        """The device failed with ``reason``: True when its board is awaited."""
        if self.timeout_s is None or first_t is None or last_t is None:
            return False
        if connection.await_board(reason, last_t) is None:  # no USB serial: cannot come back
            return False
        if self.pending is None:  # lost again before any block came: one outage
            self.pending = DeviceOutage(lost_at_s=last_t - first_t, reason=reason)
            self.outages.append(self.pending)
            self._last_t = last_t
            self._deadline = time.monotonic() + self.timeout_s
            if self._on_outage is not None:
                self._on_outage(self.pending)
        return True

    def wait(self, connection: Connection, stop: threading.Event | None) -> bool:
        """Look for the board once; wait a poll interval when it is not back. False once the
        time is up."""
        if connection.try_reconnect() is not None:
            return True
        if time.monotonic() >= self._deadline:
            return False
        if stop is None:
            time.sleep(RECONNECT_POLL_S)
        else:
            stop.wait(RECONNECT_POLL_S)
        return True

    def back(self, first_t_s: float) -> None:
        """The first block after an outage begins at session time ``first_t_s``."""
        if self.pending is None or self._last_t is None:
            return
        span = first_t_s - self._last_t
        lost = max(0, round(span * self._odr_hz) - 1)
        self.outages[-1] = self.pending = DeviceOutage(
            self.pending.lost_at_s, self.pending.reason, span, lost)
        if self._on_outage is not None:
            self._on_outage(self.pending)
        self.pending = None

    def gave_up(self, rows: int, duration_s: float) -> str:
        outage = self.pending
        assert outage is not None
        return (f"the device lost at {outage.lost_at_s:.1f} s did not come back within "
                f"{self.timeout_s:g} s; the file keeps the {rows} rows ({duration_s:.1f} s) "
                "recorded")


def _record_and_close(session: Acquisition, duration_s: float | None,
                      stop: threading.Event | None) -> RecordOutcome:
    """The recording loop, then the closing: held against Ctrl-C so that the rows, the
    board's closing counters, the alarm crossings and the fault events all end up in the
    file."""
    reconnect = session.reconnection
    assert isinstance(reconnect, _Reconnect)
    held: list[int] = []
    end = RunEnd()
    try:
        end = session.run(Until(duration_s=duration_s, stop=stop), READ_TIMEOUT_S)
    finally:
        with interrupts_held() as held:
            try:
                closed = session.stop_recording()
            finally:
                session.close()
    assert closed is not None
    status = closed.status
    reason, message = end.reason, end.message
    if reason == "lost":
        message = reconnect.gave_up(status.rows_written, status.duration_s)
    if status.state == "failed":
        reason, message = "write", status.error or message
    if held and reason in ("stopped", "duration", "end"):
        reason = "interrupted"
    return RecordOutcome(status, reason, message, session.pipeline, closed.alarm_events,
                         closed.closing_error, bool(held), reconnect.outages,
                         closed.fault_events)


def parse_duration(text: str) -> float:
    """Seconds from ``"30"``, ``"30s"``, ``"2m"``, ``"1h"``."""
    units = {"s": 1.0, "m": 60.0, "h": 3600.0}
    text = text.strip().lower()
    factor = units.get(text[-1:])
    value = float(text[:-1] if factor is not None else text)
    seconds = value * (factor or 1.0)
    if not math.isfinite(seconds) or seconds <= 0:
        raise ValueError(f"duration {text!r} must be a positive time")
    return seconds
