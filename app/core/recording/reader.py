"""Read a v1 recording: metadata, columns, and clear errors for anything else.

:func:`read_recording` loads a whole file (an hour at 1 kHz in a few seconds: the numbers are
parsed by :mod:`app.core.recording.fast_csv` on every core) and returns a :class:`Recording`;
a compressed recording (format v1 inside gzip, ``.csv.gz``) is read the same way. To read a
long recording in bounded memory, use :class:`app.core.recording.stream.RecordingStream`.

What it tolerates, and says so (a :class:`~app.core.recording.errors.RecordingWarning`, and
the message in :attr:`Recording.warnings`):

- an incomplete last row (no line end: the writer was killed mid-row): dropped;
- a metadata value that is not JSON: kept as its text;
- blank lines, ``\\r\\n`` line ends, spaces around fields, a UTF-8 byte-order mark;
- unknown columns: kept in :attr:`Recording.columns` (numbers, or text when not numbers),
  ignored otherwise.

What it refuses, with a typed error: a file that is not a recording
(:class:`NotARecordingError`), another format version (:class:`RecordingVersionError`), a header
without the required columns (:class:`MissingColumnsError`), and a row that cannot be read
(:class:`RecordingCorruptError`, which names the line and carries the rows before it).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import re
import threading
import warnings
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from app.core.bounded_input import open_regular
from app.core.calibration import SensorCalibration
from app.core.recording import fast_csv
from app.core.recording.compressed import (
    GZIP_MAGIC,
    GzipBytes,
    PlainBytes,
    byte_source,
)
from app.core.recording.errors import (
    MissingColumnsError,
    NotARecordingError,
    RecordingCorruptError,
    RecordingError,
    RecordingTooLargeError,
    RecordingVersionError,
    RecordingWarning,
)
from app.core.recording.format import (
    ACCEL_COLUMNS,
    FORMAT_VERSION,
    GYRO_COLUMNS,
    KEY_BOOKMARKS,
    KEY_CALIBRATION,
    KEY_DEVICE,
    KEY_FILTER,
    KEY_NOTE,
    MAGIC,
    OPTIONAL_COLUMNS,
    REFERENCE_COLUMNS,
    REQUIRED_COLUMNS,
    calibration_from_json,
)
from app.core.samples import RawBlock, SampleBlock, ScaleFactors

UNIT_SCALE = ScaleFactors(
    accel_m_s2_per_lsb=1.0, gyro_rad_s_per_lsb=1.0, temp_degc_per_lsb=1.0, temp_offset_degc=0.0
)
"""Recorded values are already SI: ``x * 1.0 + 0.0`` gives each one back bit for bit."""
PARALLEL_MIN_BYTES = 4 << 20
"""Bodies smaller than this are parsed on one thread."""
CHUNKED_MIN_BYTES = 8 << 20
"""Files at least this large (and every compressed one) are read in chunks, never mapped:
another program may shorten a file while it is read, which a memory map turns into a bus
error, and the text of a large file need not be in memory all at once."""
MAX_LOAD_VALUES = 64 << 20
"""Numbers :func:`read_recording` loads at most (512 MB as float64; an hour at 1 kHz with
reference columns holds 50 M): a larger recording is refused with
:class:`RecordingTooLargeError`, and is read in chunks instead by the commands that stream."""

read_chunked: Callable[..., Recording] | None = None
"""How :func:`read_recording` reads a large or compressed file:
:func:`app.core.recording.stream.read_stream`, installed here when that module loads (the
package imports it). The stream parses with this module, so this module cannot import it."""

MAX_LOAD_BYTES = 2 << 30
"""Text (decompressed) :func:`read_recording` reads at most: ``max_values`` stops real rows
earlier; this stops a file of blank lines."""

Buffer = bytes | bytearray
"""The file's bytes."""

OnCorrupt = Literal["raise", "truncate"]
MAX_HEAD_BYTES = 16 << 20
"""The metadata and header must end within this many bytes (a recording's take a few kB)."""
MAX_LISTED = 10
"""Names a message lists before "... and N more"."""
MAX_WARNINGS = 20
"""Warnings kept per file before "... and N more"."""


@dataclass(frozen=True, slots=True)
class Bookmark:
    """A named moment of a recording; ``t_s`` is on the ``t`` column's clock."""

    t_s: float
    label: str = ""


