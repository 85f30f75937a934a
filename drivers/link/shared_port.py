"""One serial port shared by the device objects of several sensors on one board.

A NUCLEO with two LSM6DSOX streams both over one port (docs/protocol.md, "Several sensors on
one board"). The app opens each sensor as a device of its own (``serial://PORT`` and
``serial://PORT?sensor=1``), with its own pipeline and worker; the port, though, can be open
only once. :class:`SharedPort` is that one open port: reference-counted (the first device
opens it, the last one to close closes it), with one reader at a time. Whatever the reader
gets goes to every attached device, each of which decodes the same bytes with a decoder of
its own sensor (sequence numbers and clocks are per sensor, so nothing else is shared).

    link = SharedPort.acquire(name, open_port, on_data)   # opens, or joins an open port
    link.pump()                                           # read once, hand to every user
    link.release(on_data)                                 # True when it closed the port
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable

import serial

from drivers.errors import DeviceIOError

DataListener = Callable[[bytes], None]


class SensorInUse(Exception):
    """The sensor asked for already has a device on this port (one device per sensor)."""

_REGISTRY: dict[str, SharedPort] = {}
"""Open ports by name."""
_REGISTRY_LOCK = threading.Lock()


class SharedPort:
    """An open serial port and the devices using it (see the module docstring)."""

    def __init__(self, name: str, port: serial.SerialBase) -> None:
        self.name = name
        self.port = port
        self.read_lock = threading.Lock()
        """Held by the one thread reading the port; the others wait for its hand-over."""
        self.write_lock = threading.Lock()
        self.streaming = False
        """The board was told START by a user (a device joining then does not restart it)."""
        self.error: DeviceIOError | None = None
        """Set when the port failed (unplugged): every user's next read raises it."""
        self._listeners: list[DataListener] = []
        self._sensors: dict[int, DataListener] = {}

    # -- sharing ------------------------------------------------------------------------------
    @classmethod
    def acquire(cls, name: str, sensor: int, open_port: Callable[[], serial.SerialBase],
                listener: DataListener) -> tuple[SharedPort, bool]:
        """The open port called ``name`` (opened with ``open_port`` when nobody has it) and
        whether this call opened it; ``listener`` (the device of ``sensor``) receives every
        byte read from now on. Raises :class:`SensorInUse` when that sensor has a device."""
        with _REGISTRY_LOCK:
            link = _REGISTRY.get(name)
            opened = link is None or link.error is not None
            if not opened and sensor in link._sensors:  # type: ignore[union-attr]
                raise SensorInUse(f"sensor {sensor} of {name} is open already")
            if opened:
                link = cls(name, open_port())
                _REGISTRY[name] = link
            assert link is not None
            link._listeners.append(listener)
            link._sensors[sensor] = listener
            return link, opened

    def release(self, listener: DataListener) -> bool:
        """Detach ``listener``; the last one closes the port (returns True then)."""
        with _REGISTRY_LOCK:
            with contextlib.suppress(ValueError):
                self._listeners.remove(listener)
            self._sensors = {k: v for k, v in self._sensors.items() if v != listener}
            if self._listeners:
                return False
            if _REGISTRY.get(self.name) is self:
                del _REGISTRY[self.name]
        with contextlib.suppress(serial.SerialException, OSError):
            self.port.close()
        return True

    @property
    def users(self) -> int:
        with _REGISTRY_LOCK:
            return len(self._listeners)

    # -- I/O ----------------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        """Write to the board (raises the port's own exceptions)."""
        with self.write_lock:
            self.port.write(data)

    def pump(self, on_error: Callable[[BaseException], DeviceIOError]) -> None:
        """Read what the port has (call with :attr:`read_lock` held) and hand it to every
        user. A failed read makes ``on_error``'s exception for every user, and raises it."""
        if self.error is not None:
            raise self.error
        try:
            waiting = self.port.in_waiting
            data = self.port.read(waiting or 1)
            if data and not waiting and self.port.in_waiting:
                data += self.port.read(self.port.in_waiting)
        except (serial.SerialException, OSError) as exc:
            self.error = on_error(exc)
            raise self.error from exc
        if not data:
            return
        with _REGISTRY_LOCK:
            listeners = list(self._listeners)
        for listener in listeners:
            listener(data)
