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
  a magnetometer's columns (``mx,my,mz``, ``magX``, ``MAG_X``) are read in uT, gauss or
  mgauss (a unit in the name, ``mx_uT``, ``magX[gauss]``, says which; else see *Units*);
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
- Without a header, a line of N numbers means: 3 ax,ay,az; 6 ax..gz; 9 ax..gz,mx,my,mz (a
  9-DoF board's magnetometer); 4, 7, 10: the first column is a timestamp if it rises on every
  line seen while connecting, else a temperature (Adafruit's plotter format
  ``temp,ax,...,gz``), then as for 3, 6, 9; 8: timestamp, ax..gz, temperature.
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
and becomes mdps. The magnetometer's unit comes from the earth's field, 25 to 65 uT: a median
``|m|`` below 2 is gauss, 2 to 200 uT, 200 and above mgauss (ST's DataLogTerminal prints
mgauss). A time column's unit comes from its name (ms, millis, us, micros, s), else
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
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import ClassVar
from urllib.parse import unquote

import numpy as np
import serial

from app.core.devices import MagnetometerInfo
from app.core.samples import RawBlock, ScaleFactors
from drivers.base import Device, DeviceDescriptor, DeviceInfo
from drivers.errors import DeviceIOError, DeviceOpenError, DeviceUrlError
from drivers.text_stream.layout import Layout, decide_layout
from drivers.text_stream.lexer import (
    ACCEL_UNITS,
    CHANNELS,
    GYRO_UNITS,
    MAG_UNITS,
    TIME_UNITS,
    ColumnName,
    Line,
    canonical_column,
    classify_line,
    looks_like_text_lines,
)
from drivers.text_stream.parser import LineParser, TextLineCounters
from drivers.text_stream.timeline import Timeline, arrival_period
from drivers.url_options import Option, parse_options

_Timeline = Timeline  # the name tests and older code used

__all__ = [
    "ACCEL_UNITS", "CHANNELS", "GYRO_UNITS", "MAG_UNITS", "TIME_UNITS", "ColumnName", "Layout",
    "Line", "LineParser", "TextLineCounters", "TextLineDevice", "TextOptions", "canonical_column",
    "classify_line", "decide_layout", "looks_like_text_lines", "parse_text_url",
]

DEFAULT_BAUD = 115200
DEFAULT_OPEN_TIMEOUT_S = 2.0
OPEN_LINES_WANTED = 8
"""Data lines collected while connecting to decide layout and units ..."""
OPEN_SETTLE_S = 0.5
"""... or as many as arrive within this time after the first one."""
MAX_LINE_BYTES = 4096
READ_SLICE_S = 0.05
"""Port read timeout: the longest a read waits for a first byte before checking its deadline."""

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
        self._timeline = Timeline()

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
        self._timeline = Timeline()
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
            mag_ut_per_lsb=MAG_UNITS[layout.mag_unit] if layout.mag_unit else 1.0,
        )
        self._timeline.start(layout, arrival_period(arrivals))
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
                   "gyro_unit": layout.gyro_unit, "time_unit": layout.time_unit,
                   **({} if layout.mag_unit is None else {"mag_unit": layout.mag_unit})},
            magnetometer=None if layout.mag_unit is None else MagnetometerInfo(
                chip="unknown (text)", odr_hz=self._timeline.rate_hz, range_ut=math.nan,
                ut_per_lsb=MAG_UNITS[layout.mag_unit], path="text lines"),
        )

    def _read(self, timeout_s: float) -> RawBlock | None:
        port = self._port
        assert port is not None
        deadline = time.monotonic() + max(0.0, timeout_s)
        if self._first_block is not None:
            first, self._first_block = self._first_block, None
            return first
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
        classified: list[Line] = []
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
            mag_raw=records.get("mag"),
        )


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
