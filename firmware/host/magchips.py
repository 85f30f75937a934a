"""Register-level LIS3MDL and LIS2MDL for the firmware core's tests (firmware/core/magnetometer.h).

Each is an :class:`~drivers.lsm6dsox_direct.bus.I2CBus` answering at its own address, to sit
on a :class:`fwcore.SharedBus` beside an emulated LSM6DSOX and share its clock. It keeps the
registers the firmware touches, converts continuously at the rate written (once MD = 00), sets
ZYXDA when a new sample is ready (ZYXOR when it overwrote an unread one) and clears them when
the output is read, and records every
sample it converted (time, counts) as the truth a test compares with. The field is a slow
rotation of a 50 uT vector, quantised to the chip's sensitivity. ``fail`` makes every transfer
fail (a loose wire).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from drivers.errors import DeviceIOError
from drivers.lsm6dsox_direct.bus import I2CBus

LIS3MDL_RATES_HZ = {0x4: 10.0, 0x5: 20.0, 0x6: 40.0, 0x7: 80.0}  # CTRL_REG1 DO, OM = UHP
LIS2MDL_RATES_HZ = {0: 10.0, 1: 20.0, 2: 50.0, 3: 100.0}  # CFG_REG_A ODR


def field_ut(t_s: float) -> np.ndarray:
    """The field the emulated chips see: 50 uT turning slowly about z, dipping 60 degrees."""
    angle = 0.5 * t_s
    horizontal, vertical = 25.0, -43.3
    return np.array([horizontal * math.cos(angle), horizontal * math.sin(angle), vertical])


class _EmulatedMagnetometer(I2CBus):
    who_am_i_register = 0
    who_am_i = 0
    status_register = 0
    ut_per_lsb = 1.0

    def __init__(self, address: int, clock: Callable[[], float]) -> None:
        self.address = address
        self._clock = clock
        self.regs = bytearray(256)
        self._power_on_registers()
        self.truth: list[tuple[float, tuple[int, int, int]]] = []
        self.fail = False
        self.reads = 0
        self._next_s: float | None = None
        self._latest = (0, 0, 0)
        self._ready = False

    # -- what a subclass says ----------------------------------------------------------------
    def _rate_hz(self) -> float | None:
        raise NotImplementedError

    def _soft_reset(self, register: int, value: int) -> bool:
        raise NotImplementedError

    def _power_on_registers(self) -> None:
        self.regs[:] = bytes(256)
        self.regs[self.who_am_i_register] = self.who_am_i

    def _read_register(self, register: int) -> int:
        return register

    # -- I2CBus ----------------------------------------------------------------------------------
    def _check(self, address: int) -> None:
        if self.fail or address != self.address:
            raise DeviceIOError(f"no ACK from I2C address 0x{address:02X}")

    def write_register(self, address: int, register: int, data: bytes) -> None:
        self._check(address)
        self._convert()
        for offset, value in enumerate(bytes(data)):
            reg = (self._read_register(register) + offset) & 0xFF
            if self._soft_reset(reg, value):
                self._power_on_registers()
                continue
            self.regs[reg] = value
        rate = self._rate_hz()
        self._next_s = None if rate is None else self._clock() + 1.0 / rate

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        self._check(address)
        self._convert()
        self.reads += 1
        start = self._read_register(register)
        out = bytes(self.regs[(start + i) & 0xFF] for i in range(length))
        status = self.status_register
        if start <= status + 6 < start + length:  # the whole sample was read: ZYXDA clears
            self._ready = False
            self.regs[status] &= ~0x88 & 0xFF  # ZYXDA and ZYXOR clear once the data is read
        return out

    def close(self) -> None:
        pass

    def monotonic(self) -> float:
        return self._clock()

    # -- conversions -------------------------------------------------------------------------
    def _convert(self) -> None:
        rate = self._rate_hz()
        if rate is None or self._next_s is None:
            return
        now = self._clock()
        while self._next_s <= now:
            counts = np.clip(np.rint(field_ut(self._next_s) / self.ut_per_lsb), -32768, 32767)
            self._latest = tuple(int(v) for v in counts)
            self.truth.append((self._next_s, self._latest))
            self._next_s += 1.0 / rate
            if self._ready:  # the previous sample was never read: ZYXOR
                self.regs[self.status_register] |= 0x80
            self._ready = True
        base = self.status_register + 1
        for axis, value in enumerate(self._latest):
            self.regs[base + 2 * axis:base + 2 * axis + 2] = int(value).to_bytes(
                2, "little", signed=True)
        if self._ready:
            self.regs[self.status_register] |= 0x08


class EmulatedLis3mdl(_EmulatedMagnetometer):
    """An LIS3MDL (0x1C or 0x1E): CTRL_REG1..5 0x20..0x24, STATUS 0x27, OUT 0x28..0x2D."""

    who_am_i_register = 0x0F
    who_am_i = 0x3D
    status_register = 0x27
    ut_per_lsb = 100.0 / 6842.0

    def __init__(self, clock: Callable[[], float], address: int = 0x1C) -> None:
        super().__init__(address, clock)

    def _power_on_registers(self) -> None:
        super()._power_on_registers()
        self.regs[0x22] = 0x03  # CTRL_REG3 at power-on: MD = 11, power-down

    def _read_register(self, register: int) -> int:
        return register & 0x7F  # the sub-address MSB asks for auto-increment

    def _soft_reset(self, register: int, value: int) -> bool:
        return register == 0x21 and bool(value & 0x04)

    def _rate_hz(self) -> float | None:
        if self.regs[0x22] & 0x03:  # single conversion or power-down
            return None
        if self.regs[0x20] & 0x60 != 0x60 or self.regs[0x23] & 0x0C != 0x0C:
            return None  # only the ultra-high-performance mode is emulated
        return LIS3MDL_RATES_HZ.get((self.regs[0x20] >> 2) & 0x7)


class EmulatedLis2mdl(_EmulatedMagnetometer):
    """An LIS2MDL (0x1E): CFG_REG_A..C 0x60..0x62, STATUS 0x67, OUT 0x68..0x6D."""

    who_am_i_register = 0x4F
    who_am_i = 0x40
    status_register = 0x67
    ut_per_lsb = 0.15

    def __init__(self, clock: Callable[[], float], address: int = 0x1E) -> None:
        super().__init__(address, clock)

    def _power_on_registers(self) -> None:
        super()._power_on_registers()
        self.regs[0x60] = 0x03  # CFG_REG_A at power-on: MD = 11, idle

    def _soft_reset(self, register: int, value: int) -> bool:
        return register == 0x60 and bool(value & 0x20)

    def _rate_hz(self) -> float | None:
        if self.regs[0x60] & 0x03:
            return None
        return LIS2MDL_RATES_HZ[(self.regs[0x60] >> 2) & 0x3]
