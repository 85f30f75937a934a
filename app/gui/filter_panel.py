"""The filter panel: choose the orientation filter and edit its parameters.

Controls are built from each filter's :class:`~app.core.filters.ParameterSpec` schema, so a
new filter needs no GUI code. A filter kept only as a reference implementation
(``reference_only``, the thesis's Kalman filter) says so in its list text and tooltip, and is
never ticked for comparison unless the user ticks it. An offline filter (``offline``: a
smoother, which needs the whole recording in one pass) is listed greyed out, marked
"(offline)", and can be neither chosen nor ticked: it cannot run on a live stream.
"""

from __future__ import annotations

import math
from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QValidator
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QSpinBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.core.filters import FILTERS, ONLINE_FILTERS, OrientationFilter, ParameterSpec
from app.core.readout import unit_symbol

REFERENCE_ONLY_LABEL = "reference, not for measurement"
REFERENCE_ONLY_NOTE = (
    "Kept as a faithful reference implementation of the founding thesis's filter, to compare "
    "with; not for measurement."
)
OFFLINE_LABEL = "offline"


def offline_note(name: str) -> str:
    """Why an offline filter cannot be chosen here, and where to use it instead."""
    return (
        "offline: needs the whole recording — use "
        f"`inclinometer replay IN.csv --filter {name} --out ANGLES.csv` "
        f"or `inclinometer evaluate IN.csv --filter {name}`"
    )


def filter_label(cls: type[OrientationFilter]) -> str:
    """The text a filter is listed under: its title, marked when it is a reference only."""
    title = cls.title or cls.name
    if cls.offline:
        mark = f"({OFFLINE_LABEL})"
        return title if title.endswith(mark) else f"{title} {mark}"
    return f"{title} ({REFERENCE_ONLY_LABEL})" if cls.reference_only else title


def filter_tooltip(cls: type[OrientationFilter]) -> str:
    """The filter's description, with the reference-only or offline note where it applies."""
    if cls.offline:
        return f"{offline_note(cls.name)}\n\n{cls.description}".strip()
    if cls.reference_only:
        return f"{cls.description}\n\n{REFERENCE_ONLY_NOTE}".strip()
    return cls.description


