"""A recording in memory: its columns as arrays and its metadata, with the accessors every
consumer uses (:class:`Recording`). Reading one from a file is :mod:`.reader`'s job.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.core.calibration import SensorCalibration
from app.core.recording.format import (
    ACCEL_COLUMNS,
    GYRO_COLUMNS,
    KEY_BOOKMARKS,
    KEY_CALIBRATION,
    KEY_DEVICE,
    KEY_FILTER,
    KEY_NOTE,
    MAG_COLUMNS,
    OPTIONAL_COLUMNS,
    REFERENCE_COLUMNS,
    REQUIRED_COLUMNS,
    calibration_from_json,
)
from app.core.samples import RawBlock, SampleBlock, ScaleFactors

UNIT_SCALE = ScaleFactors(
    accel_m_s2_per_lsb=1.0, gyro_rad_s_per_lsb=1.0, temp_degc_per_lsb=1.0, temp_offset_degc=0.0
)
"""Recorded values are already SI: ``x * 1.0 + 0.0`` gives each one back bit for bit."""
@dataclass(frozen=True, slots=True)
class Bookmark:
    """A named moment of a recording; ``t_s`` is on the ``t`` column's clock."""

    t_s: float
    label: str = ""


@dataclass
class Recording:
    """A loaded recording.

    Attributes
    ----------
    metadata : every ``# key: value`` line, JSON-decoded, in file order.
    header : the column names as in the file.
    columns : every column by name: float64 arrays (NaN where empty), or object arrays of
        text for unknown columns that are not numbers.
    path : the file read (None for bytes).
    warnings : what was skipped or tolerated, one message each.
    dropped_partial_row : True when an incomplete last row was dropped.
    corrupt_line : with ``on_corrupt="truncate"``, the line where reading stopped.
    """

    metadata: dict[str, Any]
    header: tuple[str, ...]
    columns: dict[str, np.ndarray]
    path: Path | None = None
    warnings: list[str] = field(default_factory=list)
    dropped_partial_row: bool = False
    corrupt_line: int | None = None
    comments: list[str] = field(default_factory=list)
    _known_reference: bool | None = field(default=None, init=False, repr=False, compare=False)

    # -- samples ---------------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.columns["t"].shape[0])

    @property
    def t_s(self) -> np.ndarray:
        """(N,) device clock, s (a recording need not start at 0)."""
        return self.columns["t"]

    @property
    def accel_m_s2(self) -> np.ndarray:
        """(N, 3) raw specific force, before calibration."""
        return np.column_stack([self.columns[c] for c in ACCEL_COLUMNS])

    @property
    def gyro_rad_s(self) -> np.ndarray:
        """(N, 3) raw angular rate, before calibration."""
        return np.column_stack([self.columns[c] for c in GYRO_COLUMNS])

    @property
    def temp_degc(self) -> np.ndarray:
        """(N,) temperature; NaN when the column is absent or empty."""
        temp = self.columns.get("temp")
        return np.full(len(self), np.nan) if temp is None else temp

    @property
    def gap(self) -> np.ndarray:
        """(N,) bool, True on the first sample after lost data."""
        return self._flag("gap")

    @property
    def block_start(self) -> np.ndarray | None:
        """(N,) bool, True where a device block began; None when not recorded."""
        return self._flag("block_start") if "block_start" in self.columns else None

    @property
    def has_reference(self) -> bool:
        """True when the reference columns exist and hold at least one full quaternion."""
        if self._known_reference is None:  # once: it looks at every row
            self._known_reference = all(c in self.columns for c in REFERENCE_COLUMNS) and bool(
                np.any(np.all(np.isfinite(self._reference()), axis=1)))
        return self._known_reference

    @property
    def reference_quat(self) -> np.ndarray | None:
        """(N, 4) reference orientation (NaN rows where unknown), or None without one."""
        return self._reference() if self.has_reference else None

    @property
    def has_magnetometer(self) -> bool:
        """True when the file has the magnetometer's columns ``mx,my,mz``."""
        return all(c in self.columns for c in MAG_COLUMNS)

    @property
    def mag_ut(self) -> np.ndarray | None:
        """(N, 3) magnetic field in uT as measured (NaN rows without a new field sample), or
        None without a magnetometer."""
        return self._mag() if self.has_magnetometer else None

    @property
    def unknown_columns(self) -> dict[str, np.ndarray]:
        """Columns this version does not know (kept, never used)."""
        known = set(REQUIRED_COLUMNS) | set(OPTIONAL_COLUMNS)
        return {name: values for name, values in self.columns.items() if name not in known}

    def _flag(self, name: str, rows: slice = slice(None)) -> np.ndarray:
        values = self.columns.get(name)
        if values is None:
            return np.zeros(len(range(*rows.indices(len(self)))), dtype=bool)
        values = values[rows]
        return np.isfinite(values) & (values != 0.0)

    def _reference(self, rows: slice = slice(None)) -> np.ndarray:
        return np.column_stack([self.columns[c][rows] for c in REFERENCE_COLUMNS])

    def _mag(self, rows: slice = slice(None)) -> np.ndarray:
        return np.column_stack([self.columns[c][rows] for c in MAG_COLUMNS])

    # -- metadata ------------------------------------------------------------------------------
    @property
    def device(self) -> dict[str, Any]:
        """The recorded device description (empty when the file has none)."""
        value = self.metadata.get(KEY_DEVICE)
        return dict(value) if isinstance(value, dict) else {}

    @property
    def calibration(self) -> SensorCalibration | None:
        """The calibration applied while recording (None when absent or unreadable)."""
        value = self.metadata.get(KEY_CALIBRATION)
        if value is None:
            return None
        try:
            return calibration_from_json(value)
        except ValueError:
            return None

    @property
    def filter_name(self) -> str | None:
        value = self.metadata.get(KEY_FILTER)
        return str(value["name"]) if isinstance(value, dict) and "name" in value else None

    @property
    def filter_parameters(self) -> dict[str, Any]:
        value = self.metadata.get(KEY_FILTER)
        params = value.get("parameters") if isinstance(value, dict) else None
        return dict(params) if isinstance(params, dict) else {}

    @property
    def note(self) -> str:
        value = self.metadata.get(KEY_NOTE)
        return value if isinstance(value, str) else ""

    @property
    def bookmarks(self) -> list[Bookmark]:
        """``bookmarks`` metadata: ``[{"t": s, "label": text}, ...]`` or plain times."""
        found = []
        for entry in self.metadata.get(KEY_BOOKMARKS) or []:
            if isinstance(entry, dict) and isinstance(entry.get("t"), int | float):
                found.append(Bookmark(float(entry["t"]), str(entry.get("label", ""))))
            elif isinstance(entry, int | float) and not isinstance(entry, bool):
                found.append(Bookmark(float(entry)))
        return sorted(found, key=lambda b: b.t_s)

    @property
    def duration_s(self) -> float:
        t = self.t_s
        return float(t[-1] - t[0]) if len(t) > 1 else 0.0

    @property
    def rate_hz(self) -> float:
        """Median sample rate (the recorded device's ``odr_hz`` when given)."""
        odr = self.device.get("odr_hz")
        if isinstance(odr, int | float) and odr > 0:
            return float(odr)
        steps = np.diff(self.t_s)
        steps = steps[steps > 0]
        return 1.0 / float(np.median(steps)) if len(steps) else math.nan

    # -- blocks --------------------------------------------------------------------------------
    def raw_block(self, start: int = 0, stop: int | None = None) -> RawBlock:
        """Rows ``[start, stop)`` as a device block in SI units (scale factors of 1.0)."""
        stop = len(self) if stop is None else stop
        rows = slice(start, stop)  # only these rows are touched: replay is linear in length
        temp = self.columns.get("temp")
        return RawBlock(
            t_s=self.t_s[rows],
            accel_raw=np.column_stack([self.columns[c][rows] for c in ACCEL_COLUMNS]),
            gyro_raw=np.column_stack([self.columns[c][rows] for c in GYRO_COLUMNS]),
            temp_raw=np.full(len(self.t_s[rows]), np.nan) if temp is None else temp[rows],
            scale=UNIT_SCALE,
            gap=self._flag("gap", rows),
            reference_quat=self._reference(rows) if self.has_reference else None,
            mag_raw=self._mag(rows) if self.has_magnetometer else None,
        )

    def block_bounds(self, size: int | None = None) -> np.ndarray:
        """Start indices of the blocks to replay, plus ``len(self)`` at the end.

        ``size=None``: the device's blocks as recorded (``block_start``), else blocks of
        ``size`` samples (also when the file has no ``block_start`` column: 65 536).
        """
        n = len(self)
        starts = self.block_start
        if size is None and starts is not None:
            bounds = np.flatnonzero(starts)
            if len(bounds) == 0 or bounds[0] != 0:
                bounds = np.concatenate([[0], bounds])
        else:
            bounds = np.arange(0, n, size or 65536)
        return np.concatenate([bounds, [n]]).astype(np.int64) if n else np.zeros(1, np.int64)

    def raw_blocks(self, size: int | None = None) -> Iterator[RawBlock]:
        """The whole recording as device blocks (see :meth:`block_bounds`): the columns are
        stacked once and each block holds views of its rows (the same values as
        :meth:`raw_block` of those rows, without four stackings a block)."""
        bounds = self.block_bounds(size)
        if len(bounds) < 2:
            return
        whole = self.raw_block()
        for start, stop in itertools.pairwise(bounds.tolist()):
            rows = slice(start, stop)
            yield RawBlock(
                t_s=whole.t_s[rows], accel_raw=whole.accel_raw[rows],
                gyro_raw=whole.gyro_raw[rows], temp_raw=whole.temp_raw[rows],
                scale=whole.scale, gap=whole.gap[rows] if whole.gap is not None else None,
                reference_quat=(whole.reference_quat[rows] if whole.reference_quat is not None
                                else None),
                mag_raw=whole.mag_raw[rows] if whole.mag_raw is not None else None,
            )

    def sample_block(self, calibration: SensorCalibration | None = None) -> SampleBlock:
        """Every sample in SI units, with ``calibration`` applied (none when None)."""
        block = SampleBlock(
            t_s=self.t_s, accel_m_s2=self.accel_m_s2, gyro_rad_s=self.gyro_rad_s,
            temp_degc=self.temp_degc, gap=self.gap, reference_quat=self.reference_quat,
            mag_ut=self.mag_ut,
        )
        return block if calibration is None else calibration.apply(block)
