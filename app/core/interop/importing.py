"""Which importer a file needs (detected by content, not by name), and the import itself."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from app.core.interop.euroc_read import looks_like_euroc, read_euroc
from app.core.interop.generic_csv import read_generic
from app.core.interop.imported import ImportedData, ImportInputError, split_header
from app.core.interop.ximu3 import INERTIAL, device_folders, looks_like_inertial, read_ximu3
from app.core.recording.format import FIRST_LINE

RECORDING = "recording"
EUROC = "euroc"
XIMU3 = "x-imu3"
GENERIC = "csv"
FORMATS = (XIMU3, EUROC, GENERIC)
"""The formats ``inclinometer import`` reads (``recording`` needs no import)."""


def detect_format(path: str | Path) -> str | None:
    """``"recording"`` (format v1, plain or gzip), ``"euroc"``, ``"x-imu3"`` (an
    ``Inertial.csv``, a device folder or a data logger folder), or None (not known: a generic
    CSV needs a mapping)."""
    path = Path(path)
    if path.is_dir():
        try:
            return XIMU3 if device_folders(path) else None
        except OSError:
            return None
    try:
        with open(path, "rb") as handle:
            start = handle.read(4096)
    except OSError:
        return None
    if start[:2] == b"\x1f\x8b" or start.startswith(FIRST_LINE.encode()):
        return RECORDING
    try:
        header, _ = split_header(path)
    except (ImportInputError, OSError):
        return None
    if looks_like_euroc(header):
        return EUROC
    if path.name == INERTIAL or looks_like_inertial(header):
        return XIMU3
    return None


def read_any(path: str | Path, fmt: str | None = None, *, mapping: str = "",
             delimiter: str = ",", device: str = "", mag_au_ut: float | None = None
             ) -> ImportedData:
    """Import ``path`` as ``fmt`` (None: detected; a ``mapping`` alone means the generic CSV).
    :class:`ImportInputError` says, in one line, what is wrong."""
    path = Path(path)
    if not path.exists():
        raise ImportInputError(f"{path}: no such file or folder")
    if path.is_file() and path.stat().st_size == 0:
        raise ImportInputError(f"{path}: the file is empty")
    if fmt is None:
        fmt = GENERIC if mapping else detect_format(path)
        if fmt is None:
            raise ImportInputError(f"{path}: not a format this program recognises (x-IMU3, "
                                   "EuRoC/Kalibr imu0.csv); for another CSV give the columns "
                                   "with --map t=COL:s,ax=COL:g,...")
    if fmt == RECORDING:
        raise ImportInputError(f"{path} is already an inclinometer recording; open it as it is")
    readers: dict[str, Any] = {
        XIMU3: lambda: read_ximu3(path, device=device, mag_au_ut=mag_au_ut),
        EUROC: lambda: read_euroc(path),
        GENERIC: lambda: read_generic(path, mapping, delimiter=delimiter),
    }
    if fmt not in readers:
        raise ImportInputError(f"unknown import format {fmt!r}; one of {', '.join(FORMATS)}")
    if fmt == GENERIC and not mapping:
        raise ImportInputError("a generic CSV needs its columns: --map t=COL:s,ax=COL:g,...")
    return readers[fmt]()
