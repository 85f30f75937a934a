"""Emulated LIS3MDL and LIS2MDL magnetometers, and a shared emulated I2C bus (issue 31).

:class:`EmulatedMagnetometer` answers at the register level (the map in
:mod:`~drivers.lsm6dsox_direct.mag_registers`): WHO_AM_I, the configuration registers, soft
reset, STATUS_REG with the data-ready and overrun bits, and the output registers, with the
LIS3MDL's auto-increment only when the sub-address's MSB is set and the LIS2MDL's always.

Its physics are the simulator's magnetometer (:mod:`drivers.sim.magnetometer`): the World
Magnetic Model's field for the URL's ``place`` and ``date`` plus the ``magdist`` disturbances,
turned into the sensor frame by the **same scenario object** as the emulated LSM6DSOX beside it
(so both see one motion), measured with the seed's magnetometer errors, datasheet noise and
the LSB of the full scale the registers set.

Timing: the chip converts at the rate its registers set, times ``1 + odr_error`` (its own
oscillator), sample ``k`` at ``start + (k + phase) / rate`` seconds after the bus's power-on,
``start`` being when continuous mode (or a new rate) was written. The output registers hold
the latest sample until the next one; STATUS_REG's ZYXDA (and XDA..ZDA) is set by a new sample
and cleared when the output registers are read; a sample that arrives while the previous one
was still unread sets ZYXOR (and XOR..ZOR), cleared by that read too.

Modelling choices (assumed, not from a datasheet):

- BDU: after the low byte of an axis is read, new samples do not reach the output registers
  until its high byte is read (the datasheet's "not updated until MSB and LSB are read");
- the disturbances' windows are on the bus's true time (the emulated board has no other clock);
- the noise is the datasheet's for the mode the driver sets (LIS3MDL ultra-high-performance,
  LIS2MDL with its low-pass filter) whatever OM/LP are written; the chip's own offset and
  its drift with temperature are not modelled, so OFF_CANC and COMP_TEMP_EN are stored and read
  back but change nothing; TEMP_OUT reads 0;
- ``fail_after_s``: from that bus time on the chip no longer acknowledges (a loose wire),
  while the LSM6DSOX on the same bus goes on answering.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import replace

import numpy as np

from app.core.earth_field import DEFAULT_PLACE, earth_field
from drivers.errors import DeviceIOError
from drivers.lsm6dsox_direct import mag_registers as mreg
from drivers.lsm6dsox_direct.bus import I2CBus
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox
from drivers.sim.error_model import MagnetometerErrors
from drivers.sim.magnetometer import MAG_CHIPS, MagneticWorld, SimulatedMagnetometer
from drivers.sim.options import SimOptions
from drivers.sim.scenarios import Scenario

PARTS = ("LIS3MDL", "LIS2MDL")


class EmulatedMagnetometer:
    """One emulated LIS3MDL or LIS2MDL (see the module docstring); a target on an
    :class:`EmulatedBus`.

    Parameters
    ----------
    part : ``"LIS3MDL"`` or ``"LIS2MDL"``.
    sim : the simulator options (seed, errors, noise, place, date, magdist).
    scenario : the motion, shared with the emulated LSM6DSOX.
    clock : the bus's clock (seconds); ``power_on_s`` its reading at the bus's power-on.
    address : 0x1C or 0x1E (LIS3MDL), 0x1E (LIS2MDL).
    record_truth : keep every sample the chip converts (see :meth:`truth`).
    fail_after_s : bus time after power-on from which the chip stops acknowledging.
    """

    def __init__(self, part: str, sim: SimOptions, scenario: Scenario,
                 clock: Callable[[], float], power_on_s: float, *, address: int | None = None,
                 record_truth: bool = False, fail_after_s: float | None = None) -> None:
        part = part.upper()
        if part not in PARTS:
            raise ValueError(f"unknown magnetometer part {part!r}; use LIS3MDL or LIS2MDL")
        self.part = part
        self.is_lis3mdl = part == "LIS3MDL"
        default = mreg.LIS3MDL_ADDRESSES[0] if self.is_lis3mdl else mreg.LIS2MDL_ADDRESS
        self.address = default if address is None else address
        self.scenario = scenario
        self._clock = clock
        self._power_on_s = power_on_s
        self.record_truth = record_truth
        self.fail_after_s = fail_after_s
        drawn = MagnetometerErrors.draw(sim.seed)
        self.errors = drawn if sim.errors else drawn.without_errors()
        field = earth_field(sim.place or DEFAULT_PLACE, sim.date)
        world = MagneticWorld.build(field.enu_magnetic_ut(), sim.mag_disturbances, sim.seed)
        self.chip = MAG_CHIPS[part.lower()]
        self.model = SimulatedMagnetometer(self.chip, self.errors, world, sim.seed,
                                           white_noise=sim.noise)
        self.transactions = 0
        self._truth: list[tuple[float, np.ndarray, np.ndarray]] = []
        self._reset()

    # -- target interface (EmulatedBus) -----------------------------------------------------------
    def write_register(self, address: int, register: int, data: bytes) -> None:
        self._transfer(address)
        self._advance()
        for offset, register_now in enumerate(self._addresses(register, len(data))):
            self._write_byte(register_now, data[offset])

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        self._transfer(address)
        self._advance()
        out = bytearray()
        for register_now in self._addresses(register, length):
            out.append(self._read_byte(register_now))
        return bytes(out)

    def close(self) -> None:
        """Nothing to release (the bus owns the clock)."""

    # -- what tests look at -----------------------------------------------------------------------
    @property
    def register_file(self) -> bytes:
        """The stored register values (128), without advancing time."""
        return bytes(self._regs)

    @property
    def rate_hz(self) -> float:
        """The nominal output rate the registers set (0 when not converting)."""
        return self._rate_nominal_hz if self._running else 0.0

    @property
    def samples_converted(self) -> int:
        """Samples converted since continuous mode (or the rate) was last written."""
        self._advance()
        return self._produced

    def truth(self) -> dict[str, np.ndarray]:
        """Every sample converted so far (of a long unread stretch only the newest 64, which
        is all a reader could see): ``t_true_s`` (since the bus's power-on),
        ``field_sensor_ut`` (the true field in the accelerometer's frame) and ``raw`` (counts)."""
        if not self._truth:
            return {}
        t, field, raw = zip(*self._truth, strict=True)
        return {"t_true_s": np.array(t), "field_sensor_ut": np.array(field),
                "raw": np.array(raw)}

    # -- internals: transfers and registers -------------------------------------------------------
    def _now(self) -> float:
        return self._clock() - self._power_on_s

    def _transfer(self, address: int) -> None:
        if address != self.address:
            raise DeviceIOError(f"no ACK from I2C address 0x{address:02X}")
        if self.fail_after_s is not None and self._now() >= self.fail_after_s:
            raise DeviceIOError(
                f"no ACK from the {self.part} at I2C address 0x{address:02X} (it stopped "
                f"answering after {self.fail_after_s:g} s: mag_fail_after)")
        self.transactions += 1

    def _addresses(self, register: int, length: int) -> Iterable[int]:
        """The registers a transfer of ``length`` bytes touches."""
        if self.is_lis3mdl:
            start = register & 0x7F
            step = 1 if register & mreg.LIS3MDL_AUTO_INCREMENT else 0
            return [(start + i * step) & 0x7F for i in range(length)]
        return [(register + i) & 0x7F for i in range(length)]

    def _reset(self) -> None:
        self._regs = bytearray(128)
        if self.is_lis3mdl:
            self._regs[mreg.LIS3MDL_WHO_AM_I] = mreg.LIS3MDL_WHO_AM_I_VALUE
            for register, value in mreg.LIS3MDL_RESET_VALUES.items():
                self._regs[register] = value
        else:
            self._regs[mreg.LIS2MDL_WHO_AM_I] = mreg.LIS2MDL_WHO_AM_I_VALUE
            for register, value in mreg.LIS2MDL_RESET_VALUES.items():
                self._regs[register] = value
        self._status = 0
        self._output = np.zeros(3, dtype=np.int16)
        self._pending: np.ndarray | None = None  # a sample BDU holds back
        self._bdu_low_read: set[int] = set()
        self._running = False
        self._rate_nominal_hz = 0.0
        self._start_s = 0.0
        self._produced = 0

    @property
    def _status_register(self) -> int:
        return mreg.LIS3MDL_STATUS_REG if self.is_lis3mdl else mreg.LIS2MDL_STATUS_REG

    @property
    def _out_register(self) -> int:
        return mreg.LIS3MDL_OUT_X_L if self.is_lis3mdl else mreg.LIS2MDL_OUTX_L_REG

    @property
    def _bdu(self) -> bool:
        if self.is_lis3mdl:
            return bool(self._regs[mreg.LIS3MDL_CTRL_REG5] & mreg.LIS3MDL_BDU)
        return bool(self._regs[mreg.LIS2MDL_CFG_REG_C] & mreg.LIS2MDL_BDU)

    def _write_byte(self, register: int, value: int) -> None:
        if self.is_lis3mdl:
            if register == mreg.LIS3MDL_CTRL_REG2 and value & (mreg.LIS3MDL_SOFT_RST
                                                               | mreg.LIS3MDL_REBOOT):
                self._reset()
                return
            if register not in mreg.LIS3MDL_RESET_VALUES:
                return  # read-only or reserved
            self._regs[register] = value
            if register in (mreg.LIS3MDL_CTRL_REG1, mreg.LIS3MDL_CTRL_REG3):
                self._restart()
        else:
            if register == mreg.LIS2MDL_CFG_REG_A and value & (mreg.LIS2MDL_SOFT_RST
                                                               | mreg.LIS2MDL_REBOOT):
                self._reset()
                return
            if register not in mreg.LIS2MDL_RESET_VALUES:
                return
            self._regs[register] = value
            if register == mreg.LIS2MDL_CFG_REG_A:
                self._restart()

    def _read_byte(self, register: int) -> int:
        out = self._out_register
        if register == self._status_register:
            return self._status
        if out <= register < out + 6:
            axis, high = divmod(register - out, 2)
            value = int(self._output[axis]).to_bytes(2, "little", signed=True)[high]
            if high:
                self._bdu_low_read.discard(axis)
                self._status &= ~(mreg.STATUS_AXIS_DA[axis] | mreg.STATUS_AXIS_OR[axis])
                if not self._status & 0x07:
                    self._status &= ~(mreg.STATUS_ZYXDA | mreg.STATUS_ZYXOR)
                if not self._bdu_low_read and self._pending is not None:
                    self._output, self._pending = self._pending, None
            elif self._bdu:
                self._bdu_low_read.add(axis)
            return value
        return self._regs[register]

    # -- internals: sampling ----------------------------------------------------------------------
    def _configured_rate(self) -> float:
        """The nominal rate the registers set; 0 when not in continuous mode."""
        if self.is_lis3mdl:
            mode = self._regs[mreg.LIS3MDL_CTRL_REG3] & mreg.LIS3MDL_MD_MASK
            if mode != mreg.LIS3MDL_MD_CONTINUOUS:
                return 0.0
            ctrl1 = self._regs[mreg.LIS3MDL_CTRL_REG1]
            if ctrl1 & mreg.LIS3MDL_FAST_ODR:
                return mreg.LIS3MDL_FAST_ODR_HZ[(ctrl1 >> mreg.LIS3MDL_OM_SHIFT) & 0x03]
            return mreg.LIS3MDL_DO_RATES_HZ[(ctrl1 >> mreg.LIS3MDL_DO_SHIFT) & 0x07]
        cfg_a = self._regs[mreg.LIS2MDL_CFG_REG_A]
        if cfg_a & mreg.LIS2MDL_MD_MASK != mreg.LIS2MDL_MD_CONTINUOUS:
            return 0.0
        return mreg.LIS2MDL_ODR_RATES_HZ[(cfg_a >> mreg.LIS2MDL_ODR_SHIFT) & 0x03]

    def _ut_per_lsb(self) -> float:
        if not self.is_lis3mdl:
            return mreg.LIS2MDL_UT_PER_LSB
        fs_code = (self._regs[mreg.LIS3MDL_CTRL_REG2] >> mreg.LIS3MDL_FS_SHIFT) & 0x03
        fs_gauss = {code: fs for fs, code in mreg.LIS3MDL_FS_CODES.items()}[fs_code]
        return mreg.UT_PER_GAUSS / mreg.LIS3MDL_LSB_PER_GAUSS[fs_gauss]

    def _restart(self) -> None:
        rate = self._configured_rate()
        if rate == self._rate_nominal_hz and self._running == (rate > 0):
            return
        self._rate_nominal_hz = rate
        self._running = rate > 0
        self._start_s = self._now()
        self._produced = 0

    def _advance(self) -> None:
        """Convert the samples whose time has come; only the newest reaches the registers."""
        if not self._running:
            return
        rate = self._rate_nominal_hz * (1.0 + self.errors.odr_error)
        phase = self.errors.phase
        total = math.floor((self._now() - self._start_s) * rate - phase) + 1
        due = total - self._produced
        if due <= 0:
            return
        k = np.arange(max(self._produced, total - 64), total, dtype=np.float64)
        t_true = self._start_s + (k + phase) / rate
        self.model.chip = replace(self.chip, ut_per_lsb=self._ut_per_lsb())
        field = self.model.true_field_sensor_ut(t_true, self.scenario.orientation(t_true))
        raw = self.model.measure(field).astype(np.int16)
        if self.record_truth:
            self._truth.extend(zip(t_true.tolist(), field, raw, strict=True))
        self._produced = total
        unread = self._status & 0x07
        if unread or due > 1:
            overrun_axes = 0x07 if due > 1 else unread
            self._status |= mreg.STATUS_ZYXOR | sum(
                bit for axis, bit in enumerate(mreg.STATUS_AXIS_OR) if overrun_axes >> axis & 1)
        self._status |= mreg.STATUS_ZYXDA | 0x07
        if self._bdu and self._bdu_low_read:
            self._pending = raw[-1].copy()
        else:
            self._output = raw[-1].copy()


class EmulatedBus(I2CBus):
    """An emulated I2C bus carrying several emulated chips, routed by address.

    The first target is the emulated LSM6DSOX (an
    :class:`~drivers.lsm6dsox_direct.emulated_chip.EmulatedLsm6dsox`); its clock is the bus's
    clock and its simulator options are the bus's ``sim``. An address no target has is not
    acknowledged.
    """

    max_read_bytes = 65535
    description = "emulated I2C bus"

    def __init__(self, lsm6dsox: EmulatedLsm6dsox, *others: EmulatedMagnetometer) -> None:
        self.lsm6dsox = lsm6dsox
        self.others = others
        self.targets: dict[int, EmulatedLsm6dsox | EmulatedMagnetometer] = {
            lsm6dsox.address: lsm6dsox}
        for target in others:
            if target.address in self.targets:
                raise ValueError(f"two emulated chips at I2C address 0x{target.address:02X}")
            self.targets[target.address] = target
        self.sim = lsm6dsox.sim

    @property
    def magnetometer(self) -> EmulatedMagnetometer | None:
        """The first emulated magnetometer on the bus, if any."""
        return next(iter(self.others), None)

    def _target(self, address: int) -> EmulatedLsm6dsox | EmulatedMagnetometer:
        self.lsm6dsox.check_adapter()
        target = self.targets.get(address)
        if target is None:
            raise DeviceIOError(f"no ACK from I2C address 0x{address:02X}: nothing answers there")
        return target

    def write_register(self, address: int, register: int, data: bytes) -> None:
        self._target(address).write_register(address, register, data)

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        return self._target(address).read_registers(address, register, length)

    def close(self) -> None:
        self.lsm6dsox.close()

    def monotonic(self) -> float:
        return self.lsm6dsox.monotonic()

    def delay(self, seconds: float) -> None:
        self.lsm6dsox.delay(seconds)


def make_emulated_bus(lsm6dsox: EmulatedLsm6dsox, part: str | None, *, address: int | None = None,
                      record_truth: bool = False, fail_after_s: float | None = None
                      ) -> EmulatedBus:
    """An :class:`EmulatedBus` with ``lsm6dsox`` and, unless ``part``
    is None, an emulated magnetometer that shares its clock, power-on time and scenario."""
    chips = []
    if part is not None:
        chips.append(EmulatedMagnetometer(
            part, lsm6dsox.sim, lsm6dsox.scenario, lsm6dsox.monotonic,
            lsm6dsox.power_on_s, address=address, record_truth=record_truth,
            fail_after_s=fail_after_s))
    return EmulatedBus(lsm6dsox, *chips)
