"""Typed recording errors; each message names the file and, where it helps, the line."""

from __future__ import annotations

from pathlib import Path
from typing import Any


class RecordingError(Exception):
    """A recording could not be read or written; ``path`` is the file concerned (if any)."""

    def __init__(self, message: str, path: Path | None = None) -> None:
        super().__init__(message)
        self.path = path


class NotARecordingError(RecordingError):
    """The file does not start with ``# inclinometer-recording``."""


class RecordingVersionError(RecordingError):
    """The file is a recording of another format version."""

    def __init__(self, message: str, path: Path | None, version: str) -> None:
        super().__init__(message, path)
        self.version = version


class MissingColumnsError(RecordingError):
    """The header lacks required columns (``missing`` lists them)."""

    def __init__(self, message: str, path: Path | None, missing: list[str]) -> None:
        super().__init__(message, path)
        self.missing = missing


class RecordingCorruptError(RecordingError):
    """A line could not be read.

    Attributes
    ----------
    line : 1-based line number in the file (None when the problem is not one line).
    partial : the rows before the bad line, as a :class:`~app.core.recording.reader.Recording`
        (None when the problem is before the first sample). Load it on purpose with
        ``read_recording(path, on_corrupt="truncate")``. Typed ``Any`` because the reader
        imports these errors, and the errors must not import the reader back.
    """

    def __init__(
        self, message: str, path: Path | None, line: int | None = None,
        partial: Any = None,
    ) -> None:
        super().__init__(message, path)
        self.line = line
        self.partial = partial


class RecordingTooLargeError(RecordingError):
    """The recording holds more than the reader was asked to load at once (it can still be
    read in chunks, :class:`~app.core.recording.stream.RecordingStream`)."""


class RecordingWriteError(RecordingError):
    """A recording could not be started (the file exists, the folder is missing, ...)."""


class RecordingWarning(UserWarning):
    """Something was skipped while reading (an incomplete last row, a bad metadata line)."""
