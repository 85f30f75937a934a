"""The heading offset between two magnetometer-free orientation estimates, from a hinge.

Each link's 6D orientation (gyroscope and accelerometer) knows the vertical but not the
heading: the two estimates live in earth frames turned by an unknown, slowly drifting angle
``delta`` about the vertical. A hinge ties them together: its axis, ``e1 = R1 j1`` seen from
link 1 and ``e2 = R2 j2`` from link 2, is one direction, so ``Rz(delta) e1 = e2``. With the
horizontal parts written as complex numbers ``c = e_x + i e_y``, each sample measures
``z = c2 conj(c1) = |c1| |c2| exp(i delta)``: the angle is the offset, the magnitude how much
the sample says about it (nothing when the axis is vertical).

:class:`HeadingTracker` follows ``delta`` causally with a two-state Kalman filter (offset and
its drift rate, the rate a random walk: what the two filters' residual gyroscope-bias errors
about the vertical produce), whose measurement noise grows as ``1 / (|c1| |c2|)``.
"""

from __future__ import annotations

import math

import numpy as np

from app.core import quaternion as quat

DEFAULT_MEASUREMENT_SD_RAD = math.radians(2.0)
"""Heading error of one second of samples with a horizontal axis (both links' tilt errors)."""
DEFAULT_DRIFT_WALK_RAD_S2 = math.radians(0.02)
"""Random walk of the heading drift rate, rad/s per sqrt(s): how fast the bias residual moves."""
DEFAULT_INITIAL_RATE_SD_RAD_S = math.radians(0.5)


def heading_measurements(quat1: np.ndarray, j1: np.ndarray, quat2: np.ndarray,
                         j2: np.ndarray) -> np.ndarray:
    """(N,) complex ``c2 conj(c1)`` of the hinge axis' horizontal parts (see the module)."""
    e1 = quat.rotate(quat1, j1)
    e2 = quat.rotate(quat2, j2)
    return (e2[:, 0] + 1j * e2[:, 1]) * (e1[:, 0] - 1j * e1[:, 1])


def heading_quaternion(delta_rad: np.ndarray) -> np.ndarray:
    """(N, 4) rotations by ``delta`` about the earth's vertical."""
    half = 0.5 * np.asarray(delta_rad, dtype=np.float64)
    zero = np.zeros_like(half)
    return np.stack([np.cos(half), zero, zero, np.sin(half)], axis=-1)


class HeadingTracker:
    """Causal estimate of the heading offset from :func:`heading_measurements`.

    Parameters
    ----------
    measurement_sd_rad : see :data:`DEFAULT_MEASUREMENT_SD_RAD` (a 1 s figure; per sample it
        is scaled by sqrt(sample rate), the samples' errors being correlated over ~1 s at most).
    drift_walk : see :data:`DEFAULT_DRIFT_WALK_RAD_S2`.
    """

    def __init__(self, measurement_sd_rad: float = DEFAULT_MEASUREMENT_SD_RAD,
                 drift_walk: float = DEFAULT_DRIFT_WALK_RAD_S2) -> None:
        self.measurement_sd_rad = measurement_sd_rad
        self.drift_walk = drift_walk
        self.reset()

    def reset(self) -> None:
        self.delta = math.nan
        self.rate = 0.0
        self._p = np.zeros((2, 2))

    @property
    def started(self) -> bool:
        return math.isfinite(self.delta)

    def update(self, z: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """Offsets (N,) rad after each measurement ``z`` (N,) complex, steps ``dt`` (N,) s."""
        out = np.empty(len(z))
        delta, rate = self.delta, self.rate
        p00, p01, p11 = self._p[0, 0], self._p[0, 1], self._p[1, 1]
        walk2 = self.drift_walk ** 2
        r_cont = self.measurement_sd_rad ** 2
        weights = np.abs(z)
        angles = np.angle(z)
        for i in range(len(z)):
            w = float(weights[i])
            h = float(dt[i])
            if not math.isfinite(delta):
                if w < 0.2:
                    out[i] = math.nan
                    continue
                delta, rate = float(angles[i]), 0.0
                p00, p01, p11 = math.radians(10.0) ** 2, 0.0, DEFAULT_INITIAL_RATE_SD_RAD_S ** 2
                out[i] = delta
                continue
            # predict
            delta += rate * h
            p00 += h * (2.0 * p01 + h * p11)
            p01 += h * p11
            p11 += walk2 * h
            # measure
            if w > 1e-3:
                r = r_cont / (h * w * w) if h > 0 else r_cont * 1e3
                s = p00 + r
                k0, k1 = p00 / s, p01 / s
                e = math.remainder(float(angles[i]) - delta, 2.0 * math.pi)
                delta += k0 * e
                rate += k1 * e
                p11 -= k1 * p01
                p01 -= k0 * p01
                p00 -= k0 * p00
            out[i] = delta
        self.delta, self.rate = delta, rate
        self._p = np.array([[p00, p01], [p01, p11]])
        return out
