"""The one acquisition session: every consumer of a device reads it through this loop (no Qt).

A block goes read -> time axis carried on -> cut at the stop condition -> recorder -> convert ->
calibrate -> filter (the :class:`~app.core.pipeline.Pipeline`, or convert and calibrate alone
for consumers that want samples only) -> look-alike check -> alarms -> fault detector, and
then to the subscribers. The window's worker calls :meth:`Acquisition.step` from its poll timer;
headless commands (``record``, ``calibrate --device``, ``diagnose``, the simulator's streams,
arm recordings, the fault sweep, ``check-board``) call :meth:`Acquisition.run` or iterate
:meth:`Acquisition.stream` with a :class:`Until`. Consumers differ only in what they subscribe
to (:class:`Subscriber`) and when they stop.

A recording started here gets its metadata by one routine: the board's counters at the start
and at the end, the alarms in force and their crossings, and the fault detector's events
(:meth:`Acquisition.start_recording`, :meth:`Acquisition.stop_recording`).
"""

from __future__ import annotations

import dataclasses
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.core.alarms import AlarmEvent, AlarmMonitor
from app.core.alarms.recording import alarm_events_metadata
from app.core.calibration import SensorCalibration
from app.core.devices import BoardStatus, DeviceInfo
from app.core.faults import FaultEvent
from app.core.faults.recording import KEY_FAULT_EVENTS
from app.core.heading import KEY_HEADING, Declination, heading_metadata
from app.core.lookalike import LookAlikeCheck
from app.core.pipeline import Pipeline
from app.core.recording.closing import store_closing_metadata
from app.core.recording.writer import WriterStatus
from app.core.safe_output import OutputLock
from app.core.samples import RawBlock, SampleBlock, convert_raw_block
from app.services.board_health import KEY_STATUS_END, KEY_STATUS_START, BoardHealth
from app.services.connection import Connection
from app.services.health import HealthMonitor
from app.services.recording_control import RecordingControl
from drivers.base import Device
from drivers.errors import DeviceError, DeviceIOError

READ_TIMEOUT_S = 0.15
"""Longest a step waits for a block (a driver gathers up to 100 ms of data: drivers.base)."""
CLOSING_THREAD = "save-fault-events"
"""The thread that stores a window recording's closing metadata (a long file takes a while)."""


@dataclass(slots=True)
class Block:
    """One block through every stage: as read (time axis carried on, cut at the stop),
    in SI units before calibration, and calibrated."""

    raw: RawBlock
    uncalibrated: SampleBlock
    samples: SampleBlock
    received_s: float
    """Host ``time.monotonic()`` when the block arrived."""

    def __len__(self) -> int:
        return len(self.raw)


class Subscriber:
    """What a consumer hears from a session; override what it needs (the defaults ignore)."""

    def on_block(self, block: Block) -> None:
        """Every block, after all stages."""

    def on_message(self, level: int, text: str) -> None:
        """The device's own messages (a board's LOG, STATUS rises) and the look-alike warning;
        ``level`` 0 debug .. 3 error."""

    def on_faults(self, events: list[FaultEvent]) -> None:
        """The fault detector's events of a block."""

    def on_alarms(self, events: list[AlarmEvent]) -> None:
        """The alarms' crossings of a block."""


class _Callbacks(Subscriber):
    """Plain callbacks as a subscriber (the worker's signals, a test's lists)."""

    def __init__(self, on_message: Callable[[int, str], None] | None,
                 on_faults: Callable[[list[FaultEvent]], None] | None,
                 on_alarms: Callable[[list[AlarmEvent]], None] | None) -> None:
        self._on_message = on_message
        self._on_faults = on_faults
        self._on_alarms = on_alarms

    def on_message(self, level: int, text: str) -> None:
        if self._on_message is not None:
            self._on_message(level, text)

    def on_faults(self, events: list[FaultEvent]) -> None:
        if self._on_faults is not None:
            self._on_faults(events)

    def on_alarms(self, events: list[AlarmEvent]) -> None:
        if self._on_alarms is not None:
            self._on_alarms(events)


