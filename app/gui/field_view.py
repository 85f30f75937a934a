"""The magnetic field's views: the magnetometer's axes, the field's strength and its dip against
gravity over time, with the reference (the local WMM field, or one learnt at rest) as dashed
lines, so a disturbance shows at a glance.

:class:`FieldPlots` only draws what it is handed; :class:`FieldPresenter` pulls the pipeline's
field ring (one row per field sample, :data:`app.core.pipeline.FIELD_COLUMNS`) on the frame
clock's ticks while the view is on screen, and the checks come from
:mod:`app.core.field_check`. Both exist only for a source with a magnetometer: the presenter
says when field samples come and go (:attr:`FieldPresenter.availabilityChanged`).
"""

from __future__ import annotations

import time
from datetime import date

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QDate, QObject, Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QDateEdit,
    QDoubleSpinBox,
    QFrame,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QScrollArea,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from app.core.earth_field import DEFAULT_PLACE, Place
from app.core.field_check import (
    Disturbance,
    FieldReference,
    ReferenceSettings,
    check_disturbance,
    learn_at_rest,
)
from app.gui import theme
from app.gui.elided_label import ElidedLabel
from app.gui.plots import StickyRange, _finite_bounds, _make_plot, legend_html

FIELD_REFRESH_S = 0.1
"""The field plots are rebuilt at most this often: a magnetometer delivers 10-155 samples/s,
and a redraw at 10 Hz shows every change a hand makes."""
LEARN_WINDOW_S = 2.0
"""The field of the last this many seconds is what *Learn at rest* takes."""
CHECK_WINDOW_S = 1.0
"""The status line judges the newest this many seconds against the reference."""


def _connect(gap: np.ndarray) -> np.ndarray | str:
    """pyqtgraph ``connect``: the line breaks before a sample that follows lost data."""
    if len(gap) < 2 or not np.any(gap[1:] > 0.5):
        return "all"
    return np.concatenate([gap[1:] <= 0.5, [True]])