@dataclass
class Recording:
    """A loaded recording.

    Attributes
    ----------
    metadata : every ``# key: value`` line, JSON-decoded, in file order.
    header : the column names as in the file.
    columns : every column by name: float64 arrays (NaN where empty), or object arrays of
        text for unknown columns that are not numbers.
    path : the file read (None for bytes).
    warnings : what was skipped or tolerated, one message each.
    dropped_partial_row : True when an incomplete last row was dropped.
    corrupt_line : with ``on_corrupt="truncate"``, the line where reading stopped.
    """

    metadata: dict[str, Any]
    header: tuple[str, ...]
    columns: dict[str, np.ndarray]
    path: Path | None = None
    warnings: list[str] = field(default_factory=list)
    dropped_partial_row: bool = False
    corrupt_line: int | None = None
    comments: list[str] = field(default_factory=list)
    _known_reference: bool | None = field(default=None, init=False, repr=False, compare=False)

    # -- samples ---------------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.columns["t"].shape[0])

    @property
    def t_s(self) -> np.ndarray:
        """(N,) device clock, s (a recording need not start at 0)."""
        return self.columns["t"]

    @property
    def accel_m_s2(self) -> np.ndarray:
        """(N, 3) raw specific force, before calibration."""
        return np.column_stack([self.columns[c] for c in ACCEL_COLUMNS])

    @property
    def gyro_rad_s(self) -> np.ndarray:
        """(N, 3) raw angular rate, before calibration."""
        return np.column_stack([self.columns[c] for c in GYRO_COLUMNS])

    @property
    def temp_degc(self) -> np.ndarray:
        """(N,) temperature; NaN when the column is absent or empty."""
        temp = self.columns.get("temp")
        return np.full(len(self), np.nan) if temp is None else temp

    @property
    def gap(self) -> np.ndarray:
        """(N,) bool, True on the first sample after lost data."""
        return self._flag("gap")

    @property
    def block_start(self) -> np.ndarray | None:
        """(N,) bool, True where a device block began; None when not recorded."""
        return self._flag("block_start") if "block_start" in self.columns else None

    @property
    def has_reference(self) -> bool:
        """True when the reference columns exist and hold at least one full quaternion."""
        if self._known_reference is None:  # once: it looks at every row
            self._known_reference = all(c in self.columns for c in REFERENCE_COLUMNS) and bool(
                np.any(np.all(np.isfinite(self._reference()), axis=1)))
        return self._known_reference

    @property
    def reference_quat(self) -> np.ndarray | None:
        """(N, 4) reference orientation (NaN rows where unknown), or None without one."""
        return self._reference() if self.has_reference else None

    @property
    def unknown_columns(self) -> dict[str, np.ndarray]:
        """Columns this version does not know (kept, never used)."""
        known = set(REQUIRED_COLUMNS) | set(OPTIONAL_COLUMNS)
        return {name: values for name, values in self.columns.items() if name not in known}

    def _flag(self, name: str, rows: slice = slice(None)) -> np.ndarray:
        values = self.columns.get(name)
        if values is None:
            return np.zeros(len(range(*rows.indices(len(self)))), dtype=bool)
        values = values[rows]
        return np.isfinite(values) & (values != 0.0)

    def _reference(self, rows: slice = slice(None)) -> np.ndarray:
        return np.column_stack([self.columns[c][rows] for c in REFERENCE_COLUMNS])

    # -- metadata ------------------------------------------------------------------------------
    @property
    def device(self) -> dict[str, Any]:
        """The recorded device description (empty when the file has none)."""
        value = self.metadata.get(KEY_DEVICE)
        return dict(value) if isinstance(value, dict) else {}

    @property
    def calibration(self) -> SensorCalibration | None:
        """The calibration applied while recording (None when absent or unreadable)."""
        value = self.metadata.get(KEY_CALIBRATION)
        if value is None:
            return None
        try:
            return calibration_from_json(value)
        except ValueError:
            return None

    @property
    def filter_name(self) -> str | None:
        value = self.metadata.get(KEY_FILTER)
        return str(value["name"]) if isinstance(value, dict) and "name" in value else None

    @property
    def filter_parameters(self) -> dict[str, Any]:
        value = self.metadata.get(KEY_FILTER)
        params = value.get("parameters") if isinstance(value, dict) else None
        return dict(params) if isinstance(params, dict) else {}

    @property
    def note(self) -> str:
        value = self.metadata.get(KEY_NOTE)
        return value if isinstance(value, str) else ""

    @property
    def bookmarks(self) -> list[Bookmark]:
        """``bookmarks`` metadata: ``[{"t": s, "label": text}, ...]`` or plain times."""
        found = []
        for entry in self.metadata.get(KEY_BOOKMARKS) or []:
            if isinstance(entry, dict) and isinstance(entry.get("t"), int | float):
                found.append(Bookmark(float(entry["t"]), str(entry.get("label", ""))))
            elif isinstance(entry, int | float) and not isinstance(entry, bool):
                found.append(Bookmark(float(entry)))
        return sorted(found, key=lambda b: b.t_s)

    @property
    def duration_s(self) -> float:
        t = self.t_s
        return float(t[-1] - t[0]) if len(t) > 1 else 0.0

    @property
    def rate_hz(self) -> float:
        """Median sample rate (the recorded device's ``odr_hz`` when given)."""
        odr = self.device.get("odr_hz")
        if isinstance(odr, int | float) and odr > 0:
            return float(odr)
        steps = np.diff(self.t_s)
        steps = steps[steps > 0]
        return 1.0 / float(np.median(steps)) if len(steps) else math.nan

    # -- blocks --------------------------------------------------------------------------------
    def raw_block(self, start: int = 0, stop: int | None = None) -> RawBlock:
        """Rows ``[start, stop)`` as a device block in SI units (scale factors of 1.0)."""
        stop = len(self) if stop is None else stop
        rows = slice(start, stop)  # only these rows are touched: replay is linear in length
        temp = self.columns.get("temp")
        return RawBlock(
            t_s=self.t_s[rows],
            accel_raw=np.column_stack([self.columns[c][rows] for c in ACCEL_COLUMNS]),
            gyro_raw=np.column_stack([self.columns[c][rows] for c in GYRO_COLUMNS]),
            temp_raw=np.full(len(self.t_s[rows]), np.nan) if temp is None else temp[rows],
            scale=UNIT_SCALE,
            gap=self._flag("gap", rows),
            reference_quat=self._reference(rows) if self.has_reference else None,
        )

    def block_bounds(self, size: int | None = None) -> np.ndarray:
        """Start indices of the blocks to replay, plus ``len(self)`` at the end.

        ``size=None``: the device's blocks as recorded (``block_start``), else blocks of
        ``size`` samples (also when the file has no ``block_start`` column: 65 536).
        """
        n = len(self)
        starts = self.block_start
        if size is None and starts is not None:
            bounds = np.flatnonzero(starts)
            if len(bounds) == 0 or bounds[0] != 0:
                bounds = np.concatenate([[0], bounds])
        else:
            bounds = np.arange(0, n, size or 65536)
        return np.concatenate([bounds, [n]]).astype(np.int64) if n else np.zeros(1, np.int64)

    def raw_blocks(self, size: int | None = None) -> Iterator[RawBlock]:
        """The whole recording as device blocks (see :meth:`block_bounds`)."""
        bounds = self.block_bounds(size)
        for start, stop in itertools.pairwise(bounds):
            yield self.raw_block(int(start), int(stop))

    def sample_block(self, calibration: SensorCalibration | None = None) -> SampleBlock:
        """Every sample in SI units, with ``calibration`` applied (none when None)."""
        block = SampleBlock(
            t_s=self.t_s, accel_m_s2=self.accel_m_s2, gyro_rad_s=self.gyro_rad_s,
            temp_degc=self.temp_degc, gap=self.gap, reference_quat=self.reference_quat,
        )
        return block if calibration is None else calibration.apply(block)


