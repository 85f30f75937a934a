"""The Alarms panel: a limit per quantity (tilt, roll, pitch, out of level), hysteresis, delay,
and whether crossings sound.

It only edits an :class:`~app.core.alarms.AlarmConfig` and emits it; the worker evaluates the
alarms (app/core/alarms/) and the main window shows them.
"""

from __future__ import annotations

from dataclasses import replace

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QDoubleSpinBox,
    QGridLayout,
    QLabel,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from app.core.alarms import (
    MAX_DELAY_S,
    QUANTITIES,
    QUANTITY_TITLES,
    AlarmConfig,
    AlarmLimit,
    default_alarm_config,
)
from app.gui import theme

SPIN_MIN_WIDTH_PX = 84
LIMIT_RANGE_DEG = {"heading": (-180.0, 180.0),
                   "tilt": (0.0, 180.0), "roll": (-180.0, 180.0), "pitch": (-90.0, 90.0),
                   "level": (0.0, 90.0)}


def _spin(low: float, high: float, decimals: int, suffix: str, tip: str) -> QDoubleSpinBox:
    spin = QDoubleSpinBox()
    spin.setRange(low, high)
    spin.setDecimals(decimals)
    spin.setSingleStep(0.1)
    spin.setSuffix(suffix)
    spin.setKeyboardTracking(False)
    spin.setToolTip(tip)
    # Narrower than its size hint allows when the dock is narrow (the digits still fit).
    spin.setMinimumWidth(SPIN_MIN_WIDTH_PX)
    spin.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Fixed)
    return spin


class _AlarmRow:
    """The controls of one quantity's alarm."""

    def __init__(self, quantity: str) -> None:
        self.quantity = quantity
        low, high = LIMIT_RANGE_DEG[quantity]
        self.enabled = QCheckBox(QUANTITY_TITLES[quantity])
        self.enabled.setToolTip(
            "Out of level: the tilt beyond the tolerance" if quantity == "level"
            else f"Alarm on the {quantity}")
        self.below_on = QCheckBox("below")
        self.below_on.setToolTip("Alarm below this limit")
        self.below = _spin(low, high, 2, "°", "Lower limit (degrees)")
        self.above_on = QCheckBox("above")
        self.above_on.setToolTip("Alarm above this limit" if quantity != "level"
                                 else "Tolerance: alarm when the tilt exceeds it")
        self.above = _spin(low, high, 2, "°", "Upper limit (degrees)")
        self.hysteresis = _spin(0.0, 90.0, 2, "°",
                                "Clears once back inside the limit by this much")
        self.delay = _spin(0.0, MAX_DELAY_S, 1, " s",
                           "The condition must hold this long to raise, and to clear")
        self.state = QLabel("")
        self.hysteresis_label = QLabel("hyst.")
        self.delay_label = QLabel("delay")
        for label in (self.hysteresis_label, self.delay_label):
            label.setObjectName("dimLabel")
        if quantity == "level":  # a tolerance: upper only
            self.below_on.setVisible(False)
            self.below.setVisible(False)
            self.above_on.setChecked(True)
            self.above_on.setEnabled(False)
        self.centre: QDoubleSpinBox | None = None
        self.centre_label: QLabel | None = None
        if quantity == "heading":  # limits on the difference from a set heading
            self.enabled.setToolTip("Alarm on the magnetic heading's difference from a set "
                                    "heading (wraps round north)")
            self.centre = _spin(0.0, 359.9, 1, "°", "The set heading (magnetic, clockwise "
                                "from north)")
            self.centre.setWrapping(True)
            self.centre_label = QLabel("set")
            self.centre_label.setObjectName("dimLabel")
            self.below_on.setText("ccw")
            self.below_on.setToolTip("Alarm when the heading is this far anticlockwise of it "
                                     "(a negative difference)")
            self.above_on.setText("cw")
            self.above_on.setToolTip("Alarm when the heading is this far clockwise of it")
        self.below.setEnabled(False)
        self.below_on.toggled.connect(self.below.setEnabled)
        self.above_on.toggled.connect(self.above.setEnabled)

    def widgets(self) -> list[QWidget]:
        extra = [] if self.centre is None else [self.centre]
        return [self.enabled, self.below_on, self.below, self.above_on, self.above,
                self.hysteresis, self.delay, self.state, *extra]

    def place(self, grid: QGridLayout, row: int) -> None:
        """Three grid lines: the name and state, the limits, the hysteresis and delay."""
        grid.addWidget(self.enabled, row, 0, 1, 2)
        grid.addWidget(self.state, row, 2, 1, 2, Qt.AlignmentFlag.AlignRight)
        grid.addWidget(self.below_on, row + 1, 0)
        grid.addWidget(self.below, row + 1, 1)
        grid.addWidget(self.above_on, row + 1, 2)
        grid.addWidget(self.above, row + 1, 3)
        grid.addWidget(self.hysteresis_label, row + 2, 0)
        grid.addWidget(self.hysteresis, row + 2, 1)
        grid.addWidget(self.delay_label, row + 2, 2)
        grid.addWidget(self.delay, row + 2, 3)
        if self.centre is not None and self.centre_label is not None:
            grid.addWidget(self.centre_label, row + 3, 0)
            grid.addWidget(self.centre, row + 3, 1)

    def show(self, limit: AlarmLimit) -> None:
        self.enabled.setChecked(limit.enabled)
        self.below_on.setChecked(limit.lower is not None)
        if limit.lower is not None:
            self.below.setValue(limit.lower)
        self.above_on.setChecked(limit.upper is not None)
        if limit.upper is not None:
            self.above.setValue(limit.upper)
        self.below.setEnabled(self.below_on.isChecked())
        self.above.setEnabled(self.above_on.isChecked())
        self.hysteresis.setValue(limit.hysteresis)
        self.delay.setValue(limit.delay_s)
        if self.centre is not None and limit.centre is not None:
            self.centre.setValue(limit.centre)

    def limit(self) -> AlarmLimit:
        """The row as an alarm (ValueError when its limits contradict each other)."""
        return AlarmLimit(
            self.quantity,
            upper=self.above.value() if self.above_on.isChecked() else None,
            lower=self.below.value() if self.below_on.isChecked() else None,
            hysteresis=self.hysteresis.value(), delay_s=self.delay.value(),
            enabled=self.enabled.isChecked(),
            centre=None if self.centre is None else self.centre.value() % 360.0,
        )


