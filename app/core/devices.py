"""What a device says about itself: plain data shared by the drivers and every layer above.

The drivers (:mod:`drivers.base`) fill these in; the services, the GUI and the recording
metadata read them without importing a driver.
"""

from __future__ import annotations

import unicodedata
from dataclasses import dataclass, field
from typing import Any, ClassVar

SIMULATOR_REFERENCE = "the simulator's true orientation"
"""The reference source of a simulated stream (and of recordings made from one)."""


def reference_title(source: str) -> str:
    """What a view calls a stream's reference orientation: the simulator's is its truth; any
    other (a recording's motion capture, say) is a reference, measured, not known."""
    return "Simulator truth" if source == SIMULATOR_REFERENCE else "Reference"


def is_measured_reference(info: DeviceInfo) -> bool:
    """Whether ``info``'s stream carries a measured reference (a recording's motion capture),
    not the simulator's truth (a stream without a named reference is the simulator's)."""
    return bool(info.reference) and info.reference != SIMULATOR_REFERENCE


def printable(text: str) -> str:
    """``text`` safe to print on a terminal: control and format characters (escape sequences,
    carriage returns, bidirectional overrides) become ``\\xNN`` / ``\\uNNNN`` escapes.

    Everything a device says about itself is passed through this where it enters, so a
    hostile unique id cannot rewrite the user's terminal.
    """
    if text.isprintable():
        return text
    out = []
    for char in text:
        if char.isprintable() or char == " " or unicodedata.category(char) not in ("Cc", "Cf",
                                                                                 "Zl", "Zp"):
            out.append(char)
        else:
            code = ord(char)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}")
    return "".join(out)


@dataclass(frozen=True, slots=True)
class MagnetometerInfo:
    """A magnetometer beside the accelerometer: which chip and how it is set up."""

    chip: str
    """``"LIS3MDL"``, ``"LIS2MDL"``, ``"simulated"``, or what a stream or recording names."""
    odr_hz: float
    """Its own output rate (slower than the accelerometer's; rows between hold NaN)."""
    range_ut: float
    """Full scale, +-uT (LIS3MDL: 400, 800, 1200 or 1600; LIS2MDL: 4915)."""
    ut_per_lsb: float
    """The scale of its raw counts (``ScaleFactors.mag_ut_per_lsb``)."""
    address: int | None = None
    """I2C address on the sensor bus, when it sits on one."""
    mode: str = ""
    """Its operating mode as the datasheet names it (e.g. ``"ultra-high-performance"``)."""
    path: str = ""
    """How its samples reach the host (``"bus"``, ``"sensor hub"``, ``"simulated"``...)."""


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What a device says about itself once open (its texts made :func:`printable`)."""

    url: str
    name: str
    unique_id: str
    sensor: str
    odr_hz: float
    """Output data rate actually used (trimmed clock), samples per second: the real rate."""
    odr_nominal_hz: float
    """The datasheet label the rate was set by ("104 Hz" for a chip at 104.17 Hz x trim)."""
    accel_fs_g: int
    gyro_fs_dps: int
    firmware: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    magnetometer: MagnetometerInfo | None = None
    """The magnetometer beside the sensor, None without one."""
    reference: str = ""
    """What the stream's reference orientation is, when it delivers one
    (:data:`SIMULATOR_REFERENCE`, a recording's motion capture ...); empty without."""

    def __post_init__(self) -> None:
        for name in ("name", "unique_id", "sensor", "firmware"):
            value = getattr(self, name)
            if isinstance(value, str) and not value.isprintable():
                object.__setattr__(self, name, printable(value))


@dataclass(frozen=True, slots=True)
class DeviceMessage:
    """Something the device itself reported for the user (a board's LOG packet)."""

    level: int
    """0 debug, 1 info, 2 warning, 3 error."""
    text: str

    def __post_init__(self) -> None:
        if isinstance(self.text, str) and not self.text.isprintable():
            object.__setattr__(self, "text", printable(self.text))


@dataclass(frozen=True, slots=True)
class DeviceDescriptor:
    """One entry of a device listing: a URL to open and a line to show the user."""

    url: str
    description: str
    kind: str


@dataclass(frozen=True, slots=True)
class BoardStatus:
    """A board's own health counters since its power-on (link protocol v1 STATUS, 0x08).

    Counters wrap at 2**32 on the board; compare two with :meth:`rise`.
    """

    reset_cause: str
    """Why the board last started: ``power-on``, ``reset pin``, ``independent watchdog`` ..."""
    uptime_s: float
    streaming: bool
    sensor_ok: bool
    clock_fallback: bool
    """The board runs on its internal oscillator (its UART is about 2 % off)."""
    uart_tx_dropped_bytes: int
    uart_rx_errors: int
    i2c_errors: int
    i2c_recoveries: int
    i2c_retries: int
    fifo_overruns: int
    samples_read: int
    samples_sent: int
    watchdog_resets: int
    host_gap_samples: int = 0
    """Samples the host had counted lost in sequence gaps that no corrupt frame explains
    (lost on the board) when this STATUS arrived."""
    mag_i2c_errors: int = 0
    """Failed I2C transfers to the magnetometer (STATUS version 2; 0 from older boards and
    boards without one). Also counted in ``i2c_errors``."""

    COUNTERS: ClassVar[tuple[str, ...]] = (
        "uart_tx_dropped_bytes", "uart_rx_errors", "i2c_errors", "i2c_recoveries",
        "i2c_retries", "fifo_overruns", "samples_read", "samples_sent", "watchdog_resets",
        "mag_i2c_errors",
    )
    TITLES: ClassVar[dict[str, str]] = {
        "uart_tx_dropped_bytes": "UART bytes dropped", "uart_rx_errors": "UART RX errors",
        "i2c_errors": "I2C errors", "i2c_recoveries": "I2C bus recoveries",
        "i2c_retries": "I2C retries", "fifo_overruns": "Sensor FIFO overruns",
        "samples_read": "Samples read", "samples_sent": "Samples sent",
        "watchdog_resets": "Watchdog resets", "mag_i2c_errors": "Magnetometer I2C errors",
    }

    def rise(self, earlier: BoardStatus, name: str) -> int:
        """How much counter ``name`` rose since ``earlier`` (modulo 2**32, as on the board)."""
        return (getattr(self, name) - getattr(earlier, name)) % (1 << 32)

    def restarted_since(self, earlier: BoardStatus) -> bool:
        """True when the board started again between ``earlier`` and this one."""
        return self.uptime_s < earlier.uptime_s

    def as_dict(self) -> dict[str, Any]:
        """The fields as JSON-ready values (recording metadata)."""
        return {
            "reset_cause": self.reset_cause, "uptime_s": round(self.uptime_s, 3),
            "clock_fallback": self.clock_fallback,
            **{name: getattr(self, name) for name in self.COUNTERS},
        }
