"""LSM6DSOX register map, bit fields and the configuration sequence, as data.

Source: ST's BSD-3 register driver (STMicroelectronics/lsm6dsox-pid, ``lsm6dsox_reg.h``) and the
project's HARDWARE.md. The configuration sequence below is *the* contract between this driver,
the emulated chip and the NUCLEO firmware (another issue): the firmware's tests compare their
register writes with :func:`configuration_sequence`, dumped for a few settings to
``tests/vectors/lsm6dsox_config.json``.

Configuration sequence (every write, in order)
---------------------------------------------
=====  =============  =============================  ==============================================
step   register       value                          why
=====  =============  =============================  ==============================================
1      CTRL3_C 0x12   0x01 SW_RESET                  known state; then poll until bit 0 reads 0
2      CTRL3_C 0x12   0x44 BDU | IF_INC              consistent 16-bit words, burst reads
3      CTRL9_XL 0x18  0xE2 I3C_DISABLE (DEN bits kept) I2C only, as ST's examples do
4      FIFO_CTRL3     BDR_GY << 4 | BDR_XL           batch both sensors at the ODR
       0x09
5      FIFO_CTRL4     DEC_TS_BATCH=8 (0x80) |         timestamp every 8th slot, temperature at
       0x0A           ODR_T_BATCH=12.5 Hz (0x20) |    12.5 Hz, continuous mode
                      FIFO_MODE=6 (0x06) = 0xA6
6      CTRL10_C 0x19  0x20 TIMESTAMP_EN              25 us timestamp counter (trimmed)
7      CTRL1_XL 0x10  ODR_XL << 4 | FS_XL << 2       accelerometer on: starts the FIFO filling
8      CTRL2_G 0x11   ODR_G << 4 | FS_G << 1         gyroscope on (FS_125 is FS_G's low bit)
=====  =============  =============================  ==============================================

The FIFO is configured before the sensors start so the first words are already tagged and
batched as configured. Watermark (FIFO_CTRL1/2) and the BDR counter stay at their reset values:
the host polls FIFO_STATUS1/2 instead of using interrupts.
"""

from __future__ import annotations

from drivers import lsm6dsox

# -- register addresses ------------------------------------------------------------------------
FUNC_CFG_ACCESS = 0x01
FIFO_CTRL1 = 0x07
FIFO_CTRL2 = 0x08
FIFO_CTRL3 = 0x09
FIFO_CTRL4 = 0x0A
WHO_AM_I = 0x0F
CTRL1_XL = 0x10
CTRL2_G = 0x11
CTRL3_C = 0x12
CTRL4_C = 0x13
CTRL5_C = 0x14
CTRL9_XL = 0x18
CTRL10_C = 0x19
STATUS_REG = 0x1E
OUT_TEMP_L = 0x20
OUTX_L_G = 0x22
OUTX_L_A = 0x28
TIMESTAMP0 = 0x40
FIFO_STATUS1 = 0x3A
FIFO_STATUS2 = 0x3B
INTERNAL_FREQ_FINE = 0x63
FIFO_DATA_OUT_TAG = 0x78

REGISTER_NAMES: dict[int, str] = {
    FUNC_CFG_ACCESS: "FUNC_CFG_ACCESS", FIFO_CTRL1: "FIFO_CTRL1", FIFO_CTRL2: "FIFO_CTRL2",
    FIFO_CTRL3: "FIFO_CTRL3", FIFO_CTRL4: "FIFO_CTRL4", WHO_AM_I: "WHO_AM_I",
    CTRL1_XL: "CTRL1_XL", CTRL2_G: "CTRL2_G", CTRL3_C: "CTRL3_C", CTRL4_C: "CTRL4_C",
    CTRL5_C: "CTRL5_C", CTRL9_XL: "CTRL9_XL", CTRL10_C: "CTRL10_C", STATUS_REG: "STATUS_REG",
    OUT_TEMP_L: "OUT_TEMP_L", OUTX_L_G: "OUTX_L_G", OUTX_L_A: "OUTX_L_A",
    TIMESTAMP0: "TIMESTAMP0", FIFO_STATUS1: "FIFO_STATUS1", FIFO_STATUS2: "FIFO_STATUS2",
    INTERNAL_FREQ_FINE: "INTERNAL_FREQ_FINE", FIFO_DATA_OUT_TAG: "FIFO_DATA_OUT_TAG",
}
"""Address -> name, for messages and the test-vector file."""

