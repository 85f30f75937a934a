"""Sketches that print text lines over a serial port: ``text://PORT?options``.

URL
---
``text:///dev/ttyACM0?baud=115200&columns=ax,ay,az,gx,gy,gz&accel=g&gyro=dps&time=ms&time_col=t``

The port is everything between ``text://`` and ``?``: a path (``text:///dev/ttyACM0``), a
Windows name (``text://COM3``) or a pyserial URL (``text://loop://``, ``text://spy:///dev/ttyUSB0``);
``port=`` (URL-encoded) overrides it. Ports are opened with :func:`serial.serial_for_url`.

Options (all optional):

- ``baud`` (default 115200; ignored by native USB CDC ports);
- ``columns``: names of the numbers on a line, in order; ``_`` skips a column. Names are
  recognised as in header rows (below), so ``accX`` or ``GYR_Z`` work too;
- ``accel`` = ``g`` | ``mg`` | ``m/s2``; ``gyro`` = ``dps`` | ``mdps`` | ``rad/s``;
- ``time`` = ``s`` | ``ms`` | ``us`` (unit of the time column) or ``host`` (ignore it);
  ``time_col`` names the time column (default: a column called t, time, timestamp, ms, millis,
  us, micros...);
- ``open_timeout`` seconds to wait for the first parsable lines (default 2);
- ``accel_fs`` g and ``gyro_fs`` dps: the ranges the sketch set, for display and calibration
  profiles only (default 0: unknown).

Lines understood
----------------
- Numbers separated by commas, semicolons, spaces or tabs, e.g. ``0.01,-0.02,0.99,0.1,0.0,-0.1``.
- An optional header row naming the columns, at the start or whenever the sketch restarts:
  ``ax,ay,az,gx,gy,gz``, ``accX accY accZ gyroX gyroY gyroZ``, ``ACC_X;ACC_Y;...``,
  ``time_ms,acc_x,...``, ``ax[g]``, ``gx(dps)``. Accelerometer names are an accelerometer word
  (a, ac, acc, accel, acceleration, accelerometer, xl) then the axis; gyroscope names a
  gyroscope word (g, gy, gyr, gyro, gyroscope, w, omega, rate) then the axis; a unit may follow
  (``ax_g``, ``gx_dps``) or stand in brackets.
- Without a header, a line of N numbers means: 3 ax,ay,az; 6 ax..gz; 9 ax..gz and three
  ignored (a magnetometer); 4, 7, 10: the first column is a timestamp if it rises on every line
  seen while connecting, else a temperature (Adafruit's plotter format ``temp,ax,...,gz``);
  8: timestamp, ax..gz, temperature.
- ``LABEL: value`` lines. ST's DataLogTerminal example (``ACC_X[0]: 12, ACC_Y[0]: -3,
  ACC_Z[0]: 1001`` in mg, ``GYR_X[0]: 140, ...`` in mdps; other sensors' lines are ignored)
  and the Adafruit_LSM6DS examples (``adafruit_lsm6dsox_test.ino``: a ``Temperature 25.50 deg C``
  line, ``Accel X: 0.12 \tY: -0.05 \tZ: 9.81 m/s^2 `` and ``Gyro X: 0.01 \tY: -0.00 \tZ: 0.00
  radians/s `` lines, then a blank line, every 100 ms). A bare ``Y:``/``Z:`` label continues the
  sensor named first on the line; unit words on a line (m/s^2, radians/s, rad/s, dps, mdps,
  mg, g) set that sensor's unit. A sample is emitted once it has an accelerometer reading and,
  in streams that carry one, a gyroscope reading; a half sample is dropped and counted.

Units when not given (the sensor is assumed roughly at rest while connecting): the median
``|a|`` of the first lines picks the accelerometer unit: below 4 -> g, 4 to 60 -> m/s^2,
60 and above -> mg. The gyroscope follows the usual pairing (g -> dps as Arduino_LSM6DS3 prints,
m/s^2 -> rad/s as Adafruit prints, mg -> mdps as ST prints), except that a median ``|w|`` above
35 cannot be rad/s (that is beyond +-2000 dps) and becomes dps, and above 2500 cannot be dps
and becomes mdps. A time column's unit comes from its name (ms, millis, us, micros, s), else
from comparing its steps with the lines' arrival rate, else integers are taken as ms
(Arduino's ``millis()``) and fractions as s.

Time
----
With a time column, ``t_s`` is that column from its first value, 32-bit ``millis()`` /
``micros()`` wrap-arounds unwrapped; a restart of the sketch (time going back) continues the
time axis and marks a gap; a step over 1.5 sample periods marks a gap with the samples it held.
Without one, ``t_s`` is the host's ``time.monotonic()`` at arrival, spread back by the sample
period over lines that arrived together, strictly increasing; a silence of more than five
sample periods (and 0.1 s) marks a gap on the sample after it.

Robustness: lines split across reads are joined; garbage lines (and ``nan``/``ovf`` values) are
counted and skipped, never raised; a garbled line that looked like data counts as a lost
sample (gap). Nothing parsable within ``open_timeout`` -> :class:`DeviceOpenError` that says
what arrived. The port vanishing (unplug) -> :class:`DeviceIOError`. :attr:`counters` are
thread-safe. Values are delivered as printed (floats) with :class:`ScaleFactors` that convert
them (g -> 9.80665 m/s^2 per unit, dps -> pi/180 rad/s per unit, ...); temperature in degC, NaN
when the sketch prints none; axes the sketch does not print (a gyroscope, a 2-axis
accelerometer) read 0.
"""

from __future__ import annotations

import contextlib
import math
import re
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from itertools import groupby
from typing import ClassVar
from urllib.parse import unquote

