"""NUCLEO link protocol v1: packet types, their payloads, and builders/parsers for each.

The protocol is specified in ``docs/protocol.md`` (binding: firmware and other tools implement it
independently). This module knows payloads only; framing (CRC, COBS, the 0x00 delimiter) lives
in :mod:`drivers.link.framing` and the streaming decoder in :mod:`drivers.link.decoder`.

Every packet is a small frozen dataclass with a class attribute ``TYPE`` (the type byte), a
:meth:`payload` method (the bytes after the type byte) and a ``from_payload`` class method
that validates and raises :class:`PacketError`. :func:`parse_packet` dispatches on the type.
All integers are little-endian.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from drivers import lsm6dsox

PROTOCOL_VERSION = 1
MAX_PACKET_BYTES = 512
"""Longest decoded packet: type byte + payload + 2 CRC bytes."""
MAX_SAMPLES_PER_PACKET = 32
SAMPLE_BYTES = 12
"""One sample on the wire: gx, gy, gz, ax, ay, az as i16."""
SAMPLES_HEADER_BYTES = 9
"""seq u16, t0 u32, count u8, temperature i16."""
DEFAULT_TICK_NS = 25_000
DEFAULT_BAUD = 921_600

# Device -> host.
INFO = 0x01
CONFIG = 0x02
SAMPLES = 0x03
ACK = 0x04
SELFTEST = 0x05
LOG = 0x06
PONG = 0x07
STATUS = 0x08
"""A v1 extension: the board's health counters (docs/protocol.md, 0x08 STATUS)."""
SAMPLES_INDEXED = 0x09
"""A v1 extension: SAMPLES of sensor 1, 2, ... (sensor 0 keeps using SAMPLES)."""
SENSOR = 0x0A
"""A v1 extension: one sensor of a board with several (index, count, address, settings)."""
MAG_SAMPLES = 0x0B
"""A v1 extension: magnetometer samples, each with its own time in sensor 0's ticks."""
MAGNETOMETER = 0x0C
"""A v1 extension: the board's magnetometer (chip, address, rate, range, sensitivity)."""
MAX_SENSORS = 8
"""Sensor indexes are 0..7 (the NUCLEO firmware has two: 0x6A and 0x6B)."""
# Host -> device.
HELLO = 0x81
CONFIGURE = 0x82
START = 0x83
STOP = 0x84
SELF_TEST = 0x85
PING = 0x86
GET_STATUS = 0x87
"""A v1 extension: answered by STATUS (older firmware: ACK status 2)."""

COMMAND_NAMES: dict[int, str] = {
    HELLO: "HELLO", CONFIGURE: "CONFIGURE", START: "START", STOP: "STOP",
    SELF_TEST: "SELF_TEST", PING: "PING", GET_STATUS: "GET_STATUS",
}
PACKET_NAMES: dict[int, str] = {
    INFO: "INFO", CONFIG: "CONFIG", SAMPLES: "SAMPLES", ACK: "ACK", SELFTEST: "SELFTEST",
    LOG: "LOG", PONG: "PONG", STATUS: "STATUS", SAMPLES_INDEXED: "SAMPLES_INDEXED",
    SENSOR: "SENSOR", MAG_SAMPLES: "MAG_SAMPLES", MAGNETOMETER: "MAGNETOMETER",
    **COMMAND_NAMES,
}

# ACK status codes.
ACK_OK = 0
ACK_BAD_ARGUMENT = 1
ACK_UNSUPPORTED = 2
ACK_SENSOR_ERROR = 3
ACK_BUSY = 4
ACK_STATUS_TEXT: dict[int, str] = {
    ACK_OK: "ok",
    ACK_BAD_ARGUMENT: "bad argument",
    ACK_UNSUPPORTED: "unsupported command",
    ACK_SENSOR_ERROR: "sensor error",
    ACK_BUSY: "busy",
}

LOG_LEVELS: dict[int, str] = {0: "debug", 1: "info", 2: "warning", 3: "error"}

