"""The firmware's portable core, built for this machine and driven from Python (ctypes).

The core (``firmware/core``) runs unchanged; only the board layer is replaced: I2C transfers go
to an :class:`~drivers.lsm6dsox_direct.bus.I2CBus` (the emulated LSM6DSOX, or a test's fake),
the microsecond clock is the bus's clock (virtual time in tests), and what the firmware
transmits is collected as bytes. So the host tests exercise the firmware's own COBS, CRC,
packet encoder, command handling, LSM6DSOX sequence and FIFO streaming against the Python
decoder and the emulated chip.

    lib = build_library(tmp_dir)                  # make -C firmware host BUILD=tmp_dir
    chip = EmulatedLsm6dsox(SimOptions("wobble"), clock=VirtualClock())
    board = FirmwareCore(lib, chip)
    board.send(Hello())
    packets = board.packets()                     # INFO, CONFIG

:class:`PtyBoard` serves the core on a pseudo-terminal in real time, so the app connects to
the firmware exactly as to a NUCLEO (``python firmware/host/serve.py``).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from drivers.errors import DeviceIOError
from drivers.link import protocol as p
from drivers.link.framing import FrameSplitter, encode_packet, unframe
from drivers.lsm6dsox_direct.bus import I2CBus

FIRMWARE_DIR = Path(__file__).resolve().parents[1]
COUNTER_NAMES = (
    "commands", "bus_errors", "tx_dropped_packets", "words", "unknown_tags", "incomplete_slots",
    "lost_slots", "overruns", "samples", "packets", "dropped_packets", "rx_frames",
    "rx_bad_frames", "settling", "tx_dropped_bytes", "i2c_errors", "i2c_retries",
    "samples_sent", "status_sent", "mag_i2c_errors", "mag_samples_read", "mag_samples_sent",
    "mag_overruns",
)
LED_IDLE, LED_STREAMING, LED_ERROR = 0, 1, 2
POLL_INTERVAL_S = 0.002
"""How often the firmware polls the FIFO (FW_POLL_INTERVAL_US)."""
TX_BUFFER_BYTES = 16 * 1024
"""The NUCLEO board layer's UART transmit ring."""

_I2C_WRITE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint8, ctypes.c_uint8,
                              ctypes.POINTER(ctypes.c_uint8), ctypes.c_size_t)
_I2C_READ = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint8, ctypes.c_uint8,
                             ctypes.POINTER(ctypes.c_uint8), ctypes.c_size_t)
_MICROS = ctypes.CFUNCTYPE(ctypes.c_uint32)
_DELAY = ctypes.CFUNCTYPE(None, ctypes.c_uint32)
_TX = ctypes.CFUNCTYPE(None, ctypes.POINTER(ctypes.c_uint8), ctypes.c_size_t)


class _LinkInfo(ctypes.Structure):
    _fields_ = (("firmware", ctypes.c_uint8 * 3), ("who_am_i", ctypes.c_uint8),
                ("unique_id", ctypes.c_uint8 * 12), ("name", ctypes.c_char_p))


class _LinkConfig(ctypes.Structure):
    _fields_ = (("odr_mhz", ctypes.c_uint32), ("accel_fs_g", ctypes.c_uint8),
                ("gyro_fs_dps", ctypes.c_uint16), ("tick_ns", ctypes.c_uint32))


class _LinkSensor(ctypes.Structure):
    _fields_ = (("index", ctypes.c_uint8), ("count", ctypes.c_uint8),
                ("address", ctypes.c_uint8), ("who_am_i", ctypes.c_uint8),
                ("config", _LinkConfig), ("flags", ctypes.c_uint8))


class _LinkSelfTest(ctypes.Structure):
    _fields_ = (("accel_pass", ctypes.c_uint8), ("gyro_pass", ctypes.c_uint8),
                ("accel_delta_mg", ctypes.c_int16 * 3), ("gyro_delta_dps", ctypes.c_int16 * 3))


class _LinkStatus(ctypes.Structure):
    _fields_ = (("reset_cause", ctypes.c_uint8), ("flags", ctypes.c_uint8),
                *((name, ctypes.c_uint32) for name in p.Status.COUNTERS),
                ("version", ctypes.c_uint8), ("mag_i2c_errors", ctypes.c_uint32),
                ("mag_samples_read", ctypes.c_uint32), ("mag_overruns", ctypes.c_uint32))


