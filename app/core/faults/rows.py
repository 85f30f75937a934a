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
def _select(v, n, k):  # pragma: no cover - compiled
    """Reorder ``v[:n]`` (no NaN) so that ``v[k]`` is its k-th smallest and ``v[:k]`` holds
    no larger value (Hoare's quickselect); returns ``v[k]``."""
    lo = 0
    hi = n - 1
    while lo < hi:
        pivot = v[(lo + hi) // 2]
        i = lo
        j = hi
        while i <= j:
            while v[i] < pivot:
                i += 1
            while v[j] > pivot:
                j -= 1
            if i <= j:
                v[i], v[j] = v[j], v[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return v[k]


@njit(cache=True)
def _column(a, j, square, column):  # pragma: no cover - compiled
    """Copy column j of ``a`` (squared when ``square``) without its NaNs into ``column``;
    returns how many were kept."""
    kept = 0
    for i in range(a.shape[0]):
        v = a[i, j]
        if square:
            v = v * v
        if v == v:
            column[kept] = v
            kept += 1
    return kept


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
        kept = _column(a, j, square, column)
        if kept < n and (nan_check or half >= kept):
            out[j] = np.nan  # (without the check: the middle is a NaN sorted last)
            continue
        upper = _select(column, kept, half)
        if n % 2:
            # numpy's median is the mean of the middle value (a sum from +0.0)
            out[j] = 0.0 + upper if nan_check else upper
            continue
        lower = column[0]
        for i in range(1, half):
            lower = max(lower, column[i])
        if nan_check:
            out[j] = ((0.0 + lower) + upper) / 2.0
        else:
            out[j] = 0.5 * (lower + upper)
    return out


@njit(cache=True)
def column_kth(a, k, square):  # pragma: no cover - compiled
    """``np.partition(a ** 2 if square else a, k, axis=0)[k]`` of (n, c) ``a``: each
    column's k-th smallest (NaN sorts last)."""
    n, c = a.shape
    out = np.empty(c)
    column = np.empty(n)
    for j in range(c):
        kept = _column(a, j, square, column)
        out[j] = _select(column, kept, k) if k < kept else np.nan
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

