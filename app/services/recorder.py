"""Headless recording: read a device, run the pipeline, write every block (``record`` command).

The loop is what the GUI's worker does, without Qt: ``raw = device.read()``, hand ``raw`` to the
:class:`~app.core.recording.writer.RecordingWriter`, ``pipeline.process(raw)``. It ends after
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
from app.core.alarms.recording import alarm_events_metadata
from app.core.calibration import SensorCalibration
from app.core.filters import DEFAULT_FILTER, create_filter
from app.core.pipeline import Pipeline, require_online
from app.core.recording.closing import store_closing_metadata
from app.core.recording.errors import RecordingWriteError
from app.core.recording.format import KEY_REFERENCE, recording_metadata, simulator_metadata
from app.core.recording.writer import RecordingWriter, WriterStatus
from app.core.safe_output import OutputLock, OutputRefused, interrupts_held
from app.core.samples import RawBlock
from app.services.board_health import KEY_STATUS_END, KEY_STATUS_START
from app.services.connection import Connection
from drivers.errors import DeviceError, DeviceIOError

READ_TIMEOUT_S = 0.1
RECONNECT_POLL_S = 0.1
"""How often an unplugged board is looked for (a port listing; cheap)."""
DEFAULT_RECONNECT_TIMEOUT_S = 300.0
"""How long headless ``record`` waits for an unplugged board by default."""
SIMULATOR_REFERENCE = "the simulator's true orientation"


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


def _cut(raw: RawBlock, count: int) -> RawBlock:
    """The first ``count`` samples of a block."""
    ref = raw.reference_quat
    gap = raw.gap
    return RawBlock(
        t_s=raw.t_s[:count], accel_raw=raw.accel_raw[:count], gyro_raw=raw.gyro_raw[:count],
        temp_raw=raw.temp_raw[:count], scale=raw.scale,
        gap=None if gap is None else gap[:count], lost_samples=raw.lost_samples,
        reference_quat=None if ref is None else ref[:count],
        mag_raw=None if raw.mag_raw is None else raw.mag_raw[:count],
    )


def board_status_now(device: Any) -> dict[str, Any] | None:
    """The board's counters now (asked for when the driver can), as metadata; None for
    devices without them."""
    request = getattr(device, "request_status", None)
    status = None
    if request is not None:
        try:
            status = request()
        except DeviceError:
            status = None
    status = status or getattr(device, "board_status", None)
    return None if status is None else status.as_dict()


def reference_source_of(device: Any) -> str | None:
    """What a device's reference orientation is, for the metadata (None: it has none)."""
    if getattr(device, "scheme", "") == "sim":
        return SIMULATOR_REFERENCE
    recording = getattr(device, "recording", None)
    if recording is not None and recording.has_reference:
        source = recording.metadata.get(KEY_REFERENCE)
        return source.get("source") if isinstance(source, dict) else "recorded reference"
    return None


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
) -> RecordOutcome:
    """Record ``device`` (a :class:`drivers.base.Device`) into ``path``.

    The device is opened if needed and always closed at the end. ``duration_s`` counts device
    time from the first sample (the last block is cut there); None records until ``stop`` is
    set or Ctrl-C. Raises :class:`~app.core.recording.errors.RecordingWriteError` when the
    file cannot be created, and the device's ``DeviceError`` when it cannot be opened.

    ``alarms`` watch the filtered angles of every block; ``on_alarms`` gets each block's
    crossings as they happen, and the file stores them all when it is closed.

    ``reconnect_timeout_s`` (None: never) is how long an unplugged board is awaited;
    ``on_outage`` hears of it when it is lost and again when it is back.
    """
    # Load the filters' compiled kernels before the device streams: the first block would
    # otherwise wait for them (0.3 s from numba's cache, seconds on a cold one) while the
    # sensor's FIFO overflows (benchmarks/soak-results: three of four losses were this).
    for name in {pipeline.filter.name if pipeline else filter_name or DEFAULT_FILTER,
                 *(comparisons or ())}:
        with contextlib.suppress(ValueError):  # unknown or offline: refused further on
            require_online(name)
            create_filter(name).warm_up()
    info = device.open()
    lock = OutputLock(path)
    try:
        try:
            lock.acquire()
        except OutputRefused as exc:
            raise RecordingWriteError(str(exc), Path(path)) from None
        if pipeline is None:
            pipeline = Pipeline(info.odr_hz, filter_name or DEFAULT_FILTER)
        else:
            pipeline.configure(info.odr_hz)
            if filter_name is not None and pipeline.filter.name != filter_name:
                pipeline.set_filter(filter_name)
        for key, value in (filter_parameters or {}).items():
            pipeline.set_filter_parameter(key, value)
        if comparisons:
            pipeline.set_comparisons(list(comparisons))
        if calibration is not None:
            pipeline.set_calibration(calibration)
        extra = {**simulator_metadata(device), **(extra_metadata or {})}
        board_start = board_status_now(device)
        if board_start is not None:
            extra[KEY_STATUS_START] = board_start
        if alarms is not None and alarms.watching:
            extra["alarms"] = [limit.spec() for limit in alarms.config.enabled]
            alarms.reset()
            alarms.begin_recording()
        metadata = recording_metadata(
            device=info, calibration=pipeline.calibration, orientation_filter=pipeline.filter,
            comparison_filters=pipeline.comparisons.values(), note=note,
            reference_source=reference_source_of(device), extra=extra,
        )
        writer = RecordingWriter(path, metadata, overwrite=overwrite, on_flush=on_flush,
                                 lock=lock)
        writer.start()
    except BaseException:
        lock.release()
        device.close()
        raise
    connection = Connection()
    connection.attach(device)
    try:
        return _record_and_close(connection, writer, pipeline, duration_s, stop, alarms,
                                 on_alarms, _Reconnect(reconnect_timeout_s, on_outage,
                                                       info.odr_hz))
    finally:
        lock.release()


