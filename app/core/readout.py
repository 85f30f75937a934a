"""What the instrument displays: angles averaged over a short time window.

A tilt meter shows a steady figure, not the last noisy sample. Averaging is done on the up
vector (not on the angles), so it is exact across the +-180 degree wrap.
"""

from __future__ import annotations

import numpy as np

from app.core.orientation import TiltAngles, angles_from_up, up_in_sensor_frame


def averaged_angles(quat: np.ndarray) -> TiltAngles | None:
    """Angles (floats, degrees) of the mean up direction of quaternions (N, 4); None if empty."""
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    quat = quat[np.all(np.isfinite(quat), axis=1)]
    if len(quat) == 0:
        return None
    mean_up = up_in_sensor_frame(quat).mean(axis=0)
    angles = angles_from_up(mean_up)
    return TiltAngles(*(float(v) for v in (
        angles.roll_deg, angles.pitch_deg, angles.tilt_deg, angles.direction_deg
    )))


def averaged_angle_deg(angles_deg: np.ndarray) -> float | None:
    """Circular mean (degrees, -180 ... 180) of angles in degrees, NaNs left out; None if empty.

    Averaged on the unit circle like the tilt readout's up vector, so exact across the wrap.
    """
    angles = np.asarray(angles_deg, dtype=np.float64).ravel()
    angles = angles[np.isfinite(angles)]
    if len(angles) == 0:
        return None
    rad = np.radians(angles)
    return float(np.degrees(np.arctan2(np.sin(rad).mean(), np.cos(rad).mean())))
