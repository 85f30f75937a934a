"""The sample recordings shipped in ``resources/recordings`` (made by its ``make_samples.py``)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

SAMPLE_PACKAGE = "resources"
SAMPLE_FOLDER = "recordings"


def sample_recordings() -> list[Path]:
    """Paths of the sample recordings, sorted by name (empty when none are installed)."""
    try:
        folder = resources.files(SAMPLE_PACKAGE) / SAMPLE_FOLDER
    except ModuleNotFoundError:
        return []
    if not folder.is_dir():
        return []
    return sorted(
        Path(str(entry)) for entry in folder.iterdir()
        if entry.is_file() and entry.name.endswith(".csv")
    )


def sample_recording(name: str) -> Path:
    """One sample recording by file name, with or without ``.csv`` (``"wobble-104hz"``)."""
    wanted = name if name.endswith(".csv") else f"{name}.csv"
    for path in sample_recordings():
        if path.name == wanted:
            return path
    known = ", ".join(p.stem for p in sample_recordings()) or "none installed"
    raise FileNotFoundError(f"no sample recording {name!r} (available: {known})")