import numpy as np
import serial

from app.core.samples import STANDARD_GRAVITY_M_S2, RawBlock, ScaleFactors
from drivers.base import Device, DeviceDescriptor, DeviceInfo
from drivers.errors import DeviceIOError, DeviceOpenError, DeviceUrlError
from drivers.url_options import Option, parse_options

DEFAULT_BAUD = 115200
DEFAULT_OPEN_TIMEOUT_S = 2.0
OPEN_LINES_WANTED = 8
"""Data lines collected while connecting to decide layout and units ..."""
OPEN_SETTLE_S = 0.5
"""... or as many as arrive within this time after the first one."""
MAX_LINE_BYTES = 4096
READ_SLICE_S = 0.05
"""Port read timeout: the longest a read waits for a first byte before checking its deadline."""
ACCEL_UNITS: dict[str, float] = {"g": STANDARD_GRAVITY_M_S2, "mg": STANDARD_GRAVITY_M_S2 * 1e-3,
                                 "m/s2": 1.0}
"""Accelerometer unit -> m/s^2 per unit."""
GYRO_UNITS: dict[str, float] = {"dps": math.pi / 180.0, "mdps": math.pi / 180e3, "rad/s": 1.0}
"""Gyroscope unit -> rad/s per unit."""
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
"""Time column unit -> seconds per unit."""
CHANNELS = ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp")

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUMBER_RE = re.compile(_NUMBER)
_TOKEN_SPLIT = re.compile(r"[,;\s]+")
_TO_SPACE = str.maketrans({",": " ", ";": " ", "\t": " "})
_PAIR_RE = re.compile(
    r"(?P<label>[A-Za-z][A-Za-z0-9_ .\[\]]*?)\s*[:=]\s*(?P<value>" + _NUMBER + r")"
)
_TEMPERATURE_RE = re.compile(
    r"^\s*(?:die\s*)?temp(?:erature)?(?:\[\d+\])?\s*[:=]?\s*(" + _NUMBER + r")", re.IGNORECASE
)
_BRACKETS = re.compile(r"[\[\(]([^\]\)]*)[\]\)]")
_INDEX = re.compile(r"\[\d+\]")
_ACCEL_BASES = {"a", "ac", "acc", "accel", "acceleration", "accelerometer", "xl"}
_GYRO_BASES = {"g", "gy", "gyr", "gyro", "gyroscope", "w", "omega", "rate"}
_ACCEL_UNIT_WORDS = {"g": "g", "mg": "mg", "ms2": "m/s2", "mps2": "m/s2", "mss": "m/s2"}
_GYRO_UNIT_WORDS = {"dps": "dps", "degs": "dps", "degps": "dps", "degreess": "dps", "mdps": "mdps",
                    "rads": "rad/s", "radps": "rad/s", "radianss": "rad/s"}
_TIME_NAMES: dict[str, str | None] = {
    "t": None, "time": None, "timestamp": None, "ts": None, "stamp": None,
    "ms": "ms", "millis": "ms", "tms": "ms", "timems": "ms", "timestampms": "ms", "tsms": "ms",
    "us": "us", "micros": "us", "tus": "us", "timeus": "us", "timestampus": "us", "tsus": "us",
    "sec": "s", "secs": "s", "seconds": "s", "times": "s", "timesec": "s", "timestamps": "s",
}
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
    return None


def _parse_accel_unit(text: str) -> str:
    key = text.strip().lower().replace("^", "")
    aliases = {"g": "g", "mg": "mg", "m/s2": "m/s2", "ms2": "m/s2", "mps2": "m/s2"}
    if key not in aliases:
        raise DeviceUrlError(f"accel={text!r}: use g, mg or m/s2")
    return aliases[key]


def _parse_gyro_unit(text: str) -> str:
    key = text.strip().lower()
    aliases = {"dps": "dps", "deg/s": "dps", "mdps": "mdps", "rad/s": "rad/s", "rads": "rad/s"}
    if key not in aliases:
        raise DeviceUrlError(f"gyro={text!r}: use dps, mdps or rad/s")
    return aliases[key]


# -- one line ------------------------------------------------------------------------------------
@dataclass(slots=True)
class _Line:
    """A classified line: kind is blank, numbers, header, labelled, ignored or garbage."""

    kind: str
    numbers: list[float] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    values: dict[str, float] = field(default_factory=dict)
    accel_unit: str | None = None
    gyro_unit: str | None = None
    datalog: bool = False


def classify_line(text: str) -> _Line:
    """What one line of text holds (never raises)."""
    stripped = text.strip().strip(",;").strip()
    if not stripped:
        return _Line("blank")
    tokens = [t for t in _TOKEN_SPLIT.split(stripped) if t]
    if all(_NUMBER_RE.fullmatch(t) for t in tokens):
        return _Line("numbers", numbers=[float(t) for t in tokens])
    named = [canonical_column(t) for t in tokens]
    sensor_names = sum(n is not None and n.channel != "temp" for n in named)
    if sensor_names >= 3 and not any(_NUMBER_RE.fullmatch(t) for t in tokens):
        return _Line("header", names=tokens)
    temperature = _TEMPERATURE_RE.match(stripped)
    if temperature:
        return _Line("labelled", values={"temp": float(temperature.group(1))})
    pairs = list(_PAIR_RE.finditer(stripped))
    if not pairs:
        return _Line("garbage")
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
        if name.channel[0] in "ag" and name.channel != "temp":
            base = key[:-1]
        values[name.channel] = float(pair.group("value"))
    if not values:
        return _Line("ignored")
    line = _Line("labelled", values=values, datalog=datalog)
    for word in _LINE_UNIT_RE.findall(stripped):
        accel_unit, gyro_unit = _unit_word(word)
        has_accel = any(k in values for k in ("ax", "ay", "az"))
        has_gyro = any(k in values for k in ("gx", "gy", "gz"))
        if accel_unit and has_accel and not has_gyro:
            line.accel_unit = accel_unit
        if gyro_unit and has_gyro and not has_accel:
            line.gyro_unit = gyro_unit
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


