"""The live presenter: once per screen refresh, pull from the ring buffers and feed the views
that are on screen, and only those whose input changed.

This is the one place where buffered data meets widgets. The maths it needs (averaging,
unit conversion) comes from :mod:`app.core`; the widgets only receive finished numbers.
Frames are paced by :class:`~app.gui.frame_clock.FrameClock` (the screen's refresh rate,
resting while nothing changes). Each view has its feed (:mod:`app.gui.feeds`: the bubble,
the readouts, the plots, the error table) that keeps the key of what it last showed (newest
row, settings, size), so a frame without new data draws nothing and a hidden view does no
work until it is shown again; this class runs the frame and shares the averaged window
between the bubble and the readouts.
"""

from __future__ import annotations

import time

from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import QLabel

from app.core.measurement_log import Measurement, with_heading
from app.core.readout import averaged_angles
from app.gui.bubble_level import BubbleLevel
from app.gui.feeds.errors import ErrorTableFeed
from app.gui.feeds.frame import Frame
from app.gui.feeds.heading import HeadingFeed
from app.gui.feeds.level import LevelFeed
from app.gui.feeds.plots import PLOT_DATA_INTERVAL_S, SETTLE_REBUILD_S, PlotFeed
from app.gui.feeds.readouts import DisplaySettings, ReadoutFeed
from app.gui.feeds.screen import on_screen
from app.gui.filter_panel import FilterPanel
from app.gui.frame_clock import FrameClock
from app.gui.plots import LivePlots
from app.gui.readouts import TiltReadouts
from app.services.session import DeviceSession

__all__ = ["PLOT_DATA_INTERVAL_S", "DisplaySettings", "LivePresenter", "on_screen"]


