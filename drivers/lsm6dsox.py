"""LSM6DSOX facts shared by the simulator and the real-device drivers.

Source: ST's BSD-3 register driver (STMicroelectronics/lsm6dsox-pid, ``lsm6dsox_reg.h``) and
the figures collected in the project's HARDWARE.md. Figures marked *assumed* are modelling
choices where no datasheet confirmed the value.
"""

from __future__ import annotations

import math

WHO_AM_I_VALUE = 0x6C

# Output data rate codes (ODR_XL / ODR_G) -> nominal rate in Hz.
ODR_CODES_HZ: dict[int, float] = {
    1: 12.5, 2: 26.0, 3: 52.0, 4: 104.0, 5: 208.0,
    6: 417.0, 7: 833.0, 8: 1667.0, 9: 3333.0, 10: 6667.0,
}

# Sensitivities per full scale.
ACCEL_MG_PER_LSB: dict[int, float] = {2: 0.061, 4: 0.122, 8: 0.244, 16: 0.488}
GYRO_MDPS_PER_LSB: dict[int, float] = {125: 4.375, 250: 8.75, 500: 17.50, 1000: 35.0, 2000: 70.0}

# Register field codes (not in numeric order on the chip).
FS_XL_CODES: dict[int, int] = {2: 0, 16: 1, 4: 2, 8: 3}
FS_G_CODES: dict[int, int] = {250: 0, 125: 1, 500: 2, 1000: 4, 2000: 6}

TEMP_LSB_PER_DEGC = 256.0
TEMP_OFFSET_DEGC = 25.0
TIMESTAMP_TICK_S = 25e-6
FREQ_FINE_STEP = 0.0015
"""INTERNAL_FREQ_FINE step: each LSB trims the clock by 0.15 %."""

# Noise densities (DS12814 via secondary sources).
GYRO_NOISE_DPS_PER_SQRT_HZ = 3.8e-3
ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS = 70e-6
ACCEL_NOISE_G_PER_SQRT_HZ_16G = 110e-6

STANDARD_GRAVITY_M_S2 = 9.80665


def odr_code_for(odr_hz: float) -> int:
    """The ODR code whose nominal rate is closest to ``odr_hz``."""
    return min(ODR_CODES_HZ, key=lambda code: abs(ODR_CODES_HZ[code] - odr_hz))


def accel_m_s2_per_lsb(accel_fs_g: int) -> float:
    """Accelerometer LSB size in m/s^2 at a full scale of +-``accel_fs_g`` g."""
    return ACCEL_MG_PER_LSB[accel_fs_g] * 1e-3 * STANDARD_GRAVITY_M_S2


def gyro_rad_s_per_lsb(gyro_fs_dps: int) -> float:
    """Gyroscope LSB size in rad/s at a full scale of +-``gyro_fs_dps`` dps."""
    return math.radians(GYRO_MDPS_PER_LSB[gyro_fs_dps] * 1e-3)


def accel_noise_g_per_sqrt_hz(accel_fs_g: int) -> float:
    """Accelerometer noise density for a full scale (higher at +-16 g)."""
    return ACCEL_NOISE_G_PER_SQRT_HZ_16G if accel_fs_g == 16 else ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS
