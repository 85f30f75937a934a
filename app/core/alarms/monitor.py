"""The crossings: :class:`AlarmMonitor` runs the enabled alarms over blocks of angles and
reports each raise and clear as an :class:`AlarmEvent` (see the package docstring)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from app.core.alarms.limits import QUANTITY_TITLES, AlarmConfig, AlarmLimit

RAISED, CLEARED = "raised", "cleared"


@dataclass(frozen=True, slots=True)
class AlarmEvent:
    """One crossing: an alarm raised or cleared.

    ``t`` is the device clock (s) of the sample that completed the delay; ``value`` the
    quantity's value there (degrees); ``limit`` the limit crossed (for a clear: the limit the
    alarm was raised on); ``alarm`` the alarm's text form.
    """

    t: float
    quantity: str
    state: str
    value: float
    limit: float
    alarm: str

    @property
    def raised(self) -> bool:
        return self.state == RAISED

    def message(self) -> str:
        """One line for the user: ``tilt alarm raised at 12.30 s: 2.31° above 2°``."""
        if self.raised:
            side = "above" if self.value > self.limit else "below"
            how = f"{self.value:+.2f}° {side} {self.limit:g}°"
        elif math.isfinite(self.value):
            how = f"{self.value:+.2f}°, back inside {self.limit:g}°"
        else:
            how = "the alarm was changed or switched off"
        title = QUANTITY_TITLES.get(self.quantity, self.quantity).lower()
        return f"{title} alarm {self.state} at {self.t:.2f} s: {how} ({self.alarm})"

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON: a value that is not a number (an alarm switched off) becomes null."""
        data = asdict(self)
        if not math.isfinite(self.value):
            data["value"] = None
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AlarmEvent:
        state = str(data["state"])
        if state not in (RAISED, CLEARED):
            raise ValueError(f"alarm event state {state!r}")
        value = math.nan if data["value"] is None else float(data["value"])
        return cls(float(data["t"]), str(data["quantity"]), state, value,
                   float(data["limit"]), str(data.get("alarm", "")))


@dataclass(slots=True)
class _AlarmState:
    limit: AlarmLimit
    active: bool = False
    since: float | None = None
    """Device time at which the pending condition (to raise or to clear) started."""
    crossed: float = 0.0
    """The limit the active alarm was raised on."""


@dataclass
class AlarmMonitor:
    """Runs the enabled alarms over blocks of angles and reports the crossings."""

    config: AlarmConfig = field(default_factory=AlarmConfig)

    def __post_init__(self) -> None:
        self._states: list[_AlarmState] = []
        self._last_t = -math.inf
        self._recording: list[AlarmEvent] | None = None
        self.configure(self.config)

    def configure(self, config: AlarmConfig) -> list[AlarmEvent]:
        """Use new alarms. An alarm kept unchanged keeps its state; one removed or changed
        while raised is cleared now (the returned events, at the last sample's time)."""
        old = {state.limit: state for state in self._states}
        self.config = config
        kept: list[_AlarmState] = []
        for limit in config.enabled:
            state = old.pop(limit, None)
            kept.append(state if state is not None else _AlarmState(limit))
        events = [
            AlarmEvent(self._last_t, state.limit.quantity, CLEARED, math.nan, state.crossed,
                       state.limit.spec())
            for state in old.values() if state.active and math.isfinite(self._last_t)
        ]
        self._states = kept
        self._collect(events)
        return events

    @property
    def watching(self) -> bool:
        """Whether any alarm is enabled (else :meth:`update` has nothing to do)."""
        return bool(self._states)

    def active(self) -> tuple[AlarmLimit, ...]:
        """The alarms raised now."""
        return tuple(state.limit for state in self._states if state.active)

    def active_readouts(self) -> tuple[str, ...]:
        """The readouts (roll, pitch, tilt) in alarm now, without repeats."""
        return tuple(dict.fromkeys(limit.readout for limit in self.active()))

    def reset(self) -> None:
        """Forget every state (a new device, or a replay that jumped): all quiet, no events."""
        for state in self._states:
            state.active, state.since = False, None
        self._last_t = -math.inf

    def update(self, t: np.ndarray, angles: Mapping[str, np.ndarray]) -> list[AlarmEvent]:
        """Run one block: ``t`` (s, device clock) and ``angles`` with ``roll``, ``pitch`` and
        ``tilt`` in degrees, one value per sample. Returns the crossings in time order.

        Time running backwards (a replay sought back) starts afresh (:meth:`reset`).
        """
        t = np.asarray(t, dtype=np.float64)
        if not len(t) or not self._states:
            if len(t):
                self._last_t = float(t[-1])
            return []
        if t[0] < self._last_t:
            self.reset()
        events: list[AlarmEvent] = []
        for state in self._states:
            values = state.limit.values(angles)
            events.extend(_run(state, t, values))
        self._last_t = float(t[-1])
        events.sort(key=lambda e: e.t)
        self._collect(events)
        return events

    def update_from_buffer(self, orientation: Any, count: int) -> list[AlarmEvent]:
        """Run the newest ``count`` rows of the pipeline's orientation ring buffer (what the
        pipeline just wrote for a block): :meth:`update` on its t, roll, pitch, tilt and
        heading."""
        if not self._states or count <= 0:
            return []
        rows = orientation.latest(count, ["t", "roll", "pitch", "tilt", "heading"])
        return self.update(rows["t"], rows)

    # -- a recording's events -----------------------------------------------------------------
    def begin_recording(self) -> None:
        self._recording = []

    def end_recording(self) -> list[AlarmEvent]:
        """The crossings since :meth:`begin_recording` (and stop collecting)."""
        events, self._recording = self._recording or [], None
        return events

    def _collect(self, events: list[AlarmEvent]) -> None:
        if self._recording is not None:
            self._recording.extend(events)


