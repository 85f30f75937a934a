"""What a device says about itself: plain data shared by the drivers and every layer above.

The drivers (:mod:`drivers.base`) fill these in; the services, the GUI and the recording
metadata read them without importing a driver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What a device says about itself once open."""

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


@dataclass(frozen=True, slots=True)
class DeviceMessage:
    """Something the device itself reported for the user (a board's LOG packet)."""

    level: int
    """0 debug, 1 info, 2 warning, 3 error."""
    text: str


@dataclass(frozen=True, slots=True)
class DeviceDescriptor:
    """One entry of a device listing: a URL to open and a line to show the user."""

    url: str
    description: str
    kind: str
