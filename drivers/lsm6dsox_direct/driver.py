"""The register-level LSM6DSOX driver: probe, configure, read the FIFO in bursts, self-test.

Bus-agnostic: it talks through an :class:`~drivers.lsm6dsox_direct.bus.I2CBus` and waits on
the bus's clock (``bus.delay``), so the same code runs against the MCP2221A bridge and, with
virtual time, against the emulated chip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers import lsm6dsox
from drivers.errors import DeviceIOError, DeviceOpenError
from drivers.lsm6dsox_direct import registers as reg
from drivers.lsm6dsox_direct.bus import I2CBus
from drivers.lsm6dsox_direct.fifo import DecodedSamples, FifoDecoder


@dataclass(frozen=True, slots=True)
class StreamSettings:
    """What :meth:`Lsm6dsoxDriver.configure` set up and read back."""

    odr_nominal_hz: float
    """The datasheet label (12.5 ... 6667 Hz); the chip runs at :attr:`odr_hz`."""
    accel_fs_g: int
    gyro_fs_dps: int
    freq_fine: int
    """INTERNAL_FREQ_FINE, signed: the chip's clock trim in steps of 0.15 %."""
    sequence: tuple[tuple[int, int], ...]

    @property
    def trim(self) -> float:
        """Actual over nominal rate of the chip's oscillator."""
        return 1.0 + lsm6dsox.FREQ_FINE_STEP * self.freq_fine

    @property
    def odr_code(self) -> int:
        return lsm6dsox.odr_code_for(self.odr_nominal_hz)

    @property
    def odr_hz(self) -> float:
        """The real, trimmed output data rate (6666.67 Hz / ODR_Coeff x trim), as the firmware
        reports it in CONFIG."""
        return lsm6dsox.odr_mhz(self.odr_code, self.freq_fine) / 1000.0

    @property
    def tick_s(self) -> float:
        """One timestamp tick: 25 us divided by the trim."""
        return lsm6dsox.TIMESTAMP_TICK_S / self.trim

    @property
    def ticks_per_sample(self) -> float:
        """Timestamp ticks per sample (the trim cancels: one oscillator drives both)."""
        return 1.0 / (lsm6dsox.TIMESTAMP_TICK_S * lsm6dsox.ODR_RATES_HZ[self.odr_code])


@dataclass(frozen=True, slots=True)
class SelfTestResult:
    """Outcome of the self-test: output changes per axis and whether they fall in the windows."""

    accel_pass: bool
    gyro_pass: bool
    accel_delta_mg: tuple[float, float, float]
    gyro_delta_dps: tuple[float, float, float]
    accel_window_mg: tuple[float, float] = reg.SELF_TEST_ACCEL_WINDOW_MG
    gyro_window_dps: tuple[float, float] = reg.SELF_TEST_GYRO_WINDOW_DPS

    @property
    def passed(self) -> bool:
        return self.accel_pass and self.gyro_pass

    def summary(self) -> str:
        """One line for the user."""
        def axes(values: tuple[float, float, float]) -> str:
            return "/".join(f"{v:.0f}" for v in values)

        return (
            f"accelerometer {'pass' if self.accel_pass else 'FAIL'} "
            f"({axes(self.accel_delta_mg)} mg, window {self.accel_window_mg[0]:g}-"
            f"{self.accel_window_mg[1]:g}), gyroscope {'pass' if self.gyro_pass else 'FAIL'} "
            f"({axes(self.gyro_delta_dps)} dps, window {self.gyro_window_dps[0]:g}-"
            f"{self.gyro_window_dps[1]:g})"
        )


