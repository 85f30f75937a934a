"""The serial driver for NUCLEO link protocol v1 (``docs/protocol.md``), over pyserial.

URLs
----
- ``serial:///dev/ttyACM0?baud=921600&odr=104&accel_fs=4&gyro_fs=250``, ``serial://COM3``:
  protocol v1 on that port. Any pyserial URL works as the port: ``serial://loop://``,
  ``serial://spy:///dev/ttyACM0?file=trace.txt`` (options this driver does not know stay
  with the pyserial URL).
- A bare port name or path, ``/dev/ttyACM0``, ``COM3``, ``/dev/pts/4`` (options allowed:
  ``/dev/ttyACM0?odr=208``): :class:`PortDevice` detects whether protocol v1 packets or text
  lines arrive, and hands text over to the ``text://`` driver (at the same baud rate, with the
  options this driver does not know, such as ``columns=``).

Options: ``baud`` (default 921600; ignored by native USB), ``odr`` (Hz, snapped to the nearest
LSM6DSOX rate), ``accel_fs`` (2/4/8/16 g), ``gyro_fs`` (125..2000 dps), ``timeout`` (seconds
to wait for an answer to HELLO, default 2), ``sensor`` (which sensor of the board, default 0).
Without ``odr``/``accel_fs``/``gyro_fs`` the board keeps its settings; with any of them it is
sent CONFIGURE.

Several sensors on one board
----------------------------
A board with two LSM6DSOX (docs/protocol.md, "Several sensors on one board") streams both on
one port. ``serial:///dev/ttyACM0`` is sensor 0, as always; ``serial:///dev/ttyACM0?sensor=1``
is sensor 1, a device of its own (its own decoder, sequence numbers, clock, pipeline). Both
may be open at once: they share the port (:class:`~drivers.link.shared_port.SharedPort`,
reference-counted: the first to open opens the port and starts the board, the others join
the running stream, and the last to close stops the board and closes the port). The board's
settings are common to its sensors: a device joining with other settings is refused, and a
self-test (which stops the stream) is refused while another sensor's device is open. Sensor
``k > 0``'s unique id is the board's with ``-S<k>`` appended, so each sensor keeps its own
calibration profile. A board without sensor ``k`` is refused with the number it has. At a
rate that fits sensor 0 alone (1667 Hz on the NUCLEO's I2C at 400 kHz) the board streams
sensor 0 only and pauses the others: opening a paused sensor is refused with the board's
reason (:class:`~drivers.errors.SettingRefusedError`), and a paused SENSOR arriving while it
streams makes its reads fail with that reason, never an empty stream.

Opening: STOP, HELLO -> INFO + CONFIG (HELLO is repeated every 0.5 s until the timeout), the
WHO_AM_I and protocol version are checked, CONFIGURE when asked, then START -> ACK.

Threads: one thread opens, reads and closes. :attr:`SerialLinkDevice.counters`,
:meth:`~SerialLinkDevice.self_test`, :meth:`~SerialLinkDevice.ping` and
:meth:`~SerialLinkDevice.recent_logs` are thread-safe: whichever thread holds the port reads
it and hands the other thread its answer.

Unplugged cable: reads raise :class:`DeviceIOError` ("... was disconnected ..."). To reconnect,
``DeviceInfo.extra["usb_serial"]`` names the board and :func:`reconnect_url` gives the URL to
open once a port with that USB serial number is back (the port name may differ). The new
connection's ``t_s`` starts at 0 again; ``device_clock_origin_s`` tells where on the board's
own clock (it runs on unless the board was reset) to put it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import secrets
import time
from collections import deque
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, ClassVar
from urllib.parse import urlencode

import serial

from app.core.devices import BoardStatus, MagnetometerInfo
from app.core.samples import RawBlock, merge_raw_blocks
from drivers import lsm6dsox, magnetometers
from drivers.base import Device, DeviceDescriptor, DeviceInfo, DeviceMessage, read_block_s
from drivers.errors import (
    DeviceError,
    DeviceIOError,
    DeviceOpenError,
    DeviceUrlError,
    SettingRefusedError,
)
from drivers.link import protocol as p
from drivers.link.client import (
    COMMAND_TIMEOUT_S,
    POLL_S,
    LinkClient,
    ack_message,
)
from drivers.link.decoder import LinkCounters, LinkDecoder
from drivers.link.framing import DELIMITER, encode_packet
from drivers.link.ports import (
    find_port_by_serial,
    list_serial_ports,
    open_error,
    port_info,
)
from drivers.link.shared_port import SensorInUse
from drivers.url_options import Option, parse_options

if TYPE_CHECKING:
    from drivers.text_lines import TextLineCounters

log = logging.getLogger(__name__)

DEFAULT_HELLO_TIMEOUT_S = 2.0
"""How long the board has to answer HELLO before the port is declared the wrong protocol."""
MAX_TIMEOUT_S = 3600.0
"""The longest ``timeout=`` a URL may ask to wait for the board's HELLO."""
HELLO_RESEND_S = 0.5
SELF_TEST_TIMEOUT_S = 3.0
WRITE_TIMEOUT_S = 1.0
TEXT_LINES_TO_DECIDE = 3
LINK_NOTE_INTERVAL_S = 1.0
"""At most one message a second about frames lost on the link (a bad cable makes many)."""

