"""Serial ports: listing with USB identities, a guess of what is attached, and clear errors.

Real ports come from ``serial.tools.list_ports``. Emulated boards served on pseudo-terminals
(:mod:`drivers.emulated_nucleo`) register themselves here with the USB identity a real board
would have, so discovery and reconnect-by-USB-serial work the same way for them: in this
process, and, for ``inclinometer simulate --pty`` in another terminal, through a small file
per board in this user's private runtime folder (:func:`runtime_folder`: owner and mode
checked, files written atomically without following links; removed when the board stops;
stale entries, and entries naming a process or a port that is not this user's, are ignored).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import json
import os
import secrets
import stat
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

from app.core.devices import printable
from drivers.errors import DeviceError, DeviceOpenError

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

    def __post_init__(self) -> None:
        for name in ("description", "serial_number", "manufacturer", "product"):
            value = getattr(self, name)
            if isinstance(value, str) and not value.isprintable():  # USB strings: the device's
                object.__setattr__(self, name, printable(value))

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


RUNTIME_FOLDER_MODE = 0o700
MAX_ENTRY_BYTES = 16 << 10
"""An announcement is a few hundred bytes; anything larger is not ours."""


class RuntimeFolderError(DeviceError):
    """The private folder for files shared between this user's processes is not safe."""


def _uid() -> int:
    return os.getuid()


def _check_private(path: Path, info: os.stat_result) -> str:
    """Why ``info`` (an lstat of ``path``) is not a private folder of ours; "" when it is."""
    if stat.S_ISLNK(info.st_mode):
        return f"{path} is a symbolic link"
    if not stat.S_ISDIR(info.st_mode):
        return f"{path} is not a folder"
    if info.st_uid != _uid():
        return f"{path} belongs to another user (uid {info.st_uid})"
    if stat.S_IMODE(info.st_mode) != RUNTIME_FOLDER_MODE:
        return f"{path} is open to others (mode {stat.S_IMODE(info.st_mode):o}, not 700)"
    return ""


def _private_folder(path: Path, *, create: bool) -> Path:
    """``path`` as a folder that only we can write (made 0700 when ``create``); raises
    RuntimeFolderError when it exists but is not ours, or is a link, or is open to others."""
    if create:
        with contextlib.suppress(FileExistsError):
            os.mkdir(path, RUNTIME_FOLDER_MODE)
    try:
        info = os.lstat(path)
        if (stat.S_ISDIR(info.st_mode) and info.st_uid == _uid()
                and not info.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
                and stat.S_IMODE(info.st_mode) != RUNTIME_FOLDER_MODE):
            # Ours and writable by us alone (e.g. 755 from an older version): nobody else
            # can have put anything in it, so closing it to others is safe.
            os.chmod(path, RUNTIME_FOLDER_MODE, follow_symlinks=False)
            info = os.lstat(path)
    except (OSError, NotImplementedError) as exc:
        raise RuntimeFolderError(f"the runtime folder {path} cannot be used: "
                                 f"{getattr(exc, 'strerror', None) or exc}") from None
    why = _check_private(path, info)
    if why:
        raise RuntimeFolderError(
            f"refusing to use the runtime folder: {why}. It may have been planted by another "
            f"user; remove it (or set XDG_RUNTIME_DIR to a private folder) and try again.")
    return path


def runtime_folder(*, create: bool = True) -> Path:
    """This user's private folder for files shared between its processes.

    ``$XDG_RUNTIME_DIR/inclinometer`` when XDG_RUNTIME_DIR is set, ours and mode 0700; else
    ``<temp>/inclinometer-<uid>``, created mode 0700. Either is checked (lstat: ours, not a
    link, mode 0700); one that is not raises :class:`RuntimeFolderError`.
    """
    if not hasattr(os, "getuid"):  # Windows: the per-user temporary folder is private
        folder = Path(tempfile.gettempdir()) / "inclinometer"
        if create:
            folder.mkdir(exist_ok=True)
        return folder
    base = os.environ.get("XDG_RUNTIME_DIR", "")
    if base and os.path.isabs(base):
        with contextlib.suppress(OSError):
            if not _check_private(Path(base), os.lstat(base)):
                return _private_folder(Path(base) / "inclinometer", create=create)
    return _private_folder(Path(tempfile.gettempdir()) / f"inclinometer-{_uid()}",
                           create=create)


def shared_ports_folder(*, create: bool = True) -> Path:
    """Where boards served by other processes of this user announce their ports (private,
    checked: see :func:`runtime_folder`)."""
    if not hasattr(os, "getuid"):  # pseudo-terminals, hence emulated boards: Linux and macOS
        raise RuntimeFolderError("emulated boards are shared on Linux and macOS only")
    return _private_folder(runtime_folder(create=create) / "emulated-ports", create=create)


def _entry_name(device: str) -> str:
    return device.strip("/").replace("/", "_") + ".json"


