"""Alarms on the displayed angles: limits with hysteresis and a delay (no Qt).

An :class:`AlarmLimit` watches one quantity of the filtered angles, in degrees:

- ``roll``, ``pitch``: may have a ``lower`` and an ``upper`` limit (e.g. -2 and +2);
- ``tilt``: the total tilt from vertical (never negative), lower and/or upper limit;
- ``level``: "out of level", the tilt beyond a tolerance (``upper`` only).

It **raises** once the value has been beyond a limit (``> upper`` or ``< lower``) for
``delay_s`` without a break, and **clears** once the value has been back inside by at least the
hysteresis (``<= upper - hysteresis`` and ``>= lower + hysteresis``) for the same ``delay_s``.
Clearing waits as raising does so that a value hovering at the limit gives neither a flicker of
alarm nor a flicker of all-clear. Time is the device clock of the samples, so a replay run
faster than real time raises at the same moments as live. A sample that is not a number
(NaN) neither raises nor clears and breaks a run.

The :class:`AlarmMonitor` runs the enabled limits over each block of angles (the pipeline's
orientation output, after any tare: what the instrument shows) and returns the crossings as
:class:`AlarmEvent` objects, which recordings store under the ``alarm_events`` metadata key
(docs/recording-format.md) and ``record --alarm`` prints.

The text form (``record --alarm``)::

    tilt>2.0,hyst=0.2,delay=0.5     tilt above 2 degrees
    roll<-1.5                       roll below -1.5 degrees
    |pitch|>1                       pitch above +1 or below -1 degrees
    roll>2,roll<-1                  both limits on roll
    level>0.5                       out of level: tilt beyond 0.5 degrees

Options: ``hyst`` (degrees, default 0.1) and ``delay`` (seconds, default 0.5).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

QUANTITIES: tuple[str, ...] = ("tilt", "roll", "pitch", "level")
"""What an alarm can watch, in the order the alarm panel lists them."""
QUANTITY_TITLES = {"tilt": "Tilt", "roll": "Roll", "pitch": "Pitch", "level": "Out of level"}
READOUT_OF = {"tilt": "tilt", "roll": "roll", "pitch": "pitch", "level": "tilt"}
"""The readout (and pipeline column) each quantity is computed from."""
DEFAULT_HYSTERESIS_DEG = 0.1
DEFAULT_DELAY_S = 0.5
MAX_DELAY_S = 3600.0
KEY_ALARM_EVENTS = "alarm_events"
KEY_ALARMS = "alarms"
RAISED, CLEARED = "raised", "cleared"

_LIMIT_RE = re.compile(
    r"^(?P<abs>\|)?(?P<quantity>[a-z]+)(?(abs)\|)\s*(?P<op>[<>])\s*(?P<value>[-+]?[\d.]+(?:e[-+]?\d+)?)$"
)


@dataclass(frozen=True, slots=True)
class AlarmLimit:
    """One alarm: limits on one quantity, in degrees (see the module docstring)."""

    quantity: str
    upper: float | None = None
    lower: float | None = None
    hysteresis: float = DEFAULT_HYSTERESIS_DEG
    delay_s: float = DEFAULT_DELAY_S
    enabled: bool = True

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise ValueError(f"no alarm quantity {self.quantity!r}; choose from "
                             f"{', '.join(QUANTITIES)}")
        for name in ("upper", "lower"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"{self.quantity}: the {name} limit must be a number")
        if self.upper is None and self.lower is None:
            raise ValueError(f"{self.quantity}: give an upper (>) or a lower (<) limit")
        if self.quantity == "level" and (self.lower is not None or self.upper is None
                                        or self.upper < 0):
            raise ValueError("level: give the tolerance as level>DEGREES (not negative)")
        if self.upper is not None and self.lower is not None and self.lower >= self.upper:
            raise ValueError(f"{self.quantity}: the lower limit {self.lower:g} must be below "
                             f"the upper limit {self.upper:g}")
        if not (math.isfinite(self.hysteresis) and self.hysteresis >= 0):
            raise ValueError(f"{self.quantity}: hysteresis must be 0 or more degrees")
        if not (math.isfinite(self.delay_s) and 0 <= self.delay_s <= MAX_DELAY_S):
            raise ValueError(f"{self.quantity}: delay must be 0 to {MAX_DELAY_S:g} s")

    @property
    def readout(self) -> str:
        """The readout this alarm turns red (``level`` is a tilt alarm)."""
        return READOUT_OF[self.quantity]

    def describe(self) -> str:
        """In words: ``tilt above 2°``, ``roll outside -2° to 2°``, ``out of level (tilt
        beyond 0.5°)``."""
        if self.quantity == "level":
            return f"out of level (tilt beyond {self.upper:g}°)"
        if self.upper is not None and self.lower is not None:
            return f"{self.quantity} outside {self.lower:g}° to {self.upper:g}°"
        if self.upper is not None:
            return f"{self.quantity} above {self.upper:g}°"
        return f"{self.quantity} below {self.lower:g}°"

    def spec(self) -> str:
        """The text form, e.g. ``tilt>2,hyst=0.2,delay=0.5`` (:func:`parse_alarm` reads it)."""
        parts = []
        if self.upper is not None and self.lower is not None and self.lower == -self.upper:
            parts.append(f"|{self.quantity}|>{self.upper:g}")
        else:
            if self.upper is not None:
                parts.append(f"{self.quantity}>{self.upper:g}")
            if self.lower is not None:
                parts.append(f"{self.quantity}<{self.lower:g}")
        parts.append(f"hyst={self.hysteresis:g}")
        parts.append(f"delay={self.delay_s:g}")
        return ",".join(parts)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AlarmLimit:
        """The inverse of :meth:`to_dict`; ValueError on anything malformed."""
        if not isinstance(data, Mapping):
            raise ValueError("an alarm must be an object")

        def number(key: str, default: float | None) -> float | None:
            value = data.get(key, default)
            if value is None:
                return None
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"alarm {key} must be a number, got {value!r}")
            return float(value)

        enabled = data.get("enabled", True)
        if not isinstance(enabled, bool):
            raise ValueError(f"alarm enabled must be true or false, got {enabled!r}")
        hysteresis = number("hysteresis", DEFAULT_HYSTERESIS_DEG)
        delay = number("delay_s", DEFAULT_DELAY_S)
        return cls(str(data.get("quantity", "")), number("upper", None), number("lower", None),
                   DEFAULT_HYSTERESIS_DEG if hysteresis is None else hysteresis,
                   DEFAULT_DELAY_S if delay is None else delay, enabled)


def parse_alarm(text: str) -> AlarmLimit:
    """An :class:`AlarmLimit` from its text form (module docstring); ValueError with a message
    for the user otherwise."""
    quantity: str | None = None
    upper: float | None = None
    lower: float | None = None
    options = {"hyst": DEFAULT_HYSTERESIS_DEG, "delay": DEFAULT_DELAY_S}
    for raw_part in text.split(","):
        part = raw_part.strip().lower().replace(" ", "")
        if not part:
            continue
        key, equals, value = part.partition("=")
        if equals:
            if key not in options:
                raise ValueError(f"alarm {text!r}: unknown option {key!r} (hyst=DEG, delay=S)")
            try:
                options[key] = float(value.removesuffix("s"))
            except ValueError:
                raise ValueError(f"alarm {text!r}: {key}={value!r} is not a number") from None
            continue
        match = _LIMIT_RE.match(part)
        if match is None:
            raise ValueError(f"alarm {text!r}: cannot read {raw_part.strip()!r}; write e.g. "
                             "tilt>2, roll<-1.5, |pitch|>1 or level>0.5")
        name = match["quantity"]
        if name not in QUANTITIES:
            raise ValueError(f"alarm {text!r}: no quantity {name!r}; choose from "
                             f"{', '.join(QUANTITIES)}")
        if quantity is not None and name != quantity:
            raise ValueError(f"alarm {text!r}: one quantity per alarm (give --alarm again)")
        quantity = name
        limit = float(match["value"])
        if match["abs"]:
            upper, lower = abs(limit), -abs(limit)
        elif match["op"] == ">":
            upper = limit
        else:
            lower = limit
    if quantity is None:
        raise ValueError(f"alarm {text!r}: no limit; write e.g. tilt>2")
    return AlarmLimit(quantity, upper, lower, options["hyst"], options["delay"])


@dataclass(frozen=True, slots=True)
class AlarmConfig:
    """The alarms in force and whether crossings sound (a GUI choice; the CLI prints)."""

    limits: tuple[AlarmLimit, ...] = ()
    sound: bool = False

    @property
    def enabled(self) -> tuple[AlarmLimit, ...]:
        return tuple(limit for limit in self.limits if limit.enabled)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON (for settings and recordings); :meth:`from_dict` reads it back."""
        return {"limits": [limit.to_dict() for limit in self.limits], "sound": self.sound}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AlarmConfig:
        """Raises ValueError, saying what is wrong, for anything malformed."""
        if not isinstance(data, Mapping):
            raise ValueError("the alarm configuration must be an object")
        limits = data.get("limits", [])
        if not isinstance(limits, list):
            raise ValueError("alarm limits must be a list")
        sound = data.get("sound", False)
        if not isinstance(sound, bool):
            raise ValueError(f"alarm sound must be true or false, got {sound!r}")
        return cls(tuple(AlarmLimit.from_dict(item) for item in limits), sound)