class FieldPlots(QWidget):
    """Three x-linked plots: mx, my, mz (uT); |m| (uT); dip (°). Times relative to the newest
    sample (<= 0)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._window_s = 10.0
        self.graphics = pg.GraphicsLayoutWidget()
        self.graphics.ci.setSpacing(2)
        self.status = ElidedLabel()
        self.status.setObjectName("fieldStatus")
        self.status.setContentsMargins(6, 0, 6, 0)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.status)
        layout.addWidget(self.graphics, 1)
        self.mag_plot, self.norm_plot, self.dip_plot = _make_plot(), _make_plot(), _make_plot()
        for row, plot in enumerate((self.mag_plot, self.norm_plot, self.dip_plot)):
            self.graphics.addItem(plot, row=row, col=0)
            if plot is not self.mag_plot:
                plot.setXLink(self.mag_plot)
        for plot in (self.mag_plot, self.norm_plot):
            plot.getAxis("bottom").setStyle(showValues=False)
            plot.getAxis("bottom").setHeight(4)
        self.dip_plot.setLabel("bottom", "time", units="s")
        self.mag_curves = [pg.PlotCurveItem(skipFiniteCheck=True) for _ in range(3)]
        for curve in self.mag_curves:
            self.mag_plot.addItem(curve)
        self.norm_curve = pg.PlotCurveItem(skipFiniteCheck=True)
        self.dip_curve = pg.PlotCurveItem(skipFiniteCheck=True)
        self.norm_plot.addItem(self.norm_curve)
        self.dip_plot.addItem(self.dip_curve)
        # The disturbed samples, marked on the strength plot.
        self.disturbed_marks = pg.ScatterPlotItem(size=4, pen=None)
        self.norm_plot.addItem(self.disturbed_marks)
        # The reference: a dashed line at its value and dotted ones at its tolerance.
        self.reference_lines: dict[pg.PlotItem, list[pg.InfiniteLine]] = {
            plot: [pg.InfiniteLine(angle=0, movable=False) for _ in range(3)]
            for plot in (self.norm_plot, self.dip_plot)
        }
        for plot, lines in self.reference_lines.items():
            for line in lines:
                line.setVisible(False)
                plot.addItem(line)
        self.reference: FieldReference | None = None
        self.ranges = {plot: StickyRange(plot)
                       for plot in (self.mag_plot, self.norm_plot, self.dip_plot)}
        self.set_window(self._window_s)
        self.apply_theme()
        theme.notifier().changed.connect(self.apply_theme)

    def apply_theme(self, _name: str = "") -> None:
        self.graphics.setBackground(theme.BASE_BG)
        width = theme.current().LINE_WIDTH
        for axis, curve in enumerate(self.mag_curves):
            curve.setPen(pg.mkPen(theme.AXIS_COLORS[axis], width=width))
        self.norm_curve.setPen(pg.mkPen(theme.TRACE_TILT, width=width))
        self.dip_curve.setPen(pg.mkPen(theme.TRACE_DIRECTION, width=width))
        self.disturbed_marks.setBrush(pg.mkBrush(theme.ALARM_RED))
        for lines in self.reference_lines.values():
            lines[0].setPen(pg.mkPen(theme.TRACE_REFERENCE, width=width,
                                     style=Qt.PenStyle.DashLine))
            for line in lines[1:]:
                line.setPen(pg.mkPen(theme.TRACE_REFERENCE, width=1, style=Qt.PenStyle.DotLine))
        for plot in (self.mag_plot, self.norm_plot, self.dip_plot):
            for side in ("left", "bottom"):
                plot.getAxis(side).setPen(pg.mkPen(theme.BORDER))
                plot.getAxis(side).setTextPen(pg.mkPen(theme.TEXT_DIM))
        self._show_legends()

    def _show_legends(self) -> None:
        solid, dash = Qt.PenStyle.SolidLine, Qt.PenStyle.DashLine
        reference = [] if self.reference is None else [
            ("reference", theme.TRACE_REFERENCE, dash)]
        titles = {
            self.mag_plot: ("magnetic field (µT)",
                            [(name, theme.AXIS_COLORS[i], solid)
                             for i, name in enumerate(("mx", "my", "mz"))]),
            self.norm_plot: ("field strength |m| (µT)",
                             [("|m|", theme.TRACE_TILT, solid), *reference]),
            self.dip_plot: ("dip below horizontal (°)",
                            [("dip", theme.TRACE_DIRECTION, solid), *reference]),
        }
        for plot, (title, entries) in titles.items():
            plot.setTitle(legend_html(title, entries), size="8pt", justify="left")
            plot.layout.setRowFixedHeight(0, 16)
            plot.titleLabel.setMaximumHeight(16)

    def set_window(self, seconds: float) -> None:
        self._window_s = float(seconds)
        self.mag_plot.setXRange(-self._window_s, 0.0, padding=0.0)

    @property
    def window_s(self) -> float:
        return self._window_s

    def set_reference(self, reference: FieldReference | None) -> None:
        """Draw ``reference`` (None: none) as dashed lines with dotted tolerance lines."""
        self.reference = reference
        values = {} if reference is None else {
            self.norm_plot: (reference.total_ut, *reference.field_band_ut),
            self.dip_plot: (reference.dip_deg, reference.dip_deg - reference.dip_tolerance_deg,
                            reference.dip_deg + reference.dip_tolerance_deg),
        }
        for plot, lines in self.reference_lines.items():
            for line, value in zip(lines, values.get(plot, (None,) * 3), strict=True):
                line.setVisible(value is not None)
                if value is not None:
                    line.setValue(value)
        self._show_legends()

    def clear(self) -> None:
        for curve in (*self.mag_curves, self.norm_curve, self.dip_curve):
            curve.setData([], [])
        self.disturbed_marks.setData([], [])
        self.status.setText("")

    def set_data(self, t_rel: np.ndarray, mag_ut: np.ndarray, norm_ut: np.ndarray,
                 dip: np.ndarray, connect: np.ndarray | str = "all",
                 disturbed: np.ndarray | None = None) -> None:
        """Replace every trace: times (N,) relative to the newest sample, the field (N, 3),
        ``|m|`` and dip (N,; NaN dips are left out); ``disturbed`` (N,) bool marks samples."""
        for axis, curve in enumerate(self.mag_curves):
            curve.setData(t_rel, mag_ut[:, axis], connect=connect, skipFiniteCheck=True)
        self.norm_curve.setData(t_rel, norm_ut, connect=connect, skipFiniteCheck=True)
        known = np.isfinite(dip)
        # A dip that is not known (the sensor moving) is a hole in its line.
        base = np.ones(len(t_rel), bool) if isinstance(connect, str) else connect
        dip_connect = base & known & np.concatenate([known[1:], [True]])
        self.dip_curve.setData(t_rel, np.where(known, dip, 0.0), connect=dip_connect,
                               skipFiniteCheck=True)
        marks = np.zeros(len(t_rel), bool) if disturbed is None else disturbed
        self.disturbed_marks.setData(t_rel[marks], norm_ut[marks])
        self.ranges[self.mag_plot].follow(*_finite_bounds([mag_ut]))
        norms, dips = [norm_ut], [dip[known]]
        if self.reference is not None:  # the reference stays in view
            norms.append(np.array(self.reference.field_band_ut))
            tolerance = self.reference.dip_tolerance_deg
            dips.append(np.array([self.reference.dip_deg - tolerance,
                                  self.reference.dip_deg + tolerance]))
        self.ranges[self.norm_plot].follow(*_finite_bounds(norms))
        self.ranges[self.dip_plot].follow(*_finite_bounds(dips))

    def show_check(self, disturbance: Disturbance | None, reference: FieldReference | None,
                   newest: tuple[float, float] | None) -> None:
        """The line above the plots: the newest |m| and dip, and the verdict against the
        reference."""
        if newest is None:
            self.status.setText("")
            return
        norm, dip = newest
        dip_text = "dip — (moving)" if not np.isfinite(dip) else f"dip {dip:+.1f}°"
        text = f"|m| {norm:.1f} µT  ·  {dip_text}"
        state = "ok"
        if reference is None:
            text += "  ·  no reference"
        elif disturbance is not None and disturbance.message:
            text += f"  ·  DISTURBED: {disturbance.message}"
            state = "alarm"
        else:
            text += (f"  ·  matches {reference.source} "
                     f"({reference.total_ut:.1f} µT, dip {reference.dip_deg:+.1f}°)")
        self.status.setProperty("state", state)
        colour = theme.ALARM_RED if state == "alarm" else theme.TEXT_DIM
        self.status.setStyleSheet(f"color: {colour};")
        self.status.setText(text)


class ReferenceBar(QWidget):
    """The reference's settings: the place and date of the WMM field, or learn one at rest."""

    settingsChanged = Signal(object)  # ReferenceSettings
    learnRequested = Signal()
    useWmmRequested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(4, 2, 4, 2)
        self.latitude = self._spin(-90.0, 90.0, 4, "°N")
        self.longitude = self._spin(-180.0, 360.0, 4, "°E")
        self.altitude = self._spin(-1000.0, 850_000.0, 0, " m")
        self.today = QCheckBox("today")
        self.today.setChecked(True)
        self.date = QDateEdit()
        self.date.setCalendarPopup(True)
        self.date.setDisplayFormat("yyyy-MM-dd")
        self.date.setEnabled(False)
        self.today.toggled.connect(lambda on: self.date.setEnabled(not on))
        self.learn = QPushButton("Learn at rest")
        self.learn.setToolTip("Take the last 2 s of field (held still) as the reference")
        self.use_wmm = QPushButton("Use WMM")
        self.use_wmm.setToolTip("Compare with the World Magnetic Model's field at this place")
        self.learn.clicked.connect(self.learnRequested)
        self.use_wmm.clicked.connect(self.useWmmRequested)
        layout.addWidget(QLabel("WMM at"))
        for widget in (self.latitude, self.longitude, self.altitude, self.today, self.date,
                       self.use_wmm, self.learn):
            layout.addWidget(widget)
        layout.addStretch(1)
        for spin in (self.latitude, self.longitude, self.altitude):
            spin.editingFinished.connect(self._emit)
        self.today.toggled.connect(lambda _on: self._emit())
        self.date.editingFinished.connect(self._emit)
        self.show_settings(ReferenceSettings())

    @staticmethod
    def _spin(low: float, high: float, decimals: int, suffix: str) -> QDoubleSpinBox:
        spin = QDoubleSpinBox()
        spin.setRange(low, high)
        spin.setDecimals(decimals)
        spin.setSuffix(suffix)
        spin.setKeyboardTracking(False)
        return spin

    def show_settings(self, settings: ReferenceSettings) -> None:
        for spin, value in ((self.latitude, settings.place.latitude_deg),
                            (self.longitude, settings.place.longitude_deg),
                            (self.altitude, settings.place.altitude_m)):
            spin.blockSignals(True)
            spin.setValue(value)
            spin.blockSignals(False)
        self.today.blockSignals(True)
        self.today.setChecked(settings.when is None)
        self.today.blockSignals(False)
        self.date.setEnabled(settings.when is not None)
        when = settings.when or date.today()
        self.date.setDate(QDate(when.year, when.month, when.day))

    def settings(self) -> ReferenceSettings:
        """What the fields say (raises ValueError for a place or date the model refuses)."""
        when = None
        if not self.today.isChecked():
            qdate = self.date.date()
            when = date(qdate.year(), qdate.month(), qdate.day())
        place = Place(self.latitude.value(), self.longitude.value(), self.altitude.value())
        settings = ReferenceSettings(place, when)
        settings.reference()
        return settings

    def _emit(self) -> None:
        try:
            self.settingsChanged.emit(self.settings())
        except ValueError as exc:
            self.settingsChanged.emit(str(exc))


