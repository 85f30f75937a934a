"""Serial ports: listing with USB identities, a guess of what is attached, and clear errors.

Real ports come from ``serial.tools.list_ports``. Emulated boards served on pseudo-terminals
(:mod:`drivers.emulated_nucleo`) register themselves here with the USB identity a real board
would have, so discovery and reconnect-by-USB-serial work the same way for them: in this
process, and, for ``inclinometer simulate --pty`` in another terminal, through a small file
per board in a per-user temporary folder (removed when the board stops; stale ones are
ignored).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import json
import os
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

from drivers.errors import DeviceOpenError

ST_VID = 0x0483
MCP2221_VID_PID = (0x04D8, 0x00DD)
STM32_CDC_VID_PID = (ST_VID, 0x5740)

KNOWN_USB_DEVICES: dict[tuple[int, int], tuple[str, str]] = {
    (ST_VID, 0x374B): ("nucleo", "ST-LINK/V2-1 virtual COM port (a NUCLEO board)"),
    (ST_VID, 0x374E): ("nucleo", "ST-LINK/V3 virtual COM port (a NUCLEO board)"),
    (ST_VID, 0x374F): ("nucleo", "ST-LINK/V3 virtual COM port (a NUCLEO board)"),
    (ST_VID, 0x3752): ("nucleo", "STLINK-V3 virtual COM port (a NUCLEO board)"),
    (ST_VID, 0x3753): ("nucleo", "STLINK-V3 virtual COM port (a NUCLEO board)"),
    STM32_CDC_VID_PID: ("nucleo", "STM32 native USB CDC (firmware on the board's own USB)"),
    MCP2221_VID_PID: ("mcp2221", "MCP2221A USB-I2C/UART bridge (its UART side)"),
}
"""(VID, PID) -> (kind, description)."""

TEXT_BOARD_VIDS: dict[int, str] = {
    0x2341: "Arduino", 0x2A03: "Arduino", 0x239A: "Adafruit", 0x1A86: "CH340 USB-serial",
    0x10C4: "CP210x USB-serial", 0x0403: "FTDI USB-serial", 0x2E8A: "Raspberry Pi Pico",
    0x303A: "Espressif", 0x1B4F: "SparkFun",
}
"""Vendors whose boards usually run sketches that print text lines."""

HINTS: dict[str, str] = {
    "nucleo": "protocol v1 firmware expected",
    "mcp2221": "open the sensor on its I2C bus with the LSM6DSOX direct driver instead",
    "text": "a sketch printing text lines, probably",
    "usb": "a USB serial device: protocol v1 or text lines are detected on connection",
    "serial": "a serial port: protocol v1 or text lines are detected on connection",
    "emulated": "emulated NUCLEO on a pseudo-terminal (protocol v1)",
}


@dataclass(frozen=True, slots=True)
class SerialPortInfo:
    """One serial port and, for USB ports, who made it."""

    device: str
    description: str = ""
    vid: int | None = None
    pid: int | None = None
    serial_number: str | None = None
    manufacturer: str | None = None
    product: str | None = None
    emulated: bool = False

    @property
    def vid_pid(self) -> str:
        """``"0483:374B"``, or ``""`` for a port that is not USB."""
        if self.vid is None or self.pid is None:
            return ""
        return f"{self.vid:04X}:{self.pid:04X}"

    @property
    def kind(self) -> str:
        """nucleo, mcp2221, text, usb, serial or emulated (see :data:`HINTS`)."""
        if self.emulated:
            return "emulated"
        if self.vid is not None and self.pid is not None:
            known = KNOWN_USB_DEVICES.get((self.vid, self.pid))
            if known is not None:
                return known[0]
            return "text" if self.vid in TEXT_BOARD_VIDS else "usb"
        return "serial"

    @property
    def guess(self) -> str:
        """What is probably attached, in words."""
        if self.vid is not None and self.pid is not None:
            known = KNOWN_USB_DEVICES.get((self.vid, self.pid))
            if known is not None:
                return f"{known[1]}: {HINTS[known[0]]}"
            if self.vid in TEXT_BOARD_VIDS:
                return f"{TEXT_BOARD_VIDS[self.vid]} board: {HINTS['text']}"
        return HINTS[self.kind]

    def summary(self) -> str:
        """One line for device lists."""
        parts = []
        if self.vid_pid:
            parts.append(f"USB {self.vid_pid}")
        if self.serial_number:
            parts.append(f"serial {self.serial_number}")
        if self.description and self.description != "n/a":
            parts.append(self.description)
        parts.append(self.guess)
        return ", ".join(parts)


_virtual_lock = threading.Lock()
_virtual_ports: dict[str, SerialPortInfo] = {}


def shared_ports_folder() -> Path:
    """Where boards served by other processes of this user announce their ports."""
    user = os.getuid() if hasattr(os, "getuid") else os.getlogin()
    return Path(tempfile.gettempdir()) / f"inclinometer-{user}" / "emulated-ports"


def _shared_file(device: str) -> Path:
    return shared_ports_folder() / (device.strip("/").replace("/", "_") + ".json")


def register_virtual_port(info: SerialPortInfo, *, shared: bool = False) -> None:
    """Make an emulated board's port visible to listing and lookup.

    With ``shared``, other processes of this user see it too (``inclinometer simulate``).
    """
    with _virtual_lock:
        _virtual_ports[info.device] = info
    if shared:
        path = _shared_file(info.device)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"port": dataclasses.asdict(info), "process": os.getpid()}))


def unregister_virtual_port(device: str) -> None:
    with _virtual_lock:
        _virtual_ports.pop(device, None)
    with contextlib.suppress(OSError, ValueError):
        path = _shared_file(device)
        if json.loads(path.read_text()).get("process") == os.getpid():
            path.unlink()


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, but another user's
        return True
    return True


def _shared_ports() -> list[SerialPortInfo]:
    found = []
    try:
        paths = sorted(shared_ports_folder().glob("*.json"))
    except OSError:
        return []
    for path in paths:
        try:
            entry = json.loads(path.read_text())
            pid = int(entry["process"])
            info = SerialPortInfo(**entry["port"])
        except (OSError, ValueError, TypeError, KeyError):
            continue
        if pid == os.getpid():
            continue
        if _process_alive(pid) and os.path.exists(info.device):
            found.append(info)
        else:  # left behind by a board that was killed
            with contextlib.suppress(OSError):
                path.unlink()
    return found


def list_serial_ports() -> list[SerialPortInfo]:
    """Every serial port present now: real ones first, then emulated ones."""
    from serial.tools import list_ports

    found = [
        SerialPortInfo(
            device=port.device, description=port.description or "", vid=port.vid,
            pid=port.pid, serial_number=port.serial_number, manufacturer=port.manufacturer,
            product=port.product,
        )
        for port in sorted(list_ports.comports(), key=lambda port: port.device)
    ]
    with _virtual_lock:
        found.extend(_virtual_ports.values())
    found.extend(_shared_ports())
    return found


def _same_port(a: str, b: str) -> bool:
    if sys.platform == "win32":
        return a.upper().removeprefix("\\\\.\\") == b.upper().removeprefix("\\\\.\\")
    return a == b or os.path.realpath(a) == os.path.realpath(b)


def port_info(port: str) -> SerialPortInfo | None:
    """The listing entry of ``port`` (a device path, a by-id link or a COM name), if any."""
    with _virtual_lock:
        virtual = _virtual_ports.get(port)
    if virtual is not None:
        return virtual
    if "://" in port:  # loop://, spy://...: no USB identity
        return None
    for info in list_serial_ports():
        if _same_port(info.device, port):
            return info
    return None


def find_port_by_serial(usb_serial: str) -> str | None:
    """The port whose USB serial number is ``usb_serial`` now (None when absent).

    The operating system may give a replugged board another port name; its USB serial
    number stays.
    """
    wanted = usb_serial.strip().upper()
    for info in list_serial_ports():
        if info.serial_number and info.serial_number.strip().upper() == wanted:
            return info.device
    return None


# -- open errors ----------------------------------------------------------------------------
def udev_rule(info: SerialPortInfo | None) -> str:
    """A udev rule line giving the logged-in user (and the dialout group) the port."""
    if info is not None and info.vid is not None and info.pid is not None:
        match = f'ATTRS{{idVendor}}=="{info.vid:04x}", ATTRS{{idProduct}}=="{info.pid:04x}"'
    else:
        match = f'ATTRS{{idVendor}}=="{ST_VID:04x}"'
    return f'SUBSYSTEM=="tty", {match}, MODE="0660", GROUP="dialout", TAG+="uaccess"'


def _port_group(port: str) -> str | None:
    try:
        import grp

        return grp.getgrgid(os.stat(port).st_gid).gr_name
    except (ImportError, OSError, KeyError):
        return None


def permission_denied_message(port: str, info: SerialPortInfo | None = None,
                              group: str | None = None) -> str:
    """What to do when the OS refuses access to ``port`` (Linux wording)."""
    group = group or _port_group(port) or "dialout"
    also = "" if group == "dialout" else f" (here the port belongs to the group '{group}')"
    return (
        f"Permission denied opening {port}. On Linux, serial ports belong to the 'dialout' "
        f"group{also}: add yourself with `sudo usermod -aG {group} $USER`, then log out and "
        "in again. Or install a udev rule: put the line\n"
        f"    {udev_rule(info)}\n"
        "into /etc/udev/rules.d/99-inclinometer.rules, run `sudo udevadm control "
        "--reload-rules && sudo udevadm trigger`, and replug the board."
    )


def processes_holding(port: str) -> list[str]:
    """Programs that have ``port`` open, as ``"name (pid N)"`` (Linux; else empty)."""
    if not os.path.isdir("/proc/self/fd"):
        return []
    target = os.path.realpath(port)
    holders = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
            if not any(os.readlink(f"/proc/{pid}/fd/{fd}") == target for fd in fds):
                continue
            with open(f"/proc/{pid}/comm", encoding="utf-8", errors="replace") as comm:
                name = comm.read().strip()
        except OSError:
            continue
        holders.append(f"this program (pid {pid})" if int(pid) == os.getpid()
                       else f"{name} (pid {pid})")
    return holders


def port_busy_message(port: str, holders: list[str] | None = None) -> str:
    """What to say when another program (or another connection) has ``port``."""
    holders = processes_holding(port) if holders is None else holders
    who = f" (open in: {', '.join(holders)})" if holders else ""
    return (
        f"{port} is busy: another program or connection has it open{who}. Close the other "
        "program (a serial monitor, screen, minicom, the Arduino IDE, another Inclinometer "
        "window) or the other connection, then try again."
    )


def missing_port_message(port: str) -> str:
    ports = list_serial_ports()
    if not ports:
        return (f"There is no serial port {port}, and no serial ports at all: is the board "
                "plugged in?")
    listing = "; ".join(f"{info.device} ({info.summary()})" for info in ports)
    return f"There is no serial port {port}. Ports present now: {listing}."


def open_error(port: str, exc: BaseException) -> DeviceOpenError:
    """Turn pyserial's exception on opening ``port`` into a clear :class:`DeviceOpenError`."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if sys.platform == "win32" and ("Access is denied" in text or "PermissionError" in text):
        return DeviceOpenError(port_busy_message(port, []))  # Windows says so for a port in use
    if code in (errno.EACCES, errno.EPERM):
        return DeviceOpenError(permission_denied_message(port, port_info(port)))
    if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or "exclusively lock" in text:
        return DeviceOpenError(port_busy_message(port))
    if code in (errno.ENOENT, errno.ENODEV, errno.ENXIO) or "FileNotFoundError" in text:
        return DeviceOpenError(missing_port_message(port))
    return DeviceOpenError(f"Could not open {port}: {text}")