def default_alarm_config() -> AlarmConfig:
    """One alarm per quantity, all off: what the alarm panel starts from."""
    return AlarmConfig((
        AlarmLimit("tilt", upper=2.0, enabled=False),
        AlarmLimit("roll", upper=2.0, lower=-2.0, enabled=False),
        AlarmLimit("pitch", upper=2.0, lower=-2.0, enabled=False),
        AlarmLimit("level", upper=0.5, enabled=False),
    ))


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
            values = np.asarray(angles[state.limit.readout], dtype=np.float64)
            events.extend(_run(state, t, values))
        self._last_t = float(t[-1])
        events.sort(key=lambda e: e.t)
        self._collect(events)
        return events

    def update_from_buffer(self, orientation: Any, count: int) -> list[AlarmEvent]:
        """Run the newest ``count`` rows of the pipeline's orientation ring buffer (what the
        pipeline just wrote for a block): :meth:`update` on its t, roll, pitch, tilt."""
        if not self._states or count <= 0:
            return []
        rows = orientation.latest(count, ["t", "roll", "pitch", "tilt"])
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


def alarms_from_specs(specs: Sequence[str]) -> AlarmConfig:
    """An :class:`AlarmConfig` from ``--alarm`` texts (ValueError on a bad one)."""
    return AlarmConfig(tuple(parse_alarm(spec) for spec in specs))


