"""The Allan variance page: log-log deviation of a static recording, fitted noise lines, and a
button that sets the filters' noise parameters from the result.

The maths is :mod:`app.core.allan`; this view loads a recording (or takes a result), plots
gyroscope (deg/h) and accelerometer (ug) deviations per axis with the fitted model (dashed)
and the white-noise and random-walk asymptotes of the x axis (dotted), and tabulates the
figures in the usual units. A recording that moves or is too short is refused with the reason
(:func:`app.core.allan.static_record_problem`); a figure the record cannot support is shown as
"—" with what it would need (:func:`app.core.allan.figure_support`).

*Set filter noise parameters* asks first (old and new values), then emits ``parametersApplied``
per filter that has noise-figure parameters (the EKF and its smoother) with a sentence naming
the source, which the main window applies and logs; *Undo* sets the values from before. Where
they came from is kept in the application's one settings file (the INI).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QSettings, Qt, Signal
from PySide6.QtWidgets import (
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QMessageBox,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.core.allan import (
    AllanResult,
    SensorNoiseFigures,
    analyse_static,
    figure_support,
    filter_noise_parameters,
    static_record_problem,
)
from app.core.filters import FILTERS
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.gui.file_dialogs import open_file_name

AXIS_COLOURS = ("#e5534b", "#57ab5a", "#539bf5")
SETTINGS_KEY = "calibration_lab/filter_noise_source"
DEG_H = math.degrees(1.0) * 3600.0
UG = 1e6 / STANDARD_GRAVITY_M_S2


def figure_rows(result: AllanResult) -> list[tuple[str, str, np.ndarray, str, str]]:
    """(label, unit, values (3,), sensor, figure key) in the familiar units. The noise density
    twice: the datasheet's one-sided convention (a sample at fs scatters by N·√(fs/2)) and the
    Allan/Kalibr one (the Allan deviation at τ = 1 s: N·√fs), which is √2 smaller."""
    deg = math.degrees(1.0)
    g, a = result.gyro, result.accel
    return [
        ("Gyro noise density, datasheet (1-sided)", "°/s/√Hz", g.noise_density_one_sided * deg,
         "gyro", "noise_density"),
        ("Gyro noise density, Allan/Kalibr (τ = 1 s)", "°/s/√Hz",
         g.noise_density_allan * deg, "gyro", "noise_density"),
        ("Gyro bias instability", "°/h", g.bias_instability * DEG_H, "gyro",
         "bias_instability"),
        ("Gyro random walk", "°/h/√h", g.random_walk * DEG_H * 60.0, "gyro", "random_walk"),
        ("Accel noise density, datasheet (1-sided)", "µg/√Hz", a.noise_density_one_sided * UG,
         "accel", "noise_density"),
        ("Accel noise density, Allan/Kalibr (τ = 1 s)", "µg/√Hz", a.noise_density_allan * UG,
         "accel", "noise_density"),
        ("Accel bias instability", "µg", a.bias_instability * UG, "accel", "bias_instability"),
        ("Accel random walk", "µg/√h", a.random_walk * UG * 60.0, "accel", "random_walk"),
    ]


DENSITY_TIP = (
    "Two conventions for the same white noise. Datasheet (one-sided, as ST's figures): one "
    "sample at rate fs scatters by N·√(fs/2). Allan/Kalibr/IEEE 952: the Allan deviation at "
    "τ = 1 s, one sample scatters by N·√fs; Kalibr's imu.yaml wants this one "
    "(inclinometer allan --kalibr).")


CurrentParameters = Callable[[str, list[str]], dict[str, float] | None]
"""(filter name, parameter names) -> the values in use now, None when that filter is not running."""


class AllanPage(QWidget):
    """See the module docstring.

    ``settings`` is the application's settings (the INI; default: the one
    :func:`app.gui.user_settings.create_settings` opens); ``current_parameters`` tells the
    values in use before a change, for *Undo* and the question.
    """

    parametersApplied = Signal(str, dict, str)  # filter name, {parameter: value}, source

    def __init__(self, parent: QWidget | None = None, settings: QSettings | None = None,
                 current_parameters: CurrentParameters | None = None) -> None:
        super().__init__(parent)
        if settings is None:
            from app.gui.user_settings import create_settings

            settings = create_settings()
        self.settings = settings
        self.current_parameters = current_parameters
        self.setWindowTitle("Allan variance — noise figures")
        self.result: AllanResult | None = None
        self.source = ""
        self.undo_values: dict[str, dict[str, float]] = {}
        layout = QVBoxLayout(self)
        top = QHBoxLayout()
        self.open_button = QPushButton("Open static recording…")
        self.open_button.clicked.connect(self._choose_file)
        self.apply_button = QPushButton("Set filter noise parameters")
        self.apply_button.setToolTip(
            "Set the EKF's gyro noise density, gyro bias drift and gravity noise floor (and "
            "the smoother's) from these figures")
        self.apply_button.setEnabled(False)
        self.apply_button.clicked.connect(lambda: self.request_apply())
        self.undo_button = QPushButton("Undo")
        self.undo_button.setToolTip("Set the filter noise parameters back to their values before")
        self.undo_button.setEnabled(False)
        self.undo_button.clicked.connect(self.undo)
        top.addWidget(self.open_button)
        top.addWidget(self.apply_button)
        top.addWidget(self.undo_button)
        top.addStretch(1)
        layout.addLayout(top)
        self.summary = QLabel("Open a recording of the sensor lying still (30 minutes or more).")
        self.summary.setWordWrap(True)
        layout.addWidget(self.summary)
        plots = QHBoxLayout()
        self.gyro_plot = self._make_plot("Gyroscope", "Allan deviation (°/h)")
        self.accel_plot = self._make_plot("Accelerometer", "Allan deviation (µg)")
        plots.addWidget(self.gyro_plot)
        plots.addWidget(self.accel_plot)
        layout.addLayout(plots, 1)
        self.table = QTableWidget(0, 5)
        self.table.setHorizontalHeaderLabels(["Figure", "Unit", "x", "y", "z"])
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.table.horizontalHeader().setSectionResizeMode(
            0, QHeaderView.ResizeMode.ResizeToContents)
        self.table.setMaximumHeight(250)
        layout.addWidget(self.table)
        self.applied_label = QLabel(self._last_source())
        self.applied_label.setWordWrap(True)
        self.applied_label.setObjectName("dimLabel")
        layout.addWidget(self.applied_label)
        self.resize(1000, 720)

    @staticmethod
    def _make_plot(title: str, label: str) -> pg.PlotWidget:
        plot = pg.PlotWidget(title=title)
        plot.setLogMode(True, True)
        plot.showGrid(x=True, y=True, alpha=0.3)
        plot.setLabel("bottom", "averaging time τ (s)")
        plot.setLabel("left", label)
        plot.addLegend(offset=(-10, 10))
        return plot

    def _last_source(self) -> str:
        value = self.settings.value(SETTINGS_KEY, "")
        return f"Filter noise parameters last set from: {value}" if value else ""

    # -- input ---------------------------------------------------------------------------------
    def _choose_file(self) -> None:
        path = open_file_name(self, "Static recording", "Recordings (*.csv *.csv.gz)")
        if path:
            self.load_recording(path)

    def load_recording(self, path: str | Path) -> AllanResult | None:
        """Read a recording and show its analysis; a bad file is shown, not raised."""
        from app.core.recording.errors import RecordingError
        from app.core.recording.reader import read_recording

        try:
            recording = read_recording(path)
            problem = static_record_problem(recording.gyro_rad_s, recording.accel_m_s2,
                                            recording.rate_hz)
            if problem:
                raise ValueError(problem)
            result = analyse_static(recording.gyro_rad_s, recording.accel_m_s2,
                                    recording.rate_hz, recording.temp_degc)
        except (RecordingError, OSError, ValueError) as exc:
            self._clear()
            self.summary.setText(f"<b>Cannot analyse {Path(path).name}:</b> {exc}")
            return None
        self.show_result(result, f"Allan analysis of {Path(path).name}")
        return result

    def _clear(self) -> None:
        """Forget the shown result: nothing to plot, tabulate or set."""
        self.result, self.source = None, ""
        self.gyro_plot.clear()
        self.accel_plot.clear()
        self.table.setRowCount(0)
        self.apply_button.setEnabled(False)

    def show_result(self, result: AllanResult, source: str) -> None:
        self.result, self.source = result, source
        support = figure_support(result)
        span = result.temperature_span_degc
        temperature = ""
        if math.isfinite(span):
            temperature = (f"; temperature moved {span:.2f} °C"
                           + (", regressed out" if result.temperature_removed else ""))
        self.summary.setText(
            f"{source}: {result.duration_s / 60:.1f} min at {result.rate_hz:.4g} Hz"
            f"{temperature}. Solid: measured; dashed: model (noise density and random walk "
            "from the time series' likelihood, bias instability from the curve); dotted: white "
            "noise (slope −½)"
            + (" and random walk (slope +½)" if support.supported("gyro", "random_walk")[0]
               else "") + " of x."
            + "".join(f"<br>— {note}." for note in support.notes))
        self._plot(self.gyro_plot, result.gyro, DEG_H,
                   bool(support.supported("gyro", "random_walk")[0]))
        self._plot(self.accel_plot, result.accel, UG,
                   bool(support.supported("accel", "random_walk")[0]))
        rows = figure_rows(result)
        self.table.setRowCount(len(rows))
        for r, (label, unit, values, sensor, key) in enumerate(rows):
            shown = support.supported(sensor, key)
            cells = [label, unit, *(f"{v:.4g}" if ok else "—"
                                    for v, ok in zip(values, shown, strict=True))]
            for c, text in enumerate(cells):
                item = QTableWidgetItem(text)
                if key == "noise_density":
                    item.setToolTip(DENSITY_TIP)
                self.table.setItem(r, c, item)
        self.table.resizeRowsToContents()
        whole = (self.table.horizontalHeader().sizeHint().height() + 2 * self.table.frameWidth()
                 + sum(self.table.rowHeight(r) for r in range(len(rows))))
        self.table.setMaximumHeight(whole)
        self.table.setMinimumHeight(whole)  # every row in view, the plots take what is left
        self.apply_button.setEnabled(True)

    def _plot(self, plot: pg.PlotWidget, figures: SensorNoiseFigures, factor: float,
              walk_supported: bool = True) -> None:
        plot.clear()
        tau = figures.tau_s
        for axis, name, colour in zip(figures.axes, "xyz", AXIS_COLOURS, strict=True):
            plot.plot(tau, axis.adev * factor, pen=pg.mkPen(colour, width=2), name=name,
                      symbol="o", symbolSize=4, symbolBrush=colour, symbolPen=None)
            plot.plot(tau, axis.model_adev(tau) * factor,
                      pen=pg.mkPen(colour, width=1, style=Qt.PenStyle.DashLine))
        first = figures.axes[0]
        dotted = pg.mkPen("#aaaaaa", width=1, style=Qt.PenStyle.DotLine)
        plot.plot(tau, first.white_line(tau) * factor, pen=dotted)
        if first.random_walk > 0 and walk_supported:
            plot.plot(tau, first.walk_line(tau) * factor, pen=dotted)

    # -- the button ----------------------------------------------------------------------------
    def proposed_parameters(self) -> dict[str, dict[str, float]]:
        return {} if self.result is None else filter_noise_parameters(self.result, FILTERS)

    def _current(self, name: str, keys: list[str]) -> dict[str, float] | None:
        return None if self.current_parameters is None else self.current_parameters(name, keys)

    def question(self) -> str:
        """What *Set filter noise parameters* asks: every change, old value to new."""
        lines = []
        for name, values in self.proposed_parameters().items():
            now = self._current(name, list(values)) or {}
            changes = ", ".join(
                (f"{key} {now[key]:.4g} → {value:.4g}" if key in now else f"{key} = {value:.4g}")
                for key, value in values.items())
            lines.append(f"{name}: {changes}")
        return ("Set these filter noise parameters from " + self.source + "?\n\n"
                + "\n".join(lines) + "\n\nUndo sets the values from before.")

    def request_apply(self, confirm: Callable[[str], bool] | None = None
                      ) -> dict[str, dict[str, float]]:
        """Ask (``confirm``, default a message box), then :meth:`apply_to_filters`."""
        if not self.proposed_parameters():
            return {}
        if confirm is None:
            def confirm(text: str) -> bool:
                answer = QMessageBox.question(self, "Set filter noise parameters", text)
                return answer == QMessageBox.StandardButton.Yes
        if not confirm(self.question()):
            self.applied_label.setText("Filter noise parameters not changed.")
            return {}
        return self.apply_to_filters()

    def undo(self) -> dict[str, dict[str, float]]:
        """Set the values in use before the last :meth:`apply_to_filters` again."""
        previous, self.undo_values = self.undo_values, {}
        for name, values in previous.items():
            self.parametersApplied.emit(name, values, "undo")
        self.undo_button.setEnabled(False)
        if previous:
            self.settings.setValue(SETTINGS_KEY, "")
            self.applied_label.setText("Undone: the filter noise parameters from before are set.")
        return previous

    def apply_to_filters(self) -> dict[str, dict[str, float]]:
        """Emit the noise parameters per filter and remember where they came from."""
        proposed = self.proposed_parameters()
        if not proposed:
            return proposed
        self.undo_values = {}
        for name, values in proposed.items():
            now = self._current(name, list(values))
            if now:
                self.undo_values[name] = now
        self.undo_button.setEnabled(bool(self.undo_values))
        stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
        source = f"{self.source} ({stamp})"
        self.settings.setValue(SETTINGS_KEY, source)
        for name, values in proposed.items():
            self.parametersApplied.emit(name, values, source)
        text = "; ".join(f"{name}: " + ", ".join(f"{k} = {v:.4g}" for k, v in values.items())
                         for name, values in proposed.items())
        self.applied_label.setText(f"Set {text} — from {source}")
        return proposed
