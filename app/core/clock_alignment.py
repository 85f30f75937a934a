"""Map a device's clock to the host's monotonic clock: offset and drift from receive times.

Each block a device delivers gives a pair (device time of its newest sample, host time it was
received). The host time is the device time mapped to the host plus a latency that is never
negative (USB, the driver's buffering, the reader's polling). So the mapping is the *lower
envelope* of the pairs, not a least-squares line through them: the line under every point that
is closest to them on average. That line is an edge of the points' lower convex hull (the one
above the mean device time; a linear programme whose optimum lies on the hull), found in O(n)
after sorting. Its slope gives the drift (ppm), the residuals above it the latency spread that
says how well the clocks are aligned.

:class:`ClockAligner` keeps a sliding window of pairs and refits on demand; sensors that share
one clock (one board reading two chips, one simulated arm) feed one aligner, so their mapping
is the same and their relative alignment exact.
"""

from __future__ import annotations

import itertools
import threading
from collections import deque
from dataclasses import dataclass

import numpy as np

WINDOW_S = 60.0
"""Pairs older than this (device time) leave the fit: the drift may wander with temperature."""
MIN_DRIFT_SPAN_S = 2.0
"""Below this span of device time only the offset is fitted (the slope is taken as 1)."""
SPREAD_QUANTILE = 0.9
"""The alignment's spread: this quantile of the residuals above the envelope."""


@dataclass(frozen=True)
class ClockFit:
    """``host = offset_s + scale * device``, and how well the pairs pin it down."""

    offset_s: float
    scale: float
    spread_ms: float
    """90 % of the pairs lie within this much above the line (one-sided latency jitter)."""
    points: int
    span_s: float
    """Device time covered by the pairs."""

    @property
    def drift_ppm(self) -> float:
        """How much faster the device clock runs than the host's, parts per million."""
        return (1.0 / self.scale - 1.0) * 1e6

    def to_host(self, device_t: np.ndarray | float) -> np.ndarray | float:
        """Host time of device times."""
        return self.offset_s + self.scale * np.asarray(device_t, dtype=np.float64)

    def to_device(self, host_t: np.ndarray | float) -> np.ndarray | float:
        """Device time of host times (the inverse mapping)."""
        return (np.asarray(host_t, dtype=np.float64) - self.offset_s) / self.scale


def _lower_hull(x: np.ndarray, y: np.ndarray) -> list[int]:
    """Indices of the lower convex hull of points sorted by x (Andrew's monotone chain)."""
    hull: list[int] = []
    for i in range(len(x)):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            cross = (x[b] - x[a]) * (y[i] - y[a]) - (y[b] - y[a]) * (x[i] - x[a])
            if cross > 0:
                break
            hull.pop()
        hull.append(i)
    return hull


def fit_lower_envelope(device_t: np.ndarray, host_t: np.ndarray,
                       min_drift_span_s: float = MIN_DRIFT_SPAN_S) -> ClockFit:
    """The lower-envelope line of (device, host) pairs (see the module). ValueError if empty."""
    d = np.asarray(device_t, dtype=np.float64)
    h = np.asarray(host_t, dtype=np.float64)
    keep = np.isfinite(d) & np.isfinite(h)
    d, h = d[keep], h[keep]
    if len(d) == 0:
        raise ValueError("no clock pairs to fit")
    order = np.argsort(d, kind="stable")
    d, h = d[order], h[order]
    span = float(d[-1] - d[0])
    # Centre the times so the hull's arithmetic keeps its precision on large clocks.
    d0, h0 = float(d[0]), float(h[0])
    x, y = d - d0, h - h0
    scale = 1.0
    if span >= min_drift_span_s and len(d) >= 3:
        hull = _lower_hull(x, y)
        mean_x = float(x.mean())
        for a, b in itertools.pairwise(hull):
            if x[a] <= mean_x <= x[b] and x[b] > x[a]:
                scale = float((y[b] - y[a]) / (x[b] - x[a]))
                break
        if not scale > 0.0:
            scale = 1.0  # not a clock (times out of order): fall back to the offset alone
    offset = float(np.min(y - scale * x))
    residual = y - (offset + scale * x)
    spread = float(np.quantile(residual, SPREAD_QUANTILE)) * 1e3
    return ClockFit(offset_s=h0 + offset - scale * d0, scale=scale, spread_ms=spread,
                    points=len(d), span_s=span)


class ClockAligner:
    """A sliding window of (device time, host receive time) pairs for one clock; thread-safe.

    Device threads call :meth:`add`; anyone calls :meth:`fit`. A device time that runs
    backwards (the clock restarted) clears the window.
    """

    def __init__(self, window_s: float = WINDOW_S, max_points: int = 20_000) -> None:
        self.window_s = window_s
        self._pairs: deque[tuple[float, float]] = deque(maxlen=max_points)
        self._lock = threading.Lock()
        self._cached: ClockFit | None = None

    def add(self, device_t: float, host_t: float) -> None:
        with self._lock:
            if self._pairs and device_t < self._pairs[-1][0] - 1.0:
                self._pairs.clear()
            self._pairs.append((float(device_t), float(host_t)))
            while self._pairs and self._pairs[0][0] < device_t - self.window_s:
                self._pairs.popleft()
            self._cached = None

    def __len__(self) -> int:
        return len(self._pairs)

    def fit(self) -> ClockFit | None:
        """The current mapping, None before the first pair."""
        with self._lock:
            if self._cached is None and self._pairs:
                pairs = np.array(self._pairs)
                self._cached = fit_lower_envelope(pairs[:, 0], pairs[:, 1])
            return self._cached