# -- time order ------------------------------------------------------------------------------
GAP_PERIODS = 5.0
"""A step in ``t`` longer than this many sample periods is lost data: a gap."""
MAX_JUMPS_NAMED = MAX_WARNINGS
"""Unmarked jumps named one by one in the warnings (the rest are marked all the same)."""


@dataclass(slots=True)
class TimeCheck:
    """The time-order rule of format v1, applied to rows as they are read (in chunks too).

    ``t`` must be finite and increase from row to row: the first row that is not after the
    row before it (NaN, a repeat, a step back) is refused, like a row that cannot be read.
    A step longer than :data:`GAP_PERIODS` sample periods is lost data: when the file does
    not mark it, the reader sets ``gap`` on that row (creating the column) and names the line.
    The period is the recorded device's ``odr_hz``, else the median step of the first rows.

    ``last_t`` carries the previous chunk's last time over; ``jumps`` counts the jumps marked.
    """

    period_s: float | None = None
    last_t: float | None = None
    jumps: int = 0

    @classmethod
    def for_metadata(cls, metadata: dict[str, Any]) -> TimeCheck:
        device = metadata.get(KEY_DEVICE)
        odr = device.get("odr_hz") if isinstance(device, dict) else None
        if isinstance(odr, int | float) and not isinstance(odr, bool) and \
                math.isfinite(odr) and odr > 0:
            return cls(period_s=1.0 / float(odr))
        return cls()

    def first_out_of_order(self, t: np.ndarray) -> int | None:
        """Index of the first row whose ``t`` is not finite or not after the row before it
        (None: all in order). Remembers the last time when all are."""
        if not len(t):
            return None
        before = np.empty_like(t)
        before[0] = -math.inf if self.last_t is None else self.last_t
        before[1:] = t[:-1]
        wrong = np.flatnonzero(~(np.isfinite(t) & (t > before)))
        if len(wrong):
            return int(wrong[0])
        self.last_t = float(t[-1])
        return None

    def disorder_text(self, t: np.ndarray, row: int) -> str:
        """Why row ``row`` is refused (for a message that names its line)."""
        value = float(t[row])
        before = float(t[row - 1]) if row else self.last_t
        if not math.isfinite(value):
            return f"t is {value}: every sample needs a finite time"
        if before is not None and value == before:
            return f"t = {value:.9g} repeats the previous row's time (time must increase)"
        return f"t = {value:.9g} is before the previous row's {before:.9g} (time must increase)"

    def mark_jumps(self, columns: dict[str, np.ndarray],
                   previous: float | None = None) -> list[tuple[int, str]]:
        """Set ``gap`` on rows after an unmarked jump; (row, message) for the first few.

        ``t`` must already be in order (:meth:`first_out_of_order`); ``previous`` is the time
        before the first row (None: the first row starts the file or a seek).
        """
        t = columns["t"]
        if self.period_s is None:
            steps = np.diff(t[:20_000])
            if len(steps):
                self.period_s = float(np.median(steps))
        if not len(t) or self.period_s is None or self.period_s <= 0:
            return []
        steps = np.diff(t, prepend=t[0] if previous is None else previous)
        rows = np.flatnonzero(steps > GAP_PERIODS * self.period_s)
        if not len(rows):
            return []
        gap = columns.get("gap")
        if gap is not None and gap.dtype != object:
            rows = rows[~(np.isfinite(gap[rows]) & (gap[rows] != 0.0))]
        if not len(rows):
            return []
        if gap is None or gap.dtype == object:
            gap = columns["gap"] = np.zeros(len(t))
        gap[rows] = 1.0
        named = []
        for row in rows[:max(0, MAX_JUMPS_NAMED - self.jumps)].tolist():
            step = float(steps[row])
            named.append((row, f"t jumps by {step:.6g} s ({step / self.period_s:.0f} sample "
                               "periods) with no gap mark; the row is marked as a gap"))
        self.jumps += len(rows)
        return named