class _LinkMagnetometer(ctypes.Structure):
    _fields_ = [("chip", ctypes.c_uint8), ("address", ctypes.c_uint8),
                ("who_am_i", ctypes.c_uint8), ("odr_mhz", ctypes.c_uint32),
                ("range_ut", ctypes.c_uint16), ("pt_per_lsb", ctypes.c_uint32),
                ("mode", ctypes.c_uint8), ("flags", ctypes.c_uint8)]


class BuildError(RuntimeError):
    """The host build failed or no C compiler is installed."""


def build_library(build_dir: Path) -> ctypes.CDLL:
    """``make -C firmware host BUILD=build_dir`` and load ``libfwcore.so`` with its signatures."""
    if shutil.which(os.environ.get("CC", "cc")) is None and shutil.which("gcc") is None:
        raise BuildError(
            "the firmware host tests need a C compiler: install gcc (Debian/Ubuntu: "
            "apt-get install build-essential)"
        )
    result = subprocess.run(
        ["make", "-C", str(FIRMWARE_DIR), "host", f"BUILD={build_dir}"],
        capture_output=True, text=True, check=False,
    )
    if result.returncode != 0:
        raise BuildError(f"make host failed:\n{result.stdout}\n{result.stderr}")
    lib = ctypes.CDLL(str(Path(build_dir) / "host" / "libfwcore.so"))
    _declare(lib)
    return lib


def _declare(lib: ctypes.CDLL) -> None:
    u8p = ctypes.POINTER(ctypes.c_uint8)
    size = ctypes.c_size_t
    lib.fwh_create.restype = ctypes.c_void_p
    lib.fwh_create.argtypes = [_I2C_WRITE, _I2C_READ, _MICROS, _DELAY, _TX, ctypes.c_char_p,
                               ctypes.c_char_p, ctypes.c_uint32, ctypes.c_uint32]
    lib.fwh_destroy.argtypes = [ctypes.c_void_p]
    lib.fwh_set_tx_free.argtypes = [ctypes.c_void_p, size]
    lib.fwh_receive.argtypes = [ctypes.c_void_p, ctypes.c_char_p, size]
    lib.fwh_set_board_health.argtypes = [ctypes.c_void_p, *[ctypes.c_uint32] * 4,
                                         ctypes.c_uint8, ctypes.c_int]
    lib.fwh_poll.argtypes = [ctypes.c_void_p]
    lib.fwh_led_mode.argtypes = [ctypes.c_void_p]
    lib.fwh_led_lit.argtypes = [ctypes.c_int, ctypes.c_uint32]
    lib.fwh_streaming.argtypes = [ctypes.c_void_p]
    lib.fwh_counters.restype = size
    lib.fwh_counters.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint32), size]
    lib.crc16.restype = ctypes.c_uint16
    lib.crc16.argtypes = [ctypes.c_char_p, size]
    lib.cobs_encode.restype = size
    lib.cobs_encode.argtypes = [ctypes.c_char_p, size, u8p]
    lib.cobs_decode.restype = ctypes.c_int
    lib.cobs_decode.argtypes = [ctypes.c_char_p, size, u8p, size]
    lib.fwh_rx_create.restype = ctypes.c_void_p
    lib.fwh_rx_destroy.argtypes = [ctypes.c_void_p]
    lib.fwh_rx_next.restype = size
    lib.fwh_rx_next.argtypes = [ctypes.c_void_p, ctypes.c_char_p, size,
                                ctypes.POINTER(size), u8p]
    lib.fwh_rx_bad_frames.restype = ctypes.c_uint32
    lib.fwh_rx_bad_frames.argtypes = [ctypes.c_void_p]
    wire = ctypes.POINTER(ctypes.c_uint8)
    lib.link_encode_info.restype = size
    lib.link_encode_info.argtypes = [ctypes.POINTER(_LinkInfo), wire]
    lib.link_encode_config.restype = size
    lib.link_encode_config.argtypes = [ctypes.POINTER(_LinkConfig), wire]
    lib.link_encode_samples.restype = size
    lib.link_encode_samples.argtypes = [ctypes.c_uint16, ctypes.c_uint32, ctypes.c_int16,
                                        ctypes.POINTER(ctypes.c_int16), ctypes.c_uint8, wire]
    lib.link_encode_samples_indexed.restype = size
    lib.link_encode_samples_indexed.argtypes = [
        ctypes.c_uint8, ctypes.c_uint16, ctypes.c_uint32, ctypes.c_int16,
        ctypes.POINTER(ctypes.c_int16), ctypes.c_uint8, wire]
    lib.link_encode_sensor.restype = size
    lib.link_encode_sensor.argtypes = [ctypes.POINTER(_LinkSensor), wire]
    lib.fwh_sensor_count.restype = ctypes.c_int
    lib.fwh_sensor_count.argtypes = [ctypes.c_void_p]
    lib.fw_rate_fits_sensors.restype = ctypes.c_bool
    lib.fw_rate_fits_sensors.argtypes = [ctypes.c_uint8, ctypes.c_uint32, ctypes.c_uint32,
                                         ctypes.c_uint8, ctypes.c_char_p, size]
    lib.link_encode_ack.restype = size
    lib.link_encode_ack.argtypes = [ctypes.c_uint8, ctypes.c_uint8, ctypes.c_char_p, wire]
    lib.link_encode_selftest.restype = size
    lib.link_encode_selftest.argtypes = [ctypes.POINTER(_LinkSelfTest), wire]
    lib.link_encode_log.restype = size
    lib.link_encode_log.argtypes = [ctypes.c_uint8, ctypes.c_char_p, wire]
    lib.link_encode_pong.restype = size
    lib.link_encode_pong.argtypes = [ctypes.c_uint32, wire]
    lib.link_encode_status.restype = size
    lib.link_encode_status.argtypes = [ctypes.POINTER(_LinkStatus), wire]
    lib.link_encode_magnetometer.restype = size
    lib.link_encode_magnetometer.argtypes = [ctypes.POINTER(_LinkMagnetometer), wire]
    lib.link_encode_mag_samples.restype = size
    lib.link_encode_mag_samples.argtypes = [ctypes.c_uint16, ctypes.POINTER(ctypes.c_uint32),
                                            ctypes.POINTER(ctypes.c_int16), ctypes.c_uint8, wire]
    lib.fwh_magnetometer.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint32)]
    lib.fw_mag_fits.restype = ctypes.c_bool
    lib.fw_mag_fits.argtypes = [ctypes.c_uint8, ctypes.c_uint32, ctypes.c_uint32,
                                ctypes.c_uint8, ctypes.c_uint32]
    lib.fw_rate_fits.restype = ctypes.c_bool
    lib.fw_rate_fits.argtypes = [ctypes.c_uint8, ctypes.c_uint32, ctypes.c_uint32,
                                 ctypes.c_char_p, size]


