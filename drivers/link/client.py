"""The host's side of protocol v1's request/reply traffic on one (shared) port.

:class:`LinkClient` sends commands and waits for their replies, and decodes whatever arrives
(by this device's read or by another sensor's sharing the port) into sample blocks, LOG
messages, STATUS and replies. The serial device (:mod:`drivers.serial_link`) drives the
session with it: the handshake, configuration and streaming; this module only moves packets.

Thread use: every public method is thread-safe. One condition (:attr:`LinkClient.state`)
guards the queues; the shared port's ``read_lock`` makes one thread the reader at a time,
and a thread waiting for a reply reads the port itself unless another thread is reading.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import TypeVar

import serial

from app.core.devices import BoardStatus
from app.core.samples import RawBlock
from drivers.errors import DeviceError, DeviceIOError
from drivers.link import protocol as p
from drivers.link.decoder import LinkCounters, LinkDecoder
from drivers.link.framing import encode_packet
from drivers.link.shared_port import SharedPort

log = logging.getLogger(__name__)
PacketT = TypeVar("PacketT", bound=p.Packet)

COMMAND_TIMEOUT_S = 1.0
"""How long a command waits for its ACK unless told otherwise."""
POLL_S = 0.02
"""Longest wait of one port read (the reader checks its deadline and the queues between)."""
PROBE_BYTES = 4096
"""The first bytes kept for telling another protocol (text lines, a wrong baud) apart."""
REPLY_QUEUE = 64
LOG_QUEUE = 200

ACK_MESSAGES: dict[int, str] = {
    p.ACK_BAD_ARGUMENT: "the board refused the arguments",
    p.ACK_UNSUPPORTED: "the firmware does not support this command",
    p.ACK_SENSOR_ERROR: "the sensor did not respond as expected (check the sensor board "
                        "and its connection)",
    p.ACK_BUSY: "the board is busy",
}


class LinkClient:
    """Commands out, replies and samples in, for sensor ``sensor`` of the board on ``port``.

    Attributes (read and changed under :attr:`state`): ``blocks`` (decoded sample blocks not
    yet read), ``replies`` (packets other than samples and LOGs, for :meth:`wait_for`),
    ``logs`` / ``unread_logs`` (the board's LOG messages), ``probe`` (the first bytes),
    ``board_status`` (the latest STATUS), ``link_losses`` (gaps, corrupt frames and samples
    lost on the link since they were last reported), ``streaming`` (this sensor streams),
    ``paused_while_streaming`` (a SENSOR packet that paused it), ``disconnected``.
    """

    def __init__(self, port: str, sensor: int) -> None:
        self.port = port
        self.sensor = sensor
        self.link: SharedPort | None = None
        self.decoder = LinkDecoder(sensor=sensor)
        self.state = threading.Condition()
        self.command_lock = threading.RLock()
        self.blocks: deque[RawBlock] = deque()
        self.replies: deque[p.Packet] = deque(maxlen=REPLY_QUEUE)
        self.logs: deque[p.Log] = deque(maxlen=LOG_QUEUE)
        self.unread_logs: deque[p.Log] = deque(maxlen=LOG_QUEUE)
        self.probe = bytearray()
        self.streaming = False
        self.disconnected = False
        self.board_status: BoardStatus | None = None
        self.link_losses = [0, 0, 0]  # gaps, corrupt frames, samples not yet reported
        self.paused_while_streaming: p.Sensor | None = None

    # -- the port ------------------------------------------------------------------------------
    def attach(self, opener: Callable[[], serial.SerialBase]) -> bool:
        """Open the port (or join the sensor's board already open in this program); True when
        this call opened it. Raises :class:`SensorInUse` when this sensor is open already."""
        self.disconnected = False
        self.paused_while_streaming = None
        self.link, opened = SharedPort.acquire(self.port, self.sensor, opener, self.on_data)
        return opened

    def close_port(self) -> None:
        """Let go of the port (the last user closes it)."""
        link, self.link = self.link, None
        if link is not None:
            link.release(self.on_data)

    def require_open(self) -> None:
        if self.link is None:
            raise DeviceError(f"{self.port} is not open")

    @property
    def counters(self) -> LinkCounters:
        """The decoder's statistics, a snapshot."""
        with self.state:
            return self.decoder.counters()

    # -- commands ------------------------------------------------------------------------------
    def exchange(self, packet: p.Packet, timeout_s: float) -> p.Ack:
        """Send a command and wait for its ACK (not checked)."""
        command = packet.TYPE
        self.forget(lambda r: isinstance(r, p.Ack) and r.command == command)  # stale answers
        self.send(packet)
        ack = self.wait_for(lambda pkt: isinstance(pkt, p.Ack) and pkt.command == command,
                            timeout_s)
        if ack is None:
            name = p.COMMAND_NAMES.get(command, hex(command))
            raise DeviceIOError(f"{self.port}: no ACK to {name} within {timeout_s:g} s")
        assert isinstance(ack, p.Ack)
        return ack

    def command(self, packet: p.Packet, doing: str,
                timeout_s: float = COMMAND_TIMEOUT_S) -> p.Ack:
        """Send a command; raise :class:`DeviceError` unless its ACK says ok."""
        ack = self.exchange(packet, timeout_s)
        if not ack.ok:
            raise DeviceError(ack_message(self.port, doing, ack))
        return ack

    def forget(self, match: Callable[[p.Packet], bool]) -> None:
        """Drop queued replies that ``match`` (answers to an earlier request)."""
        with self.state:
            self.replies = deque((r for r in self.replies if not match(r)),
                                 maxlen=self.replies.maxlen)

    def send(self, packet: p.Packet) -> None:
        self.write(encode_packet(packet))

    def write(self, data: bytes) -> None:
        link = self.link
        if link is None:
            raise DeviceIOError(f"{self.port} is closed")
        try:
            link.write(data)
        except serial.SerialTimeoutException as exc:
            raise DeviceIOError(f"{self.port}: writing timed out (the board does not read; "
                                f"is it hung?): {exc}") from exc
        except (serial.SerialException, OSError) as exc:
            self.disconnected = True
            raise DeviceIOError(disconnected_message(self.port, exc)) from exc

    # -- reading -------------------------------------------------------------------------------
    def pump(self) -> None:
        """Read what the port has (waiting at most :data:`POLL_S`) and decode it; every device
        sharing the port gets the bytes (:meth:`on_data`).

        Call with the shared port's ``read_lock`` held.
        """
        link = self.link
        if link is None:
            raise DeviceIOError(f"{self.port} is closed")
        try:
            link.pump(lambda exc: DeviceIOError(disconnected_message(self.port, exc)))
        except DeviceIOError:
            self.disconnected = True
            raise

    def on_data(self, data: bytes) -> None:
        """Bytes read from the port (by this client or another sharing it): decode them."""
        with self.state:
            if len(self.probe) < PROBE_BYTES:
                self.probe += data[: PROBE_BYTES - len(self.probe)]
            for packet in self.decoder.feed(data):
                if isinstance(packet, p.Log):
                    self.logs.append(packet)
                    self.unread_logs.append(packet)
                    log.log(10 + 10 * min(packet.level, 3), "%s: %s", self.port, packet.text)
                    continue
                if (isinstance(packet, p.Sensor) and packet.paused and self.streaming
                        and packet.sensor_index == self.sensor):
                    self.paused_while_streaming = packet
                if isinstance(packet, p.Status):
                    counters = self.decoder.counters()
                    self.board_status = board_status_of(
                        packet, counters.lost_samples - counters.link_lost_samples)
                self.replies.append(packet)
            for report in self.decoder.take_gap_reports():
                if report.cause == "link":
                    self.link_losses[0] += 1
                    self.link_losses[1] += report.corrupt_frames
                    self.link_losses[2] += report.lost_samples
            self.blocks.extend(self.decoder.take_blocks())
            self.state.notify_all()

    def expect(self, kind: type[PacketT], timeout_s: float,
               match: Callable[[PacketT], bool] | None = None) -> PacketT | None:
        """The first reply of type ``kind`` (and ``match``), as :meth:`wait_for`."""
        found = self.wait_for(lambda pkt: isinstance(pkt, kind) and (match is None
                                                                      or match(pkt)), timeout_s)
        return found if isinstance(found, kind) else None

    def wait_for(self, match: Callable[[p.Packet], bool], timeout_s: float) -> p.Packet | None:
        """The first reply matching ``match`` (removed from the queue), or None on timeout.

        Reads the port itself unless another thread is reading it (then waits for that
        thread to hand the reply over).
        """
        deadline = time.monotonic() + max(0.0, timeout_s)
        while True:
            with self.state:
                for index, packet in enumerate(self.replies):
                    if match(packet):
                        del self.replies[index]
                        return packet
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                link = self.link
                if link is None:
                    raise DeviceIOError(f"{self.port} is closed")
                if link.read_lock.locked():
                    self.state.wait(min(remaining, POLL_S))
                    continue
            if link.read_lock.acquire(blocking=False):
                try:
                    self.pump()
                finally:
                    link.read_lock.release()


# -- messages ---------------------------------------------------------------------------------
def board_status_of(packet: p.Status, host_gap_samples: int = 0) -> BoardStatus:
    """The app's record of a STATUS packet (``host_gap_samples``: see :class:`BoardStatus`)."""
    return BoardStatus(
        reset_cause=packet.reset_cause_text, uptime_s=packet.uptime_ms / 1000.0,
        streaming=packet.streaming, sensor_ok=packet.sensor_ok,
        clock_fallback=packet.clock_fallback,
        **{name: getattr(packet, name) for name in BoardStatus.COUNTERS
           if name != "mag_i2c_errors"},
        mag_i2c_errors=packet.mag_i2c_errors or 0,
        host_gap_samples=host_gap_samples,
    )


def disconnected_message(port: str, exc: BaseException) -> str:
    return f"{port} was disconnected (cable unplugged or board reset): {exc}"


def ack_message(port: str, doing: str, ack: p.Ack) -> str:
    """A sentence for a refused command."""
    meaning = ACK_MESSAGES.get(ack.status, f"unknown ACK status {ack.status}")
    said = f": {ack.message}" if ack.message else ""
    return f"{port}: {doing} failed, {meaning} (status {ack.status}, {ack.status_text}){said}"


__all__ = ["ACK_MESSAGES", "LinkClient", "ack_message", "board_status_of",
           "disconnected_message"]
