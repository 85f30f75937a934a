"""Injected faults in the simulated LSM6DSOX (``sim://...?fault=KIND:CHANNEL[:SIZE]@START``).

The chip's raw counts are turned back into SI units, the faults of
:mod:`app.core.faults.injection` applied, and the result quantised and clipped to int16 again,
as the chip's own output stage would (a large bias or spike saturates like a real one).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from app.core.faults.injection import FaultInjector, FaultSpec
from drivers.sim.error_model import INT16_MAX, INT16_MIN


class SimulatedFaults:
    """Applies fault specs to the simulator's raw blocks, deterministic from the seed."""

    def __init__(self, specs: Sequence[FaultSpec], seed: int, accel_lsb: float,
                 gyro_lsb: float) -> None:
        self.specs = tuple(specs)
        self._injector = FaultInjector(self.specs, seed)
        self._lsb = np.array([accel_lsb] * 3 + [gyro_lsb] * 3)

    def apply(
        self, t_s: np.ndarray, accel_raw: np.ndarray, gyro_raw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Faulty int16 ``(accel, gyro)`` (N, 3) for samples at device times ``t_s``."""
        if not self.specs:
            return accel_raw, gyro_raw
        values = np.hstack([accel_raw, gyro_raw]).astype(np.float64) * self._lsb
        faulty = self._injector.apply(t_s, values) / self._lsb
        np.rint(faulty, out=faulty)
        np.clip(faulty, INT16_MIN, INT16_MAX, out=faulty)
        raw = faulty.astype(np.int16)
        return np.ascontiguousarray(raw[:, :3]), np.ascontiguousarray(raw[:, 3:])

    def as_metadata(self) -> list[dict[str, object]]:
        """The faults as a recording's metadata lists them."""
        return [spec.as_dict() for spec in self.specs]
