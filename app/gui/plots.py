"""Live strip charts: acceleration, angular rate and angles against time.

The widget only draws arrays it is handed (:meth:`LivePlots.set_data`); the presenter pulls
them from the ring buffers and decimates them to the pixel width first.

Redrawing is kept cheap: the time axis is fixed (times are relative to the newest sample),
the value axes follow the data with hysteresis (:class:`StickyRange`: a range changes only
when the data leave it or shrink well inside it, so the axes are not re-laid out every
frame), and between two blocks of data the traces are only moved sideways
(:meth:`LivePlots.scroll_to`) instead of being rebuilt.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QGraphicsItem, QVBoxLayout, QWidget

from app.gui import theme

SCROLL_THRESHOLD_PX = 0.5
"""The traces are moved sideways only once they would move at least this far on screen."""
RANGE_MARGIN = 0.1
"""Space above and below the data when a value range is set, as a fraction of its span."""
RANGE_SHRINK = 0.4
"""A value range shrinks once the data span less than this fraction of it."""

pg.setConfigOptions(antialias=False, background=theme.BASE_BG, foreground=theme.TEXT_DIM)


def _make_plot(title: str, unit: str) -> pg.PlotItem:
    plot = pg.PlotItem()
    plot.setLabel("left", title, units=unit)
    plot.getAxis("left").setWidth(62)
    plot.showGrid(x=False, y=False)
    # Traces arrive already cut to the window and min/max-decimated to the pixel width
    # (app.core.decimation), so they are bare PlotCurveItems (_line): pyqtgraph's own
    # downsampling and clipping would only repeat the work and rebuild every trace each time
    # it scrolls (the view box clips what lies outside it anyway).
    plot.setMouseEnabled(x=False, y=True)
    plot.hideButtons()
    for name in ("left", "bottom"):  # redrawn only when their range or size changes
        plot.getAxis(name).setCacheMode(QGraphicsItem.CacheMode.DeviceCoordinateCache)
    legend = plot.addLegend(offset=(-8, 4), labelTextSize="8pt", colCount=4)
    legend.setBrush(pg.mkBrush(theme.PANEL_BG + "c0"))
    legend.setCacheMode(QGraphicsItem.CacheMode.DeviceCoordinateCache)  # drawn once, then copied
    return plot


def _line(plot: pg.PlotItem, pen: pg.QtGui.QPen, name: str) -> pg.PlotCurveItem:
    """A named trace in ``plot`` (and its legend): a bare PlotCurveItem, whose ``setData``
    only stores the arrays and drops the cached path, without PlotDataItem's per-call
    dataset bookkeeping (it would only redo what the presenter already did)."""
    curve = pg.PlotCurveItem(pen=pen, name=name, skipFiniteCheck=True)
    plot.addItem(curve)
    return curve


class StickyRange:
    """The value range of one plot, following the data with hysteresis.

    It grows as soon as the data leave it and shrinks only when they use less than
    ``RANGE_SHRINK`` of it, so noise does not change the axis (and re-lay it out) every
    frame. A user who zooms or pans the plot takes the range over; choosing *Auto* in the
    plot's menu hands it back.
    """

    def __init__(self, plot: pg.PlotItem) -> None:
        self.plot = plot
        self.following = True
        self.range: tuple[float, float] | None = None
        view = plot.getViewBox()
        view.disableAutoRange(axis=pg.ViewBox.YAxis)
        view.sigRangeChangedManually.connect(self._taken_over)
        view.sigStateChanged.connect(self._state_changed)

    def _taken_over(self, *_args: object) -> None:
        self.following = False

    def _state_changed(self, *_args: object) -> None:
        view = self.plot.getViewBox()
        if view.autoRangeEnabled()[1]:  # the menu's "Auto": follow the data again
            view.disableAutoRange(axis=pg.ViewBox.YAxis)
            self.following = True
            self.range = None

    def follow(self, low: float, high: float) -> bool:
        """Fit ``low``..``high`` (finite) if needed; True when the range changed."""
        if not self.following or not (np.isfinite(low) and np.isfinite(high)):
            return False
        if self.range is not None:
            r0, r1 = self.range
            inside = r0 <= low and high <= r1
            if inside and (high - low) >= RANGE_SHRINK * (r1 - r0):
                return False
        span = max(high - low, 1e-9 + 1e-6 * max(abs(low), abs(high)))
        margin = RANGE_MARGIN * span
        self.range = (low - margin, high + margin)
        self.plot.setYRange(*self.range, padding=0.0)
        return True


def _finite_bounds(arrays: list[np.ndarray]) -> tuple[float, float]:
    """Smallest and largest finite value over ``arrays`` (NaN, NaN when there is none)."""
    lows, highs = [], []
    for values in arrays:
        if len(values):
            with np.errstate(all="ignore"):
                lows.append(np.nanmin(values))
                highs.append(np.nanmax(values))
    if not lows:
        return float("nan"), float("nan")
    with np.errstate(all="ignore"):
        return float(np.nanmin(lows)), float(np.nanmax(highs))


class LivePlots(QWidget):
    """Stacked, x-linked plots. Times are given relative to the newest sample (<= 0)."""

    rangeSelected = Signal(float, float)  # start, end in s relative to the newest sample

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._window_s = 10.0
        self.graphics = pg.GraphicsLayoutWidget()
        self.graphics.ci.setSpacing(2)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.graphics)

        self.accel_plot = _make_plot("accel", "g")
        self.gyro_plot = _make_plot("rate", "°/s")
        self.angle_plot = _make_plot("angle", "°")
        for row, plot in enumerate((self.accel_plot, self.gyro_plot, self.angle_plot)):
            self.graphics.addItem(plot, row=row, col=0)
            if plot is not self.accel_plot:
                plot.setXLink(self.accel_plot)
        self.angle_plot.setLabel("bottom", "time", units="s")
        for plot in (self.accel_plot, self.gyro_plot):
            plot.getAxis("bottom").setStyle(showValues=False)
            plot.getAxis("bottom").setHeight(4)

        def pen(color: str, style: Qt.PenStyle = Qt.PenStyle.SolidLine) -> pg.QtGui.QPen:
            return pg.mkPen(color, width=1, style=style)

        axes = ("x", "y", "z")
        self.accel_curves = [
            _line(self.accel_plot, pen(c), a) for c, a in zip(theme.AXIS_COLORS, axes)
        ]
        self.gyro_curves = [
            _line(self.gyro_plot, pen(c), a) for c, a in zip(theme.AXIS_COLORS, axes)
        ]
        self.angle_curves = {
            "roll": _line(self.angle_plot, pen(theme.TRACE_ROLL), "roll"),
            "pitch": _line(self.angle_plot, pen(theme.TRACE_PITCH), "pitch"),
            "ref_roll": _line(
                self.angle_plot, pen(theme.TRACE_ROLL, Qt.PenStyle.DashLine), "true roll"
            ),
            "ref_pitch": _line(
                self.angle_plot, pen(theme.TRACE_PITCH, Qt.PenStyle.DashLine), "true pitch"
            ),
        }
        self.comparison_curves: dict[str, tuple[pg.PlotCurveItem, pg.PlotCurveItem]] = {}

        # Inclination error against the reference, shown only when the source has one.
        self.error_plot = _make_plot("error", "°")
        self.error_plot.setXLink(self.accel_plot)
        self.error_curve = _line(self.error_plot, pen(theme.TRACE_TILT), "main filter")
        self.comparison_error_curves: dict[str, pg.PlotCurveItem] = {}
        self._error_shown = False

        # A time range the user selects on the angle plot (statistics per angle).
        self.region = pg.LinearRegionItem(values=(-3.0, -1.0))
        self.region.setZValue(-10)
        self.region.sigRegionChangeFinished.connect(self._emit_range)
        self._region_shown = False
        self.ranges = {
            plot: StickyRange(plot)
            for plot in (self.accel_plot, self.gyro_plot, self.angle_plot, self.error_plot)
        }
        self._scroll_s = 0.0
        self.set_window(self._window_s)

    def set_error_visible(self, visible: bool) -> None:
        """Add or remove the inclination-error plot (below the angles)."""
        if visible == self._error_shown:
            return
        self._error_shown = visible
        if visible:
            self.graphics.addItem(self.error_plot, row=3, col=0)
        else:
            self.graphics.removeItem(self.error_plot)

    @property
    def error_visible(self) -> bool:
        return self._error_shown

    def set_range_selection(self, enabled: bool) -> None:
        """Show a draggable time range on the angle plot; its statistics are reported."""
        if enabled == self._region_shown:
            return
        self._region_shown = enabled
        if enabled:
            self.region.setRegion((-0.3 * self._window_s, -0.1 * self._window_s))
            self.angle_plot.addItem(self.region)
            self._emit_range()
        else:
            self.angle_plot.removeItem(self.region)

    def selected_range(self) -> tuple[float, float] | None:
        """The selected range in seconds relative to the newest sample, or None."""
        if not self._region_shown:
            return None
        start, end = self.region.getRegion()
        return float(start), float(end)

    def _emit_range(self) -> None:
        selected = self.selected_range()
        if selected is not None:
            self.rangeSelected.emit(*selected)

    def set_comparisons(self, filters: list[tuple[str, str]]) -> None:
        """Show roll and pitch curves for these (name, title) filters; drop the others."""
        wanted = dict(filters)
        for name in list(self.comparison_curves):
            if name not in wanted:
                for curve in self.comparison_curves.pop(name):
                    self.angle_plot.removeItem(curve)
        for index, (name, title) in enumerate(filters):
            if name in self.comparison_curves:
                continue
            colour = theme.COMPARISON_COLORS[index % len(theme.COMPARISON_COLORS)]
            roll = _line(self.angle_plot, pg.mkPen(colour, width=1), f"{title} roll")
            pitch = _line(
                self.angle_plot, pg.mkPen(colour, width=1, style=Qt.PenStyle.DotLine),
                f"{title} pitch",
            )
            self.comparison_curves[name] = (roll, pitch)
            self.comparison_error_curves[name] = _line(
                self.error_plot, pg.mkPen(colour, width=1), title
            )
        for name in list(self.comparison_error_curves):
            if name not in wanted:
                self.error_plot.removeItem(self.comparison_error_curves.pop(name))

    def set_comparison_data(
        self, name: str, t_rel: np.ndarray, roll: np.ndarray, pitch: np.ndarray,
        error: np.ndarray | None = None,
    ) -> None:
        """Replace one compared filter's roll and pitch traces (and its error trace)."""
        curves = self.comparison_curves.get(name)
        if curves is None:
            return
        curves[0].setData(t_rel, roll, skipFiniteCheck=True)
        curves[1].setData(t_rel, pitch, skipFiniteCheck=True)
        if error is not None and self._error_shown and name in self.comparison_error_curves:
            self.comparison_error_curves[name].setData(t_rel, error, skipFiniteCheck=True)

    def set_error_data(self, t_rel: np.ndarray, error: np.ndarray) -> None:
        """The main filter's inclination error (degrees) over time (call it after the
        compared filters' data: the plot's range covers them all)."""
        if self._error_shown:
            self.error_curve.setData(t_rel, error, skipFiniteCheck=True)
            errors = [error] + [
                curve.yData for curve in self.comparison_error_curves.values()
                if curve.yData is not None
            ]
            self.ranges[self.error_plot].follow(*_finite_bounds(errors))

    def export(self, path: str) -> None:
        """Write all plots to ``path``: ``.png`` (pyqtgraph's exporter) or ``.svg``.

        SVG goes through Qt's own QSvgGenerator: pyqtgraph's SVG exporter fails on the
        path data of current Qt releases.
        """
        suffix = path.lower().rsplit(".", 1)[-1]
        if suffix == "png":
            from pyqtgraph import exporters

            exporters.ImageExporter(self.graphics.scene()).export(path)
        elif suffix == "svg":
            from PySide6.QtCore import QRect
            from PySide6.QtGui import QPainter
            from PySide6.QtSvg import QSvgGenerator

            size = self.graphics.size()
            generator = QSvgGenerator()
            generator.setFileName(path)
            generator.setSize(size)
            generator.setViewBox(QRect(0, 0, size.width(), size.height()))
            generator.setTitle("Inclinometer plots")
            painter = QPainter(generator)
            self.graphics.render(painter)
            painter.end()
        else:
            raise ValueError(f"{path}: use a .png or .svg file name")

    def set_window(self, seconds: float) -> None:
        """Show the last ``seconds`` of data."""
        self._window_s = float(seconds)
        self.accel_plot.setXRange(-self._window_s, 0.0, padding=0.0)

    @property
    def window_s(self) -> float:
        return self._window_s

    def clear(self) -> None:
        compared = [curve for pair in self.comparison_curves.values() for curve in pair]
        for curve in (
            *self.accel_curves, *self.gyro_curves, *self.angle_curves.values(), *compared
        ):
            curve.setData([], [])

    def set_data(
        self,
        t_rel: np.ndarray,
        accel_g: np.ndarray,
        gyro_dps: np.ndarray,
        angles_t_rel: np.ndarray,
        angles: dict[str, np.ndarray],
        sensor_connect: np.ndarray | str = "all",
        angle_connect: np.ndarray | str = "all",
    ) -> None:
        """Replace every curve: times (N,) relative to now and vectors (N, 3) for the sensor
        plots; times (M,) and traces (M,) for the angle plot.

        Angle traces missing from ``angles`` (or NaN at the newest sample: no reference) are
        hidden. ``*_connect`` are pyqtgraph ``connect`` arrays: False breaks the line after
        that point (lost data shows as a hole).
        """
        for axis, curve in enumerate(self.accel_curves):
            curve.setData(t_rel, accel_g[:, axis], connect=sensor_connect, skipFiniteCheck=True)
        for axis, curve in enumerate(self.gyro_curves):
            curve.setData(t_rel, gyro_dps[:, axis], connect=sensor_connect, skipFiniteCheck=True)
        shown_angles = []
        for name, curve in self.angle_curves.items():
            values = angles.get(name)
            visible = values is not None and len(values) > 0 and bool(np.isfinite(values[-1]))
            curve.setVisible(visible)
            if visible:
                curve.setData(
                    angles_t_rel, values, connect=angle_connect, skipFiniteCheck=True
                )
                shown_angles.append(values)
            elif curve.xData is not None and len(curve.xData):
                curve.setData([], [])
        self._scroll_s = 0.0
        self._place_curves()
        self.ranges[self.accel_plot].follow(*_finite_bounds([accel_g]))
        self.ranges[self.gyro_plot].follow(*_finite_bounds([gyro_dps]))
        compared = [
            curve.yData for pair in self.comparison_curves.values() for curve in pair
            if curve.yData is not None
        ]
        self.ranges[self.angle_plot].follow(*_finite_bounds(shown_angles + compared))

    def scroll_to(self, seconds: float) -> bool:
        """Move every trace ``seconds`` to the left (the time since the newest sample arrived)
        without rebuilding it; only when that moves it a visible amount. True if it moved."""
        pixels_per_s = self.accel_plot.getViewBox().width() / max(self._window_s, 1e-9)
        if abs(seconds - self._scroll_s) * pixels_per_s < SCROLL_THRESHOLD_PX:
            return False
        self._scroll_s = float(seconds)
        self._place_curves()
        return True

    @property
    def scroll_s(self) -> float:
        """How far (seconds) the traces are moved left of where their data put them."""
        return self._scroll_s

    def _place_curves(self) -> None:
        # A moved line keeps its path: nothing is rebuilt, the view only repaints.
        for line in self._all_curves():
            if line.pos().x() != -self._scroll_s:
                line.setPos(-self._scroll_s, 0.0)

    def _all_curves(self) -> list[pg.PlotCurveItem]:
        return [
            *self.accel_curves, *self.gyro_curves, *self.angle_curves.values(),
            *(curve for pair in self.comparison_curves.values() for curve in pair),
            self.error_curve, *self.comparison_error_curves.values(),
        ]
