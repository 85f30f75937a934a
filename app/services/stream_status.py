"""What the status bar shows, measured a few times a second (no Qt)."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from app.core.devices import BoardStatus
from app.core.recording.index import Overview
from app.services.replay_control import (
    OverviewTracker,
    ReplayState,
    recorded_alarm_marks,
    replay_position,
)

if TYPE_CHECKING:
    from app.services.acquisition import Acquisition

RATE_WINDOW_S = 2.0


@dataclass(frozen=True, slots=True)
class StreamStatus:
    """Figures the status bar shows, sent a few times per second."""

    url: str
    measured_rate_hz: float
    samples: int
    lost_samples: int
    gaps: int
    pipeline_load: float
    """Fraction of one core the pipeline used over the last interval."""
    replay: ReplayState | None = None
    """For a replay: position (s), duration (s), playing, ended, bookmarks (s)."""
    overview: Overview | None = None
    """For a replay, when it changed since the last status: the session's envelope."""
    gaps_s: tuple[float, ...] | None = None
    """For a replay, with a new overview: where the gaps are, s from the start."""
    health: dict[str, str] | None = None
    """The fault detector's state per channel (ax..gz, accel, gyro, link): ok, warning, fault."""
    fault: str = ""
    """Why the reading cannot be trusted now ("" when every channel is ok or a warning)."""
    board: BoardStatus | None = None
    """The board's health counters (STATUS), when a new one arrived since the last status."""
    alarms: tuple[tuple[str, str], ...] = ()
    """The alarms raised now: (quantity, text form) each."""
    alarm_marks_s: tuple[float, ...] | None = None
    """For a replay, with a new overview: where its recording's alarms were raised, s from the
    start."""


class StatusMeter:
    """The measured sample rate over a sliding window and the pipeline's share of a core.

    ``clock`` is the host clock in seconds (``time.monotonic`` by default).
    """

    def __init__(self, window_s: float = RATE_WINDOW_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.window_s = window_s
        self._clock = clock
        self._history: deque[tuple[float, int]] = deque()
        self._last_cpu = (clock(), 0.0)

    def reset(self, filter_cpu_s: float) -> None:
        """Start afresh (a new device): forget the rate history."""
        self._history.clear()
        self._last_cpu = (self._clock(), filter_cpu_s)

    def measure(self, samples: int, filter_cpu_s: float) -> tuple[float, float]:
        """(samples per second over the window, pipeline load since the last call).

        ``samples`` is the pipeline's running sample count, ``filter_cpu_s`` its running CPU
        time in seconds.
        """
        now = self._clock()
        history = self._history
        if history and samples < history[-1][1]:  # the count restarted (a replay seek)
            history.clear()
        history.append((now, samples))
        while len(history) > 2 and now - history[0][0] > self.window_s:
            history.popleft()
        span = history[-1][0] - history[0][0]
        rate = (history[-1][1] - history[0][1]) / span if span > 0 else 0.0
        last_time, last_cpu = self._last_cpu
        load = (filter_cpu_s - last_cpu) / max(now - last_time, 1e-9)
        self._last_cpu = (now, filter_cpu_s)
        return rate, load


def stream_status(session: Acquisition, meter: StatusMeter,
                  overviews: OverviewTracker) -> StreamStatus | None:
    """The status of the session's device now (None without one): rate and load since the
    last call, a replay's position and, when changed, its overview, the detector's health,
    the board's new counters and the alarms raised."""
    device = session.connection.device
    if device is None or session.pipeline is None:
        return None
    counters = session.pipeline.counters
    rate, load = meter.measure(counters.samples, counters.filter_cpu_s)
    update = overviews.changed(device)
    health = session.health.health()
    latest = session.health.latest_fault() if health and "fault" in health.values() else None
    return StreamStatus(
        url=device.url, measured_rate_hz=rate, samples=counters.samples,
        lost_samples=counters.lost_samples, gaps=counters.gaps, pipeline_load=load,
        replay=replay_position(device),
        overview=None if update is None else update[0],
        gaps_s=None if update is None else update[1],
        health=health,
        fault="" if latest is None else f"{latest.channel} {latest.kind}: {latest.message}",
        board=session.board.take_changed(),
        alarms=tuple((limit.quantity, limit.spec()) for limit in session.alarms.active()),
        alarm_marks_s=None if update is None else recorded_alarm_marks(device),
    )
