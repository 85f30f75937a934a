"""An emulated NUCLEO board: the simulator served over a pseudo-terminal in protocol v1.

The far end of a pseudo-terminal pair behaves as the firmware would (``docs/protocol.md``):
it answers HELLO, CONFIGURE, START, STOP, SELF_TEST and PING, streams SAMPLES of up to 32
samples with ``seq`` and ``t0`` in ticks of the simulated chip's trimmed 25 us clock, refuses
output data rates the serial link could not carry at its baud rate, and sends LOG messages.
Its port is an ordinary device path (``/dev/pts/N``), so the real serial driver opens it.

    board = EmulatedNucleo("wobble", odr_hz=208, seed=3)
    device = create_device(board.port)          # protocol v1 detected
    ...
    board.close()                               # the cable is pulled
    new_port = board.replug()                   # back on another port, same ids

The board registers its port with the USB identity of an ST-LINK/V2-1 (0483:374B) and a serial
number derived from the seed, so discovery and reconnect-by-USB-serial treat it as a real one.
Pseudo-terminals need Linux or macOS.

Turn-on transient: the simulated chip is opened with ``settling=1`` (its first samples after
power-on or CONFIGURE are wrong, :mod:`drivers.sim.transient`), and the board drops
:func:`drivers.lsm6dsox.turn_on_discard` samples before any packet, as the firmware does.

Two sensors (``sensors=2``, firmware 1.1.0): a second simulated LSM6DSOX "at 0x6B" with its
own unit (seed + 1000: its own errors, trim and noise) and the same scenario, streamed as
SAMPLES_INDEXED (sensor 1) with its own sequence numbers and clock, and described by SENSOR
packets after CONFIG (docs/protocol.md, "Several sensors on one board"). The two simulators
are independent: the motion is the same scenario, drawn per unit, not one rigid body. A rate
that fits one sensor but not two streams sensor 0 alone: sensor 1 is paused (its SENSOR says
so, a LOG says why), as the firmware does. Faults (drops, overruns, cuts) touch sensor 0 only.

A magnetometer (``mag="lis3mdl"`` or ``"lis2mdl"``, docs/protocol.md "A magnetometer beside
the sensor"): the board describes it in MAGNETOMETER after CONFIG and streams its field samples
in MAG_SAMPLES at the chip's rate for the accelerometer's (:meth:`ChipSpec.rate_for`), each
timed in sensor 0's ticks on the accelerometer row it was taken with, and sent before the
SAMPLES packet that holds that row. The field is the simulator's magnetometer
(``sim://...&mag=lis3mdl|lis2mdl``, :mod:`drivers.sim.magnetometer`): the World Magnetic
Model's field at the simulator's place on :data:`MAG_FIELD_DATE`, seen in the true orientation
through the unit's hard and soft iron, its turn against the accelerometer and the datasheet
noise (``errors=False`` and ``noise=False`` switch them off, as for the accelerometer). Below
the chip's own rate the board takes every k-th of those samples, at the rate MAGNETOMETER
announces. A rate that
leaves no room for the field samples on the UART or the I2C bus pauses the magnetometer
(MAGNETOMETER flags bit 1 and a LOG), as the firmware does. STATUS is then version 2 (the
magnetometer's I2C errors and samples read).

Timing model: the board's clock runs with the wall clock from power-on (``initial_ticks`` at
power-on; it keeps running across an unplug unless :meth:`replug` is told ``power_cycle``).
Samples are produced at the simulated chip's true rate and sent every ``packet_interval_s``
(or as soon as 32 are waiting). Output the host does not read piles up to
:data:`TX_BUFFER_BYTES`; beyond that SAMPLES packets are dropped, as a firmware's full transmit
ring would (the host sees sequence gaps).
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import hashlib
import logging
import math
import os
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from cobs import cobs

from app.core.samples import RawBlock
from drivers import lsm6dsox, magnetometers
from drivers.link import protocol as p
from drivers.link.framing import FrameError, FrameSplitter, crc16, encode_packet, unframe
from drivers.link.ports import (
    SerialPortInfo,
    register_virtual_port,
    unregister_virtual_port,
)
from drivers.sim.device import SimulatedDevice
from drivers.sim.error_model import unique_id_for_seed

log = logging.getLogger(__name__)

FIRMWARE_VERSION = (1, 2, 0)
USB_VID = 0x0483
USB_PID = 0x374B
TX_BUFFER_BYTES = 16 * 1024
"""The emulated firmware's transmit ring: SAMPLES are dropped when this much is unsent."""
SIM_BLOCK = 256
PACKET_INTERVAL_S = 0.005
STATUS_INTERVAL_S = 1.0
"""STATUS while streaming, as the firmware (FW_STATUS_INTERVAL_US)."""
SELF_TEST_ACCEL_WINDOW_MG = (50, 1700)
SELF_TEST_GYRO_WINDOW_DPS = (20, 80)
"""Self-test output change windows at +-250 dps (LSM6DSO datasheet, same family)."""


def link_bytes_per_sample(samples_per_packet: int = p.MAX_SAMPLES_PER_PACKET,
                          *, indexed: bool = False) -> float:
    """Bytes on the wire per sample when packets carry ``samples_per_packet`` samples.

    Type byte, SAMPLES header (plus the sensor index in SAMPLES_INDEXED), 12 bytes per
    sample and the CRC, plus the COBS overhead (one byte, and one more per 254) and the 0x00
    delimiter.
    """
    packet = (1 + int(indexed) + p.SAMPLES_HEADER_BYTES + p.SAMPLE_BYTES * samples_per_packet
              + 2)
    encoded = cobs.max_encoded_length(packet) + 1
    return encoded / samples_per_packet


def link_capacity_bytes_s(baud: int) -> float:
    """Bytes per second an 8N1 UART carries: 10 bits per byte."""
    return baud / 10.0


