"""Stillness detection: is the sensor lying still, judged against its own noise?

The detector keeps a sliding window of ``window_s`` seconds and computes, per axis, the
standard deviation of the accelerometer and gyroscope samples in it. The sensor is *still*
when every axis stays below ``k`` times its expected noise:

    noise RMS = noise density x sqrt(ODR / 2)   (white noise over the output bandwidth)
    sigma = sqrt(noise RMS^2 + LSB^2 / 12)       (quantisation added in quadrature)
    still  <=>  std_axis <= k * sigma  for all six axes  (and the mean rate test below)

Choice of ``k`` (default :data:`DEFAULT_K` = 3): the window estimate of a standard deviation
scatters by about ``1 / sqrt(2 n)`` (10 % for the 52 samples of 0.5 s at 104 Hz), so a still
chip at datasheet noise practically never exceeds 3 sigma, and neither does one that is up to
twice as noisy as the typical figure (vibration from a desk or a fan). A rotation that moves
the accelerometer's reading by a ramp of ``g * omega * T`` across the window raises its std by
``g * omega * T / sqrt(12)``; with sigma = 0.5 mg (104 Hz, +-4 g) and T = 0.5 s, 3 sigma is
crossed from about 0.6 dps upwards, and the gyroscope's own std catches any jerky motion.

The variance test cannot see a steady rotation about the vertical (the accelerometer reading
stays put, the gyroscope reads a constant). A second test therefore bounds the window's mean
rate: ``|mean rate - gyro bias| <= max_rate``, default 5 dps, above the chip's +-1 dps
typical zero-rate offset; pass the gyro bias once it is known to tighten it.

The LSM6DSOX figures are copied from :mod:`drivers.lsm6dsox` (``app.core`` may not import
``drivers``); a test checks that the two agree.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

# LSM6DSOX figures (same values as drivers.lsm6dsox).
ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS = 70e-6
"""Accelerometer noise density at +-2/4/8 g."""
ACCEL_NOISE_G_PER_SQRT_HZ_16G = 110e-6
"""Accelerometer noise density at +-16 g."""
GYRO_NOISE_DPS_PER_SQRT_HZ = 3.8e-3
ACCEL_MG_PER_LSB: dict[int, float] = {2: 0.061, 4: 0.122, 8: 0.244, 16: 0.488}
GYRO_MDPS_PER_LSB: dict[int, float] = {125: 4.375, 250: 8.75, 500: 17.50, 1000: 35.0, 2000: 70.0}

DEFAULT_K = 3.0
"""Threshold on each axis' window standard deviation, in units of its expected noise."""
DEFAULT_WINDOW_S = 0.5
DEFAULT_MAX_RATE_DPS = 5.0
MAX_STEP_SAMPLES = 5.0
"""A time step longer than this many sample periods is a hole in the data: the window restarts."""


@dataclass(frozen=True, slots=True)
class SensorNoise:
    """Expected white noise (with quantisation) per axis at one sensor setting.

    Attributes
    ----------
    accel_rms_m_s2, gyro_rms_rad_s : per-axis standard deviation of one sample.
    odr_hz : the output data rate the figures are for.
    """

    accel_rms_m_s2: float
    gyro_rms_rad_s: float
    odr_hz: float

    @classmethod
    def lsm6dsox(cls, odr_hz: float, accel_fs_g: int = 4, gyro_fs_dps: int = 250) -> SensorNoise:
        """Datasheet noise of the LSM6DSOX: density x sqrt(ODR / 2), plus LSB / sqrt(12)."""
        if accel_fs_g not in ACCEL_MG_PER_LSB or gyro_fs_dps not in GYRO_MDPS_PER_LSB:
            raise ValueError(f"unsupported full scales +-{accel_fs_g} g / +-{gyro_fs_dps} dps")
        bandwidth = math.sqrt(odr_hz / 2.0)
        density_g = (
            ACCEL_NOISE_G_PER_SQRT_HZ_16G if accel_fs_g == 16 else ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS
        )
        accel_white = density_g * STANDARD_GRAVITY_M_S2 * bandwidth
        accel_lsb = ACCEL_MG_PER_LSB[accel_fs_g] * 1e-3 * STANDARD_GRAVITY_M_S2
        gyro_white = math.radians(GYRO_NOISE_DPS_PER_SQRT_HZ) * bandwidth
        gyro_lsb = math.radians(GYRO_MDPS_PER_LSB[gyro_fs_dps] * 1e-3)
        return cls(
            accel_rms_m_s2=math.hypot(accel_white, accel_lsb / math.sqrt(12.0)),
            gyro_rms_rad_s=math.hypot(gyro_white, gyro_lsb / math.sqrt(12.0)),
            odr_hz=float(odr_hz),
        )


