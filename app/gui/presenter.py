"""The live presenter: once per screen refresh, pull from the ring buffers and feed the views
that are on screen, and only those whose input changed.

This is the one place where buffered data meets widgets. The maths it needs (averaging,
unit conversion) comes from :mod:`app.core`; the widgets only receive finished numbers.
Frames are paced by :class:`~app.gui.frame_clock.FrameClock` (the screen's refresh rate,
resting while nothing changes); each view keeps the key of what it last showed (newest row,
settings, size), so a frame without new data draws nothing and a hidden view does no work
until it is shown again.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtWidgets import QLabel, QWidget

from app.core.calibration_procedures import StaticStatistics
from app.core.comparison import summarize_errors
from app.core.decimation import IncrementalMinMax, connect_mask, decimation_factor
from app.core.filters import FILTERS
from app.core.measurement_log import Measurement, measure
from app.core.readout import SLOPE_UNITS, averaged_angles, compare_to_truth, slope_from_angle
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.gui.bubble_level import BubbleLevel
from app.gui.filter_panel import FilterPanel
from app.gui.frame_clock import FrameClock
from app.gui.plots import LivePlots
from app.gui.readouts import TiltReadouts
from app.services.session import DeviceSession

ANGLE_TRACES = ["roll", "pitch", "ref_roll", "ref_pitch"]
ERROR_TABLE_INTERVAL_S = 0.5
MAX_SCROLL_LEAD_S = 0.25
"""Between blocks the plots scroll on with the clock, at most this long (and at most 1.5
block intervals) past the newest sample: a stream that stopped leaves them still."""
UNIT_LABELS = {key: unit.suffix or "1:n" for key, unit in SLOPE_UNITS.items()}
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
LEVEL_INTERVAL_S = 0.04
"""The bubble takes new averages at most this often (25 Hz): it shows a 0.5 s average by
default, which moves less in 40 ms than the eye can follow as separate steps."""
EXPOSURE_CHECK_S = 0.25
"""How long a view found uncovered is taken as uncovered (hidden views are noticed at
once: ``isVisible`` is checked every frame; only the costlier region test is kept)."""


@dataclass(slots=True)
class DisplaySettings:
    """How the readouts present the angles."""

    unit: str = "deg"
    averaging_s: float = 0.5
    hold: bool = False
    readout_rate_hz: float = 10.0
    """Numeric readouts change at most this often, like a digital level's display: faster
    figures cannot be read, and every text change repaints the tiles."""


def on_screen(widget: QWidget) -> bool:
    """Whether any of ``widget`` can be seen: shown, not in a hidden dock or tab, not covered
    entirely, its window not minimised."""
    return widget.isVisible() and not widget.window().isMinimized() and _exposed(widget)


class ScreenPresence:
    """:func:`on_screen` for a view asked every frame: the region test (the costly part)
    is redone at most every ``EXPOSURE_CHECK_S`` while the view stays visible."""

    def __init__(self, widget: QWidget) -> None:
        self.widget = widget
        self._checked = -np.inf
        self._exposed = False

    def __call__(self, now: float) -> bool:
        widget = self.widget
        if not widget.isVisible() or widget.window().isMinimized():
            self._checked = -np.inf
            return False
        if now - self._checked >= EXPOSURE_CHECK_S:
            self._checked = now
            self._exposed = _exposed(widget)
        return self._exposed


def _exposed(widget: QWidget) -> bool:
    """Some of ``widget`` or of a child is uncovered (children that fill their parent leave
    the parent's own visible region empty)."""
    if not widget.visibleRegion().isEmpty():
        return True
    children = widget.findChildren(QWidget, options=Qt.FindChildOption.FindDirectChildrenOnly)
    return any(child.isVisible() and _exposed(child) for child in children)


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


class LivePresenter(QObject):
    """Refreshes the bubble level, the readouts and the plots when their data change."""

    framesPerSecond = Signal(float)
    attitudeChanged = Signal(object)  # the newest orientation quaternion, on new data (3D view)

    def __init__(
        self,
        session: DeviceSession,
        level: BubbleLevel,
        readouts: TiltReadouts,
        plots: LivePlots,
        truth_label: QLabel,
        filter_panel: FilterPanel,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.filter_panel = filter_panel
        self.session = session
        self.level = level
        self.readouts = readouts
        self.plots = plots
        self.truth_label = truth_label
        self.settings = DisplaySettings()
        self.plots_enabled = True
        self.clock = FrameClock(level, parent=self)
        self.clock.tick.connect(self._on_tick)
        self.frames = 0
        """Frames that drew something (ticks without changes are not counted)."""
        self.plot_updates = 0
        """How often the plots were handed new data."""
        self.plot_scrolls = 0
        """How often the plots were only moved on between two blocks of data."""
        self._plot_wall = 0.0
        self._block_interval_s = MAX_SCROLL_LEAD_S
        self._fps_window = (time.monotonic(), 0)
        self._fps_shown = -1
        self._no_data_shown = False
        self._level_key: tuple | None = None
        self._text_key: tuple | None = None
        self._plot_key: tuple | None = None
        self._error_key: tuple | None = None
        self._last_text_update = -np.inf
        self._sensor_trace: IncrementalMinMax | None = None
        self._angle_trace: IncrementalMinMax | None = None
        self._comparison_traces: dict[str, IncrementalMinMax] = {}
        self._last_error_update = -np.inf
        self._shown_quat: np.ndarray | None = None
        """The quaternions behind the readouts' figures (what Hold keeps showing)."""
        self._last_level_update = -np.inf
        self.level_interval_s = LEVEL_INTERVAL_S
        self.plot_data_interval_s = PLOT_DATA_INTERVAL_S
        self._plots_were_shown = False
        self._quiet: tuple[tuple | None, float, bool] = (None, 0.0, False)
        """The last full frame's key, until when nothing falls due, and whether it had
        something pending."""
        self._averaged_cache: tuple[tuple, object] | None = None
        self._incremental = False
        self.incremental_max_per_px = INCREMENTAL_MAX_PER_PX
        self._t0 = 0.0  # time of the newest sample at the last rebuild (x = 0 there)
        self._drawn: dict[str, tuple[int, float]] = {}  # ring -> (rows seen, newest t drawn)
        self._drawn_rel = 0.0  # newest sample drawn, seconds after _t0
        self._drawn_wall = 0.0  # when it was drawn
        self._event_wall = 0.0  # the last rebuild or append (block interval estimate)
        self.plot_appends = 0
        """How often new samples were drawn onto the plots without a rebuild."""
        plots.resync = self._resync_plots
        self._last_live: float | None = None
        """Wall-clock time (``time.time()``) the readouts last showed new data."""
        self._stale_rows: int | None = None
        """Rows written when the device was lost (None: live)."""
        if isinstance(session, DeviceSession):  # (tests drive a bare pipeline)
            session.disconnected.connect(self.show_stale)
            session.reconnecting.connect(self.show_stale)
        self._shown = {
            view: ScreenPresence(view) for view in (level, readouts, plots, filter_panel)
        }

    def start(self) -> None:
        self.clock.start()

    def show_stale(self, *_reason: object) -> None:
        """The device was lost (a connection error, an unplug, a disconnect): the figures on
        show turn grey, with the time they were last live, until new data arrive."""
        if self._last_live is not None and self.readouts.isValid():
            # Rows already buffered are not news: only rows after these make it live again.
            self._stale_rows = self.session.pipeline.orientation.total_written
            self.readouts.setStale(self._last_live)

    def stop(self) -> None:
        self.clock.stop()

    def set_hold(self, hold: bool) -> None:
        self.settings.hold = hold
        self.readouts.setHold(hold)
        self.clock.wake()

    # -- the frame --------------------------------------------------------------------------
    def _on_tick(self) -> None:
        self.clock.report(self.refresh())

    def refresh(self) -> bool:
        """Draw what changed since the last frame; True if something was drawn (or a readout
        update is due shortly), i.e. the clock should keep the screen rate."""
        pipeline = self.session.pipeline
        orientation = pipeline.orientation
        total = orientation.total_written
        if total == 0:
            busy = self._show_no_data()
            self._count_frame(busy)
            return busy
        now = time.monotonic()
        quiet_key = self._quiet_key(total)
        if quiet_key == self._quiet[0] and now < self._quiet[1]:
            # Nothing new and nothing due (most frames between two blocks): only the plots
            # move on with the clock.
            drew = self._plots_were_shown and self._scroll_plots(now)
            self._count_frame(drew)
            return drew or self._quiet[2]
        self._no_data_shown = False
        drew = pending = False
        due = [np.inf]  # when something deferred falls due
        level_key = (total, self.settings.unit, self.settings.averaging_s)
        if not self.settings.hold:
            averaged = None
            if level_key != self._level_key and self._shown[self.level](now):
                if now - self._last_level_update >= self.level_interval_s:
                    averaged = self._averaged(orientation)
                    self._show_level(averaged)
                    self._level_key = level_key
                    self._last_level_update = now
                    drew = True
                else:
                    pending = True
                    due.append(self._last_level_update + self.level_interval_s)
            if level_key != self._text_key and self._shown[self.readouts](now):
                if now - self._last_text_update >= 1.0 / self.settings.readout_rate_hz:
                    self._show_texts(averaged or self._averaged(orientation))
                    self._text_key = level_key
                    self._last_text_update = now
                    drew = True
                else:
                    pending = True  # due shortly: the clock keeps its pace until then
                    due.append(self._last_text_update + 1.0 / self.settings.readout_rate_hz)
        plot_key = self._plot_key_of(total)
        plots_shown = self.plots_enabled and self._shown[self.plots](now)
        just_shown, self._plots_were_shown = plots_shown and not self._plots_were_shown, plots_shown
        if plots_shown:
            new_data = plot_key != self._plot_key
            structural = (just_shown or self._plot_key is None
                          or plot_key[1:] != self._plot_key[1:])
            interval = FULL_REBUILD_S if self._incremental else self.plot_data_interval_s
            rebuild = new_data and (structural or now - self._plot_wall >= interval)
            settle_at = self._drawn_wall + SETTLE_REBUILD_S
            if self.plots.behind and not new_data and now >= settle_at:
                rebuild = True  # the stream stopped: the scene takes what the screen shows
            segments = None
            if not rebuild and new_data and self._incremental and self.plots.appends:
                segments = self._new_segments(now)
                rebuild = segments is None
            if rebuild:
                self._rebuild_plots(now, plot_key, arrived=new_data)
                drew = True
            else:
                drew = self._scroll_plots(now) or drew
                if segments:
                    if self.plots.append(segments):
                        self.plot_appends += 1
                    else:  # a value left its plot's range: the range grows at a rebuild
                        self._rebuild_plots(now, plot_key)
                    drew = True
                if segments is not None:
                    self._plot_key = plot_key
                elif new_data:
                    pending = True  # new data, drawn once the interval is over
                    due.append(self._plot_wall + interval)
        error_key = (total, self.plots.window_s, tuple(pipeline.comparison_buffers))
        if error_key != self._error_key and self._shown[self.filter_panel](now):
            if now - self._last_error_update >= ERROR_TABLE_INTERVAL_S:
                self._last_error_update = now
                self._error_key = error_key
                self.update_error_table()
            else:
                due.append(self._last_error_update + ERROR_TABLE_INTERVAL_S)
        self._count_frame(drew)
        # Until new data arrive (or a setting changes) the frames only scroll the plots, up
        # to the moment a deferred update falls due.
        if self.plots.behind:
            due.append(self._drawn_wall + SETTLE_REBUILD_S)
        self._quiet = (quiet_key, max(min(due), now), pending)
        return drew or pending

    def _quiet_key(self, total: int) -> tuple:
        """What, unchanged, means a frame has nothing to draw but the plots' scrolling."""
        settings = self.settings
        # Runs every frame: one Qt call (plots shown or not; a resize is taken care of by
        # the next block's frame, and the plots repaint themselves meanwhile).
        return (total, settings.unit, settings.averaging_s, settings.hold,
                self.plots.window_s, self.plots.isVisible(),
                len(self.session.pipeline.comparison_buffers), self.plots_enabled)

    def _lead(self, now: float) -> float:
        """How far (s) the traces are moved left of where the last rebuild put them: the
        newest sample's time after it, plus the time since it arrived (a stream that
        stopped leaves them still)."""
        return self._drawn_rel + min(now - self._drawn_wall, MAX_SCROLL_LEAD_S,
                                     1.5 * self._block_interval_s)

    def _scroll_plots(self, now: float) -> bool:
        """Move the traces on with the clock."""
        if self.plots.scroll_to(self._lead(now)):
            self.plot_scrolls += 1
            return True
        return False

    def _show_no_data(self) -> bool:
        """Dashes and an empty vial, once per stretch without data; True when it drew."""
        if self._no_data_shown:
            return False
        self._no_data_shown = True
        self._level_key = self._text_key = self._plot_key = self._error_key = None
        self.level.setValid(False)
        self.readouts.setValid(False)
        self.truth_label.setText("")
        self.plots.clear()
        return True

    def _averaged(self, orientation) -> tuple[dict, object] | None:
        """The newest averaging window's rows and their mean angles (None: no attitude);
        the bubble's and the readouts' frames share it while no new rows came."""
        key = (orientation.total_written, self.settings.averaging_s, id(orientation))
        if self._averaged_cache is not None and self._averaged_cache[0] == key:
            return self._averaged_cache[1]
        result = self._average(orientation)
        self._averaged_cache = (key, result)
        return result

    def _average(self, orientation) -> tuple[dict, object] | None:
        recent = orientation.window(
            self.settings.averaging_s,
            names=["quat", "ref_roll", "ref_pitch", "incl_error"],
        )
        angles = averaged_angles(recent["quat"])
        return None if angles is None else (recent, angles)

    def _show_level(self, averaged: tuple[dict, object] | None) -> None:
        """The bubble (it repaints itself only when it moves by a visible amount)."""
        if averaged is None:
            return
        recent, angles = averaged
        self.attitudeChanged.emit(recent["quat"][-1])
        self.level.setValid(True)
        self.level.setTilt(angles.roll_deg, angles.pitch_deg, angles.tilt_deg)
        ref_roll, ref_pitch = recent["ref_roll"][-1], recent["ref_pitch"][-1]
        if np.isfinite(ref_roll):
            self.level.setReference(float(ref_roll), float(ref_pitch))
        else:
            self.level.clearReference()

    def _show_texts(self, averaged: tuple[dict, object] | None) -> None:
        """The numeric readouts and the simulator-truth line (labels repaint only when their
        text changes)."""
        if averaged is None:
            return
        recent, angles = averaged
        self._shown_quat = recent["quat"]
        unit = self.settings.unit
        self.readouts.setValid(True)
        if self._stale_rows is None:
            self._last_live = time.time()
        elif self.session.pipeline.orientation.total_written > self._stale_rows:
            self._stale_rows = None
            self._last_live = time.time()
            self.readouts.setStale(None)
        self.readouts.setValues(
            float(slope_from_angle(angles.roll_deg, unit)),
            float(slope_from_angle(angles.pitch_deg, unit)),
            float(slope_from_angle(angles.tilt_deg, unit)),
            angles.direction_deg,
            unit,
        )
        self._show_truth(recent)

    def _show_truth(self, recent: dict) -> None:
        """The simulator's truth over the same averaging window as the readouts (so during
        a turn both describe the same time), the error of the shown reading, and the
        per-sample RMS error; empty without a truth."""
        tare = self.session.pipeline.level_reference
        truth = compare_to_truth(recent["quat"], recent["ref_roll"], recent["ref_pitch"],
                                 recent["incl_error"],
                                 None if tare is None else tare.quaternion)
        untared = "" if tare is None else ", not tared"
        text = "" if truth is None else (
            f"Simulator truth ({self.settings.averaging_s:g} s mean{untared})  "
            f"roll {truth.roll_deg:+.2f}°  pitch {truth.pitch_deg:+.2f}°  ·  "
            f"reading error {truth.reading_error_deg:.2f}°  ·  "
            f"sample error {truth.sample_rms_deg:.2f}° RMS"
        )
        if self.truth_label.text() != text:
            self.truth_label.setText(text)

    def current_reading(self, label: str = "") -> Measurement | None:
        """The reading the readouts show (held, or over the averaging time up to now) with its
        mean and standard deviation, unit, filter, calibration and device; None without data."""
        info = self.session.device_info
        quat = self._shown_quat
        if not self.settings.hold or quat is None:
            quat = self.session.pipeline.orientation.window(self.settings.averaging_s,
                                                            ["quat"])["quat"]
        if info is None and not self.settings.hold:
            return None
        pipeline = self.session.pipeline
        calibration = pipeline.calibration.name
        if pipeline.level_reference is not None:
            calibration += " + tare"
        device = "" if info is None else f"{info.name} ({info.unique_id})"
        return measure(quat, self.settings.unit, self.settings.averaging_s, label=label,
                       filter_name=pipeline.filter.name, calibration=calibration,
                       device=device)

    def _rebuild_plots(self, now: float, plot_key: tuple, arrived: bool = True) -> None:
        """Hand the plots every trace anew (decimated to their width). ``arrived``: for new
        data (they are shown at the right edge); otherwise the traces stay where the screen
        shows them (their newest sample as far left of the edge as before)."""
        self._update_plots(self.session.pipeline.samples, self.session.pipeline.orientation)
        self._plot_key = plot_key
        self.plot_updates += 1
        self._plot_wall = now
        self._drawn_rel = 0.0
        if arrived:
            self._note_block(now)
            self._drawn_wall = now
        else:
            self.plots.place_at(self._lead(now))

    def _resync_plots(self) -> None:
        """The plots' scene must paint: rebuild its traces from the buffers first."""
        pipeline = self.session.pipeline
        total = pipeline.orientation.total_written
        if total == 0 or pipeline.samples.total_written == 0:
            return
        self._rebuild_plots(time.monotonic(), self._plot_key_of(total), arrived=False)

    def _plot_key_of(self, total: int) -> tuple:
        """What the traces were built from: rows, window, width, compared filters."""
        return (total, self.plots.window_s, self.plots.width(),
                tuple(self.session.pipeline.comparison_buffers))

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
            self._drawn_wall = now
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

    def _update_plots(self, samples, orientation) -> None:
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

    def update_error_table(self) -> None:
        """Refresh the filter panel's error table (called at a low rate)."""
        pipeline = self.session.pipeline
        window = self.plots.window_s
        rows = [summarize_errors(pipeline.orientation, pipeline.filter.title, window)]
        for name, ring in pipeline.comparison_buffers.items():
            rows.append(summarize_errors(ring, FILTERS[name].title, window))
        self.filter_panel.show_errors([(r.name, r.rms_deg, r.max_deg) for r in rows])

    @staticmethod
    def _rate_hint(samples) -> float:
        """Rows per second in the buffer, from its newest second."""
        recent = samples.window(1.0, ["t"])["t"]
        span = recent[-1] - recent[0] if len(recent) > 1 else 0.0
        return (len(recent) - 1) / span if span > 0 else 1.0

    def _count_frame(self, drew: bool) -> None:
        if drew:
            self.frames += 1
        start, frames_then = self._fps_window
        now = time.monotonic()
        if now - start >= 1.0:
            fps = (self.frames - frames_then) / (now - start)
            self._fps_window = (now, self.frames)
            if round(fps) != self._fps_shown:  # the status bar repaints only on a change
                self._fps_shown = round(fps)
                self.framesPerSecond.emit(fps)
