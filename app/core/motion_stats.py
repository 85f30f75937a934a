"""How a stream moves: acceleration, rotation, their spectra, tilt and rest (numpy only).

One set of figures for any stream of specific force, angular rate and (where known) true
orientation, so that a real recording and a simulated stream are described by the same code
(``benchmarks/broad_motion_stats.py`` prints them for the BROAD trials and for ``sim://`` URLs;
the simulator's tests hold its hand-held scenarios to the real trials' ranges with them).

Definitions (all over the *moving* samples unless said otherwise):

- ``|a|-g``: the magnitude of the specific force minus standard gravity, what an
  accelerometer-based tilt filter sees as disturbance; RMS and largest absolute value.
- linear acceleration: the specific force rotated into the earth frame by the true orientation,
  minus ``(0, 0, g)``; only where the orientation is known.
- spectra: Welch's method (Hann window, 50 % overlap, mean removed per segment) over the
  stretches where the values are known, the axes' power summed. Summarised by the dominant
  frequency (largest bin above 0 Hz), the median frequency (half the power below), and the
  bands holding the middle 50 % (25th-75th percentile of the power) and 90 % (5th-95th).
- tilt: angle of the sensor's z axis from vertical, from the true orientation.
- rotation: the true orientation relative to its mean (the normalised sum of the quaternions,
  signs aligned), as a rotation vector in the mean pose's axes; RMS per axis.
- rest: a sample is still when, within +-0.25 s, the rate stays below 10 dps and ``|a|-g``
  within 0.5 m/s^2; rest is a still stretch of at least 2 s. The rest fraction and the rest
  breaks are counted over the *span*: from the first to the last moving sample (a recording's
  initial and final rest are not part of the motion).

Moving samples: those flagged in ``movement`` (a recording's ``movement`` column), or, when no
flag is given, every sample of the span that is not at rest (the span is then the whole stream).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.core import quaternion as quat
from app.core.orientation import angles_from_quaternion
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

G = STANDARD_GRAVITY_M_S2
SEGMENT_S = 8.0
"""Welch segment length: 0.125 Hz resolution, 15 segments in two minutes."""
STILL_RATE_DPS = 10.0
STILL_ACCEL_M_S2 = 0.5
STILL_WINDOW_S = 0.5
MIN_REST_S = 2.0


@dataclass(frozen=True, slots=True)
class SpectrumSummary:
    """Where the power of a signal lies, Hz (NaN when there was too little data)."""

    dominant_hz: float
    median_hz: float
    band50_hz: tuple[float, float]
    band90_hz: tuple[float, float]


@dataclass(frozen=True, slots=True)
class MotionStats:
    """The figures of one stream (see the module docstring for the definitions)."""

    moving_s: float
    span_s: float
    excess_rms_m_s2: float
    excess_peak_m_s2: float
    linear_rms_m_s2: float
    linear_spectrum: SpectrumSummary
    gyro_rms_dps: float
    gyro_peak_dps: float
    gyro_spectrum: SpectrumSummary
    tilt_deg: tuple[float, float, float]
    """5th percentile, median and 95th percentile of the tilt, degrees."""
    tilt_max_deg: float
    rotation_rms_deg: tuple[float, float, float]
    """RMS rotation from the mean orientation about its x, y, z axes, degrees."""
    rest_fraction: float
    rest_breaks: int
    rest_break_mean_s: float
    reference_fraction: float
    """Fraction of the moving samples with a known orientation."""

    @property
    def excess_rms_g(self) -> float:
        return self.excess_rms_m_s2 / G

    @property
    def excess_peak_g(self) -> float:
        return self.excess_peak_m_s2 / G


# -- pieces ------------------------------------------------------------------------------------
def sample_rate_hz(t_s: np.ndarray) -> float:
    """Median rate of a time axis."""
    steps = np.diff(np.asarray(t_s, dtype=np.float64))
    steps = steps[steps > 0]
    return 1.0 / float(np.median(steps)) if len(steps) else math.nan


def linear_acceleration_earth(accel_m_s2: np.ndarray, quat_s2e: np.ndarray) -> np.ndarray:
    """Earth-frame acceleration without gravity, (N, 3); NaN rows where ``quat_s2e`` is unknown."""
    known = np.all(np.isfinite(quat_s2e), axis=1)
    out = np.full(accel_m_s2.shape, np.nan)
    q = quat.normalize(quat_s2e[known])
    out[known] = quat.rotate(q, accel_m_s2[known]) - np.array([0.0, 0.0, G])
    return out


def tilt_deg(quat_s2e: np.ndarray) -> np.ndarray:
    """Angle of the sensor z axis from vertical (N,), degrees (NaN where unknown)."""
    return angles_from_quaternion(np.asarray(quat_s2e, dtype=np.float64)).tilt_deg


def rotation_from_mean_deg(quat_s2e: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors (degrees) of known orientations from their mean orientation."""
    q = quat.normalize(np.asarray(quat_s2e, dtype=np.float64))
    if len(q) == 0:
        return np.empty((0, 3))
    q = q * np.where(q @ q[0] < 0.0, -1.0, 1.0)[:, None]
    mean = quat.normalize(np.sum(q, axis=0))
    return np.degrees(quat.to_rotation_vector(quat.multiply(quat.conjugate(mean), q)))


