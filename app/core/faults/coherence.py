"""Added noise while moving, by analytic redundancy between the six channels (issue 33).

Real high-band energy is coherent: a phone vibrating on the sensor (BROAD trial 26: a tone at
~100 Hz, 1 m/s^2 on every accelerometer axis and 0.5 dps on gx, band coherence 0.4-0.7
between axes), a tap or a jolt drives several channels and both sensors at once, a rigid
body's vibration the gyro and the accelerometer together. Noise added to one channel is
uncorrelated with every other channel and with its own past beyond the band's own colour.

So each channel's band-passed signal (:mod:`app.core.faults.motion`) is *predicted*: from the
other five channels' band output at lags ``-LAGS..LAGS`` and its own ``OWN_LAGS`` past
samples (a tone is predicted from its own past), by least squares over the last
``motion.HISTORY_WINDOWS`` windows (10 s, leaving out the last ``HISTORY_GAP``; windows with
a flagged channel teach nothing), ridge ``RIDGE`` times the mean diagonal. What the predictor
does not explain, the *residual*, is what added noise raises by its full power. Its power
per window (the median of the squared residual, as for the band) over its own recent level is
``r_c``; the test on channel c divides it by the other channels' ratios measured *without*
channel c among their regressors (a structured residual set: noise on c, entering the others'
predictions through their weights on c, cannot raise those) and by their band ratios (the
motion's own change), as the band test does. The decision is the median over
``SPAN_WINDOWS`` (1.5 s) against ``RESIDUAL_RATIO_ACCEL`` / ``RESIDUAL_RATIO_GYRO``, and the
part of the band the *other* channels do not explain (no own lags) must look white in more
than half of those windows (a rotation's rate-dependent artefact on one gyro axis is not).

A history learnt in another regime says nothing: while the gyro's rate (RMS of the norm over
the window) is more than ``REGIME_CHANGE`` times its median over the history, the window does
not count (a start of motion after rest raised one gyro axis' residual 5-40x for seconds on
BROAD trial 06). Added noise of a few dps does not move a rate of tens of dps; at rest the rest
test finds it.

Cost per window: the 30x30 lagged covariance and the 42 residuals of at most ``MAX_ROWS``
samples, and 42 Cholesky solves of 20-27 unknowns (6 + 30 + 6 predictors), all in numba:
about 0.7 ms, 0.3 % of a core at four windows a second, whatever the rate.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numba import njit

from app.core.faults.rows import RowHistory, column_kth, column_median

LAGS = 2
"""The other channels' band output at lags -2..2 around the predicted sample."""
OWN_LAGS = 2
"""The channel's own band output 1-2 samples before it."""
RIDGE = 1e-3
SPAN = 2 * LAGS + 1
DIM = 6 * SPAN
RESIDUAL_RATIO_ACCEL = 3.7
RESIDUAL_RATIO_GYRO = 2.5
"""Set on the tuning half of the BROAD trials (``motion.TUNING_TRIALS``): their largest clean
value over whole trials 2.88 on the accelerometer (24 az, tapping) and 1.96 on the gyro (06
gx), with a ~30 % margin; the held-out half reaches 2.52 and 1.41."""
REGIME_CHANGE = 2.0
MAX_ROWS = 128
"""The test uses at most the last 128 samples of each window (all of BROAD's 71; 19 ms of a
window at 6667 Hz): its cost per window does not grow with the rate."""
REFIT_WINDOWS = 1
"""The predictors are fitted again every window (every 4th let stale weights lift the
tapping trial's clean residual on az from 2.88 to 3.64)."""
_TARGET = np.array([c * SPAN + LAGS for c in range(6)])


def _regressors(c: int, skip: int | None, own: bool) -> list[int]:
    cols = [k * SPAN + j for k in range(6) if k not in (c, skip) for j in range(SPAN)]
    if own:
        cols += [c * SPAN + LAGS + j for j in range(1, OWN_LAGS + 1)]
    return cols


_FULL = [_regressors(c, None, True) for c in range(6)]
"""Predictor of c from the others and its own past (the tested residual)."""
_WITHOUT = [(c, s, _regressors(c, s, True)) for c in range(6) for s in range(6) if s != c]
"""Predictor of c without channel s (the isolation's structured residuals)."""
_CROSS = [_regressors(c, None, False) for c in range(6)]
"""Predictor of c from the others only (the whiteness gate)."""


def lagged(band: np.ndarray, tail: np.ndarray) -> np.ndarray:
    """(N, DIM) rows ``[channel k delayed j]`` (index ``k * SPAN + j``) of the band output
    (N, 6), ``tail`` the previous ``2 * LAGS`` rows (oldest first)."""
    return _lagged_rows(np.vstack([tail, band]))