class _Reconnect:
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


def _record_and_close(
    connection: Connection, writer: RecordingWriter, pipeline: Pipeline,
    duration_s: float | None, stop: threading.Event | None, alarms: AlarmMonitor | None,
    on_alarms: Callable[[list[AlarmEvent]], None] | None, reconnect: _Reconnect,
) -> RecordOutcome:
    """The recording loop, then the closing: held against Ctrl-C so that the rows, the
    board's closing counters and the alarm crossings all end up in the file."""
    reason, message = "stopped", ""
    first_t: float | None = None
    last_t: float | None = None
    held: list[int] = []
    try:
        while stop is None or not stop.is_set():
            device = connection.device
            if device is None:  # the board was unplugged: look for it
                if not reconnect.wait(connection, stop):
                    reason = "lost"
                    break
                continue
            try:
                raw = device.read(READ_TIMEOUT_S)
            except DeviceIOError as exc:
                if reconnect.lost(connection, str(exc), first_t, last_t):
                    continue
                reason, message = "device", str(exc)
                break
            except DeviceError as exc:
                reason, message = "device", str(exc)
                break
            if raw is None or len(raw) == 0:
                if getattr(device, "at_end", False):
                    reason = "end"
                    break
                continue
            connection.continue_time_axis(raw)
            reconnect.back(float(raw.t_s[0]))
            if first_t is None:
                first_t = float(raw.t_s[0])
            done = False
            if duration_s is not None:
                inside = int((raw.t_s < first_t + duration_s).sum())
                done = inside < len(raw)
                raw = _cut(raw, inside) if done else raw
            if len(raw):
                if not writer.write(raw):
                    reason, message = "write", writer.status.error or "the recording stopped"
                    break
                last_t = float(raw.t_s[-1])
                pipeline.process(raw)
                if alarms is not None:
                    crossings = alarms.update_from_buffer(pipeline.orientation, len(raw))
                    if crossings and on_alarms is not None:
                        on_alarms(crossings)
            if done:
                reason = "duration"
                break
        if writer.status.state == "failed":
            reason, message = "write", writer.status.error or ""
    except KeyboardInterrupt:
        reason = "interrupted"
    finally:
        with interrupts_held() as held:
            device = connection.device
            try:
                board_end = board_status_now(device) if device and device.is_open else None
            finally:
                status = writer.close()
                connection.close()
            crossings = alarms.end_recording() if alarms is not None else []
            closing: dict[str, Any] = {}
            if board_end is not None and status.rows_written and status.state != "failed":
                closing[KEY_STATUS_END] = board_end
            if crossings and status.rows_written:
                closing.update(alarm_events_metadata(crossings, alarms.config))  # type: ignore[union-attr]
            closing_error = _store_closing_metadata(status, closing, crossings)
    if reason == "lost":
        message = reconnect.gave_up(status.rows_written, status.duration_s)
    if status.state == "failed":
        reason, message = "write", status.error or message
    if held and reason in ("stopped", "duration", "end"):
        reason = "interrupted"
    return RecordOutcome(status, reason, message, pipeline, crossings, closing_error,
                         bool(held), reconnect.outages)


def _store_closing_metadata(status: WriterStatus, closing: dict[str, Any],
                            crossings: list[AlarmEvent]) -> str:
    """The closing metadata into the recording (else beside it); "" when stored in it."""
    what = []
    if crossings:
        what.append(f"{len(crossings)} alarm crossings")
    if KEY_STATUS_END in closing:
        what.append("the board's closing counters")
    return store_closing_metadata(
        status.path, closing, "the " + (" and ".join(what) or "closing metadata"),
        kept=f"the {status.rows_written} rows ({status.duration_s:.1f} s) were kept")


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