_SAMPLES_HEADER = struct.Struct("<HIBh")
_CONFIG = struct.Struct("<IBHI")
_INFO_HEAD = struct.Struct("<BBBBB12s")
_SELFTEST = struct.Struct("<BB3h3h")
_CONFIGURE = struct.Struct("<BBH")
_U32 = struct.Struct("<I")
_STATUS = struct.Struct("<BBB10I")
_SENSOR = struct.Struct("<BBBBIBHIB")
SENSOR_FLAG_ANSWERING = 0x01
SENSOR_FLAG_PAUSED = 0x02
"""SENSOR flags bit 1: the rate fits sensor 0 alone, so this sensor is not streamed."""

MAG_SAMPLE_BYTES = 10
"""One field sample on the wire: t u32 (sensor 0's ticks), mx, my, mz as i16."""
MAG_SAMPLES_HEADER_BYTES = 3
"""seq u16, count u8."""
MAX_MAG_SAMPLES_PER_PACKET = 32
_MAG_SAMPLES_HEADER = struct.Struct("<HB")
_MAGNETOMETER = struct.Struct("<BBBIHIBB")
MAG_FLAG_ANSWERING = 0x01
MAG_FLAG_PAUSED = 0x02
"""MAGNETOMETER flags bit 1: the accelerometer's rate leaves no room on the bus for it."""

STATUS_VERSION = 1
STATUS_VERSION_MAG = 2
"""STATUS version 2 appends mag_i2c_errors, mag_samples_read and mag_overruns (u32 each) at
offset 44."""
_STATUS_MAG = struct.Struct("<III")
RESET_CAUSES: dict[int, str] = {
    0: "unknown", 1: "power-on", 2: "reset pin", 3: "brown-out", 4: "software reset",
    5: "independent watchdog", 6: "window watchdog", 7: "low-power",
}
STATUS_FLAG_STREAMING = 0x01
STATUS_FLAG_SENSOR_OK = 0x02
STATUS_FLAG_CLOCK_FALLBACK = 0x04


class PacketError(ValueError):
    """A packet's payload does not match its type (wrong length or an impossible value)."""


class Packet(Protocol):
    """What every packet class provides."""

    TYPE: ClassVar[int]

    def payload(self) -> bytes: ...

    @classmethod
    def from_payload(cls, payload: bytes) -> Packet: ...


def _exact_length(name: str, payload: bytes, expected: int) -> None:
    if len(payload) != expected:
        raise PacketError(f"{name} payload is {len(payload)} bytes, expected {expected}")


def _text(data: bytes) -> str:
    # The CRC passed, so these are the firmware's bytes: show them even if not valid UTF-8.
    return data.decode("utf-8", errors="replace")


# -- device to host -------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Info:
    """0x01 INFO: who the device is."""

    TYPE: ClassVar[int] = INFO
    protocol_version: int
    firmware: tuple[int, int, int]
    who_am_i: int
    unique_id: bytes
    """12 bytes (the STM32's 96-bit unique device id)."""
    name: str

    def payload(self) -> bytes:
        if len(self.unique_id) != 12:
            raise PacketError(f"INFO unique_id must be 12 bytes, not {len(self.unique_id)}")
        major, minor, patch = self.firmware
        head = _INFO_HEAD.pack(
            self.protocol_version, major, minor, patch, self.who_am_i, self.unique_id
        )
        return head + self.name.encode("utf-8")

    @classmethod
    def from_payload(cls, payload: bytes) -> Info:
        if len(payload) < _INFO_HEAD.size:
            raise PacketError(f"INFO payload is {len(payload)} bytes, at least 17 expected")
        version, major, minor, patch, who_am_i, unique_id = _INFO_HEAD.unpack_from(payload)
        return cls(version, (major, minor, patch), who_am_i, unique_id,
                   _text(payload[_INFO_HEAD.size:]))

    @property
    def firmware_text(self) -> str:
        return ".".join(str(part) for part in self.firmware)

    @property
    def unique_id_hex(self) -> str:
        return self.unique_id.hex().upper()


