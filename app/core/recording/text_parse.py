"""The text of format v1, parsed: the metadata and header (:func:`read_head_from`), the rows
(vectorised with :mod:`.fast_csv`, in parallel pieces for large bodies) and the time-order
check (:class:`TimeCheck`). Shared by the whole-file reader (:mod:`.reader`) and the chunked
one (:mod:`.stream`).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import re
import threading
from collections import Counter
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from app.core.bounded_input import open_regular
from app.core.recording import fast_csv
from app.core.recording.compressed import (
    GzipBytes,
    PlainBytes,
    byte_source,
)
from app.core.recording.errors import (
    MissingColumnsError,
    NotARecordingError,
    RecordingCorruptError,
    RecordingVersionError,
)
from app.core.recording.format import (
    FORMAT_VERSION,
    KEY_DEVICE,
    MAGIC,
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
)

PARALLEL_MIN_BYTES = 4 << 20
"""Bodies smaller than this are parsed on one thread."""
MAX_LOAD_VALUES = 64 << 20
"""Numbers :func:`read_recording` loads at most (512 MB as float64; an hour at 1 kHz with
reference columns holds 50 M): a larger recording is refused with
:class:`RecordingTooLargeError`, and is read in chunks instead by the commands that stream."""

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
    return parse_head(data, path), data


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


def parse_head(data: Buffer, path: Path | None) -> RecordingHead:
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


def count_lines(data: Buffer, start: int, stop: int) -> int:
    return int(fast_csv.count_lines(np.frombuffer(data, dtype=np.uint8), start, stop))


def column_kind(name: str) -> int:
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


def row_chunks(data: Buffer, start: int, stop: int) -> list[tuple[int, int]]:
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


def parse_fast(
    data: Buffer, start: int, stop: int, header: tuple[str, ...], kinds: np.ndarray
) -> _Parsed:
    """Parse with the compiled kernel, in parallel pieces; compact around blank lines."""
    buf = np.frombuffer(data, dtype=np.uint8)
    pieces = row_chunks(data, start, stop)
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


def parse_slow(
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
