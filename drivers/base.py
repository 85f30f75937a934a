"""The device interface every driver implements (a template method, as in python-can).

The public :meth:`Device.open`, :meth:`Device.read` and :meth:`Device.close` do the bookkeeping
(state checks, error typing); a driver overrides only ``_open``, ``_read`` and ``_close``.

The descriptions a device gives of itself (:class:`DeviceInfo`, :class:`DeviceDescriptor`,
:class:`DeviceMessage`) are plain data in :mod:`app.core.devices`, so that layers above the
drivers can name them without importing a driver; they are re-exported here.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, ClassVar

from app.core.devices import BoardStatus, DeviceDescriptor, DeviceInfo, DeviceMessage
from app.core.samples import RawBlock
from drivers.errors import DeviceClosedError, DeviceError, DeviceIOError
from drivers.url_options import Option

if TYPE_CHECKING:
    from app.core.calibration import SensorCalibration
    from app.core.recording.reader import Recording

__all__ = ["Device", "DeviceDescriptor", "DeviceInfo", "DeviceMessage", "read_block_s"]

MIN_BLOCK_SAMPLES = 10
"""A streaming read gathers at least this many samples ..."""
MIN_BLOCK_S, MAX_BLOCK_S = 0.02, 0.1
"""... but waits no less than MIN_BLOCK_S and no longer than MAX_BLOCK_S for them."""


def read_block_s(odr_hz: float) -> float:
    """How much data a streaming read waits for at ``odr_hz``: ten samples, within 20 to
    100 ms. The host's cost is mostly per block (a board sends a packet every 2 ms, one or
    two samples at low rates), while the display scrolls on between blocks and a tilt
    meter's averages span half a second: 96 ms at 104 Hz, 24 ms at 417 Hz, 20 ms above."""
    if not odr_hz > 0:
        return MIN_BLOCK_S
    return min(MAX_BLOCK_S, max(MIN_BLOCK_S, MIN_BLOCK_SAMPLES / odr_hz))


