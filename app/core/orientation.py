"""Orientation conventions: quaternions to the angles a tilt meter shows.

Conventions
-----------
The orientation quaternion ``q`` rotates sensor-frame vectors into the earth frame, earth z up.
The instrument's angles depend only on where "up" lies in the sensor frame,
``u = conj(q) * (0, 0, 1) * q`` (at rest, the normalised accelerometer reading):

- **roll** = ``atan2(u_y, u_z)``: rotation about the sensor x axis, positive when the +y side
  is raised. Range (-180, 180]; upside down gives +-180.
- **pitch** = ``atan2(u_x, hypot(u_y, u_z))``: elevation of the sensor x axis above the
  horizon, positive when the +x side is raised. Range [-90, 90].
- **tilt** = ``acos(u_z)``: angle between sensor z and vertical, in [0, 180].
- **tilt direction** = ``atan2(u_y, u_x)`` in [0, 360): the direction, in the sensor x-y plane
  measured from +x towards +y, of the side that is raised. 0 when the sensor is level.

Equivalently ``q = Rz(yaw) * Ry(-pitch) * Rx(roll)`` and
``u = (sin pitch, sin roll cos pitch, cos roll cos pitch)``.

Near pitch = +-90 degrees, ``u_y`` and ``u_z`` both vanish and roll is undefined (the x axis is
vertical): roll then follows the noise. Tilt and tilt direction stay well defined there, so use
them for steep surfaces. Yaw (heading) is not observable without a magnetometer and is not shown.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core import quaternion as quat


@dataclass(slots=True)
class TiltAngles:
    """Per-sample angles in degrees (arrays of shape (N,), or floats)."""

    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    tilt_deg: np.ndarray
    direction_deg: np.ndarray


def up_in_sensor_frame(q: np.ndarray) -> np.ndarray:
    """The earth's up direction expressed in the sensor frame, shape (..., 3)."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    up = np.empty((*q.shape[:-1], 3))
    up[..., 0] = 2.0 * (x * z - w * y)
    up[..., 1] = 2.0 * (y * z + w * x)
    up[..., 2] = 1.0 - 2.0 * (x * x + y * y)
    return up


def angles_from_up(up: np.ndarray) -> TiltAngles:
    """Roll, pitch, tilt and tilt direction (degrees) from the up vector in the sensor frame.

    ``up`` need not be normalised (an accelerometer reading works).
    """
    up = np.asarray(up, dtype=np.float64)
    ux, uy, uz = up[..., 0], up[..., 1], up[..., 2]
    horizontal = np.hypot(ux, uy)
    roll = np.degrees(np.arctan2(uy, uz))
    pitch = np.degrees(np.arctan2(ux, np.hypot(uy, uz)))
    tilt = np.degrees(np.arctan2(horizontal, uz))
    direction = np.degrees(np.arctan2(uy, ux)) % 360.0
    return TiltAngles(roll, pitch, tilt, direction)


def angles_from_quaternion(q: np.ndarray) -> TiltAngles:
    """Roll, pitch, tilt and tilt direction (degrees) of sensor-to-earth quaternions."""
    return angles_from_up(up_in_sensor_frame(q))


def quaternion_from_roll_pitch(
    roll_deg: np.ndarray | float, pitch_deg: np.ndarray | float, yaw_deg: np.ndarray | float = 0.0
) -> np.ndarray:
    """Sensor-to-earth quaternion ``Rz(yaw) * Ry(-pitch) * Rx(roll)`` (degrees in)."""
    half_roll, half_pitch, half_yaw = np.broadcast_arrays(
        np.radians(roll_deg) * 0.5, np.radians(pitch_deg) * -0.5, np.radians(yaw_deg) * 0.5
    )
    cr, sr = np.cos(half_roll), np.sin(half_roll)
    cp, sp = np.cos(half_pitch), np.sin(half_pitch)
    cy, sy = np.cos(half_yaw), np.sin(half_yaw)
    # The product Rz(yaw) * Ry(-pitch) * Rx(roll), written out.
    q = np.empty((*cr.shape, 4))
    q[..., 0] = cr * cp * cy + sr * sp * sy
    q[..., 1] = sr * cp * cy - cr * sp * sy
    q[..., 2] = cr * sp * cy + sr * cp * sy
    q[..., 3] = cr * cp * sy - sr * sp * cy
    return quat.normalize(q)


def quaternion_from_up(up: np.ndarray) -> np.ndarray:
    """Zero-yaw quaternion whose up vector is ``up`` (for example an accelerometer reading)."""
    angles = angles_from_up(up)
    return quaternion_from_roll_pitch(angles.roll_deg, angles.pitch_deg)


def inclination_error_deg(q_estimate: np.ndarray, q_reference: np.ndarray) -> np.ndarray:
    """Angle in degrees between estimated and reference gravity directions (sensor frame)."""
    u_est = up_in_sensor_frame(q_estimate)
    u_ref = up_in_sensor_frame(q_reference)
    cross = np.linalg.norm(np.cross(u_est, u_ref), axis=-1)
    dot = np.sum(u_est * u_ref, axis=-1)
    return np.degrees(np.arctan2(cross, dot))

