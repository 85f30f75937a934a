"""Open another tool's file for replay: detect its format by content and import it once.

The replay window opens recordings; a x-IMU3 log, a EuRoC/Kalibr ``imu0.csv`` or a mapped CSV
is first imported (:mod:`app.core.interop`) into a format v1 recording in the user's data
folder, named after the source's content (its SHA-256, and the mapping), so opening the same
file again replays the recording made the first time. No Qt here.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import platformdirs

from app.core.interop.imported import ImportInputError, sha256_file, split_header, write_recording
from app.core.interop.importing import GENERIC, RECORDING, XIMU3, detect_format, read_any
from app.core.interop.ximu3 import INERTIAL, find_device, magnetometer_needs_scale


class NeedsMagScale(ImportInputError):
    """An x-IMU3 log whose magnetometer is in a.u.: 1 a.u. is the field where it was
    calibrated, which only the user knows (give ``mag_au_ut``; 0 leaves it out)."""


class NeedsMapping(ImportInputError):
    """A CSV whose format is not known: it needs a column mapping. ``header`` has its
    columns."""

    def __init__(self, path: Path, header: list[str]) -> None:
        super().__init__(f"{path.name}: not a known format; map its columns "
                         f"({', '.join(header)[:200]})")
        self.header = header


@dataclass
class ReplayFile:
    """What to replay: ``path`` (the recording), the format it came from (``"recording"``
    when it was one), whether it was imported now, and the importer's warnings."""

    path: Path
    source_format: str
    imported_now: bool = False
    warnings: list[str] = field(default_factory=list)


def imported_dir() -> Path:
    """Where imported recordings are kept: the user's data folder, ``imported``."""
    return Path(platformdirs.user_data_dir("Inclinometer", appauthor=False)) / "imported"


def replay_file(path: str | Path, *, mapping: str = "", folder: Path | None = None,
                mag_au_ut: float | None = None) -> ReplayFile:
    """The recording to replay for ``path``: itself when it is one, else its import (made
    now, or found from an earlier import of the same content). Raises
    :class:`NeedsMapping` for an unknown CSV without ``mapping``, :class:`ImportInputError`
    (one line) for a file that cannot be imported, :class:`NeedsMagScale` for an x-IMU3 log
    with an a.u. magnetometer without ``mag_au_ut`` (0: import it without the magnetometer),
    OSError when the folder cannot be written."""
    path = Path(path)
    fmt = GENERIC if mapping else detect_format(path)
    if fmt == RECORDING:
        return ReplayFile(path, RECORDING)
    if fmt is None:
        header, _ = split_header(path)
        raise NeedsMapping(path, header)
    source = find_device(path)[1] if fmt == XIMU3 else path
    if fmt == XIMU3 and mag_au_ut is None and magnetometer_needs_scale(path):
        raise NeedsMagScale(f"{path}: its magnetometer is in x-IMU3's a.u.")
    scale = mag_au_ut if mag_au_ut else None
    digest = hashlib.sha256(f"{sha256_file(source)}\n{mapping}\n{scale}".encode()
                            ).hexdigest()[:16]
    stem = source.parent.name if source.name == INERTIAL else source.stem
    folder = imported_dir() if folder is None else folder
    target = folder / f"{_safe(stem)}-{fmt}-{digest}.csv"
    if target.is_file():
        return ReplayFile(target, fmt)
    data = read_any(path, fmt, mapping=mapping, mag_au_ut=scale)
    folder.mkdir(parents=True, exist_ok=True)
    write_recording(data, target, inputs=[source])
    return ReplayFile(target, fmt, True, list(data.warnings))


def _safe(name: str) -> str:
    kept = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    return kept.strip("._")[:60] or "imported"
