"""Write a v1 recording from a background thread that survives crashes and full disks.

The producer (the device worker, or the headless ``record`` command) calls
:meth:`RecordingWriter.write` with each :class:`~app.core.samples.RawBlock` it processes: a
non-blocking queue put. The writer thread converts the block to SI exactly as the pipeline
does (:func:`~app.core.samples.convert_raw_block`), formats whole rows and writes them.

Durability
----------
- Rows are written whole; the file is flushed to the OS and ``fsync``-ed at most
  ``flush_interval_s`` (0.5 s) after the oldest unwritten row arrived, so at most about a second
  of data is at risk in a power cut. After a SIGKILL everything written to the OS is in the
  file; at worst its last row is incomplete, and the reader drops it with a warning.
- A write error (a full disk: ``ENOSPC``; a file-size limit: ``EFBIG``; a vanished USB stick)
  stops the recording: the file is cut back to its last complete row, closed, and kept; the
  message is in :attr:`WriterStatus.error` and goes to ``on_error``. Later blocks are refused
  (``write`` returns False).

Numbers are written with ``repr``: the shortest text that reads back as the same float64.
Recorded raw values are LSB counts times a scale factor, e.g. ``1234 * 0.0011964113`` =
``1.4763715442``; fewer digits would not give the same bits back, and more are never needed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import logging
import os
import queue
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import orjson

from app.core.recording.compressed import gzip_member
from app.core.recording.errors import RecordingWriteError
from app.core.recording.format import (
    KEY_MAGNETOMETER,
    KEY_REFERENCE,
    MAG_COLUMNS,
    REFERENCE_COLUMNS,
    REQUIRED_COLUMNS,
    metadata_text,
)
from app.core.safe_output import OutputLock, OutputRefused, check_output
from app.core.samples import RawBlock, SampleBlock, convert_raw_block, slice_block

log = logging.getLogger(__name__)

DEFAULT_FLUSH_INTERVAL_S = 0.5
"""Longest time a row waits before it is flushed and fsynced."""
WRITE_CHUNK_BYTES = 1 << 20
"""Formatted rows are handed to the OS at least every this many bytes."""
FORMAT_ROWS = 512
"""Rows formatted per call (bounds how long the thread holds the GIL in one C call)."""
GZIP_LEVEL = 1
"""zlib level 1: 40 % of the plain size at about 110 MB/s (level 6: 34 % at 20 MB/s)."""
DEFAULT_MAX_PENDING_ROWS = 20_000_000
"""Rows queued but not written after which the recording stops (the disk cannot keep up)."""

BASE_COLUMNS = (*REQUIRED_COLUMNS, "temp", "gap", "block_start")
"""Columns every recording made here has; the magnetometer's and then the reference columns
follow when present."""

Opener = Callable[[Path, str], BinaryIO]
"""Opens the file: ``opener(path, mode)`` with mode ``"xb"`` or ``"wb"``, unbuffered."""


def _open_unbuffered(path: Path, mode: str) -> BinaryIO:
    return open(path, mode, buffering=0)  # type: ignore[return-value]


@dataclass(frozen=True, slots=True)
class WriterStatus:
    """A snapshot of the writer (thread-safe to read).

    Attributes
    ----------
    state : ``"new"``, ``"recording"``, ``"stopped"`` (closed normally) or ``"failed"``.
    rows_written : complete rows in the file (handed to the OS).
    rows_synced : rows known to be on the disk (fsync returned).
    bytes_written : size of the file's complete rows, metadata included.
    pending_rows : rows queued and not yet written.
    last_t_s : device time of the last row written, None before the first.
    error : what stopped a failed recording, written for the user.
    """

    path: Path
    state: str
    rows_written: int = 0
    rows_synced: int = 0
    bytes_written: int = 0
    pending_rows: int = 0
    first_t_s: float | None = None
    last_t_s: float | None = None
    error: str | None = None

    @property
    def duration_s(self) -> float:
        """Device time covered by the rows written."""
        if self.first_t_s is None or self.last_t_s is None:
            return 0.0
        return self.last_t_s - self.first_t_s


def format_rows(
    block: SampleBlock, columns: Sequence[str], *, block_start: bool = True
) -> str:
    """The CSV rows of a block (in SI units), each ending in ``\\n``.

    Floats use ``repr``; a NaN temperature or reference is left empty; ``gap`` and
    ``block_start`` are ``0``/``1`` (``block_start`` is 1 on the first row when
    ``block_start`` is True).
    """
    n = len(block)
    if n == 0:
        return ""
    fields: list[list[str]] = []
    for name in columns:
        if name == "gap":
            fields.append(np.where(block.gap, "1", "0").tolist())
            continue
        if name == "block_start":
            flags = ["0"] * n
            flags[0] = "1" if block_start else "0"
            fields.append(flags)
            continue
        values = _column_values(block, name)
        if values is None:
            fields.append([""] * n)
            continue
        text = list(map(repr, values.tolist()))
        if name not in REQUIRED_COLUMNS:
            for index in np.flatnonzero(np.isnan(values)).tolist():
                text[index] = ""
        fields.append(text)
    return "\n".join(map(",".join, zip(*fields))) + "\n"


def format_table(columns: Sequence[np.ndarray]) -> str:
    """Rows of equally long float columns, each ending in ``\\n``; NaN is left empty.

    Each number is the shortest text that reads back as the same float64 (as ``repr``),
    written by orjson's float formatter, about five times faster than ``repr``.
    """
    return format_table_bytes(columns).decode("ascii")


def format_table_bytes(columns: Sequence[np.ndarray]) -> bytes:
    """:func:`format_table` as ASCII bytes, ready for a binary file."""
    if not columns or len(columns[0]) == 0:
        return b""
    table = np.column_stack([np.asarray(c, dtype=np.float64) for c in columns])
    if np.isinf(table).any():  # orjson writes infinities as null, like NaN
        return _format_table_repr(columns).encode("ascii")
    text = orjson.dumps(table, option=orjson.OPT_SERIALIZE_NUMPY)[2:-2].replace(b"],[", b"\n")
    if np.isnan(table).any():
        text = text.replace(b"null", b"")
    return text + b"\n"


def _format_table_repr(columns: Sequence[np.ndarray]) -> str:
    fields = []
    for values in columns:
        text = list(map(repr, np.asarray(values, dtype=np.float64).tolist()))
        for index in np.flatnonzero(np.isnan(values)).tolist():
            text[index] = ""
        fields.append(text)
    return "\n".join(map(",".join, zip(*fields))) + "\n"


def _column_values(block: SampleBlock, name: str) -> np.ndarray | None:
    if name == "t":
        return block.t_s
    axis = "xyz".find(name[-1:])
    if name in ("ax", "ay", "az"):
        return block.accel_m_s2[:, axis]
    if name in ("gx", "gy", "gz"):
        return block.gyro_rad_s[:, axis]
    if name == "temp":
        return block.temp_degc
    if name in REFERENCE_COLUMNS:
        if block.reference_quat is None:
            return None
        return block.reference_quat[:, REFERENCE_COLUMNS.index(name)]
    if name in MAG_COLUMNS:
        return None if block.mag_ut is None else block.mag_ut[:, axis]
    return None


_STOP = object()


class RecordingWriter:
    """Writes one recording file from its own thread (no Qt).

    Parameters
    ----------
    path : the CSV file to create.
    metadata : ``key -> JSON value`` (see :func:`~app.core.recording.format.recording_metadata`).
    reference : write the reference columns ``qw..qz``. None: decide from the first block (the
        header row is then written with it).
    magnetometer : write the magnetometer's columns ``mx..mz``. None: when the header is
        written at the start, from the metadata (its ``magnetometer`` key), else from the
        first block.
    overwrite : replace an existing regular file (default: refuse). The new recording is
        created beside it under a temporary name and renamed over it once its metadata is on
        disk: the old file is never truncated (a reader of it keeps its data).
    lock : an :class:`~app.core.safe_output.OutputLock` on ``path`` the caller holds (and
        releases, e.g. after its final metadata rewrite); None: the writer takes one itself
        and releases it when the file is closed. A second writer to the same file is refused.
    flush_interval_s : longest wait before rows are flushed and fsynced.
    on_error : called once, from the writer thread, with the message when the recording
        stops on a write error. A GUI re-emits it as a queued signal.
    on_flush : called from the writer thread with a :class:`WriterStatus` after each fsync.
    opener : opens the file (tests inject failures through it).
    max_pending_rows : queued rows after which the recording stops instead of using up memory.
    compress : write format v1 inside gzip; None (default): when the name ends in ``.gz``.
        Every write is one complete gzip member, so a crash leaves a file that reads up to
        its last write (see :mod:`app.core.recording.stream`).

    Use ``start()``, then ``write(raw_block)`` per block, then ``close()``; or a ``with``
    block.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        metadata: Mapping[str, Any],
        *,
        reference: bool | None = None,
        magnetometer: bool | None = None,
        overwrite: bool = False,
        flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S,
        on_error: Callable[[str], None] | None = None,
        on_flush: Callable[[WriterStatus], None] | None = None,
        opener: Opener = _open_unbuffered,
        max_pending_rows: int = DEFAULT_MAX_PENDING_ROWS,
        compress: bool | None = None,
        lock: OutputLock | None = None,
    ) -> None:
        self.path = Path(path)
        self._given_lock = lock
        self._own_lock: OutputLock | None = None
        self.compress = self.path.suffix.lower() == ".gz" if compress is None else compress
        self.metadata = dict(metadata)
        self._reference = reference
        self._magnetometer = magnetometer
        self._overwrite = overwrite
        self._flush_interval_s = float(flush_interval_s)
        self._on_error = on_error
        self._on_flush = on_flush
        self._opener = opener
        self._max_pending_rows = max_pending_rows
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._file: BinaryIO | None = None
        self._columns: tuple[str, ...] | None = None
        self._accepting = False
        self._status = WriterStatus(self.path, "new")
        self._pending_rows = 0
        # Writer-thread state: formatted pieces of whole rows (bytes, first t, last t).
        self._pieces: list[tuple[bytes, float, float]] = []
        self._buffer_bytes = 0
        self._dirty_since: float | None = None
        self._head_size = 0

    # -- producer side (any thread) ----------------------------------------------------------
    def start(self) -> RecordingWriter:
        """Create the file, write the metadata (and header), fsync, start the thread.

        Raises :class:`RecordingWriteError` when the file cannot be created or written.
        """
        if self._thread is not None:
            raise RuntimeError("the writer was started already")
        if self._given_lock is None:
            try:
                self._own_lock = OutputLock(self.path).acquire()
            except OutputRefused as exc:
                raise RecordingWriteError(str(exc), self.path) from None
        try:
            self._create()
        except BaseException:
            self._release_lock()
            raise
        self._status = WriterStatus(self.path, "recording", bytes_written=self._head_size)
        self._accepting = True
        self._thread = threading.Thread(
            target=self._run, name=f"recording-writer:{self.path.name}", daemon=True)
        self._thread.start()
        return self

    def _release_lock(self) -> None:
        lock, self._own_lock = self._own_lock, None
        if lock is not None:
            lock.release()

    def _create(self) -> None:
        """Create the file with its metadata (and header), fsynced; an overwritten file is
        replaced by a rename only then."""
        replacing = None
        if self._overwrite:
            try:
                check_output(self.path, overwrite=True)  # a regular file or nothing
            except OutputRefused as exc:
                raise RecordingWriteError(str(exc), self.path) from None
            if os.path.lexists(self.path):
                replacing = self.path
        target = self.path if replacing is None else self.path.with_name(
            f".{self.path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
        try:
            handle = self._opener(target, "xb")
        except FileExistsError:
            raise RecordingWriteError(
                f"{self.path} exists; choose another name or allow overwriting", self.path
            ) from None
        except OSError as exc:
            raise RecordingWriteError(
                f"cannot create {self.path}: {exc.strerror or exc}", self.path) from exc
        self._file = handle
        metadata = dict(self.metadata)
        head = metadata_text(metadata)
        if self._reference is None and KEY_REFERENCE in metadata:
            self._reference = True
        if self._magnetometer is None and self._reference is not None:
            self._magnetometer = KEY_MAGNETOMETER in metadata
        if self._reference is not None:
            self._columns = self._choose_columns(self._reference, bool(self._magnetometer))
            head += ",".join(self._columns) + "\n"
        encoded = self._encode(head.encode("utf-8"))
        try:
            self._write_all(encoded)
            os.fsync(handle.fileno())
            if replacing is not None:
                os.replace(target, self.path)
        except BaseException as exc:
            self._file = None
            with contextlib.suppress(OSError):
                handle.close()
            with contextlib.suppress(OSError):
                target.unlink()
            if not isinstance(exc, OSError):
                raise
            raise RecordingWriteError(
                f"cannot write {self.path}: {exc.strerror or exc}", self.path) from exc
        self._head_size = len(encoded)

    def write(self, block: RawBlock) -> bool:
        """Queue a block (never blocks). False when the recording is not (or no longer) on.

        The arrays must not be changed afterwards (devices hand out fresh arrays per block).
        """
        if not self._accepting:
            return False
        if len(block) == 0:
            return True
        with self._lock:
            if self._pending_rows + len(block) > self._max_pending_rows:
                overloaded = True
            else:
                overloaded = False
                self._pending_rows += len(block)
        if overloaded:
            self._fail(f"Recording stopped: {self.path} could not be written fast enough "
                       f"({self._max_pending_rows} rows waiting). The rows written so far "
                       "were kept.")
            return False
        self._queue.put(block)
        return True

    def close(self, timeout_s: float | None = None) -> WriterStatus:
        """Write what is queued, fsync, close the file, stop the thread; returns the status."""
        self._accepting = False
        thread = self._thread
        if thread is not None:
            self._queue.put(_STOP)
            thread.join(timeout_s)
        return self.status

    @property
    def status(self) -> WriterStatus:
        with self._lock:
            status = self._status
            pending = self._pending_rows
        return WriterStatus(
            status.path, status.state, status.rows_written, status.rows_synced,
            status.bytes_written, pending, status.first_t_s, status.last_t_s, status.error,
        )

    @property
    def is_recording(self) -> bool:
        return self._accepting

    @property
    def columns(self) -> tuple[str, ...] | None:
        """The header's columns (None until decided)."""
        return self._columns

    def __enter__(self) -> RecordingWriter:
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- writer thread ---------------------------------------------------------------------------
    @staticmethod
    def _choose_columns(reference: bool, magnetometer: bool = False) -> tuple[str, ...]:
        return (*BASE_COLUMNS, *(MAG_COLUMNS if magnetometer else ()),
                *(REFERENCE_COLUMNS if reference else ()))

    def _run(self) -> None:
        try:
            while True:
                timeout = None
                if self._dirty_since is not None:
                    timeout = max(0.0, self._dirty_since + self._flush_interval_s
                                  - time.monotonic())
                try:
                    item = self._queue.get(timeout=timeout)
                except queue.Empty:
                    item = None
                if item is _STOP:
                    if self._state() == "recording":
                        self._flush(sync=True)
                        self._set(state="stopped")
                    break
                if item is not None and self._state() == "recording":
                    self._add(item)
                elif item is not None:
                    with self._lock:
                        self._pending_rows -= len(item)
                if self._dirty_since is not None and (
                    time.monotonic() - self._dirty_since >= self._flush_interval_s
                ):
                    self._flush(sync=True)
        except OSError as exc:
            self._fail_io(exc)
        except Exception as exc:  # a bug must not lose the file silently
            self._fail(f"Recording stopped by an internal error ({exc!r}); the rows written "
                       "so far were kept.")
        finally:
            self._close_file()
            self._release_lock()

    def _add(self, raw: RawBlock) -> None:
        block = convert_raw_block(raw)
        n = len(block)
        if self._columns is None:
            magnetometer = (block.mag_ut is not None if self._magnetometer is None
                            else self._magnetometer)
            self._columns = self._choose_columns(block.reference_quat is not None, magnetometer)
            header = (",".join(self._columns) + "\n").encode("utf-8")
            self._write_rows(header, count_rows=False)
        for start in range(0, n, FORMAT_ROWS):
            piece = slice_block(block, start, start + FORMAT_ROWS)
            data = format_rows(piece, self._columns, block_start=start == 0).encode("utf-8")
            self._pieces.append((data, float(piece.t_s[0]), float(piece.t_s[-1])))
            self._buffer_bytes += len(data)
        with self._lock:
            self._pending_rows -= n
        if self._dirty_since is None:
            self._dirty_since = time.monotonic()
        if self._buffer_bytes >= WRITE_CHUNK_BYTES:
            self._flush(sync=False)

    def _flush(self, *, sync: bool) -> None:
        """Hand the buffered rows to the OS; with ``sync``, fsync too."""
        pieces, self._pieces, self._buffer_bytes = self._pieces, [], 0
        if self.compress and len(pieces) > 1:  # one gzip member per write: it compresses
            pieces = [(b"".join(p[0] for p in pieces), pieces[0][1], pieces[-1][2])]
        for data, first_t, last_t in pieces:
            self._write_rows(data, first_t=first_t, last_t=last_t)
        if sync and self._file is not None:
            os.fsync(self._file.fileno())
            self._dirty_since = None
            with self._lock:
                synced = self._status.rows_written
                self._status = dataclasses.replace(self._status, rows_synced=synced)
                status = self._status
            if self._on_flush is not None:
                _call_safely(self._on_flush, status)

    def _write_rows(
        self, data: bytes, *, count_rows: bool = True, first_t: float | None = None,
        last_t: float | None = None,
    ) -> None:
        """Write whole rows; on an error, account exactly for the complete rows that made it."""
        encoded = self._encode(data)
        try:
            written = self._write_all(encoded)
        except OSError as exc:
            written = getattr(exc, "written", 0)
            # A compressed write counts only when its whole member is in the file.
            kept = (len(data) if written == len(encoded) else 0) if self.compress else written
            self._account(data, kept, count_rows, first_t, last_t, len(encoded))
            raise
        self._account(data, written if not self.compress else len(data), count_rows, first_t,
                      last_t, len(encoded))

    def _encode(self, data: bytes) -> bytes:
        """The bytes for the file: ``data``, or one gzip member holding it."""
        return gzip_member(data, GZIP_LEVEL) if self.compress else data

    def _account(
        self, data: bytes, written: int, count_rows: bool, first_t: float | None,
        last_t: float | None, encoded_size: int | None = None,
    ) -> None:
        complete = len(data) if written == len(data) else data.rfind(b"\n", 0, written) + 1
        if self.compress:  # the file grew by the whole member, or by nothing that counts
            file_bytes = (encoded_size or 0) if complete == len(data) else 0
        else:
            file_bytes = complete
        rows = data.count(b"\n", 0, complete) if count_rows else 0
        if complete < len(data) and rows:  # the t of the last complete row, from its text
            line_start = data.rfind(b"\n", 0, complete - 1) + 1
            last_t = float(data[line_start:complete].split(b",", 1)[0])
        with self._lock:
            status = self._status
            changes: dict[str, Any] = {"bytes_written": status.bytes_written + file_bytes}
            if rows:
                changes["rows_written"] = status.rows_written + rows
                changes["last_t_s"] = last_t
                if status.first_t_s is None:
                    changes["first_t_s"] = first_t
            self._status = dataclasses.replace(status, **changes)

    def _write_all(self, data: bytes) -> int:
        """Write every byte (``write`` may take only part); returns the count written.

        On an OSError the count written so far is in the exception's ``written`` attribute.
        """
        assert self._file is not None
        view = memoryview(data)
        written = 0
        try:
            while written < len(view):
                count = self._file.write(view[written:])
                if count is None:  # a non-blocking file that took nothing: try again
                    continue
                if count == 0:
                    raise OSError(errno.EIO, "the file accepted no data")
                written += count
        except OSError as exc:
            exc.written = written  # type: ignore[attr-defined]
            raise
        return written

    def _fail_io(self, exc: OSError) -> None:
        """Cut the file back to its last complete row and record why the recording stopped."""
        status = self.status
        if self._file is not None:
            with contextlib.suppress(OSError, ValueError):
                self._file.truncate(status.bytes_written)
            with contextlib.suppress(OSError, ValueError):
                os.fsync(self._file.fileno())
        if exc.errno == errno.ENOSPC:
            reason = "the disk is full"
        elif exc.errno == errno.EFBIG:
            reason = "the file reached the largest size this system allows"
        else:
            reason = f"writing failed ({exc.strerror or exc})"
        self._fail(
            f"Recording stopped: {reason} ({self.path}). The {status.rows_written} rows "
            f"recorded until then ({status.duration_s:.1f} s) were kept."
        )

    def _fail(self, message: str) -> None:
        self._accepting = False
        with self._lock:
            if self._status.state == "failed":
                return
            self._status = dataclasses.replace(self._status, state="failed", error=message)
        if self._on_error is not None:
            _call_safely(self._on_error, message)

    def _state(self) -> str:
        with self._lock:
            return self._status.state

    def _set(self, **changes: Any) -> None:
        with self._lock:
            self._status = dataclasses.replace(self._status, **changes)

    def _close_file(self) -> None:
        handle, self._file = self._file, None
        if handle is not None:
            with contextlib.suppress(OSError):
                handle.close()


def _call_safely(callback: Callable[[Any], None], argument: Any) -> None:
    """Run a caller's callback; its failure (a closed console, a bug) must not stop writing."""
    try:
        callback(argument)
    except Exception:
        log.exception("recording writer: callback %r failed", callback)
