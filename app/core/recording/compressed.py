"""Recording bytes from a plain file or from gzip (one or more members), read sequentially.

The recorder writes compressed recordings as one gzip member per durable write, so every
member start is a place to begin decompressing (:meth:`GzipBytes.seek`), and a file cut short
by a crash holds whole members and at most one partial one, read up to where it stops.
"""

from __future__ import annotations

import bisect
import os
import zlib
from pathlib import Path
from typing import BinaryIO

from app.core.recording.errors import RecordingCorruptError

READ_BYTES = 1 << 20
"""Compressed bytes read from the file at a time."""
GZIP_MAGIC = b"\x1f\x8b"
OUTPUT_BYTES = 4 << 20
"""Decompressed bytes produced at a time (memory stays bounded whatever the ratio)."""


def is_compressed(path: str | os.PathLike[str]) -> bool:
    """True when the file starts like gzip (whatever its name)."""
    with open(path, "rb") as handle:
        return handle.read(2) == GZIP_MAGIC


class PlainBytes:
    """A plain file's bytes, read sequentially, with seeking."""

    def __init__(self, handle: BinaryIO) -> None:
        self._handle = handle
        self.truncated = False

    def read(self, size: int) -> bytes:
        return self._handle.read(size)

    def seek(self, offset: int) -> None:
        self._handle.seek(offset)


class GzipBytes:
    """The decompressed bytes of a gzip file of one or more members.

    ``members`` lists ``(compressed offset, decompressed offset)`` of every member start seen
    so far; :meth:`seek` starts at the last member at or before the offset asked for.
    ``truncated`` becomes True when the file ends inside a member (a crash mid-write): what
    that member held up to there is still delivered.
    """

    def __init__(self, handle: BinaryIO, path: Path) -> None:
        self._handle = handle
        self._path = path
        self.members: list[tuple[int, int]] = [(0, 0)]
        self.truncated = False
        self._start(0, 0)

    def _start(self, compressed: int, decompressed: int) -> None:
        self._handle.seek(compressed)
        self._decompressor = zlib.decompressobj(31)
        self._consumed = compressed  # compressed bytes handed to a decompressor so far
        self._produced = decompressed
        self._pending = b""
        self._eof = False

    def _more(self) -> bool:
        """Decompress more into ``_pending``; False at the end of the file."""
        while not self._pending:
            if self._decompressor.eof:
                rest = self._decompressor.unused_data
                start = self._consumed - len(rest)
                if not rest:
                    rest = self._handle.read(READ_BYTES)
                    if not rest:
                        self._eof = True
                        return False
                    self._consumed += len(rest)
                    start = self._consumed - len(rest)
                if self.members[-1][0] < start:
                    self.members.append((start, self._produced))
                self._decompressor = zlib.decompressobj(31)
                data = rest
            elif self._decompressor.unconsumed_tail:  # input held back by the bound below
                data = self._decompressor.unconsumed_tail
            else:
                data = self._handle.read(READ_BYTES)
                if not data:
                    self.truncated = True
                    self._eof = True
                    return False
                self._consumed += len(data)
            try:
                # At most this much output per call: 1 MB of gzip can expand to 1 GB.
                self._pending = self._decompressor.decompress(data, OUTPUT_BYTES)
            except zlib.error as exc:
                raise RecordingCorruptError(
                    f"{self._path}: the compressed data is damaged near byte "
                    f"{self._consumed - len(data)} ({exc})", self._path) from None
        return True

    def read(self, size: int) -> bytes:
        parts: list[bytes] = []
        wanted = size
        while wanted > 0 and (self._pending or (not self._eof and self._more())):
            piece, self._pending = self._pending[:wanted], self._pending[wanted:]
            parts.append(piece)
            wanted -= len(piece)
            self._produced += len(piece)  # before _more() notes where a next member starts
        return b"".join(parts)

    def seek(self, offset: int) -> None:
        index = bisect.bisect_right([d for _, d in self.members], offset) - 1
        compressed, decompressed = self.members[max(index, 0)]
        self._start(compressed, decompressed)
        skip = offset - decompressed
        while skip > 0:
            got = len(self.read(min(skip, READ_BYTES * 8)))
            if not got:
                break
            skip -= got


def decompress_file(path: Path, limit: int | None = None) -> tuple[bytes, bool]:
    """The decompressed bytes of a gzip file (at most about ``limit`` of them), and whether the
    file ended inside a member (a crash mid-write: what it held is included)."""
    with open(path, "rb") as handle:
        reader = GzipBytes(handle, path)
        parts = []
        total = 0
        while limit is None or total < limit:
            data = reader.read(8 << 20)
            if not data:
                break
            parts.append(data)
            total += len(data)
        return b"".join(parts), reader.truncated


def gzip_member(data: bytes, level: int = 1) -> bytes:
    """``data`` as one complete gzip member (zlib level 1: fast, about 40 % of plain CSV)."""
    packer = zlib.compressobj(level, zlib.DEFLATED, 31)
    return packer.compress(data) + packer.flush(zlib.Z_FINISH)


def byte_source(handle: BinaryIO, path: Path) -> PlainBytes | GzipBytes:
    """The recording's bytes from an open file: decompressed when it starts like gzip."""
    compressed = handle.read(2) == GZIP_MAGIC
    handle.seek(0)
    return GzipBytes(handle, path) if compressed else PlainBytes(handle)
