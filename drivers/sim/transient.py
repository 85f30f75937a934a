"""The LSM6DSOX's turn-on transient, as the simulator and the emulated chip model it.

After the ODR is set, the first samples come out of filters that are still settling (ST's
drivers drop :data:`drivers.lsm6dsox.TURN_ON_DISCARD` of them: the settling figures plus two).
Modelled (assumed, not measured): of ``n`` settling samples of a sensor, sample ``k`` (1-based,
counted from the ODR write) reads ``k / (n + 1)`` of the true acceleration, and the gyroscope
the true rate plus ``(1 - k / (n + 1))`` x :data:`SETTLING_GYRO_OFFSET_DPS`. Wrong enough to
show in any test, gone after the discard count.
"""

from __future__ import annotations

import numpy as np

from drivers import lsm6dsox

SETTLING_GYRO_OFFSET_DPS = 20.0
"""The gyroscope's error on the first settling sample (it decays to zero)."""


def settling_counts(odr_code: int) -> tuple[int, int]:
    """(accelerometer, gyroscope) samples that settle after the ODR write: the figures."""
    margin = lsm6dsox.SETTLING_MARGIN_SAMPLES
    accel, gyro = lsm6dsox.TURN_ON_DISCARD[odr_code]
    return accel - margin, gyro - margin


def apply_turn_on_transient(
    index: np.ndarray, accel_raw: np.ndarray, gyro_raw: np.ndarray, odr_code: int,
    gyro_fs_dps: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Raw samples with the transient applied; ``index`` counts samples from 1 at the ODR write.

    Returns the inputs themselves when no sample is settling.
    """
    n_accel, n_gyro = settling_counts(odr_code)
    if len(index) == 0 or index[0] > max(n_accel, n_gyro):
        return accel_raw, gyro_raw
    accel_raw, gyro_raw = accel_raw.copy(), gyro_raw.copy()
    settling = index <= n_accel
    share = index[settling, None] / (n_accel + 1)
    accel_raw[settling] = _saturate(np.rint(accel_raw[settling] * share))
    settling = index <= n_gyro
    error_dps = (1.0 - index[settling, None] / (n_gyro + 1)) * SETTLING_GYRO_OFFSET_DPS
    error_lsb = error_dps * 1e3 / lsm6dsox.GYRO_MDPS_PER_LSB[gyro_fs_dps]
    gyro_raw[settling] = _saturate(gyro_raw[settling] + np.rint(error_lsb))
    return accel_raw, gyro_raw


def _saturate(values: np.ndarray) -> np.ndarray:
    return np.clip(values, -32768, 32767).astype(np.int16)