class StillnessDetector:
    """Sliding-window stillness test, fed block by block.

    Parameters
    ----------
    noise : the sensor's expected noise (sets the thresholds and the window length).
    window_s : window length in seconds (at least 8 samples).
    k : threshold in multiples of the noise standard deviation (see the module docstring).
    max_rate_rad_s : bound on the window's mean angular rate after subtracting ``gyro_bias``.
    gyro_bias_rad_s : known gyroscope bias (3,), zero when unknown.

    Notes
    -----
    :meth:`update` returns one flag per sample: True when the window ending at that sample is
    still. Flags are False until the window has filled. A marked gap, a time step backwards or
    a hole longer than :data:`MAX_STEP_SAMPLES` sample periods empties the window.
    """

    def __init__(
        self,
        noise: SensorNoise,
        window_s: float = DEFAULT_WINDOW_S,
        k: float = DEFAULT_K,
        max_rate_rad_s: float = math.radians(DEFAULT_MAX_RATE_DPS),
        gyro_bias_rad_s: np.ndarray | None = None,
    ) -> None:
        self.noise = noise
        self.window = max(8, round(window_s * noise.odr_hz))
        self.k = float(k)
        self.accel_threshold_m_s2 = self.k * noise.accel_rms_m_s2
        self.gyro_threshold_rad_s = self.k * noise.gyro_rms_rad_s
        self.max_rate_rad_s = float(max_rate_rad_s)
        self.gyro_bias_rad_s = (
            np.zeros(3) if gyro_bias_rad_s is None else np.asarray(gyro_bias_rad_s, float)
        )
        self.reset()

    def reset(self) -> None:
        """Forget the window (as after a gap)."""
        self._tail = np.empty((0, 6))
        self._tail_t = np.empty(0)
        self._last_t = -math.inf
        self.is_still = False
        self.still_since_s: float | None = None
        """Time of the first sample of the current still stretch (None while moving)."""
        self.last_time_s: float | None = None
        self.accel_std_m_s2 = np.full(3, np.nan)
        self.gyro_std_rad_s = np.full(3, np.nan)
        self.gyro_mean_rad_s = np.full(3, np.nan)

    # -- queries -----------------------------------------------------------------------------
    @property
    def window_s(self) -> float:
        return self.window / self.noise.odr_hz

    @property
    def still_duration_s(self) -> float:
        """How long the sensor has been still (0 while moving), window included."""
        if not self.is_still or self.still_since_s is None or self.last_time_s is None:
            return 0.0
        return self.last_time_s - self.still_since_s

    @property
    def accel_ratio(self) -> float:
        """Largest accelerometer axis std over its threshold (< 1 is still; NaN before data)."""
        return float(np.max(self.accel_std_m_s2) / self.accel_threshold_m_s2)

    @property
    def gyro_ratio(self) -> float:
        """Largest gyroscope axis std over its threshold (< 1 is still; NaN before data)."""
        return float(np.max(self.gyro_std_rad_s) / self.gyro_threshold_rad_s)

    # -- feeding -----------------------------------------------------------------------------
    def update(self, block: SampleBlock) -> np.ndarray:
        """Feed a block; returns the per-sample still flags (N,) bool."""
        n = len(block)
        flags = np.zeros(n, dtype=bool)
        if n == 0:
            return flags
        data = np.hstack([block.accel_m_s2, block.gyro_rad_s])
        t = np.asarray(block.t_s, dtype=np.float64)
        # Cut at marked gaps, at steps backwards in time and at unmarked holes (more than
        # MAX_STEP_SAMPLES sample periods); each piece restarts the window.
        max_step = MAX_STEP_SAMPLES / self.noise.odr_hz
        cuts = np.flatnonzero(np.asarray(block.gap, dtype=bool))
        steps = np.diff(t)
        jumps = np.flatnonzero((steps <= 0.0) | (steps > max_step)) + 1
        restart = {int(c) for c in np.union1d(cuts, jumps)}
        if t[0] <= self._last_t or t[0] - self._last_t > max_step:
            restart.add(0)
        bounds = sorted({0, n, *restart})
        for start, stop in itertools.pairwise(bounds):
            if start in restart:
                self.reset()
            flags[start:stop] = self._update_piece(t[start:stop], data[start:stop])
        return flags

    def _update_piece(self, t: np.ndarray, data: np.ndarray) -> np.ndarray:
        n = len(t)
        w = self.window
        values = np.vstack([self._tail, data])
        times = np.concatenate([self._tail_t, t])
        offset = len(self._tail)
        flags = np.zeros(n, dtype=bool)
        if len(values) >= w:
            centred = values - values[0]  # keeps the sums of squares well conditioned
            s1 = np.vstack([np.zeros((1, 6)), np.cumsum(centred, axis=0)])
            s2 = np.vstack([np.zeros((1, 6)), np.cumsum(centred * centred, axis=0)])
            first_end = max(offset, w - 1)  # index (in values) of the first full window's end
            ends = np.arange(first_end, len(values)) + 1
            sum1 = s1[ends] - s1[ends - w]
            sum2 = s2[ends] - s2[ends - w]
            var = np.maximum(sum2 - sum1 * sum1 / w, 0.0) / (w - 1)
            std = np.sqrt(var)
            mean_rate = sum1[:, 3:] / w + values[0, 3:] - self.gyro_bias_rad_s
            still = (
                np.all(std[:, :3] <= self.accel_threshold_m_s2, axis=1)
                & np.all(std[:, 3:] <= self.gyro_threshold_rad_s, axis=1)
                & (np.linalg.norm(mean_rate, axis=1) <= self.max_rate_rad_s)
            )
            flags[first_end - offset :] = still
            self.accel_std_m_s2 = std[-1, :3].copy()
            self.gyro_std_rad_s = std[-1, 3:].copy()
            self.gyro_mean_rad_s = mean_rate[-1] + self.gyro_bias_rad_s
            self._track_still_run(flags, times, offset)
        keep = min(w - 1, len(values))
        self._tail = values[len(values) - keep :].copy()
        self._tail_t = times[len(times) - keep :].copy()
        self._last_t = float(t[-1])
        self.last_time_s = float(t[-1])
        return flags

    def _track_still_run(self, flags: np.ndarray, times: np.ndarray, offset: int) -> None:
        """Update ``still_since_s`` from this piece's flags."""
        if not flags[-1]:
            self.is_still = False
            self.still_since_s = None
            return
        moving = np.flatnonzero(~flags)
        if len(moving) == 0 and self.is_still:
            return  # the still stretch continues
        start = 0 if len(moving) == 0 else int(moving[-1]) + 1
        # The first still window ending at sample ``start`` began w - 1 samples earlier.
        first = max(0, offset + start - (self.window - 1))
        self.still_since_s = float(times[first])
        self.is_still = True