@dataclass(frozen=True, slots=True)
class Config:
    """0x02 CONFIG: the settings in effect."""

    TYPE: ClassVar[int] = CONFIG
    odr_mhz: int
    """Output data rate actually used (trimmed), in millihertz."""
    accel_fs_g: int
    gyro_fs_dps: int
    tick_ns: int
    """Length of one timestamp tick in nanoseconds (trimmed like the ODR)."""

    def payload(self) -> bytes:
        return _CONFIG.pack(self.odr_mhz, self.accel_fs_g, self.gyro_fs_dps, self.tick_ns)

    @classmethod
    def from_payload(cls, payload: bytes) -> Config:
        _exact_length("CONFIG", payload, _CONFIG.size)
        config = cls(*_CONFIG.unpack(payload))
        if config.odr_mhz == 0 or config.tick_ns == 0:
            raise PacketError(f"CONFIG with odr_mhz={config.odr_mhz}, tick_ns={config.tick_ns}")
        if config.accel_fs_g not in lsm6dsox.ACCEL_MG_PER_LSB:
            raise PacketError(f"CONFIG accel_fs_g={config.accel_fs_g} is not 2, 4, 8 or 16")
        if config.gyro_fs_dps not in lsm6dsox.GYRO_MDPS_PER_LSB:
            raise PacketError(
                f"CONFIG gyro_fs_dps={config.gyro_fs_dps} is not 125, 250, 500, 1000 or 2000"
            )
        return config

    @property
    def odr_hz(self) -> float:
        return self.odr_mhz / 1000.0

    @property
    def tick_s(self) -> float:
        return self.tick_ns * 1e-9

    @property
    def odr_code(self) -> int:
        """The LSM6DSOX ODR code nearest to the rate in use."""
        return lsm6dsox.odr_code_for(self.odr_hz)


@dataclass(frozen=True, slots=True, eq=False)
class Samples:
    """0x03 SAMPLES: up to 32 samples.

    ``data`` is an (count, 6) int16 array of gx, gy, gz, ax, ay, az in LSB. The streaming
    decoder does not build these objects (it decodes many packets at once); they serve
    the emulator, the tests and anyone handling one packet.
    """

    TYPE: ClassVar[int] = SAMPLES
    seq: int
    t0: int
    """Device timestamp of the first sample, in ticks (wraps at 2**32)."""
    temperature_raw: int
    data: np.ndarray

    def payload(self) -> bytes:
        rows = np.asarray(self.data).reshape(-1, 6)
        count = rows.shape[0]
        if not 1 <= count <= MAX_SAMPLES_PER_PACKET:
            raise PacketError(f"SAMPLES count must be 1..32, not {count}")
        head = _SAMPLES_HEADER.pack(
            self.seq & 0xFFFF, self.t0 & 0xFFFFFFFF, count, self.temperature_raw
        )
        return head + rows.astype("<i2").tobytes()

    @classmethod
    def from_payload(cls, payload: bytes) -> Samples:
        count = samples_count(payload, 0)
        seq, t0, _, temperature = _SAMPLES_HEADER.unpack_from(payload)
        data = np.frombuffer(payload, "<i2", offset=SAMPLES_HEADER_BYTES).reshape(count, 6)
        return cls(seq, t0, temperature, data.astype(np.int16))

    @property
    def count(self) -> int:
        return int(np.asarray(self.data).reshape(-1, 6).shape[0])

    @property
    def gyro_raw(self) -> np.ndarray:
        return np.asarray(self.data).reshape(-1, 6)[:, 0:3]

    @property
    def accel_raw(self) -> np.ndarray:
        return np.asarray(self.data).reshape(-1, 6)[:, 3:6]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Samples):
            return NotImplemented
        return (self.seq, self.t0, self.temperature_raw) == (
            other.seq, other.t0, other.temperature_raw
        ) and np.array_equal(np.asarray(self.data), np.asarray(other.data))