OPTIONS: tuple[Option, ...] = (
    Option("baud", "integer", p.DEFAULT_BAUD, positive=True, help="baud rate (native USB "
                                                                  "ignores it)"),
    replace(lsm6dsox.ODR_OPTION, default=None, field="odr_hz",
            help="output data rate, snapped to the nearest LSM6DSOX rate (12.5 ... 6667; "
                 "default: the board keeps its own; any of odr, accel_fs, gyro_fs sends "
                 "CONFIGURE)"),
    replace(lsm6dsox.ACCEL_FS_OPTION, default=None,
            help="accelerometer full scale (default: the board's)"),
    replace(lsm6dsox.GYRO_FS_OPTION, default=None,
            help="gyroscope full scale (default: the board's)"),
    Option("timeout", "number", DEFAULT_HELLO_TIMEOUT_S, unit="s", positive=True,
           maximum=MAX_TIMEOUT_S, field="hello_timeout_s",
           help="seconds to wait for the board's answer to HELLO"),
    Option("sensor", "integer", 0, minimum=0, maximum=p.MAX_SENSORS - 1,
           help="which sensor of a board with several (1 is the LSM6DSOX at 0x6B)"),
)
"""The ``serial://`` options (a bare port also takes the ``text://`` driver's)."""

WHO_AM_I_OTHERS: dict[int, str] = {
    0x69: "an LSM6DS3", 0x6A: "an LSM6DSL or LSM6DS3TR-C", 0x6B: "an LSM6DSR or ISM330DHCX",
    0x70: "an LSM6DSV",
}


@dataclass(frozen=True, slots=True)
class LinkOptions:
    """A validated serial-link URL."""

    port: str
    baud: int = p.DEFAULT_BAUD
    odr_hz: float | None = None
    accel_fs_g: int | None = None
    gyro_fs_dps: int | None = None
    hello_timeout_s: float = DEFAULT_HELLO_TIMEOUT_S
    sensor: int = 0
    """Which sensor of the board (docs/protocol.md, "Several sensors on one board")."""
    other_options: tuple[tuple[str, str], ...] = ()
    """Options of a bare port this driver does not know: for the text driver if text arrives."""

    @property
    def wants_configure(self) -> bool:
        return (self.odr_hz, self.accel_fs_g, self.gyro_fs_dps) != (None, None, None)


def _split_url(url: str) -> tuple[str, str]:
    """(port, query) of a ``serial://`` URL or a bare port."""
    rest = url[len("serial://"):] if url.lower().startswith("serial://") else url
    port, _, query = rest.partition("?")
    return port, query


def parse_link_url(url: str, *, allow_other: bool = False) -> LinkOptions:
    """Validate a ``serial://PORT?options`` URL or a bare ``PORT?options``.

    With ``allow_other`` (bare ports), options this driver does not know are kept in
    ``other_options`` (the text driver's, such as ``columns``) instead of refused.

    Raises
    ------
    DeviceUrlError
        For a missing port, an unknown option or a bad value; the message names the allowed.
    """
    port, query = _split_url(url)
    if not port:
        raise DeviceUrlError(f"{url}: no port; expected e.g. serial:///dev/ttyACM0 or COM3")
    keep_other = "://" in port or allow_other  # pyserial's own options, or text://'s
    parsed = parse_options(url, query, OPTIONS, keep_other=keep_other)
    other = tuple(parsed.other)
    if "://" in port:  # the options of the pyserial URL (spy://...?file=...)
        if other:
            port = f"{port}?{urlencode(other)}"
        other = ()
    return LinkOptions(port=port, other_options=other, **parsed.values)  # type: ignore[arg-type]


def url_with_port(url: str, port: str) -> str:
    """``url`` with its port replaced (same form: ``serial://`` or bare; options kept)."""
    _, query = _split_url(url)
    prefix = "serial://" if url.lower().startswith("serial://") else ""
    return f"{prefix}{port}" + (f"?{query}" if query else "")


def reconnect_url(url: str, usb_serial: str) -> str | None:
    """The URL to reopen a board by its USB serial number, wherever it is now.

    ``url`` is the URL the board was opened with, ``usb_serial`` is
    ``DeviceInfo.extra["usb_serial"]``. Returns None while no port has that serial number
    (the board is still unplugged or still enumerating).
    """
    port = find_port_by_serial(usb_serial)
    return None if port is None else url_with_port(url, port)


