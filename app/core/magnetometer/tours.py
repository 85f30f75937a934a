"""Deterministic simulated calibration tours with a known truth (tests and benchmarks).

A unit's magnetometer reads ``raw = S T b + h + noise``: ``b`` the earth's field in the
accelerometer's frame, ``T`` the chip's turn against the accelerometer, ``S`` the soft-iron
distortion, ``h`` the hard iron. The exact calibration is ``soft_iron = (S T)^-1``, scaled to
determinant 1 (:func:`true_soft_iron`). Orientations ``R`` turn the sensor frame into the
earth frame (ENU, y toward magnetic north), as :mod:`app.core.earth_field` has it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.core.earth_field import EarthField
from app.core.magnetometer.fit import rotation_matrices
from app.core.samples import STANDARD_GRAVITY_M_S2

LIS3MDL_NOISE_UT = np.array([0.32, 0.32, 0.41])
"""RMS noise per axis at +-4 gauss, ultra-high-performance mode (datasheet, about)."""
LIS3MDL_LSB_UT = 100.0 / 6842.0
"""Resolution at +-4 gauss: 6842 LSB/gauss."""
ACCEL_NOISE_M_S2 = 0.006
GYRO_NOISE_RAD_S = 0.002


@dataclass(frozen=True)
class MagUnit:
    """One unit's magnetometer errors."""

    hard_iron_ut: np.ndarray
    distortion: np.ndarray
    """S: the soft-iron distortion (gain included)."""
    turn: np.ndarray
    """T: rotation from the accelerometer's axes to the magnetometer chip's."""

    @property
    def turn_deg(self) -> float:
        return math.degrees(math.acos(float(np.clip((np.trace(self.turn) - 1) / 2, -1, 1))))

    def measure(self, body_field_ut: np.ndarray) -> np.ndarray:
        """The noise-free reading of a field given in the accelerometer's frame."""
        return body_field_ut @ (self.distortion @ self.turn).T + self.hard_iron_ut


def true_soft_iron(unit: MagUnit) -> np.ndarray:
    """The exact soft-iron matrix, determinant 1."""
    inverse = np.linalg.inv(unit.distortion @ unit.turn)
    return inverse / np.cbrt(np.linalg.det(inverse))


def rotation_about(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * kx + (1 - math.cos(angle_rad)) * kx @ kx


def random_unit(seed: int, hard_iron_ut: float = 30.0, soft_fraction: float = 0.04,
                turn_deg: float = 1.5) -> MagUnit:
    """A realistic unit: hard iron of about ``hard_iron_ut`` per axis, a symmetric distortion
    of a few percent plus a gain error, and a turn of ``turn_deg`` about a random axis."""
    rng = np.random.default_rng(seed)
    hard = rng.uniform(-1.0, 1.0, 3) * hard_iron_ut
    off = rng.uniform(-0.5, 0.5, 3) * soft_fraction
    distortion = np.diag(1.0 + rng.uniform(-1.0, 1.0, 3) * soft_fraction)
    distortion[0, 1] = distortion[1, 0] = off[0]
    distortion[0, 2] = distortion[2, 0] = off[1]
    distortion[1, 2] = distortion[2, 1] = off[2]
    turn = rotation_about(rng.normal(size=3), math.radians(turn_deg))
    return MagUnit(hard, distortion, turn)


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3, 3) rotations uniformly distributed."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


@dataclass(frozen=True)
class Tour:
    """A simulated tour: rows at ``rate_hz``, the field on every ``mag_every``-th row."""

    t_s: np.ndarray
    accel_m_s2: np.ndarray
    gyro_rad_s: np.ndarray
    mag_ut: np.ndarray
    """Measured field (noise, quantisation), NaN rows between field samples."""
    rotations: np.ndarray
    """(N, 3, 3) true sensor-to-earth rotations."""
    clean_mag_ut: np.ndarray
    """The same rows without noise, quantisation or disturbance."""


