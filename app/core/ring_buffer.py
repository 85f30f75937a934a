"""Preallocated ring buffers: the worker writes blocks, the GUI reads time windows.

Nothing grows while streaming: every column is allocated once, so memory stays flat however
long a session runs. Writes and reads take a short lock; a reader gets copies it may keep.
"""

from __future__ import annotations

import threading

import numpy as np


class RingBuffer:
    """Fixed-capacity columns of float64 that share one write position.

    Parameters
    ----------
    capacity : number of rows kept.
    columns : column name -> width (1 for a scalar per row, 3 for a vector, ...).
    time_column : the column (width 1, non-decreasing) that :meth:`window` searches.
    """

    def __init__(self, capacity: int, columns: dict[str, int], time_column: str = "t") -> None:
        if capacity < 1:
            raise ValueError("capacity must be at least 1")
        if columns.get(time_column) != 1:
            raise ValueError(f"time column {time_column!r} must exist with width 1")
        self.capacity = int(capacity)
        self.columns = dict(columns)
        self.time_column = time_column
        # Uninitialised: only rows written are ever read (every read goes through the
        # count), and untouched pages cost neither time nor memory (a minute at 6667 Hz
        # filled with NaN took half a second at every connect and seek).
        self._data = {
            name: np.empty((self.capacity, width)) for name, width in columns.items()
        }
        self._next = 0  # physical index of the next write
        self._count = 0  # valid rows (<= capacity)
        self._total = 0  # rows ever written
        self._lock = threading.Lock()

    # -- writing ----------------------------------------------------------------------------
    def write(self, rows: dict[str, np.ndarray]) -> None:
        """Append rows; every column must be given, each with the same number of rows."""
        n = None
        arrays = {}
        for name, width in self.columns.items():
            array = np.asarray(rows[name], dtype=np.float64).reshape(-1, width)
            if n is None:
                n = array.shape[0]
            elif array.shape[0] != n:
                raise ValueError(f"column {name!r} has {array.shape[0]} rows, expected {n}")
            arrays[name] = array
        if not n:
            return
        with self._lock:
            keep = min(n, self.capacity)
            start = self._next
            first = min(keep, self.capacity - start)
            for name, array in arrays.items():
                tail = array[n - keep :]
                column = self._data[name]
                column[start : start + first] = tail[:first]
                if keep > first:
                    column[: keep - first] = tail[first:]
            self._next = (start + keep) % self.capacity
            self._count = min(self.capacity, self._count + keep)
            self._total += n

    def clear(self) -> None:
        """Forget every row (for example when another device connects)."""
        with self._lock:
            self._next = 0
            self._count = 0
            self._total = 0

    # -- reading ----------------------------------------------------------------------------
    def __len__(self) -> int:
        return self._count

    @property
    def total_written(self) -> int:
        """Rows written since creation or the last :meth:`clear`."""
        return self._total

    def _physical(self, logical: int) -> int:
        """Physical row of the ``logical``-th valid row, oldest first."""
        return (self._next - self._count + logical) % self.capacity

    def _copy(self, first: int, count: int, names: list[str]) -> dict[str, np.ndarray]:
        start = self._physical(first)
        out = {}
        for name in names:
            column = self._data[name]
            end = start + count
            if end <= self.capacity:
                block = column[start:end].copy()
            else:
                block = np.concatenate([column[start:], column[: end - self.capacity]])
            out[name] = block[:, 0] if self.columns[name] == 1 else block
        return out

    def latest(self, count: int, names: list[str] | None = None) -> dict[str, np.ndarray]:
        """The newest ``count`` rows (fewer if fewer exist), oldest first."""
        names = list(self.columns) if names is None else names
        with self._lock:
            count = max(0, min(int(count), self._count))
            return self._copy(self._count - count, count, names)

    def since(
        self, absolute_index: int, names: list[str] | None = None
    ) -> tuple[int, dict[str, np.ndarray]]:
        """Rows from absolute row ``absolute_index`` on (the first row ever written is 0).

        Returns the absolute index of the first row returned, which is later than asked when
        older rows have already been overwritten.
        """
        names = list(self.columns) if names is None else names
        with self._lock:
            oldest = self._total - self._count
            first = min(max(int(absolute_index), oldest), self._total)
            return first, self._copy(first - oldest, self._total - first, names)

    def window(self, duration_s: float, names: list[str] | None = None) -> dict[str, np.ndarray]:
        """Rows whose time lies within ``duration_s`` of the newest row, oldest first."""
        names = list(self.columns) if names is None else names
        with self._lock:
            if self._count == 0:
                return self._copy(0, 0, names)
            times = self._data[self.time_column][:, 0]
            newest = times[self._physical(self._count - 1)]
            threshold = newest - duration_s
            # Binary search over logical rows (time is non-decreasing in logical order).
            low, high = 0, self._count
            while low < high:
                mid = (low + high) // 2
                if times[self._physical(mid)] < threshold:
                    low = mid + 1
                else:
                    high = mid
            return self._copy(low, self._count - low, names)