# -- reading ---------------------------------------------------------------------------------------
def read_recording(
    path: str | os.PathLike[str], *, on_corrupt: OnCorrupt = "raise",
    max_bytes: int | None = MAX_LOAD_BYTES, max_values: int = MAX_LOAD_VALUES,
) -> Recording:
    """Load a recording file.

    Parameters
    ----------
    path : the CSV file (a regular file: a FIFO or a device is refused, never waited on).
    on_corrupt : ``"raise"`` (default): a row that cannot be read raises
        :class:`RecordingCorruptError` (with the line number, and the rows before it in
        ``partial``); ``"truncate"``: keep the rows before it, warn, and set
        :attr:`Recording.corrupt_line`.
    max_bytes : refuse (:class:`RecordingTooLargeError`) a recording whose text, decompressed,
        is longer than this (None: no limit but ``max_values``; blank lines count here only).
    max_values : refuse a recording of more numbers than this (rows times columns), so memory
        stays bounded whatever the file (a small ``.csv.gz`` may expand a thousandfold).

    Raises
    ------
    RecordingError
        Subclasses for a foreign file, another version, missing columns, a corrupt row or a
        recording over the limits; a plain :class:`RecordingError` when the file cannot be
        read at all (or becomes shorter while it is read).
    """
    path = Path(path)
    try:
        with open_regular(path) as handle:
            size = os.fstat(handle.fileno()).st_size
            small = handle.read(2) != GZIP_MAGIC and size < CHUNKED_MIN_BYTES
            if small:
                handle.seek(0)
                data = handle.read(CHUNKED_MIN_BYTES)
                small = len(data) < CHUNKED_MIN_BYTES  # else it grew meanwhile: chunks
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read the recording: {exc.strerror or exc}",
                             path) from exc
    if not small:
        if read_chunked is None:  # pragma: no cover (the package installs it)
            raise RuntimeError("app.core.recording.stream was not imported")
        return read_chunked(path, on_corrupt=on_corrupt, max_bytes=max_bytes,
                            max_values=max_values)
    if len(data) < size:
        raise RecordingError(f"{path}: the file became shorter while it was read (another "
                             "program is rewriting it); nothing was loaded", path)
    if max_bytes is not None and len(data) > max_bytes:
        raise RecordingTooLargeError(
            f"{path}: the recording is larger than {max_bytes} bytes", path)
    recording = parse_recording(data, path, on_corrupt=on_corrupt)
    if len(recording) * len(recording.header) > max_values:
        raise RecordingTooLargeError(
            f"{path}: the recording holds more than {max_values} numbers", path)
    return recording


