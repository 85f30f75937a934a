"""The Microchip MCP2221A USB-I2C bridge (USB 04D8:00DD) as an :class:`I2CBus`.

Library: `EasyMCP2221 <https://pypi.org/project/EasyMCP2221/>`_ (MIT), imported only when an
``lsm6dsox://mcp2221`` device is opened or listed. Why this one: it is maintained (releases
through 2025), pure Python on top of ``hidapi`` (binary wheels for Linux, macOS and Windows),
and already does what a bare HID command layer would have to redo: long transfers cut into
the chip's 60-byte reports, write-then-read with a repeated start, recovery of a stuck I2C
engine after an error, and picking an adapter by USB serial number. PyMCP2221A (last release
2019) is not maintained; Adafruit Blinka's MCP2221 support drags in the whole Blinka stack.
Install it with ``pip install 'inclinometer[mcp2221]'`` (or ``pip install EasyMCP2221``).

Throughput and the usable ODR
-----------------------------
Each HID command is one USB full-speed report out and one back; the figure quoted for the
MCP2221A is about 100-125 I2C transactions per second, and long reads come back 60 bytes per
report. A sample costs 2 FIFO words (gyroscope, accelerometer) plus a timestamp word every 8th
slot: 2.125 words = 14.9 bytes. Taking one report exchange as the unit that is limited to
~100/s, the bridge moves about 6 kbyte/s, or about 400 samples/s; a poll costs two transfers
(FIFO status, then one burst of every word waiting), so bursts must be big: the driver polls
at most 20 times a second and reads the whole FIFO level each time. Hence
:data:`MAX_ODR_HZ` = 417 Hz is the fastest rate we promise; 833 Hz and up overrun the FIFO
(512 words, about 0.6 s at 417 Hz) on a typical host. ``force=1`` in the URL lifts the limit
for adapters and hosts that turn out faster; overruns then show as gaps.

Not tested against hardware: the tests exercise the error paths and the call mapping with a
stand-in for the library (and run the whole driver through it against the emulated chip).
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any

from drivers.errors import DeviceIOError, DeviceOpenError
from drivers.lsm6dsox_direct.bus import I2CBus

VENDOR_ID = 0x04D8
PRODUCT_ID = 0x00DD
LIBRARY = "EasyMCP2221"
INSTALL_HINT = "pip install 'inclinometer[mcp2221]' (or: pip install EasyMCP2221)"
MAX_ODR_HZ = 417.0
MIN_POLL_INTERVAL_S = 0.05
DEFAULT_SPEED_HZ = 400_000
UDEV_HINT = (
    "On Linux, let your user open the adapter's hidraw device with a udev rule, e.g. "
    "/etc/udev/rules.d/99-mcp2221.rules containing "
    'SUBSYSTEM=="hidraw", ATTRS{idVendor}=="04d8", ATTRS{idProduct}=="00dd", '
    'MODE="0660", TAG+="uaccess"; then run "sudo udevadm control --reload" and replug it.'
)


def import_library() -> ModuleType:
    """Import EasyMCP2221, or raise :class:`DeviceOpenError` saying how to install it."""
    try:
        return importlib.import_module(LIBRARY)
    except ImportError as exc:
        raise DeviceOpenError(
            f"the MCP2221A USB-I2C bridge needs the {LIBRARY} package, which is not installed "
            f"({exc}); install it with: {INSTALL_HINT}"
        ) from exc


def list_adapters() -> list[dict[str, Any]]:
    """MCP2221A adapters on USB (empty when the library is missing): serial, path, product."""
    try:
        import_library()
        hid = importlib.import_module("hid")
        found = hid.enumerate(VENDOR_ID, PRODUCT_ID)
    except (DeviceOpenError, ImportError, OSError):
        return []
    return [
        {
            "serial": str(entry.get("serial_number") or ""),
            "path": entry.get("path", b""),
            "product": str(entry.get("product_string") or "MCP2221A"),
            "index": index,
        }
        for index, entry in enumerate(found)
    ]


class Mcp2221Bus(I2CBus):
    """An MCP2221A adapter, opened by USB serial number or enumeration index.

    Parameters
    ----------
    serial : the adapter's USB serial number (None: take the ``index``-th adapter).
    index : enumeration order among MCP2221A adapters.
    speed_hz : I2C clock, 47 kHz ... 400 kHz.
    library : the EasyMCP2221 module (tests pass a stand-in); imported lazily when None.
    """

    max_read_bytes = 65535
    min_poll_interval_s = MIN_POLL_INTERVAL_S

    def __init__(
        self,
        *,
        serial: str | None = None,
        index: int = 0,
        speed_hz: int = DEFAULT_SPEED_HZ,
        library: ModuleType | None = None,
    ) -> None:
        self._lib = library if library is not None else import_library()
        which = f"serial {serial}" if serial else f"#{index}"
        try:
            self._device: Any = self._lib.Device(
                VID=VENDOR_ID, PID=PRODUCT_ID, devnum=index, usbserial=serial
            )
        except RuntimeError as exc:
            raise DeviceOpenError(
                f"no MCP2221A adapter ({which}, USB {VENDOR_ID:04X}:{PRODUCT_ID:04X}) found: "
                f"is it plugged in? ({exc})"
            ) from exc
        except OSError as exc:
            raise DeviceOpenError(
                f"the MCP2221A adapter {which} is there but could not be opened ({exc}): "
                f"another program may hold it, or you lack permission. {UDEV_HINT}"
            ) from exc
        try:
            self._device.I2C_speed(speed_hz)
        except ValueError as exc:
            raise DeviceOpenError(f"I2C speed {speed_hz} Hz: {exc}") from exc
        except (RuntimeError, OSError) as exc:
            raise DeviceOpenError(f"the MCP2221A would not set the I2C speed: {exc}") from exc
        self.serial = str(getattr(self._device, "usbserial", serial or ""))
        self.description = f"MCP2221A {self.serial or which} at {speed_hz // 1000} kHz"

    def write_register(self, address: int, register: int, data: bytes) -> None:
        self._call(address, "I2C_write", bytes([register]) + bytes(data))

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        # Register pointer without a stop, then a repeated-start read: one I2C transaction.
        self._call(address, "I2C_write", bytes([register]), kind="nonstop")
        return bytes(self._call(address, "I2C_read", length, kind="restart"))

    def close(self) -> None:
        # EasyMCP2221 keeps one handle per USB path and reuses it on the next open; dropping
        # our reference is all a close needs.
        self._device = None

    def _call(self, address: int, method: str, *args: Any, **kwargs: Any) -> Any:
        if self._device is None:
            raise DeviceIOError("the MCP2221A adapter is closed")
        errors = self._lib.exceptions
        try:
            return getattr(self._device, method)(address, *args, **kwargs)
        except errors.NotAckError as exc:
            raise DeviceIOError(
                f"no ACK from I2C address 0x{address:02X}: check the wiring, the power and the "
                "address (0x6A with SA0 low, 0x6B with SA0 high)"
            ) from exc
        except errors.TimeoutError as exc:
            raise DeviceIOError(f"I2C transfer to 0x{address:02X} timed out: {exc}") from exc
        except (errors.LowSCLError, errors.LowSDAError) as exc:
            raise DeviceIOError(
                f"the I2C bus is stuck ({type(exc).__name__}): check the pull-up resistors; a "
                "sensor stuck mid-byte needs a power cycle"
            ) from exc
        except (OSError, ValueError, RuntimeError) as exc:
            raise DeviceIOError(
                f"the MCP2221A stopped answering (unplugged?): {exc}"
            ) from exc