# -- layout ----------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Layout:
    """How lines map to channels, and the units (decided while connecting)."""

    kind: str
    """``columns`` (numeric rows) or ``labelled``."""
    n_columns: int = 0
    columns: dict[str, int] = field(default_factory=dict)
    """Channel -> column index (``columns`` layouts)."""
    accel_unit: str = "g"
    gyro_unit: str = "dps"
    time_unit: str = "host"
    """s, ms, us, or host (no time column used)."""
    has_gyro: bool = True

    def describe(self) -> str:
        if self.kind == "labelled":
            what = "labelled lines"
        else:
            order = sorted(self.columns, key=self.columns.get)  # type: ignore[arg-type]
            what = f"{self.n_columns} columns ({','.join(order)})"
        units = f"accel in {self.accel_unit}, gyro in {self.gyro_unit}, time {self.time_unit}"
        return f"{what}; {units}"


def _default_columns(n: int, rows: np.ndarray) -> dict[str, int] | None:
    """The channel of each column of a headerless row of ``n`` numbers (module docstring)."""
    six = ("ax", "ay", "az", "gx", "gy", "gz")
    if n in (3, 6, 9):
        return {name: i for i, name in enumerate(six[: 3 if n == 3 else 6])}
    if n in (4, 7, 10):
        first = rows[:, 0]
        rising = len(first) >= 2 and bool(np.all(np.diff(first) > 0))
        single_time = len(first) == 1 and first[0] == round(first[0]) and first[0] > 200
        lead = "t" if rising or single_time else "temp"
        names = (lead, *six[: 3 if n == 4 else 6])
        return {name: i for i, name in enumerate(names)}
    if n == 8:
        return {name: i for i, name in enumerate(("t", *six, "temp"))}
    return None


def _columns_from_names(names: list[str], time_col: str | None) -> tuple[dict[str, int], dict]:
    """Channel -> index from header or ``columns=`` names, and the unit hints they carry."""
    columns: dict[str, int] = {}
    hints: dict[str, str] = {}
    wanted_time = time_col.strip().lower() if time_col else None
    for index, name in enumerate(names):
        if name.strip() in ("", "_", "-", "skip"):
            continue
        if wanted_time is not None and name.strip().lower() == wanted_time:
            columns["t"] = index
            continue
        meaning = canonical_column(name)
        if meaning is None or meaning.channel in columns:
            continue
        if meaning.channel == "t" and wanted_time is not None:
            continue
        columns[meaning.channel] = index
        if meaning.unit:
            hints[meaning.channel[0] if meaning.channel != "temp" else "temp"] = meaning.unit
    return columns, hints


# -- the parser: lines to records ----------------------------------------------------------------
@dataclass(slots=True)
class TextLineCounters:
    """What the driver saw. ``lines`` = parsed + rejected + ignored (blank lines not counted)."""

    bytes: int = 0
    lines: int = 0
    parsed: int = 0
    rejected: int = 0
    ignored: int = 0
    samples: int = 0
    incomplete: int = 0
    lost_samples: int = 0


class _Records:
    """Growing per-channel arrays, in arrival order."""

    def __init__(self) -> None:
        self.parts: list[dict[str, np.ndarray]] = []

    def add(self, **arrays: np.ndarray) -> None:
        self.parts.append(arrays)

    def take(self) -> dict[str, np.ndarray] | None:
        if not self.parts:
            return None
        parts, self.parts = self.parts, []
        return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


