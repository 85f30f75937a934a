"""Register maps of the LIS3MDL and LIS2MDL magnetometers beside the LSM6DSOX (issue 31).

Shared by the register-level driver (:mod:`~drivers.lsm6dsox_direct.mag_driver`) and the
emulated chips (:mod:`~drivers.lsm6dsox_direct.emulated_mag`), so both speak one map.

Sources. LIS3MDL datasheet DocID024204: section 5.1.1 (I2C operation: a multi-byte transfer
auto-increments only when the sub-address's MSB is 1), section 7 (register address map),
section 8 (register descriptions: 8.1 WHO_AM_I, 8.2-8.6 CTRL_REG1..5, 8.8 STATUS_REG,
8.9-8.14 OUT_*), table 3 (sensitivity per full scale) and tables 20/21 (OM and DO, FAST_ODR
rates). LIS2MDL datasheet DocID027847: section 6.1.1 (I2C operation; the register address
increments on its own in a multi-byte transfer), section 7 (register map), section 8
(8.4 WHO_AM_I, 8.5-8.7 CFG_REG_A/B/C, 8.10 STATUS_REG, 8.11 OUTX_L_REG...), table 2
(1.5 mgauss/LSB). The addresses, bit positions and reset values below were checked against
those sections as quoted by ST's own register headers (lis3mdl_platform.h, lis2mdl_reg.h)
and independent drivers (RIOT lis3mdl-internal.h, Meadow Lis3Mdl.Registers.cs).
"""

from __future__ import annotations

UT_PER_GAUSS = 100.0

# -- LIS3MDL (DocID024204) ------------------------------------------------------------------------
LIS3MDL_ADDRESSES = (0x1C, 0x1E)
"""7-bit address with SA1 low (0x1C, Adafruit's 9-DoF board) or high (0x1E), section 5.1.1."""
LIS3MDL_WHO_AM_I = 0x0F
LIS3MDL_WHO_AM_I_VALUE = 0x3D
LIS3MDL_AUTO_INCREMENT = 0x80
"""Sub-address MSB: set it to read or write several registers in one transfer (5.1.1)."""
LIS3MDL_CTRL_REG1 = 0x20  # TEMP_EN | OM1 OM0 | DO2 DO1 DO0 | FAST_ODR | ST   (8.2)
LIS3MDL_CTRL_REG2 = 0x21  # 0 | FS1 FS0 | 0 | REBOOT | SOFT_RST | 0 0          (8.3)
LIS3MDL_CTRL_REG3 = 0x22  # 0 0 | LP | 0 0 | SIM | MD1 MD0                     (8.4)
LIS3MDL_CTRL_REG4 = 0x23  # 0 0 0 0 | OMZ1 OMZ0 | BLE | 0                      (8.5)
LIS3MDL_CTRL_REG5 = 0x24  # FAST_READ | BDU | 0 ...                            (8.6)
LIS3MDL_STATUS_REG = 0x27  # ZYXOR ZOR YOR XOR ZYXDA ZDA YDA XDA                (8.8)
LIS3MDL_OUT_X_L = 0x28  # OUT_X_L .. OUT_Z_H: 0x28-0x2D, int16 little-endian (BLE = 0)
LIS3MDL_RESET_VALUES = {LIS3MDL_CTRL_REG1: 0x10, LIS3MDL_CTRL_REG2: 0x00,
                        LIS3MDL_CTRL_REG3: 0x03, LIS3MDL_CTRL_REG4: 0x00,
                        LIS3MDL_CTRL_REG5: 0x00}
"""Section 7: CTRL_REG1 0x10 (DO = 10 Hz), CTRL_REG3 0x03 (power-down)."""
LIS3MDL_OM_SHIFT = 5
LIS3MDL_DO_SHIFT = 2
LIS3MDL_FAST_ODR = 0x02
LIS3MDL_OM_UHP = 0x3  # OM = 11: ultra-high-performance (table 20)
LIS3MDL_FS_SHIFT = 5
LIS3MDL_SOFT_RST = 0x04
LIS3MDL_REBOOT = 0x08
LIS3MDL_MD_MASK = 0x03
LIS3MDL_MD_CONTINUOUS = 0x00
LIS3MDL_MD_POWER_DOWN = 0x03
LIS3MDL_OMZ_SHIFT = 2
LIS3MDL_BDU = 0x40
LIS3MDL_DO_RATES_HZ = (0.625, 1.25, 2.5, 5.0, 10.0, 20.0, 40.0, 80.0)
"""DO2..DO0 = 0..7 (table 21)."""
LIS3MDL_FAST_ODR_HZ = {0: 1000.0, 1: 560.0, 2: 300.0, 3: 155.0}
"""FAST_ODR = 1: the rate is set by OM (LP, MP, HP, UHP), table 21."""
LIS3MDL_LSB_PER_GAUSS = {4: 6842.0, 8: 3421.0, 12: 2281.0, 16: 1711.0}
"""FS1 FS0 = 00, 01, 10, 11 (table 3, section 8.3)."""
LIS3MDL_FS_CODES = {4: 0, 8: 1, 12: 2, 16: 3}