# -- bit fields --------------------------------------------------------------------------------
CTRL3_C_BOOT = 0x80
CTRL3_C_BDU = 0x40
CTRL3_C_IF_INC = 0x04
CTRL3_C_SW_RESET = 0x01
CTRL3_C_RESET_VALUE = 0x04
"""CTRL3_C after reset: IF_INC set."""
CTRL9_XL_RESET_VALUE = 0xE0
"""CTRL9_XL after reset: DEN_X/Y/Z set."""
CTRL9_XL_I3C_DISABLE = 0x02
CTRL10_C_TIMESTAMP_EN = 0x20

CTRL5_C_ST_XL_POSITIVE = 0x01
CTRL5_C_ST_XL_NEGATIVE = 0x02
CTRL5_C_ST_G_POSITIVE = 0x04
CTRL5_C_ST_G_NEGATIVE = 0x0C
CTRL5_C_ST_XL_MASK = 0x03
CTRL5_C_ST_G_MASK = 0x0C

STATUS_XLDA = 0x01
STATUS_GDA = 0x02
STATUS_TDA = 0x04

FIFO_STATUS2_DIFF_FIFO_HIGH_MASK = 0x03
FIFO_STATUS2_OVR_LATCHED = 0x08
FIFO_STATUS2_COUNTER_BDR_IA = 0x10
FIFO_STATUS2_FULL_IA = 0x20
FIFO_STATUS2_OVR_IA = 0x40
FIFO_STATUS2_WTM_IA = 0x80

FIFO_MODE_BYPASS = 0
FIFO_MODE_FIFO = 1
FIFO_MODE_CONTINUOUS = 6
FIFO_MODE_MASK = 0x07

DEC_TS_BATCH_CODES: dict[int, int] = {0: 0, 1: 1, 8: 2, 32: 3}
"""Timestamp batch decimation (every Nth batch event; 0 = off) -> DEC_TS_BATCH[1:0] code."""
ODR_T_BATCH_CODES: dict[float, int] = {0.0: 0, 1.6: 1, 12.5: 2, 52.0: 3}
"""Temperature batch rate, Hz -> ODR_T_BATCH[1:0] code."""

# -- FIFO words --------------------------------------------------------------------------------
FIFO_WORD_BYTES = 7
FIFO_CAPACITY_WORDS = 512
"""FIFO depth in uncompressed words. (assumed: DIFF_FIFO is 10 bits and the watermark 9 bits;
3 kbyte of uncompressed data, which ST's "up to 9 kbyte" counts with compression.)"""
TAG_GYRO = 0x01
TAG_ACCEL = 0x02
TAG_TEMPERATURE = 0x03
TAG_TIMESTAMP = 0x04
TAG_CFG_CHANGE = 0x05

# -- settings the driver uses ------------------------------------------------------------------
TIMESTAMP_DECIMATION = 8
"""A timestamp word every 8 slots: 2.125 words per sample instead of 3 (bus bandwidth)."""
TEMPERATURE_BATCH_HZ = 12.5
SW_RESET_TIMEOUT_S = 0.05

KNOWN_WHO_AM_I: dict[int, str] = {
    0x69: "an LSM6DS3 / LSM6DS33",
    0x6A: "an LSM6DSL / LSM6DSM / LSM6DS3TR-C",
    0x6B: "an LSM6DSR / ISM330DHCX",
    0x00: "nothing driving the bus (a missing pull-up or a stuck bus)",
    0xFF: "nothing driving the bus (no device, or SDA held high)",
}
"""Other values WHO_AM_I may read, to make a mismatch message useful."""

# Self-test windows (HARDWARE.md: LSM6DSO datasheet, same family), at the full scales ST's
# procedure uses: accelerometer at +-4 g, gyroscope at +-2000 dps.
SELF_TEST_ACCEL_FS_G = 4
SELF_TEST_ACCEL_ODR_CODE = 3  # 52 Hz
SELF_TEST_ACCEL_WINDOW_MG = (50.0, 1700.0)
SELF_TEST_GYRO_FS_DPS = 2000
SELF_TEST_GYRO_ODR_CODE = 5  # 208 Hz
SELF_TEST_GYRO_WINDOW_DPS = (150.0, 700.0)
SELF_TEST_SETTLE_S = 0.1
SELF_TEST_SAMPLES = 5


def ctrl1_xl_value(odr_code: int, accel_fs_g: int) -> int:
    """CTRL1_XL: ODR_XL[7:4] and FS_XL[3:2]."""
    return (odr_code << 4) | (lsm6dsox.FS_XL_CODES[accel_fs_g] << 2)


def ctrl2_g_value(odr_code: int, gyro_fs_dps: int) -> int:
    """CTRL2_G: ODR_G[7:4] and FS_G[3:2] with FS_125 in bit 1."""
    return (odr_code << 4) | (lsm6dsox.FS_G_CODES[gyro_fs_dps] << 1)