class LineParser:
    """Classified lines -> records (accelerometer, gyroscope, temperature, times, losses).

    Numeric rows take a vectorised path: runs of lines that match the expected row pattern are
    joined and converted by numpy in one go; other lines are classified one at a time.
    """

    def __init__(self, layout: Layout, counters: TextLineCounters, lock: threading.Lock,
                 *, columns_fixed: bool = False, time_col: str | None = None) -> None:
        self.layout = layout
        self.counters = counters
        self.lock = lock
        self.columns_fixed = columns_fixed
        self.time_col = time_col
        self.records = _Records()
        self._pending: dict[str, float] = {}
        self._lost = 0
        self._row_re = self._row_pattern(layout.n_columns)

    @staticmethod
    def _row_pattern(n: int) -> re.Pattern[str] | None:
        if n <= 0:
            return None
        sep = r"(?:\s*[,;]\s*|\s+)"
        return re.compile(rf"\s*[,;]?\s*{_NUMBER}(?:{sep}{_NUMBER}){{{n - 1}}}\s*[,;]?\s*")

    def feed(self, lines: list[str], arrival_s: np.ndarray) -> None:
        """Parse complete lines that arrived at host times ``arrival_s`` (one per line)."""
        pattern = self._row_re if self.layout.kind == "columns" else None
        fast = [pattern is not None and pattern.fullmatch(line) is not None for line in lines]
        start = 0
        for is_row, run in groupby(fast):
            count = len(list(run))
            chunk = lines[start : start + count]
            times = arrival_s[start : start + count]
            start += count
            if is_row:
                self._rows(chunk, times)
            else:
                for line, when in zip(chunk, times):
                    self._slow(line, float(when))

    def _count(self, **increments: int) -> None:
        with self.lock:
            for name, value in increments.items():
                setattr(self.counters, name, getattr(self.counters, name) + value)

    def _rows(self, lines: list[str], arrival_s: np.ndarray) -> None:
        n = self.layout.n_columns
        text = " ".join(lines).translate(_TO_SPACE)
        values = np.array(text.split(), dtype=np.float64).reshape(-1, n)
        self._emit_rows(values, arrival_s)
        self._count(lines=len(lines), parsed=len(lines))

    def _emit_rows(self, values: np.ndarray, arrival_s: np.ndarray) -> None:
        cols = self.layout.columns
        m = len(values)

        def take(names: tuple[str, ...], fill: float) -> np.ndarray:
            out = np.full((m, len(names)), fill)
            for j, name in enumerate(names):
                if name in cols:
                    out[:, j] = values[:, cols[name]]
            return out

        lost = np.zeros(m, dtype=np.int64)
        lost[0] = self._lost
        self._lost = 0
        self.records.add(
            accel=take(("ax", "ay", "az"), 0.0), gyro=take(("gx", "gy", "gz"), 0.0),
            temp=take(("temp",), math.nan)[:, 0],
            t_raw=take(("t",), math.nan)[:, 0], arrival=np.asarray(arrival_s, dtype=np.float64),
            lost=lost,
        )

    def _slow(self, text: str, arrival_s: float) -> None:
        line = classify_line(text)
        if line.kind == "blank":
            return
        if line.kind == "numbers" and self.layout.kind == "columns":
            if len(line.numbers) == self.layout.n_columns:
                self._emit_rows(np.array([line.numbers]), np.array([arrival_s]))
                self._count(lines=1, parsed=1)
            else:
                self._reject(looks_like_data=len(line.numbers) >= 3)
            return
        if line.kind == "header" and self.layout.kind == "columns" and not self.columns_fixed:
            columns, _hints = _columns_from_names(line.names, self.time_col)
            if "t" in columns and self.layout.time_unit == "host":
                columns.pop("t")
            self.layout = replace(self.layout, n_columns=len(line.names), columns=columns)
            self._row_re = self._row_pattern(len(line.names))
            self._count(lines=1, parsed=1)
            return
        if line.kind == "labelled" and self.layout.kind == "labelled":
            self._labelled(line.values, arrival_s)
            return
        if line.kind in ("ignored", "header"):
            self._count(lines=1, ignored=1)
            return
        self._reject(looks_like_data=len(_NUMBER_RE.findall(text)) >= 3 or "nan" in text.lower())

    def _reject(self, *, looks_like_data: bool) -> None:
        if looks_like_data:
            self._lost += 1
        self._count(lines=1, rejected=1)

    def _labelled(self, values: dict[str, float], arrival_s: float) -> None:
        """Collect labelled readings into a sample; emit it once complete."""
        pending = self._pending
        groups = {"a": ("ax", "ay", "az"), "g": ("gx", "gy", "gz")}
        for names in groups.values():
            if any(n in values for n in names) and any(n in pending for n in names):
                self._drop_incomplete()  # a new reading of a sensor already held
                pending = self._pending
                break
        if "temp" in values and "temp" in pending and any(n in pending for n in groups["a"]):
            self._drop_incomplete()
            pending = self._pending
        pending.update(values)
        self._count(lines=1, parsed=1)
        have_accel = all(n in pending for n in groups["a"])
        have_gyro = all(n in pending for n in groups["g"])
        if not have_gyro and any(n in values for n in groups["g"]):
            return
        if have_accel and (have_gyro or not self.layout.has_gyro):
            row = [pending.get(n, 0.0) for n in (*groups["a"], *groups["g"])]
            lost = np.array([self._lost], dtype=np.int64)
            self._lost = 0
            self.records.add(
                accel=np.array([row[:3]]), gyro=np.array([row[3:]]),
                temp=np.array([pending.get("temp", math.nan)]),
                t_raw=np.array([pending.get("t", math.nan)]), arrival=np.array([arrival_s]),
                lost=lost,
            )
            self._pending = {}

    def _drop_incomplete(self) -> None:
        if any(k != "temp" for k in self._pending):
            self._lost += 1
            self._count(incomplete=1)
        self._pending = {}


# -- deciding the layout while connecting --------------------------------------------------
@dataclass(frozen=True, slots=True)
class TextOptions:
    """A validated ``text://`` URL."""

    port: str
    baud: int = DEFAULT_BAUD
    columns: tuple[str, ...] | None = None
    accel_unit: str | None = None
    gyro_unit: str | None = None
    time_unit: str | None = None
    time_col: str | None = None
    open_timeout_s: float = DEFAULT_OPEN_TIMEOUT_S
    accel_fs_g: int = 0
    gyro_fs_dps: int = 0


def _columns(text: str) -> tuple[str, ...]:
    names = tuple(name.strip() for name in text.split(","))
    if len(names) < 3:
        raise ValueError("needs at least ax,ay,az")
    return names


def _time_unit(text: str) -> str:
    if text.lower() not in (*TIME_UNITS, "host"):
        raise ValueError("use s, ms, us or host")
    return text.lower()


def _word(parse: Callable[[str], str]) -> Callable[[str], str]:
    """A unit parser's :class:`DeviceUrlError` as the ValueError an option raises."""
    def read(text: str) -> str:
        try:
            return parse(text)
        except DeviceUrlError as exc:
            raise ValueError(str(exc)) from None
    return read