def valid_samples_count(buffer: bytes | memoryview, offset: int) -> int:
    """The sample count of a valid SAMPLES payload at ``offset`` (the rest of ``buffer``), 0 for
    an invalid one: :func:`samples_count` without an exception, for a decoder's hot path."""
    length = len(buffer) - offset
    if length < SAMPLES_HEADER_BYTES:
        return 0
    count = buffer[offset + 6]
    valid = 1 <= count <= MAX_SAMPLES_PER_PACKET and length == (
        SAMPLES_HEADER_BYTES + SAMPLE_BYTES * count)
    return count if valid else 0


def samples_count(buffer: bytes | memoryview, offset: int, length: int | None = None) -> int:
    """Validate a SAMPLES payload at ``offset`` and return its sample count.

    ``length`` is the payload's length (default: the rest of ``buffer``).
    """
    if length is None:
        count = valid_samples_count(buffer, offset)
        if count:
            return count
    length = len(buffer) - offset if length is None else length
    if length < SAMPLES_HEADER_BYTES:
        raise PacketError(f"SAMPLES payload is {length} bytes, at least 9 expected")
    count = buffer[offset + 6]
    if not 1 <= count <= MAX_SAMPLES_PER_PACKET:
        raise PacketError(f"SAMPLES count is {count}, expected 1..32")
    expected = SAMPLES_HEADER_BYTES + SAMPLE_BYTES * count
    if length != expected:
        raise PacketError(f"SAMPLES with count {count} is {length} bytes, expected {expected}")
    return count


@dataclass(frozen=True, slots=True)
class Ack:
    """0x04 ACK: the outcome of a command."""

    TYPE: ClassVar[int] = ACK
    command: int
    status: int
    message: str = ""

    def payload(self) -> bytes:
        return bytes((self.command, self.status)) + self.message.encode("utf-8")

    @classmethod
    def from_payload(cls, payload: bytes) -> Ack:
        if len(payload) < 2:
            raise PacketError(f"ACK payload is {len(payload)} bytes, at least 2 expected")
        return cls(payload[0], payload[1], _text(payload[2:]))

    @property
    def ok(self) -> bool:
        return self.status == ACK_OK

    @property
    def status_text(self) -> str:
        return ACK_STATUS_TEXT.get(self.status, f"unknown status {self.status}")


@dataclass(frozen=True, slots=True)
class SelfTestResult:
    """0x05 SELFTEST: the sensor's self-test outcome (output change with the test force on)."""

    TYPE: ClassVar[int] = SELFTEST
    accel_pass: bool
    gyro_pass: bool
    accel_delta_mg: tuple[int, int, int]
    gyro_delta_dps: tuple[int, int, int]

    def payload(self) -> bytes:
        return _SELFTEST.pack(
            int(self.accel_pass), int(self.gyro_pass), *self.accel_delta_mg, *self.gyro_delta_dps
        )

    @classmethod
    def from_payload(cls, payload: bytes) -> SelfTestResult:
        _exact_length("SELFTEST", payload, _SELFTEST.size)
        values = _SELFTEST.unpack(payload)
        return cls(bool(values[0]), bool(values[1]), tuple(values[2:5]), tuple(values[5:8]))

    @property
    def passed(self) -> bool:
        return self.accel_pass and self.gyro_pass


@dataclass(frozen=True, slots=True)
class Log:
    """0x06 LOG: a message from the firmware (level 0 debug .. 3 error)."""

    TYPE: ClassVar[int] = LOG
    level: int
    text: str

    def payload(self) -> bytes:
        return bytes((self.level,)) + self.text.encode("utf-8")

    @classmethod
    def from_payload(cls, payload: bytes) -> Log:
        if len(payload) < 1:
            raise PacketError("LOG payload is empty, at least the level byte expected")
        return cls(payload[0], _text(payload[1:]))

    @property
    def level_name(self) -> str:
        return LOG_LEVELS.get(self.level, f"level {self.level}")


@dataclass(frozen=True, slots=True)
class Pong:
    """0x07 PONG: the answer to PING, echoing its token."""

    TYPE: ClassVar[int] = PONG
    token: int

    def payload(self) -> bytes:
        return _U32.pack(self.token)

    @classmethod
    def from_payload(cls, payload: bytes) -> Pong:
        _exact_length("PONG", payload, 4)
        return cls(_U32.unpack(payload)[0])