def rate_fits(lib: ctypes.CDLL, odr_code: int, baud: int, i2c_hz: int) -> tuple[bool, str]:
    """The firmware's verdict on an ODR code for a link, and its reason when it refuses."""
    why = ctypes.create_string_buffer(160)
    fits = lib.fw_rate_fits(odr_code, baud, i2c_hz, why, len(why))
    return bool(fits), why.value.decode()


class ForwardingBus(I2CBus):
    """An I2C bus that hands every transfer to ``inner``: subclass it to record, count or break
    transfers between the firmware and the (emulated) chip."""

    def __init__(self, inner: I2CBus) -> None:
        self.inner = inner

    def write_register(self, address: int, register: int, data: bytes) -> None:
        self.inner.write_register(address, register, data)

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        return self.inner.read_registers(address, register, length)

    def close(self) -> None:
        self.inner.close()

    def monotonic(self) -> float:
        return self.inner.monotonic()

    def delay(self, seconds: float) -> None:
        self.inner.delay(seconds)


class SharedBus(I2CBus):
    """Several chips (each an :class:`I2CBus` answering at its own ``address``) on one I2C bus,
    as two LSM6DSOX with SA0 low and high: a transfer goes to the chip at its address, and
    nothing acknowledges elsewhere. The first chip's clock is the bus's."""

    def __init__(self, *chips: I2CBus) -> None:
        self.chips = {int(chip.address): chip for chip in chips}  # type: ignore[attr-defined]
        self.first = chips[0]

    def _chip(self, address: int) -> I2CBus:
        chip = self.chips.get(address)
        if chip is None:
            raise DeviceIOError(f"no ACK from I2C address 0x{address:02X}")
        return chip

    def write_register(self, address: int, register: int, data: bytes) -> None:
        self._chip(address).write_register(address, register, data)

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        return self._chip(address).read_registers(address, register, length)

    def close(self) -> None:
        for chip in self.chips.values():
            chip.close()

    def monotonic(self) -> float:
        return self.first.monotonic()

    def delay(self, seconds: float) -> None:
        self.first.delay(seconds)


