"""The register-level LIS3MDL / LIS2MDL driver on the LSM6DSOX's bus: probe, configure, poll.

Bus-agnostic like :class:`~drivers.lsm6dsox_direct.driver.Lsm6dsoxDriver`; the register map is
:mod:`~drivers.lsm6dsox_direct.mag_registers`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.devices import MagnetometerInfo
from drivers.errors import DeviceIOError
from drivers.lsm6dsox_direct import mag_registers as mreg
from drivers.lsm6dsox_direct.bus import I2CBus

LIS3MDL_FS_GAUSS = 4
PROBES: tuple[tuple[str, int], ...] = (
    ("LIS3MDL", 0x1C), ("LIS3MDL", 0x1E), ("LIS2MDL", 0x1E),
)
"""Where the driver looks, in order (issue 31: Adafruit's 9-DoF board, X-NUCLEO-IKS01A3)."""


@dataclass(frozen=True, slots=True)
class MagSettings:
    """What :meth:`MagnetometerDriver.configure` set up and read back."""

    chip: str
    address: int
    odr_hz: float
    range_ut: float
    ut_per_lsb: float
    mode: str
    sequence: tuple[tuple[int, int], ...]

    def info(self) -> MagnetometerInfo:
        return MagnetometerInfo(chip=self.chip, odr_hz=self.odr_hz, range_ut=self.range_ut,
                                ut_per_lsb=self.ut_per_lsb, address=self.address,
                                mode=self.mode, path="bus")


def best_rate(rates: tuple[float, ...], max_rate_hz: float) -> float:
    """The fastest of ``rates`` at or below ``max_rate_hz`` (the slowest if none is)."""
    below = [r for r in rates if r <= max_rate_hz]
    return max(below) if below else min(rates)


class MagnetometerDriver:
    """Drives one LIS3MDL or LIS2MDL (``part``) at ``address`` on ``bus``."""

    def __init__(self, bus: I2CBus, part: str, address: int, label: str = "magnetometer") -> None:
        self.bus = bus
        self.part = part
        self.address = address
        self.label = label
        self.settings: MagSettings | None = None
        self.overruns = 0
        """Polls that found ZYXOR set: a sample was overwritten before it was read."""

    @property
    def is_lis3mdl(self) -> bool:
        return self.part == "LIS3MDL"

    # -- registers --------------------------------------------------------------------------------
    def read(self, register: int, length: int = 1) -> bytes:
        if self.is_lis3mdl and length > 1:
            register |= mreg.LIS3MDL_AUTO_INCREMENT  # DocID024204 5.1.1
        data = self.bus.read_registers(self.address, register, length)
        if len(data) != length:
            raise DeviceIOError(f"{self.label}: the {self.part} at 0x{self.address:02X} gave "
                                f"{len(data)} of {length} bytes from register 0x{register:02X}")
        return data

    def write(self, register: int, value: int) -> None:
        self.bus.write_register(self.address, register, bytes([value & 0xFF]))

    # -- probe and set-up -------------------------------------------------------------------------
    @classmethod
    def probe(cls, bus: I2CBus, label: str = "magnetometer") -> MagnetometerDriver | None:
        """The first chip of :data:`PROBES` whose WHO_AM_I answers right; None if none does.

        An address that does not acknowledge is simply empty (on a real bus a NACK is
        what an absent chip gives)."""
        for part, address in PROBES:
            register, expected = (
                (mreg.LIS3MDL_WHO_AM_I, mreg.LIS3MDL_WHO_AM_I_VALUE) if part == "LIS3MDL"
                else (mreg.LIS2MDL_WHO_AM_I, mreg.LIS2MDL_WHO_AM_I_VALUE))
            try:
                value = bus.read_registers(address, register, 1)
            except DeviceIOError:
                continue
            if value[:1] == bytes([expected]):
                return cls(bus, part, address, label)
        return None

    def configure(self, max_rate_hz: float) -> MagSettings:
        """Soft reset, then the chip's low-noise setting at the fastest rate at or below
        ``max_rate_hz`` (what the bus can poll); check the registers took."""
        if self.is_lis3mdl:
            rate = best_rate(mreg.LIS3MDL_DO_RATES_HZ, max_rate_hz)
            self.write(mreg.LIS3MDL_CTRL_REG2, mreg.LIS3MDL_SOFT_RST)
            sequence = mreg.lis3mdl_sequence(rate, LIS3MDL_FS_GAUSS)
            ut_per_lsb = mreg.UT_PER_GAUSS / mreg.LIS3MDL_LSB_PER_GAUSS[LIS3MDL_FS_GAUSS]
            range_ut = LIS3MDL_FS_GAUSS * mreg.UT_PER_GAUSS
            mode = "ultra-high-performance"
        else:
            rate = best_rate(mreg.LIS2MDL_ODR_RATES_HZ, max_rate_hz)
            self.write(mreg.LIS2MDL_CFG_REG_A, mreg.LIS2MDL_SOFT_RST)
            sequence = mreg.lis2mdl_sequence(rate)
            ut_per_lsb = mreg.LIS2MDL_UT_PER_LSB
            range_ut = 32768 * ut_per_lsb
            mode = ("continuous, high-resolution, low-pass filter, offset cancellation, "
                    "temperature compensation")
        for register, value in sequence:
            self.write(register, value)
        first = min(r for r, _ in sequence)
        readback = self.read(first, max(r for r, _ in sequence) - first + 1)
        wrong = [f"0x{r:02X} reads 0x{readback[r - first]:02X}, wrote 0x{v:02X}"
                 for r, v in sequence if readback[r - first] != v]
        if wrong:
            raise DeviceIOError(f"{self.label}: the {self.part}'s configuration did not stick: "
                                f"{'; '.join(wrong)}")
        self.settings = MagSettings(self.part, self.address, rate, range_ut, ut_per_lsb, mode,
                                    tuple(sequence))
        return self.settings

    def stop(self) -> None:
        """Power-down (LIS3MDL) or idle (LIS2MDL) mode."""
        if self.is_lis3mdl:
            self.write(mreg.LIS3MDL_CTRL_REG3, mreg.LIS3MDL_MD_POWER_DOWN)
        else:
            self.write(mreg.LIS2MDL_CFG_REG_A, mreg.LIS2MDL_MD_IDLE)

    # -- streaming --------------------------------------------------------------------------------
    def poll(self) -> np.ndarray | None:
        """STATUS_REG and the six output bytes in one burst: the (3,) counts when ZYXDA says
        they are new, else None. ZYXOR counts in :attr:`overruns`."""
        status_register = (mreg.LIS3MDL_STATUS_REG if self.is_lis3mdl
                           else mreg.LIS2MDL_STATUS_REG)
        data = self.read(status_register, 7)
        if data[0] & mreg.STATUS_ZYXOR:
            self.overruns += 1
        if not data[0] & mreg.STATUS_ZYXDA:
            return None
        return np.frombuffer(data[1:], dtype="<i2").astype(np.float64)
