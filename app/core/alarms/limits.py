"""What an alarm is: an :class:`AlarmLimit` on one quantity, the :class:`AlarmConfig` in force,
and their text form (``record --alarm``; see the package docstring)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

QUANTITIES: tuple[str, ...] = ("tilt", "roll", "pitch", "level", "heading")
"""What an alarm can watch, in the order the alarm panel lists them."""
QUANTITY_TITLES = {"tilt": "Tilt", "roll": "Roll", "pitch": "Pitch", "level": "Out of level",
                   "heading": "Heading"}
READOUT_OF = {"tilt": "tilt", "roll": "roll", "pitch": "pitch", "level": "tilt",
              "heading": "heading"}
"""The readout (and pipeline column) each quantity is computed from."""
DEFAULT_HYSTERESIS_DEG = 0.1
DEFAULT_DELAY_S = 0.5
MAX_DELAY_S = 3600.0

_HEADING_SECTOR_RE = re.compile(r"^heading:(?P<start>[-+]?[\d.]+)\.\.(?P<end>[-+]?[\d.]+)$")
_HEADING_OFF_RE = re.compile(
    r"^(?P<abs>\|)?heading-(?P<centre>[-+]?[\d.]+)(?(abs)\|)\s*(?P<op>[<>])\s*"
    r"(?P<value>[-+]?[\d.]+)$")
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
    centre: float | None = None
    """A heading alarm's set heading (magnetic, degrees clockwise from north): its limits are
    on the heading's difference from it, wrapped into -180 ... 180 (positive clockwise)."""

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise ValueError(f"no alarm quantity {self.quantity!r}; choose from "
                             f"{', '.join(QUANTITIES)}")
        if (self.quantity == "heading") != (self.centre is not None):
            raise ValueError("a heading alarm, and only it, needs the set heading")
        if self.centre is not None and not (math.isfinite(self.centre)
                                            and 0.0 <= self.centre < 360.0):
            raise ValueError(f"heading: the set heading {self.centre} is outside 0 ... 360°")
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

    def values(self, angles: Mapping[str, Any]) -> Any:
        """This alarm's quantity per sample from the pipeline's columns (degrees): the column
        itself, or for a heading its wrapped difference from the set heading."""
        values = np.asarray(angles[self.readout], dtype=np.float64)
        if self.centre is None:
            return values
        return np.mod(values - self.centre + 180.0, 360.0) - 180.0

    @property
    def readout(self) -> str:
        """The readout this alarm turns red (``level`` is a tilt alarm)."""
        return READOUT_OF[self.quantity]

    def describe(self) -> str:
        """In words: ``tilt above 2°``, ``roll outside -2° to 2°``, ``out of level (tilt
        beyond 0.5°)``."""
        if self.quantity == "level":
            return f"out of level (tilt beyond {self.upper:g}°)"
        if self.centre is not None:
            if self.upper is not None and self.lower is not None:
                start, end = (self.centre + self.lower) % 360.0, (self.centre + self.upper) % 360.0
                return f"magnetic heading outside {start:g}° to {end:g}° (clockwise)"
            if self.upper is not None:
                return f"magnetic heading more than {self.upper:g}° clockwise of {self.centre:g}°"
            below = -(self.lower or 0.0)
            return f"magnetic heading more than {below:g}° anticlockwise of {self.centre:g}°"
        if self.upper is not None and self.lower is not None:
            return f"{self.quantity} outside {self.lower:g}° to {self.upper:g}°"
        if self.upper is not None:
            return f"{self.quantity} above {self.upper:g}°"
        return f"{self.quantity} below {self.lower:g}°"

    def spec(self) -> str:
        """The text form, e.g. ``tilt>2,hyst=0.2,delay=0.5`` (:func:`parse_alarm` reads it)."""
        parts = []
        name = self.quantity if self.centre is None else f"heading-{self.centre:g}"
        if self.upper is not None and self.lower is not None and self.lower == -self.upper:
            parts.append(f"|{name}|>{self.upper:g}")
        else:
            if self.upper is not None:
                parts.append(f"{name}>{self.upper:g}")
            if self.lower is not None:
                parts.append(f"{name}<{self.lower:g}")
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
                   DEFAULT_DELAY_S if delay is None else delay, enabled,
                   number("centre", None))


def parse_alarm(text: str) -> AlarmLimit:
    """An :class:`AlarmLimit` from its text form (module docstring); ValueError with a message
    for the user otherwise."""
    quantity: str | None = None
    upper: float | None = None
    lower: float | None = None
    centre: float | None = None
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
        heading = _heading_limits(text, part)
        if heading is not None:
            if quantity is not None and (quantity != "heading" or heading[0] != centre):
                raise ValueError(f"alarm {text!r}: one quantity (and one set heading) per alarm")
            quantity = "heading"
            centre, new_upper, new_lower = heading
            upper = new_upper if new_upper is not None else upper
            lower = new_lower if new_lower is not None else lower
            continue
        match = _LIMIT_RE.match(part)
        if match is None:
            raise ValueError(f"alarm {text!r}: cannot read {raw_part.strip()!r}; write e.g. "
                             "tilt>2, roll<-1.5, |pitch|>1 or level>0.5")
        name = match["quantity"]
        if name == "heading":
            raise ValueError(f"alarm {text!r}: a heading alarm is 'heading:FROM..TO' (outside "
                             "a sector), '|heading-SET|>DEG' or 'heading-SET>DEG'")
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
    return AlarmLimit(quantity, upper, lower, options["hyst"], options["delay"],
                      centre=centre)


def _heading_limits(text: str, part: str) -> tuple[float, float | None, float | None] | None:
    """A heading term's (set heading, upper, lower) (None: not a heading term): a sector
    ``heading:FROM..TO`` (clockwise from FROM to TO; the alarm is outside it), or the difference
    from a set heading, ``|heading-SET|>DEG``, ``heading-SET>DEG`` (clockwise of it),
    ``heading-SET<-DEG`` (anticlockwise)."""
    sector = _HEADING_SECTOR_RE.match(part)
    if sector is not None:
        start, end = float(sector["start"]) % 360.0, float(sector["end"]) % 360.0
        width = (end - start) % 360.0
        if not 0.0 < width < 360.0:
            raise ValueError(f"alarm {text!r}: the sector {part!r} is empty")
        return (start + width / 2.0) % 360.0, width / 2.0, -width / 2.0
    match = _HEADING_OFF_RE.match(part)
    if match is None:
        return None
    centre, limit = float(match["centre"]) % 360.0, float(match["value"])
    if match["abs"]:
        return centre, abs(limit), -abs(limit)
    return (centre, limit, None) if match["op"] == ">" else (centre, None, limit)


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
        AlarmLimit("heading", upper=10.0, lower=-10.0, enabled=False, centre=0.0),
    ))


def alarms_from_specs(specs: Sequence[str]) -> AlarmConfig:
    """An :class:`AlarmConfig` from ``--alarm`` texts (ValueError on a bad one)."""
    return AlarmConfig(tuple(parse_alarm(spec) for spec in specs))