@dataclass(frozen=True, slots=True)
class Status:
    """0x08 STATUS (a v1 extension): the board's health counters since power-on.

    Counters are u32 and wrap; ``extra`` keeps the bytes of fields a later ``version``
    appended (not decoded here, and sent back unchanged by :meth:`payload`).
    """

    TYPE: ClassVar[int] = STATUS
    version: int
    reset_cause: int
    flags: int
    uptime_ms: int
    uart_tx_dropped_bytes: int
    uart_rx_errors: int
    i2c_errors: int
    i2c_recoveries: int
    i2c_retries: int
    fifo_overruns: int
    samples_read: int
    samples_sent: int
    watchdog_resets: int
    extra: bytes = b""

    COUNTERS: ClassVar[tuple[str, ...]] = (
        "uptime_ms", "uart_tx_dropped_bytes", "uart_rx_errors", "i2c_errors", "i2c_recoveries",
        "i2c_retries", "fifo_overruns", "samples_read", "samples_sent", "watchdog_resets",
    )

    def payload(self) -> bytes:
        return _STATUS.pack(
            self.version, self.reset_cause, self.flags,
            *(getattr(self, name) & 0xFFFFFFFF for name in self.COUNTERS),
        ) + self.extra

    @classmethod
    def from_payload(cls, payload: bytes) -> Status:
        if len(payload) < _STATUS.size:
            raise PacketError(
                f"STATUS payload is {len(payload)} bytes, at least {_STATUS.size} expected")
        values = _STATUS.unpack_from(payload)
        if values[0] == 0:
            raise PacketError("STATUS with status_version 0")
        return cls(*values, extra=bytes(payload[_STATUS.size:]))  # type: ignore[misc]

    @property
    def reset_cause_text(self) -> str:
        return RESET_CAUSES.get(self.reset_cause, f"cause {self.reset_cause}")

    @property
    def streaming(self) -> bool:
        return bool(self.flags & STATUS_FLAG_STREAMING)

    @property
    def sensor_ok(self) -> bool:
        return bool(self.flags & STATUS_FLAG_SENSOR_OK)

    @property
    def clock_fallback(self) -> bool:
        return bool(self.flags & STATUS_FLAG_CLOCK_FALLBACK)

    @property
    def mag_i2c_errors(self) -> int | None:
        """Failed I2C transfers to the magnetometer (status version 2), None before it."""
        fields = self._mag_fields()
        return None if fields is None else fields[0]

    @property
    def mag_samples_read(self) -> int | None:
        """Field samples read from the magnetometer (status version 2), None before it."""
        fields = self._mag_fields()
        return None if fields is None else fields[1]

    @property
    def mag_overruns(self) -> int | None:
        """Field samples the chip overwrote before the board read them (version 2)."""
        fields = self._mag_fields()
        return None if fields is None else fields[2]

    def _mag_fields(self) -> tuple[int, int, int] | None:
        if self.version < STATUS_VERSION_MAG or len(self.extra) < _STATUS_MAG.size:
            return None
        return _STATUS_MAG.unpack_from(self.extra)

    @staticmethod
    def mag_extra(mag_i2c_errors: int, mag_samples_read: int, mag_overruns: int = 0) -> bytes:
        """The bytes status version 2 appends (for ``extra``)."""
        return _STATUS_MAG.pack(mag_i2c_errors & 0xFFFFFFFF, mag_samples_read & 0xFFFFFFFF,
                                mag_overruns & 0xFFFFFFFF)


