"""The closing metadata of a finished recording (alarm crossings, fault events, the board's
closing counters): stored in the file in one atomic rewrite, or, when that cannot be done (a
full disk: the rewrite needs room for a copy of the file), kept beside it, never lost.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from app.core.recording.errors import RecordingError
from app.core.safe_output import write_output

CLOSING_SUFFIX = ".closing.json"


def closing_metadata_path(path: str | os.PathLike[str]) -> Path:
    """Where the closing metadata goes when it cannot be written into the recording."""
    path = Path(path)
    return path.with_name(path.name + CLOSING_SUFFIX)


def store_closing_metadata(path: str | os.PathLike[str], closing: Mapping[str, Any],
                           what: str, kept: str = "its rows were kept") -> str:
    """Write ``closing`` into the recording ``path`` (one atomic rewrite); returns "".

    When the rewrite fails, the file stays as it was and ``closing`` goes to
    ``NAME.closing.json`` beside it (``{"recording": NAME, "metadata": {...}}``), or, without
    room for that either, into the returned message itself. ``what`` names the entries for
    the message ("the 4 alarm crossings"), ``kept`` what the file still holds.
    """
    if not closing:
        return ""
    from app.core.recording.edit import rewrite_metadata

    path = Path(path)
    try:
        rewrite_metadata(path, dict(closing))
        return ""
    except (OSError, ValueError, RecordingError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
    head = f"{path}: {kept}, but {what} could not be added to it ({reason})"
    aside = closing_metadata_path(path)
    document = {"recording": path.name, "metadata": dict(closing)}
    try:
        write_output(aside, json.dumps(document, indent=1, default=str) + "\n")
    except OSError:
        return f"{head}, nor written beside it; here they are: {json.dumps(document, default=str)}"
    return f"{head}; they were written to {aside}"