OPTIONS: tuple[Option, ...] = (
    Option("port", "text", None, help="the port (URL-encoded), instead of the one after "
                                      "text://"),
    Option("baud", "integer", DEFAULT_BAUD, positive=True,
           help="baud rate (native USB CDC ports ignore it)"),
    Option("columns", "text", None, parse=_columns, metavar="ax,ay,az,...",
           help="names of the numbers on a line, in order; _ skips a column (default: a "
                "header row, or the layout guessed)"),
    Option("accel", "choice", None, choices=("g", "mg", "m/s2"), field="accel_unit",
           parse=_word(_parse_accel_unit), help="accelerometer unit (default: guessed)"),
    Option("gyro", "choice", None, choices=("dps", "mdps", "rad/s"), field="gyro_unit",
           parse=_word(_parse_gyro_unit), help="gyroscope unit (default: guessed)"),
    Option("time", "choice", None, choices=(*TIME_UNITS, "host"), field="time_unit",
           parse=_time_unit,
           help="unit of the time column, or host: ignore it (default: guessed)"),
    Option("time_col", "text", None, help="name of the time column (default: t, time, "
                                          "timestamp, ms, millis, us, micros...)"),
    Option("open_timeout", "number", DEFAULT_OPEN_TIMEOUT_S, unit="s", positive=True,
           maximum=3600.0, field="open_timeout_s",
           help="seconds to wait for the first parsable lines"),
    Option("accel_fs", "integer", 0, unit="g", minimum=0, field="accel_fs_g",
           help="the accelerometer range the sketch set, for display and calibration "
                "profiles only (0: unknown)"),
    Option("gyro_fs", "integer", 0, unit="dps", minimum=0, field="gyro_fs_dps",
           help="the gyroscope range the sketch set (0: unknown)"),
)
"""The ``text://`` options."""


def parse_text_url(url: str) -> TextOptions:
    """Validate ``text://PORT?options`` (see the module docstring)."""
    if not url.lower().startswith("text://"):
        raise DeviceUrlError(f"{url}: not a text:// URL")
    port, _, query = url[len("text://") :].partition("?")
    values = parse_options(url, query, OPTIONS).values
    port = unquote(str(values.pop("port", port))).strip()
    if not port:
        raise DeviceUrlError(f"{url}: no port; e.g. text:///dev/ttyACM0 or text://COM3")
    return TextOptions(port=port, **values)  # type: ignore[arg-type]


def _guess_accel_unit(magnitude: float) -> str:
    if magnitude < 4.0:
        return "g"
    return "m/s2" if magnitude < 60.0 else "mg"


def _guess_gyro_unit(accel_unit: str, magnitude: float) -> str:
    unit = {"g": "dps", "m/s2": "rad/s", "mg": "mdps"}[accel_unit]
    if unit == "rad/s" and magnitude > 35.0:
        unit = "dps"
    if unit == "dps" and magnitude > 2500.0:
        unit = "mdps"
    return unit


def _guess_time_unit(times: np.ndarray, arrivals: np.ndarray) -> str:
    steps = np.diff(times)
    steps = steps[steps > 0]
    if len(steps) and arrivals[-1] - arrivals[0] > 0.05:
        host_period = (arrivals[-1] - arrivals[0]) / (len(arrivals) - 1)
        step = float(np.median(steps))
        return min(TIME_UNITS, key=lambda u: abs(math.log(step * TIME_UNITS[u] / host_period)))
    return "ms" if np.all(times == np.round(times)) else "s"


def decide_layout(
    lines: list[_Line], arrivals: list[float], options: TextOptions
) -> Layout | None:
    """Layout and units from the lines seen while connecting (None: nothing usable)."""
    numeric = [(ln, t) for ln, t in zip(lines, arrivals) if ln.kind == "numbers"]
    labelled = [ln for ln in lines if ln.kind == "labelled"
                and any(k[0] in "ag" for k in ln.values if k != "temp")]
    headers = [ln for ln in lines if ln.kind == "header"]
    hints: dict[str, str] = {}
    if options.columns or headers or (numeric and len(numeric) >= len(labelled)):
        names = list(options.columns) if options.columns else headers[-1].names if headers else None
        if names is not None:
            columns, hints = _columns_from_names(names, options.time_col)
            n = len(names)
        else:
            n = Counter(len(ln.numbers) for ln, _ in numeric).most_common(1)[0][0]
            rows = np.array([ln.numbers for ln, _ in numeric if len(ln.numbers) == n])
            found = _default_columns(n, rows)
            if found is None:
                raise DeviceOpenError(
                    f"{options.port}: lines hold {n} numbers, and no header says which is "
                    "which; add columns=... to the URL (e.g. columns=t,ax,ay,az,gx,gy,gz,_)"
                )
            columns = found
        if not any(c in columns for c in ("ax", "ay", "az")):
            raise DeviceOpenError(
                f"{options.port}: no accelerometer column among {names}; name them with "
                "columns=... (e.g. columns=ax,ay,az,gx,gy,gz)"
            )
        rows_n = [(ln.numbers, t) for ln, t in numeric if len(ln.numbers) == n]
        if not rows_n:
            return None
        values = np.array([r for r, _ in rows_n])
        row_times = np.array([t for _, t in rows_n])
        has_gyro = any(c in columns for c in ("gx", "gy", "gz"))
        layout = Layout("columns", n, columns, has_gyro=has_gyro)
        accel = values[:, [columns[c] for c in ("ax", "ay", "az") if c in columns]]
        gyro = values[:, [columns[c] for c in ("gx", "gy", "gz") if c in columns]]
        time_values = values[:, columns["t"]] if "t" in columns else None
    elif labelled:
        datalog = any(ln.datalog for ln in labelled)
        accel_rows = [[ln.values[k] for k in ("ax", "ay", "az")] for ln in labelled
                      if all(k in ln.values for k in ("ax", "ay", "az"))]
        gyro_rows = [[ln.values[k] for k in ("gx", "gy", "gz")] for ln in labelled
                     if all(k in ln.values for k in ("gx", "gy", "gz"))]
        if not accel_rows:
            return None
        accel = np.array(accel_rows)
        gyro = np.array(gyro_rows) if gyro_rows else np.zeros((1, 3))
        for ln in labelled:
            if ln.accel_unit:
                hints.setdefault("a", ln.accel_unit)
            if ln.gyro_unit:
                hints.setdefault("g", ln.gyro_unit)
        if datalog:
            hints.setdefault("a", "mg")
            hints.setdefault("g", "mdps")
        layout = Layout("labelled", has_gyro=bool(gyro_rows))
        time_values = None
        row_times = np.array(arrivals)
    else:
        return None

    accel_unit = options.accel_unit or hints.get("a") or _guess_accel_unit(
        float(np.median(np.linalg.norm(accel, axis=1)))
    )
    gyro_unit = options.gyro_unit or hints.get("g") or _guess_gyro_unit(
        accel_unit, float(np.median(np.linalg.norm(gyro, axis=1)))
    )
    time_unit = "host"
    if time_values is not None and options.time_unit != "host":
        time_unit = options.time_unit or hints.get("t") or _guess_time_unit(time_values, row_times)
    columns = dict(layout.columns)
    if time_unit == "host":
        columns.pop("t", None)
    return replace(layout, columns=columns, accel_unit=accel_unit, gyro_unit=gyro_unit,
                   time_unit=time_unit)