@dataclass(frozen=True, slots=True, eq=False)
class SamplesIndexed:
    """0x09 SAMPLES_INDEXED (a v1 extension): SAMPLES of sensor ``sensor_index`` (1..7).

    The payload is the sensor index followed by exactly a SAMPLES payload; ``seq`` counts
    this sensor's packets only. Sensor 0 is never sent this way (its data go in SAMPLES, so
    a v1 reader that skips this type still gets sensor 0 intact).
    """

    TYPE: ClassVar[int] = SAMPLES_INDEXED
    sensor_index: int
    samples: Samples

    def payload(self) -> bytes:
        if not 1 <= self.sensor_index < MAX_SENSORS:
            raise PacketError(f"SAMPLES_INDEXED sensor_index must be 1..{MAX_SENSORS - 1}, "
                              f"not {self.sensor_index}")
        return bytes((self.sensor_index,)) + self.samples.payload()

    @classmethod
    def from_payload(cls, payload: bytes) -> SamplesIndexed:
        if len(payload) < 1:
            raise PacketError("SAMPLES_INDEXED payload is empty")
        index = payload[0]
        if not 1 <= index < MAX_SENSORS:
            raise PacketError(f"SAMPLES_INDEXED sensor_index is {index}, expected "
                              f"1..{MAX_SENSORS - 1}")
        return cls(index, Samples.from_payload(payload[1:]))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SamplesIndexed):
            return NotImplemented
        return self.sensor_index == other.sensor_index and self.samples == other.samples


@dataclass(frozen=True, slots=True)
class Sensor:
    """0x0A SENSOR (a v1 extension): one sensor of the board, after CONFIG.

    Sent for every sensor (index 0 too) after INFO + CONFIG (HELLO) and after CONFIG
    (CONFIGURE). ``sensor_count`` says how many the board found; the settings are laid out
    as CONFIG's and describe this sensor's own trimmed clock.
    """

    TYPE: ClassVar[int] = SENSOR
    sensor_index: int
    sensor_count: int
    i2c_address: int
    who_am_i: int
    odr_mhz: int
    accel_fs_g: int
    gyro_fs_dps: int
    tick_ns: int
    flags: int = SENSOR_FLAG_ANSWERING

    def payload(self) -> bytes:
        return _SENSOR.pack(self.sensor_index, self.sensor_count, self.i2c_address,
                            self.who_am_i, self.odr_mhz, self.accel_fs_g, self.gyro_fs_dps,
                            self.tick_ns, self.flags)

    @classmethod
    def from_payload(cls, payload: bytes) -> Sensor:
        _exact_length("SENSOR", payload, _SENSOR.size)
        sensor = cls(*_SENSOR.unpack(payload))
        if not sensor.sensor_index < sensor.sensor_count <= MAX_SENSORS:
            raise PacketError(f"SENSOR index {sensor.sensor_index} of "
                              f"{sensor.sensor_count} sensors")
        Config.from_payload(payload[4:15])  # the same checks as CONFIG
        return sensor

    @property
    def config(self) -> Config:
        """This sensor's settings as a CONFIG."""
        return Config(self.odr_mhz, self.accel_fs_g, self.gyro_fs_dps, self.tick_ns)

    @property
    def answering(self) -> bool:
        return bool(self.flags & SENSOR_FLAG_ANSWERING)

    @property
    def paused(self) -> bool:
        """The board streams sensor 0 alone at this rate: this sensor sends no samples."""
        return bool(self.flags & SENSOR_FLAG_PAUSED)


