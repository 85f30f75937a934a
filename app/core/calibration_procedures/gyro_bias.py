"""Gyroscope bias: hold still for N seconds; the step restarts by itself when the board moves.

At rest the gyroscope's true rate is zero (the earth's 0.004 dps rotation is far below the
LSM6DSOX's resolution here), so the mean reading over a still stretch *is* the bias, at the
current temperature. Its uncertainty is reported two ways and the larger one is used:

- white noise: ``std / sqrt(n)`` per axis;
- batch means: the collection is cut into ``batches`` consecutive pieces and the standard
  deviation of their means is divided by ``sqrt(batches)``. This also sees correlated noise
  (bias random walk, temperature drift, slow vibration) that ``std / sqrt(n)`` misses.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from app.core.calibration_procedures.stillness import StillnessDetector
from app.core.samples import SampleBlock

DEFAULT_DURATION_S = 10.0
DEFAULT_BATCHES = 10
DEFAULT_MAX_DRIFT_DEG = 0.05
"""Largest accepted turn of the accelerometer reading between the first and last quarter."""


class GyroBiasState(Enum):
    """Where the gyro-bias step stands."""

    WAITING = "waiting"
    """Not still yet (or the window is still filling)."""
    COLLECTING = "collecting"
    RESTARTED = "restarted"
    """The board moved while collecting: the samples were dropped; waiting to be still again."""
    DONE = "done"


@dataclass(frozen=True)
class GyroBiasResult:
    """The measured gyroscope bias (rad/s, sensor axes) and its quality.

    Attributes
    ----------
    bias_rad_s : (3,) mean rate at rest.
    std_error_rad_s : (3,) uncertainty of the bias, the larger of the two estimates below.
    white_std_error_rad_s : (3,) ``std / sqrt(n)``.
    batch_std_error_rad_s : (3,) from the scatter of batch means (NaN with fewer than 2).
    noise_std_rad_s : (3,) per-sample standard deviation while still.
    samples, duration_s : what was averaged.
    temperature_degc : mean die temperature during the collection.
    restarts : how often the step restarted because the board moved.
    """

    bias_rad_s: np.ndarray
    std_error_rad_s: np.ndarray
    white_std_error_rad_s: np.ndarray
    batch_std_error_rad_s: np.ndarray
    noise_std_rad_s: np.ndarray
    samples: int
    duration_s: float
    temperature_degc: float
    restarts: int

    @property
    def bias_dps(self) -> np.ndarray:
        return np.degrees(self.bias_rad_s)

    @property
    def std_error_dps(self) -> np.ndarray:
        return np.degrees(self.std_error_rad_s)


def gyro_bias_from_samples(
    gyro_rad_s: np.ndarray,
    temp_degc: np.ndarray | None = None,
    batches: int = DEFAULT_BATCHES,
    duration_s: float = math.nan,
    restarts: int = 0,
) -> GyroBiasResult:
    """Bias and uncertainty from still samples (N, 3); see the module docstring."""
    gyro = np.asarray(gyro_rad_s, dtype=np.float64).reshape(-1, 3)
    n = len(gyro)
    if n < 2:
        raise ValueError("at least two still samples are needed for a gyro bias")
    bias = gyro.mean(axis=0)
    noise = gyro.std(axis=0, ddof=1)
    white = noise / math.sqrt(n)
    batches = min(batches, n // 2)
    if batches >= 2:
        means = np.array([piece.mean(axis=0) for piece in np.array_split(gyro, batches)])
        batch = means.std(axis=0, ddof=1) / math.sqrt(batches)
        std_error = np.maximum(white, batch)
    else:
        batch = np.full(3, np.nan)
        std_error = white
    no_temperature = temp_degc is None or len(temp_degc) == 0
    temperature = math.nan if no_temperature else float(np.mean(temp_degc))  # type: ignore[arg-type]
    return GyroBiasResult(
        bias_rad_s=bias,
        std_error_rad_s=std_error,
        white_std_error_rad_s=white,
        batch_std_error_rad_s=batch,
        noise_std_rad_s=noise,
        samples=n,
        duration_s=duration_s,
        temperature_degc=temperature,
        restarts=restarts,
    )


class GyroBiasCalibration:
    """The gyro-bias step as a small state machine fed with (uncalibrated) sample blocks.

    Parameters
    ----------
    detector : the stillness detector to use (its state is shared: do not feed it elsewhere).
    duration_s : how long the board must stay still.
    batches : number of batch means for the uncertainty.
    max_drift_deg : the collection restarts when the accelerometer's mean direction over its
        first and last quarters differ by more (a slow turn, too slow for the stillness test,
        that would bias the result: 0.01 dps about a horizontal axis turns 0.075 degree
        between the quarters of 10 s). A slow turn about the vertical stays unseen.

    Attributes
    ----------
    state : :class:`GyroBiasState`.
    restarts : how often the board moved during a collection.
    restart_reason : the message of the last restart, or None.
    message : one line for the user describing the state.
    result : the :class:`GyroBiasResult` once ``state`` is DONE, else None.
    """

    def __init__(
        self,
        detector: StillnessDetector,
        duration_s: float = DEFAULT_DURATION_S,
        batches: int = DEFAULT_BATCHES,
        max_drift_deg: float = DEFAULT_MAX_DRIFT_DEG,
    ) -> None:
        self.detector = detector
        self.max_drift_deg = float(max_drift_deg)
        self.duration_s = float(duration_s)
        self.batches = batches
        self.samples_needed = max(2, math.ceil(duration_s * detector.noise.odr_hz))
        self.reset()

    def reset(self) -> None:
        """Start over (forgets restarts and any result)."""
        self.detector.reset()
        self.state = GyroBiasState.WAITING
        self.restarts = 0
        self.restart_reason: str | None = None
        """Why the collection last restarted (kept while a new one runs)."""
        self.result: GyroBiasResult | None = None
        self.message = "Put the board down and keep it still."
        self._gyro: list[np.ndarray] = []
        self._accel: list[np.ndarray] = []
        self._temp: list[np.ndarray] = []
        self._count = 0
        self._start_s = math.nan

    @property
    def progress(self) -> float:
        """Fraction 0..1 of the still time collected so far."""
        if self.state is GyroBiasState.DONE:
            return 1.0
        return min(1.0, self._count / self.samples_needed)

    def update(self, block: SampleBlock) -> GyroBiasState:
        """Feed one block; returns the new state."""
        if len(block) == 0:
            return self.state
        flags = self.detector.update(block)  # kept running for the live stillness display
        if self.state is GyroBiasState.DONE:
            return self.state
        edges = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
        bounds = [0, *edges.tolist(), len(flags)]
        for start, stop in itertools.pairwise(bounds):
            if flags[start]:
                self._collect(block, start, stop)
                if self.state is GyroBiasState.DONE:
                    break
            elif self.state is GyroBiasState.COLLECTING:
                self._restart(float(block.t_s[start]))
        return self.state

    def _collect(self, block: SampleBlock, start: int, stop: int) -> None:
        if self.state is not GyroBiasState.COLLECTING:
            self.state = GyroBiasState.COLLECTING
            self._start_s = float(block.t_s[start])
        take = min(stop - start, self.samples_needed - self._count)
        self._gyro.append(np.asarray(block.gyro_rad_s[start : start + take]))
        self._accel.append(np.asarray(block.accel_m_s2[start : start + take]))
        self._temp.append(np.asarray(block.temp_degc[start : start + take]))
        self._count += take
        self.message = "Keep still..."
        if self._count >= self.samples_needed:
            end_s = float(block.t_s[start + take - 1])
            accel = np.vstack(self._accel)
            quarter = max(1, len(accel) // 4)
            drift = _angle_deg(accel[:quarter].mean(axis=0), accel[-quarter:].mean(axis=0))
            if drift > self.max_drift_deg:
                self._restart(
                    end_s,
                    f"The board turned slowly ({drift:.2f} deg while collecting, at most "
                    f"{self.max_drift_deg:g} deg allowed); starting again. Let it rest on a "
                    "table.",
                )
                return
            gyro = np.vstack(self._gyro)
            self.result = gyro_bias_from_samples(
                gyro,
                np.concatenate(self._temp),
                self.batches,
                duration_s=end_s - self._start_s,
                restarts=self.restarts,
            )
            self.state = GyroBiasState.DONE
            self._gyro, self._accel, self._temp = [], [], []
            bias = self.result.bias_dps
            self.message = (
                f"Gyro bias {bias[0]:+.3f}, {bias[1]:+.3f}, {bias[2]:+.3f} dps "
                f"(+-{np.max(self.result.std_error_dps):.4f} dps)."
            )

    def _restart(self, time_s: float, message: str | None = None) -> None:
        held = self._count / self.detector.noise.odr_hz
        self.restarts += 1
        self.state = GyroBiasState.RESTARTED
        self._gyro, self._accel, self._temp = [], [], []
        self._count = 0
        self.message = message or (
            f"The board moved at t = {time_s:.1f} s after {held:.1f} s of {self.duration_s:g} s; "
            "starting again when it is still."
        )
        self.restart_reason = self.message


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))
