"""Hand-made sample blocks for filter tests (imported by the test modules)."""

from __future__ import annotations

import numpy as np

from app.core.orientation import quaternion_from_roll_pitch, up_in_sensor_frame
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

G = STANDARD_GRAVITY_M_S2


def block(t, accel, gyro=None, gap=None) -> SampleBlock:
    """A SampleBlock at times ``t``; accel/gyro broadcast to (N, 3), 25 degC, no gaps."""
    t = np.asarray(t, dtype=float)
    n = len(t)
    accel = np.broadcast_to(np.asarray(accel, dtype=float), (n, 3)).copy()
    gyro = np.zeros((n, 3)) if gyro is None else np.broadcast_to(gyro, (n, 3)).copy()
    gap = np.zeros(n, bool) if gap is None else np.asarray(gap, bool)
    return SampleBlock(t, accel, gyro, np.full(n, 25.0), gap)


def accel_for(roll: float, pitch: float) -> np.ndarray:
    """The accelerometer reading at rest in a roll/pitch pose (m/s^2)."""
    return up_in_sensor_frame(quaternion_from_roll_pitch(roll, pitch)) * G