# -- the device -----------------------------------------------------------------------------
class TextLineDevice(Device):
    """A microcontroller sketch printing text lines (see the module docstring).

    Parameters
    ----------
    url : ``text://PORT?options``.
    port : an already open pyserial port to adopt instead of opening ``PORT`` (the bare-port
        detection hands over the port it sniffed); it is closed with the device.
    initial_data : bytes already read from that port, parsed first.
    """

    scheme: ClassVar[str] = "text"
    url_options: ClassVar[tuple[Option, ...]] = OPTIONS

    def __init__(
        self, url: str, *, port: serial.SerialBase | None = None, initial_data: bytes = b""
    ) -> None:
        super().__init__(url)
        self.options = parse_text_url(url)
        self._port: serial.SerialBase | None = None
        self._given_port = port
        self._initial = bytes(initial_data)
        self._counter_lock = threading.Lock()
        self._counters = TextLineCounters()
        self._buffer = b""
        self._parser: LineParser | None = None
        self.layout: Layout | None = None
        self._timeline = _Timeline()

    @property
    def counters(self) -> TextLineCounters:
        """A snapshot of the line counters (thread-safe)."""
        with self._counter_lock:
            return replace(self._counters)

    @classmethod
    def discover(cls) -> list[DeviceDescriptor]:
        """Nothing: any serial port may carry text; the port listing offers them."""
        return []

    # -- Device template ----------------------------------------------------------------------
    def _open(self) -> DeviceInfo:
        opts = self.options
        self._counters = TextLineCounters()
        self._buffer = b""
        self._timeline = _Timeline()
        port = self._given_port or _open_port(self.url, opts)
        if self._given_port is not None:
            port.timeout = READ_SLICE_S
        self._port = port
        self._first_block: RawBlock | None = None
        try:
            layout, lines, arrivals = self._collect(port)
        except BaseException:
            self._port = None
            port.close()
            raise
        self.layout = layout
        self._parser = LineParser(layout, self._counters, self._counter_lock,
                                  columns_fixed=opts.columns is not None, time_col=opts.time_col)
        self._scale = ScaleFactors(
            accel_m_s2_per_lsb=ACCEL_UNITS[layout.accel_unit],
            gyro_rad_s_per_lsb=GYRO_UNITS[layout.gyro_unit],
        )
        self._timeline.start(layout, _arrival_period(arrivals))
        self._parser.feed(lines, np.asarray(arrivals))
        self._first_block = self._take_block()  # learns the rate from what came while connecting
        name = getattr(port, "name", None) or getattr(port, "port", None) or opts.port
        return DeviceInfo(
            url=self.url,
            name=f"Text lines on {name}",
            unique_id=f"text:{opts.port}",
            sensor="unknown (text)",
            odr_hz=self._timeline.rate_hz,
            odr_nominal_hz=self._timeline.rate_hz,
            accel_fs_g=opts.accel_fs_g,
            gyro_fs_dps=opts.gyro_fs_dps,
            firmware="",
            extra={"layout": layout.describe(), "baud": opts.baud, "accel_unit": layout.accel_unit,
                   "gyro_unit": layout.gyro_unit, "time_unit": layout.time_unit},
        )

    def _read(self, timeout_s: float) -> RawBlock | None:
        port = self._port
        assert port is not None
        deadline = time.monotonic() + max(0.0, timeout_s)
        if self._first_block is not None:
            block, self._first_block = self._first_block, None
            return block
        while True:
            block = self._take_block()
            if block is not None:
                return block
            remaining = deadline - time.monotonic()
            if remaining <= 0.0 and not self._waiting(port):
                return None
            data = self._port_read(port)
            if data:
                self._feed(data, time.monotonic())

    def _close(self) -> None:
        port, self._port = self._port, None
        self._parser = None
        if port is not None:
            with contextlib.suppress(OSError, serial.SerialException):
                port.close()

    # -- internals ----------------------------------------------------------------------------
    def _waiting(self, port: serial.SerialBase) -> int:
        try:
            return port.in_waiting
        except (OSError, serial.SerialException) as exc:
            raise DeviceIOError(
                f"{self.url}: the port stopped working (unplugged?): {exc}"
            ) from exc

    def _port_read(self, port: serial.SerialBase) -> bytes:
        """What the port has, waiting up to the port's read timeout (READ_SLICE_S) for a byte."""
        try:
            data = port.read(max(1, port.in_waiting))
            if data and port.in_waiting:
                data += port.read(port.in_waiting)
            return data
        except (OSError, serial.SerialException) as exc:
            raise DeviceIOError(
                f"{self.url}: the port stopped working (unplugged?): {exc}"
            ) from exc

    def _split(self, data: bytes) -> list[bytes]:
        """Complete lines from the stream (partial lines wait for the rest)."""
        with self._counter_lock:
            self._counters.bytes += len(data)
        self._buffer += data
        *lines, self._buffer = self._buffer.split(b"\n")
        if len(self._buffer) > MAX_LINE_BYTES:
            self._buffer = b""
            with self._counter_lock:
                self._counters.lines += 1
                self._counters.rejected += 1
        return lines

    def _feed(self, data: bytes, arrival_s: float) -> None:
        lines = [line.rstrip(b"\r").decode("latin-1") for line in self._split(data)]
        if lines and self._parser is not None:
            self._parser.feed(lines, np.full(len(lines), arrival_s))

    def _collect(self, port: serial.SerialBase) -> tuple[Layout, list[str], list[float]]:
        """Read until enough data lines arrived to decide the layout; say what came if none."""
        opts = self.options
        start = time.monotonic()
        deadline = start + opts.open_timeout_s
        texts: list[str] = []
        arrivals: list[float] = []
        classified: list[_Line] = []
        first_data_s: float | None = None
        received = b""
        pending = self._initial
        while True:
            now = time.monotonic()
            data, pending = pending, b""
            if not data:
                if now >= deadline:
                    break
                data = self._port_read(port)
                now = time.monotonic()
            received += data[: 4096 - len(received)] if len(received) < 4096 else b""
            for raw in self._split(data):
                text = raw.rstrip(b"\r").decode("latin-1")
                line = classify_line(text)
                texts.append(text)
                arrivals.append(now)
                classified.append(line)
                if line.kind in ("numbers", "labelled") and first_data_s is None:
                    first_data_s = now
            data_lines = sum(ln.kind in ("numbers", "labelled") for ln in classified)
            if data_lines >= OPEN_LINES_WANTED or (
                first_data_s is not None and now - first_data_s >= OPEN_SETTLE_S
            ):
                layout = decide_layout(classified, arrivals, opts)
                if layout is not None:
                    return layout, texts, arrivals
        layout = decide_layout(classified, arrivals, opts) if classified else None
        if layout is not None:
            return layout, texts, arrivals
        raise DeviceOpenError(_nothing_parsable(self.url, opts, received, texts))

    def _take_block(self) -> RawBlock | None:
        parser = self._parser
        if parser is None:
            return None
        records = parser.records.take()
        if records is None:
            return None
        t_s, lost, gap = self._timeline.times(records, parser.layout)
        n = len(t_s)
        with self._counter_lock:
            self._counters.samples += n
            self._counters.lost_samples += int(lost.sum())
        return RawBlock(
            t_s=t_s,
            accel_raw=records["accel"],
            gyro_raw=records["gyro"],
            temp_raw=records["temp"],
            scale=self._scale,
            gap=gap,
            lost_samples=int(lost.sum()),
        )