def runs(mask: np.ndarray) -> np.ndarray:
    """``(start, stop)`` index pairs (K, 2) of the runs of True in ``mask``."""
    padded = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return edges.reshape(-1, 2)


def _moving_max(x: np.ndarray, half: int) -> np.ndarray:
    """Largest value of ``x`` within ``+-half`` samples of each one."""
    if half <= 0 or len(x) == 0:
        return x.copy()
    padded = np.concatenate([np.full(half, -np.inf), x, np.full(half, -np.inf)])
    return np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1).max(axis=1)


def rest_mask(
    accel_m_s2: np.ndarray, gyro_rad_s: np.ndarray, rate_hz: float, *,
    rate_dps: float = STILL_RATE_DPS, accel_m_s2_tol: float = STILL_ACCEL_M_S2,
    window_s: float = STILL_WINDOW_S, min_rest_s: float = MIN_REST_S,
) -> np.ndarray:
    """(N,) True at rest: still over ``+-window_s/2`` and for at least ``min_rest_s``."""
    half = round(0.5 * window_s * rate_hz)
    rate = np.degrees(np.linalg.norm(gyro_rad_s, axis=1))
    excess = np.abs(np.linalg.norm(accel_m_s2, axis=1) - G)
    still = (_moving_max(rate, half) < rate_dps) & (_moving_max(excess, half) < accel_m_s2_tol)
    rest = np.zeros_like(still)
    for start, stop in runs(still):
        if stop - start >= min_rest_s * rate_hz:
            rest[start:stop] = True
    return rest


