"""What every importer shares: the imported samples, strict CSV tables, the recording written.

An importer (:mod:`.ximu3`, :mod:`.euroc_read`, :mod:`.generic_csv`) reads another tool's file
into :class:`ImportedData`: SI units on the recording's time axis (seconds from the first
sample; the first timestamp as the file gave it is kept in the origin), and
:func:`write_recording` writes it as a format v1 recording with the project's recording
writer, atomically: a temporary file beside the target, renamed into place only when complete
(:mod:`app.core.safe_output`); an existing file is refused unless overwriting is allowed.

Bad input raises :class:`ImportInputError` with one line that names the file, line and column.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.core.recording.format import (
    CONVENTIONS,
    KEY_APP,
    KEY_APP_VERSION,
    KEY_CONVENTIONS,
    KEY_DEVICE,
    KEY_MAGNETOMETER,
    KEY_NOTE,
    KEY_UNITS,
    UNITS,
)
from app.core.recording.writer import RecordingWriter
from app.core.safe_output import PathLike, output_path
from app.core.samples import RawBlock, ScaleFactors
from app.core.version import __version__

KEY_IMPORTED_FROM = "imported_from"
"""The metadata key of an imported recording's origin (docs/recording-format.md)."""
GAP_PERIODS = 5.0
"""A step in time of more than this many median sample periods is lost data (as the reader)."""
BLOCK_MIN_S, BLOCK_MAX_S, BLOCK_SAMPLES = 0.02, 0.1, 10
"""The rows are written in blocks as a live device delivers them (ten samples, within 20 to
100 ms: drivers.base.read_block_s): each block's first row has ``block_start`` 1, and a replay
hands the rows on block by block at their pace."""
DEG = math.pi / 180.0


class ImportInputError(ValueError):
    """A file that cannot be imported: one line naming the file, line and column."""


@dataclass
class ImportedData:
    """Samples read from another tool's file, in the recording's units and frame.

    Attributes
    ----------
    t_s : (N,) seconds from the first sample, strictly increasing.
    accel_m_s2, gyro_rad_s : (N, 3) specific force and angular rate.
    mag_ut : (N, 3) field in uT, NaN on rows without a new field sample; None without one.
    temp_degc : (N,) or None.
    origin : the ``imported_from`` metadata (format, file, sha256, tool, time origin, units).
    device : the ``device`` metadata (name, unique_id, sensor, odr_hz...).
    magnetometer : the ``magnetometer`` metadata when ``mag_ut`` is present.
    """

    t_s: np.ndarray
    accel_m_s2: np.ndarray
    gyro_rad_s: np.ndarray
    mag_ut: np.ndarray | None = None
    temp_degc: np.ndarray | None = None
    origin: dict[str, Any] = field(default_factory=dict)
    device: dict[str, Any] = field(default_factory=dict)
    magnetometer: dict[str, Any] | None = None
    warnings: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) if len(self) else 0.0

    @property
    def rate_hz(self) -> float:
        """The median sample rate (NaN with fewer than two samples)."""
        steps = np.diff(self.t_s)
        return float(1.0 / np.median(steps)) if steps.size else math.nan


def sha256_file(path: PathLike) -> str:
    """The file's SHA-256 in hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while chunk := handle.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def origin(fmt: str, path: PathLike, tool: str, **extra: Any) -> dict[str, Any]:
    """The ``imported_from`` value: ``format``, ``file``, ``sha256`` (of ``path``), ``tool``."""
    path = Path(path)
    return {"format": fmt, "file": path.name, "sha256": sha256_file(path), "tool": tool,
            **extra}


# -- strict numeric tables --------------------------------------------------------------------
def split_header(path: Path, *, delimiter: str = ",") -> tuple[list[str], int]:
    """The first non-blank line's fields (the header) and its 1-based line number."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as handle:
            for number, line in enumerate(handle, 1):
                text = line.strip()
                if text:
                    return [f.strip() for f in text.split(delimiter)], number
    except UnicodeDecodeError:
        raise ImportInputError(f"{path}: not a text file (it is not UTF-8)") from None
    raise ImportInputError(f"{path}: the file is empty")


def read_table(path: Path, names: Sequence[str], *, header_line: int, delimiter: str = ",",
               columns: Sequence[int] | None = None, integer: Sequence[int] = ()
               ) -> tuple[list[np.ndarray], np.ndarray]:
    """The numeric columns of a CSV table below its header line, each as a float64 array,
    and each row's 1-based line number in the file.

    ``columns``: which 0-based columns to return (default: all ``len(names)``); every row must
    have exactly ``len(names)`` fields (the header's count). Columns in ``integer`` are read as
    int64 (exact nanosecond timestamps). Blank lines are skipped. A field that is not a finite
    number, or a row of another length, raises :class:`ImportInputError` naming its line and
    column (by the header's name).
    """
    width = len(names)
    wanted = list(range(width)) if columns is None else list(columns)
    ints = set(integer)
    values: list[list[Any]] = [[] for _ in wanted]
    lines: list[int] = []
    with open(path, encoding="utf-8-sig", newline="") as handle:
        for number, line in enumerate(handle, 1):
            if number <= header_line:
                continue
            text = line.strip()
            if not text:
                continue
            fields = text.split(delimiter)
            lines.append(number)
            if len(fields) != width:
                raise ImportInputError(
                    f"{path.name}: line {number} has {len(fields)} fields, the header has "
                    f"{width}")
            for slot, index in enumerate(wanted):
                values[slot].append(_number(fields[index], index in ints, path, number,
                                            names[index]))
    if not values or not values[0]:
        raise ImportInputError(f"{path.name}: no data rows below the header (line "
                               f"{header_line})")
    arrays = [np.asarray(v, dtype=np.int64 if wanted[k] in ints else np.float64)
              for k, v in enumerate(values)]
    return arrays, np.asarray(lines, dtype=np.int64)


