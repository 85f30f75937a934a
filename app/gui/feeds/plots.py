"""The live plots' feed: the traces are rebuilt (min/max decimated to the plots' width) when
new data or a new window need it; at moderate rates new samples are drawn onto the screen as
they arrive; between blocks the traces scroll on with the clock."""

from __future__ import annotations

import time

import numpy as np

from app.core.calibration_procedures import StaticStatistics
from app.core.decimation import IncrementalMinMax, connect_mask, decimation_factor
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.gui.feeds.frame import Frame
from app.gui.feeds.screen import ScreenPresence
from app.gui.plots import LivePlots

ANGLE_TRACES = ["roll", "pitch", "ref_roll", "ref_pitch"]
MAX_SCROLL_LEAD_S = 0.25
"""Between blocks the plots scroll on with the clock, at most this long (and at most 1.5
block intervals) past the newest sample: a stream that stopped leaves them still."""
PLOT_DATA_INTERVAL_S = 0.05
"""New data rebuild the traces at most this often; the frames between only scroll them.
At a 10 s window on 1270 px the newest 50 ms are 6 px: the trace's end stays that close to
the right edge, while every frame still moves the traces on. Rebuilding is what costs."""
INCREMENTAL_MAX_PER_PX = 8.0
"""Up to this many samples per pixel column (a 10 s window at 833 Hz on 1270 px: 6.6) new
samples are drawn onto the screen as they arrive (:meth:`LivePlots.append`), and the traces
are rebuilt only every ``FULL_REBUILD_S``; at higher rates they are rebuilt every
``PLOT_DATA_INTERVAL_S`` (min/max decimated) and only scroll in between."""
FULL_REBUILD_S = 2.0
"""While new samples are appended, the traces are still rebuilt this often (a value range
shrinks only at a rebuild; a range that must grow rebuilds at once)."""
SETTLE_REBUILD_S = 0.5
"""Samples appended onto the screen reach the plots' scene (export, a repaint) by a rebuild
once no new ones came for this long (a stream that stopped or paused)."""
MAX_APPEND_ROWS = 2048
"""More new rows than this in one frame are drawn by a rebuild instead."""


def _breaks(gap: np.ndarray) -> np.ndarray:
    """Where appended lines break: after lost data; never before the first row (the
    previous end, whose loss lies before it)."""
    breaks = gap > 0.5
    breaks[0] = False
    return breaks


def gap_connect(gap: np.ndarray) -> np.ndarray | str:
    """pyqtgraph ``connect`` for a (decimated) gap column: ``"all"`` when nothing was lost,
    which lets pyqtgraph build the line in one pass."""
    if len(gap) < 2 or not np.any(gap[1:] > 0.5):
        return "all"
    return connect_mask(gap)


class PlotFeed:
    """Hands the plots their traces: rebuilt, appended to, or only scrolled."""

    def __init__(self, plots: LivePlots, session) -> None:
        self.plots = plots
        self.session = session
        self.shown = ScreenPresence(plots)
        self.updates = 0
        """How often the plots were handed new data."""
        self.scrolls = 0
        """How often the plots were only moved on between two blocks of data."""
        self.appends = 0
        """How often new samples were drawn onto the plots without a rebuild."""
        self.data_interval_s = PLOT_DATA_INTERVAL_S
        self.incremental_max_per_px = INCREMENTAL_MAX_PER_PX
        self.key: tuple | None = None
        self.was_shown = False
        self._plot_wall = 0.0
        self._block_interval_s = MAX_SCROLL_LEAD_S
        self._sensor_trace: IncrementalMinMax | None = None
        self._angle_trace: IncrementalMinMax | None = None
        self._comparison_traces: dict[str, IncrementalMinMax] = {}
        self._incremental = False
        self._t0 = 0.0  # time of the newest sample at the last rebuild (x = 0 there)
        self._drawn: dict[str, tuple[int, float]] = {}  # ring -> (rows seen, newest t drawn)
        self._drawn_rel = 0.0  # newest sample drawn, seconds after _t0
        self.drawn_wall = 0.0  # when it was drawn
        self._event_wall = 0.0  # the last rebuild or append (block interval estimate)
        plots.resync = self._resync

    def frame(self, frame: Frame, total: int, enabled: bool) -> None:
        """Rebuild, append or scroll, as this frame needs."""
        now = frame.now
        plot_key = self.key_of(total)
        plots_shown = enabled and self.shown(now)
        just_shown, self.was_shown = plots_shown and not self.was_shown, plots_shown
        if not plots_shown:
            return
        new_data = plot_key != self.key
        structural = just_shown or self.key is None or plot_key[1:] != self.key[1:]
        interval = FULL_REBUILD_S if self._incremental else self.data_interval_s
        rebuild = new_data and (structural or now - self._plot_wall >= interval)
        if self.plots.behind and not new_data and now >= self.drawn_wall + SETTLE_REBUILD_S:
            rebuild = True  # the stream stopped: the scene takes what the screen shows
        segments = None
        if not rebuild and new_data and self._incremental and self.plots.appends:
            segments = self._new_segments(now)
            rebuild = segments is None
        if rebuild:
            self._rebuild(now, plot_key, arrived=new_data)
            frame.drew = True
            return
        frame.drew = self.scroll(now) or frame.drew
        if segments:
            if self.plots.append(segments):
                self.appends += 1
            else:  # a value left its plot's range: the range grows at a rebuild
                self._rebuild(now, plot_key)
            frame.drew = True
        if segments is not None:
            self.key = plot_key
        elif new_data:
            frame.defer(self._plot_wall + interval)  # new data, drawn after the interval

    def key_of(self, total: int) -> tuple:
        """What the traces were built from: rows, window, width, compared filters."""
        return (total, self.plots.window_s, self.plots.width(),
                tuple(self.session.pipeline.comparison_buffers))

    def _lead(self, now: float) -> float:
        """How far (s) the traces are moved left of where the last rebuild put them: the
        newest sample's time after it, plus the time since it arrived (a stream that
        stopped leaves them still)."""
        return self._drawn_rel + min(now - self.drawn_wall, MAX_SCROLL_LEAD_S,
                                     1.5 * self._block_interval_s)

    def scroll(self, now: float) -> bool:
        """Move the traces on with the clock."""
        if self.plots.scroll_to(self._lead(now)):
            self.scrolls += 1
            return True
        return False

    def clear(self) -> None:
        self.key = None
        self.plots.clear()

    def _rebuild(self, now: float, plot_key: tuple, arrived: bool = True) -> None:
        """Hand the plots every trace anew (decimated to their width). ``arrived``: for new
        data (they are shown at the right edge); otherwise the traces stay where the screen
        shows them (their newest sample as far left of the edge as before)."""
        self._update(self.session.pipeline.samples, self.session.pipeline.orientation)
        self.key = plot_key
        self.updates += 1
        self._plot_wall = now
        self._drawn_rel = 0.0
        if arrived:
            self._note_block(now)
            self.drawn_wall = now
        else:
            self.plots.place_at(self._lead(now))

    def _resync(self) -> None:
        """The plots' scene must paint: rebuild its traces from the buffers first."""
        pipeline = self.session.pipeline
        total = pipeline.orientation.total_written
        if total == 0 or pipeline.samples.total_written == 0:
            return
        self._rebuild(time.monotonic(), self.key_of(total), arrived=False)

    def _note_block(self, now: float) -> None:
        interval = min(now - self._event_wall, MAX_SCROLL_LEAD_S)
        self._block_interval_s += 0.2 * (interval - self._block_interval_s)
        self._event_wall = now

    def _new_segments(self, now: float) -> list | None:
        """The samples that arrived since the traces were last drawn, as lines from each
        trace's previous end (for :meth:`LivePlots.append`); [] when none arrived; None when
        a rebuild should draw them (too many)."""
        pipeline = self.session.pipeline
        plots = self.plots
        sensor = self._rows_since("samples", pipeline.samples, ["t", "accel", "gyro", "gap"])
        angles = self._rows_since(
            "orientation", pipeline.orientation, ["t", *ANGLE_TRACES, "gap", "incl_error"])
        compared = {
            name: self._rows_since(f"compare:{name}", ring, ["t", "roll", "pitch", "incl_error"])
            for name, ring in pipeline.comparison_buffers.items()
        }
        if any(rows is None for rows in (sensor, angles, *compared.values())):
            return None
        segments: list = []
        t0 = self._t0
        if sensor is not None and len(sensor["t"]) > 1:
            x = sensor["t"] - t0
            breaks = _breaks(sensor["gap"])
            accel = sensor["accel"] / STANDARD_GRAVITY_M_S2
            gyro = np.degrees(sensor["gyro"])
            for axis in range(3):
                segments.append((plots.accel_curves[axis], x, accel[:, axis], breaks))
                segments.append((plots.gyro_curves[axis], x, gyro[:, axis], breaks))
            self._drawn_rel = float(x[-1])
            self.drawn_wall = now
        if angles is not None and len(angles["t"]) > 1:
            x = angles["t"] - t0
            breaks = _breaks(angles["gap"])
            for name, curve in plots.angle_curves.items():
                segments.append((curve, x, angles[name], breaks))
            if plots.error_visible:
                segments.append((plots.error_curve, x, angles["incl_error"], breaks))
        for name, rows in compared.items():
            curves = plots.comparison_curves.get(name)
            if curves is None or rows is None or len(rows["t"]) < 2:
                continue
            x = rows["t"] - t0
            breaks = np.zeros(len(x), dtype=bool)
            segments.append((curves[0], x, rows["roll"], breaks))
            segments.append((curves[1], x, rows["pitch"], breaks))
            error_curve = plots.comparison_error_curves.get(name)
            if plots.error_visible and error_curve is not None:
                segments.append((error_curve, x, rows["incl_error"], breaks))
        if segments:
            self._note_block(now)
        return segments

    def _rows_since(self, key: str, ring, names: list[str]) -> dict | None:
        """The rows of ``ring`` from the newest one drawn on (it first); None when there are
        too many, or the ring restarted."""
        seen, last_t = self._drawn.get(key, (0, -np.inf))
        first, rows = ring.since(max(seen - 1, 0), names)
        if len(rows["t"]) > MAX_APPEND_ROWS or (len(rows["t"]) and rows["t"][-1] < last_t):
            return None
        self._drawn[key] = (first + len(rows["t"]), float(rows["t"][-1]) if len(rows["t"])
                            else last_t)
        keep = rows["t"] >= last_t
        return {name: values[keep] for name, values in rows.items()}

    def _update(self, samples, orientation) -> None:
        if self._sensor_trace is None or self._sensor_trace.ring is not samples:
            self._sensor_trace = IncrementalMinMax(samples, ["accel", "gyro", "gap"])
        if self._angle_trace is None or self._angle_trace.ring is not orientation:
            self._angle_trace = IncrementalMinMax(
                orientation, [*ANGLE_TRACES, "gap", "incl_error"]
            )
        window = self.plots.window_s
        # Rows seen before the fetch: rows written meanwhile are drawn twice, never missed.
        totals = {"samples": samples.total_written, "orientation": orientation.total_written,
                  **{f"compare:{name}": ring.total_written
                     for name, ring in self.session.pipeline.comparison_buffers.items()}}
        # A min/max pair per two pixel columns: all a plot can show at 1 px line width.
        info = self.session.device_info
        rate = info.odr_hz if info is not None else self._rate_hint(samples)
        expected_rows = min(len(samples), window * rate)
        width = max(self.plots.width(), 200)
        self._incremental = window * rate / width <= self.incremental_max_per_px
        factor = decimation_factor(int(expected_rows), width)
        if self._incremental and expected_rows <= width:
            # No more samples than pixel columns: drawn as they are, like the new samples
            # appended between rebuilds (a min/max pair per two columns would look different).
            factor = 1
        sensor_t, sensor = self._sensor_trace.window(window, factor)
        angle_t, angle_values = self._angle_trace.window(window, factor)
        if len(sensor_t) == 0:
            return
        newest = sensor_t[-1]
        self._t0 = float(newest)
        # Every ring is drawn up to here: appends go on from these rows.
        self._drawn = {key: (seen, self._t0) for key, seen in totals.items()}
        self._update_comparisons(window, factor, newest)
        self.plots.set_data(
            sensor_t - newest,
            sensor[:, :3] / STANDARD_GRAVITY_M_S2,
            np.degrees(sensor[:, 3:6]),
            angle_t - newest,
            {key: angle_values[:, i] for i, key in enumerate(ANGLE_TRACES)},
            sensor_connect=gap_connect(sensor[:, 6]),
            angle_connect=gap_connect(angle_values[:, len(ANGLE_TRACES)]),
        )
        error = angle_values[:, len(ANGLE_TRACES) + 1]
        self.plots.set_error_visible(len(error) > 0 and bool(np.isfinite(error[-1])))
        self.plots.set_error_data(angle_t - newest, error)

    def _update_comparisons(self, window: float, factor: int, newest: float) -> None:
        buffers = self.session.pipeline.comparison_buffers
        traces = {}
        for name, ring in buffers.items():
            trace = self._comparison_traces.get(name)
            traces[name] = trace if trace is not None and trace.ring is ring else (
                IncrementalMinMax(ring, ["roll", "pitch", "incl_error"])
            )
            t, values = traces[name].window(window, factor)
            self.plots.set_comparison_data(
                name, t - newest, values[:, 0], values[:, 1], values[:, 2]
            )
        self._comparison_traces = traces

    @staticmethod
    def _rate_hint(samples) -> float:
        """Rows per second in the buffer, from its newest second."""
        recent = samples.window(1.0, ["t"])["t"]
        span = recent[-1] - recent[0] if len(recent) > 1 else 0.0
        return (len(recent) - 1) / span if span > 0 else 1.0

    def range_statistics(self, start_rel_s: float, end_rel_s: float):
        """Statistics of roll, pitch and tilt over a range relative to the newest sample."""
        orientation = self.session.pipeline.orientation
        rows = orientation.window(self.plots.window_s, ["t", "roll", "pitch", "tilt"])
        if len(rows["t"]) == 0:
            return None
        newest = rows["t"][-1]
        inside = (rows["t"] >= newest + start_rel_s) & (rows["t"] <= newest + end_rel_s)
        if not np.any(inside):
            return None
        statistics = StaticStatistics(duration_s=float("inf"))
        statistics.update(
            rows["t"][inside], rows["roll"][inside], rows["pitch"][inside], rows["tilt"][inside]
        )
        return statistics.result()
