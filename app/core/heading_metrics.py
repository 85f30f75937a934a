"""Heading scoring on real data: BROAD's error split, and the fixed turn of the sensor frame.

BROAD's metric (Laidig et al. 2021, ``broad_utils.calculateRMSE``): the error quaternion
``e = q_est (x) q_ref^-1`` is a rotation in the earth frame (ENU, y toward magnetic north, z up),
split into its rotation about the vertical, the **heading** error ``2 atan(|e_z / e_w|)``, and
the rest, the **inclination** error ``2 acos(sqrt(e_w^2 + e_z^2))``; the **total** error is the
angle of ``e``. The inclination error equals the angle between the estimated and the true
gravity directions (:func:`app.core.orientation.inclination_error_deg`, which this reuses).

The trap: BROAD's trials start with the sensor pointing so that a gyro-only heading is nearly
right, so a 6-axis filter starting at heading zero scores a few degrees by luck. Turning the
sensor frame by a fixed rotation ``R`` (``a' = R a``, ``g' = R g``, ``m' = R m``, reference
``q' = q_ref (x) R^-1``) removes that luck and changes no inclination: only the magnetometer can
then find north. :data:`PROJECT_TURN_DEG` is the project's fixed turn (``evaluate --turn``).

Numpy only: no Qt.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from app.core import quaternion as quat
from app.core.orientation import inclination_error_deg
from app.core.samples import SampleBlock

PROJECT_TURN_DEG = (20.0, -30.0, 110.0)
"""The project's fixed turn of the sensor frame, a rotation vector in degrees."""


def turn_quaternion(rotation_vector_deg: tuple[float, float, float] | np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of a rotation vector given in degrees."""
    vector = np.radians(np.asarray(rotation_vector_deg, dtype=np.float64))
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise ValueError(f"a turn is three finite angles in degrees, not {rotation_vector_deg!r}")
    return quat.from_rotation_vector(vector)


def turn_vectors(turn: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Sensor-frame vectors (N, 3) in the turned frame: ``R v`` (NaN rows stay NaN)."""
    matrix = quat.rotate(turn, np.eye(3)).T  # columns: the images of the unit vectors
    return np.asarray(vectors, dtype=np.float64) @ matrix.T


def turn_reference(turn: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Sensor-to-earth quaternions (N, 4) for the turned sensor frame: ``q (x) R^-1``."""
    inverse = np.broadcast_to(quat.conjugate(turn), np.shape(reference))
    return quat.multiply(np.asarray(reference, dtype=np.float64), inverse)


def turn_block(block: SampleBlock, turn: np.ndarray) -> SampleBlock:
    """``block`` with its sensor frame turned by ``turn`` (accelerometer, gyroscope,
    magnetometer and reference alike; time, temperature and gaps unchanged)."""
    return dataclasses.replace(
        block,
        accel_m_s2=turn_vectors(turn, block.accel_m_s2),
        gyro_rad_s=turn_vectors(turn, block.gyro_rad_s),
        mag_ut=None if block.mag_ut is None else turn_vectors(turn, block.mag_ut),
        reference_quat=(None if block.reference_quat is None
                        else turn_reference(turn, block.reference_quat)),
    )


def error_quaternion(q_estimate: np.ndarray, q_reference: np.ndarray) -> np.ndarray:
    """``q_est (x) q_ref^-1`` (N, 4), normalised: the error as a rotation of the earth frame."""
    e = quat.multiply(np.asarray(q_estimate, np.float64),
                      quat.conjugate(np.asarray(q_reference, np.float64)))
    return e / np.linalg.norm(e, axis=-1, keepdims=True)


def heading_error_deg(q_estimate: np.ndarray, q_reference: np.ndarray) -> np.ndarray:
    """BROAD's heading error, degrees in [0, 180]: the error's rotation about the vertical."""
    e = error_quaternion(q_estimate, q_reference)
    return np.degrees(2.0 * np.arctan2(np.abs(e[..., 3]), np.abs(e[..., 0])))


def total_error_deg(q_estimate: np.ndarray, q_reference: np.ndarray) -> np.ndarray:
    """The angle of the error rotation, degrees in [0, 180]."""
    e = error_quaternion(q_estimate, q_reference)
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(e[..., 1:], axis=-1), np.abs(e[..., 0])))


def error_split_deg(q_estimate: np.ndarray, q_reference: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(heading, inclination, total) errors in degrees, per row."""
    return (heading_error_deg(q_estimate, q_reference),
            inclination_error_deg(q_estimate, q_reference),
            total_error_deg(q_estimate, q_reference))