def _open_folder(folder: Path) -> int:
    """An fd of the checked folder: every later step works relative to it (no re-resolving)."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_NOFOLLOW", 0)
    fd = os.open(folder, flags)
    why = _check_private(folder, os.fstat(fd))
    if why:
        os.close(fd)
        raise RuntimeFolderError(f"refusing to use the runtime folder: {why}")
    return fd


def register_virtual_port(info: SerialPortInfo, *, shared: bool = False) -> None:
    """Make an emulated board's port visible to listing and lookup.

    With ``shared``, other processes of this user see it too (``inclinometer simulate``): a
    small file in the private runtime folder, written atomically (a new file made with
    O_EXCL | O_NOFOLLOW, then renamed), never through a link. Raises
    :class:`RuntimeFolderError` when that folder is not safe.
    """
    if shared:
        _write_entry(info)
    with _virtual_lock:
        _virtual_ports[info.device] = info


def _write_entry(info: SerialPortInfo) -> None:
    data = json.dumps({"port": dataclasses.asdict(info), "process": os.getpid()}).encode()
    folder = _open_folder(shared_ports_folder())
    try:
        name = _entry_name(info.device)
        temporary = f".{name}.{secrets.token_hex(4)}.tmp"
        flags = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                 | getattr(os, "O_CLOEXEC", 0))
        fd = os.open(temporary, flags, 0o600, dir_fd=folder)
        try:
            with os.fdopen(fd, "wb") as handle:
                handle.write(data)
            os.replace(temporary, name, src_dir_fd=folder, dst_dir_fd=folder)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(temporary, dir_fd=folder)
            raise
    except OSError as exc:
        raise RuntimeFolderError(f"cannot announce {info.device} in the runtime folder: "
                                 f"{exc.strerror or exc}") from None
    finally:
        os.close(folder)


def _read_entry(folder: int, name: str) -> dict | None:
    """An announcement, read without following links, only from a regular file of ours."""
    flags = (os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
             | getattr(os, "O_CLOEXEC", 0))
    try:
        fd = os.open(name, flags, dir_fd=folder)
    except OSError:
        return None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_uid != _uid() or (
                info.st_size > MAX_ENTRY_BYTES):
            return None
        entry = json.loads(os.read(fd, MAX_ENTRY_BYTES))
    except (OSError, ValueError):
        return None
    finally:
        os.close(fd)
    return entry if isinstance(entry, dict) else None


def unregister_virtual_port(device: str) -> None:
    with _virtual_lock:
        _virtual_ports.pop(device, None)
    try:
        folder = _open_folder(shared_ports_folder(create=False))
    except (OSError, DeviceError):
        return
    try:
        name = _entry_name(device)
        entry = _read_entry(folder, name)
        if entry is not None and entry.get("process") == os.getpid():
            with contextlib.suppress(OSError):
                os.unlink(name, dir_fd=folder)
    finally:
        os.close(folder)


def _process_ours(pid: int) -> bool:
    """``pid`` is a live process of this user."""
    if pid <= 0:
        return False
    if os.path.isdir("/proc/self"):
        try:
            return os.stat(f"/proc/{pid}").st_uid == _uid()
        except OSError:
            return False
    try:
        os.kill(pid, 0)
    except OSError:  # gone, or another user's (EPERM)
        return False
    return True


def _pty_ours(device: str) -> bool:
    """``device`` is a pseudo-terminal that this user owns (what an emulated board serves)."""
    real = os.path.realpath(device)
    if not (real.startswith("/dev/pts/") or real.startswith("/dev/ttys")):
        return False
    try:
        info = os.stat(real)
    except OSError:
        return False
    return stat.S_ISCHR(info.st_mode) and info.st_uid == _uid()


def _shared_ports() -> list[SerialPortInfo]:
    """Ports announced by this user's other processes; entries naming a process or a port
    that is not ours are ignored (and stale ones of ours removed)."""
    try:
        folder = _open_folder(shared_ports_folder(create=False))
    except (OSError, DeviceError):
        return []
    found = []
    try:
        names = sorted(n for n in os.listdir(folder) if n.endswith(".json"))
        for name in names:
            entry = _read_entry(folder, name)
            try:
                pid = int(entry["process"])  # type: ignore[index]
                info = SerialPortInfo(**entry["port"])  # type: ignore[index]
                if not isinstance(info.device, str) or name != _entry_name(info.device):
                    continue
            except (ValueError, TypeError, KeyError):
                continue
            if pid == os.getpid():
                continue
            if _process_ours(pid) and _pty_ours(info.device):
                found.append(info)
            elif not _process_ours(pid):  # left behind by a board of ours that was killed
                with contextlib.suppress(OSError):
                    os.unlink(name, dir_fd=folder)
    except OSError:
        return found
    finally:
        os.close(folder)
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
