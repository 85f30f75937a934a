"""The one error path of the ``inclinometer`` command.

Every sub-command ends in :func:`run_guarded`: input the command cannot use (a
:class:`CommandError`, or one of :data:`EXPECTED`: an unreadable file, a bad device URL, a
number out of range, JSON nested too deeply...) becomes one line ``inclinometer: MESSAGE`` on
stderr and exit status 2. Anything else is a bug: one line naming it and the crash log that
holds its traceback, exit status 1; with ``--debug`` or ``INCLINOMETER_DEBUG=1`` the traceback
is printed as Python prints it. Warnings are printed as one line ``inclinometer: warning: ...``.
"""

from __future__ import annotations

import contextlib
import math
import os
import stat
import sys
import tempfile
import traceback
import warnings
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

EXIT_USAGE = 2
EXIT_BUG = 1
EXIT_FAILED = 1
"""The command ran but gives no result (data that does not calibrate, a full disk)."""
DEBUG_ENV = "INCLINOMETER_DEBUG"
CRASH_LOG_NAME = "crash.log"
CRASH_LOG_MAX_BYTES = 1 << 20
MESSAGE_MAX_CHARS = 600


class CommandError(Exception):
    """Input a command cannot use, or data that gives no result: one line for the user and an
    exit status (default 2, :data:`EXIT_USAGE`). ``command`` names the sub-command in the
    line (``inclinometer calibrate: MESSAGE``) for the commands that always did."""

    def __init__(self, message: str, code: int = EXIT_USAGE, command: str = "") -> None:
        super().__init__(message)
        self.code = code
        self.command = command


def _expected() -> tuple[type[BaseException], ...]:
    from app.core.calibration_procedures.profiles import ProfileError
    from app.core.recording.errors import RecordingError
    from drivers.errors import DeviceError

    return (CommandError, RecordingError, DeviceError, ProfileError, OSError, ValueError,
            OverflowError, RecursionError, MemoryError)


def debug_wanted(flag: bool = False) -> bool:
    """True with ``--debug`` (``flag``) or ``INCLINOMETER_DEBUG`` set (not 0)."""
    return flag or os.environ.get(DEBUG_ENV, "").strip() not in ("", "0")


_CONTROL = {c: f"\\x{c:02x}" for c in [*range(0x20), 0x7F, *range(0x80, 0xA0)]}


def printable(value: object) -> str:
    """``value`` as text with control characters (terminal escape sequences, carriage
    returns, newlines) shown as ``\\xNN``: text from a device or a file never drives the
    terminal."""
    return str(value).translate(_CONTROL)


def one_line(exc: BaseException) -> str:
    """The exception's message on one line, bounded; the kind of error when it has none."""
    if isinstance(exc, RecursionError):
        return "the input is nested too deeply to read"
    if isinstance(exc, MemoryError):
        return "the input is too large to process in memory"
    if isinstance(exc, OSError) and exc.strerror:
        where = exc.filename if exc.filename is not None else ""
        text = f"{where}: {exc.strerror}" if where else exc.strerror
    elif "int_max_str_digits" in str(exc):
        text = "a number has more digits than can be read (over 4300)"
    else:
        text = str(exc) or type(exc).__name__
    text = printable(" ".join(text.split()))
    if len(text) > MESSAGE_MAX_CHARS:
        text = text[:MESSAGE_MAX_CHARS] + "..."
    return text


def crash_log_path() -> Path:
    """Where the traceback of an unexpected error is kept (user log folder)."""
    import platformdirs

    return Path(platformdirs.user_log_dir("Inclinometer", appauthor=False)) / CRASH_LOG_NAME


def _log_crash(argv: list[str]) -> Path | None:
    """Append the current traceback to the crash log (kept under a megabyte)."""
    try:
        path = crash_log_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.exists() and path.stat().st_size > CRASH_LOG_MAX_BYTES:
            path.unlink()
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        with path.open("a", encoding="utf-8") as log:
            log.write(f"--- {stamp} inclinometer {' '.join(argv)[:2000]}\n")
            log.write(traceback.format_exc())
        return path
    except OSError:
        return None


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one line, without Python's source line."""
    text = " ".join(str(message).split())
    with contextlib.suppress(OSError, ValueError):
        print(f"inclinometer: warning: {text}", file=file or sys.stderr)


def install_warning_format() -> None:
    """Print every warning as ``inclinometer: warning: MESSAGE`` (numpy's overflow and NaN
    warnings included)."""
    warnings.showwarning = _show_warning


def run_guarded(command: Callable[[], int], argv: list[str], debug: bool = False) -> int:
    """Run ``command``; return its exit status, or the status of the error it raised
    (``argv`` goes into the crash log; ``debug``: let every error through, traceback and
    all)."""
    try:
        return command()
    except KeyboardInterrupt:
        print("inclinometer: interrupted", file=sys.stderr)
        return 130
    except _expected() as exc:
        if debug_wanted(debug):
            raise
        where = f"inclinometer {exc.command}" if isinstance(exc, CommandError) and (
            exc.command) else "inclinometer"
        print(f"{where}: {one_line(exc)}", file=sys.stderr)
        return exc.code if isinstance(exc, CommandError) else EXIT_USAGE
    except Exception as exc:
        if debug_wanted(debug):
            raise
        log = _log_crash(argv)
        where = (f"the traceback is in {log}" if log is not None
                 else "the traceback could not be saved")
        print(f"inclinometer: internal error ({type(exc).__name__}: {one_line(exc)}); "
              f"{where}; --debug or {DEBUG_ENV}=1 prints it", file=sys.stderr)
        return EXIT_BUG


def finite(value: float, option: str, *, minimum: float | None = None,
           positive: bool = False, maximum: float | None = None) -> float:
    """``value`` if it is a finite number within the bounds, else CommandError naming
    ``option``."""
    if not math.isfinite(value):
        raise CommandError(f"{option} must be a finite number, not {value!r}")
    if positive and not value > 0:
        raise CommandError(f"{option} must be positive, not {value:g}")
    if minimum is not None and value < minimum:
        raise CommandError(f"{option} must be at least {minimum:g}, not {value:g}")
    if maximum is not None and value > maximum:
        raise CommandError(f"{option} must be at most {maximum:g}, not {value:g}")
    return value


def check_regular_file(path: str | os.PathLike[str]) -> None:
    """CommandError for an existing path that is not a regular file: a pipe such as
    ``<(cat a.csv)``, a device, a folder (a recording is read twice: head, then rows)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return  # the reader says what is wrong with a missing or unnamable file
    if not stat.S_ISREG(mode):
        kind = ("a folder" if stat.S_ISDIR(mode) else "a pipe" if stat.S_ISFIFO(mode)
                else "a device or socket")
        raise CommandError(f"{path}: {kind}, not a regular file; save the recording to a "
                           "file first")


def check_output_folder(path: str | os.PathLike[str], option: str) -> None:
    """CommandError unless a file can be created in the folder ``path`` goes into (tried
    with an empty temporary file, removed at once: permissions alone do not tell, e.g. for
    root or on a read-only file system)."""
    folder = Path(path).expanduser().absolute().parent
    if not folder.is_dir():
        raise CommandError(f"{option} {path}: no such directory {str(folder)!r}")
    try:
        handle, probe = tempfile.mkstemp(dir=folder, prefix=".inclinometer-", suffix=".probe")
    except OSError as exc:
        raise CommandError(f"{option} {path}: the folder {str(folder)!r} cannot be written "
                           f"({exc.strerror or exc})") from None
    os.close(handle)
    with contextlib.suppress(OSError):
        os.unlink(probe)
