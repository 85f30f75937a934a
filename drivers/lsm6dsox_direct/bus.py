"""The small I2C bus interface the register-level driver talks through.

A backend implements three methods (register writes, auto-increment burst reads, close) and
may override the two time methods: an emulated bus runs on its own clock, so tests need no
sleeps, and a real bus uses the wall clock.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod


class I2CBus(ABC):
    """An I2C master that can write and burst-read the registers of a target.

    Backends raise :class:`drivers.errors.DeviceIOError` when a transfer fails (no ACK, the
    adapter unplugged), with a message for the user.

    Attributes
    ----------
    max_read_bytes : the longest single read the backend supports; the driver splits FIFO
        bursts to fit.
    description : one line for the user ("MCP2221A 0123456 at 400 kHz").
    min_poll_interval_s : the shortest pause between FIFO polls (slow bridges raise it).
    """

    max_read_bytes: int = 65535
    description: str = "I2C bus"
    min_poll_interval_s: float = 0.0

    @abstractmethod
    def write_register(self, address: int, register: int, data: bytes) -> None:
        """Write ``data`` to consecutive registers from ``register`` of the 7-bit ``address``."""

    @abstractmethod
    def read_registers(self, address: int, register: int, length: int) -> bytes:
        """Read ``length`` bytes from ``register`` on (register address auto-increments)."""

    @abstractmethod
    def close(self) -> None:
        """Release the adapter; safe to call twice."""

    def monotonic(self) -> float:
        """The bus's clock in seconds (the wall clock for real hardware)."""
        return time.monotonic()

    def delay(self, seconds: float) -> None:
        """Wait ``seconds`` on the bus's clock."""
        if seconds > 0.0:
            time.sleep(seconds)