class AlarmPanel(QWidget):
    """Edits the alarms; ``alarmsChanged(AlarmConfig)`` after every valid change."""

    alarmsChanged = Signal(object)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        intro = QLabel("Limits on the filtered angles, in degrees. An alarm is raised once "
                       "beyond a limit for the delay, and clears once back inside by the "
                       "hysteresis for the delay.")
        intro.setWordWrap(True)
        intro.setObjectName("dimLabel")
        layout.addWidget(intro)
        grid = QGridLayout()
        grid.setHorizontalSpacing(6)
        grid.setVerticalSpacing(3)
        self.rows: dict[str, _AlarmRow] = {}
        for index, quantity in enumerate(QUANTITIES):
            row = _AlarmRow(quantity)
            self.rows[quantity] = row
            row.place(grid, 4 * index)
            if row.centre is None:
                grid.setRowMinimumHeight(4 * index + 3, 6)  # a gap between quantities
        grid.setColumnStretch(1, 1)
        grid.setColumnStretch(3, 1)
        layout.addLayout(grid)
        self.sound = QCheckBox("Sound on each alarm")
        self.sound.setToolTip("The system's beep when an alarm is raised")
        layout.addWidget(self.sound)
        self.problem = QLabel("")
        self.problem.setWordWrap(True)
        self.problem.setStyleSheet(f"color: {theme.WARN_AMBER};")
        layout.addWidget(self.problem)
        layout.addStretch(1)
        self._config = default_alarm_config()
        self.set_config(self._config)
        for row in self.rows.values():
            for box in (row.enabled, row.below_on, row.above_on):
                box.toggled.connect(self._on_edited)
            for spin in (row.below, row.above, row.hysteresis, row.delay,
                         *([] if row.centre is None else [row.centre])):
                spin.valueChanged.connect(self._on_edited)
        self.sound.toggled.connect(self._on_edited)

    def config(self) -> AlarmConfig:
        """The alarms as last accepted."""
        return self._config

    def set_config(self, config: AlarmConfig) -> None:
        """Show ``config`` (the first alarm per quantity; quantities it lacks keep the
        default, switched off) without emitting."""
        defaults = {limit.quantity: limit for limit in default_alarm_config().limits}
        given: dict[str, AlarmLimit] = {}
        for limit in config.limits:
            given.setdefault(limit.quantity, limit)
        controls = [w for row in self.rows.values() for w in row.widgets()] + [self.sound]
        for widget in controls:
            widget.blockSignals(True)
        try:
            for quantity, row in self.rows.items():
                row.show(given.get(quantity, defaults[quantity]))
            self.sound.setChecked(config.sound)
        finally:
            for widget in controls:
                widget.blockSignals(False)
        self._config = self._read() or replace(default_alarm_config(), sound=config.sound)
        self.problem.setText("")

    def show_active(self, quantities: set[str] | frozenset[str]) -> None:
        """Mark the rows whose alarm is raised now."""
        for quantity, row in self.rows.items():
            on = quantity in quantities
            row.state.setText("ALARM" if on else "")
            row.state.setStyleSheet(f"color: {theme.ALARM_STATE}; font-weight: bold;"
                                    if on else "")

    def _read(self) -> AlarmConfig | None:
        try:
            limits = tuple(row.limit() for row in self.rows.values())
        except ValueError as exc:
            self.problem.setText(f"Not applied: {exc}")
            return None
        return AlarmConfig(limits, self.sound.isChecked())

    def _on_edited(self, *_args: object) -> None:
        config = self._read()
        if config is None:
            return
        self.problem.setText("")
        if config != self._config:
            self._config = config
            self.alarmsChanged.emit(config)
