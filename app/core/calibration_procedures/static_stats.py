"""Static statistics of the angles over a fixed duration, to judge repeatability.

The default of 20 s follows the MEMS measuring-arm evaluation that averaged 2 000 samples at
100 Hz. :class:`StaticStatistics` is fed angle blocks (from the pipeline's orientation buffer
or a filter's output) and keeps the samples whose time lies within ``duration_s`` of the
first one; it reports, per angle, the mean, standard deviation (ddof = 1), minimum, maximum
and spread (max - min).

Roll wraps at +-180 degrees (upside down); it is unwrapped around the first sample before the
statistics and the mean is wrapped back, so a board lying upside down gives a sensible mean
and spread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.core.orientation import TiltAngles

DEFAULT_DURATION_S = 20.0


@dataclass(frozen=True)
class AngleStats:
    """Statistics of one angle, degrees."""

    mean: float
    std: float
    minimum: float
    maximum: float
    spread: float
    samples: int


@dataclass(frozen=True)
class StaticStatisticsResult:
    """Roll, pitch and tilt statistics over ``duration_s`` (actual span of the samples)."""

    roll: AngleStats
    pitch: AngleStats
    tilt: AngleStats
    samples: int
    duration_s: float
    t_start_s: float


def _stats(values: np.ndarray, wrap: bool = False) -> AngleStats:
    n = len(values)
    if wrap:
        values = (values - values[0] + 180.0) % 360.0 - 180.0 + values[0]
    mean = float(np.mean(values))
    minimum, maximum = float(np.min(values)), float(np.max(values))
    spread = maximum - minimum
    if wrap:
        shift = (mean + 180.0) % 360.0 - 180.0 - mean
        mean, minimum, maximum = mean + shift, minimum + shift, maximum + shift
    std = float(np.std(values, ddof=1)) if n > 1 else math.nan
    return AngleStats(mean, std, minimum, maximum, spread, n)


class StaticStatistics:
    """Collects angles for ``duration_s`` seconds of device time, then stops.

    Parameters
    ----------
    duration_s : how long to collect (from the first sample's time).
    """

    def __init__(self, duration_s: float = DEFAULT_DURATION_S) -> None:
        if not duration_s > 0.0:
            raise ValueError("the duration must be positive")
        self.duration_s = float(duration_s)
        self.reset()

    def reset(self) -> None:
        self._t: list[np.ndarray] = []
        self._roll: list[np.ndarray] = []
        self._pitch: list[np.ndarray] = []
        self._tilt: list[np.ndarray] = []
        self._t0: float | None = None
        self._last_t = -math.inf
        self.is_complete = False

    @property
    def samples(self) -> int:
        return int(sum(len(t) for t in self._t))

    @property
    def progress(self) -> float:
        """Fraction 0..1 of the duration covered."""
        if self.is_complete:
            return 1.0
        if self._t0 is None:
            return 0.0
        return min(1.0, (self._last_t - self._t0) / self.duration_s)

    def update(
        self,
        t_s: np.ndarray,
        roll_deg: np.ndarray,
        pitch_deg: np.ndarray,
        tilt_deg: np.ndarray,
    ) -> bool:
        """Feed one block of angles; returns True once the duration is complete."""
        if self.is_complete:
            return True
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        if len(t) == 0:
            return False
        if self._t0 is None:
            self._t0 = float(t[0])
        end = self._t0 + self.duration_s
        keep = t < end
        if not np.all(keep):
            self.is_complete = True
        self._t.append(t[keep])
        self._roll.append(np.asarray(roll_deg, dtype=np.float64).reshape(-1)[keep])
        self._pitch.append(np.asarray(pitch_deg, dtype=np.float64).reshape(-1)[keep])
        self._tilt.append(np.asarray(tilt_deg, dtype=np.float64).reshape(-1)[keep])
        self._last_t = float(t[-1])
        return self.is_complete

    def update_angles(self, t_s: np.ndarray, angles: TiltAngles) -> bool:
        """:meth:`update` with a :class:`~app.core.orientation.TiltAngles`."""
        return self.update(t_s, angles.roll_deg, angles.pitch_deg, angles.tilt_deg)

    def result(self) -> StaticStatisticsResult:
        """The statistics so far (complete or not); needs at least one sample."""
        if self.samples == 0:
            raise ValueError("no samples collected yet")
        t = np.concatenate(self._t)
        return StaticStatisticsResult(
            roll=_stats(np.concatenate(self._roll), wrap=True),
            pitch=_stats(np.concatenate(self._pitch)),
            tilt=_stats(np.concatenate(self._tilt)),
            samples=len(t),
            duration_s=float(t[-1] - t[0]),
            t_start_s=float(t[0]),
        )