def _outside(limit: AlarmLimit, values: np.ndarray) -> np.ndarray:
    beyond = np.zeros(len(values), dtype=bool)
    if limit.upper is not None:
        beyond |= values > limit.upper
    if limit.lower is not None:
        beyond |= values < limit.lower
    return beyond


def _back_inside(limit: AlarmLimit, values: np.ndarray) -> np.ndarray:
    inside = np.isfinite(values)
    if limit.upper is not None:
        inside &= values <= limit.upper - limit.hysteresis
    if limit.lower is not None:
        inside &= values >= limit.lower + limit.hysteresis
    return inside


def _run(state: _AlarmState, t: np.ndarray, values: np.ndarray) -> list[AlarmEvent]:
    """The state machine over one block, vectorised over the runs of the pending condition
    (beyond the limit while quiet, back inside while raised): the first run that lasts the
    delay is a crossing; then the same from the sample after it, with the other condition.
    Crossings are rare, so a block costs a few array passes however noisy the values are."""
    limit = state.limit
    events: list[AlarmEvent] = []
    i = 0
    while i < len(t):
        tail_t, tail_v = t[i:], values[i:]
        condition = _back_inside(limit, tail_v) if state.active else _outside(limit, tail_v)
        edges = np.flatnonzero(np.diff(condition.astype(np.int8), prepend=0, append=0))
        starts, ends = edges[0::2], edges[1::2]  # runs [start, end) where it holds
        if not len(starts):
            state.since = None
            break
        begun = tail_t[starts]
        if starts[0] == 0 and state.since is not None:
            begun[0] = state.since  # the run began in an earlier block
        due_t = begun + limit.delay_s
        complete = np.flatnonzero(tail_t[ends - 1] >= due_t)
        if not len(complete):
            state.since = float(begun[-1]) if ends[-1] == len(condition) else None
            break
        k = int(complete[0])
        due = int(starts[k]) + int(np.searchsorted(tail_t[starts[k]:ends[k]], due_t[k]))
        value = float(tail_v[due])
        if state.active:
            events.append(AlarmEvent(float(tail_t[due]), limit.quantity, CLEARED, value,
                                     state.crossed, limit.spec()))
        else:
            above = limit.upper is not None and value > limit.upper
            state.crossed = float(limit.upper if above else limit.lower)  # type: ignore[arg-type]
            events.append(AlarmEvent(float(tail_t[due]), limit.quantity, RAISED, value,
                                     state.crossed, limit.spec()))
        state.active = not state.active
        state.since = None
        i += due + 1
    return events
