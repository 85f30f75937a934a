"""What a line of a sketch's text output holds, and what its column and label names mean.

See :mod:`drivers.text_lines` for the lines understood.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from app.core.samples import STANDARD_GRAVITY_M_S2

ACCEL_UNITS: dict[str, float] = {"g": STANDARD_GRAVITY_M_S2, "mg": STANDARD_GRAVITY_M_S2 * 1e-3,
                                 "m/s2": 1.0}
"""Accelerometer unit -> m/s^2 per unit."""
GYRO_UNITS: dict[str, float] = {"dps": math.pi / 180.0, "mdps": math.pi / 180e3, "rad/s": 1.0}
"""Gyroscope unit -> rad/s per unit."""
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
"""Time column unit -> seconds per unit."""
MAG_UNITS: dict[str, float] = {"uT": 1.0, "gauss": 100.0, "mgauss": 0.1}
"""Magnetometer unit -> uT per unit."""
CHANNELS = ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp", "mx", "my", "mz")
MAG_CHANNELS = ("mx", "my", "mz")

NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
NUMBER_RE = re.compile(NUMBER)
_TOKEN_SPLIT = re.compile(r"[,;\s]+")
TO_SPACE = str.maketrans({",": " ", ";": " ", "\t": " "})
_PAIR_RE = re.compile(
    r"(?P<label>[A-Za-z][A-Za-z0-9_ .\[\]]*?)\s*[:=]\s*(?P<value>" + NUMBER + r")"
)
_TEMPERATURE_RE = re.compile(
    r"^\s*(?:die\s*)?temp(?:erature)?(?:\[\d+\])?\s*[:=]?\s*(" + NUMBER + r")", re.IGNORECASE
)
_BRACKETS = re.compile(r"[\[\(]([^\]\)]*)[\]\)]")
_INDEX = re.compile(r"\[\d+\]")
_ACCEL_BASES = {"a", "ac", "acc", "accel", "acceleration", "accelerometer", "xl"}
_GYRO_BASES = {"g", "gy", "gyr", "gyro", "gyroscope", "w", "omega", "rate"}
_MAG_BASES = {"m", "mag", "magn", "magnetic", "magnetometer", "compass", "b", "field"}
_MAG_UNIT_WORDS = {"ut": "uT", "utesla": "uT", "microtesla": "uT", "gauss": "gauss", "ga": "gauss",
                   "mgauss": "mgauss", "mga": "mgauss", "milligauss": "mgauss"}
_ACCEL_UNIT_WORDS = {"g": "g", "mg": "mg", "ms2": "m/s2", "mps2": "m/s2", "mss": "m/s2"}
_GYRO_UNIT_WORDS = {"dps": "dps", "degs": "dps", "degps": "dps", "degreess": "dps", "mdps": "mdps",
                    "rads": "rad/s", "radps": "rad/s", "radianss": "rad/s"}
_TIME_NAMES: dict[str, str | None] = {
    "t": None, "time": None, "timestamp": None, "ts": None, "stamp": None,
    "ms": "ms", "millis": "ms", "tms": "ms", "timems": "ms", "timestampms": "ms", "tsms": "ms",
    "us": "us", "micros": "us", "tus": "us", "timeus": "us", "timestampus": "us", "tsus": "us",
    "sec": "s", "secs": "s", "seconds": "s", "times": "s", "timesec": "s", "timestamps": "s",
}
_MAG_LINE_UNIT_RE = re.compile(r"\b(utesla|microtesla|ut|µt|mgauss|milligauss|gauss)\b",
                               re.IGNORECASE)
_LINE_UNIT_RE = re.compile(
    r"(m/s\^?2|m/s²|radians/s|rad/s|degrees/s|deg/s|°/s|\bmdps\b|\bdps\b|\bmg\b|\bg\b)",
    re.IGNORECASE,
)


# -- names and units ---------------------------------------------------------------------------
def _unit_word(text: str) -> tuple[str | None, str | None]:
    """(accel unit, gyro unit) a unit word names; at most one is not None."""
    key = re.sub(r"[^a-z0-9]", "", text.lower().replace("°", "deg"))
    if key in _ACCEL_UNIT_WORDS:
        return _ACCEL_UNIT_WORDS[key], None
    return None, _GYRO_UNIT_WORDS.get(key)


@dataclass(frozen=True, slots=True)
class ColumnName:
    """What a column or label name means: a channel (see :data:`CHANNELS`) and a unit hint."""

    channel: str
    unit: str | None = None


def canonical_column(name: str) -> ColumnName | None:
    """Recognise a column or label name (``accX``, ``ACC_X[0]``, ``gx(dps)``, ``time_ms``)."""
    hint_text = " ".join(m.group(1) for m in _BRACKETS.finditer(_INDEX.sub("", name)))
    key = re.sub(r"[^a-z0-9]", "", _BRACKETS.sub("", name).lower())
    if not key:
        return None
    if key in _TIME_NAMES:
        hint = hint_text.strip().lower()
        return ColumnName("t", _TIME_NAMES[key] or (hint if hint in TIME_UNITS else None))
    if key.startswith("temp") or key in {"tmp", "degc", "dietemp"}:
        return ColumnName("temp")
    for i in range(len(key) - 1, -1, -1):
        if key[i] not in "xyz":
            continue
        base, rest = key[:i], key[i + 1 :]
        if base in _ACCEL_BASES and (rest == "" or rest in _ACCEL_UNIT_WORDS):
            unit = _ACCEL_UNIT_WORDS.get(rest) or _unit_word(hint_text)[0]
            return ColumnName("a" + key[i], unit)
        if base in _GYRO_BASES and (rest == "" or rest in _GYRO_UNIT_WORDS):
            unit = _GYRO_UNIT_WORDS.get(rest) or _unit_word(hint_text)[1]
            return ColumnName("g" + key[i], unit)
        if base in _MAG_BASES and (rest == "" or rest in _MAG_UNIT_WORDS):
            hint = re.sub(r"[^a-z0-9]", "", hint_text.lower())
            return ColumnName("m" + key[i], _MAG_UNIT_WORDS.get(rest) or _MAG_UNIT_WORDS.get(hint))
    return None


# -- one line ------------------------------------------------------------------------------------
@dataclass(slots=True)
class Line:
    """A classified line: kind is blank, numbers, header, labelled, ignored or garbage."""

    kind: str
    numbers: list[float] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    values: dict[str, float] = field(default_factory=dict)
    accel_unit: str | None = None
    gyro_unit: str | None = None
    mag_unit: str | None = None
    datalog: bool = False


def classify_line(text: str) -> Line:
    """What one line of text holds (never raises)."""
    stripped = text.strip().strip(",;").strip()
    if not stripped:
        return Line("blank")
    tokens = [t for t in _TOKEN_SPLIT.split(stripped) if t]
    if all(NUMBER_RE.fullmatch(t) for t in tokens):
        return Line("numbers", numbers=[float(t) for t in tokens])
    named = [canonical_column(t) for t in tokens]
    sensor_names = sum(n is not None and n.channel != "temp" for n in named)
    if sensor_names >= 3 and not any(NUMBER_RE.fullmatch(t) for t in tokens):
        return Line("header", names=tokens)
    temperature = _TEMPERATURE_RE.match(stripped)
    if temperature:
        return Line("labelled", values={"temp": float(temperature.group(1))})
    pairs = list(_PAIR_RE.finditer(stripped))
    if not pairs:
        return Line("garbage")
    values: dict[str, float] = {}
    base = ""
    datalog = False
    for pair in pairs:
        label = pair.group("label").strip()
        datalog = datalog or bool(_INDEX.search(label))
        key = re.sub(r"[^a-z0-9]", "", _INDEX.sub("", label).lower())
        if key in ("x", "y", "z") and base:
            key = base + key
        name = canonical_column(key)
        if name is None:
            continue
        if name.channel[0] in "agm" and name.channel != "temp":
            base = key[:-1]
        values[name.channel] = float(pair.group("value"))
    if not values:
        return Line("ignored")
    line = Line("labelled", values=values, datalog=datalog)
    for word in _LINE_UNIT_RE.findall(stripped):
        accel_unit, gyro_unit = _unit_word(word)
        has_accel = any(k in values for k in ("ax", "ay", "az"))
        has_gyro = any(k in values for k in ("gx", "gy", "gz"))
        if accel_unit and has_accel and not has_gyro:
            line.accel_unit = accel_unit
        if gyro_unit and has_gyro and not has_accel:
            line.gyro_unit = gyro_unit
    if any(k in values for k in MAG_CHANNELS) and not any(k[0] in "ag" for k in values
                                                          if k != "temp"):
        found = _MAG_LINE_UNIT_RE.search(stripped)
        if found:
            line.mag_unit = _MAG_UNIT_WORDS[re.sub(r"[^a-z]", "", found.group(1).lower())]
    return line


def looks_like_text_lines(data: bytes) -> bool:
    """True when ``data`` holds at least one complete line this driver can use.

    For the bare-port detection (text lines or the binary protocol?): a numeric row of three or
    more numbers, a header row, or a labelled accelerometer/gyroscope line.
    """
    lines = data.split(b"\n")[:-1]
    for raw in lines[-50:]:
        line = classify_line(raw.decode("latin-1"))
        if (line.kind == "numbers" and len(line.numbers) >= 3) or line.kind == "header":
            return True
        if line.kind == "labelled" and any(k[0] in "ag" for k in line.values if k != "temp"):
            return True
    return False