def read_metadata(path: str | os.PathLike[str]) -> tuple[dict[str, Any], tuple[str, ...]]:
    """Only the metadata and the header (reads the beginning of the file; for listings)."""
    head, _ = read_head(Path(path))
    return head.metadata, head.header


def read_head(path: Path) -> tuple[RecordingHead, bytes]:
    """The parsed metadata and header, and the bytes read (at least up to the header)."""
    with open_regular(path) as handle:
        return read_head_from(byte_source(handle, path), path)


def read_head_from(source: PlainBytes | GzipBytes, path: Path) -> tuple[RecordingHead, bytes]:
    """:func:`read_head` from a byte source positioned at the start of the file.

    Refuses (:class:`RecordingCorruptError`) a head that goes on past
    :data:`MAX_HEAD_BYTES`; lines already seen are never scanned again, so this is linear.
    """
    chunk = bytearray()
    scanned = 0
    while True:
        more = source.read(1 << 20)
        chunk += more
        end, scanned = _header_end(chunk, scanned)
        if end is not None or not more:
            break
        if len(chunk) > MAX_HEAD_BYTES:
            raise RecordingCorruptError(
                f"{path}: no header row within the first {MAX_HEAD_BYTES >> 20} MB: the "
                "metadata lines go on and on, this is not a recording that can be read", path)
    data = bytes(chunk)
    return _parse_head(data, path), data


def _header_end(chunk: bytes | bytearray, position: int = 0) -> tuple[int | None, int]:
    """(offset just after the header line, or None while ``chunk`` lacks it; where the
    complete metadata lines seen so far end, to continue from)."""
    while True:
        newline = chunk.find(b"\n", position)
        if newline < 0:
            return None, position
        if not chunk.startswith(b"#", position) and not chunk.startswith(b"\xef\xbb\xbf#",
                                                                          position):
            return newline + 1, position
        position = newline + 1


@dataclass
class RecordingHead:
    """What precedes the rows: metadata, header, and where the body starts (a byte offset)."""

    metadata: dict[str, Any]
    header: tuple[str, ...]
    body_start: int
    header_line: int
    comments: list[str]
    warnings: list[str]


def _describe(line: bytes) -> str:
    """What a foreign first line is, never what it says (the file may be a secret)."""
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError:
        return f"binary data ({len(line)} bytes)"
    if not text.isprintable():
        return f"binary data ({len(line)} bytes)"
    kind = "a CSV line" if "," in text else "a line of text"
    return f"{kind} of {len(text)} characters"


