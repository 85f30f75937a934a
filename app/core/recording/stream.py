"""Read a recording in chunks: bounded memory and linear time, plain CSV or CSV inside gzip.

:class:`RecordingStream` opens a file, reads its metadata and header (the first kilobytes) and
then yields :class:`Chunk` s of rows, each parsed by the same compiled kernel as
:func:`~app.core.recording.reader.read_recording`. Memory is one chunk (about
:data:`CHUNK_BYTES` of text and its numbers), whatever the file's length; nothing done per
chunk looks at the rest of the file.

Compressed recordings (``.csv.gz``, format v1 inside gzip) are recognised by their first
bytes, not their name. The recorder writes one gzip member per durable write (RFC 1952 allows
any number of members; ``zcat`` and every gzip reader read them as one stream), so a file cut
short by a crash reads up to its last complete member, and :meth:`RecordingStream.seek` can
start decompressing at any member without reading what comes before it.

Row blocks as the device delivered them (the ``block_start`` column) may straddle two chunks:
:func:`device_blocks` carries the unfinished block over, so a replay hands every filter
exactly the blocks it got live.
"""

from __future__ import annotations

import itertools
import os
import queue
import threading
import warnings
from collections.abc import Generator, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, TypeVar, overload

import numpy as np

from app.core.bounded_input import open_regular
from app.core.recording.compressed import GzipBytes, PlainBytes, byte_source
from app.core.recording.errors import (
    RecordingCorruptError,
    RecordingError,
    RecordingTooLargeError,
    RecordingWarning,
)
from app.core.recording.format import REFERENCE_COLUMNS
from app.core.recording.table import Recording
from app.core.recording.text_parse import (
    MAX_JUMPS_NAMED,
    MAX_LOAD_BYTES,
    MAX_LOAD_VALUES,
    RecordingHead,
    TimeCheck,
    column_kind,
    count_lines,
    parse_fast,
    parse_slow,
    read_head_from,
)
from app.core.samples import RawBlock

T = TypeVar("T")
CHUNK_BYTES = 8 << 20
"""Text read and parsed at a time (about 37 k rows of a 6667 Hz recording)."""
WHOLE_CHUNK_BYTES = 32 << 20
"""Chunks of :func:`read_stream`, which keeps every row anyway: larger pieces for the parser
threads, fewer waits for the slowest of them."""
MAX_LINE_BYTES = 16 << 20
"""A line longer than this is refused (a row takes about 200 bytes): memory stays bounded
whatever the file holds, ``/dev/zero``-like data or a line a gigabyte long."""


@dataclass(slots=True)
class Chunk:
    """Consecutive rows of a recording.

    ``rows`` is a :class:`Recording` of just these rows (the file's metadata and header);
    ``first_row`` the index of its first row in the file, ``offset`` the (decompressed) byte
    offset where its first line starts and ``line`` that line's number.
    """

    rows: Recording
    first_row: int
    offset: int
    line: int

    def __len__(self) -> int:
        return len(self.rows)


