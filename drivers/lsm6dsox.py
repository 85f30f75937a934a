"""LSM6DSOX facts shared by the simulator and the real-device drivers.

Source: ST's BSD-3 register driver (STMicroelectronics/lsm6dsox-pid, ``lsm6dsox_reg.h``) and
the figures collected in the project's HARDWARE.md. Figures marked *assumed* are modelling
choices where no datasheet confirmed the value.
"""

from __future__ import annotations

import functools
import math

from drivers.url_options import Option

WHO_AM_I_VALUE = 0x6C

# Output data rates. The datasheet labels a rate "12.5 Hz", "104 Hz", ... "6667 Hz"; the chip
# runs at 6666.67 Hz / ODR_Coeff with ODR_Coeff = 512, 256, ... 1 (AN5272), times its trim
# (INTERNAL_FREQ_FINE). The labels are for people (menus, CLI options, messages); every
# computation (sample times, CONFIG's odr_mhz, gap estimates, expected sample counts) uses the
# real rates. This module is the one place that maps one to the other.
ODR_BASE_HZ = 20000.0 / 3.0
"""The chip's fastest rate, "6667 Hz": a 40 kHz timestamp clock divided by 6."""
ODR_LABELS_HZ: dict[int, float] = {
    1: 12.5, 2: 26.0, 3: 52.0, 4: 104.0, 5: 208.0,
    6: 417.0, 7: 833.0, 8: 1667.0, 9: 3333.0, 10: 6667.0,
}
"""ODR code (ODR_XL / ODR_G) -> the datasheet's label in Hz."""
ODR_RATES_HZ: dict[int, float] = {code: ODR_BASE_HZ / 2 ** (10 - code) for code in ODR_LABELS_HZ}
"""ODR code -> the rate the chip really runs at before its trim (12.5 Hz is 13.02 Hz)."""

# Turn-on transient: after the ODR is (re)set the first samples come out of filters that are
# still settling. ST's drivers drop them: per ODR code, (accelerometer, gyroscope) samples to
# discard, the settling figures plus two. 12.5-416 Hz: the figures of Linux's st_lsm6dsx driver
# (commit db3c490503be, from AN4987: accelerometer 1-2, gyroscope 2-36 samples) plus two.
# 833-6667 Hz are not in that table: the gyroscope's settling time stays near 80 ms, so its
# count doubles with the rate up to 539 (+2 = 541) at 6667 Hz; the accelerometer's grows by one
# every other step to 5 (+2 = 7). To be confirmed on the bench. firmware/core/lsm6dsox.c holds
# the same table; the host tests compare the two.
TURN_ON_DISCARD: dict[int, tuple[int, int]] = {
    1: (3, 4), 2: (3, 7), 3: (3, 9), 4: (4, 14), 5: (4, 22),
    6: (4, 38), 7: (5, 72), 8: (5, 137), 9: (6, 272), 10: (7, 541),
}
SETTLING_MARGIN_SAMPLES = 2
"""TURN_ON_DISCARD is the settling figure plus this many samples."""

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


@functools.lru_cache(maxsize=64)
def odr_code_for(odr_hz: float) -> int:
    """The ODR code whose label or real rate is closest to ``odr_hz`` (104 and 104.17 -> 4).

    Cached: the simulator asks for its rate several times a block."""
    def distance(code: int) -> float:
        return min(abs(ODR_LABELS_HZ[code] - odr_hz), abs(ODR_RATES_HZ[code] - odr_hz))

    return min(ODR_LABELS_HZ, key=distance)


ODR_SNAP_MIN_HZ = 1.0
ODR_SNAP_MAX_HZ = 8000.0
"""Requested rates from here to there snap to the nearest ODR; others are refused (1e9 Hz is
a mistake, not a wish for 6667 Hz)."""