def _parse_head(data: Buffer, path: Path | None) -> RecordingHead:
    where = f"{path}: " if path is not None else ""
    position = 3 if data[:3] == b"\xef\xbb\xbf" else 0
    first_end = data.find(b"\n", position)
    first = data[position: first_end if first_end >= 0 else len(data)].rstrip(b"\r")
    magic = f"# {MAGIC}".encode()
    if not first.startswith(magic):
        shown = "the file is empty" if not data else f"its first line is {_describe(first)}"  # type: ignore[arg-type]
        raise NotARecordingError(
            f"{where}not an inclinometer recording: {shown}, expected "
            f"'# {MAGIC} {FORMAT_VERSION}'", path)
    version = first[len(magic):].strip().decode("utf-8", errors="replace")
    if version != str(FORMAT_VERSION):
        if version.isdigit() and int(version) > FORMAT_VERSION:
            detail = "a newer version of the program wrote it"
        else:
            detail = "this program reads only version 1"
        raise RecordingVersionError(
            f"{where}recording format version {version or '(none)'} is not supported "
            f"({detail}); this program reads format {FORMAT_VERSION}", path, version)
    metadata: dict[str, Any] = {}
    comments: list[str] = []
    problems: list[str] = []
    line_number = 1
    position = first_end + 1 if first_end >= 0 else len(data)
    while True:
        end = data.find(b"\n", position)
        if end < 0:
            raise RecordingCorruptError(
                f"{where}the file ends before its header row (line {line_number + 1}): "
                "no samples were recorded", path, line_number + 1)
        line_number += 1
        raw = data[position:end].rstrip(b"\r")
        position = end + 1
        if not raw.startswith(b"#"):
            break
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            problems.append(f"line {line_number}: metadata line is not UTF-8; skipped")
            continue
        key, separator, value = text[2:].partition(": ")
        if not text.startswith("# ") or not separator or not key.strip():
            comments.append(text)
            continue
        key = key.strip()
        try:
            decoded = json.loads(value)
        except json.JSONDecodeError:
            decoded = value.strip()
            problems.append(f"line {line_number}: metadata {_short(key)} is not JSON; kept "
                            "as text")
        except RecursionError:  # JSON nested deeper than any recording writes
            decoded = value.strip()
            problems.append(f"line {line_number}: metadata {_short(key)} is nested too "
                            "deeply to read; kept as text")
        if key in metadata:
            problems.append(f"line {line_number}: metadata {_short(key)} appears again; "
                            "the last value is kept")
        metadata[key] = decoded
    try:
        header_text = raw.decode("utf-8").lstrip("\ufeff")
    except UnicodeDecodeError:
        raise RecordingCorruptError(
            f"{where}line {line_number}: the header row is not UTF-8 text", path,
            line_number) from None
    names = next(csv.reader([header_text])) if header_text.strip() else []
    header = tuple(name.strip() for name in names)
    counts = Counter(header)
    duplicates = sorted(name for name, count in counts.items() if count > 1)
    if duplicates:
        raise RecordingCorruptError(
            f"{where}line {line_number}: the header names {_listing(duplicates)} more than "
            "once", path, line_number)
    missing = [name for name in REQUIRED_COLUMNS if name not in counts]
    if missing:
        raise MissingColumnsError(
            f"{where}line {line_number}: the header lacks the required column(s) "
            f"{', '.join(missing)} (it has: {_listing(header) or 'nothing'}); required are "
            f"{', '.join(REQUIRED_COLUMNS)}", path, missing)
    return RecordingHead(metadata, header, position, line_number, comments,
                         _bounded(problems))


def _short(text: str, limit: int = 40) -> str:
    """``repr`` of a name, cut to about ``limit`` characters."""
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _listing(items: Sequence[str], limit: int = MAX_LISTED) -> str:
    """``a, b, c ... and N more``: names for a message, never the whole of a hostile list."""
    shown = ", ".join(item if len(item) <= 40 else item[:40] + "..." for item in items[:limit])
    return shown + (f" ... and {len(items) - limit} more" if len(items) > limit else "")


def _bounded(problems: list[str], limit: int = MAX_WARNINGS) -> list[str]:
    """At most ``limit`` messages, then one that counts the rest."""
    if len(problems) <= limit:
        return problems
    return [*problems[:limit], f"... and {len(problems) - limit} more such problems"]


def parse_recording(
    data: Buffer, path: Path | None = None, *, on_corrupt: OnCorrupt = "raise"
) -> Recording:
    """:func:`read_recording` on bytes already in memory."""
    if on_corrupt not in ("raise", "truncate"):
        raise ValueError(f"on_corrupt must be 'raise' or 'truncate', not {on_corrupt!r}")
    head = _parse_head(data, path)
    where = f"{path}: " if path is not None else ""
    problems = list(head.warnings)
    stop = data.rfind(b"\n") + 1
    stop = max(stop, head.body_start)
    dropped = False
    tail = data[stop:]
    if tail.strip(b" \t\r\x00"):
        line = head.header_line + _count_lines(data, head.body_start, stop) + 1
        problems.append(
            f"{where}line {line}: the last row is incomplete (the recording was interrupted "
            "while writing it); it was dropped")
        dropped = True
    kinds = np.array([_kind(name) for name in head.header], dtype=np.int8)
    parse = _parse_slow if data.find(b'"', head.body_start, stop) >= 0 else _parse_fast
    columns, rows, error, offsets = parse(data, head.body_start, stop, head.header, kinds)
    clock = TimeCheck.for_metadata(head.metadata)
    bad = clock.first_out_of_order(columns["t"])
    if bad is not None:  # before any row the parser could not read
        error = (int(offsets[bad]), clock.disorder_text(columns["t"], bad))
        columns = {name: values[:bad] for name, values in columns.items()}
        rows = bad
    named = clock.mark_jumps(columns)
    for row, text in named:
        line = _count_lines(data, 0, int(offsets[row])) + 1
        problems.append(f"{where}line {line}: {text}")
    if clock.jumps > len(named):
        problems.append(f"{where}{clock.jumps} unmarked jumps in t in all were marked as gaps")
    recording = Recording(
        metadata=head.metadata, header=head.header, columns=columns, path=path,
        warnings=problems, dropped_partial_row=dropped, comments=head.comments,
    )
    if error is not None:
        offset, message = error
        line = _count_lines(data, 0, offset) + 1
        text = f"{where}line {line}: {message}; the {rows} row(s) before it are valid"
        if on_corrupt == "raise":
            _warn_all(problems)
            raise RecordingCorruptError(text, path, line, recording)
        recording.corrupt_line = line
        problems.append(f"{text}; reading stopped there")
    _warn_all(problems)
    return recording


def _warn_all(messages: list[str]) -> None:
    for message in messages:
        warnings.warn(message, RecordingWarning, stacklevel=4)


def _count_lines(data: Buffer, start: int, stop: int) -> int:
    return int(fast_csv.count_lines(np.frombuffer(data, dtype=np.uint8), start, stop))


def _kind(name: str) -> int:
    if name in REQUIRED_COLUMNS:
        return fast_csv.KIND_REQUIRED
    if name in OPTIONAL_COLUMNS:
        return fast_csv.KIND_OPTIONAL
    return fast_csv.KIND_LENIENT


_ERRORS = {
    fast_csv.ERROR_NUMBER: "column {column!r} holds {field}, which is not a number",
    fast_csv.ERROR_EMPTY: "the required column {column!r} is empty",
    fast_csv.ERROR_TOO_FEW: "the row has {count} field(s), the header has {expected}",
    fast_csv.ERROR_TOO_MANY: "the row has more fields than the header's {expected}",
}
_NUMBER = re.compile(
    r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)", re.IGNORECASE
)

_Parsed = tuple[dict[str, np.ndarray], int, tuple[int, str] | None, np.ndarray]
"""(columns, rows kept, (byte offset of the bad line, message) or None, each kept row's byte
offset)."""


def _error_text(fields: list[str], code: int, column: int, header: tuple[str, ...]) -> str:
    name = header[column] if column < len(header) else f"#{column + 1}"
    field_text = repr(fields[column].strip()[:40]) if column < len(fields) else "''"
    return _ERRORS[code].format(column=name, field=field_text, count=len(fields),
                                expected=len(header))


def _line_fields(data: Buffer, offset: int) -> list[str]:
    end = data.find(b"\n", offset)
    line = data[offset: end if end >= 0 else len(data)].rstrip(b"\r")
    text = line.decode("utf-8", errors="replace")
    return next(csv.reader([text])) if '"' in text else text.split(",")