class RecordingStream:
    """An open recording read in chunks (use as a context manager, or call :meth:`close`).

    Raises the reader's typed errors (:class:`~app.core.recording.errors.RecordingError`
    subclasses) for a file that is not a recording, another version or missing columns, at
    once; a bad row raises :class:`RecordingCorruptError` from :meth:`chunks` after the chunk
    of rows before it.
    """

    def __init__(self, path: str | os.PathLike[str], *, chunk_bytes: int | None = None) -> None:
        self.path = Path(path)
        self.chunk_bytes = int(CHUNK_BYTES if chunk_bytes is None else chunk_bytes)
        try:
            self._handle: BinaryIO = open_regular(self.path)  # closed in close()
            self._size_at_open = os.fstat(self._handle.fileno()).st_size
        except OSError as exc:
            raise RecordingError(f"{self.path}: cannot read the recording: "
                                 f"{exc.strerror or exc}", self.path) from exc
        try:
            self._bytes: PlainBytes | GzipBytes = byte_source(self._handle, self.path)
            self.compressed = isinstance(self._bytes, GzipBytes)
            self.head = self._read_head()
        except BaseException:
            self._handle.close()
            raise
        self._kinds = np.array([column_kind(name) for name in self.head.header], dtype=np.int8)
        self.warnings: list[str] = list(self.head.warnings)
        self._has_reference_columns = all(c in self.head.header for c in REFERENCE_COLUMNS)
        self._clock = TimeCheck.for_metadata(self.head.metadata)
        self._told: set[str] = set()

    def _read_head(self) -> RecordingHead:
        head, data = read_head_from(self._bytes, self.path)
        self._body = data[head.body_start:]  # already read: the first rows
        return head

    @property
    def metadata(self) -> dict:
        return self.head.metadata

    @property
    def header(self) -> tuple[str, ...]:
        return self.head.header

    @property
    def members(self) -> list[tuple[int, int]]:
        """Gzip members seen so far: (compressed offset, decompressed offset); [] when plain."""
        return list(self._bytes.members) if isinstance(self._bytes, GzipBytes) else []

    def adopt_members(self, members: list[tuple[int, int]]) -> None:
        """Learn gzip member starts another reader of the same file found (its index), so a
        seek decompresses from the nearest one instead of from the last one this reader saw."""
        if isinstance(self._bytes, GzipBytes) and len(members) > len(self._bytes.members):
            self._bytes.members = sorted(set(self._bytes.members) | set(members))

    def file_size(self) -> int:
        return os.fstat(self._handle.fileno()).st_size

    def close(self) -> None:
        self._handle.close()

    def __enter__(self) -> RecordingStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def chunks(
        self, offset: int | None = None, first_row: int = 0, line: int | None = None,
        max_bytes: int | None = None,
    ) -> Generator[Chunk, None, None]:
        """The rows from the body's start, or from a line start at ``offset`` (decompressed
        bytes, as :attr:`Chunk.offset` gives; ``first_row`` and ``line`` then say which row
        and line that is). Warns (:class:`RecordingWarning`) for an incomplete last row.
        With ``max_bytes``, raises :class:`RecordingTooLargeError` past that offset."""
        if offset is None or offset == self.head.body_start:
            offset = self.head.body_start
            line = self.head.header_line + 1
            self._bytes.seek(self.head.body_start + len(self._body))
            carry = self._body
        else:
            self._bytes.seek(offset)
            carry = b""
        line = self.head.header_line + 1 if line is None else line
        clock = self._clock if first_row == 0 else TimeCheck(self._clock.period_s)
        clock.last_t = None
        clock.jumps = 0
        row = first_row
        pending: list[bytes] = [carry] if carry else []
        while True:
            more = self._bytes.read(self.chunk_bytes)
            ended = not more
            if more and b"\n" not in more:
                pending.append(more)  # a long line: gather it without copying it twice
                if sum(len(p) for p in pending) <= MAX_LINE_BYTES:
                    continue
                if b"\n" not in pending[0]:  # bounded memory, whatever the file holds
                    raise RecordingCorruptError(
                        f"{self.path}: line {line} is longer than {MAX_LINE_BYTES >> 20} MB "
                        f"(a row takes about 200 bytes): this is not a recording's row; the "
                        f"{row} row(s) before it are valid", self.path, line)
                more = b""  # in pending already: parse the lines before the long one first
            data = b"".join([*pending, more])
            pending = []
            cut = data.rfind(b"\n") + 1
            if ended and not cut:  # the end: only an unfinished row, if anything, is left
                self._end(data, line)
                return
            body = data  # its lines up to ``cut`` (a slice would copy them)
            parse = parse_slow if body.find(b'"', 0, cut) >= 0 else parse_fast
            columns, rows, error, offsets = parse(body, 0, cut, self.head.header, self._kinds)
            previous = clock.last_t
            bad = clock.first_out_of_order(columns["t"])
            if bad is not None:  # refused like a row that cannot be read, before any such
                error = (int(offsets[bad]), clock.disorder_text(columns["t"], bad))
                columns = {name: values[:bad] for name, values in columns.items()}
                rows = bad
            counted = clock.jumps
            for at_row, text in clock.mark_jumps(columns, previous):
                self._warn(f"{self.path}: line "
                           f"{line + count_lines(body, 0, int(offsets[at_row]))}: {text}")
            if clock.jumps > counted and clock.jumps > MAX_JUMPS_NAMED and \
                    counted <= MAX_JUMPS_NAMED:
                self._warn(f"{self.path}: more unmarked jumps in t follow; each is marked as "
                           "a gap")
            recording = Recording(metadata=self.head.metadata, header=self.head.header,
                                  columns=columns, path=self.path)
            # Every chunk carries the reference columns the header has (NaN where unknown),
            # so chunks join; whether any row knows it is for the whole file to say.
            recording._known_reference = self._has_reference_columns
            if rows:
                yield Chunk(recording, row, offset, line)
            if error is not None:
                bad, message = error
                at = line + count_lines(body, 0, bad)
                raise RecordingCorruptError(
                    f"{self.path}: line {at}: {message}; the {row + rows} row(s) before it "
                    "are valid", self.path, at)
            line += count_lines(body, 0, cut)
            row += rows
            offset += cut
            if max_bytes is not None and offset > max_bytes:
                raise RecordingTooLargeError(
                    f"{self.path}: the recording is larger than {max_bytes} bytes"
                    + (" when decompressed" if self.compressed else ""), self.path)
            tail = data[cut:]
            if ended:
                self._end(tail, line)
                return
            if tail:
                pending.append(tail)

    def _warn(self, message: str) -> None:
        """Warn once per stream (a replay reads its file again on every loop and seek)."""
        if message in self._told or len(self._told) > 2 * MAX_JUMPS_NAMED:
            return
        self._told.add(message)
        self.warnings.append(message)
        warnings.warn(message, RecordingWarning, stacklevel=4)

    def _end(self, tail: bytes, line: int) -> None:
        if not self.compressed and self._handle.tell() < self._size_at_open:
            raise RecordingError(
                f"{self.path}: the file became shorter while it was read (another program is "
                f"rewriting it); reading stopped at line {line}", self.path)
        problems = []
        if tail.strip(b" \t\r\n\x00"):
            problems.append(f"{self.path}: line {line}: the last row is incomplete (the "
                            "recording was interrupted while writing it); it was dropped")
        if self._bytes.truncated:
            problems.append(f"{self.path}: the compressed file ends early (the recording was "
                            "interrupted); everything up to its last complete write was read")
        for message in problems:
            self.warnings.append(message)
            warnings.warn(message, RecordingWarning, stacklevel=3)


