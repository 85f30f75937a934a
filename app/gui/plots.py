"""Live strip charts: acceleration, angular rate and angles against time.

The widget only draws arrays it is handed (:meth:`LivePlots.set_data`); the presenter pulls
them from the ring buffers and decimates them to the pixel width first. Each plot's legend is
a one-line header above its data (never on the traces); colours follow the theme.

Redrawing is kept cheap: the time axis is fixed (times are relative to the newest sample),
the value axes follow the data with hysteresis (:class:`StickyRange`: a range changes only
when the data leave it or shrink well inside it, so the axes are not re-laid out every
frame), and between two rebuilds the traces are only moved sideways
(:meth:`LivePlots.scroll_to`: the pixels on screen are shifted, the strip that comes into
view is filled with the background) and new samples are drawn onto the screen as short lines
(:meth:`LivePlots.append`), without pyqtgraph's scene. The scene's own items stay where the
last rebuild put them; before the scene has to paint anything else (the window was covered,
a menu closed), ``resync`` rebuilds them from the buffers first.
"""

from __future__ import annotations

from collections.abc import Callable
from html import escape

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF, QRect, Qt, Signal
from PySide6.QtGui import QFontMetricsF, QPainter, QPaintEvent, QPalette, QPen, QPolygonF, QRegion
from PySide6.QtWidgets import QGraphicsItem, QVBoxLayout, QWidget

from app.core.screen_fit import label_step
from app.gui import theme
from app.gui.lazy_menu import lazy_menu_plot

TAIL_S = 1.0
"""How much of each trace's newest end :meth:`LivePlots.append` keeps to repaint from."""
SCROLL_THRESHOLD_PX = 0.5
"""The traces are moved sideways only once they would move at least this far on screen."""
TICK_PX = 4
"""Tick marks point this far out of the data area (pyqtgraph's default points inwards)."""
RANGE_MARGIN = 0.1
"""Space above and below the data when a value range is set, as a fraction of its span."""
RANGE_SHRINK = 0.4
"""A value range shrinks once the data span less than this fraction of it."""

pg.setConfigOptions(antialias=False, background=theme.BASE_BG, foreground=theme.TEXT_DIM)

HEADER_PX = 16
"""Height of the legend line above each plot."""
_SAMPLES = {
    Qt.PenStyle.SolidLine: "━━",
    Qt.PenStyle.DashLine: "╺╸╺╸",
    Qt.PenStyle.DotLine: "┅┅",
}
"""How a pen style looks in a legend line."""


class _UncrowdedAxis(pg.AxisItem):
    """A value axis whose labels never overlap: pyqtgraph puts at least two major steps on
    any axis, so a plot 35 px high (1366x768) wrote 0, 50, 100 and 150 on top of each other.
    The major step grows until labels are 1.1 lines apart."""

    def tickSpacing(self, minVal: float, maxVal: float, size: float):
        levels = super().tickSpacing(minVal, maxVal, size)
        if not levels:
            return levels
        line = QFontMetricsF(self.style["tickFont"] or self.font()).height()
        major = label_step(abs(maxVal - minVal), levels[0][0], size, 1.1 * line)
        # Coarser: only the major ticks (pyqtgraph would label a finer level where it
        # thinks there is room, between labels a line and a half apart).
        return levels if major == levels[0][0] else [(major, 0.0)]


def _make_plot() -> pg.PlotItem:
    plot = lazy_menu_plot(axisItems={"left": _UncrowdedAxis("left")})
    # The plot's name and unit lead its header line: a rotated axis label does not fit a
    # short plot. Values stay in the named unit (no "m°" prefixes).
    plot.getAxis("left").setWidth(48)
    plot.getAxis("left").enableAutoSIPrefix(False)
    plot.showGrid(x=False, y=False)
    # Traces arrive already cut to the window and min/max-decimated to the pixel width
    # (app.core.decimation), so they are bare PlotCurveItems (_line): pyqtgraph's own
    # downsampling and clipping would only repeat the work and rebuild every trace each time
    # it scrolls (the view box clips what lies outside it anyway).
    plot.setMouseEnabled(x=False, y=True)
    plot.hideButtons()
    for name in ("left", "bottom"):  # redrawn only when their range or size changes
        plot.getAxis(name).setCacheMode(QGraphicsItem.CacheMode.DeviceCoordinateCache)
        # Ticks outside the data area: inside it everything moves with the traces, so a
        # scroll can be a copy of its pixels (LivePlots.scroll_to).
        plot.getAxis(name).setStyle(tickLength=TICK_PX)
    return plot


