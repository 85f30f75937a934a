"""The magnetometer chips the NUCLEO board looks for beside the LSM6DSOX: datasheet facts.

Shared by the link protocol (MAGNETOMETER, MAG_SAMPLES: ``docs/protocol.md``), the emulated
board and the host side. Sources: ST's LIS3MDL datasheet (DocID024204) and register header
``lis3mdl_reg.h`` (STMicroelectronics/lis3mdl-pid), ST's LIS2MDL datasheet
and ``lis2mdl_reg.h`` (STMicroelectronics/lis2mdl-pid). ``firmware/core/magnetometer.h``
holds the same numbers for the firmware.
"""

from __future__ import annotations

from dataclasses import dataclass

CHIP_LIS3MDL = 1
CHIP_LIS2MDL = 2

MODE_ULTRA_HIGH_PERFORMANCE = 3
"""LIS3MDL OM = OMZ = 11: the lowest noise (3.2 mgauss rms X/Y at +-4 gauss)."""
MODE_HIGH_RESOLUTION = 4
"""LIS2MDL CFG_REG_A LP = 0 (high resolution, as opposed to low power)."""
MODE_NAMES: dict[int, str] = {
    0: "low-power", 1: "medium-performance", 2: "high-performance",
    MODE_ULTRA_HIGH_PERFORMANCE: "ultra-high-performance",
    MODE_HIGH_RESOLUTION: "high-resolution, offset cancellation",
    5: "low-power (LIS2MDL)",
}


@dataclass(frozen=True, slots=True)
class ChipSpec:
    """One magnetometer part as the firmware sets it up."""

    code: int
    name: str
    addresses: tuple[int, ...]
    who_am_i_register: int
    who_am_i: int
    rates_hz: tuple[float, ...]
    """Output rates in the mode the firmware uses, slowest first."""
    range_ut: int
    """Full scale, +-uT, at the setting the firmware uses."""
    pt_per_lsb: int
    """Sensitivity in picotesla per LSB (rounded), as MAGNETOMETER carries it."""
    mode: int

    @property
    def ut_per_lsb(self) -> float:
        return self.pt_per_lsb / 1e6

    def rate_for(self, accel_odr_hz: float) -> float:
        """The chip's rate for an accelerometer rate: the fastest not above it, else the
        slowest (the field is then sampled on every accelerometer row it can be)."""
        fitting = [rate for rate in self.rates_hz if rate <= accel_odr_hz]
        return fitting[-1] if fitting else self.rates_hz[0]


LIS3MDL = ChipSpec(
    code=CHIP_LIS3MDL, name="LIS3MDL", addresses=(0x1C, 0x1E),
    who_am_i_register=0x0F, who_am_i=0x3D,
    # CTRL_REG1 DO = 100..111 with OM = 11 (ultra-high-performance): 10, 20, 40, 80 Hz
    # (lis3mdl_reg.h LIS3MDL_UHP_10Hz..LIS3MDL_UHP_80Hz).
    rates_hz=(10.0, 20.0, 40.0, 80.0),
    # CTRL_REG2 FS = 00: +-4 gauss = +-400 uT, 6842 LSB/gauss (datasheet Table 2;
    # lis3mdl_from_fs4_to_gauss divides by 6842): 1e8 pT / 6842 = 14615.6 pT.
    range_ut=400, pt_per_lsb=14616, mode=MODE_ULTRA_HIGH_PERFORMANCE,
)
LIS2MDL = ChipSpec(
    code=CHIP_LIS2MDL, name="LIS2MDL", addresses=(0x1E,),
    who_am_i_register=0x4F, who_am_i=0x40,
    # CFG_REG_A ODR = 00..11: 10, 20, 50, 100 Hz (lis2mdl_reg.h lis2mdl_odr_t).
    rates_hz=(10.0, 20.0, 50.0, 100.0),
    # Fixed +-49.152 gauss, 1.5 mgauss/LSB (datasheet Table 2; lis2mdl_from_lsb_to_mgauss
    # multiplies by 1.5): 0.15 uT = 150000 pT.
    range_ut=4915, pt_per_lsb=150_000, mode=MODE_HIGH_RESOLUTION,
)
CHIPS: dict[int, ChipSpec] = {LIS3MDL.code: LIS3MDL, LIS2MDL.code: LIS2MDL}
CHIPS_BY_NAME: dict[str, ChipSpec] = {chip.name.lower(): chip for chip in CHIPS.values()}


def chip_name(code: int) -> str:
    spec = CHIPS.get(code)
    return spec.name if spec else f"magnetometer chip {code}"
