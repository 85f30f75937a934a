"""Read a v1 recording: metadata, columns, and clear errors for anything else.

:func:`read_recording` loads a whole file (an hour at 1 kHz in a few seconds: the numbers are
parsed by :mod:`app.core.recording.fast_csv` on every core) and returns a :class:`Recording`;
a compressed recording (format v1 inside gzip, ``.csv.gz``) is read the same way. To read a
long recording in bounded memory, use :class:`app.core.recording.stream.RecordingStream`.

What it tolerates, and says so (a :class:`~app.core.recording.errors.RecordingWarning`, and
the message in :attr:`Recording.warnings`):

- an incomplete last row (no line end: the writer was killed mid-row): dropped;
- a metadata value that is not JSON: kept as its text;
- blank lines, ``\\r\\n`` line ends, spaces around fields, a UTF-8 byte-order mark;
- unknown columns: kept in :attr:`Recording.columns` (numbers, or text when not numbers),
  ignored otherwise.

What it refuses, with a typed error: a file that is not a recording
(:class:`NotARecordingError`), another format version (:class:`RecordingVersionError`), a header
without the required columns (:class:`MissingColumnsError`), and a row that cannot be read
(:class:`RecordingCorruptError`, which names the line and carries the rows before it).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from app.core.recording.stream import read_stream
from app.core.recording.table import UNIT_SCALE, Bookmark, Recording
from app.core.recording.text_parse import (
    GAP_PERIODS,
    MAX_JUMPS_NAMED,
    MAX_LOAD_BYTES,
    MAX_LOAD_VALUES,
    MAX_WARNINGS,
    Buffer,
    OnCorrupt,
    RecordingHead,
    TimeCheck,
    column_kind,
    count_lines,
    parse_fast,
    parse_head,
    parse_slow,
    read_head,
    read_head_from,
    row_chunks,
)

__all__ = [
    "GAP_PERIODS", "MAX_JUMPS_NAMED", "MAX_LOAD_BYTES", "MAX_LOAD_VALUES", "MAX_WARNINGS",
    "UNIT_SCALE", "Bookmark", "Recording", "RecordingHead", "TimeCheck", "parse_recording",
    "read_head", "read_head_from", "read_metadata", "read_recording", "row_chunks",
]

from app.core.bounded_input import open_regular
from app.core.recording.compressed import (
    GZIP_MAGIC,
)
from app.core.recording.errors import (
    RecordingCorruptError,
    RecordingError,
    RecordingTooLargeError,
    RecordingWarning,
)

CHUNKED_MIN_BYTES = 8 << 20
"""Files at least this large (and every compressed one) are read in chunks, never mapped:
another program may shorten a file while it is read, which a memory map turns into a bus
error, and the text of a large file need not be in memory all at once."""
# -- reading ---------------------------------------------------------------------------------------
def read_recording(
    path: str | os.PathLike[str], *, on_corrupt: OnCorrupt = "raise",
    max_bytes: int | None = MAX_LOAD_BYTES, max_values: int = MAX_LOAD_VALUES,
) -> Recording:
    """Load a recording file.

    Parameters
    ----------
    path : the CSV file (a regular file: a FIFO or a device is refused, never waited on).
    on_corrupt : ``"raise"`` (default): a row that cannot be read raises
        :class:`RecordingCorruptError` (with the line number, and the rows before it in
        ``partial``); ``"truncate"``: keep the rows before it, warn, and set
        :attr:`Recording.corrupt_line`.
    max_bytes : refuse (:class:`RecordingTooLargeError`) a recording whose text, decompressed,
        is longer than this (None: no limit but ``max_values``; blank lines count here only).
    max_values : refuse a recording of more numbers than this (rows times columns), so memory
        stays bounded whatever the file (a small ``.csv.gz`` may expand a thousandfold).

    Raises
    ------
    RecordingError
        Subclasses for a foreign file, another version, missing columns, a corrupt row or a
        recording over the limits; a plain :class:`RecordingError` when the file cannot be
        read at all (or becomes shorter while it is read).
    """
    path = Path(path)
    try:
        with open_regular(path) as handle:
            size = os.fstat(handle.fileno()).st_size
            small = handle.read(2) != GZIP_MAGIC and size < CHUNKED_MIN_BYTES
            if small:
                handle.seek(0)
                data = handle.read(CHUNKED_MIN_BYTES)
                small = len(data) < CHUNKED_MIN_BYTES  # else it grew meanwhile: chunks
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read the recording: {exc.strerror or exc}",
                             path) from exc
    if not small:
        return read_stream(path, on_corrupt=on_corrupt, max_bytes=max_bytes,
                           max_values=max_values)
    if len(data) < size:
        raise RecordingError(f"{path}: the file became shorter while it was read (another "
                             "program is rewriting it); nothing was loaded", path)
    if max_bytes is not None and len(data) > max_bytes:
        raise RecordingTooLargeError(
            f"{path}: the recording is larger than {max_bytes} bytes", path)
    recording = parse_recording(data, path, on_corrupt=on_corrupt)
    if len(recording) * len(recording.header) > max_values:
        raise RecordingTooLargeError(
            f"{path}: the recording holds more than {max_values} numbers", path)
    return recording


def read_metadata(path: str | os.PathLike[str]) -> tuple[dict[str, Any], tuple[str, ...]]:
    """Only the metadata and the header (reads the beginning of the file; for listings)."""
    head, _ = read_head(Path(path))
    return head.metadata, head.header


def parse_recording(
    data: Buffer, path: Path | None = None, *, on_corrupt: OnCorrupt = "raise"
) -> Recording:
    """:func:`read_recording` on bytes already in memory."""
    if on_corrupt not in ("raise", "truncate"):
        raise ValueError(f"on_corrupt must be 'raise' or 'truncate', not {on_corrupt!r}")
    head = parse_head(data, path)
    where = f"{path}: " if path is not None else ""
    problems = list(head.warnings)
    stop = data.rfind(b"\n") + 1
    stop = max(stop, head.body_start)
    dropped = False
    tail = data[stop:]
    if tail.strip(b" \t\r\x00"):
        line = head.header_line + count_lines(data, head.body_start, stop) + 1
        problems.append(
            f"{where}line {line}: the last row is incomplete (the recording was interrupted "
            "while writing it); it was dropped")
        dropped = True
    kinds = np.array([column_kind(name) for name in head.header], dtype=np.int8)
    parse = parse_slow if data.find(b'"', head.body_start, stop) >= 0 else parse_fast
    columns, rows, error, offsets = parse(data, head.body_start, stop, head.header, kinds)
    clock = TimeCheck.for_metadata(head.metadata)
    bad = clock.first_out_of_order(columns["t"])
    if bad is not None:  # before any row the parser could not read
        error = (int(offsets[bad]), clock.disorder_text(columns["t"], bad))
        columns = {name: values[:bad] for name, values in columns.items()}
        rows = bad
    named = clock.mark_jumps(columns)
    for row, text in named:
        line = count_lines(data, 0, int(offsets[row])) + 1
        problems.append(f"{where}line {line}: {text}")
    if clock.jumps > len(named):
        problems.append(f"{where}{clock.jumps} unmarked jumps in t in all were marked as gaps")
    recording = Recording(
        metadata=head.metadata, header=head.header, columns=columns, path=path,
        warnings=problems, dropped_partial_row=dropped, comments=head.comments,
    )
    if error is not None:
        offset, message = error
        line = count_lines(data, 0, offset) + 1
        text = f"{where}line {line}: {message}; the {rows} row(s) before it are valid"
        if on_corrupt == "raise":
            _warn_all(problems)
            raise RecordingCorruptError(text, path, line, recording)
        recording.corrupt_line = line
        problems.append(f"{text}; reading stopped there")
    _warn_all(problems)
    return recording


def _warn_all(messages: list[str]) -> None:
    for message in messages:
        warnings.warn(message, RecordingWarning, stacklevel=4)


