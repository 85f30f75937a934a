"""Accelerometer-only tilt: the thesis's static inclination, with an optional moving average.

Roll and pitch follow from where gravity points in the sensor frame (atan2 form of
``alpha = atan(Ax / sqrt(Ay^2 + Az^2))``), with yaw held at zero. Exact at rest, but any linear
acceleration tilts the estimate. The moving average runs on the acceleration *vector*, not on
angles, so it never breaks at the +-180 degree wrap.
"""

from __future__ import annotations

import numpy as np

from app.core.filters.base import OrientationFilter, ParameterSpec
from app.core.orientation import quaternion_from_up
from app.core.samples import SampleBlock


class AccelerometerTilt(OrientationFilter):
    """Inclination from the accelerometer alone."""

    name = "accel"
    title = "Accelerometer only"
    description = "Tilt from gravity alone: exact at rest, disturbed by any linear acceleration."
    parameters = (
        ParameterSpec(
            "average_samples", "Moving average", "samples", 1, 1, 10000,
            "Average the acceleration over this many samples (1 = no averaging).",
            kind="int", log_scale=True,
        ),
    )

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._history = np.empty((0, 3))

    def _process(self, block: SampleBlock) -> np.ndarray:
        window = int(self._values["average_samples"])
        accel = block.accel_m_s2
        if window > 1:
            history = self._history[-(window - 1) :]
            extended = np.concatenate([history, accel])
            cumulative = np.cumsum(np.vstack([np.zeros((1, 3)), extended]), axis=0)
            ends = np.arange(len(history) + 1, len(extended) + 1)
            starts = np.maximum(ends - window, 0)
            accel = (cumulative[ends] - cumulative[starts]) / (ends - starts)[:, None]
            self._history = extended[-(window - 1) :]
        return quaternion_from_up(accel)