def welch_psd(
    x: np.ndarray, rate_hz: float, valid: np.ndarray | None = None, segment_s: float = SEGMENT_S
) -> tuple[np.ndarray, np.ndarray, int]:
    """Welch power spectral density of ``x`` (N,) or (N, K), axes summed, per Hz.

    Only segments lying wholly inside runs of ``valid`` (default: finite rows) are used.
    Returns the frequencies, the density and the number of segments averaged.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if valid is None:
        valid = np.all(np.isfinite(x), axis=1)
    n = max(8, round(segment_s * rate_hz))
    step = n // 2
    window = np.hanning(n)
    scale = 1.0 / (rate_hz * np.sum(window * window))
    freqs = np.fft.rfftfreq(n, 1.0 / rate_hz)
    total = np.zeros(len(freqs))
    count = 0
    for start, stop in runs(valid):
        if stop - start < n:
            continue
        starts = np.arange(start, stop - n + 1, step)
        segments = np.lib.stride_tricks.sliding_window_view(x[start:stop], n, axis=0)
        segments = segments[starts - start]  # (S, K, n)
        segments = segments - segments.mean(axis=-1, keepdims=True)
        spectra = np.abs(np.fft.rfft(segments * window, axis=-1)) ** 2
        total += spectra.sum(axis=(0, 1))
        count += len(starts)
    if count == 0:
        return freqs, np.full(len(freqs), np.nan), 0
    psd = total * scale / count
    psd[1:-1] *= 2.0  # one-sided (n even: the last bin is Nyquist)
    if n % 2:
        psd[-1] *= 2.0
    return freqs, psd, count


def summarise_spectrum(freqs: np.ndarray, psd: np.ndarray) -> SpectrumSummary:
    """Dominant frequency, median frequency and the 50 % and 90 % power bands."""
    if not np.all(np.isfinite(psd)) or np.sum(psd) <= 0.0:
        nan = math.nan
        return SpectrumSummary(nan, nan, (nan, nan), (nan, nan))
    dominant = float(freqs[1:][np.argmax(psd[1:])])
    # Each bin's power spread evenly over its width: the cumulative power at the bins' upper
    # edges (a tone between two bins then has its median where it is).
    half_bin = 0.5 * float(freqs[1] - freqs[0])
    edges = np.concatenate([[0.0], freqs + half_bin])
    cumulative = np.concatenate([[0.0], np.cumsum(psd)])
    cumulative /= cumulative[-1]

    def at(fraction: float) -> float:
        return float(np.interp(fraction, cumulative, edges))

    return SpectrumSummary(dominant, at(0.5), (at(0.25), at(0.75)), (at(0.05), at(0.95)))


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x))) if len(x) else math.nan


# -- the whole picture -------------------------------------------------------------------------
def motion_stats(
    t_s: np.ndarray,
    accel_m_s2: np.ndarray,
    gyro_rad_s: np.ndarray,
    quat_s2e: np.ndarray | None = None,
    movement: np.ndarray | None = None,
    segment_s: float = SEGMENT_S,
) -> MotionStats:
    """The figures of a stream: (N,) times, (N, 3) specific force and rate, (N, 4) orientation
    (NaN rows where unknown; None: no reference) and an optional (N,) movement flag."""
    t_s = np.asarray(t_s, dtype=np.float64)
    accel = np.asarray(accel_m_s2, dtype=np.float64)
    gyro = np.asarray(gyro_rad_s, dtype=np.float64)
    n = len(t_s)
    rate = sample_rate_hz(t_s)
    if quat_s2e is None:
        quat_s2e = np.full((n, 4), np.nan)
    rest = rest_mask(accel, gyro, rate)
    if movement is None:
        span = slice(0, n)
        moving = ~rest
    else:
        moving = np.asarray(movement, dtype=bool)
        flagged = np.flatnonzero(moving)
        span = slice(int(flagged[0]), int(flagged[-1]) + 1) if len(flagged) else slice(0, 0)

    excess = np.linalg.norm(accel, axis=1) - G
    linear = linear_acceleration_earth(accel, quat_s2e)
    known = np.all(np.isfinite(linear), axis=1)
    rate_dps = np.degrees(np.linalg.norm(gyro, axis=1))
    tilt = tilt_deg(quat_s2e)
    tilt_moving = tilt[moving & known]
    rotation = rotation_from_mean_deg(quat_s2e[moving & known])
    rest_in_span = rest[span].copy()
    breaks = runs(rest_in_span)
    # A rest cut short by the span's ends is a break only if it is still long enough.
    short = breaks[:, 1] - breaks[:, 0] < MIN_REST_S * rate
    for start, stop in breaks[short]:
        rest_in_span[start:stop] = False
    breaks = breaks[~short]
    lengths = (breaks[:, 1] - breaks[:, 0]) / rate if len(breaks) else np.empty(0)

    freqs, psd, _ = welch_psd(linear, rate, moving & known, segment_s)
    g_freqs, g_psd, _ = welch_psd(gyro, rate, moving, segment_s)
    nan3 = (math.nan, math.nan, math.nan)
    return MotionStats(
        moving_s=float(np.sum(moving) / rate),
        span_s=float(len(rest_in_span) / rate),
        excess_rms_m_s2=_rms(excess[moving]),
        excess_peak_m_s2=float(np.max(np.abs(excess[moving]))) if moving.any() else math.nan,
        linear_rms_m_s2=_rms(np.linalg.norm(linear[moving & known], axis=1)),
        linear_spectrum=summarise_spectrum(freqs, psd),
        gyro_rms_dps=_rms(rate_dps[moving]),
        gyro_peak_dps=float(np.max(rate_dps[moving])) if moving.any() else math.nan,
        gyro_spectrum=summarise_spectrum(g_freqs, g_psd),
        tilt_deg=tuple(float(v) for v in np.percentile(tilt_moving, [5, 50, 95]))  # type: ignore[arg-type]
        if len(tilt_moving) else nan3,
        tilt_max_deg=float(np.max(tilt_moving)) if len(tilt_moving) else math.nan,
        rotation_rms_deg=tuple(float(v) for v in np.sqrt(np.mean(rotation**2, axis=0)))  # type: ignore[arg-type]
        if len(rotation) else nan3,
        rest_fraction=float(np.mean(rest_in_span)) if len(rest_in_span) else math.nan,
        rest_breaks=len(breaks),
        rest_break_mean_s=float(np.mean(lengths)) if len(lengths) else 0.0,
        reference_fraction=float(np.mean(known[moving])) if moving.any() else math.nan,
    )


def block_stats(block: SampleBlock, movement: np.ndarray | None = None) -> MotionStats:
    """:func:`motion_stats` of a whole stream held in one SampleBlock."""
    return motion_stats(
        block.t_s, block.accel_m_s2, block.gyro_rad_s, block.reference_quat, movement
    )
