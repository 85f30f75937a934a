"""Injected faults in the simulated LSM6DSOX (``sim://...?fault=KIND:CHANNEL[:SIZE]@START``).

The chip's raw counts are turned back into SI units, the faults of
:mod:`app.core.faults.injection` applied, and the result quantised and clipped to int16 again,
as the chip's own output stage would (a large bias or spike saturates like a real one).
Faults on the magnetometer's mx..mz (uT) act on its own samples only (the rows that carry
one), at those rows' times.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from app.core.faults.injection import FAULT_CHANNELS, FaultInjector, FaultSpec
from drivers.sim.error_model import INT16_MAX, INT16_MIN


class SimulatedFaults:
    """Applies fault specs to the simulator's raw blocks, deterministic from the seed."""

    def __init__(self, specs: Sequence[FaultSpec], seed: int, accel_lsb: float,
                 gyro_lsb: float, mag_lsb: float = 1.0) -> None:
        self.specs = tuple(specs)
        self._injector = FaultInjector(self.specs, seed)
        self._lsb = np.array([accel_lsb] * 3 + [gyro_lsb] * 3)
        self._mag_lsb = mag_lsb
        on_mag = any(spec.axis >= 6 for spec in self.specs)
        # Both injectors see every spec (so each keeps its own noise stream index) on 9
        # columns when there are magnetometer faults; each uses only its own columns.
        self._width = len(FAULT_CHANNELS) if on_mag else 6
        self._mag_injector = FaultInjector(self.specs, seed) if on_mag else None

    def apply(
        self, t_s: np.ndarray, accel_raw: np.ndarray, gyro_raw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Faulty int16 ``(accel, gyro)`` (N, 3) for samples at device times ``t_s``."""
        if not self.specs:
            return accel_raw, gyro_raw
        values = np.zeros((len(t_s), self._width))
        values[:, :6] = np.hstack([accel_raw, gyro_raw]) * self._lsb
        faulty = self._injector.apply(t_s, values)[:, :6] / self._lsb
        np.rint(faulty, out=faulty)
        np.clip(faulty, INT16_MIN, INT16_MAX, out=faulty)
        raw = faulty.astype(np.int16)
        return np.ascontiguousarray(raw[:, :3]), np.ascontiguousarray(raw[:, 3:])

    def apply_mag(self, t_s: np.ndarray, mag_raw: np.ndarray) -> np.ndarray:
        """Faulty magnetometer counts (M, 3, float) of its samples at device times ``t_s``."""
        if self._mag_injector is None or not len(t_s):
            return mag_raw
        values = np.zeros((len(t_s), self._width))
        values[:, 6:] = np.asarray(mag_raw, dtype=np.float64) * self._mag_lsb
        faulty = self._mag_injector.apply(t_s, values)[:, 6:] / self._mag_lsb
        np.rint(faulty, out=faulty)
        np.clip(faulty, INT16_MIN, INT16_MAX, out=faulty)
        return faulty

    def as_metadata(self) -> list[dict[str, object]]:
        """The faults as a recording's metadata lists them."""
        return [spec.as_dict() for spec in self.specs]
