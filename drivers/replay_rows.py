"""Where a replay's rows come from: all in memory, or streamed from the file a chunk at a time.

:class:`MemoryRows` holds a loaded :class:`~app.core.recording.reader.Recording` (small
files: everything is at hand). :class:`StreamedRows` holds at most a few chunks of a long
recording (about 8 MB of text each) and finds any row or time through a
:class:`~app.core.recording.index.RecordingIndex` that a background thread builds in one pass,
together with the session's :class:`~app.core.recording.index.Overview`. The first rows are
there as soon as the first chunk is parsed; memory does not grow with the recording.

Both answer the same questions for :class:`drivers.replay.ReplayDevice` (rows by index, the
row at a time, block ends, gaps); the device holds its lock while asking.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Generator
from dataclasses import dataclass

import numpy as np

from app.core.recording.errors import RecordingError
from app.core.recording.format import ACCEL_COLUMNS, GYRO_COLUMNS, REFERENCE_COLUMNS
from app.core.recording.index import Overview, RecordingIndex
from app.core.recording.reader import Recording
from app.core.recording.stream import Chunk, RecordingStream

INDEX_WAIT_S = 60.0
"""Longest wait for the background index to reach a row or time asked for."""


@dataclass(slots=True)
class Rows:
    """Consecutive rows, as arrays (views where possible)."""

    t: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray
    temp: np.ndarray
    gap: np.ndarray
    reference: np.ndarray | None
    block_start: np.ndarray | None
    mag: np.ndarray | None = None
    """(N, 3) magnetic field in uT (NaN rows without a new sample), None without one."""

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def slice(self, start: int, stop: int) -> Rows:
        ref, starts, mag = self.reference, self.block_start, self.mag
        return Rows(self.t[start:stop], self.accel[start:stop], self.gyro[start:stop],
                    self.temp[start:stop], self.gap[start:stop],
                    None if ref is None else ref[start:stop],
                    None if starts is None else starts[start:stop],
                    None if mag is None else mag[start:stop])

    @staticmethod
    def join(parts: list[Rows]) -> Rows:
        if len(parts) == 1:
            return parts[0]
        ref = None if parts[0].reference is None else np.concatenate([p.reference for p in parts])
        starts = (None if parts[0].block_start is None
                  else np.concatenate([p.block_start for p in parts]))
        return Rows(np.concatenate([p.t for p in parts]),
                    np.concatenate([p.accel for p in parts]),
                    np.concatenate([p.gyro for p in parts]),
                    np.concatenate([p.temp for p in parts]),
                    np.concatenate([p.gap for p in parts]), ref, starts,
                    None if parts[0].mag is None else np.concatenate([p.mag for p in parts]))


def rows_of(recording: Recording, reference: bool | None = None) -> Rows:
    """A recording's (or a chunk's) rows as :class:`Rows`."""
    columns = recording.columns
    has_reference = recording.has_reference if reference is None else reference
    return Rows(
        t=np.ascontiguousarray(recording.t_s),
        accel=np.column_stack([columns[c] for c in ACCEL_COLUMNS]),
        gyro=np.column_stack([columns[c] for c in GYRO_COLUMNS]),
        temp=np.ascontiguousarray(recording.temp_degc),
        gap=recording.gap,
        reference=(np.column_stack([columns[c] for c in REFERENCE_COLUMNS])
                   if has_reference else None),
        block_start=recording.block_start,
        mag=recording.mag_ut,
    )


def lost_before(t: float, previous_t: float | None, rate_hz: float) -> int:
    """Samples lost between a gap row at ``t`` and the row before it at ``previous_t``."""
    if previous_t is None or not math.isfinite(rate_hz):
        return 0
    return max(0, round((t - previous_t) * rate_hz) - 1)


class MemoryRows:
    """Every row of a loaded recording."""

    streamed = False

    def __init__(self, recording: Recording, rate_hz: float) -> None:
        self._recording = recording
        self._overview: Overview | None = None
        self._rows = rows_of(recording)
        self.rate_hz = rate_hz
        self.count = len(self._rows)
        self.first_t = float(self._rows.t[0])
        self.last_t = float(self._rows.t[-1])
        self.has_block_start = self._rows.block_start is not None
        self.has_reference = self._rows.reference is not None
        self.gap_rows = np.flatnonzero(self._rows.gap)
        self._bounds = (np.concatenate([np.flatnonzero(self._rows.block_start), [self.count]])  # type: ignore[arg-type]
                        if self.has_block_start else None)

    def complete(self) -> bool:
        return True

    def exists(self, row: int) -> bool:
        return 0 <= row < self.count

    def t(self, row: int) -> float:
        return float(self._rows.t[row])

    def index_at_t(self, t_s: float, side: str = "left") -> int:
        return int(np.searchsorted(self._rows.t, t_s, side))  # type: ignore[call-overload]

    def block_end(self, pos: int) -> int:
        assert self._bounds is not None
        k = int(np.searchsorted(self._bounds, pos, "right"))
        return int(self._bounds[min(k, len(self._bounds) - 1)])

    def rows(self, start: int, stop: int) -> Rows:
        return self._rows.slice(start, stop)

    def lost_at(self, row: int) -> int:
        if row <= 0 or not self._rows.gap[row]:
            return 0
        return lost_before(float(self._rows.t[row]), float(self._rows.t[row - 1]), self.rate_hz)

    def gaps(self) -> tuple[np.ndarray, np.ndarray]:
        """(gap rows, their times) found so far."""
        return self.gap_rows, self._rows.t[self.gap_rows]

    def overview(self) -> Overview:
        """The whole session's envelope (made once, on first asking)."""
        if self._overview is None:
            index = RecordingIndex(self.count)
            index.add(self._recording, 0, 0, 0)
            index.finish()
            self._overview = index.overview()
        return self._overview

    def problem(self) -> str:
        return ""

    def close(self) -> None:
        pass


class StreamedRows:
    """A long recording read a chunk at a time (see the module docstring).

    The lock of the owning device guards every call; the index thread takes ``self._cond``
    (the same lock, given by the device) only to add what it found.
    """

    streamed = True

    def __init__(self, stream: RecordingStream, cond: threading.Condition) -> None:
        self._stream = stream
        self._cond = cond
        self._chunks: Generator[Chunk, None, None] | None = stream.chunks()
        self._problem = ""
        first = self._next_chunk()
        if first is None:  # a bad first row says why; else there are no rows at all
            raise RecordingError(self._problem or f"{stream.path}: the recording holds no "
                                 "samples", stream.path)
        self.has_reference = all(c in stream.header for c in REFERENCE_COLUMNS)
        self.has_block_start = "block_start" in stream.header
        self._cur: tuple[int, Rows] = (0, rows_of(first.rows, self.has_reference))
        self._prev: tuple[int, Rows] | None = None
        self._final: int | None = None
        self.first_t = float(self._cur[1].t[0])
        head = Recording(stream.metadata, stream.header, {"t": self._cur[1].t})
        odr = head.device.get("odr_hz")
        steps = np.diff(self._cur[1].t)
        steps = steps[steps > 0]
        self.rate_hz = (float(odr) if isinstance(odr, int | float) and odr > 0
                        else 1.0 / float(np.median(steps)) if len(steps) else 100.0)
        bytes_per_row = max(1.0, stream.chunk_bytes / max(1, len(first)))
        scale = 2.5 if stream.compressed else 1.0  # gzip keeps about 40 % of the text
        self.expected_rows = int(stream.file_size() * scale / bytes_per_row) + 1
        self.index = RecordingIndex(self.expected_rows)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._build_index, name="replay-index",
                                        daemon=True)
        self._thread.start()

    # -- the index thread ----------------------------------------------------------------------
    def _build_index(self) -> None:
        try:
            with RecordingStream(self._stream.path, chunk_bytes=self._stream.chunk_bytes) as s:
                for chunk in s.chunks():
                    if self._stop.is_set():
                        return
                    with self._cond:
                        self.index.add(chunk.rows, chunk.first_row, chunk.offset, chunk.line)
                        self._stream.adopt_members(s.members)  # compressed: seek points
                        self._cond.notify_all()
        except (RecordingError, OSError) as exc:
            with self._cond:
                self._problem = str(exc)
        finally:
            with self._cond:
                self.index.finish()
                self._cond.notify_all()

    def _wait_for(self, ready: Callable[[], object]) -> None:
        """Wait (lock held) until ``ready()`` or the index is complete."""
        self._cond.wait_for(lambda: ready() or self.index.complete or self._stop.is_set(),
                            timeout=INDEX_WAIT_S)

    # -- what the device asks -------------------------------------------------------------------
    @property
    def count(self) -> int:
        """Rows: exact once known, else the best estimate (for a slider)."""
        if self._final is not None:
            return self._final
        if self.index.complete:
            return self.index.rows
        return max(self.expected_rows, self.index.rows, self._end())

    @property
    def last_t(self) -> float:
        if self.index.complete and self.index.entries:
            return self.index.last_t_s
        return self.first_t + (self.count - 1) / self.rate_hz

    def complete(self) -> bool:
        return self._final is not None or self.index.complete

    def _end(self) -> int:
        return self._cur[0] + len(self._cur[1])

    def _window(self, row: int) -> tuple[int, Rows] | None:
        for window in (self._cur, self._prev):
            if window is not None and window[0] <= row < window[0] + len(window[1]):
                return window
        return None

    def exists(self, row: int) -> bool:
        """Whether ``row`` exists; loads its chunk (after the current one: read on; else
        through the index)."""
        if row < 0:
            return False
        if self._window(row) is not None:
            return True
        if self._final is not None and row >= self._final:
            return False
        if row == self._end() and self._chunks is not None:
            return self._read_on()
        return self._load(row)

    def _next_chunk(self) -> Chunk | None:
        """The next chunk of the current read; None at its end or at a row that cannot be
        read (the reason is kept for :meth:`problem`)."""
        assert self._chunks is not None
        try:
            return next(self._chunks, None)
        except RecordingError as exc:
            self._problem = str(exc)
            return None

    def _read_on(self) -> bool:
        chunk = self._next_chunk()
        if chunk is None:
            self._final = self._end()
            self._chunks = None
            return False
        self._prev = self._cur
        self._cur = (chunk.first_row, rows_of(chunk.rows, self.has_reference))
        return True

    def _load(self, row: int) -> bool:
        self._wait_for(lambda: self.index.rows > row)
        entry = self.index.entry_for_row(row)
        if entry is None:
            if self.index.complete:
                self._final = self.index.rows
            return False
        if self._chunks is not None:
            self._chunks.close()
        self._chunks = self._stream.chunks(entry.offset, entry.first_row, entry.line)
        self._prev = None
        chunk = self._next_chunk()
        if chunk is None:
            return False
        self._cur = (chunk.first_row, rows_of(chunk.rows, self.has_reference))
        return self._window(row) is not None

    def t(self, row: int) -> float:
        if not self.exists(row):
            raise IndexError(row)
        start, rows = self._window(row)  # type: ignore[misc]
        return float(rows.t[row - start])

    def index_at_t(self, t_s: float, side: str = "left") -> int:
        for window in (self._cur, self._prev):
            if window is not None and len(window[1]) and window[1].t[0] <= t_s <= window[1].t[-1]:
                local = int(np.searchsorted(window[1].t, t_s, side))  # type: ignore[call-overload]
                return window[0] + local
        if t_s < self.first_t:
            return 0
        self._wait_for(lambda: self.index.entries and self.index.last_t_s >= t_s)
        entry = self.index.entry_for_time(t_s)
        if entry is None or (self.index.complete and t_s > self.index.last_t_s):
            return self.index.rows if self.index.complete else self._end()
        if not self.exists(entry.first_row):
            return entry.first_row
        return self.index_at_t(t_s, side) if self._window(entry.first_row) else entry.first_row

    def block_end(self, pos: int) -> int:
        """End of the device block that starts at ``pos`` (may read the next chunk)."""
        if not self.exists(pos):
            return pos
        start, rows = self._window(pos)  # type: ignore[misc]
        assert rows.block_start is not None
        later = np.flatnonzero(rows.block_start[pos - start + 1:])
        if len(later):
            return pos + 1 + int(later[0])
        end = start + len(rows)
        if not self.exists(end):
            return end
        start, rows = self._window(end)  # type: ignore[misc]
        assert rows.block_start is not None
        found = np.flatnonzero(rows.block_start)
        return start + int(found[0]) if len(found) else start + len(rows)

    def rows(self, start: int, stop: int) -> Rows:
        """Rows ``[start, stop)`` (fewer when the recording ends first)."""
        parts = []
        row = start
        while row < stop and self.exists(row):
            first, window = self._window(row)  # type: ignore[misc]
            upto = min(stop, first + len(window))
            parts.append(window.slice(row - first, upto - first))
            row = upto
        return Rows.join(parts)

    def lost_at(self, row: int) -> int:
        if row <= 0 or not self.exists(row):
            return 0
        start, rows = self._window(row)  # type: ignore[misc]
        if not rows.gap[row - start]:
            return 0
        before = self._window(row - 1)
        previous = None if before is None else float(before[1].t[row - 1 - before[0]])
        return lost_before(float(rows.t[row - start]), previous, self.rate_hz)

    def gaps(self) -> tuple[np.ndarray, np.ndarray]:
        return (np.asarray(self.index.gap_rows, dtype=np.int64),
                np.asarray(self.index.gap_t_s, dtype=np.float64))

    def wait_for_index(self) -> None:
        """Wait (lock held) for the whole file to be indexed (e.g. for the next gap)."""
        self._wait_for(lambda: False)

    def overview(self) -> Overview:
        return self.index.overview()

    def problem(self) -> str:
        return self._problem

    def close(self) -> None:
        self._stop.set()
        if self._chunks is not None:
            self._chunks.close()
            self._chunks = None
        self._stream.close()