def c_encode(lib: ctypes.CDLL, packet: p.Packet) -> bytes:
    """The wire frame (COBS + 0x00) the firmware's C encoder makes of a device packet."""
    wire = (ctypes.c_uint8 * 516)()
    if isinstance(packet, p.Info):
        info = _LinkInfo((ctypes.c_uint8 * 3)(*packet.firmware), packet.who_am_i,
                         (ctypes.c_uint8 * 12)(*packet.unique_id), packet.name.encode())
        n = lib.link_encode_info(ctypes.byref(info), wire)
    elif isinstance(packet, p.Config):
        config = _LinkConfig(packet.odr_mhz, packet.accel_fs_g, packet.gyro_fs_dps,
                             packet.tick_ns)
        n = lib.link_encode_config(ctypes.byref(config), wire)
    elif isinstance(packet, p.Samples):
        rows = np.ascontiguousarray(np.asarray(packet.data, dtype=np.int16).reshape(-1, 6))
        n = lib.link_encode_samples(packet.seq, packet.t0, packet.temperature_raw,
                                    rows.ctypes.data_as(ctypes.POINTER(ctypes.c_int16)),
                                    rows.shape[0], wire)
    elif isinstance(packet, p.SamplesIndexed):
        inner = packet.samples
        rows = np.ascontiguousarray(np.asarray(inner.data, dtype=np.int16).reshape(-1, 6))
        n = lib.link_encode_samples_indexed(
            packet.sensor_index, inner.seq, inner.t0, inner.temperature_raw,
            rows.ctypes.data_as(ctypes.POINTER(ctypes.c_int16)), rows.shape[0], wire)
    elif isinstance(packet, p.Sensor):
        sensor = _LinkSensor(packet.sensor_index, packet.sensor_count, packet.i2c_address,
                             packet.who_am_i, _LinkConfig(packet.odr_mhz, packet.accel_fs_g,
                                                          packet.gyro_fs_dps, packet.tick_ns),
                             packet.flags)
        n = lib.link_encode_sensor(ctypes.byref(sensor), wire)
    elif isinstance(packet, p.Ack):
        n = lib.link_encode_ack(packet.command, packet.status, packet.message.encode(), wire)
    elif isinstance(packet, p.SelfTestResult):
        result = _LinkSelfTest(packet.accel_pass, packet.gyro_pass,
                               (ctypes.c_int16 * 3)(*packet.accel_delta_mg),
                               (ctypes.c_int16 * 3)(*packet.gyro_delta_dps))
        n = lib.link_encode_selftest(ctypes.byref(result), wire)
    elif isinstance(packet, p.Log):
        n = lib.link_encode_log(packet.level, packet.text.encode(), wire)
    elif isinstance(packet, p.Pong):
        n = lib.link_encode_pong(packet.token, wire)
    elif isinstance(packet, p.Status):
        with_mag = packet.version == p.STATUS_VERSION_MAG and len(packet.extra) == 12
        if not (packet.version == 1 and not packet.extra) and not with_mag:
            raise ValueError("the firmware sends STATUS version 1, or 2 with its 12 bytes")
        status = _LinkStatus(packet.reset_cause, packet.flags,
                             *(getattr(packet, name) for name in p.Status.COUNTERS),
                             packet.version, packet.mag_i2c_errors or 0,
                             packet.mag_samples_read or 0, packet.mag_overruns or 0)
        n = lib.link_encode_status(ctypes.byref(status), wire)
    elif isinstance(packet, p.Magnetometer):
        mag = _LinkMagnetometer(packet.chip, packet.i2c_address, packet.who_am_i,
                                packet.odr_mhz, packet.range_ut, packet.pt_per_lsb,
                                packet.mode, packet.flags)
        n = lib.link_encode_magnetometer(ctypes.byref(mag), wire)
    elif isinstance(packet, p.MagSamples):
        ticks = np.ascontiguousarray(packet.t, dtype=np.uint32)
        xyz = np.ascontiguousarray(packet.xyz, dtype=np.int16)
        n = lib.link_encode_mag_samples(packet.seq, ticks.ctypes.data_as(
            ctypes.POINTER(ctypes.c_uint32)), xyz.ctypes.data_as(ctypes.POINTER(ctypes.c_int16)),
            len(ticks), wire)
    else:
        raise TypeError(f"the firmware does not send {type(packet).__name__}")
    return bytes(wire[:n])


