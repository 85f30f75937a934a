"""Repeatability of an arm's end point over repeated placements (the paper's tables).

The user puts the arm's tip on the same spot N times and captures each placement; a
placement is the mean of the end points over a short window (so noise averages out). The
statistics per coordinate are the mean, the sample standard deviation (n - 1), the minimum,
the maximum and the range.

The end point in cylindrical coordinates is the paper's R, theta and Z: ``azimuth_deg`` is
theta, the end point's angle about the base's vertical axis. Angles are circular: their mean
is the mean direction, and the SD, minimum, maximum and range are taken of the angles moved
by whole turns to within 180 degrees of it (placements at 179 and -179 degrees have a range of
2, not 358). Each placement also keeps where its column angle came from (``measured`` by the
magnetometers, or ``typed``) and the column's magnetic azimuth (NaN when typed).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.arm.azimuth import circular_mean_deg, unwrap_about
from app.core.arm.kinematics import cylindrical

COORDINATES = ("x", "y", "z", "R", "Z", "azimuth_deg")
CYLINDRICAL = ("R", "azimuth_deg", "Z")
"""The paper's R, theta, Z (theta is ``azimuth_deg``)."""
COLUMN_AZIMUTH = "column_azimuth_deg"
"""Where the column pointed, clockwise from magnetic north (measured placements only)."""
ANGLES = ("azimuth_deg", COLUMN_AZIMUTH)
STATISTICS = ("mean", "sd", "min", "max", "range")
THETA_SOURCES = ("typed", "measured")


@dataclass(frozen=True, slots=True)
class CoordinateStats:
    """Statistics of one coordinate over the placements (sd is NaN for a single one)."""

    n: int
    mean: float
    sd: float
    min: float
    max: float

    @property
    def range(self) -> float:
        return self.max - self.min


class Placements:
    """Captured placements of the end point and their statistics."""

    def __init__(self, base: Sequence[float] = (0.0, 0.0, 0.0), unit: str = "mm") -> None:
        self.base = np.asarray(base, dtype=np.float64).reshape(3)
        self.unit = unit
        self._points: list[np.ndarray] = []
        self._samples: list[int] = []
        self._sources: list[str] = []
        self._column_azimuths: list[float] = []

    def __len__(self) -> int:
        return len(self._points)

    def capture(self, end_points: np.ndarray, theta_source: str = "typed",
                column_azimuth_deg: float = math.nan) -> np.ndarray:
        """Add a placement: the mean of end points (N, 3) over the capture window.

        ``theta_source`` says where the column's angle came from (``typed`` or ``measured``)
        and ``column_azimuth_deg`` where the column pointed (magnetic, measured only).
        """
        if theta_source not in THETA_SOURCES:
            raise ValueError(f"theta_source must be one of {THETA_SOURCES}, not {theta_source!r}")
        points = np.asarray(end_points, dtype=np.float64).reshape(-1, 3)
        points = points[np.all(np.isfinite(points), axis=1)]
        if len(points) == 0:
            raise ValueError("no valid end point to capture")
        mean = points.mean(axis=0)
        self._points.append(mean)
        self._samples.append(len(points))
        self._sources.append(theta_source)
        self._column_azimuths.append(float(column_azimuth_deg))
        return mean

    @property
    def theta_sources(self) -> tuple[str, ...]:
        return tuple(self._sources)

    def remove_last(self) -> None:
        if self._points:
            self._points.pop()
            self._samples.pop()
            self._sources.pop()
            self._column_azimuths.pop()

    def clear(self) -> None:
        self._points.clear()
        self._samples.clear()
        self._sources.clear()
        self._column_azimuths.clear()

    def table(self) -> np.ndarray:
        """(N, 6) one row per placement: x, y, z, R, Z, azimuth_deg."""
        if not self._points:
            return np.empty((0, len(COORDINATES)))
        points = np.array(self._points)
        return np.column_stack([points, cylindrical(points, self.base)])  # type: ignore[arg-type]

    def statistics(self) -> dict[str, CoordinateStats]:
        """Per coordinate: n, mean, SD (n - 1), min, max (angles circular, see the module);
        ``column_azimuth_deg`` too when every placement measured it. Empty without
        placements."""
        table = self.table()
        n = len(table)
        if n == 0:
            return {}
        columns = {name: table[:, i] for i, name in enumerate(COORDINATES)}
        azimuths = np.array(self._column_azimuths)
        if np.all(np.isfinite(azimuths)):
            columns[COLUMN_AZIMUTH] = azimuths
        stats = {}
        for name, values in columns.items():
            mean = float(values.mean())
            if name in ANGLES:
                mean = circular_mean_deg(values)
                values = unwrap_about(values, mean)
                if name == COLUMN_AZIMUTH:
                    mean %= 360.0
                    values = unwrap_about(values, mean)
            sd = float(values.std(ddof=1)) if n > 1 else math.nan
            stats[name] = CoordinateStats(n, mean, sd, float(values.min()), float(values.max()))
        return stats

    def to_csv(self) -> str:
        """Placements then the mean, sd, min, max and range rows, one column per coordinate."""
        out = io.StringIO()
        out.write(f"# arm end point repeatability, lengths in {self.unit}, angles in degrees\n")
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(["placement", "samples", *COORDINATES, "theta_from", COLUMN_AZIMUTH])
        rows = zip(self.table(), self._samples, self._sources, self._column_azimuths)
        for i, (row, samples, source, azimuth) in enumerate(rows, start=1):
            writer.writerow([i, samples, *(repr(float(v)) for v in row), source,
                             repr(azimuth) if math.isfinite(azimuth) else ""])
        stats = self.statistics()
        for what in STATISTICS:
            if stats:
                values = [getattr(stats[name], what) for name in COORDINATES]
                azimuth_text = (repr(float(getattr(stats[COLUMN_AZIMUTH], what)))
                                if COLUMN_AZIMUTH in stats else "")
                writer.writerow([what, "", *(repr(float(v)) for v in values), "", azimuth_text])
        return out.getvalue()

    def to_dict(self) -> dict:
        """The placements and their statistics as JSON-ready data (NaN as None)."""
        def number(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        table = self.table()
        return {
            "unit": self.unit,
            "placements": [
                {"samples": samples, "theta_from": source,
                 **{name: number(v) for name, v in zip(COORDINATES, row)},
                 COLUMN_AZIMUTH: number(azimuth)}
                for row, samples, source, azimuth in zip(
                    table, self._samples, self._sources, self._column_azimuths)
            ],
            "statistics": {
                name: {"n": item.n, **{what: number(getattr(item, what))
                                       for what in STATISTICS}}
                for name, item in self.statistics().items()
            },
        }

    def export_csv(self, path: str | Path) -> None:
        Path(path).write_text(self.to_csv(), encoding="utf-8")
