"""Small per-window helpers of the fault tests: a fixed history of rows kept in time order,
and the column median of a few rows without numpy's per-call overhead (same values as
``np.median(a, axis=0)``; the tests call them hundreds of times a second)."""

from __future__ import annotations

import numpy as np
from numba import njit


class RowHistory:
    """The last ``capacity`` rows of ``width`` values, oldest first, in one array (a deque
    of rows turned into an array every window cost more than the tests using it)."""

    def __init__(self, capacity: int, width: int, dtype: type = np.float64) -> None:
        self.capacity = capacity
        self._buf: np.ndarray = np.zeros((capacity, width), dtype=dtype)
        self._count = 0

    def __len__(self) -> int:
        return self._count

    def append(self, row: np.ndarray) -> None:
        """Add ``row`` as the newest, dropping the oldest when full."""
        buf = self._buf
        buf[:-1] = buf[1:]
        buf[-1] = row
        if self._count < self.capacity:
            self._count += 1

    def clear(self) -> None:
        self._count = 0

    def rows(self) -> np.ndarray:
        """(len, width) the rows held, oldest first (a view: valid until the next append)."""
        return self._buf[self.capacity - self._count:]


@njit(cache=True)
def column_median(a, square, nan_check):  # pragma: no cover - compiled
    """``np.median(a ** 2 if square else a, axis=0)`` of (n, c) ``a`` (n >= 1), to the bit.
    Without ``nan_check`` the median by ``np.partition`` instead: NaN sorts last, and the
    middle value itself or half the sum of the middle two."""
    n, c = a.shape
    out = np.empty(c)
    column = np.empty(n)
    half = n // 2
    for j in range(c):
        nan = False
        for i in range(n):
            v = a[i, j]
            if square:
                v = v * v
            column[i] = v
            if v != v:
                nan = True
        if nan and nan_check:
            out[j] = np.nan
            continue
        column.sort()
        if not nan_check:  # as 0.5 * (the two middle values) or the middle one
            out[j] = column[half] if n % 2 else 0.5 * (column[half - 1] + column[half])
        elif n % 2:  # numpy's: the mean of the middle one or two (a sum from +0.0)
            out[j] = 0.0 + column[half]
        else:
            out[j] = ((0.0 + column[half - 1]) + column[half]) / 2.0
    return out


@njit(cache=True)
def less_others(log_r):  # pragma: no cover - compiled
    """``log_r[c] - max(0.0, float(np.max(np.delete(log_r, c))))`` for every c, NaN
    included (the max over the other channels, then at least 0)."""
    n = log_r.shape[0]
    out = np.empty(n)
    for c in range(n):
        top = -np.inf
        nan = False
        for o in range(n):
            if o != c:
                v = log_r[o]
                if v != v:
                    nan = True
                elif v > top:
                    top = v
        out[c] = log_r[c] - (top if (not nan and top > 0.0) else 0.0)
    return out


@njit(cache=True)
def column_kth(a, k, square):  # pragma: no cover - compiled
    """``np.partition(a ** 2 if square else a, k, axis=0)[k]`` of (n, c) ``a``: each
    column's k-th smallest (NaN sorts last)."""
    n, c = a.shape
    out = np.empty(c)
    column = np.empty(n)
    for j in range(c):
        for i in range(n):
            v = a[i, j]
            column[i] = v * v if square else v
        column.sort()
        out[j] = column[k]
    return out