class ScientificSpinBox(QDoubleSpinBox):
    """A spin box that shows and accepts numbers like 1e-05 (for parameters spanning decades)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setDecimals(15)  # Qt rounds values to this many decimals internally

    def textFromValue(self, value: float) -> str:
        return f"{value:.4g}"

    def valueFromText(self, text: str) -> float:
        try:
            return float(text.replace(self.suffix(), "").strip())
        except ValueError:
            return self.value()

    def validate(self, text: str, position: int):
        body = text.replace(self.suffix(), "").strip()
        try:
            float(body)
        except ValueError:
            partial = body in ("", "-", "+", ".") or body[-1:] in ("e", "E", "-", "+")
            state = QValidator.State.Intermediate if partial else QValidator.State.Invalid
            return state, text, position
        return QValidator.State.Acceptable, text, position

    def stepBy(self, steps: int) -> None:
        # A step is a factor of about 1.26 (ten steps per decade).
        value = self.value() or self.minimum() or 1e-6
        self.setValue(value * 10 ** (0.1 * steps))


def _decimals_for(spec: ParameterSpec) -> int:
    smallest = spec.minimum if spec.minimum > 0 else max(spec.default, 1e-3)
    return min(6, max(1, -math.floor(math.log10(abs(smallest))) + 1)) if smallest else 3


class FilterPanel(QWidget):
    """Filter chooser, a form of parameter controls, and filters to compare side by side."""

    filterRequested = Signal(str)
    parameterChanged = Signal(str, object)
    comparisonsRequested = Signal(list)
    sourceDefaultRequested = Signal()
    """The user ticked "The source's default": the filter follows each source again."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        self.combo = QComboBox()
        # The longest text (a reference-only filter's) must not widen the whole dock.
        self.combo.setSizeAdjustPolicy(
            QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.combo.setMinimumContentsLength(24)
        for name, cls in FILTERS.items():
            if cls.offline and self.combo.count() and self.combo.itemData(
                    self.combo.count() - 1) in ONLINE_FILTERS:
                self.combo.insertSeparator(self.combo.count())
            self.combo.addItem(filter_label(cls), name)
            tooltip = Qt.ItemDataRole.ToolTipRole
            self.combo.setItemData(self.combo.count() - 1, filter_tooltip(cls), tooltip)
            if cls.offline:  # listed, greyed out: it cannot run on a live stream
                item = self.combo.model().item(self.combo.count() - 1)
                item.setEnabled(False)
        self.combo.activated.connect(self._on_activated)
        layout.addWidget(self.combo)
        self.source_default = QCheckBox("The source's default")
        self.source_default.setToolTip(
            "Run the default filter of each source: with a magnetometer the 9-axis one (it "
            "gives the heading), without one the 6-axis one. Picking a filter or setting a "
            "parameter keeps that filter for every source instead.")
        self.source_default.clicked.connect(self._on_source_default)
        layout.addWidget(self.source_default)
        self.description = QLabel()
        self.description.setWordWrap(True)
        self.description.setObjectName("dimLabel")
        layout.addWidget(self.description)
        self.form_host = QWidget()
        self.form = QFormLayout(self.form_host)
        self.form.setContentsMargins(0, 4, 0, 0)
        layout.addWidget(self.form_host)

        compare = QGroupBox("Compare with")
        compare_layout = QVBoxLayout(compare)
        self.compare_list = QListWidget()
        self.compare_list.setToolTip(
            "Run these filters on the same data; their roll and pitch are overlaid on the plot"
        )
        for name, cls in FILTERS.items():
            item = QListWidgetItem(filter_label(cls))
            item.setData(Qt.ItemDataRole.UserRole, name)
            if cls.offline:
                item.setFlags(item.flags() & ~Qt.ItemFlag.ItemIsEnabled
                              & ~Qt.ItemFlag.ItemIsUserCheckable)
            else:
                item.setFlags(item.flags() | Qt.ItemFlag.ItemIsUserCheckable)
                item.setCheckState(Qt.CheckState.Unchecked)
            item.setToolTip(filter_tooltip(cls))
            self.compare_list.addItem(item)
        self.compare_list.setMaximumHeight(22 * max(3, len(FILTERS)) + 6)
        self.compare_list.itemChanged.connect(self._on_compare_changed)
        compare_layout.addWidget(self.compare_list)
        self.error_table = QTableWidget(0, 3)
        self.error_table.setHorizontalHeaderLabels(["Filter", "RMS error", "Max error"])
        self.error_table.verticalHeader().setVisible(False)
        self.error_table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.error_table.setSelectionMode(QTableWidget.SelectionMode.NoSelection)
        self.error_table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.error_table.setToolTip(
            "Inclination error against the reference orientation (the simulator's truth) "
            "over the plot window"
        )
        compare_layout.addWidget(self.error_table)
        self.error_note = QLabel("Errors appear when the source knows its true orientation.")
        self.error_note.setObjectName("dimLabel")
        self.error_note.setWordWrap(True)
        compare_layout.addWidget(self.error_note)
        layout.addWidget(compare)
        layout.addStretch(1)
        self._controls: dict[str, QWidget] = {}
        self._current = ""

    @property
    def current_filter(self) -> str:
        return self._current

    def show_filter(self, name: str, values: dict[str, Any]) -> None:
        """Show ``name`` as the running filter with these parameter values."""
        cls = FILTERS[name]
        self.combo.setCurrentIndex(self.combo.findData(name))
        # setFlags emits itemChanged: without the block, the still-unticked list would be sent
        # as the comparison set and undo comparisons requested but not yet reported back.
        self.compare_list.blockSignals(True)
        for row in range(self.compare_list.count()):
            item = self.compare_list.item(row)
            item_name = item.data(Qt.ItemDataRole.UserRole)
            disabled = item_name == name or item_name not in ONLINE_FILTERS
            flags = item.flags()
            item.setFlags(flags & ~Qt.ItemFlag.ItemIsEnabled if disabled
                          else flags | Qt.ItemFlag.ItemIsEnabled)
        self.compare_list.blockSignals(False)
        self.description.setText(filter_tooltip(cls))
        if name != self._current:
            self._current = name
            self._build_form(cls.parameters)
        for key, value in values.items():
            control = self._controls.get(key)
            if control is None:
                continue
            control.blockSignals(True)
            if isinstance(control, QCheckBox):
                control.setChecked(bool(value))
            else:
                control.setValue(value)
            control.blockSignals(False)

    def compared_filters(self) -> list[str]:
        """Names of the filters ticked for comparison (the main filter excluded)."""
        names = []
        for row in range(self.compare_list.count()):
            item = self.compare_list.item(row)
            name = item.data(Qt.ItemDataRole.UserRole)
            if (item.checkState() == Qt.CheckState.Checked and name != self._current
                    and name in ONLINE_FILTERS):
                names.append(name)
        return names

    def show_comparisons(self, names: list[str]) -> None:
        """Tick exactly ``names`` (what the worker reports as running)."""
        self.compare_list.blockSignals(True)
        for row in range(self.compare_list.count()):
            item = self.compare_list.item(row)
            item_name = item.data(Qt.ItemDataRole.UserRole)
            if item_name not in ONLINE_FILTERS:
                continue  # never ticked (and without a check box)
            checked = item_name in names
            item.setCheckState(Qt.CheckState.Checked if checked else Qt.CheckState.Unchecked)
        self.compare_list.blockSignals(False)

    def show_errors(self, rows: list[tuple[str, float, float]]) -> None:
        """Fill the error table: (title, RMS degrees, max degrees); NaN shows as a dash."""
        self.error_table.setRowCount(len(rows))
        known = False
        for row, (title, rms, worst) in enumerate(rows):
            known |= rms == rms
            cells = (title, f"{rms:.3f}°" if rms == rms else "—",
                     f"{worst:.3f}°" if worst == worst else "—")
            for column, text in enumerate(cells):
                self.error_table.setItem(row, column, QTableWidgetItem(text))
        self.error_note.setVisible(not known)

    def _on_compare_changed(self, _item: QListWidgetItem) -> None:
        self.comparisonsRequested.emit(self.compared_filters())

    def set_follows_source(self, follows: bool) -> None:
        """Show whether the filter is the source's default or the user's choice."""
        self.source_default.setChecked(follows)

    def _on_source_default(self, checked: bool) -> None:
        if checked:
            self.sourceDefaultRequested.emit()
        elif self._current:  # unticked: the running filter becomes the user's choice
            self.filterRequested.emit(self._current)

    def _on_activated(self, index: int) -> None:
        name = self.combo.itemData(index)
        if name not in ONLINE_FILTERS:  # a separator or an offline filter: never live
            if self._current:
                self.combo.setCurrentIndex(self.combo.findData(self._current))
            return
        if name != self._current:
            self.filterRequested.emit(name)

    def _build_form(self, specs: tuple[ParameterSpec, ...]) -> None:
        while self.form.rowCount():
            self.form.removeRow(0)
        self._controls = {}
        for spec in specs:
            control = self._make_control(spec)
            control.setToolTip(spec.help)
            self._controls[spec.name] = control
            row = QHBoxLayout()
            row.addWidget(control, 1)
            if spec.presets:
                row.addWidget(self._make_presets(spec))
            holder = QWidget()
            holder.setLayout(row)
            row.setContentsMargins(0, 0, 0, 0)
            label = QLabel(spec.label)
            label.setToolTip(spec.help)
            self.form.addRow(label, holder)

    def _make_presets(self, spec: ParameterSpec) -> QComboBox:
        presets = QComboBox()
        presets.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        presets.setMinimumContentsLength(8)
        presets.addItem("Presets…", None)
        for label, value in spec.presets:
            presets.addItem(f"{label}  ({value:.4g} {unit_symbol(spec.unit)})", value)

        def chosen(index: int) -> None:
            value = presets.itemData(index)
            if value is not None:
                self.parameterChanged.emit(spec.name, value)
            presets.setCurrentIndex(0)

        presets.activated.connect(chosen)
        return presets

    def _make_control(self, spec: ParameterSpec) -> QWidget:
        if spec.kind == "bool":
            box = QCheckBox()
            box.setChecked(bool(spec.default))
            box.toggled.connect(lambda on, n=spec.name: self.parameterChanged.emit(n, on))
            return box
        if spec.kind == "int":
            spin = QSpinBox()
            spin.setRange(int(spec.minimum), int(spec.maximum))
            spin.setValue(int(spec.default))
        elif spec.log_scale and spec.maximum / max(spec.minimum, 1e-300) > 1e5:
            spin = ScientificSpinBox()
            spin.setRange(spec.minimum, spec.maximum)
            spin.setValue(spec.default)
        else:
            spin = QDoubleSpinBox()
            spin.setDecimals(_decimals_for(spec))
            spin.setRange(spec.minimum, spec.maximum)
            spin.setValue(spec.default)
            if spec.log_scale:
                spin.setStepType(QDoubleSpinBox.StepType.AdaptiveDecimalStepType)
        if spec.unit:
            spin.setSuffix(f" {unit_symbol(spec.unit)}")
        spin.setKeyboardTracking(False)
        spin.valueChanged.connect(lambda v, n=spec.name: self.parameterChanged.emit(n, v))
        return spin