class FieldView(QWidget):
    """The Field dock's contents: the reference bar above the plots."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.reference_bar = ReferenceBar()
        self.plots = FieldPlots()
        # The bar scrolls sideways in a narrow dock rather than widening the window (the
        # dock shares the bottom tab group, which must fit a 1366x768 screen and less).
        bar = QScrollArea()
        bar.setWidget(self.reference_bar)
        bar.setWidgetResizable(True)
        bar.setFrameShape(QFrame.Shape.NoFrame)
        bar.setVerticalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        bar.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAsNeeded)
        bar.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Fixed)
        bar.setFixedHeight(self.reference_bar.sizeHint().height()
                           + bar.horizontalScrollBar().sizeHint().height())
        self.reference_scroller = bar
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(0)
        layout.addWidget(bar)
        layout.addWidget(self.plots, 1)


class FieldPresenter(QObject):
    """Feeds a :class:`FieldView` from ``session.pipeline.field`` on each ``tick`` (the frame
    clock), at most every :data:`FIELD_REFRESH_S` and only while the view is visible."""

    availabilityChanged = Signal(bool)
    """True once field samples arrive (a source with a magnetometer), False when the ring
    restarts empty (another device)."""
    problem = Signal(str)
    """A one-line message (a reference that could not be learnt or computed)."""
    wmmChanged = Signal(object)
    """The World Magnetic Model's field at the place and date the user set (a FieldReference),
    for the filters' check of the field they learn; None while the place is the default (a
    guess: checked against it, a sensor elsewhere would learn no reference at rest) or the
    field cannot be computed."""

    def __init__(self, session, view: FieldView, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.view = view
        self.settings = ReferenceSettings()
        self.reference: FieldReference | None = None
        self.learned = False
        self.available: bool | None = None  # unknown until the first frame says
        self._key: tuple | None = None
        self._last = -np.inf
        self.updates = 0
        """How often the plots were handed new data."""
        bar = view.reference_bar
        bar.settingsChanged.connect(self._on_settings)
        bar.learnRequested.connect(self.learn_reference)
        bar.useWmmRequested.connect(self.use_wmm)
        self.use_wmm()

    # -- settings (a section of the user settings) ----------------------------------------------
    def settings_dict(self) -> dict:
        return self.settings.to_dict()

    def apply_settings(self, stored: dict) -> None:
        """Stored settings (ValueError when they are not valid: the caller reports it)."""
        self.settings = ReferenceSettings.from_dict(stored)
        self.view.reference_bar.show_settings(self.settings)
        if not self.learned:
            self.use_wmm()
        else:
            self.wmmChanged.emit(self.for_filters(self.wmm()))

    def for_filters(self, wmm: FieldReference | None) -> FieldReference | None:
        """What the filters check their field against: the WMM's at a place the user set."""
        return wmm if self.settings.place != DEFAULT_PLACE else None

    def _on_settings(self, settings: object) -> None:
        if isinstance(settings, str):
            self.problem.emit(f"Field reference: {settings}")
            return
        self.settings = settings
        self.use_wmm()

    def wmm(self) -> FieldReference | None:
        """The WMM field at the place and date set (None, with a message, when it cannot be
        computed)."""
        try:
            return self.settings.reference()
        except ValueError as exc:
            self.problem.emit(f"Field reference: {exc}")
            return None

    def use_wmm(self) -> None:
        """Compare with the WMM field at the place and date set."""
        self.reference = self.wmm()
        self.wmmChanged.emit(self.for_filters(self.reference))
        self.learned = False
        self.view.plots.set_reference(self.reference)
        self._key = None

    def learn_reference(self) -> bool:
        """Take the last :data:`LEARN_WINDOW_S` of field as the reference (the sensor at
        rest); False, with a message, when it cannot."""
        rows = self.session.pipeline.field.window(LEARN_WINDOW_S, ["norm", "dip"])
        try:
            reference = learn_at_rest(rows["norm"], rows["dip"])
        except ValueError as exc:
            self.problem.emit(f"Field reference not learnt: {exc}")
            return False
        self.reference = reference
        self.learned = True
        self.view.plots.set_reference(reference)
        self._key = None
        return True

    # -- the frame ------------------------------------------------------------------------------
    def refresh(self) -> bool:
        """Draw what changed; True if it drew."""
        ring = self.session.pipeline.field
        total = ring.total_written
        available = total > 0
        if available != self.available:
            self.available = available
            if not available:
                self.view.plots.clear()
                self._key = None
            self.availabilityChanged.emit(available)
        plots = self.view.plots
        if not available or not plots.isVisible():
            return False
        key = (total, id(ring), plots.window_s, id(self.reference))
        now = time.monotonic()
        if key == self._key or now - self._last < FIELD_REFRESH_S:
            return False
        self._key, self._last = key, now
        rows = ring.window(plots.window_s, ["t", "mag", "norm", "dip", "gap"])
        if not len(rows["t"]):
            return False
        t_rel = rows["t"] - rows["t"][-1]
        disturbance = None
        if self.reference is not None:
            disturbance = check_disturbance(rows["norm"], rows["dip"], self.reference)
        plots.set_data(t_rel, rows["mag"], rows["norm"], rows["dip"], _connect(rows["gap"]),
                       None if disturbance is None else disturbance.disturbed)
        recent = t_rel >= -CHECK_WINDOW_S
        recent_check = None if self.reference is None else check_disturbance(
            rows["norm"][recent], rows["dip"][recent], self.reference)
        plots.show_check(recent_check, self.reference,
                         (float(rows["norm"][-1]), float(rows["dip"][-1])))
        self.updates += 1
        return True
