"""Classified lines to sample records: accelerometer, gyroscope, field, temperature, times and
losses.
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass, replace
from itertools import groupby

import numpy as np

from drivers.text_stream.layout import Layout, columns_from_names
from drivers.text_stream.lexer import MAG_CHANNELS, NUMBER, NUMBER_RE, TO_SPACE, classify_line


# -- the parser: lines to records ----------------------------------------------------------------
@dataclass(slots=True)
class TextLineCounters:
    """What the driver saw. ``lines`` = parsed + rejected + ignored (blank lines not counted)."""

    bytes: int = 0
    lines: int = 0
    parsed: int = 0
    rejected: int = 0
    ignored: int = 0
    samples: int = 0
    incomplete: int = 0
    lost_samples: int = 0


class _Records:
    """Growing per-channel arrays, in arrival order."""

    def __init__(self) -> None:
        self.parts: list[dict[str, np.ndarray]] = []

    def add(self, **arrays: np.ndarray) -> None:
        self.parts.append(arrays)

    def take(self) -> dict[str, np.ndarray] | None:
        if not self.parts:
            return None
        parts, self.parts = self.parts, []
        return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


class LineParser:
    """Classified lines -> records (accelerometer, gyroscope, temperature, times, losses).

    Numeric rows take a vectorised path: runs of lines that match the expected row pattern are
    joined and converted by numpy in one go; other lines are classified one at a time.
    """

    def __init__(self, layout: Layout, counters: TextLineCounters, lock: threading.Lock,
                 *, columns_fixed: bool = False, time_col: str | None = None) -> None:
        self.layout = layout
        self.counters = counters
        self.lock = lock
        self.columns_fixed = columns_fixed
        self.time_col = time_col
        self.records = _Records()
        self._pending: dict[str, float] = {}
        self._lost = 0
        self._row_re = self._row_pattern(layout.n_columns)

    @staticmethod
    def _row_pattern(n: int) -> re.Pattern[str] | None:
        if n <= 0:
            return None
        sep = r"(?:\s*[,;]\s*|\s+)"
        return re.compile(rf"\s*[,;]?\s*{NUMBER}(?:{sep}{NUMBER}){{{n - 1}}}\s*[,;]?\s*")

    def feed(self, lines: list[str], arrival_s: np.ndarray) -> None:
        """Parse complete lines that arrived at host times ``arrival_s`` (one per line)."""
        pattern = self._row_re if self.layout.kind == "columns" else None
        fast = [pattern is not None and pattern.fullmatch(line) is not None for line in lines]
        start = 0
        for is_row, run in groupby(fast):
            count = len(list(run))
            chunk = lines[start : start + count]
            times = arrival_s[start : start + count]
            start += count
            if is_row:
                self._rows(chunk, times)
            else:
                for line, when in zip(chunk, times):
                    self._slow(line, float(when))

    def _count(self, **increments: int) -> None:
        with self.lock:
            for name, value in increments.items():
                setattr(self.counters, name, getattr(self.counters, name) + value)

    def _rows(self, lines: list[str], arrival_s: np.ndarray) -> None:
        n = self.layout.n_columns
        text = " ".join(lines).translate(TO_SPACE)
        values = np.array(text.split(), dtype=np.float64).reshape(-1, n)
        self._emit_rows(values, arrival_s)
        self._count(lines=len(lines), parsed=len(lines))

    def _emit_rows(self, values: np.ndarray, arrival_s: np.ndarray) -> None:
        cols = self.layout.columns
        m = len(values)

        def take(names: tuple[str, ...], fill: float) -> np.ndarray:
            out = np.full((m, len(names)), fill)
            for j, name in enumerate(names):
                if name in cols:
                    out[:, j] = values[:, cols[name]]
            return out

        lost = np.zeros(m, dtype=np.int64)
        lost[0] = self._lost
        self._lost = 0
        mag = {} if self.layout.mag_unit is None else {"mag": take(MAG_CHANNELS, math.nan)}
        self.records.add(
            accel=take(("ax", "ay", "az"), 0.0), gyro=take(("gx", "gy", "gz"), 0.0),
            temp=take(("temp",), math.nan)[:, 0],
            t_raw=take(("t",), math.nan)[:, 0], arrival=np.asarray(arrival_s, dtype=np.float64),
            lost=lost, **mag,
        )

    def _slow(self, text: str, arrival_s: float) -> None:
        line = classify_line(text)
        if line.kind == "blank":
            return
        if line.kind == "numbers" and self.layout.kind == "columns":
            if len(line.numbers) == self.layout.n_columns:
                self._emit_rows(np.array([line.numbers]), np.array([arrival_s]))
                self._count(lines=1, parsed=1)
            else:
                self._reject(looks_like_data=len(line.numbers) >= 3)
            return
        if line.kind == "header" and self.layout.kind == "columns" and not self.columns_fixed:
            columns, _hints = columns_from_names(line.names, self.time_col)
            if "t" in columns and self.layout.time_unit == "host":
                columns.pop("t")
            self.layout = replace(self.layout, n_columns=len(line.names), columns=columns)
            self._row_re = self._row_pattern(len(line.names))
            self._count(lines=1, parsed=1)
            return
        if line.kind == "labelled" and self.layout.kind == "labelled":
            self._labelled(line.values, arrival_s)
            return
        if line.kind in ("ignored", "header"):
            self._count(lines=1, ignored=1)
            return
        self._reject(looks_like_data=len(NUMBER_RE.findall(text)) >= 3 or "nan" in text.lower())

    def _reject(self, *, looks_like_data: bool) -> None:
        if looks_like_data:
            self._lost += 1
        self._count(lines=1, rejected=1)

    def _labelled(self, values: dict[str, float], arrival_s: float) -> None:
        """Collect labelled readings into a sample; emit it once complete."""
        pending = self._pending
        groups = {"a": ("ax", "ay", "az"), "g": ("gx", "gy", "gz")}
        for names in groups.values():
            if any(n in values for n in names) and any(n in pending for n in names):
                self._drop_incomplete()  # a new reading of a sensor already held
                pending = self._pending
                break
        if "temp" in values and "temp" in pending and any(n in pending for n in groups["a"]):
            self._drop_incomplete()
            pending = self._pending
        pending.update(values)
        self._count(lines=1, parsed=1)
        have_accel = all(n in pending for n in groups["a"])
        have_gyro = all(n in pending for n in groups["g"])
        if not have_gyro and any(n in values for n in groups["g"]):
            return
        if have_accel and (have_gyro or not self.layout.has_gyro):
            row = [pending.get(n, 0.0) for n in (*groups["a"], *groups["g"])]
            lost = np.array([self._lost], dtype=np.int64)
            self._lost = 0
            mag = {} if self.layout.mag_unit is None else {
                "mag": np.array([[pending.get(n, math.nan) for n in MAG_CHANNELS]])}
            self.records.add(
                accel=np.array([row[:3]]), gyro=np.array([row[3:]]),
                temp=np.array([pending.get("temp", math.nan)]),
                t_raw=np.array([pending.get("t", math.nan)]), arrival=np.array([arrival_s]),
                lost=lost, **mag,
            )
            self._pending = {}

    def _drop_incomplete(self) -> None:
        if any(k != "temp" for k in self._pending):
            self._lost += 1
            self._count(incomplete=1)
        self._pending = {}