def with_enabled(config: AlarmConfig, quantity: str, enabled: bool) -> AlarmConfig:
    """``config`` with every alarm on ``quantity`` switched on or off."""
    return replace(config, limits=tuple(
        replace(limit, enabled=enabled) if limit.quantity == quantity else limit
        for limit in config.limits
    ))


# -- recordings: the ``alarm_events`` metadata key ---------------------------------------------
def alarm_events_metadata(events: Iterable[AlarmEvent],
                          config: AlarmConfig | None = None) -> dict[str, Any]:
    """The metadata entries that store a recording's crossings (and the alarms in force)."""
    entries: dict[str, Any] = {
        KEY_ALARM_EVENTS: [e.as_dict() for e in sorted(events, key=lambda e: e.t)]
    }
    if config is not None:
        entries[KEY_ALARMS] = [limit.spec() for limit in config.enabled]
    return entries


def save_alarm_events(path: str | os.PathLike[str], events: Iterable[AlarmEvent],
                      config: AlarmConfig | None = None) -> None:
    """Store the crossings into a finished recording (as fault events are stored)."""
    from app.core.recording.edit import rewrite_metadata

    rewrite_metadata(path, alarm_events_metadata(events, config))


def recorded_alarm_events(metadata: Mapping[str, Any]) -> list[AlarmEvent]:
    """The crossings a recording's metadata holds (none when absent; malformed ones skipped)."""
    entries = metadata.get(KEY_ALARM_EVENTS)
    if not isinstance(entries, list):
        return []
    events = []
    for entry in entries:
        try:
            events.append(AlarmEvent.from_dict(entry))
        except (KeyError, TypeError, ValueError):
            continue
    return events