class LivePresenter(QObject):
    """Runs the frames that refresh the bubble level, the readouts, the plots and the error
    table (each through its feed) when their data change."""

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
        self.session = session
        self.level, self.readouts, self.plots = level, readouts, plots
        self.truth_label, self.filter_panel = truth_label, filter_panel
        self.settings = DisplaySettings()
        self.plots_enabled = True
        self.level_feed = LevelFeed(level, self.attitudeChanged.emit)
        self.readout_feed = ReadoutFeed(readouts, truth_label, session, self.settings)
        self.plot_feed = PlotFeed(plots, session)
        self.error_feed = ErrorTableFeed(filter_panel, session, plots)
        self.clock = FrameClock(level, parent=self)
        self.clock.tick.connect(self._on_tick)
        self.frames = 0
        """Frames that drew something (ticks without changes are not counted)."""
        self._fps_window = (time.monotonic(), 0)
        self._fps_shown = -1
        self._no_data_shown = False
        self._quiet: tuple[tuple | None, float, bool] = (None, 0.0, False)
        """The last full frame's key, until when nothing falls due, and whether it had
        something pending."""
        self._averaged_cache: tuple[tuple, object] | None = None
        self.heading_feed: HeadingFeed | None = None
        """The compass's feed, once the window attached one (:meth:`attach_heading`)."""
        if isinstance(session, DeviceSession):  # (tests drive a bare pipeline)
            session.disconnected.connect(self.show_stale)
            session.reconnecting.connect(self.show_stale)

    # -- the feeds' knobs and counters, as before the split -----------------------------------
    level_interval_s = property(
        lambda self: self.level_feed.interval_s,
        lambda self, value: setattr(self.level_feed, "interval_s", value))
    plot_data_interval_s = property(
        lambda self: self.plot_feed.data_interval_s,
        lambda self, value: setattr(self.plot_feed, "data_interval_s", value))
    incremental_max_per_px = property(
        lambda self: self.plot_feed.incremental_max_per_px,
        lambda self, value: setattr(self.plot_feed, "incremental_max_per_px", value))
    plot_updates = property(lambda self: self.plot_feed.updates,
                            doc="How often the plots were handed new data.")
    plot_scrolls = property(lambda self: self.plot_feed.scrolls,
                            doc="How often the plots were only moved on between two blocks.")
    plot_appends = property(lambda self: self.plot_feed.appends,
                            doc="How often new samples were drawn onto the plots.")
    _level_key = property(lambda self: self.level_feed.key)

    def attach_heading(self, feed: HeadingFeed) -> None:
        """Feed the compass too (its heading shares the readouts' averaging window)."""
        self.heading_feed = feed

    def start(self) -> None:
        self.clock.start()

    def stop(self) -> None:
        self.clock.stop()

    def show_stale(self, *_reason: object) -> None:
        """The device was lost (a connection error, an unplug, a disconnect): the figures on
        show turn grey, with the time they were last live, until new data arrive."""
        self.readout_feed.show_stale()

    def set_hold(self, hold: bool) -> None:
        self.settings.hold = hold
        self.readouts.setHold(hold)
        self.clock.wake()

    def current_reading(self, label: str = "") -> Measurement | None:
        """The reading the readouts show (see :meth:`ReadoutFeed.current_reading`), with the
        compass's heading over the same samples."""
        reading = self.readout_feed.current_reading(label)
        if reading is None or self.heading_feed is None:
            return reading
        quat = self.readout_feed.reading_quat()
        return with_heading(reading, quat,
                            self.heading_feed.reading_for(quat, self.settings.hold))

    def range_statistics(self, start_rel_s: float, end_rel_s: float):
        """Statistics of roll, pitch and tilt over a range relative to the newest sample."""
        return self.plot_feed.range_statistics(start_rel_s, end_rel_s)

    def update_error_table(self) -> None:
        """Refresh the filter panel's error table."""
        self.error_feed.update()

    # -- the frame --------------------------------------------------------------------------
    def _on_tick(self) -> None:
        self.clock.report(self.refresh())

    def refresh(self) -> bool:
        """Draw what changed since the last frame; True if something was drawn (or a readout
        update is due shortly), i.e. the clock should keep the screen rate."""
        orientation = self.session.pipeline.orientation
        total = orientation.total_written
        if total == 0:
            busy = self._show_no_data()
            self._count_frame(busy)
            return busy
        frame = Frame(time.monotonic())
        quiet_key = self._quiet_key(total)
        if quiet_key == self._quiet[0] and frame.now < self._quiet[1]:
            # Nothing new and nothing due (most frames between two blocks): only the plots
            # move on with the clock.
            drew = self.plot_feed.was_shown and self.plot_feed.scroll(frame.now)
            self._count_frame(drew)
            return drew or self._quiet[2]
        self._no_data_shown = False
        key = (total, self.settings.unit, self.settings.averaging_s)
        if not self.settings.hold:
            self.level_feed.frame(frame, key, lambda: self._averaged(orientation))
            self.readout_feed.frame(frame, key, lambda: self._averaged(orientation))
        if self.heading_feed is not None:
            self.heading_feed.frame(frame, key, lambda: self._averaged_quat(orientation),
                                    self.settings.hold)
        self.plot_feed.frame(frame, total, self.plots_enabled)
        self.error_feed.frame(frame, total)
        self._count_frame(frame.drew)
        # Until new data arrive (or a setting changes) the frames only scroll the plots, up
        # to the moment a deferred update falls due.
        if self.plots.behind:
            frame.due.append(self.plot_feed.drawn_wall + SETTLE_REBUILD_S)
        self._quiet = (quiet_key, max(min(frame.due), frame.now), frame.pending)
        return frame.drew or frame.pending

    def _quiet_key(self, total: int) -> tuple:
        """What, unchanged, means a frame has nothing to draw but the plots' scrolling."""
        settings = self.settings
        # Runs every frame: one Qt call (plots shown or not; a resize is taken care of by
        # the next block's frame, and the plots repaint themselves meanwhile).
        heading = None if self.heading_feed is None else self.heading_feed.settings
        return (total, settings.unit, settings.averaging_s, settings.hold,
                self.plots.window_s, self.plots.isVisible(),
                len(self.session.pipeline.comparison_buffers), self.plots_enabled, heading)

    def _show_no_data(self) -> bool:
        """Dashes and an empty vial, once per stretch without data; True when it drew."""
        if self._no_data_shown:
            return False
        self._no_data_shown = True
        self.level_feed.clear()
        self.readout_feed.clear()
        if self.heading_feed is not None:
            self.heading_feed.clear()
        self.error_feed.key = None
        self.plot_feed.clear()
        return True

    def _averaged(self, orientation) -> tuple[dict, object] | None:
        """The newest averaging window's rows and their mean angles (None: no attitude);
        the bubble's and the readouts' frames share it while no new rows came."""
        key = (orientation.total_written, self.settings.averaging_s, id(orientation))
        if self._averaged_cache is not None and self._averaged_cache[0] == key:
            return self._averaged_cache[1]
        recent = orientation.window(
            self.settings.averaging_s,
            names=["quat", "ref_roll", "ref_pitch", "incl_error"],
        )
        angles = averaged_angles(recent["quat"])
        result = None if angles is None else (recent, angles)
        self._averaged_cache = (key, result)
        return result

    def _averaged_quat(self, orientation):
        """The quaternions of the newest averaging window (None: no attitude)."""
        averaged = self._averaged(orientation)
        return None if averaged is None else averaged[0]["quat"]

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