class CReceiver:
    """The firmware's frame receiver (link_rx) on its own: bytes in, packets out."""

    def __init__(self, lib: ctypes.CDLL) -> None:
        self.lib = lib
        self._rx = ctypes.c_void_p(lib.fwh_rx_create())

    def feed(self, data: bytes) -> list[bytes]:
        """The good packets (type + payload, without the CRC) that ``data`` completes."""
        out: list[bytes] = []
        offset = ctypes.c_size_t(0)
        packet = (ctypes.c_uint8 * 512)()
        while True:
            n = self.lib.fwh_rx_next(self._rx, bytes(data), len(data), ctypes.byref(offset),
                                     packet)
            if not n:
                return out
            out.append(bytes(packet[:n]))

    @property
    def bad_frames(self) -> int:
        return int(self.lib.fwh_rx_bad_frames(self._rx))

    def close(self) -> None:
        self.lib.fwh_rx_destroy(self._rx)


class FirmwareCore:
    """One firmware core (as on a board) with ``bus`` behind its I2C and collected output.

    Parameters
    ----------
    lib : from :func:`build_library`.
    bus : the I2C bus; a :class:`~drivers.errors.DeviceIOError` from it reads as a NACK.
    unique_id : the 12 bytes INFO reports.
    baud, i2c_hz : the link and bus the firmware limits the ODR by (0: no limit).
    clock : seconds; defaults to the bus's :meth:`~I2CBus.monotonic`. The firmware's delays
        go to the bus's :meth:`~I2CBus.delay` (virtual time advances on an emulated bus).
    """

    def __init__(
        self,
        lib: ctypes.CDLL,
        bus: I2CBus,
        *,
        unique_id: bytes = bytes(range(0x10, 0x1C)),
        name: str = "NUCLEO-F746ZG",
        baud: int = p.DEFAULT_BAUD,
        i2c_hz: int = 400_000,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.lib = lib
        self.bus = bus
        self.clock = clock or bus.monotonic
        self.output = bytearray()
        self.callback_errors: list[BaseException] = []
        self._splitter = FrameSplitter()
        self._closed = False
        # Keep the callbacks alive as long as the core.
        self._callbacks = (
            _I2C_WRITE(self._i2c_write), _I2C_READ(self._i2c_read), _MICROS(self._micros),
            _DELAY(self._delay), _TX(self._tx),
        )
        handle = lib.fwh_create(*self._callbacks, bytes(unique_id), name.encode(), baud, i2c_hz)
        if not handle:
            raise MemoryError("fwh_create failed")
        self._handle = ctypes.c_void_p(handle)

    # -- the platform, in Python ---------------------------------------------------------------
    def _i2c_write(self, address: int, register: int, data, length: int) -> int:
        try:
            self.bus.write_register(address, register, ctypes.string_at(data, length))
            return 0
        except DeviceIOError:
            return 1
        except BaseException as exc:  # a bug in a test's fake: report it, do not hide it
            self.callback_errors.append(exc)
            return 1

    def _i2c_read(self, address: int, register: int, out, length: int) -> int:
        try:
            data = self.bus.read_registers(address, register, length)
            if len(data) != length:  # a short read is a failed transfer, as on a real bus
                return 1
            ctypes.memmove(out, data, length)
            return 0
        except DeviceIOError:
            return 1
        except BaseException as exc:
            self.callback_errors.append(exc)
            return 1

    def _micros(self) -> int:
        return int(self.clock() * 1e6) & 0xFFFFFFFF

    def _delay(self, microseconds: int) -> None:
        self.bus.delay(microseconds * 1e-6)

    def _tx(self, data, length: int) -> None:
        self.output += ctypes.string_at(data, length)

    # -- driving it ------------------------------------------------------------------------------
    def receive(self, data: bytes) -> None:
        """Bytes from the host, as the UART would deliver them."""
        self.lib.fwh_receive(self._handle, bytes(data), len(data))
        self._check_callbacks()

    def send(self, *packets: p.Packet) -> None:
        """Encode ``packets`` with the Python encoder and hand them to the firmware."""
        self.receive(b"".join(encode_packet(packet) for packet in packets))

    def poll(self) -> None:
        self.lib.fwh_poll(self._handle)
        self._check_callbacks()

    def run(self, seconds: float, step_s: float = 0.0005) -> None:
        """Poll in steps of ``step_s`` of virtual time (the bus must have a virtual clock)."""
        end = self.clock() + seconds
        while self.clock() < end:
            self.bus.delay(step_s)
            self.poll()

    def set_board_health(self, *, uart_rx_errors: int = 0, uart_tx_dropped_bytes: int = 0,
                         i2c_recoveries: int = 0, watchdog_resets: int = 0,
                         reset_cause: int = 1, clock_fallback: bool = False) -> None:
        """What the board layer reports for STATUS (the core counts the rest itself)."""
        self.lib.fwh_set_board_health(self._handle, uart_rx_errors, uart_tx_dropped_bytes,
                                      i2c_recoveries, watchdog_resets, reset_cause,
                                      int(clock_fallback))

    def set_tx_free(self, free_bytes: int) -> None:
        """What the transmit buffer reports as free (0: full)."""
        self.lib.fwh_set_tx_free(self._handle, free_bytes)

    def take_output(self) -> bytes:
        """The bytes sent since the last call."""
        data, self.output = bytes(self.output), bytearray()
        return data

    def packets(self) -> list[p.Packet]:
        """Decode the output sent since the last call (bad frames raise: the firmware must not
        send any)."""
        frames = self._splitter.feed(self.take_output())
        return [p.parse_packet(packet[0], packet[1:]) for packet in map(unframe, frames)]

    @property
    def led_mode(self) -> int:
        return int(self.lib.fwh_led_mode(self._handle))

    def led_lit(self, mode: int, now_ms: int) -> bool:
        return bool(self.lib.fwh_led_lit(mode, now_ms))

    @property
    def streaming(self) -> bool:
        return bool(self.lib.fwh_streaming(self._handle))

    @property
    def sensor_count(self) -> int:
        """Sensors the firmware found at power-on (1, or 2 at 0x6A and 0x6B)."""
        return int(self.lib.fwh_sensor_count(self._handle))

    def magnetometer(self) -> dict[str, int | bool]:
        """The magnetometer as the core sees it (chip 0: none found)."""
        out = (ctypes.c_uint32 * 4)()
        self.lib.fwh_magnetometer(self._handle, out)
        return {"chip": out[0], "address": out[1], "odr_mhz": out[2],
                "found": bool(out[3] & 1), "ok": bool(out[3] & 2), "paused": bool(out[3] & 4)}

    def counters(self) -> dict[str, int]:
        values = (ctypes.c_uint32 * len(COUNTER_NAMES))()
        n = self.lib.fwh_counters(self._handle, values, len(values))
        return dict(zip(COUNTER_NAMES[:n], values[:n], strict=True))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.lib.fwh_destroy(self._handle)

    def _check_callbacks(self) -> None:
        if self.callback_errors:
            raise RuntimeError("a platform callback failed") from self.callback_errors[0]


class PtyBoard:
    """The firmware core served on a pseudo-terminal in real time, like a NUCLEO on USB.

    The core's main loop runs in a thread: bytes from the pty go to the firmware, its output to
    the pty. ``bus`` should run on the wall clock (an :class:`EmulatedLsm6dsox` without a
    virtual clock). Open :attr:`port` with the app (``inclinometer --device PORT``).
    """

    def __init__(self, core_factory: Callable[[], FirmwareCore]) -> None:
        import pty
        import termios
        import tty

        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)
        attributes = termios.tcgetattr(self._slave)
        attributes[3] &= ~termios.ECHO
        termios.tcsetattr(self._slave, termios.TCSANOW, attributes)
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._factory = core_factory
        self.core: FirmwareCore | None = None
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._loop, name="firmware-core", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        pending = bytearray()  # the board's transmit ring: the firmware drops SAMPLES when full
        try:
            self.core = core = self._factory()
            while not self._stop.is_set():
                try:
                    data = os.read(self._master, 4096)
                except BlockingIOError:
                    data = b""
                core.set_tx_free(max(0, TX_BUFFER_BYTES - len(pending)))
                if data:
                    core.receive(data)
                core.poll()
                pending += core.take_output()
                if pending:
                    with contextlib.suppress(BlockingIOError):
                        del pending[:os.write(self._master, pending)]
                time.sleep(0.0005)
        except BaseException as exc:  # reported by close()
            self.error = exc

    def close(self) -> None:
        """Stop the core and remove the pty (the host sees the cable pulled)."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)
        if self.core is not None:
            self.core.close()
        if self.error is not None:
            raise RuntimeError("the firmware core's loop failed") from self.error
