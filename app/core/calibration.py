"""The calibration stage: sensor-error correction applied to every block.

``a_cal = A (a_raw - b_a)`` and ``w_cal = G (w_raw - b_g)``, with biases in SI units and
3x3 matrices that hold scale and misalignment. The identity calibration leaves data unchanged.
The calibration wizard (a later stage of the project) fills these from measurements.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from app.core.samples import SampleBlock


def _zeros3() -> np.ndarray:
    return np.zeros(3)


def _eye3() -> np.ndarray:
    return np.eye(3)


@dataclass(frozen=True)
class SensorCalibration:
    """Accelerometer and gyroscope correction; ``name`` labels the active profile."""

    accel_bias_m_s2: np.ndarray = field(default_factory=_zeros3)
    accel_matrix: np.ndarray = field(default_factory=_eye3)
    gyro_bias_rad_s: np.ndarray = field(default_factory=_zeros3)
    gyro_matrix: np.ndarray = field(default_factory=_eye3)
    name: str = "uncalibrated"

    @property
    def is_identity(self) -> bool:
        return (
            not np.any(self.accel_bias_m_s2)
            and not np.any(self.gyro_bias_rad_s)
            and np.array_equal(self.accel_matrix, np.eye(3))
            and np.array_equal(self.gyro_matrix, np.eye(3))
        )

    def apply(self, block: SampleBlock) -> SampleBlock:
        """A calibrated copy of ``block`` (the block itself when this is the identity)."""
        if self.is_identity:
            return block
        accel = (block.accel_m_s2 - self.accel_bias_m_s2) @ self.accel_matrix.T
        gyro = (block.gyro_rad_s - self.gyro_bias_rad_s) @ self.gyro_matrix.T
        return replace(block, accel_m_s2=accel, gyro_rad_s=gyro)


IDENTITY_CALIBRATION = SensorCalibration()