def _chunks(data: Buffer, start: int, stop: int) -> list[tuple[int, int]]:
    """Split ``[start, stop)`` at line ends into about one piece per core."""
    size = stop - start
    count = 1 if size < PARALLEL_MIN_BYTES else max(1, min(os.cpu_count() or 1, 8))
    bounds = [start]
    for k in range(1, count):
        cut = data.find(b"\n", start + size * k // count, stop)
        if cut < 0 or cut + 1 <= bounds[-1]:
            continue
        bounds.append(cut + 1)
    bounds.append(stop)
    return [(a, b) for a, b in itertools.pairwise(bounds) if b > a]


def _parse_fast(
    data: Buffer, start: int, stop: int, header: tuple[str, ...], kinds: np.ndarray
) -> _Parsed:
    """Parse with the compiled kernel, in parallel pieces; compact around blank lines."""
    buf = np.frombuffer(data, dtype=np.uint8)
    pieces = _chunks(data, start, stop)
    pool = _parser_pool() if len(pieces) > 1 else None
    try:
        return _parse_pieces(data, buf, pieces, pool, header, kinds)
    finally:
        del buf


_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _parser_pool() -> ThreadPoolExecutor:
    """One pool of parser threads for the process (a streamed read parses hundreds of
    chunks: starting threads for each cost more than some chunks take)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max(1, min(os.cpu_count() or 1, 8)),
                                       thread_name_prefix="recording-parser")
        return _POOL


def _parse_pieces(
    data: Buffer, buf: np.ndarray, pieces: list[tuple[int, int]],
    pool: ThreadPoolExecutor | None, header: tuple[str, ...], kinds: np.ndarray,
) -> _Parsed:
    ncols = len(kinds)

    def lines(piece: tuple[int, int]) -> int:
        # Room for the lines that are not blank, and never more than the bytes can hold: a
        # kept row has its required fields, ncols - 1 commas and a line end (room for every
        # line asked 700 MB for 8 MB of line ends).
        most = (piece[1] - piece[0]) // (ncols + len(REQUIRED_COLUMNS)) + 1
        lines = int(fast_csv.count_lines(buf, piece[0], piece[1]))  # the fast count first
        return lines if lines <= most else min(most, int(fast_csv.count_rows(buf, *piece)))

    counts = list(pool.map(lines, pieces)) if pool is not None else [lines(p) for p in pieces]
    first_rows = [0, *itertools.accumulate(counts)]
    capacity = first_rows[-1]
    values = np.empty(ncols * capacity)
    flags = np.zeros(ncols * capacity, dtype=np.uint8)
    offsets = np.zeros(capacity, dtype=np.int64)

    def run(index: int) -> tuple[int, int, int, int]:
        a, b = pieces[index]
        return fast_csv.parse_body(
            buf, a, b, kinds, first_rows[index], capacity, values, values.view(np.int64),
            flags, offsets, fast_csv.POW5_HIGH, fast_csv.POW5_LOW, fast_csv.EXACT_POWERS_OF_TEN)

    if pool is not None:
        results = list(pool.map(run, range(len(pieces))))
    else:
        results = [run(0) for _ in pieces]
    error = None
    ranges = []
    for index, (parsed, code, offset, column) in enumerate(results):
        ranges.append((first_rows[index], first_rows[index] + parsed))
        if code != fast_csv.ERROR_NONE:
            error = (offset, _error_text(_line_fields(data, offset), code, column, header))
            break
    table = values.reshape(ncols, capacity)
    cell_flags = flags.reshape(ncols, capacity)
    contiguous = all(ranges[k][1] == ranges[k + 1][0] for k in range(len(ranges) - 1))
    if contiguous:
        kept = ranges[-1][1] if ranges else 0
        table, cell_flags, offsets = table[:, :kept], cell_flags[:, :kept], offsets[:kept]
    else:  # blank lines left holes
        keep = np.concatenate([np.arange(a, b) for a, b in ranges])
        table, cell_flags, offsets = table[:, keep], cell_flags[:, keep], offsets[keep]
    # The rare cells the kernel leaves to Python (see fast_csv), then text columns.
    for col, row in zip(*np.nonzero(cell_flags == fast_csv.FLAG_SLOW)):
        table[col, row] = float(_line_fields(data, int(offsets[row]))[col].strip())
    columns: dict[str, np.ndarray] = {}
    for col, name in enumerate(header):
        if np.any(cell_flags[col] == fast_csv.FLAG_TEXT):
            columns[name] = np.array(
                [_line_fields(data, int(o))[col].strip() for o in offsets.tolist()], dtype=object)
        else:
            columns[name] = table[col]
    return columns, int(offsets.shape[0]), error, offsets


def _parse_slow(
    data: Buffer, start: int, stop: int, header: tuple[str, ...], kinds: np.ndarray
) -> _Parsed:
    """Line by line with the csv module: for files with quoted fields (rare, slow)."""
    ncols = len(kinds)
    cells: list[list[float | str]] = [[] for _ in range(ncols)]
    text_columns: set[int] = set()
    error = None
    offset = start
    rows = 0
    row_offsets: list[int] = []
    while offset < stop:
        end = data.find(b"\n", offset)
        line_offset, offset = offset, end + 1
        raw = data[line_offset:end].rstrip(b"\r")
        if not raw.strip(b" \t"):
            continue
        try:
            fields = next(csv.reader([raw.decode("utf-8")]))
        except (UnicodeDecodeError, csv.Error) as exc:
            error = (line_offset, f"the row cannot be read as CSV ({exc})")
            break
        code, column = fast_csv.ERROR_NONE, -1
        if len(fields) < ncols:
            code, column = fast_csv.ERROR_TOO_FEW, len(fields)
        elif len(fields) > ncols:
            code, column = fast_csv.ERROR_TOO_MANY, ncols
        values: list[float | str] = []
        for col in range(ncols if code == fast_csv.ERROR_NONE else 0):
            text = fields[col].strip(" \t")
            if not text:
                if kinds[col] == fast_csv.KIND_REQUIRED:
                    code, column = fast_csv.ERROR_EMPTY, col
                    break
                values.append(math.nan)
            elif _NUMBER.fullmatch(text):
                values.append(float(text))
            elif kinds[col] == fast_csv.KIND_LENIENT:
                values.append(text)
                text_columns.add(col)
            else:
                code, column = fast_csv.ERROR_NUMBER, col
                break
        if code != fast_csv.ERROR_NONE:
            error = (line_offset, _error_text(fields, code, column, header))
            break
        for col, value in enumerate(values):
            cells[col].append(value)
        row_offsets.append(line_offset)
        rows += 1
    columns: dict[str, np.ndarray] = {}
    for col, name in enumerate(header):
        if col in text_columns:
            columns[name] = np.array([str(v) for v in cells[col]], dtype=object)
        else:
            columns[name] = np.array(cells[col], dtype=np.float64)
    return columns, rows, error, np.array(row_offsets, dtype=np.int64)
