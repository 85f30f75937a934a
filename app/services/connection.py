"""The session's connection: open a device by URL, and after an unplug wait for the same board.

No Qt: the worker calls these methods from its thread and turns the answers into signals;
headless ``record`` (:mod:`app.services.recorder`) calls them from its loop.

- :meth:`Connection.open` / :meth:`Connection.close`: one device at a time
  (:meth:`Connection.attach` takes one opened elsewhere: headless ``record``).
- :meth:`Connection.await_board`: a board that vanished mid-session (the cable was pulled) is
  awaited by its USB serial number, on any port; :meth:`Connection.try_reconnect` looks for it.
- :meth:`Connection.continue_time_axis`: a reconnected board starts its time at 0 again; its
  samples are shifted so the session's time axis runs on, and the first one is marked as a gap.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from app.core.devices import DeviceInfo
from app.core.samples import RawBlock
from app.core.self_test import SelfTestReport
from drivers.base import Device
from drivers.errors import DeviceError
from drivers.registry import create_device

log = logging.getLogger(__name__)

NO_SELF_TEST = ("The connected device has no self-test: it needs the NUCLEO firmware or a "
                "register-level LSM6DSOX.")


class SelfTestUnavailableError(DeviceError):
    """The connected device (or no device) cannot run the sensor's self-test."""


@dataclass(slots=True)
class AwaitedBoard:
    """A board that was unplugged mid-session and is awaited back (by USB serial number)."""

    url: str
    usb_serial: str
    unique_id: str
    last_t_s: float
    """Session time of the last sample before the cable was pulled."""
    lost_at: float
    """Host clock (``time.monotonic()``) when it was lost."""
    clock_origin_s: float | None
    """The board clock at the old connection's t = 0, when the driver knows it."""


def _reconnect_url(url: str, usb_serial: str) -> str | None:
    from drivers.serial_link import reconnect_url  # only serial boards come back; pyserial

    return reconnect_url(url, usb_serial)


class Connection:
    """The open device, or the board awaited after an unplug.

    ``factory`` makes a closed device from a URL (the driver registry by default);
    ``find_board`` gives the URL of an awaited board once a port has its USB serial number.
    """

    def __init__(
        self,
        factory: Callable[[str], Device] = create_device,
        find_board: Callable[[str, str], str | None] = _reconnect_url,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._factory = factory
        self._find_board = find_board
        self._clock = clock
        self.device: Device | None = None
        self.awaited: AwaitedBoard | None = None
        self._time_offset_s = 0.0
        """Added to device time so the session's time axis runs on across reconnections."""
        self._align_time = False
        self._gap_pending = False

    @property
    def awaiting(self) -> bool:
        """True while an unplugged board is awaited."""
        return self.awaited is not None

    def open(self, url: str) -> DeviceInfo:
        """Open ``url`` (closing nothing: call :meth:`close` first). Raises DeviceError."""
        device = self._factory(url)
        info = device.open()
        self.attach(device)
        return info

    def attach(self, device: Device) -> None:
        """Take ``device``, opened elsewhere, as the connection's device (a new session time)."""
        self.device = device
        self.awaited = None
        self._time_offset_s = 0.0
        self._align_time = self._gap_pending = False

    def close(self) -> tuple[bool, bool]:
        """Close the device and stop awaiting a board: (a device was open, a board was awaited).

        A driver's error while closing is logged, never raised: the device is gone either way.
        """
        device, self.device = self.device, None
        waiting, self.awaited = self.awaited is not None, None
        if device is not None:
            try:
                device.close()
            except DeviceError as exc:
                log.warning("closing %s: %s", device.url, exc)
        return device is not None, waiting

    def await_board(self, reason: str, last_t_s: float | None) -> str | None:
        """After the device failed with ``reason``: await it back if it can return.

        It can when it has a USB serial number and samples have arrived (``last_t_s``, the
        session time of the last one, is not None). Then the device is closed and the message
        for the user is returned; otherwise nothing changes and None is returned (the caller
        closes the session).
        """
        device = self.device
        info = None if device is None else device.info
        usb_serial = None if info is None else info.extra.get("usb_serial")
        if device is None or info is None or not usb_serial or last_t_s is None:
            return None
        self.awaited = AwaitedBoard(
            url=info.url, usb_serial=str(usb_serial), unique_id=info.unique_id,
            last_t_s=last_t_s, lost_at=self._clock(), clock_origin_s=self._clock_origin(device),
        )
        self.device = None
        try:
            device.close()
        except DeviceError as exc:
            log.warning("closing %s: %s", info.url, exc)
        return (f"{reason}. The session is kept: waiting for the board (USB serial {usb_serial}) "
                "to come back on any port.")

    def try_reconnect(self) -> DeviceInfo | None:
        """Open the awaited board if it is back (same unique id); None while it is not."""
        plan = self.awaited
        if plan is None:
            return None
        url = self._find_board(plan.url, plan.usb_serial)
        if url is None:
            return None
        try:
            device = self._factory(url)
            info = device.open()
        except DeviceError as exc:  # still enumerating, or busy for a moment: try again
            log.info("reconnect to %s not yet possible: %s", url, exc)
            return None
        if info.unique_id != plan.unique_id:
            device.close()
            return None
        self.device = device
        self._align_time = True  # the new connection's time starts at 0 again
        self._gap_pending = True
        return info

    def continue_time_axis(self, raw: RawBlock) -> None:
        """Shift a reconnected board's time (in place) so the session's time keeps real time.

        The first block after a reconnection gets ``gap = True`` on its first sample.
        """
        plan = self.awaited
        if self._align_time and plan is not None:
            origin = None if self.device is None else self.device.device_clock_origin_s
            # The board's clock read clock_origin_s + last_t_s at the last sample; a clock that
            # ran on is past it now. (Comparing with the origin alone took a reset board,
            # started as late after power-on as before, for one whose clock ran on: no outage.)
            if origin is not None and plan.clock_origin_s is not None and (
                origin >= plan.clock_origin_s + plan.last_t_s
            ):
                # Same board, clock still running: its own clock spans the outage exactly.
                self._time_offset_s = float(origin) - plan.clock_origin_s
            else:  # the board was reset: measure the outage on the host's clock
                outage = self._clock() - plan.lost_at
                self._time_offset_s = plan.last_t_s + outage - float(raw.t_s[0])
            self._align_time = False
            self.awaited = None
        if self._time_offset_s:
            raw.t_s = raw.t_s + self._time_offset_s
        if self._gap_pending:
            gap = np.zeros(len(raw), dtype=bool) if raw.gap is None else raw.gap.copy()
            gap[0] = True
            raw.gap = gap
            self._gap_pending = False

    def self_test(self) -> SelfTestReport:
        """Run the sensor's self-test (about a second; streaming pauses, the pause is a gap).

        Raises :class:`SelfTestUnavailableError` when the device has none, and the driver's
        DeviceError (DeviceIOError when the board was lost) when it fails.
        """
        device = self.device
        if device is None or not device.supports_self_test:
            raise SelfTestUnavailableError(NO_SELF_TEST)
        return SelfTestReport.from_result(device.self_test())

    def _clock_origin(self, device: Device) -> float | None:
        origin = device.device_clock_origin_s
        return None if origin is None else float(origin) - self._time_offset_s
