"""An emulated LSM6DSOX behind a virtual I2C bus: registers, FIFO, timestamp, self-test, physics.

The chip answers the register-level driver exactly as the real part would for the features the
project uses: WHO_AM_I, software reset, CTRL1_XL/CTRL2_G (ODR and full scale), CTRL3_C (BDU,
IF_INC), CTRL5_C self-test, CTRL10_C timestamp, STATUS_REG, the output registers, TIMESTAMP0-3,
INTERNAL_FREQ_FINE and the FIFO (FIFO_CTRL3/4 batching, continuous and bypass modes, tagged
7-byte words with TAG_CNT and parity, FIFO_STATUS1/2 with the overrun flags).

The physics are the simulator's (:mod:`drivers.sim`): a scenario moves the chip, a seed-picked
unit's errors and the :class:`~drivers.sim.error_model.MeasurementModel` turn the truth into LSB,
and the unit's oscillator trim sets INTERNAL_FREQ_FINE, the ODR and the 25 us timestamp tick.

Time comes from a clock: the wall clock for the ``lsm6dsox://emulated`` product device, or a
:class:`VirtualClock` that moves only when the test (or the driver's :meth:`delay`) moves it,
so tests need no sleeps. Samples are computed lazily, on each bus access, for the time that
has passed.

Modelling choices (assumed, not from a datasheet):

- the sample engine runs at the faster of the accelerometer and gyroscope ODRs, and both
  sensors are sampled on its ticks; a sensor batched at a lower rate is written every Nth slot;
- within a slot the words are written as timestamp, gyroscope, accelerometer, temperature;
- the FIFO holds :data:`~drivers.lsm6dsox_direct.registers.FIFO_CAPACITY_WORDS` words; in
  continuous mode the oldest are overwritten, which sets FIFO_OVR_LATCHED (cleared by reading
  FIFO_STATUS2) and FIFO_OVR_IA (cleared once the level falls below full);
- a software reset completes :data:`RESET_TIME_S` after it is written;
- the turn-on transient (:mod:`drivers.sim.transient`): after CTRL1_XL or CTRL2_G is written,
  the first samples of the engine's ODR code are settling, per sensor; a reader that drops
  :data:`drivers.lsm6dsox.TURN_ON_DISCARD` samples sees none of them;
- the self-test adds a per-unit output change: 300-900 mg per accelerometer axis, and a
  gyroscope rate of 250-500 dps at +-2000 dps full scale, proportional to the full scale
  (inside the datasheet windows of HARDWARE.md); ``self_test_working=False`` models a chip
  whose self-test produces no change.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from app.core import quaternion as quat
from drivers import lsm6dsox
from drivers.errors import DeviceIOError
from drivers.lsm6dsox_direct import registers as reg
from drivers.lsm6dsox_direct.bus import I2CBus
from drivers.sim.error_model import (
    REFERENCE_TEMP_DEGC,
    STREAM_SCENARIO,
    MeasurementModel,
    UnitErrors,
)
from drivers.sim.options import SimOptions
from drivers.sim.scenarios import SCENARIOS, Scenario
from drivers.sim.transient import apply_turn_on_transient

RESET_TIME_S = 50e-6
PART_ACCEL_RANGE_FACTOR = {"LSM6DSOX": 1, "LSM6DSO": 1, "LSM6DSO32": 2, "LSM6DSO32X": 2}
"""Parts answering WHO_AM_I 0x6C, and their accelerometer range over the LSM6DSOX's at the
same FS_XL code (the LSM6DSO32's "+-4 g" is +-8 g: it reads half the acceleration)."""
TICKS_PER_S_NOMINAL = 1.0 / lsm6dsox.TIMESTAMP_TICK_S
STREAM_SELF_TEST = 7
"""Random stream of the unit's self-test response (after the simulator's streams 0-5)."""
_GRAVITY_EARTH = np.array([0.0, 0.0, lsm6dsox.STANDARD_GRAVITY_M_S2])
_FS_XL_FROM_CODE = {code: fs for fs, code in lsm6dsox.FS_XL_CODES.items()}
_FS_G_FROM_CODE = {code: fs for fs, code in lsm6dsox.FS_G_CODES.items()}
_TEMP_BATCH_HZ = {code: hz for hz, code in reg.ODR_T_BATCH_CODES.items()}
_TS_DECIMATION = {code: n for n, code in reg.DEC_TS_BATCH_CODES.items()}
_READ_ONLY = {
    reg.WHO_AM_I, reg.STATUS_REG, reg.FIFO_STATUS1, reg.FIFO_STATUS2, reg.INTERNAL_FREQ_FINE,
    *range(reg.OUT_TEMP_L, reg.OUTX_L_A + 6), *range(reg.TIMESTAMP0, reg.TIMESTAMP0 + 4),
    *range(reg.FIFO_DATA_OUT_TAG, reg.FIFO_DATA_OUT_TAG + 7),
}
_ODD_PARITY = np.array([bin(value).count("1") % 2 for value in range(256)], dtype=np.uint8)


class VirtualClock:
    """A clock in seconds that moves only through :meth:`advance` (for tests)."""

    def __init__(self, start_s: float = 0.0) -> None:
        self.now_s = float(start_s)

    def __call__(self) -> float:
        return self.now_s

    def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds`` (>= 0)."""
        self.now_s += max(0.0, float(seconds))


@dataclass(frozen=True, slots=True)
class SelfTestResponse:
    """The output change the unit's self-test produces (positive mode; negative flips it)."""

    accel_mg: np.ndarray
    """(3,) per axis, independent of the full scale."""
    gyro_dps_at_2000: np.ndarray
    """(3,) at +-2000 dps; proportional to the full scale at other settings."""

    @classmethod
    def draw(cls, seed: int) -> SelfTestResponse:
        rng = np.random.default_rng([seed, STREAM_SELF_TEST])
        return cls(rng.uniform(300.0, 900.0, 3), rng.uniform(250.0, 500.0, 3))


class EmulatedLsm6dsox(I2CBus):
    """An I2C bus with one emulated LSM6DSOX on it (see the module docstring).

    Parameters
    ----------
    sim : the simulator options that pick the scenario, the unit (seed, ``errors``) and the
        white noise; ODR and full scales come from the registers the driver writes.
    address : the chip's 7-bit I2C address (0x6A or 0x6B); others do not acknowledge.
    clock : a :class:`VirtualClock` (time moves only when told; :meth:`delay` advances it), or
        None for the wall clock.
    who_am_i : what WHO_AM_I reads (0x6C; another value emulates a different part).
    self_test_working : False: enabling the self-test changes nothing (a faulty chip).
    unit : the unit's errors, overriding the seed's draw.
    record_truth : keep the truth of every sample batched in the FIFO (see :meth:`truth`).
    fail_after_s : bus time after which every transfer fails, as if the adapter were pulled.
    part : which part answers (:data:`PART_ACCEL_RANGE_FACTOR`): a look-alike LSM6DSO32 reads
        half the acceleration.
    """

    max_read_bytes = 65535
    description = "emulated I2C bus"

    def __init__(
        self,
        sim: SimOptions | None = None,
        *,
        address: int = 0x6A,
        clock: VirtualClock | None = None,
        who_am_i: int = lsm6dsox.WHO_AM_I_VALUE,
        self_test_working: bool = True,
        unit: UnitErrors | None = None,
        record_truth: bool = False,
        fail_after_s: float | None = None,
        part: str = "LSM6DSOX",
    ) -> None:
        self.sim = sim or SimOptions(scenario="static")
        self.address = address
        self.virtual_clock = clock
        self._clock: Callable[[], float] = clock if clock is not None else time.monotonic
        self.who_am_i = who_am_i
        drawn = UnitErrors.draw(self.sim.seed)
        self.unit = unit or (drawn if self.sim.errors else drawn.without_errors())
        self.self_test_response = SelfTestResponse.draw(self.sim.seed)
        self.self_test_working = self_test_working
        self.record_truth = record_truth
        self.fail_after_s = fail_after_s
        self.part = part
        self.accel_range_factor = PART_ACCEL_RANGE_FACTOR[part]
        rng = np.random.default_rng([self.sim.seed, STREAM_SCENARIO])
        self.scenario: Scenario = SCENARIOS[self.sim.scenario](rng, **self.sim.scenario_params)
        self.transactions = 0
        self.bytes_read = 0
        self._truth: list[dict[str, np.ndarray]] = []
        self._power_on_s = self._clock()
        self._closed = False
        self._power_on_reset()

    # -- clock ---------------------------------------------------------------------------------
    @property
    def trim(self) -> float:
        """Trimmed rate over nominal rate: ``1 + 0.0015 * INTERNAL_FREQ_FINE``."""
        return self.unit.clock_trim_factor

    @property
    def true_rate_factor(self) -> float:
        """Real oscillator rate over nominal (the trim and the untrimmed residual)."""
        return self.trim * (1.0 + self.unit.clock_residual)

    def monotonic(self) -> float:
        return self._clock()

    @property
    def power_on_s(self) -> float:
        """The clock's reading at power-on (chips sharing the bus count time from it)."""
        return self._power_on_s

    def delay(self, seconds: float) -> None:
        if self.virtual_clock is not None:
            self.virtual_clock.advance(seconds)
        else:
            super().delay(seconds)

    def _now(self) -> float:
        """Seconds since power-on."""
        return self._clock() - self._power_on_s

    # -- I2CBus --------------------------------------------------------------------------------
    def write_register(self, address: int, register: int, data: bytes) -> None:
        self._transfer(address)
        self._advance()
        increment = bool(self._regs[reg.CTRL3_C] & reg.CTRL3_C_IF_INC)
        for offset, value in enumerate(bytes(data)):
            self._write_byte((register + offset) & 0xFF if increment else register, value)

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        self._transfer(address)
        self._advance()
        self.bytes_read += length
        if register == reg.FIFO_DATA_OUT_TAG:
            return self._pop_fifo(length)
        image = self._register_image()
        if not self._regs[reg.CTRL3_C] & reg.CTRL3_C_IF_INC:
            return bytes([image[register]]) * length
        stop = min(256, register + length)
        out = bytes(image[register:stop]) + bytes(register + length - stop)
        self._after_read(register, stop)
        return out

    def close(self) -> None:
        self._closed = True

    # -- what tests look at --------------------------------------------------------------------
    @property
    def fifo_level(self) -> int:
        """Unread FIFO words right now."""
        self._advance()
        return len(self._fifo)

    @property
    def register_file(self) -> bytes:
        """The stored register values (as last written), without advancing time."""
        return bytes(self._regs)

    def truth(self) -> dict[str, np.ndarray]:
        """Every sample batched in the FIFO so far (``record_truth=True``), in FIFO order.

        Keys: ``index`` (sample number since the ODR was set), ``t_true_s`` (since power-on),
        ``specific_force_m_s2``, ``angular_rate_rad_s``, ``accel_raw``, ``gyro_raw``, ``temp_degc``.
        """
        if not self._truth:
            return {}
        return {key: np.concatenate([c[key] for c in self._truth]) for key in self._truth[0]}

    # -- internals: registers --------------------------------------------------------------------
    def check_adapter(self) -> None:
        """Raise :class:`DeviceIOError` when the bus is closed or the adapter was pulled
        (``fail_after_s``): what every transfer on the bus, to any address, checks first."""
        if self._closed:
            raise DeviceIOError("the emulated I2C bus is closed")
        if self.fail_after_s is not None and self._now() >= self.fail_after_s:
            raise DeviceIOError(
                f"emulated I2C adapter unplugged after {self.fail_after_s:g} s (fail_after option)"
            )

    def _transfer(self, address: int) -> None:
        self.check_adapter()
        if address != self.address:
            raise DeviceIOError(
                f"no ACK from I2C address 0x{address:02X}: nothing answers there (the emulated "
                f"LSM6DSOX is at 0x{self.address:02X})"
            )
        self.transactions += 1

    def _power_on_reset(self) -> None:
        self._regs = bytearray(256)
        self._regs[reg.WHO_AM_I] = self.who_am_i
        self._regs[reg.CTRL3_C] = reg.CTRL3_C_RESET_VALUE
        self._regs[reg.CTRL9_XL] = reg.CTRL9_XL_RESET_VALUE
        self._regs[reg.INTERNAL_FREQ_FINE] = self.unit.freq_fine & 0xFF
        self._reset_done_s = self._now()
        self._engine_rate_hz = 0.0
        self._engine_start_s = 0.0
        self._produced = 0
        self._model: MeasurementModel | None = None
        self._slot = 0
        self._ts_start_s: float | None = None
        self._status = 0
        self._latest = np.zeros(7, dtype=np.int16)  # temperature, gyro x3, accel x3
        self._clear_fifo()

    def _clear_fifo(self) -> None:
        self._fifo = np.empty((0, reg.FIFO_WORD_BYTES), dtype=np.uint8)
        self._ovr_latched = False
        self._ovr_ia = False
        self._slot = 0

    def _write_byte(self, register: int, value: int) -> None:
        if register in _READ_ONLY:
            return
        if register == reg.CTRL3_C and value & (reg.CTRL3_C_SW_RESET | reg.CTRL3_C_BOOT):
            self._power_on_reset()
            self._reset_done_s = self._now() + RESET_TIME_S
            return
        old = self._regs[register]
        self._regs[register] = value
        if register in (reg.CTRL1_XL, reg.CTRL2_G):
            self._start_engine()
        elif register == reg.FIFO_CTRL4:
            if value & reg.FIFO_MODE_MASK == reg.FIFO_MODE_BYPASS:
                self._clear_fifo()
            elif old & reg.FIFO_MODE_MASK == reg.FIFO_MODE_BYPASS:
                self._slot = 0
        elif register == reg.CTRL10_C:
            enabled = bool(value & reg.CTRL10_C_TIMESTAMP_EN)
            if enabled and self._ts_start_s is None:
                self._ts_start_s = self._now()
            elif not enabled:
                self._ts_start_s = None

    def _register_image(self) -> bytearray:
        image = bytearray(self._regs)
        if self._now() < self._reset_done_s:
            image[reg.CTRL3_C] |= reg.CTRL3_C_SW_RESET
        image[reg.STATUS_REG] = self._status
        image[reg.OUT_TEMP_L : reg.OUTX_L_A + 6] = self._latest.astype("<i2").tobytes()
        image[reg.TIMESTAMP0 : reg.TIMESTAMP0 + 4] = int(self._ticks_now()).to_bytes(4, "little")
        level = len(self._fifo)
        image[reg.FIFO_STATUS1] = level & 0xFF
        image[reg.FIFO_STATUS2] = (
            (level >> 8) & reg.FIFO_STATUS2_DIFF_FIFO_HIGH_MASK
            | (reg.FIFO_STATUS2_OVR_LATCHED if self._ovr_latched else 0)
            | (reg.FIFO_STATUS2_FULL_IA if level >= reg.FIFO_CAPACITY_WORDS - 3 else 0)
            | (reg.FIFO_STATUS2_OVR_IA if self._ovr_ia else 0)
        )
        return image

    def _after_read(self, start: int, stop: int) -> None:
        """Read side effects: data-ready bits and the latched overrun flag clear."""
        def covered(first: int, count: int) -> bool:
            return start < first + count and first < stop

        if covered(reg.OUT_TEMP_L, 2):
            self._status &= ~reg.STATUS_TDA
        if covered(reg.OUTX_L_G, 6):
            self._status &= ~reg.STATUS_GDA
        if covered(reg.OUTX_L_A, 6):
            self._status &= ~reg.STATUS_XLDA
        if covered(reg.FIFO_STATUS2, 1):
            self._ovr_latched = False

    def _pop_fifo(self, length: int) -> bytes:
        """FIFO reads: whole words leave the FIFO; an empty FIFO reads as zeros."""
        count = min(len(self._fifo), -(-length // reg.FIFO_WORD_BYTES))
        words, self._fifo = self._fifo[:count], self._fifo[count:]
        if len(self._fifo) < reg.FIFO_CAPACITY_WORDS:
            self._ovr_ia = False
        return (words.tobytes() + bytes(length))[:length]

    def _ticks_now(self) -> int:
        if self._ts_start_s is None:
            return 0
        ticks = (self._now() - self._ts_start_s) * TICKS_PER_S_NOMINAL * self.true_rate_factor
        return math.floor(ticks) & 0xFFFFFFFF

    # -- internals: sampling -----------------------------------------------------------------
    def _odr_code(self, register: int) -> int:
        code = self._regs[register] >> 4
        return code if code in lsm6dsox.ODR_RATES_HZ else 0

    def _start_engine(self) -> None:
        code = max(self._odr_code(reg.CTRL1_XL), self._odr_code(reg.CTRL2_G))
        if code == 0:
            self._model = None
            self._engine_rate_hz = 0.0
            return
        nominal = lsm6dsox.ODR_RATES_HZ[code]  # the real rate: "12.5 Hz" runs at 13.02 Hz
        accel_fs = _FS_XL_FROM_CODE[(self._regs[reg.CTRL1_XL] >> 2) & 0x03]
        gyro_fs = _FS_G_FROM_CODE.get((self._regs[reg.CTRL2_G] >> 1) & 0x07, 250)
        self._accel_fs_g, self._gyro_fs_dps = accel_fs, gyro_fs
        self._model = MeasurementModel(
            self.unit, accel_fs, gyro_fs, nominal * self.trim, white_noise=self.sim.noise
        )
        self._engine_rate_hz = nominal * self.true_rate_factor
        self._engine_start_s = self._now()
        self._produced = 0

    def _batching(self) -> tuple[int, int, int, int]:
        """Every how many slots: (accel, gyro, timestamp, temperature); 0 = not batched."""
        if self._regs[reg.FIFO_CTRL4] & reg.FIFO_MODE_MASK == reg.FIFO_MODE_BYPASS:
            return 0, 0, 0, 0
        nominal = self._engine_rate_hz / self.true_rate_factor

        def every(rate_hz: float) -> int:
            return max(1, round(nominal / rate_hz)) if rate_hz > 0 else 0

        bdr = self._regs[reg.FIFO_CTRL3]
        xl_code, g_code = bdr & 0x0F, bdr >> 4
        rates = lsm6dsox.ODR_RATES_HZ
        accel = every(rates.get(xl_code, 0.0)) if self._odr_code(reg.CTRL1_XL) else 0
        gyro = every(rates.get(g_code, 0.0)) if self._odr_code(reg.CTRL2_G) else 0
        ctrl4 = self._regs[reg.FIFO_CTRL4]
        timestamp = _TS_DECIMATION[ctrl4 >> 6] if self._ts_start_s is not None else 0
        temperature = every(_TEMP_BATCH_HZ[(ctrl4 >> 4) & 0x03])
        if not (accel or gyro):
            return 0, 0, 0, 0
        return accel, gyro, timestamp, temperature

    def _advance(self) -> None:
        """Produce the samples whose time has come."""
        model = self._model
        if model is None:
            return
        elapsed_s = self._now() - self._engine_start_s
        due = math.floor(elapsed_s * self._engine_rate_hz) - self._produced
        if due <= 0:
            return
        batching = self._batching()
        # Only the newest samples can survive in the FIFO (or in the output registers).
        room = reg.FIFO_CAPACITY_WORDS + 8 if any(batching) else 1
        skip = max(0, due - room)
        first = self._produced + skip + 1
        index = np.arange(first, self._produced + due + 1)
        t_true = self._engine_start_s + index / self._engine_rate_hz
        motion = self.scenario.motion(t_true)
        specific_force = quat.rotate_inverse(
            motion.orientation_quat, motion.linear_accel_m_s2 + _GRAVITY_EARTH
        )
        temp_degc = self.unit.temperature_degc(t_true)
        accel_raw, gyro_raw = model.measure(
            int(index[0]), specific_force, motion.angular_rate_rad_s, temp_degc
        )
        if self.accel_range_factor != 1:  # a look-alike with wider ranges: fewer LSB per g
            accel_raw = _saturate(np.rint(accel_raw / self.accel_range_factor))
        accel_raw, gyro_raw = self._apply_settling(index, accel_raw, gyro_raw)
        accel_raw, gyro_raw = self._apply_self_test(accel_raw, gyro_raw)
        temp_raw = np.rint((temp_degc - REFERENCE_TEMP_DEGC) * lsm6dsox.TEMP_LSB_PER_DEGC)
        temp_raw = np.clip(temp_raw, -32768, 32767).astype(np.int16)
        self._latest = np.concatenate([temp_raw[-1:], gyro_raw[-1], accel_raw[-1]])
        xl_on, g_on = self._odr_code(reg.CTRL1_XL), self._odr_code(reg.CTRL2_G)
        self._status |= reg.STATUS_TDA | (reg.STATUS_XLDA if xl_on else 0)
        self._status |= reg.STATUS_GDA if g_on else 0
        if any(batching):
            slots = self._slot + skip + np.arange(len(index))
            ticks = self._sample_ticks(t_true)
            self._push(batching, slots, accel_raw, gyro_raw, temp_raw, ticks, skip > 0)
            if self.record_truth:
                self._truth.append({
                    "index": index, "t_true_s": t_true, "specific_force_m_s2": specific_force,
                    "angular_rate_rad_s": motion.angular_rate_rad_s, "accel_raw": accel_raw,
                    "gyro_raw": gyro_raw, "temp_degc": temp_degc,
                })
            self._slot += due
        self._produced += due

    def _apply_settling(
        self, index: np.ndarray, accel_raw: np.ndarray, gyro_raw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The turn-on transient on samples 1..n after the ODR was set (module docstring)."""
        code = max(self._odr_code(reg.CTRL1_XL), self._odr_code(reg.CTRL2_G))
        return apply_turn_on_transient(index, accel_raw, gyro_raw, code, self._gyro_fs_dps)

    def _apply_self_test(
        self, accel_raw: np.ndarray, gyro_raw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        ctrl5 = self._regs[reg.CTRL5_C]
        st_xl, st_g = ctrl5 & reg.CTRL5_C_ST_XL_MASK, ctrl5 & reg.CTRL5_C_ST_G_MASK
        if not self.self_test_working or not (st_xl or st_g):
            return accel_raw, gyro_raw
        response = self.self_test_response
        if st_xl in (reg.CTRL5_C_ST_XL_POSITIVE, reg.CTRL5_C_ST_XL_NEGATIVE):
            sign = 1.0 if st_xl == reg.CTRL5_C_ST_XL_POSITIVE else -1.0
            lsb = response.accel_mg / lsm6dsox.ACCEL_MG_PER_LSB[self._accel_fs_g]
            accel_raw = _saturate(accel_raw + np.rint(sign * lsb))
        if st_g in (reg.CTRL5_C_ST_G_POSITIVE, reg.CTRL5_C_ST_G_NEGATIVE):
            sign = 1.0 if st_g == reg.CTRL5_C_ST_G_POSITIVE else -1.0
            dps = response.gyro_dps_at_2000 * self._gyro_fs_dps / 2000.0
            lsb = dps * 1e3 / lsm6dsox.GYRO_MDPS_PER_LSB[self._gyro_fs_dps]
            gyro_raw = _saturate(gyro_raw + np.rint(sign * lsb))
        return accel_raw, gyro_raw

    def _sample_ticks(self, t_true: np.ndarray) -> np.ndarray:
        if self._ts_start_s is None:
            return np.zeros(len(t_true), dtype=np.uint32)
        ticks = np.floor((t_true - self._ts_start_s) * TICKS_PER_S_NOMINAL * self.true_rate_factor)
        return (ticks.astype(np.int64) & 0xFFFFFFFF).astype(np.uint32)

    def _push(
        self,
        batching: tuple[int, int, int, int],
        slots: np.ndarray,
        accel_raw: np.ndarray,
        gyro_raw: np.ndarray,
        temp_raw: np.ndarray,
        ticks: np.ndarray,
        skipped: bool,
    ) -> None:
        """Write the slots' words (timestamp, gyro, accel, temperature) into the FIFO."""
        every_accel, every_gyro, every_ts, every_temp = batching
        payload_ts = np.zeros((len(slots), 6), dtype=np.uint8)
        payload_ts[:, :4] = ticks.astype("<u4").view(np.uint8).reshape(-1, 4)
        payload_temp = np.zeros((len(slots), 6), dtype=np.uint8)
        payload_temp[:, :2] = temp_raw.astype("<i2").view(np.uint8).reshape(-1, 2)
        kinds = (
            (every_ts, reg.TAG_TIMESTAMP, payload_ts),
            (every_gyro, reg.TAG_GYRO, gyro_raw.astype("<i2").view(np.uint8).reshape(-1, 6)),
            (every_accel, reg.TAG_ACCEL, accel_raw.astype("<i2").view(np.uint8).reshape(-1, 6)),
            (every_temp, reg.TAG_TEMPERATURE, payload_temp),
        )
        parts, keys = [], []
        for order, (every, tag, payload) in enumerate(kinds):
            if not every:
                continue
            chosen = slots % every == 0
            tag_byte = ((tag << 3) | ((slots[chosen] % 4) << 1)).astype(np.uint8)
            tag_byte |= _ODD_PARITY[tag_byte]
            parts.append(np.column_stack([tag_byte, payload[chosen]]))
            keys.append(slots[chosen] * 4 + order)
        words = np.concatenate(parts)[np.argsort(np.concatenate(keys), kind="stable")]
        fifo = np.concatenate([self._fifo, words])
        overflow = len(fifo) - reg.FIFO_CAPACITY_WORDS
        if overflow > 0 or skipped:
            self._ovr_latched = self._ovr_ia = True
            fifo = fifo[max(0, overflow):]
        self._fifo = fifo


def _saturate(values: np.ndarray) -> np.ndarray:
    return np.clip(values, -32768, 32767).astype(np.int16)
