"""Change the metadata of a finished recording (e.g. to store bookmarks) without touching rows."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, BinaryIO

from app.core.recording.compressed import GZIP_MAGIC, GzipBytes, gzip_member
from app.core.recording.format import KEY_BOOKMARKS, metadata_text
from app.core.recording.reader import Bookmark, read_head


def rewrite_metadata(
    path: str | os.PathLike[str], changes: Mapping[str, Any], *, remove: Iterable[str] = ()
) -> dict[str, Any]:
    """Set (or ``remove``) metadata keys of a recording; returns the new metadata.

    The file is rewritten atomically (a temporary file beside it, fsynced, then renamed); the
    header and every row are copied byte for byte. Not for a file still being recorded.
    """
    path = Path(path)
    head, chunk = read_head(path)
    metadata = dict(head.metadata)
    for key in remove:
        metadata.pop(key, None)
    metadata.update(changes)
    header_start = chunk.rfind(b"\n", 0, head.body_start - 1) + 1
    text = metadata_text(metadata)
    if head.comments:
        text += "".join(f"{comment}\n" for comment in head.comments)
    new_head = text.encode("utf-8") + chunk[header_start: head.body_start]
    fd, temp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as out, open(path, "rb") as source:
            if source.read(2) == GZIP_MAGIC:
                _copy_compressed(path, source, out, new_head, head.body_start)
            else:
                out.write(new_head)
                source.seek(head.body_start)
                shutil.copyfileobj(source, out, 1 << 20)
            out.flush()
            os.fsync(out.fileno())
        shutil.copymode(path, temp_name)  # the same permissions as before, not mkstemp's 0600
        os.replace(temp_name, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp_name)
        raise
    return metadata


def _copy_compressed(path: Path, source: BinaryIO, out: BinaryIO, new_head: bytes,
                     body_start: int) -> None:
    """A compressed recording with a new head: the rows' gzip members are copied as they are
    when they start where the rows do (as the recorder writes them), else recompressed."""
    out.write(gzip_member(new_head))
    reader = GzipBytes(source, path)
    reader.seek(body_start)
    first = reader.read(1)  # finds the member that holds the first row
    starts = {decompressed: compressed for compressed, decompressed in reader.members}
    if body_start in starts:
        source.seek(starts[body_start])
        shutil.copyfileobj(source, out, 1 << 20)
        return
    while data := first + reader.read(8 << 20):
        out.write(gzip_member(data))
        first = b""


def save_bookmarks(path: str | os.PathLike[str], bookmarks: Iterable[Bookmark]) -> None:
    """Store ``bookmarks`` as the recording's ``bookmarks`` metadata (replacing earlier ones)."""
    entries = [{"t": b.t_s, "label": b.label} for b in sorted(bookmarks, key=lambda b: b.t_s)]
    rewrite_metadata(path, {KEY_BOOKMARKS: entries})