def _lagged_rows(x: np.ndarray) -> np.ndarray:
    """:func:`lagged` of ``x`` (N + 2 * LAGS, 6): the tail and the band in one array."""
    n = len(x) - 2 * LAGS
    z = np.empty((n, 6, SPAN))
    for j in range(SPAN):
        z[:, :, j] = x[SPAN - 1 - j:SPAN - 1 - j + n]
    return z.reshape(n, DIM)


@njit(cache=True)
def _gram(z):  # pragma: no cover
    """``z.T @ z`` without BLAS: its threads spin on a loaded machine for matrices this small
    (a window cost 10x more CPU time under load)."""
    m, d = z.shape
    out = np.zeros((d, d))
    for i in range(m):
        for a in range(d):
            za = z[i, a]
            for b in range(a, d):
                out[a, b] += za * z[i, b]
    for a in range(d):
        for b in range(a):
            out[a, b] = out[b, a]
    return out


@njit(cache=True)
def _product(z, w):  # pragma: no cover
    """``z @ w`` without BLAS (see :func:`_gram`)."""
    m, d = z.shape
    p = w.shape[1]
    out = np.zeros((m, p))
    for i in range(m):
        for a in range(d):
            za = z[i, a]
            if za != 0.0:
                for k in range(p):
                    out[i, k] += za * w[a, k]
    return out


@njit(cache=True)
def _worst_lag(e, reference):  # pragma: no cover
    """Per column of ``e``: the largest |autocorrelation - reference| over lags 1..len."""
    m, p = e.shape
    out = np.zeros(p)
    for k in range(p):
        power = 0.0
        for i in range(m):
            power += e[i, k] * e[i, k]
        power = max(power, 1e-300)
        for lag in range(1, len(reference) + 1):
            acc = 0.0
            for i in range(lag, m):
                acc += e[i, k] * e[i - lag, k]
            out[k] = max(out[k], abs(acc / power - reference[lag - 1]))
    return out


@njit(cache=True)
def _solve_set(cov, columns, targets, ridge):  # pragma: no cover
    """Each predictor's ridge least squares (Cholesky), as residual weights (DIM, P)."""
    p, k = columns.shape
    out = np.zeros((cov.shape[0], p))
    a = np.empty((k, k))
    b = np.empty(k)
    for m in range(p):
        trace = 0.0
        for i in range(k):
            trace += cov[columns[m, i], columns[m, i]]
        reg = ridge * trace / k + 1e-200
        for i in range(k):
            b[i] = cov[columns[m, i], targets[m]]
            for j in range(k):
                a[i, j] = cov[columns[m, i], columns[m, j]]
            a[i, i] += reg
        # Cholesky a = L L^T in place (lower triangle)
        for j in range(k):
            d = a[j, j]
            for q in range(j):
                d -= a[j, q] * a[j, q]
            d = np.sqrt(max(d, 1e-300))
            a[j, j] = d
            for i in range(j + 1, k):
                v = a[i, j]
                for q in range(j):
                    v -= a[i, q] * a[j, q]
                a[i, j] = v / d
        for i in range(k):  # forward: L y = b
            v = b[i]
            for q in range(i):
                v -= a[i, q] * b[q]
            b[i] = v / a[i, i]
        for i in range(k - 1, -1, -1):  # back: L^T w = y
            v = b[i]
            for q in range(i + 1, k):
                v -= a[q, i] * b[q]
            b[i] = v / a[i, i]
        for i in range(k):
            out[columns[m, i], m] = -b[i]
        out[targets[m], m] = 1.0
    return out


_EYE = np.eye(6, dtype=bool)
_loaded: list[bool] = []


def _load_kernels() -> None:
    """Compile or load the kernels now, once per process: not ~8 s into a stream, when the
    test arms (the first window would take tens of ms, a stall in a live stream)."""
    if _loaded:
        return
    z = np.zeros((4, DIM))
    cov = np.eye(DIM)
    weights = np.hstack([s.weights(cov) for s in _SETS])
    _worst_lag(_product(z, weights)[:, 36:], np.zeros(2))
    _gram(z)
    _loaded.append(True)


class _Set:
    """Predictors of equal size: their regressor columns and targets (indices into DIM)."""

    def __init__(self, rows: list[tuple[int, list[int]]]) -> None:
        self.targets = np.array([target for target, _ in rows])
        self.columns = np.array([cols for _, cols in rows])

    def weights(self, cov: np.ndarray) -> np.ndarray:
        """(DIM, predictors): residual = z @ weights, by ridge least squares on ``cov``."""
        return _solve_set(cov, self.columns, self.targets, RIDGE)


_SETS = (_Set([(int(_TARGET[c]), cols) for c, cols in enumerate(_FULL)]),
         _Set([(int(_TARGET[c]), cols) for c, _, cols in _WITHOUT]),
         _Set([(int(_TARGET[c]), cols) for c, cols in enumerate(_CROSS)]))