@dataclass(slots=True)
class Until:
    """When a run stops (whichever comes first); a source that ends always stops it.

    ``duration_s`` of device time from the first sample and ``samples`` cut the last block
    there; ``stop`` is set from elsewhere (another thread, a signal handler); ``when`` is asked
    after every block (a consumer that has what it wanted); ``wall_s`` of host time bounds a
    run that gets too few samples (a device that stalls).
    """

    duration_s: float | None = None
    samples: int | None = None
    stop: threading.Event | None = None
    when: Callable[[], bool] | None = None
    wall_s: float | None = None


@dataclass(slots=True)
class RunEnd:
    """How a run ended.

    ``reason``: ``"duration"``, ``"samples"``, ``"done"`` (``when`` said so), ``"stopped"``,
    ``"timeout"`` (``wall_s``), ``"interrupted"`` (Ctrl-C), ``"end"`` (the source ended),
    ``"device"`` (it failed: ``message``, ``error``), ``"lost"`` (an unplugged board did not
    come back) or ``"write"`` (the recording failed: ``message``).
    """

    reason: str = "stopped"
    message: str = ""
    error: DeviceError | None = None
    samples: int = 0
    first_t_s: float | None = None
    last_t_s: float | None = None


@dataclass(slots=True)
class ClosedRecording:
    """A recording the session finished, and what its closing metadata holds."""

    status: WriterStatus
    fault_events: list[FaultEvent] = field(default_factory=list)
    alarm_events: list[AlarmEvent] = field(default_factory=list)
    closing_error: str = ""
    """Why the closing metadata is not in the file and where it went; "" when stored (or
    stored in the background: the error then goes to ``on_error``)."""


class Reconnection:
    """How a run waits for an unplugged board (the window's worker does it with its timers);
    the default never waits."""

    def lost(self, connection: Connection, reason: str, first_t: float | None,
             last_t: float | None) -> bool:
        """The device failed with ``reason``: True when its board is awaited."""
        return False

    def wait(self, connection: Connection, stop: threading.Event | None) -> bool:
        """Look for the board once; False once the time is up."""
        return False

    def back(self, first_t_s: float) -> None:
        """The first block after an outage begins at ``first_t_s``."""


def head(raw: RawBlock, count: int) -> RawBlock:
    """The first ``count`` samples of a block: every per-sample array is cut, whatever columns
    the block carries (a magnetometer's too)."""
    n = len(raw)
    cut: dict[str, Any] = {}
    for item in dataclasses.fields(raw):
        value = getattr(raw, item.name)
        if isinstance(value, np.ndarray) and value.shape[:1] == (n,):
            cut[item.name] = value[:count]
    return dataclasses.replace(raw, **cut)