def _sensor_rows(unit: MagUnit, earth: EarthField, rotations: np.ndarray,
                 linear_m_s2: np.ndarray, rng: np.random.Generator, mag_every: int,
                 disturbance_ut: np.ndarray | None, field_scale: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = rotations.shape[0]
    up = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
    accel = np.einsum("nji,nj->ni", rotations, linear_m_s2 + up)
    accel += rng.normal(scale=ACCEL_NOISE_M_S2, size=accel.shape)
    body_field = np.einsum("nji,j->ni", rotations, earth.enu_magnetic_ut() * field_scale)
    clean = unit.measure(body_field)
    noisy = clean + rng.normal(size=clean.shape) * LIS3MDL_NOISE_UT
    if disturbance_ut is not None:
        noisy = noisy + disturbance_ut
    noisy = np.round(noisy / LIS3MDL_LSB_UT) * LIS3MDL_LSB_UT
    empty = np.ones(n, dtype=bool)
    empty[::mag_every] = False
    noisy[empty] = np.nan
    clean = clean.copy()
    clean[empty] = np.nan
    return accel, noisy, clean


def pose_tour(unit: MagUnit, earth: EarthField, seed: int, poses: int = 150,
              rows_per_pose: int = 8, rate_hz: float = 100.0, mag_every: int = 2,
              half_sphere: bool = False, disturbance_ut: float = 0.0,
              field_scale: float = 1.0) -> Tour:
    """Random orientations covering the sphere, each held still for ``rows_per_pose`` rows.

    ``half_sphere``: only orientations whose field points into the sensor's upper half (a
    tour that skipped half the directions). ``disturbance_ut``: a magnet passing by adds a
    field of this strength to a run of 5 % of the rows in the middle of the tour.
    ``field_scale`` multiplies the earth's field (a place far from the WMM's value).
    """
    rng = np.random.default_rng(seed)
    chosen = []
    while sum(len(c) for c in chosen) < poses:
        candidates = random_rotations(poses, rng)
        if half_sphere:
            body = np.einsum("nji,j->ni", candidates, earth.enu_magnetic_ut())
            candidates = candidates[body[:, 2] > 0]
        chosen.append(candidates)
    rotations = np.repeat(np.concatenate(chosen)[:poses], rows_per_pose, axis=0)
    n = rotations.shape[0]
    disturbance = None
    if disturbance_ut:
        disturbance = np.zeros((n, 3))
        start, length = n // 2, max(1, n // 20)
        bump = np.sin(np.linspace(0, math.pi, length))[:, None]
        disturbance[start:start + length] = bump * disturbance_ut * np.array([0.6, -0.64, 0.48])
    accel, mag, clean = _sensor_rows(unit, earth, rotations, np.zeros((n, 3)), rng, mag_every,
                                     disturbance, field_scale)
    gyro = rng.normal(scale=GYRO_NOISE_RAD_S, size=(n, 3))
    return Tour(np.arange(n) / rate_hz, accel, gyro, mag, rotations, clean)


def _smooth_noise(rng: np.random.Generator, n: int, width: int) -> np.ndarray:
    """(n, 3) zero-mean noise low-passed over about ``width`` rows, unit RMS."""
    raw = rng.normal(size=(n + 4 * width, 3))
    kernel = np.exp(-0.5 * (np.arange(-2 * width, 2 * width + 1) / width) ** 2)
    smooth = np.stack([np.convolve(raw[:, k], kernel, mode="valid")[:n] for k in range(3)], 1)
    return smooth / np.sqrt(np.mean(smooth ** 2))


def hand_tour(unit: MagUnit, earth: EarthField, seed: int, seconds: float = 60.0,
              rate_hz: float = 100.0, mag_every: int = 1, rate_rad_s: float = 1.2,
              linear_m_s2: float = 0.3, gyro_bias_rad_s: float = 0.01) -> Tour:
    """A tour by hand: the sensor turned continuously (a smooth random angular rate of about
    ``rate_rad_s``) and shaken a little (``linear_m_s2`` RMS of linear acceleration); the
    gyroscope reads with a constant bias of ``gyro_bias_rad_s`` per axis (an uncalibrated
    LSM6DSOX: about half a degree per second)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    width = max(1, int(0.4 * rate_hz))
    omega = _smooth_noise(rng, n, width) * rate_rad_s / math.sqrt(3.0)
    rotations = np.empty((n, 3, 3))
    current = random_rotations(1, rng)[0]
    dt = 1.0 / rate_hz
    steps = rotation_matrices(omega * dt)
    for i in range(n):
        rotations[i] = current
        current = current @ steps[i]
    linear = _smooth_noise(rng, n, width) * linear_m_s2 / math.sqrt(3.0)
    accel, mag, clean = _sensor_rows(unit, earth, rotations, linear, rng, mag_every, None, 1.0)
    gyro = omega + gyro_bias_rad_s + rng.normal(scale=GYRO_NOISE_RAD_S, size=(n, 3))
    return Tour(np.arange(n) * dt, accel, gyro, mag, rotations, clean)


def heading_errors_deg(calibrated_ut: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """Per row: the calibrated field turned into the earth frame with the true orientation,
    its horizontal direction's angle from magnetic north (degrees, east positive)."""
    earth = np.einsum("nij,nj->ni", rotations, calibrated_ut)
    return np.degrees(np.arctan2(earth[:, 0], earth[:, 1]))