class Lsm6dsoxDriver:
    """Drives one LSM6DSOX on an I2C bus.

    Parameters
    ----------
    bus : the I2C bus the chip is on.
    address : its 7-bit address (0x6A with SA0 low, 0x6B with SA0 high).
    label : prefix of error messages (the device URL).
    """

    def __init__(self, bus: I2CBus, address: int = 0x6A, label: str = "LSM6DSOX") -> None:
        self.bus = bus
        self.address = address
        self.label = label
        self.settings: StreamSettings | None = None
        self.decoder: FifoDecoder | None = None
        self.settling_left = 0
        """Samples of the turn-on transient still to drop (lsm6dsox.TURN_ON_DISCARD)."""
        self.settling_dropped = 0
        self.max_burst_words = max(1, bus.max_read_bytes // reg.FIFO_WORD_BYTES)

    # -- registers ------------------------------------------------------------------------------
    def read(self, register: int, length: int = 1) -> bytes:
        data = self.bus.read_registers(self.address, register, length)
        if len(data) != length:
            raise DeviceIOError(
                f"{self.label}: asked for {length} bytes from register 0x{register:02X}, "
                f"got {len(data)}"
            )
        return data

    def write(self, register: int, value: int) -> None:
        self.bus.write_register(self.address, register, bytes([value & 0xFF]))

    # -- set-up ---------------------------------------------------------------------------------
    def check_who_am_i(self) -> int:
        """Read WHO_AM_I; raise :class:`DeviceOpenError` saying what answered if not 0x6C."""
        value = self.read(reg.WHO_AM_I)[0]
        if value != lsm6dsox.WHO_AM_I_VALUE:
            guess = reg.KNOWN_WHO_AM_I.get(value)
            what = f" ({guess})" if guess else ""
            raise DeviceOpenError(
                f"{self.label}: WHO_AM_I (register 0x0F) at I2C address 0x{self.address:02X} "
                f"reads 0x{value:02X}{what}, but an LSM6DSOX answers 0x6C. Check the part "
                "and the address (0x6A with SA0 low, 0x6B with SA0 high)."
            )
        return value

    def _wait_for_reset(self) -> None:
        deadline = self.bus.monotonic() + reg.SW_RESET_TIMEOUT_S
        while self.read(reg.CTRL3_C)[0] & reg.CTRL3_C_SW_RESET:
            if self.bus.monotonic() > deadline:
                raise DeviceOpenError(
                    f"{self.label}: the software reset did not finish within "
                    f"{reg.SW_RESET_TIMEOUT_S * 1e3:g} ms (CTRL3_C.SW_RESET stays 1)"
                )
            self.bus.delay(100e-6)

    def configure(self, odr_hz: float, accel_fs_g: int, gyro_fs_dps: int) -> StreamSettings:
        """Reset the chip and run :func:`~registers.configuration_sequence`; check it took.

        Streaming starts with the last write: the FIFO then fills in continuous mode.
        """
        sequence = reg.configuration_sequence(odr_hz, accel_fs_g, gyro_fs_dps)
        for register, value in sequence:
            self.write(register, value)
            if register == reg.CTRL3_C and value & reg.CTRL3_C_SW_RESET:
                self._wait_for_reset()
        final = dict(sequence)
        first, last = min(final), max(final)
        readback = self.read(first, last - first + 1)
        wrong = [
            f"0x{r:02X} reads 0x{readback[r - first]:02X}, wrote 0x{v:02X}"
            for r, v in final.items()
            if readback[r - first] != v
        ]
        if wrong:
            raise DeviceIOError(f"{self.label}: configuration did not stick: {'; '.join(wrong)}")
        freq_fine = int.from_bytes(self.read(reg.INTERNAL_FREQ_FINE), "little", signed=True)
        self.settings = StreamSettings(
            lsm6dsox.ODR_LABELS_HZ[reg.check_settings(odr_hz, accel_fs_g, gyro_fs_dps)],
            accel_fs_g, gyro_fs_dps, freq_fine, tuple(sequence),
        )
        self.decoder = FifoDecoder(self.settings.ticks_per_sample)
        # The FIFO fills from the ODR write on: its first samples are the turn-on transient.
        self.settling_left = lsm6dsox.turn_on_discard(odr_hz)
        return self.settings

    def stop(self) -> None:
        """Sensors off and FIFO in bypass (empties it)."""
        self.write(reg.FIFO_CTRL4, reg.FIFO_MODE_BYPASS)
        self.write(reg.CTRL1_XL, 0)
        self.write(reg.CTRL2_G, 0)

    # -- streaming ------------------------------------------------------------------------------
    def fifo_status(self) -> tuple[int, bool]:
        """(unread words, overrun flagged) from FIFO_STATUS1/2 in one transfer."""
        status = self.read(reg.FIFO_STATUS1, 2)
        level = status[0] | (status[1] & reg.FIFO_STATUS2_DIFF_FIFO_HIGH_MASK) << 8
        overrun = bool(status[1] & (reg.FIFO_STATUS2_OVR_IA | reg.FIFO_STATUS2_OVR_LATCHED))
        return level, overrun

    def poll(self) -> DecodedSamples | None:
        """Read the FIFO level, then up to :attr:`max_burst_words` words in one burst."""
        if self.decoder is None:
            raise DeviceIOError(f"{self.label}: not configured")
        level, overrun = self.fifo_status()
        if overrun:
            self.decoder.mark_overrun()
        if level == 0:
            return None
        count = min(level, self.max_burst_words)
        data = self.read(reg.FIFO_DATA_OUT_TAG, count * reg.FIFO_WORD_BYTES)
        decoded = self.decoder.decode(data)
        if self.settling_left and len(decoded):
            drop = min(self.settling_left, len(decoded))
            decoded = decoded.tail(drop)
            self.settling_left -= drop
            self.settling_dropped += drop
        return decoded if len(decoded) else None

    # -- self-test --------------------------------------------------------------------------------
    def self_test(self) -> SelfTestResult:
        """ST's self-test procedure through CTRL5_C; leaves both sensors off and the FIFO empty.

        Accelerometer at 52 Hz, +-4 g: wait 100 ms, drop one sample, average five; enable the
        positive self-test; wait 100 ms, drop one, average five; the change per axis must lie in
        50-1700 mg. Gyroscope likewise at 208 Hz, +-2000 dps, window 150-700 dps. The sensor
        must lie still: motion between the two averages reads as output change. Call
        :meth:`configure` afterwards to stream again.
        """
        self.write(reg.FIFO_CTRL4, reg.FIFO_MODE_BYPASS)
        self.write(reg.CTRL2_G, 0)
        self.write(reg.CTRL3_C, reg.CTRL3_C_BDU | reg.CTRL3_C_IF_INC)
        self.write(reg.CTRL5_C, 0)
        accel_fs = reg.SELF_TEST_ACCEL_FS_G
        self.write(reg.CTRL1_XL, reg.ctrl1_xl_value(reg.SELF_TEST_ACCEL_ODR_CODE, accel_fs))
        accel_lsb = self._self_test_delta(
            reg.STATUS_XLDA, reg.OUTX_L_A, reg.CTRL5_C_ST_XL_POSITIVE, reg.SELF_TEST_ACCEL_ODR_CODE
        )
        self.write(reg.CTRL1_XL, 0)
        gyro_fs = reg.SELF_TEST_GYRO_FS_DPS
        self.write(reg.CTRL2_G, reg.ctrl2_g_value(reg.SELF_TEST_GYRO_ODR_CODE, gyro_fs))
        gyro_lsb = self._self_test_delta(
            reg.STATUS_GDA, reg.OUTX_L_G, reg.CTRL5_C_ST_G_POSITIVE, reg.SELF_TEST_GYRO_ODR_CODE
        )
        self.write(reg.CTRL2_G, 0)
        self.settings = None
        self.decoder = None
        accel_mg = accel_lsb * lsm6dsox.ACCEL_MG_PER_LSB[accel_fs]
        gyro_dps = gyro_lsb * lsm6dsox.GYRO_MDPS_PER_LSB[gyro_fs] * 1e-3
        low_a, high_a = reg.SELF_TEST_ACCEL_WINDOW_MG
        low_g, high_g = reg.SELF_TEST_GYRO_WINDOW_DPS
        return SelfTestResult(
            accel_pass=bool(np.all((accel_mg >= low_a) & (accel_mg <= high_a))),
            gyro_pass=bool(np.all((gyro_dps >= low_g) & (gyro_dps <= high_g))),
            accel_delta_mg=tuple(float(v) for v in accel_mg),  # type: ignore[arg-type]
            gyro_delta_dps=tuple(float(v) for v in gyro_dps),  # type: ignore[arg-type]
        )

    def _self_test_delta(
        self, ready_bit: int, out_register: int, enable_value: int, odr_code: int
    ) -> np.ndarray:
        """|mean with self-test - mean without| per axis, in LSB."""
        period_s = 1.0 / lsm6dsox.ODR_RATES_HZ[odr_code]
        self.bus.delay(reg.SELF_TEST_SETTLE_S)
        off = self._average(ready_bit, out_register, period_s)
        self.write(reg.CTRL5_C, enable_value)
        self.bus.delay(reg.SELF_TEST_SETTLE_S)
        on = self._average(ready_bit, out_register, period_s)
        self.write(reg.CTRL5_C, 0)
        return np.abs(on - off)

    def _average(self, ready_bit: int, out_register: int, period_s: float) -> np.ndarray:
        """Drop the first new sample, then average the next :data:`SELF_TEST_SAMPLES`."""
        samples = [self._next_sample(ready_bit, out_register, period_s)
                   for _ in range(reg.SELF_TEST_SAMPLES + 1)]
        return np.mean(samples[1:], axis=0)

    def _next_sample(self, ready_bit: int, out_register: int, period_s: float) -> np.ndarray:
        deadline = self.bus.monotonic() + 10.0 * period_s + 0.05
        while not self.read(reg.STATUS_REG)[0] & ready_bit:
            if self.bus.monotonic() > deadline:
                raise DeviceIOError(
                    f"{self.label}: no new data during the self-test (STATUS_REG 0x1E bit "
                    f"{ready_bit.bit_length() - 1} stayed 0)"
                )
            self.bus.delay(period_s / 4.0)
        return np.frombuffer(self.read(out_register, 6), dtype="<i2").astype(np.float64)
