"""Added noise while the sensor moves (issue 33): the high-band residual of each channel.

Hand and machine motion has little energy far above 20 Hz; added white noise spreads evenly
up to Nyquist. Each channel is band-passed to ``BAND`` (0.25 to 0.45 of the sample rate: 71 to
129 Hz at BROAD's 285.7 Hz, above any hand motion and below the gyro's own rise at Nyquist;
a 4th-order Butterworth high-pass and low-pass, :func:`butterworth_sos`), and its power per
0.25 s window is taken as the *median* of the squared output, so a tap or a jolt that fills
a few samples of the window weighs nothing.

The residual of channel c in a window is its power over its own recent level (the median of
its last ``HISTORY_WINDOWS`` windows, 10 s, leaving out the last ``HISTORY_GAP``), ``r_c``,
divided by the largest such ratio of the five other channels (``max(1, ...)``): the hand
held still or moved, a tap or a vibration raises the high band of several channels at once
(the shock reaches both sensors), a noisy channel alone. The decision is the median of that
ratio over the last ``SPAN_WINDOWS`` windows (1.5 s) against ``RATIO_ACCEL`` /
``RATIO_GYRO``: a sequential test that needs the residual on more than half of 1.5 s, so
isolated transients never decide it. It must also look white in more than half of them
(:data:`WHITE_TOLERANCE`): a vibration on one axis is a tone, not noise.

The thresholds are power ratios set on half of the twelve BROAD trials (01, 06, 10, 15, 24,
28: the largest clean value 3.4 on the accelerometer, 5.2 on the gyro, both on the tapping
trial) with a 30 % margin, and checked on the other half (largest 2.0 and 3.5). White noise
of sigma on a channel whose band power is ``p`` raises the ratio to ``1 + 0.4 sigma^2 / p``
(0.4: the band's share of the spectrum up to Nyquist): at rest (``p`` the sensor's own noise)
twice the sensor's noise is found; in hand motion, whose band power is 1-15x the rest level,
about 1 dps on the gyro and 0.2 m/s^2 on the accelerometer (docs/fault-detection.md).

While a channel is flagged its level is not learnt (a lasting fault stays a fault).

Beside this band test, :mod:`app.core.faults.coherence` tests what the other channels do
not explain of each channel's band (a vibration that fills the band of every channel hides
added noise from the band test, not from that one); :attr:`MotionNoiseCheck.flagged` is
either, :attr:`~MotionNoiseCheck.by_band` and :attr:`~MotionNoiseCheck.by_residual` say
which.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.faults.coherence import (
    RESIDUAL_RATIO_ACCEL,
    RESIDUAL_RATIO_GYRO,
    CoherenceCheck,
)
from app.core.faults.rows import RowHistory, column_median, less_others

BAND: tuple[float, float] = (0.25, 0.45)
"""Pass band as fractions of the sample rate."""
MIN_LOW_HZ = 60.0
"""The band starts at least this far above hand motion (20 Hz): below 240 Hz of sample rate
there is no such band, and the test is off (at 104 Hz a stroke's own acceleration filled the
26-47 Hz band; noise is then found at rest only)."""
ORDER = 4
HISTORY_WINDOWS = 40
HISTORY_GAP = 2
HISTORY_MIN = 16
"""Windows of history before the test is armed (4 s)."""
SPAN_WINDOWS = 6
RELEASE = 0.5
"""A channel the residual test flagged stays flagged while its residual ratio (the median
over ``SPAN_WINDOWS``) is above the threshold's square root (0.5 of its log): 1.6x on the gyro,
1.9x on the accelerometer, where a clean channel sits near 1x. Released at the threshold
itself, a dip of the ratio in a burst of motion (BROAD 15, 1 dps on gx: 3.9x, then 1.6x at
5 s) unflagged the channel, its noisy windows became its recent level within 10 s, and the
noise, still there, was never seen again in motion."""
RATIO_ACCEL = 4.5
RATIO_GYRO = 6.5
TUNING_TRIALS: tuple[str, ...] = ("01_", "06_", "10_", "15_", "24_", "28_")
"""The BROAD trials (file-name prefixes) the thresholds were set on; the other six are held
out (``evaluate-faults --in-motion`` reports both halves)."""
WHITE_LAGS = 6
WHITE_TOLERANCE = 0.35
"""A window's band output is white noise's when its autocorrelation at lags 1-6 is within
0.35 of band-limited white noise's (the filter's own, :func:`band_autocorrelation`): a tone
or two (a machine's vibration) keeps ``cos(2 pi f k)`` at every lag, band-limited noise's
decays to 0 by lag 5."""
BAND_SHARE = 2.0 * (BAND[1] - BAND[0])
"""Share of white noise's power (0 .. Nyquist) in the band."""


def butterworth_sos(order: int, cutoff: float, kind: str) -> np.ndarray:
    """Second-order sections (n/2, 6: b0 b1 b2 a0 a1 a2) of a digital Butterworth filter,
    ``cutoff`` a fraction of the sample rate (bilinear transform, pre-warped); ``kind``
    ``"low"`` or ``"high"``; ``order`` even."""
    if order % 2 or not 0.0 < cutoff < 0.5:
        raise ValueError("order must be even and cutoff within (0, 0.5) of the rate")
    k = math.tan(math.pi * cutoff)
    rows = []
    for i in range(order // 2):
        q = 1.0 / (2.0 * math.sin((2 * i + 1) * math.pi / (2 * order)))
        norm = 1.0 / (1.0 + k / q + k * k)
        a1 = 2.0 * (k * k - 1.0) * norm
        a2 = (1.0 - k / q + k * k) * norm
        if kind == "low":
            b0 = k * k * norm
            rows.append([b0, 2.0 * b0, b0, 1.0, a1, a2])
        elif kind == "high":
            rows.append([norm, -2.0 * norm, norm, 1.0, a1, a2])
        else:
            raise ValueError(f"kind must be 'low' or 'high', not {kind!r}")
    return np.array(rows)


def band_autocorrelation(sos: np.ndarray, lags: int = WHITE_LAGS) -> np.ndarray:
    """Autocorrelation at lags 1..``lags`` of white noise through ``sos`` (from its impulse
    response)."""
    impulse = np.zeros((4096, 1))
    impulse[0, 0] = 1.0
    response = np.zeros_like(impulse)
    _band_filter(impulse, sos, np.zeros((sos.shape[0], 1, 2)), response)
    h = response[:, 0]
    power = float(h @ h)
    return np.array([float(h[k:] @ h[:-k]) / power for k in range(1, lags + 1)])


@njit(cache=True)
def _band_filter(x, sos, state, out):  # pragma: no cover
    """Filter (N, C) ``x`` through the sections into ``out``; ``state`` (sections, C, 2)
    carries over (transposed direct form II)."""
    n, channels = x.shape
    sections = sos.shape[0]
    for i in range(n):
        for c in range(channels):
            v = x[i, c]
            for s in range(sections):
                y = sos[s, 0] * v + state[s, c, 0]
                state[s, c, 0] = sos[s, 1] * v - sos[s, 4] * y + state[s, c, 1]
                state[s, c, 1] = sos[s, 2] * v - sos[s, 5] * y
                v = y
            out[i, c] = v


class MotionNoiseCheck:
    """Added noise on one of six channels (ax..gz) while moving; see the module docstring.

    :meth:`filter` per chunk of samples (in stream order, a chunk never crossing a window's
    end), :meth:`end_window` at each 0.25 s window's end; :attr:`flagged` (6,) the channels
    whose test holds, :attr:`level` the median ratio over the other channels and :attr:`own`
    the last window's power over the channel's own recent level.
    """

    def __init__(self, window: int, odr_hz: float) -> None:
        self.window = window
        self.enabled = BAND[0] * odr_hz >= MIN_LOW_HZ
        self._sos = np.vstack([butterworth_sos(ORDER, BAND[0], "high"),
                               butterworth_sos(ORDER, BAND[1], "low")])
        self._thresholds = np.log(np.array([RATIO_ACCEL] * 3 + [RATIO_GYRO] * 3))
        self._white_reference = band_autocorrelation(self._sos)
        self._out = np.zeros((window, 6))
        self._residual_thresholds = np.log(np.array([RESIDUAL_RATIO_ACCEL] * 3
                                                    + [RESIDUAL_RATIO_GYRO] * 3))
        self._coherence = CoherenceCheck(HISTORY_WINDOWS, HISTORY_GAP, HISTORY_MIN,
                                         self._white_reference, WHITE_TOLERANCE)
        self.reset()

    def reset(self) -> None:
        """Forget the history (a new sensor)."""
        self._history = RowHistory(HISTORY_WINDOWS + HISTORY_GAP, 6)
        self._level = np.zeros(6)
        self._coherence.reset()
        self.restart()

    def restart(self) -> None:
        """A gap: the filter starts again and the decision with it; the levels stay."""
        self._state = np.zeros((self._sos.shape[0], 6, 2))
        self._settle = 2
        self._ratios = RowHistory(SPAN_WINDOWS, 6)
        self._white = RowHistory(SPAN_WINDOWS, 6, np.bool_)
        self._residuals = RowHistory(SPAN_WINDOWS, 6)
        self._residual_white = RowHistory(SPAN_WINDOWS, 6, np.bool_)
        self._rate_sq = 0.0
        self._coherence.restart()
        self.flagged = np.zeros(6, dtype=bool)
        self.by_band = np.zeros(6, dtype=bool)
        self.by_residual = np.zeros(6, dtype=bool)
        self._rate_window = 0.0
        self.level = np.ones(6)
        self.residual_level = np.ones(6)
        self.own = np.ones(6)

    def filter(self, x: np.ndarray, position: int) -> None:
        """Band-pass the rows ``x`` (N, 6) into the window's buffer from ``position`` on."""
        if self.enabled:
            _band_filter(x, self._sos, self._state,
                         self._out[position:position + len(x)])
            self._rate_sq += float(np.einsum("ij,ij->", x[:, 3:], x[:, 3:]))

    def end_window(self, n: int) -> None:
        """Close a window of ``n`` samples: its power, the ratio, the decision."""
        self._rate_window = math.sqrt(self._rate_sq / max(n, 1))
        self._rate_sq = 0.0
        if n < self.window // 2 or not self.enabled:
            return
        power = column_median(self._out[:n], True, True)
        if self._settle > 0:  # the filter's start-up transient
            self._settle -= 1
            return
        log_raw = None
        if len(self._history) >= HISTORY_MIN + HISTORY_GAP:
            past = self._history.rows()[:-HISTORY_GAP]
            level = np.maximum(column_median(past, False, True), 1e-300)
            self._level = level
            log_r = np.log(np.maximum(power, 1e-300) / level)
            log_raw = log_r
            self._ratios.append(less_others(log_r))
            self._white.append(self._whiteness(n))
            if len(self._ratios) == SPAN_WINDOWS:
                median = column_median(self._ratios.rows(), False, True)
                white = 2 * self._white.rows().sum(axis=0) >= SPAN_WINDOWS
                self.by_band = (median > self._thresholds) & white
                self.level = np.exp(median)
                self.own = np.exp(log_r)
        self._residual_test(n, log_raw)
        self.flagged = self.by_band | self.by_residual
        # a flagged channel keeps the level it had: its noisy windows teach nothing
        self._history.append(np.where(self.flagged, self._level, power))

    def _residual_test(self, n: int, log_raw: np.ndarray | None) -> None:
        """The coherence test (:mod:`app.core.faults.coherence`) beside the band's."""
        log_s, white = self._coherence.window(self._out[:n], self._rate_window, log_raw,
                                              self.flagged)
        self._residuals.append(np.where(np.isfinite(log_s), log_s, 0.0))
        self._residual_white.append(white)
        if len(self._residuals) < SPAN_WINDOWS:
            return
        median = column_median(self._residuals.rows(), False, True)
        white_most = 2 * self._residual_white.rows().sum(axis=0) > SPAN_WINDOWS
        # onset: over the threshold and white; held while over its square root (RELEASE),
        # so that a dip in a burst of motion does not let the noise into the history
        self.by_residual = np.where(self.by_residual, median > RELEASE * self._residual_thresholds,
                                    (median > self._residual_thresholds) & white_most)
        self.residual_level = np.exp(median)

    def _whiteness(self, n: int) -> np.ndarray:
        """Per channel: the window's band output looks like band-limited white noise."""
        return _worst_lag(self._out[:n], self._white_reference) <= WHITE_TOLERANCE


@njit(cache=True)
def _worst_lag(out, reference):  # pragma: no cover - compiled
    """Per column of ``out``: the largest |autocorrelation - reference| over lags 1..len, as
    ``np.einsum("ij,ij->j", out[k:], out[:-k]) / np.maximum(power, 1e-300)`` (its sums run
    row after row from 0.0, as einsum's do here) and ``np.maximum`` (NaN wins)."""
    n, channels = out.shape
    power = np.zeros(channels)
    for i in range(n):
        for c in range(channels):
            power[c] += out[i, c] * out[i, c]
    worst = np.zeros(channels)
    lagged = np.empty(channels)
    for k in range(1, len(reference) + 1):
        lagged[:] = 0.0
        for i in range(n - k):
            for c in range(channels):
                lagged[c] += out[k + i, c] * out[i, c]
        for c in range(channels):
            p = power[c] if (power[c] != power[c] or power[c] > 1e-300) else 1e-300
            d = abs(lagged[c] / p - reference[k - 1])
            if d != d or d > worst[c]:
                worst[c] = d
    return worst
