"""Axis conventions of an export: ENU (ROS REP 103) or NED, for vectors and orientations.

This program's frames (app/core/orientation.py, app/core/earth_field.py): the body frame is the
sensor's axes (z up when it lies flat: a level sensor reads +g on z, specific force), the
earth frame ENU with y toward magnetic north; a quaternion rotates body vectors into the earth
frame. That is ROS's convention (REP 103: body x forward, y left, z up; world ENU) as it is.

NED: the earth frame north-east-down, the body frame forward-right-down (x kept, y and z
negated: a rotation by 180 degrees about x), as PX4 and most aerospace tools have them. A body
vector becomes ``(x, -y, -z)``; the orientation becomes ``q_ned = W * q * conj(B)``, ``W`` the
rotation ENU -> NED (``(e, n, u) -> (n, e, -u)``, 180 degrees about (1, 1, 0)/sqrt(2)) and ``B``
the body's FLU -> FRD.
"""

from __future__ import annotations

import math

import numpy as np

from app.core import quaternion as quat

FRAMES = ("enu", "ned")
"""The axis conventions an export can state (``--frame``)."""
ENU_TO_NED = np.array([0.0, 1.0 / math.sqrt(2.0), 1.0 / math.sqrt(2.0), 0.0])
"""The earth-frame rotation ENU -> NED as a quaternion (w, x, y, z)."""
FLU_TO_FRD = np.array([0.0, 1.0, 0.0, 0.0])
"""The body-frame rotation forward-left-up -> forward-right-down (180 degrees about x)."""
BODY_SIGNS = {"enu": np.array([1.0, 1.0, 1.0]), "ned": np.array([1.0, -1.0, -1.0])}

DESCRIPTIONS = {
    "enu": ("ENU (ROS REP 103): body frame = the sensor's axes, x forward, y left, z up (a "
            "level sensor reads +9.81 m/s^2 on z); earth frame x east, y magnetic north, z up; "
            "the quaternion rotates body vectors into the earth frame"),
    "ned": ("NED: body frame forward-right-down (the sensor's x, -y, -z; a level sensor reads "
            "-9.81 m/s^2 on z); earth frame x magnetic north, y east, z down; the quaternion "
            "rotates body vectors into the earth frame"),
}
"""What each convention means, as every export states it."""


def check_frame(frame: str) -> str:
    """``frame`` in lower case; ValueError for one that is not in :data:`FRAMES`."""
    name = frame.lower()
    if name not in FRAMES:
        raise ValueError(f"frame {frame!r}: one of {', '.join(FRAMES)}")
    return name


def body_vectors(frame: str, vectors: np.ndarray) -> np.ndarray:
    """Body-frame vectors (N, 3) of this program (FLU) in ``frame``'s body axes."""
    return np.asarray(vectors, dtype=np.float64) * BODY_SIGNS[check_frame(frame)]


def orientation(frame: str, q: np.ndarray) -> np.ndarray:
    """Orientations (N, 4) (w, x, y, z) of this program (body FLU -> ENU) in ``frame``."""
    q = np.asarray(q, dtype=np.float64)
    if check_frame(frame) == "enu":
        return q
    return quat.multiply(quat.multiply(ENU_TO_NED, q), quat.conjugate(FLU_TO_FRD))