def legend_html(title: str, entries: list[tuple[str, str, Qt.PenStyle]]) -> str:
    """A plot's header line: its title, then a short sample of each (label, colour, pen
    style) and the label."""
    dim = theme.TEXT_DIM
    items = [f'<span style="color:{theme.TEXT}"><b>{escape(title)}</b></span>'] + [
        f'<span style="color:{colour}">{_SAMPLES.get(style, "━━")}</span>'
        f'&nbsp;<span style="color:{dim}">{escape(label)}</span>'
        for label, colour, style in entries
    ]
    return "&nbsp;&nbsp;&nbsp;&nbsp;".join(items)


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


class _PlotView(pg.GraphicsLayoutWidget):
    """The plots' graphics view: what only a scroll or new samples changed is painted by
    :meth:`LivePlots._paint_fast`; anything else by the scene, brought up to date first."""

    def __init__(self, owner: LivePlots) -> None:
        super().__init__()
        self._owner = owner
        # Qt fills every area to be painted with the background first (the viewport's
        # palette follows the theme, LivePlots.apply_theme), in C++: a strip a scroll
        # uncovers then needs nothing more from Python.
        self.viewport().setAutoFillBackground(True)
        self.viewport().setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent, False)
        # The palette's Base is the theme's plot background (theme.palette).
        self.viewport().setBackgroundRole(QPalette.ColorRole.Base)

    def paintEvent(self, event: QPaintEvent) -> None:
        if self._owner._paint_fast(event):
            return
        self._owner._before_scene_paint()
        super().paintEvent(event)


