"""Repeatability of an arm's end point over repeated placements (the paper's tables).

The user puts the arm's tip on the same spot N times and captures each placement; a
placement is the mean of the end points over a short window (so noise averages out). The
statistics per coordinate are the mean, the sample standard deviation (n - 1), the minimum,
the maximum and the range.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.arm.kinematics import cylindrical

COORDINATES = ("x", "y", "z", "R", "Z", "azimuth_deg")
STATISTICS = ("mean", "sd", "min", "max", "range")


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

    def __len__(self) -> int:
        return len(self._points)

    def capture(self, end_points: np.ndarray) -> np.ndarray:
        """Add a placement: the mean of end points (N, 3) over the capture window."""
        points = np.asarray(end_points, dtype=np.float64).reshape(-1, 3)
        points = points[np.all(np.isfinite(points), axis=1)]
        if len(points) == 0:
            raise ValueError("no valid end point to capture")
        mean = points.mean(axis=0)
        self._points.append(mean)
        self._samples.append(len(points))
        return mean

    def remove_last(self) -> None:
        if self._points:
            self._points.pop()
            self._samples.pop()

    def clear(self) -> None:
        self._points.clear()
        self._samples.clear()

    def table(self) -> np.ndarray:
        """(N, 6) one row per placement: x, y, z, R, Z, azimuth_deg."""
        if not self._points:
            return np.empty((0, len(COORDINATES)))
        points = np.array(self._points)
        return np.column_stack([points, cylindrical(points, self.base)])  # type: ignore[arg-type]

    def statistics(self) -> dict[str, CoordinateStats]:
        """Per coordinate: n, mean, SD (n - 1), min, max. Empty without placements."""
        table = self.table()
        n = len(table)
        if n == 0:
            return {}
        sd = table.std(axis=0, ddof=1) if n > 1 else np.full(table.shape[1], np.nan)
        return {
            name: CoordinateStats(
                n, float(table[:, i].mean()), float(sd[i]),
                float(table[:, i].min()), float(table[:, i].max()),
            )
            for i, name in enumerate(COORDINATES)
        }

    def to_csv(self) -> str:
        """Placements then the mean, sd, min, max and range rows, one column per coordinate."""
        out = io.StringIO()
        out.write(f"# arm end point repeatability, lengths in {self.unit}, angles in degrees\n")
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(["placement", "samples", *COORDINATES])
        for i, (row, samples) in enumerate(zip(self.table(), self._samples), start=1):
            writer.writerow([i, samples, *(repr(float(v)) for v in row)])
        stats = self.statistics()
        for what in STATISTICS:
            if stats:
                values = [getattr(stats[name], what) for name in COORDINATES]
                writer.writerow([what, "", *(repr(float(v)) for v in values)])
        return out.getvalue()

    def export_csv(self, path: str | Path) -> None:
        Path(path).write_text(self.to_csv(), encoding="utf-8")
