"""An index of a recording by row and time, and an overview of the whole session, in one pass.

:class:`RecordingIndex` is filled chunk by chunk (:meth:`RecordingIndex.add`, from a
:class:`~app.core.recording.stream.RecordingStream`): where each chunk starts (byte offset, row,
line, time), where the gaps are (with the samples each one lost), and an
:class:`Overview`: the minimum and maximum of every axis over bins of consecutive rows, about
:data:`OVERVIEW_BINS` of them however long the recording, to draw the session at a glance.

Its size grows with the number of chunks (one entry per 8 MB of text) and gaps, never with the
rows: an hour at 6667 Hz is about 700 entries. Seeking with it reads one chunk.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from app.core.recording.format import ACCEL_COLUMNS, GYRO_COLUMNS
from app.core.recording.reader import Recording

OVERVIEW_BINS = 2000
"""Bins an overview aims at for the whole recording."""
CHANNELS = (*ACCEL_COLUMNS, *GYRO_COLUMNS)


@dataclass(frozen=True, slots=True)
class IndexEntry:
    """Where one chunk of rows starts."""

    first_row: int
    rows: int
    offset: int
    """Decompressed byte offset of its first line."""
    line: int
    first_t_s: float
    last_t_s: float


@dataclass(frozen=True, slots=True)
class Overview:
    """Minimum and maximum of each axis (ax, ay, az, gx, gy, gz) over bins of rows.

    ``t_s`` (B,) is each bin's first time on the device clock; ``low`` and ``high`` (B, 6) in
    the recording's units (m/s², rad/s); ``complete`` is False while the index is being built.
    """

    t_s: np.ndarray
    low: np.ndarray
    high: np.ndarray
    complete: bool
    rows: int

    def since_start(self, start_t_s: float) -> np.ndarray:
        """Bin times in s from ``start_t_s`` (the recording's first sample)."""
        return self.t_s - start_t_s


class RecordingIndex:
    """Chunk entries, gaps and the overview of one recording (see the module docstring).

    ``expected_rows`` sizes the overview's bins (an estimate is enough: the file's size over
    the first chunk's bytes per row). Not thread-safe: one thread adds, and readers take
    what they need under the owner's lock.
    """

    def __init__(self, expected_rows: int) -> None:
        self.entries: list[IndexEntry] = []
        self._first_ts: list[float] = []
        self._first_rows: list[int] = []
        self.gap_rows: list[int] = []
        self.gap_t_s: list[float] = []
        self.gap_lost: list[int] = []
        self.rows = 0
        self.complete = False
        self.rate_hz = math.nan
        self.bin_rows = max(1, math.ceil(max(expected_rows, 1) / OVERVIEW_BINS))
        self._bin_t: list[float] = []
        self._bin_low: list[np.ndarray] = []
        self._bin_high: list[np.ndarray] = []
        self._open: tuple[float, np.ndarray, np.ndarray, int] | None = None
        self._last_t: float | None = None

    # -- building ------------------------------------------------------------------------------
    def add(self, rows: Recording, first_row: int, offset: int, line: int) -> None:
        """Index one chunk (its rows, where it starts)."""
        n = len(rows)
        if n == 0:
            return
        t = rows.t_s
        self.entries.append(IndexEntry(first_row, n, offset, line, float(t[0]), float(t[-1])))
        self._first_ts.append(float(t[0]))
        self._first_rows.append(first_row)
        if math.isnan(self.rate_hz) and n > 1:
            odr = rows.device.get("odr_hz")
            steps = np.diff(t)
            steps = steps[steps > 0]
            self.rate_hz = (float(odr) if isinstance(odr, int | float) and odr > 0
                            else 1.0 / float(np.median(steps)) if len(steps) else math.nan)
        for local in np.flatnonzero(rows.gap).tolist():
            previous = t[local - 1] if local > 0 else self._last_t
            lost = 0
            if previous is not None and math.isfinite(self.rate_hz):
                lost = max(0, round((float(t[local]) - float(previous)) * self.rate_hz) - 1)
            self.gap_rows.append(first_row + local)
            self.gap_t_s.append(float(t[local]))
            self.gap_lost.append(lost)
        self._overview(t, np.column_stack([rows.columns[c] for c in CHANNELS]))
        self._last_t = float(t[-1])
        self.rows = first_row + n

    def _overview(self, t: np.ndarray, values: np.ndarray) -> None:
        start = 0
        n = len(t)
        if self._open is not None:  # finish the bin the last chunk left open
            t0, low, high, count = self._open
            take = min(self.bin_rows - count, n)
            part = values[:take]
            low = np.fmin(low, np.nanmin(part, axis=0))
            high = np.fmax(high, np.nanmax(part, axis=0))
            count += take
            start = take
            self._open = (t0, low, high, count)
            if count == self.bin_rows:
                self._close_bin()
        whole = (n - start) // self.bin_rows * self.bin_rows
        if whole:
            block = values[start:start + whole].reshape(-1, self.bin_rows, values.shape[1])
            with np.errstate(all="ignore"):
                lows, highs = np.nanmin(block, axis=1), np.nanmax(block, axis=1)
            self._bin_t.extend(t[start:start + whole:self.bin_rows].tolist())
            self._bin_low.extend(lows)
            self._bin_high.extend(highs)
        rest = start + whole
        if rest < n:
            part = values[rest:]
            self._open = (float(t[rest]), np.nanmin(part, axis=0), np.nanmax(part, axis=0),
                          n - rest)

    def _close_bin(self) -> None:
        assert self._open is not None
        t0, low, high, _ = self._open
        self._bin_t.append(t0)
        self._bin_low.append(low)
        self._bin_high.append(high)
        self._open = None

    def finish(self) -> None:
        """The whole file was indexed."""
        if self._open is not None:
            self._close_bin()
        self.complete = True

    # -- looking up ----------------------------------------------------------------------------
    @property
    def first_t_s(self) -> float:
        return self.entries[0].first_t_s if self.entries else math.nan

    @property
    def last_t_s(self) -> float:
        return self.entries[-1].last_t_s if self.entries else math.nan

    def entry_for_row(self, row: int) -> IndexEntry | None:
        """The chunk holding ``row``; None when it is not indexed yet."""
        k = bisect.bisect_right(self._first_rows, row) - 1
        if k < 0 or row >= self.rows:
            return None
        return self.entries[k]

    def entry_for_time(self, t_s: float) -> IndexEntry | None:
        """The chunk whose time span holds ``t_s`` (the first for earlier times, the last for
        later ones); None when nothing is indexed yet."""
        if not self.entries:
            return None
        k = bisect.bisect_right(self._first_ts, t_s) - 1
        return self.entries[max(k, 0)]

    def overview(self) -> Overview:
        """The overview so far (a copy: safe to hand to another thread)."""
        t = list(self._bin_t)
        low = list(self._bin_low)
        high = list(self._bin_high)
        if self._open is not None:
            t.append(self._open[0])
            low.append(self._open[1])
            high.append(self._open[2])
        width = len(CHANNELS)
        return Overview(np.asarray(t, dtype=np.float64),
                        np.asarray(low, dtype=np.float64).reshape(-1, width),
                        np.asarray(high, dtype=np.float64).reshape(-1, width),
                        self.complete, self.rows)