class Acquisition:
    """Moves one block at a time from the connection's device through every stage.

    ``pipeline`` (None: convert and apply ``calibration`` only, no filter, no ring buffers)
    and ``recording`` (None: never records) are the stages a consumer may leave out; so are the
    fault detector (``detect_faults``) and the look-alike check (``check_lookalike``). The
    alarms watch the pipeline's filtered angles. ``on_message``, ``on_events`` and
    ``on_alarms`` are callbacks for the first subscriber; ``subscribers`` more of them. A
    board's STATUS counters go to ``board``; a rise becomes a message.
    """

    def __init__(self, connection: Connection, pipeline: Pipeline | None = None,
                 recording: RecordingControl | None = None,
                 on_message: Callable[[int, str], None] | None = None,
                 health: HealthMonitor | None = None,
                 on_events: Callable[[list[FaultEvent]], None] | None = None,
                 alarms: AlarmMonitor | None = None,
                 on_alarms: Callable[[list[AlarmEvent]], None] | None = None, *,
                 subscribers: Sequence[Subscriber] = (),
                 calibration: SensorCalibration | None = None,
                 detect_faults: bool = True, check_lookalike: bool = True,
                 ask_board_status: bool = True) -> None:
        self.connection = connection
        self.pipeline = pipeline
        self.recording = recording or RecordingControl(on_error=lambda _m: None,
                                                       on_status=lambda _s: None)
        self.health = health or HealthMonitor()
        self.board = BoardHealth()
        self.lookalike = LookAlikeCheck()
        self.alarms = alarms or AlarmMonitor()
        self.declination: Declination | None = None
        """The declination in force (the heading's true north), stored with a recording under
        the ``heading`` metadata key; None: not set, the key is left out."""
        self.calibration = calibration
        self.detect_faults = detect_faults
        self.check_lookalike = check_lookalike
        self.ask_board_status = ask_board_status
        """Ask the board for its counters when a recording starts and ends (headless); the
        window's thread takes the latest the board sent instead of waiting for a reply."""
        self.subscribers: list[Subscriber] = [
            _Callbacks(on_message, on_events, on_alarms), *subscribers]
        self.on_received: Callable[[float, float], None] | None = None
        """Called with (session time of a block's newest sample, host ``time.monotonic()`` when
        the block arrived), from the reading thread: what a clock alignment needs."""
        self.reconnection = Reconnection()
        self._checked_device: object | None = None
        self._generation: tuple[object, int] | None = None
        """A replay and its jump count (seeks, loops) at its last block."""
        self._info: DeviceInfo | None = None
        self._write_failed = False
        self._cut = False
        self.ended = RunEnd()
        """How the last :meth:`stream` or :meth:`run` ended."""

    def subscribe(self, subscriber: Subscriber) -> Subscriber:
        self.subscribers.append(subscriber)
        return subscriber

    # -- a device -------------------------------------------------------------------------------
    def begin(self, info: DeviceInfo) -> None:
        """A new device: the board, the alarms and the look-alike check start afresh, and the
        fault detector starts at the first block (knowing its scale factors)."""
        self._info = info
        self.health.stop()
        self.board.reset()
        self.alarms.reset()
        if self.pipeline is not None:
            self.pipeline.configure(info.odr_hz)
            self.pipeline.adopt_source(info.magnetometer is not None)

    def open(self, url: str) -> DeviceInfo:
        """Open ``url`` as the session's device and :meth:`begin`. Raises DeviceError."""
        info = self.connection.open(url)
        self.begin(info)
        return info

    def attach(self, device: Device) -> DeviceInfo:
        """Take ``device`` (opened here if it is not) as the session's device."""
        info = device.open()
        self.connection.attach(device)
        self.begin(info)
        return info

    def close(self) -> None:
        """Close the device (a recording under way must be stopped first)."""
        self.connection.close()

    # -- one block ------------------------------------------------------------------------------
    def step(self, timeout_s: float = READ_TIMEOUT_S) -> int:
        """Read at most one block (waiting up to ``timeout_s``); returns its samples.

        Raises the driver's DeviceError (DeviceIOError when the device was lost) and whatever
        the pipeline raises; the caller decides what happens to the session.
        """
        block = self._read(timeout_s, None, None)
        return 0 if block is None else len(block)

    def _read(self, timeout_s: float, until: Until | None, first_t: float | None,
              got: int = 0) -> Block | None:
        device = self.connection.device
        if device is None:
            return None
        raw = device.read(timeout_s)
        received_s = time.monotonic()
        self._tell_messages(device)
        if raw is None or not len(raw):
            return None
        self._follow_jumps(device)
        self.connection.continue_time_axis(raw)
        if until is not None:
            keep = _inside(raw, until, float(raw.t_s[0]) if first_t is None else first_t, got)
            if keep < len(raw):
                self._cut = True
                raw = head(raw, keep)
            if not len(raw):
                return None
        if self.on_received is not None:
            self.on_received(float(raw.t_s[-1]), received_s)
        if not self.recording.write(raw):
            self._write_failed = True
        block = self._process(raw, received_s)
        self._check_lookalike(device, block.uncalibrated)
        if self.pipeline is not None:
            crossings = self.alarms.update_from_buffer(self.pipeline.orientation, len(raw))
            if crossings:
                for subscriber in self.subscribers:
                    subscriber.on_alarms(crossings)
        if self.detect_faults:
            if self.health.detector is None and self._info is not None:
                self.health.start(self._info, raw.scale)
            if self.health.detector is not None and self.pipeline is not None:
                # the gyro bias test carries the field as the earth's only when calibrated
                self.health.detector.field_calibration = self.pipeline.calibration.magnetometer
            events = self.health.update(raw, block.uncalibrated)
            if events:
                for subscriber in self.subscribers:
                    subscriber.on_faults(events)
        for subscriber in self.subscribers:
            subscriber.on_block(block)
        return block

    def _process(self, raw: RawBlock, received_s: float) -> Block:
        if self.pipeline is not None:
            samples = self.pipeline.process(raw)
            uncalibrated = self.pipeline.uncalibrated
            assert uncalibrated is not None
        else:
            uncalibrated = convert_raw_block(raw)
            samples = (uncalibrated if self.calibration is None
                       else self.calibration.apply(uncalibrated))
        return Block(raw, uncalibrated, samples, received_s)

    def _tell_messages(self, device: Device) -> None:
        for message in device.take_messages():
            self._tell(message.level, message.text)
        for note in self.board.update(device.board_status):
            self._tell(note.level, note.text)

    def _tell(self, level: int, text: str) -> None:
        for subscriber in self.subscribers:
            subscriber.on_message(level, text)

    def _follow_jumps(self, device: Device) -> None:
        generation = device.last_block_generation
        if generation is None:
            return
        last = self._generation
        if last is not None and last[0] is device and last[1] != generation and (
                device.info is not None) and self.pipeline is not None:
            # The replay jumped (a loop back to the start, a seek): time would run
            # backwards in the buffers, so the views start afresh (drivers/replay.py).
            self.pipeline.configure(device.info.odr_hz)
        self._generation = (device, generation)

    def _check_lookalike(self, device: object, block: SampleBlock) -> None:
        if not self.check_lookalike:
            return
        if device is not self._checked_device:  # a new device: judge it again
            self._checked_device = device
            self.lookalike.reset()
        if not self.lookalike.done:
            warning = self.lookalike.update(block)
            if warning:
                self._tell(2, f"sensor: {warning}")

    def last_sample_time(self) -> float | None:
        """Session time of the newest sample, None before the first one."""
        if self.pipeline is None or self.pipeline.counters.samples == 0:
            return None
        last_t = self.pipeline.samples.latest(1)["t"]
        return float(last_t[0]) if len(last_t) else 0.0

    # -- the loop -------------------------------------------------------------------------------
    def stream(self, until: Until, timeout_s: float = READ_TIMEOUT_S) -> Iterator[Block]:
        """The blocks until ``until`` (or the source's end, a failure); :attr:`ended` says how
        the run ended once the iteration is over."""
        end = self.ended = RunEnd()
        started = time.monotonic()
        self._write_failed = self._cut = False
        try:
            while until.stop is None or not until.stop.is_set():
                if until.wall_s is not None and time.monotonic() - started > until.wall_s:
                    end.reason = "timeout"
                    return
                device = self.connection.device
                if device is None:  # the board was unplugged: look for it
                    if not self.reconnection.wait(self.connection, until.stop):
                        end.reason = "lost"
                        return
                    continue
                try:
                    block = self._read(timeout_s, until, end.first_t_s, end.samples)
                except DeviceIOError as exc:
                    if self.reconnection.lost(self.connection, str(exc), end.first_t_s,
                                              end.last_t_s):
                        continue
                    end.reason, end.message, end.error = "device", str(exc), exc
                    return
                except DeviceError as exc:
                    end.reason, end.message, end.error = "device", str(exc), exc
                    return
                if block is None:
                    if device.at_end or not device.is_open:
                        end.reason = "end"
                        return
                    if self._limit_reached(until, end):
                        return
                    continue
                self.reconnection.back(float(block.raw.t_s[0]))
                if end.first_t_s is None:
                    end.first_t_s = float(block.raw.t_s[0])
                end.last_t_s = float(block.raw.t_s[-1])
                end.samples += len(block)
                yield block
                if self._write_failed:
                    end.reason = "write"
                    end.message = self.recording.error or "the recording stopped"
                    return
                if self._limit_reached(until, end):
                    return
                if until.when is not None and until.when():
                    end.reason = "done"
                    return
        except KeyboardInterrupt:
            end.reason = "interrupted"

    def _limit_reached(self, until: Until, end: RunEnd) -> bool:
        if until.samples is not None and end.samples >= until.samples:
            end.reason = "samples"
            return True
        if self._cut:  # a sample lay beyond the duration
            end.reason = "duration"
            return True
        return False

    def run(self, until: Until, timeout_s: float = READ_TIMEOUT_S) -> RunEnd:
        """Run until ``until``; returns how it ended (Ctrl-C ends it as ``"interrupted"``)."""
        try:
            for _block in self.stream(until, timeout_s):
                pass
        except KeyboardInterrupt:
            self.ended.reason = "interrupted"
        return self.ended

    # -- recording: the one metadata writer -------------------------------------------------------
    def start_recording(self, path: str | os.PathLike[str], note: str = "", *,
                        extra: dict[str, Any] | None = None, overwrite: bool = False,
                        lock: OutputLock | None = None,
                        on_flush: Callable[[WriterStatus], None] | None = None) -> WriterStatus:
        """Record the device's raw stream (before calibration) to ``path`` in format v1.

        The metadata holds the device, the calibration and filters in force, a simulator's
        truth, the board's counters now and the alarms in force; the fault events, the alarm
        crossings and the board's closing counters are added when it stops. Raises ValueError
        without a device and RecordingError when the file cannot be started.
        """
        device = self.connection.device
        extra = dict(extra or {})
        board = self._board_status_now(device)
        if board is not None:
            extra[KEY_STATUS_START] = board.as_dict()
        alarms = [limit.spec() for limit in self.alarms.config.enabled]
        if alarms:
            extra["alarms"] = alarms
        if self.declination is not None and KEY_HEADING not in extra:
            extra[KEY_HEADING] = heading_metadata(self.declination)
        status = self.recording.start(device, self.pipeline, str(path), note, extra=extra,
                                      overwrite=overwrite, lock=lock, on_flush=on_flush,
                                      calibration=self.calibration)
        self.health.begin_recording()
        self.alarms.begin_recording()
        return status

    def stop_recording(self, *, background: bool = False,
                       on_error: Callable[[str], None] | None = None) -> ClosedRecording | None:
        """Finish the recording and store its closing metadata (in a thread with
        ``background``: a long file's rewrite takes a while; its error goes to ``on_error``).
        None when nothing was being recorded."""
        if not self.recording.active:
            return None
        device = self.connection.device
        try:
            board_end = self._board_status_now(device) if device and device.is_open else None
        finally:
            status = self.recording.stop()
        assert status is not None
        crossings = self.alarms.end_recording()
        faults = self.health.take_recording()
        closing: dict[str, Any] = {}
        what = []
        if status.rows_written:
            if faults:
                closing[KEY_FAULT_EVENTS] = [e.as_dict() for e in sorted(faults,
                                                                         key=lambda e: e.t)]
                what.append(f"{len(faults)} fault events")
            if crossings:
                closing.update(alarm_events_metadata(crossings, self.alarms.config))
                what.append(f"{len(crossings)} alarm crossings")
            if board_end is not None and status.state != "failed":
                closing[KEY_STATUS_END] = board_end.as_dict()
                what.append("the board's closing counters")
        closed = ClosedRecording(status, faults if status.rows_written else [],
                                 crossings, "")
        if not closing:
            return closed
        description = "the " + " and ".join(what)
        kept = f"the {status.rows_written} rows ({status.duration_s:.1f} s) were kept"

        def store() -> str:
            return store_closing_metadata(status.path, closing, description, kept=kept)

        if not background:
            closed.closing_error = store()
            return closed

        def save() -> None:
            problem = store()
            if problem and on_error is not None:
                on_error(problem)

        threading.Thread(target=save, name=CLOSING_THREAD, daemon=True).start()
        return closed

    def _board_status_now(self, device: Device | None) -> BoardStatus | None:
        """The board's counters now: asked for where the device can (``ask_board_status``),
        else the latest it sent."""
        if device is None:
            return None
        if self.ask_board_status:
            try:
                status = device.request_status()
            except DeviceError:
                status = None
            if status is not None:
                return status
        return self.board.latest or device.board_status


def _inside(raw: RawBlock, until: Until, first_t: float, got: int) -> int:
    """How many of the block's samples lie inside the stop condition's duration and count."""
    keep = len(raw)
    if until.duration_s is not None:
        keep = min(keep, int((raw.t_s < first_t + until.duration_s).sum()))
    if until.samples is not None:
        keep = min(keep, max(0, until.samples - got))
    return keep