def fifo_ctrl4_value(mode: int = FIFO_MODE_CONTINUOUS) -> int:
    """FIFO_CTRL4: DEC_TS_BATCH[7:6], ODR_T_BATCH[5:4], FIFO_MODE[2:0]."""
    return (
        (DEC_TS_BATCH_CODES[TIMESTAMP_DECIMATION] << 6)
        | (ODR_T_BATCH_CODES[TEMPERATURE_BATCH_HZ] << 4)
        | mode
    )


def check_settings(odr_hz: float, accel_fs_g: int, gyro_fs_dps: int) -> int:
    """Validate a setting; return the ODR code. Raises ``ValueError`` naming the choices."""
    codes = [code for code in lsm6dsox.ODR_LABELS_HZ
             if abs(lsm6dsox.ODR_LABELS_HZ[code] - odr_hz) < 1e-6
             or abs(lsm6dsox.ODR_RATES_HZ[code] - odr_hz) < 1e-6]
    if not codes:
        rates = ", ".join(f"{hz:g}" for hz in lsm6dsox.ODR_LABELS_HZ.values())
        raise ValueError(f"odr {odr_hz:g} Hz is not an LSM6DSOX rate; use one of {rates}")
    if accel_fs_g not in lsm6dsox.FS_XL_CODES:
        raise ValueError(f"accel_fs {accel_fs_g} g: use 2, 4, 8 or 16")
    if gyro_fs_dps not in lsm6dsox.FS_G_CODES:
        raise ValueError(f"gyro_fs {gyro_fs_dps} dps: use 125, 250, 500, 1000 or 2000")
    return codes[0]


def configuration_sequence(
    odr_hz: float, accel_fs_g: int, gyro_fs_dps: int
) -> list[tuple[int, int]]:
    """The register writes that configure streaming, in order, as ``(register, value)``.

    ``odr_hz`` must be one of the labels (12.5 ... 6667) or real rates (13.02 ... 6666.67).
    After the first write (SW_RESET) the host polls CTRL3_C until bit 0 reads 0 before going
    on. See the module docstring for what each write does.
    """
    odr_code = check_settings(odr_hz, accel_fs_g, gyro_fs_dps)
    return [
        (CTRL3_C, CTRL3_C_SW_RESET),
        (CTRL3_C, CTRL3_C_BDU | CTRL3_C_IF_INC),
        (CTRL9_XL, CTRL9_XL_RESET_VALUE | CTRL9_XL_I3C_DISABLE),
        (FIFO_CTRL3, (odr_code << 4) | odr_code),
        (FIFO_CTRL4, fifo_ctrl4_value()),
        (CTRL10_C, CTRL10_C_TIMESTAMP_EN),
        (CTRL1_XL, ctrl1_xl_value(odr_code, accel_fs_g)),
        (CTRL2_G, ctrl2_g_value(odr_code, gyro_fs_dps)),
    ]


VECTOR_SETTINGS: tuple[tuple[float, int, int], ...] = (
    (12.5, 2, 125), (104.0, 4, 250), (208.0, 8, 500), (417.0, 16, 1000), (833.0, 4, 2000),
    (1667.0, 8, 250), (6667.0, 16, 2000),
)
"""The settings dumped to ``tests/vectors/lsm6dsox_config.json``."""


def configuration_vectors() -> dict[str, object]:
    """The test-vector document: the sequence for each of :data:`VECTOR_SETTINGS`."""
    return {
        "description": (
            "LSM6DSOX register writes that configure streaming, in order, as [register, value]"
            " (drivers/lsm6dsox_direct/registers.py). After the first write (CTRL3_C SW_RESET)"
            " poll CTRL3_C until bit 0 reads 0. Regenerate with: python"
            " tests/vectors/make_lsm6dsox_config.py > tests/vectors/lsm6dsox_config.json"
        ),
        "registers": {f"0x{r:02X}": name for r, name in sorted(REGISTER_NAMES.items())},
        "settings": [
            {
                "odr_hz": odr,
                "accel_fs_g": accel,
                "gyro_fs_dps": gyro,
                "sequence": [[r, v] for r, v in configuration_sequence(odr, accel, gyro)],
                "sequence_hex": [
                    f"{REGISTER_NAMES[r]} 0x{r:02X} <- 0x{v:02X}"
                    for r, v in configuration_sequence(odr, accel, gyro)
                ],
            }
            for odr, accel, gyro in VECTOR_SETTINGS
        ],
    }