def _number(text: str, integer: bool, path: Path, line: int, column: str) -> float | int:
    text = text.strip()
    try:
        value: float | int = int(text) if integer else float(text)
    except ValueError:
        what = "an integer" if integer else "a number"
        raise ImportInputError(f"{path.name}: line {line}, column {column!r}: {text!r} is not "
                               f"{what}") from None
    if not integer and not math.isfinite(value):
        raise ImportInputError(f"{path.name}: line {line}, column {column!r}: {text!r} is not "
                               "a finite number")
    return value


def check_time(path: Path, t: np.ndarray, lines: np.ndarray) -> None:
    """Refuse time that stands still or goes back, naming the row's line (``lines``: each
    row's line number, as :func:`read_table` gives them)."""
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        row = int(bad[0]) + 1
        raise ImportInputError(
            f"{path.name}: line {int(lines[row])}: the timestamp does not increase "
            f"({t[row]!r} after {t[row - 1]!r})")


def gap_flags(t_s: np.ndarray) -> np.ndarray:
    """True on the first sample after a step of more than :data:`GAP_PERIODS` periods."""
    gap = np.zeros(t_s.shape[0], dtype=bool)
    steps = np.diff(t_s)
    if steps.size:
        gap[1:] = steps > GAP_PERIODS * np.median(steps)
    return gap


def place_on_rows(t_rows: np.ndarray, t_samples: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Slower samples (a magnetometer's) on the rows of faster ones: each on the first row at or
    after its time (the format's rule), the latest one where several fall on one row; NaN on
    rows without one. Samples after the last row are dropped."""
    out = np.full((t_rows.shape[0], values.shape[1]), np.nan)
    rows = np.searchsorted(t_rows, t_samples, side="left")
    keep = rows < t_rows.shape[0]
    out[rows[keep]] = values[keep]  # later samples on the same row win (numpy assigns in order)
    return out


def hold_on_rows(t_rows: np.ndarray, t_samples: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A slow scalar (a temperature) held from each of its samples on: NaN before the first."""
    index = np.searchsorted(t_samples, t_rows, side="right") - 1
    out = np.where(index >= 0, values[np.clip(index, 0, None)], np.nan)
    return out.astype(np.float64)


# -- the recording ----------------------------------------------------------------------------
def recording_metadata(data: ImportedData, note: str = "") -> dict[str, Any]:
    """The imported recording's metadata: the app, the device, units, conventions, origin."""
    device = {"url": f"import:{data.origin.get('format', '?')}", **data.device}
    if len(data) > 1:
        device.setdefault("odr_hz", data.rate_hz)
    metadata: dict[str, Any] = {
        KEY_APP: "inclinometer", KEY_APP_VERSION: __version__, KEY_DEVICE: device,
        KEY_UNITS: {k: v for k, v in UNITS.items()
                    if data.mag_ut is not None or k not in ("mx", "my", "mz")},
        KEY_CONVENTIONS: CONVENTIONS,
        KEY_IMPORTED_FROM: data.origin,
    }
    if data.mag_ut is not None:
        metadata[KEY_MAGNETOMETER] = data.magnetometer or {"chip": "imported"}
    if note:
        metadata[KEY_NOTE] = note
    return metadata


def block_rows(rate_hz: float) -> int:
    """Rows per device block at ``rate_hz`` (see :data:`BLOCK_SAMPLES`)."""
    if not math.isfinite(rate_hz) or rate_hz <= 0:
        return 1
    seconds = min(BLOCK_MAX_S, max(BLOCK_MIN_S, BLOCK_SAMPLES / rate_hz))
    return max(1, round(seconds * rate_hz))


def write_recording(data: ImportedData, out: PathLike, *, inputs: Sequence[PathLike] = (),
                    overwrite: bool = False, note: str = "", option: str = "") -> Path:
    """Write ``data`` as a format v1 recording at ``out`` (gzip when it ends in ``.gz``).

    Nothing is half-written: the rows go to a temporary file beside ``out`` that is renamed
    into place when the writer has closed it; ``out`` existing is refused unless
    ``overwrite``, and an input file as the output always is.
    """
    out = Path(out)
    metadata = recording_metadata(data, note)
    n = len(data)
    temp = np.full(n, np.nan) if data.temp_degc is None else data.temp_degc
    gap = gap_flags(data.t_s)
    scale = ScaleFactors(1.0, 1.0, 1.0, 0.0, 1.0)  # already SI: x * 1.0 keeps every bit
    rows = block_rows(data.rate_hz)
    with output_path(out, inputs=inputs, overwrite=overwrite, option=option,
                     keep_suffix=True) as temporary:
        writer = RecordingWriter(temporary, metadata, reference=False,
                                 magnetometer=data.mag_ut is not None, overwrite=True,
                                 compress=out.suffix.lower() == ".gz").start()
        try:
            for start in range(0, n, rows):
                part = slice(start, start + rows)
                writer.write(RawBlock(
                    t_s=data.t_s[part], accel_raw=data.accel_m_s2[part],
                    gyro_raw=data.gyro_rad_s[part], temp_raw=temp[part], scale=scale,
                    gap=gap[part], mag_raw=None if data.mag_ut is None else data.mag_ut[part]))
        finally:
            status = writer.close()
        if status.state != "stopped" or status.rows_written != n:
            raise OSError(status.error or f"{out}: the recording writer wrote "
                                          f"{status.rows_written} of {n} rows")
    return out