class Device(ABC):
    """A source of :class:`~app.core.samples.RawBlock` s, named by a URL.

    Thread use: one thread opens, reads and closes a device. Only methods documented as
    thread-safe (such as a simulator's live controls) may be called from other threads.
    """

    scheme: ClassVar[str] = ""
    url_options: ClassVar[tuple[Option, ...]] = ()
    """The options this driver's URLs take, as data (:mod:`drivers.url_options`)."""

    @classmethod
    def options_for(cls, url: str = "") -> tuple[Option, ...]:
        """The options ``url`` may take (a driver whose options depend on the rest of the URL,
        such as the simulator's scenario, overrides this); :attr:`url_options` by default."""
        return cls.url_options

    def __init__(self, url: str) -> None:
        self.url = url
        self._info: DeviceInfo | None = None
        self._lock = threading.Lock()

    # -- public template methods -------------------------------------------------------------
    def open(self) -> DeviceInfo:
        """Open the device and return its description; raises :class:`DeviceOpenError`."""
        if self._info is not None:
            return self._info
        self._info = self._open()
        return self._info

    def read(self, timeout_s: float) -> RawBlock | None:
        """Return the next block, or None when nothing arrived within ``timeout_s``."""
        if self._info is None:
            raise DeviceClosedError(f"{self.url} is not open")
        try:
            return self._read(timeout_s)
        except DeviceError:
            raise
        except OSError as exc:
            raise DeviceIOError(f"{self.url}: {exc}") from exc

    def close(self) -> None:
        """Close the device; safe to call twice."""
        if self._info is None:
            return
        try:
            self._close()
        finally:
            self._info = None

    def take_messages(self) -> list[DeviceMessage]:
        """Messages the device reported since the last call, oldest first (default: none).

        Call from the thread that reads.
        """
        return []

    # -- optional capabilities ----------------------------------------------------------------
    # Declared here with the answer of a device that lacks them (as python-can's BusABC
    # declares its optional methods), so that callers ask every device the same question
    # instead of probing with getattr or testing URL schemes; a driver that has one overrides.

    # replayable: a recording played back as a device (drivers/replay.py)
    replayable: ClassVar[bool] = False
    """The device plays a recording back (seek, speed, bookmarks: :mod:`drivers.replay`)."""
    recording: Recording | None = None
    """The recording a replay plays (None for live devices, and before a replay opened)."""

    @property
    def at_end(self) -> bool:
        """True when the source delivered everything it has and will deliver nothing more
        (a replay at its end that does not loop). A live device never ends."""
        return False

    @property
    def last_block_generation(self) -> int | None:
        """A count that changes when the source jumps (a replay's seek or loop), read right
        after :meth:`read`: time runs backwards there. None for sources that never jump."""
        return None

    @property
    def recorded_calibration(self) -> SensorCalibration | None:
        """The calibration a replayed recording was made with (None: none, or live)."""
        return None

    # steerable: a simulator the program can tilt
    steerable: ClassVar[bool] = False
    """Devices of this kind take live controls (a simulator's panel in the window)."""

    @property
    def is_steerable(self) -> bool:
        """True when :meth:`set_target_attitude` can move this device now."""
        return False

    def set_target_attitude(self, roll_deg: float, pitch_deg: float,
                            yaw_deg: float = 0.0) -> float:
        """Tilt the device to an attitude; returns the glide time (s). Thread-safe."""
        raise DeviceError(f"{self.url}: cannot be tilted from the program")

    # knows its truth: the true orientation (and a simulated unit's true errors)
    knows_truth: ClassVar[bool] = False
    """Devices of this kind deliver their true orientation with every block (a simulator);
    a replay's recording may hold one too: ask :attr:`reference_source`."""
    unit_errors: Any = None
    """A simulated unit's true errors (``drivers.sim.error_model.UnitErrors``), what a
    calibration should find; None for real hardware."""

    def truth_metadata(self) -> dict[str, Any]:
        """What a recording's ``simulator`` metadata holds for this device (a simulated unit's
        true errors, its true rate, injected faults, the earth's field...); empty for devices
        that know no truth of their own."""
        return {}

    @property
    def reference_source(self) -> str | None:
        """What the blocks' ``reference_quat`` is, for a recording's metadata; None when the
        device delivers no reference orientation."""
        return None

    @classmethod
    def unpaced_url(cls, url: str) -> str:
        """The URL of the same source read as fast as it computes, where the driver can
        (a simulator without real-time pacing); others return ``url`` unchanged."""
        return url

    # has a board clock (and health counters)
    @property
    def device_clock_origin_s(self) -> float | None:
        """The board clock's reading where ``t_s`` is 0 (a reconnected board carries its time
        on by it); None for devices without a clock of their own."""
        return None

    @property
    def board_status(self) -> BoardStatus | None:
        """The board's latest health counters (link protocol v1 STATUS); None for devices
        without them. Thread-safe."""
        return None

    def request_status(self) -> BoardStatus | None:
        """The board's counters now (asked for where the device can; by default the latest
        it sent). Raises DeviceError when asking fails."""
        return self.board_status

    # runs a self-test
    @property
    def supports_self_test(self) -> bool:
        """Whether :meth:`self_test` runs the sensor's own self-test (default: no).

        Drivers that have one return an object with ``accel_pass``, ``gyro_pass``,
        ``accel_delta_mg`` and ``gyro_delta_dps``.
        """
        return False

    def self_test(self) -> Any:
        """Run the sensor's self-test (streaming pauses). Raises DeviceError without one."""
        raise DeviceError(f"{self.url}: the device has no self-test")

    @property
    def info(self) -> DeviceInfo | None:
        """The open device's description, None while closed."""
        return self._info

    @property
    def is_open(self) -> bool:
        return self._info is not None

    def __enter__(self) -> Device:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- what drivers implement -------------------------------------------------------------
    @classmethod
    def discover(cls) -> list[DeviceDescriptor]:
        """Devices of this kind that could be opened now (default: none to list)."""
        return []

    @abstractmethod
    def _open(self) -> DeviceInfo: ...

    @abstractmethod
    def _read(self, timeout_s: float) -> RawBlock | None: ...

    @abstractmethod
    def _close(self) -> None: ...
