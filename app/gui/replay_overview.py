"""The whole replayed session at a glance: each accelerometer axis's min-max band over time.

Built from the replay's :class:`~app.core.recording.index.Overview` (a long recording's grows
while it is indexed in the background). A line marks the position, ticks mark gaps, dashed
lines the recorded alarms and amber ones the bookmarks; a click asks to go there.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QWidget

from app.core.recording.index import Overview
from app.gui import theme
from app.gui.lazy_menu import LazyMenuViewBox

HEIGHT_PX = 36


class ReplayOverview(pg.PlotWidget):
    """Min-max bands of ax, ay, az over the session; ``seekRequested(s)`` on a click."""

    seekRequested = Signal(float)

    def __init__(self, parent: QWidget | None = None) -> None:
        # No menu (a click seeks): pyqtgraph would build one only to drop it.
        super().__init__(parent, plotItem=pg.PlotItem(viewBox=LazyMenuViewBox(enableMenu=False)))
        self.setFixedHeight(HEIGHT_PX)
        self.setMinimumWidth(200)
        self.setToolTip("The whole recording: accelerometer x, y, z (min to max). "
                        "Click to go there.")
        self.setMenuEnabled(False)
        self.setMouseEnabled(x=False, y=False)
        self.hideButtons()
        plot = self.getPlotItem()
        plot.hideAxis("left")
        plot.hideAxis("bottom")
        plot.setContentsMargins(0, 0, 0, 0)
        self._bands: list[pg.FillBetweenItem] = []
        self._curves: list[tuple[pg.PlotDataItem, pg.PlotDataItem]] = []
        for colour in theme.AXIS_COLORS:
            low, high = pg.PlotDataItem(pen=pg.mkPen(colour)), pg.PlotDataItem(pen=pg.mkPen(colour))
            band = pg.FillBetweenItem(low, high, brush=pg.mkBrush(pg.mkColor(colour).lighter(60)))
            for item in (low, high, band):
                self.addItem(item)
            self._curves.append((low, high))
            self._bands.append(band)
        self.position = pg.InfiniteLine(angle=90, movable=False,
                                        pen=pg.mkPen(theme.TEXT, width=2))
        self.position.setZValue(10)
        self.addItem(self.position)
        self._gaps: list[pg.InfiniteLine] = []
        self._alarm_marks: list[pg.InfiniteLine] = []
        self._bookmarks: list[pg.InfiniteLine] = []
        self._duration_s = 0.0
        self.scene().sigMouseClicked.connect(self._on_click)
        self._on_theme_changed()
        theme.notifier().changed.connect(self._on_theme_changed)

    def _on_theme_changed(self, _name: str = "") -> None:
        """Background, bands and position line in the current theme's colours."""
        self.setBackground(theme.BASE_BG)
        for colour, (low, high), band in zip(theme.AXIS_COLORS, self._curves, self._bands):
            low.setPen(pg.mkPen(colour))
            high.setPen(pg.mkPen(colour))
            band.setBrush(pg.mkBrush(pg.mkColor(colour).lighter(60)))
        self.position.setPen(pg.mkPen(theme.TEXT, width=2))
        for line in self._bookmarks:
            line.setPen(self._bookmark_pen())

    def show_overview(self, overview: Overview, duration_s: float,
                      gaps_s: tuple[float, ...] = ()) -> None:
        """Draw the bands over ``duration_s`` (times from the first bin: the first sample)."""
        if not len(overview.t_s):
            return
        x = overview.since_start(float(overview.t_s[0]))
        for axis, (low, high) in enumerate(self._curves):
            low.setData(x, overview.low[:, axis])
            high.setData(x, overview.high[:, axis])
        for line in self._gaps:
            self.removeItem(line)
        self._gaps = []
        for gap in gaps_s[:200]:  # a few hundred marks read as a solid bar anyway
            line = pg.InfiniteLine(gap, angle=90, pen=pg.mkPen(theme.ALARM_RED))
            self.addItem(line)
            self._gaps.append(line)
        self.set_duration(duration_s)
        finite = overview.low[np.isfinite(overview.low)], overview.high[np.isfinite(
            overview.high)]
        if len(finite[0]) and len(finite[1]):
            self.setYRange(float(finite[0].min()), float(finite[1].max()), padding=0.05)

    def show_alarm_marks(self, positions_s: tuple[float, ...]) -> None:
        """Mark where the recording's alarms were raised (s from the start), dashed."""
        for line in self._alarm_marks:
            self.removeItem(line)
        self._alarm_marks = []
        pen = pg.mkPen(theme.ALARM_STATE, width=2, style=Qt.PenStyle.DashLine)
        for position in positions_s[:200]:
            line = pg.InfiniteLine(position, angle=90, pen=pen)
            self.addItem(line)
            self._alarm_marks.append(line)

    def alarm_marks(self) -> list[float]:
        """The positions marked as alarms (s from the start)."""
        return [float(line.value()) for line in self._alarm_marks]

    @staticmethod
    def _bookmark_pen() -> pg.QtGui.QPen:
        return pg.mkPen(theme.WARN_AMBER, width=2)

    def show_bookmarks(self, positions_s: tuple[float, ...]) -> None:
        """Mark the replay's bookmarks (s from the start)."""
        for line in self._bookmarks:
            self.removeItem(line)
        self._bookmarks = []
        for position in positions_s[:200]:
            line = pg.InfiniteLine(position, angle=90, pen=self._bookmark_pen())
            line.setZValue(5)  # over the bands, under the position line
            self.addItem(line)
            self._bookmarks.append(line)

    def bookmarks(self) -> list[float]:
        """The positions marked as bookmarks (s from the start)."""
        return [float(line.value()) for line in self._bookmarks]

    def set_duration(self, duration_s: float) -> None:
        if duration_s > 0 and duration_s != self._duration_s:
            self._duration_s = duration_s
            self.setXRange(0.0, duration_s, padding=0.0)

    def show_position(self, position_s: float) -> None:
        self.position.setValue(position_s)

    def _on_click(self, event) -> None:
        if event.button() != Qt.MouseButton.LeftButton or self._duration_s <= 0:
            return
        point = self.getPlotItem().vb.mapSceneToView(event.scenePos())
        self.seekRequested.emit(min(max(float(point.x()), 0.0), self._duration_s))