def _runs(x: np.ndarray, y: np.ndarray, breaks: np.ndarray) -> list[np.ndarray]:
    """Index runs of a line to draw: a new run starts where ``breaks`` is True; points that
    are not finite are left out and end a run."""
    finite = np.isfinite(x) & np.isfinite(y)
    if finite.all() and not breaks[1:].any():
        return [np.arange(len(x))] if len(x) > 1 else []
    cut = np.array(breaks, dtype=bool, copy=True)
    cut |= ~finite
    cut[1:] |= ~finite[:-1]
    runs = np.split(np.arange(len(x)), np.flatnonzero(cut))
    return [run[finite[run]] for run in runs if np.count_nonzero(finite[run]) > 1]


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
        self.resync: Callable[[], None] | None = None
        """Rebuilds every trace from the buffers (set by the presenter): called before the
        scene paints while it is behind what the screen shows."""
        self._stale = False  # the scene's traces are behind the screen (moved or extended)
        self._fast = QRegion()  # what _paint_fast may paint: scrolled-in strips, new lines
        # Each appended trace's newest points (x, y, breaks): a fast paint repaints its
        # region as a whole (a backing store need not keep what was there), from these.
        self._tails: dict[pg.PlotCurveItem, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._tail_ends: dict[pg.PlotItem, float] = {}  # newest x of each plot's tails
        self._areas: dict[pg.PlotItem, QRect] = {}
        self._pixels_per_s: float | None = None
        self._maps: dict[pg.PlotItem, tuple[float, float, float, float]] = {}
        self._plot_of: dict[pg.PlotCurveItem, pg.PlotItem] = {}
        self.graphics = _PlotView(self)
        self.graphics.ci.setSpacing(2)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.graphics)

        self.accel_plot = _make_plot()
        self.gyro_plot = _make_plot()
        self.angle_plot = _make_plot()
        for row, plot in enumerate((self.accel_plot, self.gyro_plot, self.angle_plot)):
            self.graphics.addItem(plot, row=row, col=0)
            if plot is not self.accel_plot:
                plot.setXLink(self.accel_plot)
        self.angle_plot.setLabel("bottom", "time", units="s")
        for plot in (self.accel_plot, self.gyro_plot):
            plot.getAxis("bottom").setStyle(showValues=False)
            plot.getAxis("bottom").setHeight(4)

        # Each curve's colour (read from the current theme) and pen style, and the legend
        # entries of each plot, so that a theme switch can redraw them.
        self._pens: dict[pg.PlotCurveItem, tuple[Callable[[], str], Qt.PenStyle]] = {}
        self._legends: dict[pg.PlotItem, list[tuple[str, pg.PlotCurveItem]]] = {}
        self._titles: dict[pg.PlotItem, str] = {
            self.accel_plot: "acceleration (g)", self.gyro_plot: "angular rate (°/s)",
            self.angle_plot: "roll, pitch (°)",
        }
        solid, dash = Qt.PenStyle.SolidLine, Qt.PenStyle.DashLine

        def axis_colour(index: int) -> Callable[[], str]:
            return lambda: theme.AXIS_COLORS[index]

        axes = ("x", "y", "z")
        self.accel_curves = [
            self._curve(self.accel_plot, name, axis_colour(i)) for i, name in enumerate(axes)
        ]
        self.gyro_curves = [
            self._curve(self.gyro_plot, name, axis_colour(i)) for i, name in enumerate(axes)
        ]
        self.angle_curves = {
            "roll": self._curve(self.angle_plot, "roll", lambda: theme.TRACE_ROLL),
            "pitch": self._curve(self.angle_plot, "pitch", lambda: theme.TRACE_PITCH),
            "ref_roll": self._curve(
                self.angle_plot, "true roll", lambda: theme.TRACE_ROLL, dash
            ),
            "ref_pitch": self._curve(
                self.angle_plot, "true pitch", lambda: theme.TRACE_PITCH, dash
            ),
        }
        self.comparison_curves: dict[str, tuple[pg.PlotCurveItem, pg.PlotCurveItem]] = {}

        # Inclination error against the reference, shown only when the source has one.
        self.error_plot = _make_plot()
        self._titles[self.error_plot] = "inclination error (°)"
        self.error_plot.setXLink(self.accel_plot)
        self.error_curve = self._curve(
            self.error_plot, "main filter", lambda: theme.TRACE_TILT, solid
        )
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
        for plot in (self.accel_plot, self.gyro_plot, self.angle_plot, self.error_plot):
            plot.getViewBox().sigResized.connect(self._layout_changed)
            plot.getViewBox().sigRangeChanged.connect(self._layout_changed)
        self.set_window(self._window_s)
        self.apply_theme()
        theme.notifier().changed.connect(self.apply_theme)

    # -- colours and legends ------------------------------------------------------------------
    def _curve(
        self, plot: pg.PlotItem, label: str, colour: Callable[[], str],
        style: Qt.PenStyle = Qt.PenStyle.SolidLine,
    ) -> pg.PlotCurveItem:
        """A new curve on ``plot`` with a legend entry."""
        # A bare PlotCurveItem: its setData only stores the arrays and drops the cached path,
        # without PlotDataItem's per-call dataset work (the presenter already cut and
        # decimated the data).
        curve = pg.PlotCurveItem(pen=pg.mkPen(colour(), width=1, style=style),
                                 skipFiniteCheck=True)
        # Moving a trace sideways (scroll_to) changes nothing but its position: without this
        # flag pyqtgraph would drop the trace's bounds on every move and compute them again
        # (a pass over its data and the view's pixel size) for each frame.
        curve.setFlag(QGraphicsItem.GraphicsItemFlag.ItemSendsGeometryChanges, False)
        plot.addItem(curve)
        self._plot_of[curve] = plot
        self._pens[curve] = (colour, style)
        self._legends.setdefault(plot, []).append((label, curve))
        return curve

    def _drop_curve(self, plot: pg.PlotItem, curve: pg.PlotCurveItem) -> None:
        plot.removeItem(curve)
        self._plot_of.pop(curve, None)
        self._tails.pop(curve, None)
        self._pens.pop(curve, None)
        self._legends[plot] = [entry for entry in self._legends[plot] if entry[1] is not curve]

    def name_reference(self, measured: bool) -> None:
        """Call the dashed angle traces "reference roll/pitch" for a measured reference (a
        recording's motion capture), "true roll/pitch" for the simulator's truth."""
        word = "reference" if measured else "true"
        curves = {self.angle_curves["ref_roll"]: f"{word} roll",
                  self.angle_curves["ref_pitch"]: f"{word} pitch"}
        entries = self._legends[self.angle_plot]
        renamed = [(curves.get(curve, label), curve) for label, curve in entries]
        if renamed != entries:
            self._legends[self.angle_plot] = renamed
            self._show_legend(self.angle_plot)

    def legend_entries(self, plot: pg.PlotItem) -> list[str]:
        """The labels in ``plot``'s legend line, in order."""
        return [label for label, _ in self._legends.get(plot, [])]

    def _show_legend(self, plot: pg.PlotItem) -> None:
        entries = [
            (label, self._pens[curve][0](), self._pens[curve][1])
            for label, curve in self._legends.get(plot, [])
        ]
        plot.setTitle(legend_html(self._titles[plot], entries), size="8pt", justify="left")
        # A compact header: pyqtgraph gives titles 30 px.
        plot.layout.setRowFixedHeight(0, HEADER_PX)
        plot.titleLabel.setMaximumHeight(HEADER_PX)

    def apply_theme(self, _name: str = "") -> None:
        """Background, axes, curves and legends in the current theme's colours."""
        pg.setConfigOptions(background=theme.BASE_BG, foreground=theme.TEXT_DIM)
        self.graphics.setBackground(theme.BASE_BG)

        width = theme.current().LINE_WIDTH
        for curve, (colour, style) in self._pens.items():
            curve.setPen(pg.mkPen(colour(), width=width, style=style))
        for plot in (self.accel_plot, self.gyro_plot, self.angle_plot, self.error_plot):
            for side in ("left", "bottom"):
                axis = plot.getAxis(side)
                axis.setPen(pg.mkPen(theme.BORDER))
                axis.setTextPen(pg.mkPen(theme.TEXT_DIM))  # also the axis label
            self._show_legend(plot)
        self.region.setBrush(pg.mkBrush(theme.ACCENT + "30"))
        for line in self.region.lines:
            line.setPen(pg.mkPen(theme.ACCENT, width=1))

    def set_error_visible(self, visible: bool) -> None:
        """Add or remove the inclination-error plot (below the angles)."""
        if visible == self._error_shown:
            return
        self._error_shown = visible
        # One time axis, under the lowest plot.
        angle_axis = self.angle_plot.getAxis("bottom")
        angle_axis.setStyle(showValues=not visible)
        if visible:
            self.angle_plot.setLabel("bottom", None)
            angle_axis.setHeight(4)
            self.graphics.addItem(self.error_plot, row=3, col=0)
            self.error_plot.setLabel("bottom", "time", units="s")
        else:
            self.graphics.removeItem(self.error_plot)
            angle_axis.setHeight(None)
            self.angle_plot.setLabel("bottom", "time", units="s")

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
                    self._drop_curve(self.angle_plot, curve)
        for index, (name, title) in enumerate(filters):
            if name in self.comparison_curves:
                continue
            def colour(i: int = index) -> str:
                return theme.COMPARISON_COLORS[i % len(theme.COMPARISON_COLORS)]

            roll = self._curve(self.angle_plot, f"{title} roll", colour)
            pitch = self._curve(
                self.angle_plot, f"{title} pitch", colour, Qt.PenStyle.DotLine
            )
            self.comparison_curves[name] = (roll, pitch)
            self.comparison_error_curves[name] = self._curve(self.error_plot, title, colour)
        for name in list(self.comparison_error_curves):
            if name not in wanted:
                self._drop_curve(self.error_plot, self.comparison_error_curves.pop(name))
        self.apply_theme()

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
        if suffix in ("png", "svg"):
            # Every trace from the buffers, whatever the screen shows: a hidden view (a dock
            # behind another tab) is not kept up to date, and a stretch without data (a seek)
            # emptied its traces.
            self._fast = QRegion()
            if self.resync is not None:
                self.resync()
            self._before_scene_paint()  # without a presenter: at least where they scrolled to
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
        self._pixels_per_s = None
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
        self._in_sync()

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
        self._in_sync()
        self.ranges[self.accel_plot].follow(*_finite_bounds([accel_g]))
        self.ranges[self.gyro_plot].follow(*_finite_bounds([gyro_dps]))
        compared = [
            curve.yData for pair in self.comparison_curves.values() for curve in pair
            if curve.yData is not None
        ]
        self.ranges[self.angle_plot].follow(*_finite_bounds(shown_angles + compared))

    def scroll_to(self, seconds: float) -> bool:
        """Move every trace ``seconds`` to the left of where the last rebuild put it (the time
        since its newest sample) without rebuilding it; only when that moves it a visible
        amount. True if it moved."""
        pixels_per_s = self._pixels_per_s
        if pixels_per_s is None:
            pixels_per_s = self._pixels_per_s = (
                self.accel_plot.getViewBox().width() / max(self._window_s, 1e-9))
        if abs(seconds - self._scroll_s) * pixels_per_s < SCROLL_THRESHOLD_PX:
            return False
        if self._region_shown:  # the selected range stays put: repaint the data areas
            self._scroll_s = float(seconds)
            self._place_curves()
            return True
        return self._blit_to(seconds, pixels_per_s)

    def place_at(self, seconds: float) -> None:
        """Right after a rebuild: show the traces ``seconds`` left of where it put them (in
        the scene: nothing on the screen is shifted)."""
        self._scroll_s = float(seconds)
        self._place_curves()

    @property
    def behind(self) -> bool:
        """Whether the scene's traces are behind what the screen shows (samples appended,
        or scrolled, since the last rebuild)."""
        return self._stale

    @property
    def appends(self) -> bool:
        """Whether new samples may be drawn with :meth:`append` (not while a range is
        selected: the data areas are then repainted as a whole)."""
        return not self._region_shown

    def _blit_to(self, seconds: float, pixels_per_s: float) -> bool:
        """Scroll by whole pixels as a copy of what is on screen: each data area's pixels are
        shifted (QWidget.scroll) and the strip that comes into view is filled with the
        background (new data are not there yet). The traces in the scene are not moved: a
        scene paint brings them up to date first (:meth:`_before_scene_paint`). The
        outermost pixel of each area, where the axis lines may reach, is left alone."""
        old_px = round(self._scroll_s * pixels_per_s)
        new_px = round(seconds * pixels_per_s)
        if new_px == old_px:
            return False
        self._scroll_s = new_px / pixels_per_s
        self._stale = True
        shift = old_px - new_px
        # What is still to be painted moves with the pixels (Qt moves its dirty areas too).
        self._fast = self._fast.translated(shift, 0)
        scroll = self.graphics.viewport().scroll
        strips = QRegion()
        for plot in self._shown_plots():
            area = self._area(plot)
            scroll(shift, 0, area)
            if shift < 0:  # the newest end comes into view on the right
                strip = QRect(area.right() + shift + 1, area.top(), -shift, area.height())
            else:
                strip = QRect(area.left(), area.top(), shift, area.height())
            strips += strip & area
        self._fast += strips
        return True

    def append(
        self, segments: list[tuple[pg.PlotCurveItem, np.ndarray, np.ndarray, np.ndarray]],
    ) -> bool:
        """Draw new samples onto the screen as lines from each trace's previous end, without
        rebuilding anything: (curve, x, y, breaks) with x in the last rebuild's time (seconds
        relative to its newest sample), the previous end first, and ``breaks`` True where the
        line must not join a point to the one before it (lost data, NaN). False, and nothing
        drawn, when a value leaves its plot's range (the caller rebuilds: the range grows).
        """
        if self._region_shown:
            return False
        drawn = []  # (curve, plot, x, y, breaks, low, high) of the traces on screen
        for curve, x, y, breaks in segments:
            plot = self._plot_of.get(curve)
            if plot is None or not curve.isVisible() or len(x) < 2:
                continue
            finite = y[np.isfinite(y)]
            low, high = (float(finite.min()), float(finite.max())) if len(finite) else (
                np.nan, np.nan)
            sticky = self.ranges.get(plot)
            if sticky is not None and sticky.following and sticky.range is not None and (
                    low < sticky.range[0] or high > sticky.range[1]):
                return False
            drawn.append((curve, plot, x, y, breaks, low, high))
        spans: dict[pg.PlotItem, list[float]] = {}  # x0, x1, y0, y1 of what is new
        for curve, plot, x, y, breaks, low, high in drawn:
            self._extend_tail(curve, x, y, breaks)
            if np.isnan(low):
                continue
            span = spans.get(plot)
            if span is None:
                spans[plot] = [float(x[0]), float(x[-1]), low, high]
            else:
                span[0], span[1] = min(span[0], float(x[0])), max(span[1], float(x[-1]))
                span[2], span[3] = min(span[2], low), max(span[3], high)
        viewport = self.graphics.viewport()
        for plot, (x0, x1, y0, y1) in spans.items():
            sx, ox, sy, oy = self._mapping(plot)
            left, right = sorted((sx * x0 + ox, sx * x1 + ox))
            top, bottom = sorted((sy * y0 + oy, sy * y1 + oy))
            rect = QRect(int(np.floor(left)) - 2, int(np.floor(top)) - 2,
                         int(right - left) + 5, int(bottom - top) + 5) & self._area(plot)
            if not rect.isEmpty():
                self._fast += rect
                viewport.update(rect)
        self._stale = True
        return True

    def _extend_tail(self, curve: pg.PlotCurveItem, x: np.ndarray, y: np.ndarray,
                     breaks: np.ndarray) -> None:
        """Add new points (the previous end first) to a trace's tail; the first time, the
        tail starts from the end of the data the last rebuild gave the trace."""
        tail = self._tails.get(curve)
        if tail is None:
            old_x, old_y = curve.xData, curve.yData
            if old_x is not None and len(old_x):
                keep = old_x >= old_x[-1] - TAIL_S
                old_breaks = np.zeros(int(np.count_nonzero(keep)), dtype=bool)
                connect = curve.opts.get("connect")
                if isinstance(connect, np.ndarray) and len(connect) == len(old_x):
                    # pyqtgraph: connect[i] False leaves i and i + 1 apart
                    old_breaks[1:] = ~connect[keep][:-1].astype(bool)
                tail = (old_x[keep], old_y[keep], old_breaks)
            else:
                tail = (x[:0], y[:0], breaks[:0])
        tx, ty, tb = tail
        if len(tx) and x[0] <= tx[-1]:  # the previous end is there already
            newer = x > tx[-1]
            x, y, breaks = x[newer], y[newer], breaks[newer]
        tx, ty, tb = np.concatenate([tx, x]), np.concatenate([ty, y]), np.concatenate([tb, breaks])
        keep = tx >= tx[-1] - TAIL_S
        self._tails[curve] = (tx[keep], ty[keep], tb[keep])
        plot = self._plot_of[curve]
        self._tail_ends[plot] = max(self._tail_ends.get(plot, -np.inf), float(tx[-1]))

    def _mapping(self, plot: pg.PlotItem) -> tuple[float, float, float, float]:
        """x and y scale and offset from a trace's coordinates (as the last rebuild placed it,
        moved by the current scroll) to viewport pixels."""
        base = self._maps.get(plot)
        if base is None:
            box = plot.getViewBox()
            transform = box.childGroup.deviceTransform(self.graphics.viewportTransform())
            base = self._maps[plot] = (transform.m11(), transform.dx(), transform.m22(),
                                       transform.dy())
        sx, dx, sy, dy = base
        return sx, dx - sx * self._scroll_s, sy, dy

    def _area(self, plot: pg.PlotItem) -> QRect:
        """A plot's data area in viewport pixels, without its outermost pixel."""
        area = self._areas.get(plot)
        if area is None:
            box = plot.getViewBox()
            view = self.graphics
            outer = view.mapFromScene(box.mapRectToScene(box.boundingRect())).boundingRect()
            area = self._areas[plot] = outer.adjusted(1, 1, -1, -2)
        return area

    def _shown_plots(self) -> list[pg.PlotItem]:
        plots = [self.accel_plot, self.gyro_plot, self.angle_plot]
        if self._error_shown:
            plots.append(self.error_plot)
        return plots

    def _paint_fast(self, event: QPaintEvent) -> bool:
        """Paint a region that only scrolling and :meth:`append` touched (Qt has filled it
        with the background): the traces' newest lines that reach into it. False (nothing
        painted) for any other region."""
        region = event.region()
        fast = self._fast
        if fast.isEmpty() or not region.subtracted(fast).isEmpty():
            return False
        self._fast = QRegion()
        bounds = region.boundingRect()
        left, right = bounds.left() - 2, bounds.right() + 2
        if self._tail_end_px() < left:
            return True  # a strip scrolled into view beyond every trace's end: background
        viewport = self.graphics.viewport()
        painter: QPainter | None = None
        transforms: dict[pg.PlotItem, tuple[float, float, float, float, float, float]] = {}
        for curve, (x, y, breaks) in self._tails.items():
            plot = self._plot_of.get(curve)
            if plot is None or len(x) < 2:
                continue
            mapping = transforms.get(plot)
            if mapping is None:
                sx, ox, sy, oy = self._mapping(plot)
                # The region's x extent in the traces' own coordinates.
                mapping = transforms[plot] = (sx, ox, sy, oy, (left - ox) / sx,
                                              (right - ox) / sx)
            sx, ox, sy, oy, x_left, x_right = mapping
            if x[-1] < x_left or x[0] > x_right or not curve.isVisible():
                continue  # the trace does not reach the region (the usual scroll strip)
            # Only the points whose lines can reach the region (x grows along a trace).
            first = max(int(x.searchsorted(x_left)) - 1, 0)
            last = min(int(x.searchsorted(x_right)) + 1, len(x))
            if last - first < 2:
                continue
            px, py = sx * x[first:last] + ox, sy * y[first:last] + oy
            if painter is None:
                painter = QPainter(viewport)
            painter.setClipRect(self._area(plot))
            pen = curve.opts["pen"]
            if pen.style() != Qt.PenStyle.SolidLine:
                # The dash pattern's phase follows the unscrolled x position, so that the
                # pieces painted one after another line up (exact for level lines).
                pen = QPen(pen)
                pen.setDashOffset((px[0] + sx * self._scroll_s) / max(pen.widthF(), 1.0))
            painter.setPen(pen)
            xs, ys = px.tolist(), py.tolist()
            for run in _runs(px, py, breaks[first:last]):
                painter.drawPolyline(QPolygonF([QPointF(xs[i], ys[i]) for i in run]))
        if painter is not None:
            painter.end()
        return True

    def _tail_end_px(self) -> float:
        """The rightmost pixel any trace's newest point is at (-inf without tails)."""
        right = -np.inf
        for plot, end in self._tail_ends.items():
            sx, ox, _, _ = self._mapping(plot)
            right = max(right, sx * end + ox)
        return right

    def _before_scene_paint(self) -> None:
        """The scene paints: bring its traces up to what the screen shows first."""
        self._fast = QRegion()
        if not self._stale:
            return
        if self.resync is not None:
            self.resync()  # a rebuild: set_data puts everything in place
        if self._stale:  # no presenter (or it had nothing): at least where they scrolled to
            self._place_curves()
            self._stale = False

    def _layout_changed(self, *_args: object) -> None:
        """A plot's size or range changed: its pixels and their mapping are measured anew."""
        self._areas.clear()
        self._maps.clear()
        self._pixels_per_s = None

    def _in_sync(self) -> None:
        self._stale = False
        self._fast = QRegion()
        self._tails.clear()
        self._tail_ends.clear()
        self._layout_changed()

    @property
    def scroll_s(self) -> float:
        """How far (seconds) the traces are moved left of where their data put them."""
        return self._scroll_s

    def _place_curves(self) -> None:
        # A moved line keeps its path: nothing is rebuilt.
        for line in self._all_curves():
            if line.pos().x() != -self._scroll_s:
                line.setPos(-self._scroll_s, 0.0)

    def _all_curves(self) -> list[pg.PlotCurveItem]:
        return [
            *self.accel_curves, *self.gyro_curves, *self.angle_curves.values(),
            *(curve for pair in self.comparison_curves.values() for curve in pair),
            self.error_curve, *self.comparison_error_curves.values(),
        ]