class _Timeline:
    """Device times from a time column or from host arrival times (see the module docstring)."""

    GAP_FACTOR = 1.5
    MIN_STEP_S = 1e-6
    SILENCE_PERIODS = 5.0
    """On the host's clock, a silence longer than this many sample periods is a gap ..."""
    MIN_SILENCE_S = 0.1
    """... and than this (lines arrive in bursts: a USB serial port delivers every few ms)."""

    def __init__(self) -> None:
        self.origin_s: float | None = None
        self.period_s = 0.01
        self.rate_hz = 100.0
        self.last_t_s: float | None = None
        self.last_raw: float | None = None
        self.last_arrival_s: float | None = None

    def start(self, layout: Layout, period_s: float | None) -> None:
        self.layout = layout
        if period_s is not None:
            self.period_s = period_s
            self.rate_hz = 1.0 / period_s

    def times(
        self, records: dict[str, np.ndarray], layout: Layout
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t_s, lost samples before each, gap flags) for a batch of records."""
        lost = records["lost"].copy()
        if layout.time_unit != "host":
            t, restarted = self._from_column(records["t_raw"] * TIME_UNITS[layout.time_unit], lost)
        else:
            t, restarted = self._from_arrivals(records["arrival"])  # a silence: a gap
        self._learn_rate(t, lost | restarted)
        self.last_t_s = float(t[-1])
        return t, lost, (lost > 0) | restarted

    def _from_column(self, raw_s: np.ndarray, lost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Times from the time column; adds gaps' lost samples to ``lost``; returns restarts."""
        previous = self.last_raw if self.last_raw is not None else raw_s[0]
        steps = np.diff(raw_s, prepend=previous)
        if self.layout.time_unit != "s":  # 32-bit millis()/micros() wrap-around
            wrap = 2.0**32 * TIME_UNITS[self.layout.time_unit]
            steps[steps < -0.5 * wrap] += wrap
        missing = ~np.isfinite(steps)
        restarted = ~missing & (steps < 0)  # the sketch restarted: time went back
        steps[missing | restarted] = self.period_s
        first_ever = self.last_t_s is None
        if first_ever:
            steps[0] = 0.0
        t = (0.0 if first_ever else self.last_t_s) + np.cumsum(steps)
        if not first_ever or len(t) > 1:  # equal stamps (printing faster than the clock ticks)
            ramp = np.arange(len(t)) * self.MIN_STEP_S
            floor = -math.inf if first_ever else self.last_t_s + self.MIN_STEP_S
            t = np.maximum.accumulate(np.maximum(t, floor) - ramp) + ramp
        finite = raw_s[np.isfinite(raw_s)]
        if len(finite):
            self.last_raw = float(finite[-1])
        long_step = steps > self.GAP_FACTOR * self.period_s
        lost += np.where(long_step, np.maximum(np.rint(steps / self.period_s) - 1, 0), 0).astype(
            np.int64
        )
        return t, restarted

    def _from_arrivals(self, arrival_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arrival times, spread back by the period over lines that came together; t = 0 at
        the first sample; strictly increasing. With them, True on each sample after a silence
        of more than :data:`SILENCE_PERIODS` sample periods (and :data:`MIN_SILENCE_S`): the
        samples are not known to be lost, but nothing may integrate across the hole."""
        n = len(arrival_s)
        last_in_group = np.searchsorted(arrival_s, arrival_s, side="right") - 1
        t = arrival_s - (last_in_group - np.arange(n)) * self.period_s
        if self.origin_s is None:
            self.origin_s = float(t[0])
        t = t - self.origin_s
        floor = (self.last_t_s if self.last_t_s is not None else -math.inf) + self.MIN_STEP_S
        t = np.maximum(t, floor)
        ramp = np.arange(n) * self.MIN_STEP_S
        t = np.maximum.accumulate(t - ramp) + ramp
        steps = np.diff(t, prepend=t[0] if self.last_t_s is None else self.last_t_s)
        silent = steps > max(self.SILENCE_PERIODS * self.period_s, self.MIN_SILENCE_S)
        if self.last_arrival_s is not None and arrival_s[-1] > self.last_arrival_s:
            period = (arrival_s[-1] - self.last_arrival_s) / n
            if period < 4.0 * self.period_s:
                self.period_s = min(1.0, max(1e-4, 0.8 * self.period_s + 0.2 * period))
        self.last_arrival_s = float(arrival_s[-1])
        return t, silent

    def _learn_rate(self, t: np.ndarray, broken: np.ndarray) -> None:
        if self.layout.time_unit == "host":
            self.rate_hz = 1.0 / self.period_s
            return
        steps = np.diff(t)
        steps = steps[(broken[1:] == 0) & (steps > 0)]
        if len(steps):
            self.period_s = 0.8 * self.period_s + 0.2 * float(np.median(steps))
            if self.last_t_s is None:
                self.period_s = float(np.median(steps))
        self.rate_hz = 1.0 / self.period_s


def _arrival_period(arrivals: list[float]) -> float | None:
    """Line period from arrival times, when they spread over more than 50 ms."""
    if len(arrivals) >= 2 and arrivals[-1] - arrivals[0] > 0.05:
        return (arrivals[-1] - arrivals[0]) / (len(arrivals) - 1)
    return None


def _open_port(url: str, options: TextOptions) -> serial.SerialBase:
    """Open the port; turn the usual failures into messages that say what to do."""
    port = options.port
    kwargs: dict[str, object] = {"baudrate": options.baud, "timeout": READ_SLICE_S}
    if "://" not in port:
        kwargs["exclusive"] = True
    try:
        return serial.serial_for_url(port, **kwargs)
    except (serial.SerialException, OSError, ValueError) as exc:
        text = str(exc)
        if "Permission denied" in text or "Errno 13" in text:
            hint = (
                "permission denied: on Linux add yourself to the 'dialout' group "
                "(sudo usermod -aG dialout $USER, then log in again) or install a udev rule "
                'giving the port MODE="0660", GROUP="dialout"'
            )
        elif "busy" in text.lower() or "lock" in text.lower() or "Errno 16" in text:
            hint = "the port is busy: another program (a serial monitor?) has it open"
        elif "No such file" in text or "Errno 2" in text or "could not open" in text:
            hint = "no such port: is the board plugged in? (the name may change after replug)"
        else:
            hint = "could not open the port"
        raise DeviceOpenError(f"{url}: {hint} ({text})") from exc


def _nothing_parsable(url: str, options: TextOptions, received: bytes, texts: list[str]) -> str:
    """The error message when no data line arrived while connecting."""
    waited = f"{options.open_timeout_s:g} s"
    if not received:
        return (
            f"{url}: nothing arrived within {waited}. Is the sketch running and printing to "
            f"this port at {options.baud} baud? (Boards that reset when the port opens may "
            "need a longer open_timeout=.)"
        )
    printable = sum(32 <= b < 127 or b in (9, 10, 13) for b in received) / len(received)
    shown = [repr(t.strip()[:60]) for t in texts if t.strip()][:3]
    seen = f"{len(received)} bytes" + (f", {len(texts)} lines, e.g. {', '.join(shown)}"
                                        if shown else "")
    if printable < 0.8 or b"\x00" in received:
        return (
            f"{url}: no text lines within {waited}; received {seen} of binary-looking data "
            f"(first bytes {received[:16].hex(' ')}). The baud rate may be wrong (tried "
            f"{options.baud}), or the board speaks the binary protocol: open it by its bare port "
            "name or as serial://... instead."
        )
    return (
        f"{url}: no parsable sensor lines within {waited}; received {seen}. Expected numbers "
        "separated by commas, spaces or tabs (ax,ay,az,gx,gy,gz), a header row naming the "
        "columns, or labelled lines such as 'ACC_X[0]: 12, ACC_Y[0]: -3, ACC_Z[0]: 1001'."
    )