_WITHOUT_INDEX = (np.array([c for c, _, _ in _WITHOUT]), np.array([s for _, s, _ in _WITHOUT]))
_POWER_INDEX = np.empty((6, 7), dtype=np.intp)
"""Where each of the (6, 7) powers comes from in the 36 residuals' medians: [c, 6] and [c, c]
the full predictor of c (0..5), [c, s] the one without s (6..35)."""
_POWER_INDEX[:, 6] = np.arange(6)
_POWER_INDEX[_WITHOUT_INDEX] = np.arange(6, 36)
_POWER_INDEX[np.arange(6), np.arange(6)] = np.arange(6)


class CoherenceCheck:
    """The residual test; fed each window's band output by :class:`MotionNoiseCheck`.

    :meth:`window` returns per channel the window's log ratio for the test (or NaN when the
    test cannot count it) and whether the cross residual looks white.
    """

    def __init__(self, history: int, gap: int, minimum: int, white_reference: np.ndarray,
                 white_tolerance: float) -> None:
        self._history_len = history
        self._gap = gap
        self._minimum = minimum
        self._white_reference = white_reference
        self._white_tolerance = white_tolerance
        _load_kernels()
        self.reset()

    def reset(self) -> None:
        """Forget everything learnt (a new sensor)."""
        self._covs: deque[np.ndarray] = deque(maxlen=self._history_len + self._gap)
        self._fit = np.zeros((DIM, DIM))
        """The sum of ``_covs`` but the last ``gap`` (kept as it goes, rebuilt every
        ``history`` windows against rounding)."""
        self._since_rebuild = 0
        self._powers = RowHistory(self._history_len + self._gap, 42)
        self._rates = RowHistory(self._history_len + self._gap, 1)
        self._level = np.ones((6, 7))
        self._weights: np.ndarray | None = None
        self._age = 0
        self.restart()

    def restart(self) -> None:
        """A gap: the lags start again; what was learnt stays."""
        self._tail = np.zeros((2 * LAGS, 6))

    def window(self, band: np.ndarray, rate: float, log_raw: np.ndarray | None,
               flagged: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One window's band output (n, 6), the gyro's rate RMS, the band test's log ratios
        (None before it is armed) and the channels flagged so far: (log ratio for the test
        per channel, NaN where it does not count; the cross residual white)."""
        x = np.vstack([self._tail, band])[-(MAX_ROWS + 2 * LAGS):]
        self._tail = x[-2 * LAGS:]
        z = _lagged_rows(x)
        log_s = np.full(6, np.nan)
        white = np.zeros(6, dtype=bool)
        power = None
        if len(self._covs) >= self._minimum + self._gap:
            if self._weights is None or self._age >= REFIT_WINDOWS:
                self._weights = np.hstack([s.weights(self._fit) for s in _SETS])
                self._age = 0
            self._age += 1
            e = _product(z, self._weights)
            half = (len(z) - 1) // 2
            med = column_kth(e[:, :36], half, True)
            power = med[_POWER_INDEX]
            white = self._whiteness(e[:, 36:])
            if len(self._powers) >= self._minimum + self._gap and log_raw is not None:
                past = self._powers.rows()[:-self._gap]
                self._level = np.maximum(column_median(past, False, False), 1e-300).reshape(6, 7)
                rates = self._rates.rows()[:-self._gap]
                if rate <= REGIME_CHANGE * max(float(column_median(rates, False, False)[0]),
                                               1e-12):
                    lr = np.log(np.maximum(power, 1e-300) / self._level)
                    # others[k, c]: channel k without c, or k's band ratio (k != c)
                    others = np.maximum(lr[:, :6], log_raw[:, None])
                    others[_EYE] = -np.inf
                    log_s = lr[:, 6] - np.maximum(0.0, others.max(axis=0))
        if not flagged.any():
            self._learn(_gram(z) * (len(band) / len(z)))
        if power is not None:
            self._powers.append(np.where(flagged[:, None], self._level, power).reshape(42))
        self._rates.append(np.array([rate]))
        return log_s, white

    def _learn(self, cov: np.ndarray) -> None:
        covs = self._covs
        if len(covs) == covs.maxlen:
            self._fit -= covs[0]
        if len(covs) >= self._gap:
            self._fit += covs[-self._gap]
        covs.append(cov)
        self._since_rebuild += 1
        if self._since_rebuild >= self._history_len:
            self._since_rebuild = 0
            self._fit = np.sum(list(covs)[:-self._gap], axis=0)

    def _whiteness(self, e: np.ndarray) -> np.ndarray:
        return _worst_lag(e, self._white_reference) <= self._white_tolerance