def link_bytes_per_odr_sample(sensors: int = 1) -> float:
    """Wire bytes per sample period with ``sensors`` sensors (sensor 1.. in SAMPLES_INDEXED)."""
    return link_bytes_per_sample() + (sensors - 1) * link_bytes_per_sample(indexed=True)


def odr_fits_link(odr_hz: float, baud: int | None, sensors: int = 1) -> bool:
    """True when full SAMPLES packets at ``odr_hz`` fit the link (always on native USB)."""
    return baud is None or (odr_hz * link_bytes_per_odr_sample(sensors)
                            <= link_capacity_bytes_s(baud))


# The firmware's rule for the sensor bus (firmware/core/firmware.c, fw_rate_fits): per sample a
# gyroscope and an accelerometer FIFO word and a timestamp word every 8th, temperature words at
# 12.5 Hz, 7 bytes of 9 bits each, plus 80 bits for each of its 500 polls a second; it plans on
# 80 % of the bus clock.
_FIFO_WORDS_PER_SAMPLE = 2.0 + 1.0 / 8.0
_TEMPERATURE_WORDS_S = 12.5
_BITS_PER_FIFO_WORD = 7 * 9
_POLL_BITS_S = 80 * 500
_BUS_USABLE = 0.8


def sensor_bus_bits_s(odr_hz: float, sensors: int = 1) -> float:
    """Bits per second the firmware moves over I2C to drain ``sensors`` FIFOs at ``odr_hz``."""
    words_s = odr_hz * _FIFO_WORDS_PER_SAMPLE + _TEMPERATURE_WORDS_S
    return sensors * (words_s * _BITS_PER_FIFO_WORD + _POLL_BITS_S)


def odr_fits_sensor_bus(odr_hz: float, bus_hz: int | None, sensors: int = 1) -> bool:
    """True when the firmware can drain the FIFOs at ``odr_hz`` over I2C at ``bus_hz``."""
    return bus_hz is None or sensor_bus_bits_s(odr_hz, sensors) <= _BUS_USABLE * bus_hz


# The firmware's rule for the magnetometer (firmware/core/firmware.c, fw_mag_fits): per field
# sample up to three burst reads of STATUS..OUT_Z (10 bytes of 9 bits: address, register,
# address, 7 data) and one read of the LSM6DSOX's TIMESTAMP0..3 (7 bytes); on the UART a
# MAG_SAMPLES packet of one sample, 18 bytes with COBS and the 0x00.
MAG_BUS_BITS_PER_SAMPLE = 3 * 10 * 9 + 7 * 9
MAG_LINK_BYTES_PER_SAMPLE = 1 + p.MAG_SAMPLES_HEADER_BYTES + p.MAG_SAMPLE_BYTES + 2 + 2


def mag_fits(odr_hz: float, mag_hz: float, baud: int | None, bus_hz: int | None,
             sensors: int = 1) -> bool:
    """True when the accelerometer's stream at ``odr_hz`` leaves room for the field samples
    at ``mag_hz`` on the UART and the sensor's I2C bus (None: no limit)."""
    link_ok = baud is None or (odr_hz * link_bytes_per_odr_sample(sensors)
                               + mag_hz * MAG_LINK_BYTES_PER_SAMPLE
                               <= link_capacity_bytes_s(baud))
    bus_ok = bus_hz is None or (sensor_bus_bits_s(odr_hz, sensors)
                                + mag_hz * MAG_BUS_BITS_PER_SAMPLE <= _BUS_USABLE * bus_hz)
    return link_ok and bus_ok


MAG_FIELD_DATE = dt.date(2026, 7, 2)
"""The date of the WMM field the emulated magnetometer sees (fixed: recordings repeat)."""


def usb_serial_for_seed(seed: int) -> str:
    """A 24-digit hex USB serial number, stable per seed (like an ST-LINK's)."""
    digest = hashlib.blake2b(f"emulated-stlink:{seed}".encode(), digest_size=9).hexdigest()
    return "0670FF" + digest.upper()


@dataclass(frozen=True, slots=True)
class NucleoFaults:
    """Faults to inject (tests). Sequence numbers count every SAMPLES packet, sent or not."""

    drop_seqs: frozenset[int] = frozenset()
    """SAMPLES packets with these sequence numbers are not sent."""
    corrupt_seqs: frozenset[int] = frozenset()
    """SAMPLES packets with these sequence numbers get one sample byte flipped (bad CRC)."""
    drop_probability: float = 0.0
    corrupt_probability: float = 0.0
    overrun_seqs: frozenset[int] = frozenset()
    """The samples of these SAMPLES packets are lost in a sensor FIFO overrun: never read, not
    sent, counted in STATUS (``fifo_overruns``) and told in a LOG, as the firmware does."""
    cut_seqs: frozenset[int] = frozenset()
    """These SAMPLES frames lose bytes from their middle after the board sent them, as inside
    the ST-LINK's USB bridge (no flow control): the host sees corrupt frames, the board's
    counters see nothing."""
    i2c_retry_seqs: frozenset[int] = frozenset()
    """Reading these packets' samples needed one I2C retry (counted in STATUS)."""
    self_test_fails: bool = False
    seed: int = 0


@dataclass(slots=True)
class NucleoStats:
    """What the emulated board did (read after :meth:`EmulatedNucleo.close`, or loosely live)."""

    commands: int = 0
    bad_frames: int = 0
    packets_sent: int = 0
    samples_sent: int = 0
    packets_dropped: int = 0
    samples_dropped: int = 0
    packets_corrupted: int = 0
    settling_discarded: int = 0
    """Samples of the simulated chip's turn-on transient dropped before any packet."""
    packets_cut: int = 0
    tx_dropped_bytes: int = 0
    """Wire bytes of packets dropped because the transmit buffer was full (or injected)."""
    fifo_overruns: int = 0
    samples_read: int = 0
    """Samples read out of the (simulated) sensor: sent, or dropped by the transmit buffer."""
    i2c_errors: int = 0
    i2c_retries: int = 0
    status_sent: int = 0
    mag_samples_read: int = 0
    """Field samples the magnetometer delivered (sent in MAG_SAMPLES)."""
    mag_i2c_errors: int = 0