def odr_problem(odr_hz: float) -> str | None:
    """Why ``odr_hz`` cannot be asked of the chip (None when it snaps to an ODR)."""
    if not math.isfinite(odr_hz):
        return "is not a finite number"
    if odr_hz <= 0.0:
        return "must be positive (12.5 ... 6667 Hz)"
    if not ODR_SNAP_MIN_HZ <= odr_hz <= ODR_SNAP_MAX_HZ:
        return (f"is outside the LSM6DSOX's rates (12.5 ... 6667 Hz; from "
                f"{ODR_SNAP_MIN_HZ:g} to {ODR_SNAP_MAX_HZ:g} Hz snap to the nearest)")
    return None


def real_odr_hz(odr_hz: float) -> float:
    """The untrimmed rate the chip runs at for a label or rate (12.5 -> 13.0208)."""
    return ODR_RATES_HZ[odr_code_for(odr_hz)]


def odr_label_hz(odr_hz: float) -> float:
    """The datasheet label of a label or rate (13.0208 -> 12.5)."""
    return ODR_LABELS_HZ[odr_code_for(odr_hz)]


def odr_text(odr_hz: float) -> str:
    """For people: the label, with the real rate beside it ("12.5 Hz (13.02 Hz)")."""
    code = odr_code_for(odr_hz)
    return f"{ODR_LABELS_HZ[code]:g} Hz ({ODR_RATES_HZ[code]:.2f} Hz)"


def trim_ppm(freq_fine: int) -> int:
    """``1 + 0.0015 * INTERNAL_FREQ_FINE`` in parts per million (an integer, as the firmware)."""
    return 1_000_000 + 1500 * int(freq_fine)


def odr_mhz(odr_code: int, freq_fine: int = 0) -> int:
    """CONFIG's odr_mhz: the real, trimmed rate in mHz, rounded exactly as the firmware does."""
    numerator = 20_000_000 * trim_ppm(freq_fine)  # 6666.67 Hz = 20 000 000 / 3 mHz
    denominator = 3 * 2 ** (10 - odr_code) * 1_000_000
    return (numerator + denominator // 2) // denominator


def tick_ns(freq_fine: int = 0) -> int:
    """CONFIG's tick_ns: the trimmed 25 us timestamp tick in ns, rounded as the firmware does."""
    trim = trim_ppm(freq_fine)
    return (25_000 * 1_000_000 + trim // 2) // trim


def turn_on_discard(odr_hz: float) -> int:
    """Samples (slots with both sensors) to drop after the ODR is set: the larger figure."""
    return max(TURN_ON_DISCARD[odr_code_for(odr_hz)])


def accel_m_s2_per_lsb(accel_fs_g: int) -> float:
    """Accelerometer LSB size in m/s^2 at a full scale of +-``accel_fs_g`` g."""
    return ACCEL_MG_PER_LSB[accel_fs_g] * 1e-3 * STANDARD_GRAVITY_M_S2


def gyro_rad_s_per_lsb(gyro_fs_dps: int) -> float:
    """Gyroscope LSB size in rad/s at a full scale of +-``gyro_fs_dps`` dps."""
    return math.radians(GYRO_MDPS_PER_LSB[gyro_fs_dps] * 1e-3)


def accel_noise_g_per_sqrt_hz(accel_fs_g: int) -> float:
    """Accelerometer noise density for a full scale (higher at +-16 g)."""
    return ACCEL_NOISE_G_PER_SQRT_HZ_16G if accel_fs_g == 16 else ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS


# The chip's settings as device-URL options (drivers.url_options), shared by every driver of it.
ODR_OPTION = Option(
    "odr", "number", 104.0, unit="Hz", check=odr_problem, convert=odr_label_hz,
    field="odr_nominal_hz",
    help="output data rate, snapped to the nearest LSM6DSOX rate (12.5 ... 6667; 12.5 runs "
         "at 13.02)",
)
ACCEL_FS_OPTION = Option(
    "accel_fs", "choice", 4, unit="g", choices=tuple(sorted(ACCEL_MG_PER_LSB)),
    field="accel_fs_g", help="accelerometer full scale",
)
GYRO_FS_OPTION = Option(
    "gyro_fs", "choice", 250, unit="dps", choices=tuple(sorted(GYRO_MDPS_PER_LSB)),
    field="gyro_fs_dps", help="gyroscope full scale",
)