def read_stream(path: str | os.PathLike[str], *, on_corrupt: str = "raise",
                max_bytes: int | None = MAX_LOAD_BYTES,
                max_values: int = MAX_LOAD_VALUES) -> Recording:
    """A whole recording read through :class:`RecordingStream` (compressed or large files).

    Same contract as :func:`~app.core.recording.reader.read_recording` (``max_bytes`` counts
    decompressed text, so a small ``.csv.gz`` that expands a thousandfold is stopped early).
    Each chunk's numbers go straight into one table reserved for ``max_values`` numbers: only
    the pages written become memory, so memory is the numbers loaded plus one chunk.
    """
    with RecordingStream(path, chunk_bytes=WHOLE_CHUNK_BYTES) as stream:
        loaded = _Loaded(stream, max_values)
        corrupt: RecordingCorruptError | None = None
        try:
            for chunk in prefetched(stream.chunks(max_bytes=max_bytes)):
                loaded.add(chunk)
        except RecordingCorruptError as exc:
            corrupt = exc
        recording = loaded.recording()
        recording.warnings = list(stream.warnings)
        if corrupt is not None:
            if on_corrupt == "raise":
                corrupt.partial = recording
                raise corrupt
            recording.corrupt_line = corrupt.line
            recording.warnings.append(f"{corrupt}; reading stopped there")
            warnings.warn(recording.warnings[-1], RecordingWarning, stacklevel=2)
        recording.dropped_partial_row = any("incomplete" in w for w in recording.warnings)
        recording.comments = list(stream.head.comments)
        return recording




class _Loaded:
    """The rows of consecutive chunks, gathered for one :class:`Recording`.

    Numbers go into a (columns, rows) table reserved at once for ``max_values`` (virtual
    memory: pages never written cost nothing), so nothing is copied twice and the heap does
    not keep the pieces of a join. Text cells (unknown columns) and a ``gap`` column the time
    check added are kept per chunk and placed at the end.
    """

    def __init__(self, stream: RecordingStream, max_values: int) -> None:
        self.stream = stream
        self.names = list(stream.header)
        self.max_values = max_values
        self.capacity = max_values // max(len(self.names), 1)
        self.table = np.empty((len(self.names), self.capacity))
        self.texts: dict[int, list[tuple[int, np.ndarray]]] = {}
        self.gaps: list[tuple[int, np.ndarray]] = []
        self.rows = 0

    def add(self, chunk: Chunk) -> None:
        n = len(chunk)
        if self.rows + n > self.capacity:
            raise RecordingTooLargeError(
                f"{self.stream.path}: the recording holds more than {self.max_values} numbers "
                f"(over {self.rows} rows): too large to load at once"
                + (" (decompressed)" if self.stream.compressed else ""), self.stream.path)
        columns = chunk.rows.columns
        for index, name in enumerate(self.names):
            if columns[name].dtype == object:
                self.texts.setdefault(index, []).append((self.rows, columns[name]))
            else:
                self.table[index, self.rows:self.rows + n] = columns[name]
        if "gap" not in self.names and "gap" in columns:
            self.gaps.append((self.rows, columns["gap"]))
        self.rows += n

    def recording(self) -> Recording:
        rows = self.rows
        columns: dict[str, np.ndarray] = {}
        for index, name in enumerate(self.names):
            column = self.table[index, :rows]
            if index in self.texts:
                column = column.astype(object)
                for start, values in self.texts[index]:
                    column[start:start + len(values)] = values
            columns[name] = column
        if self.gaps:
            gap = columns["gap"] = np.zeros(rows)
            for start, values in self.gaps:
                gap[start:start + len(values)] = values
        return Recording(metadata=self.stream.metadata, header=self.stream.header,
                         columns=columns, path=self.stream.path)


# -- reading ahead ----------------------------------------------------------------------------
_DONE = object()


def prefetched(items: Iterator[T], depth: int = 1) -> Iterator[T]:
    """``items`` produced one step ahead in a thread: the next chunk is read and parsed (the
    parser's kernels release the GIL) while the caller works on this one. Exceptions reach the
    caller in order; closing the generator stops the thread."""
    ready: queue.Queue[Any] = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def produce() -> None:
        try:
            for item in items:
                while not stop.is_set():
                    try:
                        ready.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            ready.put(_DONE)
        except BaseException as exc:  # handed to the consumer
            ready.put(exc)

    thread = threading.Thread(target=produce, name="recording-prefetch", daemon=True)
    thread.start()
    try:
        while True:
            item = ready.get()
            if item is _DONE:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        thread.join()


# -- device blocks across chunks ------------------------------------------------------------
def _join(first: RawBlock, second: RawBlock) -> RawBlock:
    ref = (None if first.reference_quat is None or second.reference_quat is None
           else np.concatenate([first.reference_quat, second.reference_quat]))
    return RawBlock(
        t_s=np.concatenate([first.t_s, second.t_s]),
        accel_raw=np.concatenate([first.accel_raw, second.accel_raw]),
        gyro_raw=np.concatenate([first.gyro_raw, second.gyro_raw]),
        temp_raw=np.concatenate([first.temp_raw, second.temp_raw]),
        scale=first.scale,
        gap=np.concatenate([first.gap, second.gap]),  # type: ignore[list-item]
        reference_quat=ref,
        mag_raw=None if first.mag_raw is None or second.mag_raw is None
        else np.concatenate([first.mag_raw, second.mag_raw]),
    )


@overload
def device_blocks(chunks: Iterator[Chunk], size: int | None = None) -> Iterator[RawBlock]: ...


@overload
def device_blocks(chunks: Iterator[Chunk], size: int | None,
                  extra: Sequence[str]) -> Iterator[tuple[RawBlock, dict[str, np.ndarray]]]: ...


def device_blocks(chunks: Iterator[Chunk], size: int | None = None,
                  extra: Sequence[str] | None = None) -> Iterator[Any]:
    """The rows as device blocks, exactly as :meth:`Recording.raw_blocks` cuts a whole file.

    ``size=None``: the blocks the device delivered (``block_start``), else blocks of ``size``
    rows counted from the file's first row. A block cut by a chunk's end is completed from
    the next chunk. With ``extra`` (column names), each block comes with those columns'
    values for its rows (a name the file lacks is left out).
    """
    if extra is None:
        for block, _ in _device_blocks(chunks, size, ()):
            yield block
    else:
        yield from _device_blocks(chunks, size, tuple(extra))


def _device_blocks(chunks: Iterator[Chunk], size: int | None,
                   extra: tuple[str, ...]) -> Iterator[tuple[RawBlock, dict[str, np.ndarray]]]:
    carry: tuple[RawBlock, dict[str, np.ndarray]] | None = None
    for chunk in chunks:
        rows = chunk.rows
        n = len(rows)
        if size is None and "block_start" in rows.columns:
            starts = np.flatnonzero(rows.block_start).tolist()  # type: ignore[arg-type]
        else:
            step = size or 65536
            starts = list(range((-chunk.first_row) % step, n, step))
        continues = not starts or starts[0] != 0
        bounds = ([0] if continues else []) + starts + [n]
        blocks = [(rows.raw_block(a, b),
                   {k: rows.columns[k][a:b] for k in extra if k in rows.columns})
                  for a, b in itertools.pairwise(bounds) if b > a]
        if carry is not None:
            if continues and blocks:
                blocks[0] = (_join(carry[0], blocks[0][0]),
                             {k: np.concatenate([carry[1][k], v]) for k, v in blocks[0][1].items()
                              if k in carry[1]})
            else:
                yield carry
            carry = None
        if blocks:
            carry = blocks.pop()
        yield from blocks
    if carry is not None:
        yield carry