@dataclass(frozen=True, slots=True, eq=False)
class MagSamples:
    """0x0B MAG_SAMPLES (a v1 extension): field samples of the board's magnetometer.

    ``t`` (u32, wraps) is each sample's time in ticks of sensor 0's clock (the clock of
    SAMPLES' ``t0``, CONFIG's ``tick_ns``): the magnetometer is read on the board's own
    schedule, so its samples carry their own times. ``xyz`` holds raw counts (i16).
    ``seq`` counts MAG_SAMPLES packets (+1 per packet produced, wraps at 65536).
    """

    TYPE: ClassVar[int] = MAG_SAMPLES
    seq: int
    t: np.ndarray
    """(n,) uint32 ticks."""
    xyz: np.ndarray
    """(n, 3) int16 counts."""

    def __post_init__(self) -> None:  # lists (test vectors) become arrays
        object.__setattr__(self, "t", np.asarray(self.t, dtype=np.int64).astype(np.uint32))
        object.__setattr__(self, "xyz", np.asarray(self.xyz, dtype=np.int16).reshape(-1, 3))

    def payload(self) -> bytes:
        n = int(self.t.shape[0])
        if not 1 <= n <= MAX_MAG_SAMPLES_PER_PACKET or self.xyz.shape != (n, 3):
            raise PacketError(f"MAG_SAMPLES holds 1..{MAX_MAG_SAMPLES_PER_PACKET} samples "
                              f"of 3 axes, not {self.xyz.shape}")
        rows = np.zeros(n, dtype=[("t", "<u4"), ("m", "<i2", 3)])
        rows["t"] = np.asarray(self.t, dtype=np.int64) & 0xFFFFFFFF
        rows["m"] = self.xyz
        return _MAG_SAMPLES_HEADER.pack(self.seq & 0xFFFF, n) + rows.tobytes()

    @classmethod
    def from_payload(cls, payload: bytes) -> MagSamples:
        if len(payload) < _MAG_SAMPLES_HEADER.size:
            raise PacketError(f"MAG_SAMPLES payload is {len(payload)} bytes")
        seq, count = _MAG_SAMPLES_HEADER.unpack_from(payload)
        if not 1 <= count <= MAX_MAG_SAMPLES_PER_PACKET:
            raise PacketError(f"MAG_SAMPLES count {count}, expected "
                              f"1..{MAX_MAG_SAMPLES_PER_PACKET}")
        _exact_length("MAG_SAMPLES", payload, _MAG_SAMPLES_HEADER.size + MAG_SAMPLE_BYTES * count)
        rows = np.frombuffer(payload, dtype=[("t", "<u4"), ("m", "<i2", 3)],
                             offset=_MAG_SAMPLES_HEADER.size)
        return cls(seq, rows["t"].astype(np.uint32), rows["m"].astype(np.int16))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MagSamples):
            return NotImplemented
        return (self.seq == other.seq and np.array_equal(self.t, other.t)
                and np.array_equal(self.xyz, other.xyz))


@dataclass(frozen=True, slots=True)
class Magnetometer:
    """0x0C MAGNETOMETER (a v1 extension): the board's magnetometer and its settings.

    Sent after CONFIG (and the SENSOR packets) in answer to HELLO and CONFIGURE, only by a
    board that found a magnetometer at power-on.
    """

    TYPE: ClassVar[int] = MAGNETOMETER
    chip: int
    """1 LIS3MDL, 2 LIS2MDL (:mod:`drivers.magnetometers`)."""
    i2c_address: int
    who_am_i: int
    odr_mhz: int
    range_ut: int
    pt_per_lsb: int
    """Sensitivity: picotesla per LSB."""
    mode: int
    flags: int = MAG_FLAG_ANSWERING

    def payload(self) -> bytes:
        return _MAGNETOMETER.pack(self.chip, self.i2c_address, self.who_am_i, self.odr_mhz,
                                  self.range_ut, self.pt_per_lsb, self.mode, self.flags)

    @classmethod
    def from_payload(cls, payload: bytes) -> Magnetometer:
        _exact_length("MAGNETOMETER", payload, _MAGNETOMETER.size)
        mag = cls(*_MAGNETOMETER.unpack(payload))
        if mag.chip == 0 or mag.odr_mhz == 0 or mag.range_ut == 0 or mag.pt_per_lsb == 0:
            raise PacketError("MAGNETOMETER with chip, odr_mhz, range_ut or pt_per_lsb 0")
        return mag

    @property
    def odr_hz(self) -> float:
        return self.odr_mhz / 1000.0

    @property
    def ut_per_lsb(self) -> float:
        return self.pt_per_lsb / 1e6

    @property
    def answering(self) -> bool:
        return bool(self.flags & MAG_FLAG_ANSWERING)

    @property
    def paused(self) -> bool:
        """The accelerometer's rate leaves no room on the bus: no MAG_SAMPLES are sent."""
        return bool(self.flags & MAG_FLAG_PAUSED)


