"""The acquisition step: read the device, carry the time axis on, run the pipeline, record.

This is the loop body the worker's poll timer runs, without Qt. The pipeline fills the ring
buffers the views read; samples never travel through signals.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from app.core.alarms import AlarmEvent, AlarmMonitor
from app.core.faults import FaultEvent
from app.core.lookalike import LookAlikeCheck
from app.core.pipeline import Pipeline
from app.services.board_health import BoardHealth
from app.services.connection import Connection
from app.services.health import HealthMonitor
from app.services.recording_control import RecordingControl

READ_TIMEOUT_S = 0.15
"""Longest a step waits for a block (a driver gathers up to 100 ms of data: drivers.base)."""


class Acquisition:
    """Moves one block at a time from the connection's device into the pipeline.

    ``on_message(level, text)`` gets the device's own messages (a board's LOG packets), and a
    warning when the accelerometer reads 0.5 g or 2 g at rest after a device is opened (a
    look-alike part, :mod:`app.core.lookalike`); ``on_events(events)`` the fault detector's
    events (``health``), when a block has some; ``on_alarms(events)`` the alarms' crossings
    (``alarms``, on the block's filtered angles). A board's STATUS counters go to ``board``; a
    rise becomes a message through ``on_message``.
    """

    def __init__(self, connection: Connection, pipeline: Pipeline, recording: RecordingControl,
                 on_message: Callable[[int, str], None],
                 health: HealthMonitor | None = None,
                 on_events: Callable[[list[FaultEvent]], None] | None = None,
                 alarms: AlarmMonitor | None = None,
                 on_alarms: Callable[[list[AlarmEvent]], None] | None = None) -> None:
        self.connection = connection
        self.pipeline = pipeline
        self.recording = recording
        self.health = health or HealthMonitor()
        self.board = BoardHealth()
        self._on_message = on_message
        self._on_events = on_events
        self.lookalike = LookAlikeCheck()
        self._checked_device: object | None = None
        self.alarms = alarms or AlarmMonitor()
        self._on_alarms = on_alarms
        self._generation: tuple[object, int] | None = None
        """A replay and its jump count (seeks, loops) at its last block."""
        self.on_received: Callable[[float, float], None] | None = None
        """Called with (session time of a block's newest sample, host ``time.monotonic()`` when
        the block arrived), from the worker thread: what a clock alignment needs."""

    def step(self, timeout_s: float = READ_TIMEOUT_S) -> int:
        """Read at most one block (waiting up to ``timeout_s``); returns its samples.

        Raises the driver's DeviceError (DeviceIOError when the device was lost) and whatever
        the pipeline raises; the caller decides what happens to the session.
        """
        device = self.connection.device
        if device is None:
            return 0
        raw = device.read(timeout_s)
        received_s = time.monotonic()
        for message in device.take_messages():
            self._on_message(message.level, message.text)
        for note in self.board.update(device.board_status):
            self._on_message(note.level, note.text)
        if raw is None or not len(raw):
            return 0
        generation = getattr(device, "last_block_generation", None)
        if generation is not None:
            last = self._generation
            if last is not None and last[0] is device and last[1] != generation and (
                    device.info is not None):
                # The replay jumped (a loop back to the start, a seek): time would run
                # backwards in the buffers, so the views start afresh (drivers/replay.py).
                self.pipeline.configure(device.info.odr_hz)
            self._generation = (device, generation)
        self.connection.continue_time_axis(raw)
        if self.on_received is not None:
            self.on_received(float(raw.t_s[-1]), received_s)
        self.pipeline.process(raw)
        self._check_lookalike(device)
        self.recording.write(raw)
        crossings = self.alarms.update_from_buffer(self.pipeline.orientation, len(raw))
        if crossings and self._on_alarms is not None:
            self._on_alarms(crossings)
        events = self.health.update(raw, self.pipeline.uncalibrated)
        if events and self._on_events is not None:
            self._on_events(events)
        return len(raw)

    def _check_lookalike(self, device: object) -> None:
        if device is not self._checked_device:  # a new device: judge it again
            self._checked_device = device
            self.lookalike.reset()
        block = self.pipeline.uncalibrated
        if block is not None and not self.lookalike.done:
            warning = self.lookalike.update(block)
            if warning:
                self._on_message(2, f"sensor: {warning}")

    def last_sample_time(self) -> float | None:
        """Session time of the newest sample, None before the first one."""
        if self.pipeline.counters.samples == 0:
            return None
        last_t = self.pipeline.samples.latest(1)["t"]
        return float(last_t[0]) if len(last_t) else 0.0