# -- LIS2MDL (DocID027847) ------------------------------------------------------------------------
LIS2MDL_ADDRESS = 0x1E
LIS2MDL_WHO_AM_I = 0x4F
LIS2MDL_WHO_AM_I_VALUE = 0x40
LIS2MDL_CFG_REG_A = 0x60  # COMP_TEMP_EN | REBOOT | SOFT_RST | LP | ODR1 ODR0 | MD1 MD0  (8.5)
LIS2MDL_CFG_REG_B = 0x61  # 0 0 0 | OFF_CANC_ONE_SHOT | INT_on_DataOFF | Set_FREQ | OFF_CANC | LPF
LIS2MDL_CFG_REG_C = 0x62  # 0 | INT_on_PIN | I2C_DIS | BDU | BLE | 4WSPI | Self_test | DRDY_on_PIN
LIS2MDL_STATUS_REG = 0x67  # Zyxor zor yor xor Zyxda zda yda xda                    (8.10)
LIS2MDL_OUTX_L_REG = 0x68  # OUTX_L_REG .. OUTZ_H_REG: 0x68-0x6D, int16 little-endian
LIS2MDL_RESET_VALUES = {LIS2MDL_CFG_REG_A: 0x03, LIS2MDL_CFG_REG_B: 0x00,
                        LIS2MDL_CFG_REG_C: 0x00}
"""Section 7: CFG_REG_A 0x03 (idle)."""
LIS2MDL_COMP_TEMP_EN = 0x80
LIS2MDL_SOFT_RST = 0x20
LIS2MDL_REBOOT = 0x40
LIS2MDL_LP = 0x10
LIS2MDL_ODR_SHIFT = 2
LIS2MDL_MD_MASK = 0x03
LIS2MDL_MD_CONTINUOUS = 0x00
LIS2MDL_MD_IDLE = 0x03
LIS2MDL_OFF_CANC = 0x02
LIS2MDL_LPF = 0x01
LIS2MDL_BDU = 0x10
LIS2MDL_ODR_RATES_HZ = (10.0, 20.0, 50.0, 100.0)
"""ODR1 ODR0 = 00, 01, 10, 11."""
LIS2MDL_UT_PER_LSB = 1.5e-3 * UT_PER_GAUSS
"""1.5 mgauss/LSB (table 2); 16 bits give +-49.152 gauss."""

# -- both -----------------------------------------------------------------------------------------
STATUS_ZYXDA = 0x08
STATUS_ZYXOR = 0x80
STATUS_AXIS_DA = (0x01, 0x02, 0x04)  # XDA, YDA, ZDA
STATUS_AXIS_OR = (0x10, 0x20, 0x40)  # XOR, YOR, ZOR


def lis3mdl_sequence(rate_hz: float, fs_gauss: int = 4) -> list[tuple[int, int]]:
    """The LIS3MDL's configuration for ``rate_hz`` (a DO rate, or 155 with FAST_ODR):
    ultra-high-performance on x/y (OM) and z (OMZ), ``fs_gauss`` full scale, BDU, continuous
    mode last (conversion starts with it)."""
    if rate_hz in LIS3MDL_DO_RATES_HZ:
        ctrl1 = LIS3MDL_OM_UHP << LIS3MDL_OM_SHIFT | LIS3MDL_DO_RATES_HZ.index(rate_hz) << 2
    elif rate_hz == LIS3MDL_FAST_ODR_HZ[LIS3MDL_OM_UHP]:
        ctrl1 = LIS3MDL_OM_UHP << LIS3MDL_OM_SHIFT | LIS3MDL_FAST_ODR
    else:
        raise ValueError(f"the LIS3MDL has no rate {rate_hz:g} Hz in ultra-high-performance mode")
    return [
        (LIS3MDL_CTRL_REG1, ctrl1),
        (LIS3MDL_CTRL_REG2, LIS3MDL_FS_CODES[fs_gauss] << LIS3MDL_FS_SHIFT),
        (LIS3MDL_CTRL_REG4, LIS3MDL_OM_UHP << LIS3MDL_OMZ_SHIFT),
        (LIS3MDL_CTRL_REG5, LIS3MDL_BDU),
        (LIS3MDL_CTRL_REG3, LIS3MDL_MD_CONTINUOUS),
    ]


def lis2mdl_sequence(rate_hz: float) -> list[tuple[int, int]]:
    """The LIS2MDL's configuration for ``rate_hz`` (10, 20, 50, 100): offset cancellation and
    the low-pass filter (CFG_REG_B), BDU (CFG_REG_C), then temperature compensation, the rate
    and continuous mode in CFG_REG_A last (conversion starts with it)."""
    if rate_hz not in LIS2MDL_ODR_RATES_HZ:
        raise ValueError(f"the LIS2MDL has no rate {rate_hz:g} Hz")
    return [
        (LIS2MDL_CFG_REG_B, LIS2MDL_OFF_CANC | LIS2MDL_LPF),
        (LIS2MDL_CFG_REG_C, LIS2MDL_BDU),
        (LIS2MDL_CFG_REG_A, LIS2MDL_COMP_TEMP_EN
         | LIS2MDL_ODR_RATES_HZ.index(rate_hz) << LIS2MDL_ODR_SHIFT | LIS2MDL_MD_CONTINUOUS),
    ]