# -- host to device -------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _NoPayload:
    TYPE: ClassVar[int] = 0

    def payload(self) -> bytes:
        return b""

    @classmethod
    def from_payload(cls, payload: bytes) -> _NoPayload:
        _exact_length(PACKET_NAMES[cls.TYPE], payload, 0)
        return cls()


@dataclass(frozen=True, slots=True)
class Hello(_NoPayload):
    """0x81 HELLO: the device answers INFO, then CONFIG."""

    TYPE: ClassVar[int] = HELLO


@dataclass(frozen=True, slots=True)
class Configure:
    """0x82 CONFIGURE: the device answers ACK, then CONFIG (the settings now in effect)."""

    TYPE: ClassVar[int] = CONFIGURE
    odr_code: int
    """LSM6DSOX ODR code 1..10 (12.5 ... 6667 Hz)."""
    accel_fs_g: int
    gyro_fs_dps: int

    def payload(self) -> bytes:
        return _CONFIGURE.pack(self.odr_code, self.accel_fs_g, self.gyro_fs_dps)

    @classmethod
    def from_payload(cls, payload: bytes) -> Configure:
        _exact_length("CONFIGURE", payload, _CONFIGURE.size)
        return cls(*_CONFIGURE.unpack(payload))


@dataclass(frozen=True, slots=True)
class Start(_NoPayload):
    """0x83 START: the device answers ACK, then streams SAMPLES."""

    TYPE: ClassVar[int] = START


@dataclass(frozen=True, slots=True)
class Stop(_NoPayload):
    """0x84 STOP: the device stops streaming and answers ACK."""

    TYPE: ClassVar[int] = STOP


@dataclass(frozen=True, slots=True)
class SelfTest(_NoPayload):
    """0x85 SELF_TEST: the device answers ACK, then SELFTEST."""

    TYPE: ClassVar[int] = SELF_TEST


@dataclass(frozen=True, slots=True)
class Ping:
    """0x86 PING: the device answers PONG with the same token."""

    TYPE: ClassVar[int] = PING
    token: int

    def payload(self) -> bytes:
        return _U32.pack(self.token)

    @classmethod
    def from_payload(cls, payload: bytes) -> Ping:
        _exact_length("PING", payload, 4)
        return cls(_U32.unpack(payload)[0])


@dataclass(frozen=True, slots=True)
class GetStatus(_NoPayload):
    """0x87 GET_STATUS (a v1 extension): the device answers STATUS."""

    TYPE: ClassVar[int] = GET_STATUS


PACKET_CLASSES: dict[int, type[Packet]] = {
    cls.TYPE: cls
    for cls in (Info, Config, Samples, Ack, SelfTestResult, Log, Pong, Status, SamplesIndexed,
                Sensor, MagSamples, Magnetometer, Hello, Configure, Start, Stop, SelfTest, Ping,
                GetStatus)
}
DEVICE_PACKET_TYPES = frozenset({INFO, CONFIG, SAMPLES, ACK, SELFTEST, LOG, PONG, STATUS,
                                 SAMPLES_INDEXED, SENSOR, MAG_SAMPLES, MAGNETOMETER})
HOST_PACKET_TYPES = frozenset(COMMAND_NAMES)


class UnknownPacketType(PacketError):
    """A packet type this host does not know (the protocol allows new types: ignore it)."""


def parse_packet(packet_type: int, payload: bytes) -> Packet:
    """The packet object for a type byte and its payload.

    Raises
    ------
    UnknownPacketType
        For a type not in this module.
    PacketError
        When the payload does not fit its type.
    """
    cls = PACKET_CLASSES.get(packet_type)
    if cls is None:
        raise UnknownPacketType(f"unknown packet type 0x{packet_type:02X}")
    return cls.from_payload(bytes(payload))


def describe_packet(packet: Packet) -> str:
    """A short text for logs and error messages."""
    return f"{PACKET_NAMES.get(packet.TYPE, hex(packet.TYPE))} {packet!r}"
