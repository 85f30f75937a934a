"""The measurement log: stored readings, like a digital level's memory (no Qt).

A :class:`Measurement` is the reading the instrument shows at one moment: the mean and the
standard deviation of roll, pitch and tilt over the readout's averaging window (see
:func:`measure`), in the display unit, with the filter, calibration and device it came from and
a label the user can edit. A :class:`MeasurementLog` keeps them in a JSON file under the user
data directory so they survive a restart, and exports them as CSV or tab-separated text (for
pasting into a spreadsheet).

A reading taken while the instrument was not steady (its samples scatter by more than
:data:`UNSTEADY_SPREAD_DEG` about their mean) is stored with a ``warning`` saying so: its mean
depends on when the button was pressed.

A log file that cannot be read is moved aside (``measurements.json.corrupt-<time>``), never
overwritten, and the log starts empty; :meth:`MeasurementLog.load` says so in its message.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from collections.abc import Iterable
from dataclasses import asdict, dataclass, fields, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from app.core.bounded_input import (
    InputTooLargeError,
    NotRegularFileError,
    loads_json,
    read_bounded,
)
from app.core.heading import (
    HEADING_UNITS,
    HeadingReading,
    circular_mean_deg,
    heading_in_unit,
    magnetic_heading_deg,
    signed_difference_deg,
)
from app.core.orientation import angles_from_up, up_in_sensor_frame
from app.core.readout import averaged_angles, slope_from_angle

LOG_FORMAT = "inclinometer-measurement-log"
LOG_VERSION = 1
LOG_FILE_NAME = "measurements.json"
MAX_LOG_BYTES = 64 << 20
"""A larger log file is treated as damaged (an entry takes about 400 bytes)."""
COLUMNS: tuple[str, ...] = (
    "time", "label", "roll", "roll_std", "pitch", "pitch_std", "tilt", "tilt_std",
    "direction_deg", "unit", "window_s", "samples", "filter", "calibration", "device",
    "spread_deg", "warning", "heading", "heading_std", "heading_unit", "heading_north",
)
"""The CSV columns, in order (the fields of :class:`Measurement`)."""

UNSTEADY_SPREAD_DEG = 0.1
"""A reading whose samples' up direction scatters by more than this (RMS angle about the mean,
degrees) is flagged as not steady: ten times the readouts' resolution (0.01°). Measured on the
simulated LSM6DSOX through the EKF over 0.5 s: at rest 0.001° (at most 0.013°, 104-833 Hz), on
a running machine (``sim://vibration``) 0.04-0.09°, hand-held (``sim://wobble``) about 1°. So
a reading at rest or on a vibrating bench is kept as it is, while a mean over a moving
instrument (one that depends on the moment the button was pressed) is not kept silently."""


@dataclass(frozen=True, slots=True)
class Measurement:
    """One stored reading. Angles in ``unit`` (``deg``, ``percent``, ``mm/m``...), the
    direction of the raised side in degrees; ``time`` is local ISO 8601 with its offset."""

    time: str
    label: str
    roll: float
    roll_std: float
    pitch: float
    pitch_std: float
    tilt: float
    tilt_std: float
    direction_deg: float
    unit: str
    window_s: float
    samples: int
    filter: str
    calibration: str
    device: str
    spread_deg: float = math.nan
    """RMS angle (degrees) of the samples' up direction about the mean: how steady it was."""
    warning: str = ""
    """Why the reading may be wrong ("" when it is sound), e.g. not steady."""
    heading: float = math.nan
    """The heading shown (:mod:`app.core.heading`), in ``heading_unit`` from
    ``heading_north``; NaN when there was none (no magnetometer, a filter without it, the
    sensor near vertical)."""
    heading_std: float = math.nan
    """Standard deviation of the per-sample headings about it (same unit)."""
    heading_unit: str = ""
    """``deg`` or ``mil``; "" without a heading."""
    heading_north: str = ""
    """``magnetic`` or ``true``; "" without a heading."""

    @property
    def flagged(self) -> bool:
        return bool(self.warning)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Measurement:
        """ValueError (or KeyError/TypeError) for an entry that is not a measurement."""
        values = {}
        for spec in fields(cls):
            if spec.name not in data and spec.name in _ADDED_LATER:
                continue  # a log written before these existed: the defaults
            value = data[spec.name]
            if spec.type == "float":
                if value is None:  # NaN is stored as null (JSON has no NaN)
                    value = math.nan
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ValueError(f"{spec.name} must be a number, got {_short(value)}")
                value = float(value)
            elif spec.type == "int":
                if isinstance(value, bool) or not isinstance(value, int):
                    raise ValueError(f"{spec.name} must be a whole number, got {_short(value)}")
            elif not isinstance(value, str):
                raise ValueError(f"{spec.name} must be text, got {_short(value)}")
            values[spec.name] = value
        return cls(**values)

    def row(self) -> list[str]:
        """The CSV / clipboard fields, numbers to 6 significant digits."""
        out = []
        for name in COLUMNS:
            value = getattr(self, name)
            out.append(f"{value:.6g}" if isinstance(value, float) else str(value))
        return out


_ADDED_LATER = ("spread_deg", "warning", "heading", "heading_std", "heading_unit",
                "heading_north")
"""Fields a log written before them lacks: they take their defaults."""


def with_heading(measurement: Measurement, quat: np.ndarray, reading: HeadingReading
                 ) -> Measurement:
    """``measurement`` with the heading shown (``reading``, over the same quaternions
    ``quat``) and the spread of the per-sample headings; unchanged without a heading."""
    if not reading.ok:
        return measurement
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    per_sample = magnetic_heading_deg(quat[np.all(np.isfinite(quat), axis=1)])
    per_sample = per_sample[np.isfinite(per_sample)]
    scale = HEADING_UNITS[reading.unit].per_circle / 360.0
    spread = math.nan
    if len(per_sample) > 1:
        centre = circular_mean_deg(per_sample)
        if centre is not None:
            spread = float(np.std(signed_difference_deg(per_sample, centre), ddof=1)) * scale
    return replace(measurement, heading=heading_in_unit(reading.heading_deg, reading.unit),
                   heading_std=spread, heading_unit=reading.unit, heading_north=reading.north)


def measure(quat: np.ndarray, unit: str, window_s: float, *, label: str = "",
            filter_name: str = "", calibration: str = "", device: str = "",
            when: datetime | None = None) -> Measurement | None:
    """The reading over the quaternions (N, 4) of the averaging window; None without data.

    The means are those the readouts show (the mean up direction, exact across the +-180°
    wrap); the standard deviations are of the per-sample values in ``unit`` about them.
    """
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    quat = quat[np.all(np.isfinite(quat), axis=1)]
    mean = averaged_angles(quat)
    if mean is None:
        return None
    per_sample = angles_from_up(up_in_sensor_frame(quat))

    def stats(samples: np.ndarray, mean_deg: float) -> tuple[float, float]:
        # Deviations about the mean, wrapped, so a roll near +-180° does not spread over 360°.
        deviation = (samples - mean_deg + 180.0) % 360.0 - 180.0
        converted = np.asarray(slope_from_angle(mean_deg + deviation, unit), dtype=np.float64)
        spread = float(np.std(converted, ddof=1)) if len(converted) > 1 else 0.0
        return float(slope_from_angle(mean_deg, unit)), spread

    ups = up_in_sensor_frame(quat).reshape(-1, 3)
    centre = ups.mean(axis=0)
    centre /= np.linalg.norm(centre)
    off = np.arctan2(np.linalg.norm(np.cross(ups, centre), axis=1), ups @ centre)
    spread = float(np.degrees(np.sqrt(np.mean(off**2))))
    roll, roll_std = stats(per_sample.roll_deg, mean.roll_deg)  # type: ignore[arg-type]
    pitch, pitch_std = stats(per_sample.pitch_deg, mean.pitch_deg)  # type: ignore[arg-type]
    tilt, tilt_std = stats(per_sample.tilt_deg, mean.tilt_deg)  # type: ignore[arg-type]
    stamp = (when or datetime.now().astimezone()).isoformat(timespec="seconds")
    return Measurement(stamp, label, roll, roll_std, pitch, pitch_std, tilt, tilt_std,
                       float(mean.direction_deg), unit, float(window_s), len(quat),
                       filter_name, calibration, device, spread, steadiness_warning(spread))


def steadiness_warning(spread_deg: float) -> str:
    """The warning for a reading that scattered by ``spread_deg`` ("" when steady)."""
    if not spread_deg > UNSTEADY_SPREAD_DEG:
        return ""
    return (f"not steady: the samples scattered by {spread_deg:.2f}° RMS over the averaging "
            f"time (more than {UNSTEADY_SPREAD_DEG:g}°); hold the instrument still and store "
            "again")


def default_log_path() -> Path:
    """``<user data dir>/measurements.json`` for this platform (not created here)."""
    import platformdirs

    return Path(platformdirs.user_data_dir("Inclinometer", appauthor=False)) / LOG_FILE_NAME


class MeasurementLog:
    """The stored readings, saved to ``path`` after every change (when a path is given)."""

    def __init__(self, path: str | os.PathLike[str] | None = None,
                 entries: Iterable[Measurement] = ()) -> None:
        self.path = None if path is None else Path(path)
        self.entries: list[Measurement] = list(entries)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> tuple[MeasurementLog, str]:
        """The log stored at ``path`` (empty when there is none) and a message for the user
        ("" when all is well). A file that cannot be read is moved aside, never overwritten,
        and the log starts empty."""
        path = Path(path)
        refused = ""
        try:
            text = read_bounded(path, MAX_LOG_BYTES)
        except FileNotFoundError:
            return cls(path), ""
        except (InputTooLargeError, NotRegularFileError) as exc:
            if path.is_dir():  # left alone, as an unreadable file
                return cls(None), (f"The measurement log {path} cannot be read ({exc}); "
                                   "this session's readings will not be saved.")
            text, refused = b"", str(exc)  # a FIFO, a device, too large: moved aside below
        except OSError as exc:
            # Unreadable (permissions...): keep it where it is; the log does not save over it.
            log = cls(None)
            return log, (f"The measurement log {path} cannot be read ({exc.strerror or exc}); "
                         "this session's readings will not be saved.")
        try:
            if not text:
                raise ValueError(refused or "the file is empty")
            entries = _parse_log(text)
        except (ValueError, KeyError, TypeError, OSError) as exc:
            aside = _move_aside(path)
            where = f"moved to {aside}" if aside else "left in place (it could not be moved)"
            log = cls(path if aside else None)
            return log, (f"The measurement log {path} is damaged ({exc}); it was {where} and "
                         "the log starts empty.")
        return cls(path, entries), ""

    # -- editing (each change is saved) -------------------------------------------------------
    def add(self, measurement: Measurement) -> None:
        self.entries.append(measurement)
        self.save()

    def set_label(self, row: int, label: str) -> None:
        self.entries[row] = replace(self.entries[row], label=label)
        self.save()

    def remove(self, rows: Iterable[int]) -> None:
        """Delete these rows (indices into :attr:`entries`)."""
        doomed = set(rows)
        self.entries = [e for i, e in enumerate(self.entries) if i not in doomed]
        self.save()

    def clear(self) -> None:
        self.entries = []
        self.save()

    def __len__(self) -> int:
        return len(self.entries)

    # -- files and text ----------------------------------------------------------------------
    def save(self) -> None:
        """Write the log atomically (a temporary file beside it, then renamed). Raises
        OSError when it cannot be written."""
        if self.path is None:
            return
        document = {"format": LOG_FORMAT, "version": LOG_VERSION,
                    "entries": [_json_safe(e.to_dict()) for e in self.entries]}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, temp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp",
                                    dir=self.path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as out:
                json.dump(document, out, indent=1, ensure_ascii=False, allow_nan=False)
                out.flush()
                os.fsync(out.fileno())
            os.replace(temp, self.path)
        except BaseException:
            Path(temp).unlink(missing_ok=True)
            raise

    def csv_text(self, delimiter: str = ",", rows: Iterable[int] | None = None) -> str:
        """The header and the rows (all, or ``rows``) as CSV; ``delimiter="\\t"`` for the
        clipboard (spreadsheets split pasted tab-separated text into cells)."""
        chosen = self.entries if rows is None else [self.entries[i] for i in sorted(set(rows))]
        buffer = io.StringIO()
        writer = csv.writer(buffer, delimiter=delimiter, lineterminator="\n")
        writer.writerow(COLUMNS)
        for entry in chosen:
            writer.writerow(entry.row())
        return buffer.getvalue()

    def export_csv(self, path: str | os.PathLike[str]) -> None:
        """Write every row to a CSV file (UTF-8). Raises OSError."""
        Path(path).write_text(self.csv_text(), encoding="utf-8")


def _json_safe(data: dict[str, Any]) -> dict[str, Any]:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in data.items()}


def _short(value: Any) -> str:
    """``repr`` of a value for a one-line message, cut to 40 characters."""
    text = repr(value) if not isinstance(value, list | dict) else type(value).__name__
    return text if len(text) <= 40 else text[:40] + "..."


def _parse_log(text: bytes) -> list[Measurement]:
    document = loads_json(text, max_bytes=MAX_LOG_BYTES)
    if not isinstance(document, dict) or document.get("format") != LOG_FORMAT:
        raise ValueError("not a measurement log")
    if document.get("version") != LOG_VERSION:
        raise ValueError(f"log version {document.get('version')!r}, this program reads "
                         f"{LOG_VERSION}")
    entries = document.get("entries")
    if not isinstance(entries, list):
        raise ValueError("no list of entries")
    return [Measurement.from_dict(entry) for entry in entries]


def _move_aside(path: Path) -> Path | None:
    """Rename a damaged file to a name not yet taken; None when that fails."""
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    for attempt in range(100):
        suffix = f".corrupt-{stamp}" + (f"-{attempt}" if attempt else "")
        target = path.with_name(path.name + suffix)
        if target.exists():
            continue
        try:
            os.rename(path, target)
        except OSError:
            return None
        return target
    return None