class _TextLinesSeen(DeviceOpenError):
    """Text lines arrived instead of protocol v1 (a :class:`PortDevice` hands over)."""

    def __init__(self, message: str, sample_line: str) -> None:
        super().__init__(message)
        self.sample_line = sample_line


def _text_lines(data: bytes) -> list[str] | None:
    """The complete lines in ``data`` if it looks like text, else None."""
    if b"\n" not in data:
        return None
    printable = sum(1 for byte in data if 32 <= byte < 127 or byte in (9, 10, 13))
    if printable < 0.95 * len(data):
        return None
    complete = data[: data.rfind(b"\n")].decode("ascii", errors="replace").split("\n")
    return [line.strip() for line in complete if line.strip()]


class SerialLinkDevice(Device):
    """A board speaking protocol v1 on a serial port (see the module docstring).

    Parameters
    ----------
    url : ``serial://PORT?options`` (or a bare port for :class:`PortDevice`).
    hello_timeout_s : overrides the URL's ``timeout`` option.
    """

    scheme: ClassVar[str] = "serial"
    url_options: ClassVar[tuple[Option, ...]] = OPTIONS
    detect_text: ClassVar[bool] = False

    def __init__(self, url: str, *, hello_timeout_s: float | None = None) -> None:
        super().__init__(url)
        options = parse_link_url(url, allow_other=self.detect_text)
        if hello_timeout_s is not None:
            options = dataclasses.replace(options, hello_timeout_s=hello_timeout_s)
        self.options = options
        self.port = options.port
        self.info_packet: p.Info | None = None
        self.config_packet: p.Config | None = None
        self.sensor_packet: p.Sensor | None = None
        self._client = LinkClient(options.port, options.sensor)
        self._last_read_s = -math.inf
        self._link_note_at = -math.inf

    # -- discovery -----------------------------------------------------------------------------
    @classmethod
    def discover(cls) -> list[DeviceDescriptor]:
        """Serial ports present now, with USB VID:PID, serial number and a guess."""
        try:
            ports = list_serial_ports()
        except Exception as exc:  # listing must never break the device menu
            log.warning("listing serial ports failed: %s", exc)
            return []
        return [DeviceDescriptor(info.device, info.summary(), "serial") for info in ports]

    # -- thread-safe helpers ----------------------------------------------------------------------
    @property
    def counters(self) -> LinkCounters:
        """Link statistics (packets, samples, CRC errors, undecodable, gaps): a snapshot.

        Thread-safe. A property, as the text driver's ``counters``.
        """
        with self._client.state:
            return self._client.decoder.counters()

    def recent_logs(self) -> list[p.Log]:
        """The board's latest LOG messages, oldest first. Thread-safe."""
        with self._client.state:
            return list(self._client.logs)

    @property
    def supports_self_test(self) -> bool:
        return True

    def take_messages(self) -> list[DeviceMessage]:
        """The board's LOG messages since the last call, and what was lost on the link
        (at most one such message a second). Thread-safe."""
        with self._client.state:
            logs = list(self._client.unread_logs)
            self._client.unread_logs.clear()
            messages = [DeviceMessage(entry.level, entry.text) for entry in logs]
            gaps, frames, lost = self._client.link_losses
            now = time.monotonic()
            if gaps and now - self._link_note_at >= LINK_NOTE_INTERVAL_S:
                self._link_note_at = now
                self._client.link_losses = [0, 0, 0]
                messages.append(DeviceMessage(2, link_loss_message(gaps, frames, lost)))
        return messages

    @property
    def board_status(self) -> BoardStatus | None:
        """The latest STATUS the board sent (once a second while streaming). Thread-safe."""
        with self._client.state:
            return self._client.board_status

    def request_status(self, timeout_s: float = COMMAND_TIMEOUT_S) -> BoardStatus | None:
        """Ask for a STATUS now (GET_STATUS); None when the firmware predates it. Thread-safe."""
        self._require_open()
        with self._client.command_lock:
            self._client.forget(lambda r: isinstance(r, p.Status))
            self._client.send(p.GetStatus())
            answer = self._client.wait_for(
                lambda pkt: isinstance(pkt, p.Status) or (
                    isinstance(pkt, p.Ack) and pkt.command == p.GET_STATUS), timeout_s)
        if answer is None:
            raise DeviceIOError(f"{self.port}: no STATUS within {timeout_s:g} s")
        if isinstance(answer, p.Ack):
            return None
        with self._client.state:
            return self._client.board_status

    @property
    def usb_serial(self) -> str | None:
        """The USB serial number of the port, when known."""
        return None if self._info is None else self._info.extra.get("usb_serial")

    @property
    def device_clock_origin_s(self) -> float | None:
        """Device time (s since the board's clock started, unwrapped) where ``t_s`` is 0.

        None until the first sample arrived. When the same board (same unique id) comes back
        with its clock still running, ``t_s + device_clock_origin_s`` continues across the
        reconnect; when it is smaller than before, the board was reset.
        """
        with self._client.state:
            return self._client.decoder.clock_origin_s

    def ping(self, timeout_s: float = COMMAND_TIMEOUT_S) -> float:
        """Round-trip time of PING -> PONG in seconds. Thread-safe."""
        self._require_open()
        token = secrets.randbits(32)
        start = time.perf_counter()
        self._client.send(p.Ping(token))
        pong = self._client.wait_for(lambda pkt: isinstance(pkt, p.Pong) and pkt.token == token,
                              timeout_s)
        if pong is None:
            raise DeviceIOError(f"{self.port}: no PONG within {timeout_s:g} s")
        return time.perf_counter() - start

    def self_test(self, timeout_s: float = SELF_TEST_TIMEOUT_S) -> p.SelfTestResult:
        """Run the sensor's self-test; streaming pauses meanwhile. Thread-safe.

        The first sample after the pause is marked as a gap. Raises :class:`DeviceError`
        when the board refuses or does not answer.
        """
        self._require_open()
        link = self._client.link
        if link is not None and link.users > 1:
            raise DeviceError(
                f"{self.port}: the self-test stops the board's stream, and another sensor of "
                "this board is open: close it first")
        with self._client.command_lock:
            was_streaming = self._client.streaming
            if was_streaming:
                self._client.command(p.Stop(), "stopping the stream for the self-test")
                self._client.streaming = False
            try:
                self._client.command(p.SelfTest(), "self-test", timeout_s)
                result = self._client.expect(p.SelfTestResult, timeout_s)
                if result is None:
                    raise DeviceIOError(f"{self.port}: no SELFTEST result within {timeout_s:g} s")
                return result
            finally:
                if was_streaming:
                    self._start_streaming(new_origin=False, mark_gap=True)

    def send_command(self, packet: p.Packet, timeout_s: float = COMMAND_TIMEOUT_S) -> p.Ack:
        """Send any command and return its ACK (not checked). Thread-safe."""
        self._require_open()
        with self._client.command_lock:
            return self._client.exchange(packet, timeout_s)

    # -- Device template ------------------------------------------------------------------------
    def _open(self) -> DeviceInfo:
        try:
            opened = self._client.attach(self._open_port)
        except SensorInUse:
            raise DeviceOpenError(
                f"{self.port} is busy: this program has sensor {self.options.sensor} of it "
                "open already (close that device first)") from None
        try:
            return self._handshake() if opened else self._join()
        except BaseException:
            self._client.close_port()
            raise

    def _read(self, timeout_s: float) -> RawBlock | None:
        # Everything queued comes back as one block, once it holds read_block_s of samples or
        # that long after the previous read (the board sends a packet per FIFO poll: one or
        # two samples a packet at low rates, and the pipeline's cost is mostly per block).
        now = time.monotonic()
        deadline = now + timeout_s
        info = self._info
        span = read_block_s(info.odr_hz) if info is not None else 0.0
        settle = min(deadline, self._last_read_s + span)
        enough = max(1, math.ceil(span * info.odr_hz)) if info is not None else 1
        while True:
            with self._client.state:
                if self._client.blocks:
                    queued = sum(len(block) for block in self._client.blocks)
                    if queued >= enough or time.monotonic() >= settle:
                        blocks = list(self._client.blocks)
                        self._client.blocks.clear()
                        self._last_read_s = time.monotonic()
                        merged = merge_raw_blocks(blocks)
                        if len(merged) > 1:  # a change of scale: the rest waits its turn
                            self._client.blocks.extend(merged[1:])
                        return merged[0] if merged else None
                paused = self._client.paused_while_streaming
            if paused is not None:
                raise DeviceError(self._paused_message(paused, self._pause_reason()))
            if time.monotonic() >= deadline:
                return None
            link = self._client.link
            if link is None:
                raise DeviceIOError(f"{self.port} is closed")
            with link.read_lock:
                self._client.pump()

    def _close(self) -> None:
        link = self._client.link
        if not self._client.disconnected and link is not None and link.users == 1:
            with contextlib.suppress(DeviceError):  # the last user stops the board
                self._client.write(encode_packet(p.Stop()))
                link.streaming = False
        self._client.streaming = False
        self._client.close_port()

    # -- opening ------------------------------------------------------------------------------
    def _open_port(self) -> serial.SerialBase:
        try:
            port = serial.serial_for_url(
                self.port, baudrate=self.options.baud, timeout=POLL_S,
                write_timeout=WRITE_TIMEOUT_S, exclusive=True,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise open_error(self.port, exc) from exc
        with contextlib.suppress(serial.SerialException, OSError):
            port.reset_input_buffer()
        return port

    def _handshake(self) -> DeviceInfo:
        with self._client.state:  # nothing of an earlier connection carries over
            self._client.blocks.clear()
            self._client.replies.clear()
        self._client.decoder = LinkDecoder()
        self._client.decoder.arm_start(new_origin=True)
        self._client.probe.clear()
        self._client.write(DELIMITER + encode_packet(p.Stop()) + encode_packet(p.Hello()))
        info, config = self._await_hello()
        if info.protocol_version != p.PROTOCOL_VERSION:
            raise DeviceOpenError(
                f"{self.port}: the board speaks protocol version {info.protocol_version}; "
                f"this program speaks version {p.PROTOCOL_VERSION}. Update the firmware or "
                "the program so that they match."
            )
        if info.who_am_i != lsm6dsox.WHO_AM_I_VALUE:
            raise DeviceOpenError(who_am_i_message(self.port, info.who_am_i))
        if self.options.sensor:
            self.sensor_packet = self._await_sensor()
        if self.options.wants_configure:
            config = self._configure(config)
        if not self.options.sensor:
            self._await_magnetometer()
        if self.options.other_options:
            ignored = ", ".join(key for key, _ in self.options.other_options)
            log.warning("%s speaks protocol v1: ignoring the text-line options %s", self.port,
                        ignored)
        self._refuse_if_paused()
        self.info_packet, self.config_packet = info, config
        self._start_streaming(new_origin=True, mark_gap=False)
        return self._device_info(info, self._sensor_config(config))

    def _join(self) -> DeviceInfo:
        """Open another sensor of a board whose port another device has open: HELLO (answered
        while streaming too), this sensor's SENSOR, and the stream as it runs."""
        with self._client.state:
            self._client.blocks.clear()
            self._client.replies.clear()
        self._client.decoder = LinkDecoder(sensor=self.options.sensor)
        self._client.probe.clear()
        self._client.write(encode_packet(p.Hello()))
        info, config = self._await_hello()
        if self.options.sensor:
            self.sensor_packet = self._await_sensor()
            self._refuse_if_paused()
        ours = self._sensor_config(config)
        opts = self.options
        wanted = (lsm6dsox.odr_code_for(opts.odr_hz) if opts.odr_hz else ours.odr_code,
                  opts.accel_fs_g or ours.accel_fs_g, opts.gyro_fs_dps or ours.gyro_fs_dps)
        if wanted != (ours.odr_code, ours.accel_fs_g, ours.gyro_fs_dps):
            raise DeviceOpenError(
                f"{self.port}: another sensor of this board is open and streaming at "
                f"{lsm6dsox.odr_text(ours.odr_hz)}, +-{ours.accel_fs_g} g, "
                f"+-{ours.gyro_fs_dps} dps; the sensors of one board share their settings: "
                "open this one with the same settings, or close the other first")
        self.info_packet, self.config_packet = info, config
        link = self._client.link
        if link is not None and not link.streaming:
            self._start_streaming(new_origin=True, mark_gap=False)
        else:
            self._client.streaming = True
        return self._device_info(info, ours)

    def _sensor_config(self, config: p.Config) -> p.Config:
        """This sensor's settings: CONFIG for sensor 0, its SENSOR's for the others."""
        if self.options.sensor == 0 or self.sensor_packet is None:
            return config
        return self.sensor_packet.config

    def _refuse_if_paused(self) -> None:
        """Refuse to open a sensor the board does not stream at this rate (it fits sensor 0
        alone): the board's LOG after SENSOR says why."""
        sensor = self.sensor_packet
        if not self.options.sensor or sensor is None or not sensor.paused:
            return
        reason = self._pause_reason()
        raise SettingRefusedError(self._paused_message(sensor, reason), reason)

    def _pause_reason(self) -> str:
        """The board's latest LOG about this sensor's pause (it follows the SENSOR packets;
        a PING round trip makes sure it arrived). Empty when there is none."""
        prefix = f"sensor {self.options.sensor} ("
        with contextlib.suppress(DeviceError):
            token = secrets.randbits(32)
            self._client.send(p.Ping(token))
            self._client.wait_for(lambda pkt: isinstance(pkt, p.Pong) and pkt.token == token,
                           COMMAND_TIMEOUT_S)
        with self._client.state:
            return next((entry.text for entry in reversed(self._client.logs)
                         if entry.text.startswith(prefix) and "paused" in entry.text), "")

    def _paused_message(self, sensor: p.Sensor, reason: str) -> str:
        rate = lsm6dsox.odr_text(sensor.config.odr_hz)
        why = reason or "the rate does not fit all of the board's sensors"
        return (f"{self.port}: sensor {sensor.sensor_index} (the LSM6DSOX at "
                f"0x{sensor.i2c_address:02X}) is paused at {rate}: the board streams sensor 0 "
                f"alone at this rate ({why}). Open the board at a rate all its sensors fit "
                "(?odr=...), or sensor 0 alone.")

    def _await_magnetometer(self) -> None:
        """Let the board's MAGNETOMETER (a v1 extension, sent after CONFIG and the SENSOR
        packets) reach the decoder: a PING, whose PONG comes after it. A board without a
        magnetometer, or firmware before the extension, sends none."""
        token = secrets.randbits(32)
        self._client.send(p.Ping(token))
        self._client.wait_for(lambda pkt: isinstance(pkt, p.Pong) and pkt.token == token,
                       COMMAND_TIMEOUT_S)
        with self._client.state:
            mag = self._client.decoder.magnetometer
        if mag is not None and mag.paused:
            log.warning("%s: the board's %s is paused at this rate (see its LOG): no field "
                        "samples", self.port, magnetometers.chip_name(mag.chip))

    def _magnetometer_info(self) -> MagnetometerInfo | None:
        """The board's magnetometer as the app describes it; None without one streaming."""
        if self.options.sensor:
            return None
        with self._client.state:
            mag = self._client.decoder.magnetometer
        if mag is None or not mag.answering or mag.paused:
            return None
        return MagnetometerInfo(
            chip=magnetometers.chip_name(mag.chip), odr_hz=mag.odr_hz,
            range_ut=float(mag.range_ut), ut_per_lsb=mag.ut_per_lsb,
            address=mag.i2c_address, mode=magnetometers.MODE_NAMES.get(mag.mode, ""),
            path="bus")

    def _await_sensor(self) -> p.Sensor:
        """This sensor's SENSOR packet, or a clear refusal when the board lacks it (a PING
        right after HELLO's answer: its PONG coming first means no such sensor)."""
        index = self.options.sensor
        token = secrets.randbits(32)
        self._client.send(p.Ping(token))
        answer = self._client.wait_for(
            lambda pkt: (isinstance(pkt, p.Sensor) and pkt.sensor_index == index)
            or (isinstance(pkt, p.Pong) and pkt.token == token), COMMAND_TIMEOUT_S)
        if isinstance(answer, p.Sensor):
            return answer
        with self._client.state:
            counts = [pkt.sensor_count for pkt in self._client.replies if isinstance(pkt, p.Sensor)]
        has = f"has {counts[0]} sensors" if counts else "has one sensor (it sent no SENSOR)"
        raise DeviceOpenError(
            f"{self.port}: no sensor {index} on this board: it {has}; sensor 1 is a second "
            "LSM6DSOX at I2C address 0x6B (SA0 to 3.3 V) beside one at 0x6A, and needs "
            "firmware 1.1.0 or later")

    def _await_hello(self) -> tuple[p.Info, p.Config]:
        start = time.monotonic()
        deadline = start + self.options.hello_timeout_s
        next_hello = start + HELLO_RESEND_S
        info: p.Info | None = None
        config: p.Config | None = None
        while info is None or config is None:
            now = time.monotonic()
            if now >= deadline:
                raise DeviceOpenError(self._wrong_protocol_message())
            if now >= next_hello:
                self._client.write(DELIMITER + encode_packet(p.Hello()))
                next_hello += HELLO_RESEND_S
            if self.detect_text and now - start >= HELLO_RESEND_S:
                self._check_for_text()
            packet = self._client.wait_for(lambda pkt: isinstance(pkt, p.Info | p.Config),
                                    min(deadline, next_hello) - time.monotonic())
            if isinstance(packet, p.Info):
                info = packet
            elif isinstance(packet, p.Config):
                config = packet
        return info, config

    def _check_for_text(self) -> None:
        with self._client.state:
            probe = bytes(self._client.probe)
            packets = self._client.decoder.counters().packets
        lines = _text_lines(probe)
        if packets == 0 and lines is not None and len(lines) >= TEXT_LINES_TO_DECIDE:
            raise _TextLinesSeen(f"{self.port}: text lines arrive, e.g. {lines[0]!r}", lines[0])

    def _wrong_protocol_message(self) -> str:
        with self._client.state:
            probe = bytes(self._client.probe)
            counters = self._client.decoder.counters()
            last_error = self._client.decoder.last_error
        waited = f"{self.options.hello_timeout_s:g} s"
        head = f"{self.port}: no answer in NUCLEO protocol v1 within {waited} of HELLO. "
        if not probe:
            return head + (
                "Nothing at all was received. Is this the right port, is the board powered "
                "and running the Inclinometer firmware, and (on the ST-LINK port) is the baud "
                f"rate right (the firmware uses {p.DEFAULT_BAUD}, this port is set to "
                f"{self.options.baud})?"
            )
        lines = _text_lines(probe)
        if lines is not None:
            example = lines[0] if lines else probe[:60].decode("ascii", "replace")
            return head + (
                f"Received {len(probe)} bytes of text lines, e.g. {example!r}: this is a sketch "
                f"printing text. Open it as text://{self.port}, or give just the port name "
                f"({self.port}) to have it detected."
            )
        first = probe[:32].hex(" ")
        details = []
        if counters.packets:
            details.append(f"{counters.packets} packets decoded but no INFO/CONFIG")
        if counters.crc_errors:
            details.append(f"{counters.crc_errors} frames failed the CRC")
        if counters.undecodable:
            details.append(f"{counters.undecodable} frames were undecodable")
        if last_error:
            details.append(f"last problem: {last_error}")
        summary = f" ({'; '.join(details)})" if details else ""
        return head + (
            f"Received {len(probe)} bytes that are neither protocol v1 nor text{summary}; "
            f"first bytes: {first}. A wrong baud rate looks like this: the firmware uses "
            f"{p.DEFAULT_BAUD} baud, this port is set to {self.options.baud} (a sketch "
            "printing text at another rate: add ?baud=115200 or its rate to the port)."
        )

    def _configure(self, current: p.Config) -> p.Config:
        opts = self.options
        odr_code = (current.odr_code if opts.odr_hz is None
                    else lsm6dsox.odr_code_for(opts.odr_hz))
        accel = current.accel_fs_g if opts.accel_fs_g is None else opts.accel_fs_g
        gyro = current.gyro_fs_dps if opts.gyro_fs_dps is None else opts.gyro_fs_dps
        wanted = f"{lsm6dsox.ODR_LABELS_HZ[odr_code]:g} Hz, +-{accel} g, +-{gyro} dps"
        with self._client.state:
            self._client.replies = deque(
                (r for r in self._client.replies if not isinstance(r, p.Config | p.Sensor)),
                maxlen=self._client.replies.maxlen)
        ack = self._client.exchange(p.Configure(odr_code, accel, gyro), COMMAND_TIMEOUT_S)
        if ack.status == p.ACK_BAD_ARGUMENT:
            raise SettingRefusedError(ack_message(self.port, f"configuring {wanted}", ack),
                                      ack.message)
        if not ack.ok:
            raise DeviceOpenError(ack_message(self.port, f"configuring {wanted}", ack))
        config = self._client.expect(p.Config, COMMAND_TIMEOUT_S)
        if config is None:
            raise DeviceOpenError(f"{self.port}: the board acknowledged CONFIGURE but sent no "
                                  f"CONFIG within {COMMAND_TIMEOUT_S:g} s")
        if self.options.sensor:  # this sensor's own clock follows in its SENSOR
            index = self.options.sensor
            sensor = self._client.expect(p.Sensor, COMMAND_TIMEOUT_S,
                                         lambda pkt: pkt.sensor_index == index)
            if sensor is None:
                raise DeviceOpenError(f"{self.port}: the board acknowledged CONFIGURE but sent "
                                      f"no SENSOR for sensor {index}")
            self.sensor_packet = sensor
        applied = (config.odr_code, config.accel_fs_g, config.gyro_fs_dps)
        if applied != (odr_code, accel, gyro):
            raise DeviceOpenError(
                f"{self.port}: asked for {wanted}, the board uses "
                f"{lsm6dsox.odr_text(config.odr_hz)}, +-{config.accel_fs_g} g, "
                f"+-{config.gyro_fs_dps} dps"
            )
        return config

    def _start_streaming(self, *, new_origin: bool, mark_gap: bool) -> None:
        with self._client.state:
            self._client.decoder.arm_start(new_origin=new_origin, mark_gap=mark_gap)
        self._client.command(p.Start(), "starting the stream")
        self._client.streaming = True
        if self._client.link is not None:
            self._client.link.streaming = True

    def _device_info(self, info: p.Info, config: p.Config) -> DeviceInfo:
        usb = port_info(self.port)
        odr_nominal = lsm6dsox.ODR_LABELS_HZ[config.odr_code]  # the label; odr_hz is real
        index = self.options.sensor
        sensor = self.sensor_packet
        return DeviceInfo(
            url=self.url,
            name=(info.name or "NUCLEO (protocol v1)") + (f", sensor {index}" if index else ""),
            unique_id=info.unique_id_hex + (f"-S{index}" if index else ""),
            sensor="LSM6DSOX",
            odr_hz=config.odr_hz,
            odr_nominal_hz=odr_nominal,
            accel_fs_g=config.accel_fs_g,
            gyro_fs_dps=config.gyro_fs_dps,
            firmware=info.firmware_text,
            magnetometer=self._magnetometer_info(),
            extra={
                "port": self.port,
                "baud": self.options.baud,
                "protocol": "NUCLEO link v1",
                "who_am_i": info.who_am_i if sensor is None else sensor.who_am_i,
                "tick_ns": config.tick_ns,
                "sensor_index": index,
                "i2c_address": None if sensor is None else sensor.i2c_address,
                "sensor_count": None if sensor is None else sensor.sensor_count,
                "usb_serial": None if usb is None else usb.serial_number,
                "usb_vid_pid": None if usb is None else usb.vid_pid,
                "usb_description": None if usb is None else usb.summary(),
            },
        )

    # -- commands -----------------------------------------------------------------------------
    def _require_open(self) -> None:
        if self._client.link is None:
            raise DeviceError(f"{self.url} is not open")

class PortDevice(SerialLinkDevice):
    """A bare port name (``/dev/ttyACM0``, ``COM3``): protocol v1 or text lines, detected.

    While waiting for the answer to HELLO, text lines (at least three, and no valid packet)
    mean a sketch printing text: the port is closed and reopened by the ``text://`` driver.
    """

    scheme: ClassVar[str] = "port"
    detect_text: ClassVar[bool] = True

    @classmethod
    def options_for(cls, url: str = "") -> tuple[Option, ...]:
        """The link's options, then the text driver's it hands over."""
        from drivers.text_lines import OPTIONS as TEXT_OPTIONS

        names = {option.name for option in OPTIONS} | {"port"}
        return OPTIONS + tuple(o for o in TEXT_OPTIONS if o.name not in names)

    def __init__(self, url: str, *, hello_timeout_s: float | None = None) -> None:
        super().__init__(url, hello_timeout_s=hello_timeout_s)
        self.text_device: Device | None = None

    @classmethod
    def discover(cls) -> list[DeviceDescriptor]:
        return []  # the serial driver lists the ports

    @property
    def counters(self) -> LinkCounters | TextLineCounters:  # type: ignore[override]
        """The counters of the driver in use (protocol v1 or text lines). Thread-safe."""
        text = self.text_device
        if text is not None and hasattr(text, "counters"):
            return text.counters
        return super().counters

    @property
    def supports_self_test(self) -> bool:
        return self.text_device is None  # a sketch printing text lines has none

    def _require_open(self) -> None:
        if self.text_device is not None:
            raise DeviceError(f"{self.port}: a sketch printing text lines has no self-test "
                              "or ping; those need the NUCLEO firmware (protocol v1)")
        super()._require_open()

    def _open(self) -> DeviceInfo:
        try:
            return super()._open()
        except _TextLinesSeen as seen:
            return self._hand_over_to_text(seen)

    def _hand_over_to_text(self, seen: _TextLinesSeen) -> DeviceInfo:
        from drivers.registry import create_device

        # Text was seen at this baud rate: the text driver must use it too.
        query = urlencode([("baud", str(self.options.baud)), *self.options.other_options])
        text_url = f"text://{self.port}?{query}"
        try:
            device = create_device(text_url)
        except DeviceUrlError as exc:
            raise DeviceOpenError(
                f"{self.port}: text lines were seen (e.g. {seen.sample_line!r}), not protocol "
                f"v1, but the text-line driver is not available ({exc})."
            ) from exc
        info = device.open()
        self.text_device = device
        usb = port_info(self.port)
        extra = {**info.extra, "detected": "text lines", "text_url": text_url,
                 "usb_serial": None if usb is None else usb.serial_number,
                 "usb_vid_pid": None if usb is None else usb.vid_pid}
        return dataclasses.replace(info, url=self.url, extra=extra)

    def _read(self, timeout_s: float) -> RawBlock | None:
        if self.text_device is not None:
            return self.text_device.read(timeout_s)
        return super()._read(timeout_s)

    def _close(self) -> None:
        text, self.text_device = self.text_device, None
        if text is not None:
            text.close()
            return
        super()._close()


# -- messages ---------------------------------------------------------------------------------
def link_loss_message(gaps: int, corrupt_frames: int, lost_samples: int) -> str:
    """``link: 3 corrupt frames, ~40 samples lost`` (and how many gaps, when more than one)."""
    frames = "frame" if corrupt_frames == 1 else "frames"
    where = f" in {gaps} gaps" if gaps > 1 else ""
    return (f"link: {corrupt_frames} corrupt {frames}, ~{lost_samples} samples lost{where} "
            "(bytes lost between the board and this computer)")


def who_am_i_message(port: str, who_am_i: int) -> str:
    expected = f"0x{lsm6dsox.WHO_AM_I_VALUE:02X}"
    if who_am_i in (0x00, 0xFF):
        hint = ("no sensor answers: check that the sensor board sits in its socket and the "
                "I2C wiring")
    elif who_am_i in WHO_AM_I_OTHERS:
        hint = f"0x{who_am_i:02X} is what {WHO_AM_I_OTHERS[who_am_i]} reads: another sensor"
    else:
        hint = "another sensor, or a damaged one"
    return (f"{port}: the board's sensor reads WHO_AM_I 0x{who_am_i:02X}, but an LSM6DSOX "
            f"reads {expected} ({hint}).")

