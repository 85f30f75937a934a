"""Reading input files with bounds: regular files only, never blocking, never unbounded.

Every file the program reads that someone else may have made (settings, the measurement log,
calibration profiles, session manifests, arm layouts, recordings) goes through here:

- :func:`open_regular` opens without blocking (a FIFO with no writer would otherwise hang the
  ``open`` for ever) and refuses anything that is not a regular file (a FIFO, ``/dev/zero``,
  a character device, a folder) with :class:`NotRegularFileError`;
- :func:`read_bounded` reads at most a given number of bytes and refuses a larger file with
  :class:`InputTooLargeError` (both are ``OSError``, as any read failure);
- :func:`loads_json` / :func:`load_json` decode JSON with its nesting depth, size and integer
  digits capped and NaN / Infinity refused, raising :class:`JsonInputError` (a ``ValueError``)
  with a one-line reason. Python's own decoder recurses: JSON nested a few thousand deep
  exhausts the stack, so the depth is checked by a linear scan before decoding.
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import stat
from pathlib import Path
from typing import Any, BinaryIO

MAX_JSON_BYTES = 16 << 20
"""Largest JSON document read (settings, logs and profiles take kilobytes)."""
MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects accepted (the program writes at most 5)."""
MAX_INT_DIGITS = 40
"""Longest integer accepted, in digits (a 64-bit number has 20)."""


class _InputOSError(OSError):
    """An ``OSError`` whose text is just its reason (no ``[Errno N]``)."""

    def __str__(self) -> str:
        return str(self.strerror)


class NotRegularFileError(_InputOSError):
    """The path names a FIFO, a device, a socket or a folder, not a regular file."""


class InputTooLargeError(_InputOSError):
    """The file is larger than the reader accepts."""


class JsonInputError(ValueError):
    """The text is not JSON within the bounds (depth, size, integer digits, finite numbers)."""


def _kind(mode: int) -> str:
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def open_regular(path: str | os.PathLike[str]) -> BinaryIO:
    """``path`` opened for binary reading, if it is a regular file.

    Opened with ``O_NONBLOCK`` (so a FIFO never blocks the open) and checked with ``fstat``
    on the open descriptor (no race with a rename); the flag is cleared again for a regular
    file. Raises :class:`NotRegularFileError` or the ``OSError`` of the open.
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    fd = os.open(path, flags | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotRegularFileError(
                errno.EINVAL, f"it is {_kind(mode)}, not a regular file; only files are read")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bounded(path: str | os.PathLike[str], max_bytes: int) -> bytes:
    """The whole of a regular file of at most ``max_bytes`` bytes.

    Raises :class:`NotRegularFileError`, :class:`InputTooLargeError` (never reading more than
    ``max_bytes + 1`` bytes, whatever ``st_size`` claims) or the ``OSError`` of the read.
    """
    with open_regular(path) as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise InputTooLargeError(
            errno.EFBIG, f"the file is larger than {max_bytes} bytes, more than such a file "
            "ever holds")
    return data


# Strings (with their escapes) or brackets: what the depth scan must tell apart.
_TOKENS = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"?|[\[\]{}]')


def json_depth_problem(data: bytes, max_depth: int = MAX_JSON_DEPTH) -> str | None:
    """Why ``data`` nests deeper than ``max_depth`` (None: it does not). Linear in its length."""
    depth = 0
    for match in _TOKENS.finditer(data):
        token = match.group()
        if token in (b"[", b"{"):
            depth += 1
            if depth > max_depth:
                return f"it is nested more than {max_depth} deep"
        elif token in (b"]", b"}"):
            depth -= 1
    return None


def _parse_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise JsonInputError(f"it holds an integer of {digits} digits (at most "
                             f"{MAX_INT_DIGITS} are accepted)")
    return int(text)


def _parse_float(text: str) -> float:
    if len(text) > 100:
        raise JsonInputError(f"it holds a number of {len(text)} characters")
    value = float(text)
    if not math.isfinite(value):
        raise JsonInputError(f"it holds a number out of range ({text[:30]})")
    return value


def _parse_constant(text: str) -> float:
    raise JsonInputError(f"it holds {text}, which JSON does not allow")


def loads_json(data: str | bytes, *, max_bytes: int = MAX_JSON_BYTES,
               max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Decode JSON text within the bounds; :class:`JsonInputError` says why it is refused."""
    raw = data.encode("utf-8", errors="surrogatepass") if isinstance(data, str) else data
    if len(raw) > max_bytes:
        raise JsonInputError(f"it is {len(raw)} bytes long, more than the {max_bytes} accepted")
    problem = json_depth_problem(raw, max_depth)
    if problem:
        raise JsonInputError(problem)
    try:
        text = raw.decode("utf-8") if isinstance(data, bytes) else data
    except UnicodeDecodeError as exc:
        raise JsonInputError(f"it is not UTF-8 text (byte {exc.start})") from None
    try:
        return json.loads(text, parse_int=_parse_int, parse_float=_parse_float,
                          parse_constant=_parse_constant)
    except JsonInputError:
        raise
    except RecursionError:  # the scan above makes this unreachable; kept as a last guard
        raise JsonInputError("it is nested too deeply to read") from None
    except ValueError as exc:  # JSONDecodeError, or int() past Python's digit limit
        raise JsonInputError(f"it is not valid JSON ({exc})") from None


def load_json(path: str | os.PathLike[str], *, max_bytes: int = MAX_JSON_BYTES,
              max_depth: int = MAX_JSON_DEPTH) -> Any:
    """A JSON file read with :func:`read_bounded` and decoded with :func:`loads_json`.

    Raises ``OSError`` (including :class:`NotRegularFileError`, :class:`InputTooLargeError`)
    when it cannot be read, :class:`JsonInputError` when it is not bounded JSON.
    """
    return loads_json(read_bounded(Path(path), max_bytes), max_bytes=max_bytes,
                      max_depth=max_depth)