class EmulatedNucleo:
    """The simulated LSM6DSOX behind a NUCLEO firmware, on a pseudo-terminal.

    Parameters
    ----------
    scenario : simulator scenario (see :data:`drivers.sim.SCENARIOS`).
    odr_hz, accel_fs_g, gyro_fs_dps : settings at power-on (CONFIGURE changes them).
    seed : picks the simulated unit: its errors, unique id and USB serial number.
    baud : the UART's baud rate, used to refuse rates the link cannot carry; None for native
        USB (no limit). A pseudo-terminal itself has no speed.
    sensor_bus_hz : the I2C clock the firmware reads the sensor at, used to refuse rates it
        cannot drain (the NUCLEO firmware: 400 000, up to 1667 Hz); None for no limit.
    errors, noise : as the simulator's options.
    who_am_i : what INFO reports (another value tests the host's check).
    faults : fault injection.
    packet_interval_s : longest wait before waiting samples are sent.
    initial_ticks : the board clock at power-on (near 2**32 to test the wrap).
    on_packet_sent : called in the board's thread as ``f(seq, first_sample, count, t_write)``
        right after a SAMPLES packet was written (``time.perf_counter()``).
    scenario_params : the scenario's own options.
    share_port : announce the port to other processes of this user too (for
        ``inclinometer simulate``), not only to this one.
    sends_status : False acts as firmware before the STATUS extension: no STATUS, and
        GET_STATUS is an unknown command.
    sensors : 1, or 2 for a second LSM6DSOX (see the module docstring).
    mag : ``"lis3mdl"``, ``"lis2mdl"`` or None: the magnetometer beside the sensor.
    """

    def __init__(
        self,
        scenario: str = "wobble",
        *,
        odr_hz: float = 104.0,
        accel_fs_g: int = 4,
        gyro_fs_dps: int = 250,
        seed: int = 1,
        baud: int | None = p.DEFAULT_BAUD,
        sensor_bus_hz: int | None = None,
        errors: bool = True,
        noise: bool = True,
        who_am_i: int = lsm6dsox.WHO_AM_I_VALUE,
        faults: NucleoFaults | None = None,
        packet_interval_s: float = PACKET_INTERVAL_S,
        initial_ticks: int = 0,
        on_packet_sent: Callable[[int, int, int, float], None] | None = None,
        scenario_params: dict[str, object] | None = None,
        share_port: bool = False,
        sends_status: bool = True,
        sensors: int = 1,
        mag: str | None = None,
    ) -> None:
        if sensors not in (1, 2):
            raise ValueError(f"sensors={sensors}: the NUCLEO board carries 1 or 2 LSM6DSOX")
        if mag is not None and mag.lower() not in magnetometers.CHIPS_BY_NAME:
            raise ValueError(f"mag={mag!r}: use lis3mdl, lis2mdl or none")
        self.mag = None if mag is None else magnetometers.CHIPS_BY_NAME[mag.lower()]
        self.sensors = sensors
        odr_code = lsm6dsox.odr_code_for(odr_hz)
        # The one-sensor rule: a rate that fits sensor 0 alone pauses sensor 1.
        if not odr_fits_link(lsm6dsox.ODR_RATES_HZ[odr_code], baud):
            raise ValueError(f"{odr_hz:g} Hz does not fit a {baud} baud link")
        if not odr_fits_sensor_bus(lsm6dsox.ODR_RATES_HZ[odr_code], sensor_bus_hz):
            raise ValueError(f"{odr_hz:g} Hz does not fit I2C at {sensor_bus_hz} Hz")
        self.scenario = scenario
        self.seed = seed
        self.baud = baud
        self.sensor_bus_hz = sensor_bus_hz
        self.errors = errors
        self.noise = noise
        self.who_am_i = who_am_i
        self.faults = faults or NucleoFaults()
        self.packet_interval_s = packet_interval_s
        self.initial_ticks = initial_ticks
        self.on_packet_sent = on_packet_sent
        self.scenario_params = dict(scenario_params or {})
        self.share_port = share_port
        self.sends_status = sends_status
        self.unique_id = bytes.fromhex(unique_id_for_seed(seed).removeprefix("SIM-"))
        self.usb_serial = usb_serial_for_seed(seed)
        self.stats = NucleoStats()
        self._fault_rng = np.random.default_rng(self.faults.seed)
        self._settings = (odr_code, accel_fs_g, gyro_fs_dps)
        self._lock = threading.Lock()
        self._outgoing: list[bytes] = []  # raw bytes other threads ask to send
        self._overrun_next = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._master = self._slave = -1
        self._wake_r = self._wake_w = -1
        self.port = ""
        self._power_on()
        self.replug()

    # -- the cable ------------------------------------------------------------------------------
    @property
    def is_plugged(self) -> bool:
        return self._thread is not None

    def close(self) -> None:
        """Pull the cable: the pseudo-terminal disappears (the host's reads fail)."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        self._stop.set()
        os.write(self._wake_w, b"x")
        thread.join()
        unregister_virtual_port(self.port)
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._master = self._slave = self._wake_r = self._wake_w = -1
        self._streaming = False

    def replug(self, *, power_cycle: bool = False) -> str:
        """Plug the cable in (again): a new pseudo-terminal, same unique id and USB serial.

        With ``power_cycle`` the board also restarts (clock, sequence numbers, motion).
        Returns the new port name.
        """
        import pty
        import tty

        self.close()
        if power_cycle:
            self._power_on()
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)  # no echo, no line editing before the host opens the port
        os.set_blocking(self._master, False)
        self._wake_r, self._wake_w = os.pipe()
        self.port = os.ttyname(self._slave)
        self._splitter = FrameSplitter()
        self._tx = bytearray()
        self._streaming = False
        register_virtual_port(
            SerialPortInfo(
                device=self.port, description="STM32 STLink (emulated NUCLEO)", vid=USB_VID,
                pid=USB_PID, serial_number=self.usb_serial, manufacturer="STMicroelectronics",
                product="STM32 STLink", emulated=True,
            ),
            shared=self.share_port,
        )
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name=f"nucleo {self.port}",
                                        daemon=True)
        self._thread.start()
        return self.port

    def __enter__(self) -> EmulatedNucleo:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- thread-safe controls -------------------------------------------------------------------
    def log(self, level: int, text: str) -> None:
        """Send a LOG message to the host."""
        self.inject(encode_packet(p.Log(level, text)))

    def inject(self, data: bytes) -> None:
        """Send raw bytes to the host (garbage, hand-made frames)."""
        with self._lock:
            self._outgoing.append(bytes(data))
        if self._thread is not None:
            os.write(self._wake_w, b"x")

    @property
    def streaming(self) -> bool:
        return self._streaming

    @property
    def config(self) -> p.Config:
        """The CONFIG the board would report now."""
        sim = self._sim
        freq_fine = sim.unit_errors.freq_fine
        odr_mhz = lsm6dsox.odr_mhz(self._settings[0], freq_fine)  # the real rate, trimmed
        return p.Config(odr_mhz, sim.options.accel_fs_g, sim.options.gyro_fs_dps,
                        lsm6dsox.tick_ns(freq_fine))

    def sensor_packets(self) -> list[p.Sensor]:
        """The SENSOR packets the board sends after CONFIG (none with one sensor)."""
        if self.sensors < 2:
            return []
        configs = [self.config, self._second.config]
        paused = p.SENSOR_FLAG_PAUSED if self.sensor1_paused else 0
        return [p.Sensor(index, self.sensors, address, self.who_am_i, config.odr_mhz,
                         config.accel_fs_g, config.gyro_fs_dps, config.tick_ns,
                         p.SENSOR_FLAG_ANSWERING | (paused if index else 0))
                for index, (address, config) in enumerate(zip((0x6A, 0x6B), configs,
                                                               strict=True))]

    def _fits_all(self, odr_code: int, *, link: bool = True, bus: bool = True) -> bool:
        odr = lsm6dsox.ODR_RATES_HZ[odr_code]
        return ((not link or odr_fits_link(odr, self.baud, self.sensors))
                and (not bus or odr_fits_sensor_bus(odr, self.sensor_bus_hz, self.sensors)))

    @property
    def sensor1_paused(self) -> bool:
        """The rate fits sensor 0 alone: sensor 1 is not streamed (as the firmware)."""
        return self.sensors > 1 and not self._fits_all(self._settings[0])

    def pause_message(self) -> str:
        """The firmware's LOG for a paused sensor 1 (empty while both stream)."""
        if not self.sensor1_paused:
            return ""
        code = self._settings[0]
        highest = max(c for c in lsm6dsox.ODR_LABELS_HZ if c == 1 or self._fits_all(c))
        where = (f"I2C {(self.sensor_bus_hz or 0) // 1000} kHz"
                 if not self._fits_all(code, link=False)
                 else f"the UART at {self.baud} baud")
        return (f"sensor 1 (0x6B) paused: {lsm6dsox.ODR_LABELS_HZ[code]:g} Hz does not fit "
                f"two sensors on {where} (highest {lsm6dsox.ODR_LABELS_HZ[highest]:g} Hz)")

    def _queue_sensors(self) -> None:
        """SENSOR packets after CONFIG, and the LOG when sensor 1 is paused."""
        for sensor in self.sensor_packets():
            self._queue(sensor)
        if self.sensor1_paused:
            self._queue(p.Log(1, self.pause_message()))

    @property
    def mag_rate_hz(self) -> float:
        """The magnetometer's rate for the accelerometer's current rate."""
        assert self.mag is not None
        return self.mag.rate_for(lsm6dsox.ODR_RATES_HZ[self._settings[0]])

    @property
    def mag_paused(self) -> bool:
        """The accelerometer's rate leaves no room for the field samples."""
        return self.mag is not None and not mag_fits(
            lsm6dsox.ODR_RATES_HZ[self._settings[0]], self.mag_rate_hz, self.baud,
            self.sensor_bus_hz, self.sensors if not self.sensor1_paused else 1)

    def magnetometer_packet(self) -> p.Magnetometer | None:
        """MAGNETOMETER as the board sends it after CONFIG (None without a magnetometer)."""
        mag = self.mag
        if mag is None:
            return None
        flags = p.MAG_FLAG_ANSWERING | (p.MAG_FLAG_PAUSED if self.mag_paused else 0)
        return p.Magnetometer(mag.code, mag.addresses[0], mag.who_am_i,
                              round(self.mag_rate_hz * 1000), mag.range_ut, mag.pt_per_lsb,
                              mag.mode, flags)

    def _queue_magnetometer(self) -> None:
        packet = self.magnetometer_packet()
        if packet is None:
            return
        self._queue(packet)
        if packet.paused:
            odr = lsm6dsox.ODR_RATES_HZ[self._settings[0]]
            self._queue(p.Log(1, f"magnetometer ({self.mag.name if self.mag else ''}) paused: "
                                 f"{lsm6dsox.odr_label_hz(odr):g} Hz leaves no room for its "
                                 f"{packet.odr_hz:g} Hz on the UART or I2C"))

    def status(self) -> p.Status:
        """The STATUS the board would send now (its counters since power-on)."""
        now, base = self.stats, self._status_base
        stats = NucleoStats(**{f.name: getattr(now, f.name) - getattr(base, f.name)
                               for f in dataclasses.fields(NucleoStats)})
        flags = p.STATUS_FLAG_SENSOR_OK | (p.STATUS_FLAG_STREAMING if self._streaming else 0)
        uptime_ms = round((time.monotonic() - self._power_on_wall) * 1000)
        return p.Status(
            p.STATUS_VERSION, 1, flags, uptime_ms & 0xFFFFFFFF,
            stats.tx_dropped_bytes & 0xFFFFFFFF, 0, stats.i2c_errors & 0xFFFFFFFF, 0,
            stats.i2c_retries & 0xFFFFFFFF, stats.fifo_overruns & 0xFFFFFFFF,
            stats.samples_read & 0xFFFFFFFF, stats.samples_sent & 0xFFFFFFFF, 0,
        ) if self.mag is None else p.Status(
            p.STATUS_VERSION_MAG, 1, flags, uptime_ms & 0xFFFFFFFF,
            stats.tx_dropped_bytes & 0xFFFFFFFF, 0, stats.i2c_errors & 0xFFFFFFFF, 0,
            stats.i2c_retries & 0xFFFFFFFF, stats.fifo_overruns & 0xFFFFFFFF,
            stats.samples_read & 0xFFFFFFFF, stats.samples_sent & 0xFFFFFFFF, 0,
            extra=p.Status.mag_extra(stats.mag_i2c_errors, stats.mag_samples_read),
        )

    def inject_fifo_overrun(self) -> None:
        """Lose the samples of the next SAMPLES packet to a sensor FIFO overrun (thread-safe)."""
        with self._lock:
            self._overrun_next = True

    @property
    def info(self) -> p.Info:
        name = f"NUCLEO-F746ZG emulated ({self.scenario}, seed {self.seed})"
        return p.Info(p.PROTOCOL_VERSION, FIRMWARE_VERSION, self.who_am_i, self.unique_id, name)

    def self_test_result(self) -> p.SelfTestResult:
        """What SELF_TEST reports: output changes drawn per unit, inside the datasheet windows."""
        rng = np.random.default_rng([self.seed, 0x5E1F])
        accel = tuple(int(v) for v in rng.uniform(250, 700, 3).round())
        gyro = tuple(int(v) for v in rng.uniform(35, 65, 3).round())
        if self.faults.self_test_fails:
            gyro = (2, 1, 3)
        accel_ok = all(SELF_TEST_ACCEL_WINDOW_MG[0] <= a <= SELF_TEST_ACCEL_WINDOW_MG[1]
                       for a in accel)
        gyro_ok = all(SELF_TEST_GYRO_WINDOW_DPS[0] <= g <= SELF_TEST_GYRO_WINDOW_DPS[1]
                      for g in gyro)
        return p.SelfTestResult(accel_ok, gyro_ok, accel, gyro)  # type: ignore[arg-type]

    # -- board state ----------------------------------------------------------------------------
    def _power_on(self) -> None:
        self._power_on_wall = time.monotonic()
        self._status_base = dataclasses.replace(self.stats)  # STATUS counts from power-on
        self._seq = 0
        self._last_end_ticks: float = self.initial_ticks
        self._sim = self._new_sim(*self._settings)
        self._pending: list[np.ndarray] = []  # generated, not yet sent: (n, 7) gx..az, temp
        self._pending_mag: list[np.ndarray] = []  # their field counts, NaN: no sample there
        self._mag_seq = 0
        self._mag_row = 0  # accelerometer rows of the run so far (places the field samples)
        self._taken_mag: np.ndarray | None = None
        self._run_sent = 0
        if self.sensors > 1:
            if getattr(self, "_second", None) is not None:
                self._second.sim.close()  # type: ignore[has-type]
            self._second = _SecondSensor(self)

    def _new_sim(self, odr_code: int, accel_fs_g: int, gyro_fs_dps: int,
                 seed: int | None = None) -> SimulatedDevice:
        seed = self.seed if seed is None else seed
        url = (f"sim://{self.scenario}?odr={lsm6dsox.ODR_LABELS_HZ[odr_code]:g}"
               f"&accel_fs={accel_fs_g}&gyro_fs={gyro_fs_dps}&seed={seed}&realtime=0"
               f"&block={SIM_BLOCK}&errors={int(self.errors)}&noise={int(self.noise)}"
               "&settling=1")
        if self.mag is not None and seed == self.seed:  # beside sensor 0 only
            url += f"&mag={self.mag.name.lower()}&date={MAG_FIELD_DATE.isoformat()}"
        sim = SimulatedDevice(url, **self.scenario_params)  # type: ignore[arg-type]
        sim.open()
        # The simulated chip starts with its turn-on transient; the firmware drops it, as
        # firmware/core does (fifo_stream_discard), before any packet.
        if seed == self.seed:
            self._settling_left = lsm6dsox.turn_on_discard(lsm6dsox.ODR_LABELS_HZ[odr_code])
        return sim

    def _board_ticks(self, now: float) -> int:
        tick_s = self.config.tick_s
        return self.initial_ticks + round((now - self._power_on_wall) / tick_s)

    # -- the serving thread ---------------------------------------------------------------------
    def _serve(self) -> None:
        try:
            self._serve_until_stopped()
        except Exception:  # a bug here must show, not leave the host waiting in silence
            log.exception("emulated NUCLEO on %s stopped", self.port)

    def _serve_until_stopped(self) -> None:
        next_send = math.inf
        while not self._stop.is_set():
            now = time.monotonic()
            if self._streaming:
                next_send = self._next_send_time(now)
            timeout = None if not self._streaming else max(0.0, next_send - now)
            if timeout is not None:
                timeout = min(timeout, 0.5)
            writers = [self._master] if self._tx else []
            try:
                readable, writable, _ = select.select(
                    [self._master, self._wake_r], writers, [], timeout
                )
            except (OSError, ValueError):
                return
            if self._wake_r in readable:
                with contextlib.suppress(OSError):
                    os.read(self._wake_r, 4096)
                if self._stop.is_set():
                    return
            with self._lock:
                outgoing, self._outgoing = self._outgoing, []
            for data in outgoing:
                self._tx += data
            if self._master in readable:
                try:
                    data = os.read(self._master, 4096)
                except BlockingIOError:
                    data = b""
                except OSError:
                    return
                for frame in self._splitter.feed(data):
                    self._on_frame(frame)
            if self._streaming and time.monotonic() >= next_send:
                self._send_samples(time.monotonic())
            if (self._streaming and self.sends_status
                    and time.monotonic() - self._last_status >= STATUS_INTERVAL_S):
                self._send_status()
            if self._tx or writable:
                self._flush_tx()

    def _flush_tx(self) -> None:
        if not self._tx:
            return
        try:
            written = os.write(self._master, self._tx)
        except BlockingIOError:
            return
        except OSError:
            self._tx.clear()
            return
        del self._tx[:written]

    def _queue(self, packet: p.Packet) -> None:
        self._tx += encode_packet(packet)

    def _send_status(self) -> None:
        """The periodic STATUS: never waits, dropped (and counted) when the buffer is full."""
        self._last_status = time.monotonic()
        frame = encode_packet(self.status())
        self.stats.status_sent += 1
        if len(self._tx) > TX_BUFFER_BYTES:
            self.stats.tx_dropped_bytes += len(frame)
            return
        self._tx += frame

    def _next_send_time(self, now: float) -> float:
        odr = self._sim.true_odr_hz
        first_due = self._run_start + self._run_sent / odr
        full_due = self._run_start + (self._run_sent + p.MAX_SAMPLES_PER_PACKET - 1) / odr
        return max(first_due, min(full_due, self._last_send + self.packet_interval_s))

    # -- commands -------------------------------------------------------------------------------
    def _on_frame(self, frame: bytes) -> None:
        try:
            body = unframe(frame)
        except FrameError:
            self.stats.bad_frames += 1  # the firmware ignores it; the host times out, retries
            return
        command = body[0]
        self.stats.commands += 1
        if command not in p.HOST_PACKET_TYPES or (
                command == p.GET_STATUS and not self.sends_status):
            self._queue(p.Ack(command, p.ACK_UNSUPPORTED, f"unknown command 0x{command:02X}"))
            return
        try:
            packet = p.parse_packet(command, body[1:])
        except p.PacketError as exc:
            self._queue(p.Ack(command, p.ACK_BAD_ARGUMENT, str(exc)))
            return
        if isinstance(packet, p.Hello):
            self._queue(self.info)
            self._queue(self.config)
            self._queue_sensors()
            self._queue_magnetometer()
        elif isinstance(packet, p.Configure):
            self._configure(packet)
        elif isinstance(packet, p.Start):
            if not self._streaming:
                self._start()
            self._queue(p.Ack(p.START, p.ACK_OK))
            config = self.config
            self._queue(p.Log(1, f"streaming at {lsm6dsox.odr_text(config.odr_hz)}, "
                                 f"+-{config.accel_fs_g} g, "
                                 f"+-{config.gyro_fs_dps} dps"
                                 + (" (sensor 1 at 0x6B paused: the rate does not fit two "
                                    "sensors)" if self.sensor1_paused else "")))
            if self.sends_status:
                self._last_status = time.monotonic()
                self.stats.status_sent += 1
                self._queue(self.status())
        elif isinstance(packet, p.Stop):
            self._streaming = False
            self._queue(p.Ack(p.STOP, p.ACK_OK))
        elif isinstance(packet, p.SelfTest):
            if self._streaming:
                self._queue(p.Ack(p.SELF_TEST, p.ACK_BUSY, "streaming; send STOP first"))
            else:
                self._queue(p.Ack(p.SELF_TEST, p.ACK_OK))
                self._queue(self.self_test_result())
        elif isinstance(packet, p.Ping):
            self._queue(p.Pong(packet.token))
        elif isinstance(packet, p.GetStatus):
            self.stats.status_sent += 1
            self._queue(self.status())

    def _configure(self, command: p.Configure) -> None:
        problem = ""
        if command.odr_code not in lsm6dsox.ODR_RATES_HZ:
            problem = f"odr_code {command.odr_code} is not 1..10"
        elif command.accel_fs_g not in lsm6dsox.ACCEL_MG_PER_LSB:
            problem = f"accel_fs_g {command.accel_fs_g} is not 2, 4, 8 or 16"
        elif command.gyro_fs_dps not in lsm6dsox.GYRO_MDPS_PER_LSB:
            problem = f"gyro_fs_dps {command.gyro_fs_dps} is not 125, 250, 500, 1000 or 2000"
        # The one-sensor rule (a rate that fits sensor 0 alone pauses sensor 1).
        elif not odr_fits_link(lsm6dsox.ODR_RATES_HZ[command.odr_code], self.baud):
            odr = lsm6dsox.ODR_RATES_HZ[command.odr_code]
            needed = odr * link_bytes_per_odr_sample()
            problem = (f"{lsm6dsox.odr_label_hz(odr):g} Hz needs {needed:,.0f} bytes/s; "
                       f"{self.baud} baud carries {link_capacity_bytes_s(self.baud or 0):,.0f}")
        elif not odr_fits_sensor_bus(lsm6dsox.ODR_RATES_HZ[command.odr_code],
                                     self.sensor_bus_hz):
            odr = lsm6dsox.ODR_RATES_HZ[command.odr_code]
            bus_hz = self.sensor_bus_hz or 0
            problem = (f"ODR {lsm6dsox.odr_label_hz(odr):g} Hz needs about "
                       f"{sensor_bus_bits_s(odr) / 1e3:.0f} kbit/s on I2C1"
                       f"; the bus at {bus_hz / 1e3:g} kHz carries about "
                       f"{_BUS_USABLE * bus_hz / 1e3:.0f}")
        if problem:
            self._queue(p.Ack(p.CONFIGURE, p.ACK_BAD_ARGUMENT, problem))
        elif self._streaming:
            self._queue(p.Ack(p.CONFIGURE, p.ACK_BUSY, "streaming; send STOP first"))
        else:
            self._settings = (command.odr_code, command.accel_fs_g, command.gyro_fs_dps)
            self._sim.close()
            self._sim = self._new_sim(*self._settings)
            self._pending = []
            self._pending_mag = []
            if self.sensors > 1:
                self._second.configure(self._settings)
            self._queue(p.Ack(p.CONFIGURE, p.ACK_OK))
        self._queue(self.config)
        self._queue_sensors()
        self._queue_magnetometer()

    def _start(self) -> None:
        now = time.monotonic()
        self._streaming = True
        self._run_start = now
        self._run_sent = 0
        self._last_send = now
        self._run_origin_ticks = max(self._board_ticks(now), math.ceil(self._last_end_ticks))
        self._last_status = now
        self._mag_row = 0
        if self.sensors > 1 and not self.sensor1_paused:
            self._second.start(now)

    # -- samples --------------------------------------------------------------------------------
    def _field_counts(self, raw: RawBlock) -> np.ndarray:
        """(n, 3) the magnetometer's counts on the simulator's rows, NaN where the chip took
        no sample: the simulator's magnetometer (same chip, same counts), thinned to the rate
        MAGNETOMETER announces when the accelerometer is slower than the chip."""
        mag = self.mag
        assert mag is not None
        if raw.mag_raw is None:
            raise RuntimeError("the simulator delivered no magnetometer")
        counts = np.array(raw.mag_raw, dtype=float)
        if abs(raw.scale.mag_ut_per_lsb / mag.ut_per_lsb - 1.0) > 1e-4:  # another sensitivity
            counts = np.clip(np.rint(counts * raw.scale.mag_ut_per_lsb / mag.ut_per_lsb),
                             -32768, 32767)
        if self.mag_rate_hz < mag.rates_hz[-1]:  # the chip runs slower for this rate
            rows = self._mag_row + np.arange(len(raw))
            ratio = self.mag_rate_hz / lsm6dsox.ODR_RATES_HZ[self._settings[0]]
            taken = np.floor(rows * ratio) != np.floor((rows - 1) * ratio)
            counts[~taken] = np.nan
        return counts

    def _take_samples(self, count: int) -> np.ndarray:
        rows: list[np.ndarray] = []
        mags: list[np.ndarray] = []
        have = 0
        while have < count:
            if not self._pending:
                raw = self._sim.read(1.0)
                assert raw is not None
                block = np.empty((len(raw), 7), dtype=np.int16)
                block[:, 0:3] = raw.gyro_raw
                block[:, 3:6] = raw.accel_raw
                block[:, 6] = raw.temp_raw
                settling, self._settling_left = (min(self._settling_left, len(block)),
                                                 max(0, self._settling_left - len(block)))
                self.stats.settling_discarded += settling
                if settling == len(block):
                    continue
                self._pending = [block[settling:]]
                if self.mag is not None:
                    self._pending_mag = [self._field_counts(raw)[settling:]]
                    self._mag_row += len(raw)
            head = self._pending[0]
            take = min(count - have, len(head))
            rows.append(head[:take])
            if self.mag is not None:
                mags.append(self._pending_mag[0][:take])
            have += take
            if take == len(head):
                self._pending.pop(0)
                if self.mag is not None:
                    self._pending_mag.pop(0)
            else:
                self._pending[0] = head[take:]
                if self.mag is not None:
                    self._pending_mag[0] = self._pending_mag[0][take:]
        self._taken_mag = np.concatenate(mags) if mags else None
        return np.concatenate(rows)

    def _send_mag(self, counts: np.ndarray, t0: int, ticks_per_sample: float) -> None:
        """MAG_SAMPLES for the field samples on the rows of one SAMPLES packet (sent before
        it, as the firmware's are: it reads the field as it comes, the FIFO every 2 ms)."""
        if self.mag is None or self.mag_paused:
            return
        rows = np.flatnonzero(~np.isnan(counts[:, 0]))
        for first in range(0, len(rows), p.MAX_MAG_SAMPLES_PER_PACKET):
            chunk = rows[first:first + p.MAX_MAG_SAMPLES_PER_PACKET]
            ticks = (t0 + np.rint(chunk * ticks_per_sample).astype(np.int64)) & 0xFFFFFFFF
            self._queue(p.MagSamples(self._mag_seq & 0xFFFF, ticks.astype(np.uint32),
                                     counts[chunk].astype(np.int16)))
            self._mag_seq += 1
            self.stats.mag_samples_read += len(chunk)

    def _send_samples(self, now: float) -> None:
        due = math.floor((now - self._run_start) * self._sim.true_odr_hz) + 1 - self._run_sent
        if due <= 0:
            return
        # The chip's own clock places t0: ticks of 25 us / trim per sample of 6666.67 Hz /
        # ODR_Coeff x trim (the trim cancels), whatever CONFIG says.
        real_hz = lsm6dsox.ODR_RATES_HZ[self._settings[0]]
        ticks_per_sample = 1.0 / (lsm6dsox.TIMESTAMP_TICK_S * real_hz)
        rows = self._take_samples(due)
        for first in range(0, due, p.MAX_SAMPLES_PER_PACKET):
            chunk = rows[first:first + p.MAX_SAMPLES_PER_PACKET]
            index = self._run_sent + first
            t0 = self._run_origin_ticks + round(index * ticks_per_sample)
            if self._taken_mag is not None:
                self._send_mag(self._taken_mag[first:first + p.MAX_SAMPLES_PER_PACKET], t0,
                               ticks_per_sample)
            self._send_packet(p.Samples(self._seq & 0xFFFF, t0 & 0xFFFFFFFF, int(chunk[0, 6]),
                                        chunk[:, 0:6]), index)
            self._last_end_ticks = t0 + len(chunk) * ticks_per_sample
            self._seq += 1
        self._run_sent += due
        self._last_send = now
        if self.sensors > 1 and not self.sensor1_paused:
            self._second.send_due(now)

    def _send_packet(self, packet: p.Samples, first_sample: int) -> None:
        stats, faults = self.stats, self.faults
        count = packet.count
        with self._lock:
            overrun, self._overrun_next = self._overrun_next, False
        if overrun or packet.seq in faults.overrun_seqs:
            # Lost inside the sensor: never read, the sequence number skipped, a LOG.
            stats.fifo_overruns += 1
            stats.packets_dropped += 1
            stats.samples_dropped += count
            self._queue(p.Log(2, "FIFO overrun: samples were lost before they could be read "
                                 "(the host sees a gap)"))
            return
        stats.samples_read += count
        if packet.seq in faults.i2c_retry_seqs:
            stats.i2c_errors += 1
            stats.i2c_retries += 1
        dropped = packet.seq in faults.drop_seqs or (
            faults.drop_probability > 0 and self._fault_rng.random() < faults.drop_probability
        )
        if dropped or len(self._tx) > TX_BUFFER_BYTES:
            stats.packets_dropped += 1
            stats.samples_dropped += count
            stats.tx_dropped_bytes += len(encode_packet(packet))
            return
        corrupt = packet.seq in faults.corrupt_seqs or (
            faults.corrupt_probability > 0
            and self._fault_rng.random() < faults.corrupt_probability
        )
        if corrupt:
            body = bytearray((p.SAMPLES,)) + packet.payload()
            body += crc16(bytes(body)).to_bytes(2, "little")
            body[1 + p.SAMPLES_HEADER_BYTES] ^= 0x55  # a sample byte: the CRC catches it
            self._tx += cobs.encode(bytes(body)) + b"\x00"
            stats.packets_corrupted += 1
        elif packet.seq in faults.cut_seqs:
            frame = encode_packet(packet)
            start = len(frame) // 3
            self._tx += frame[:start] + frame[start + max(1, len(frame) // 4):]
            stats.packets_cut += 1
        else:
            self._tx += encode_packet(packet)
        self._flush_tx()
        stats.packets_sent += 1
        stats.samples_sent += count
        if self.on_packet_sent is not None:
            self.on_packet_sent(packet.seq, first_sample, count, time.perf_counter())


class _SecondSensor:
    """Sensor 1 of a two-sensor board: its own simulated unit, sequence numbers and clock.

    Streamed as SAMPLES_INDEXED with index 1 at the moments the board sends sensor 0's
    packets; its samples share the board's transmit buffer (dropped whole when it is full).
    """

    SEED_OFFSET = 1000

    def __init__(self, board: EmulatedNucleo) -> None:
        self.board = board
        self.seed = board.seed + self.SEED_OFFSET
        self.seq = 0
        self.last_end_ticks = float(board.initial_ticks)
        self.run_start: float = 0.0
        self.run_sent = 0
        self.run_origin_ticks = 0
        self.configure(board._settings)

    def configure(self, settings: tuple[int, int, int]) -> None:
        if getattr(self, "sim", None) is not None:
            self.sim.close()  # type: ignore[has-type]
        self.odr_code = settings[0]
        self.sim = self.board._new_sim(*settings, seed=self.seed)
        self.pending: list[np.ndarray] = []
        self.settling_left = lsm6dsox.turn_on_discard(lsm6dsox.ODR_LABELS_HZ[self.odr_code])

    @property
    def config(self) -> p.Config:
        freq_fine = self.sim.unit_errors.freq_fine
        return p.Config(lsm6dsox.odr_mhz(self.odr_code, freq_fine), self.sim.options.accel_fs_g,
                        self.sim.options.gyro_fs_dps, lsm6dsox.tick_ns(freq_fine))

    def start(self, now: float) -> None:
        board = self.board
        self.run_start = now
        self.run_sent = 0
        ticks = board.initial_ticks + round((now - board._power_on_wall) / self.config.tick_s)
        self.run_origin_ticks = max(ticks, math.ceil(self.last_end_ticks))

    def _take(self, count: int) -> np.ndarray:
        rows: list[np.ndarray] = []
        have = 0
        while have < count:
            if not self.pending:
                raw = self.sim.read(1.0)
                assert raw is not None
                block = np.empty((len(raw), 7), dtype=np.int16)
                block[:, 0:3] = raw.gyro_raw
                block[:, 3:6] = raw.accel_raw
                block[:, 6] = raw.temp_raw
                settling = min(self.settling_left, len(block))
                self.settling_left -= settling
                self.board.stats.settling_discarded += settling
                if settling == len(block):
                    continue
                self.pending = [block[settling:]]
            head = self.pending[0]
            take = min(count - have, len(head))
            rows.append(head[:take])
            have += take
            if take == len(head):
                self.pending.pop(0)
            else:
                self.pending[0] = head[take:]
        return np.concatenate(rows)

    def send_due(self, now: float) -> None:
        due = math.floor((now - self.run_start) * self.sim.true_odr_hz) + 1 - self.run_sent
        if due <= 0:
            return
        board, stats = self.board, self.board.stats
        ticks_per_sample = 1.0 / (lsm6dsox.TIMESTAMP_TICK_S
                                  * lsm6dsox.ODR_RATES_HZ[self.odr_code])
        rows = self._take(due)
        for first in range(0, due, p.MAX_SAMPLES_PER_PACKET):
            chunk = rows[first:first + p.MAX_SAMPLES_PER_PACKET]
            t0 = self.run_origin_ticks + round((self.run_sent + first) * ticks_per_sample)
            packet = p.SamplesIndexed(1, p.Samples(self.seq & 0xFFFF, t0 & 0xFFFFFFFF,
                                                   int(chunk[0, 6]), chunk[:, 0:6]))
            self.last_end_ticks = t0 + len(chunk) * ticks_per_sample
            self.seq += 1
            frame = encode_packet(packet)
            stats.samples_read += len(chunk)
            if len(board._tx) > TX_BUFFER_BYTES:
                stats.packets_dropped += 1
                stats.samples_dropped += len(chunk)
                stats.tx_dropped_bytes += len(frame)
                continue
            board._tx += frame
            stats.packets_sent += 1
            stats.samples_sent += len(chunk)
        self.run_sent += due
