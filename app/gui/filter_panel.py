"""The filter panel: choose the orientation filter and edit its parameters.

Controls are built from each filter's :class:`~app.core.filters.ParameterSpec` schema, so a
new filter needs no GUI code.
"""

from __future__ import annotations

import math
from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from app.core.filters import FILTERS, ParameterSpec


def _decimals_for(spec: ParameterSpec) -> int:
    smallest = spec.minimum if spec.minimum > 0 else max(spec.default, 1e-3)
    return min(6, max(1, -math.floor(math.log10(abs(smallest))) + 1)) if smallest else 3


class FilterPanel(QWidget):
    """Filter chooser plus a form of parameter controls."""

    filterRequested = Signal(str)
    parameterChanged = Signal(str, object)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        self.combo = QComboBox()
        for name, cls in FILTERS.items():
            self.combo.addItem(cls.title, name)
            tooltip = Qt.ItemDataRole.ToolTipRole
            self.combo.setItemData(self.combo.count() - 1, cls.description, tooltip)
        self.combo.activated.connect(self._on_activated)
        layout.addWidget(self.combo)
        self.description = QLabel()
        self.description.setWordWrap(True)
        self.description.setObjectName("dimLabel")
        layout.addWidget(self.description)
        self.form_host = QWidget()
        self.form = QFormLayout(self.form_host)
        self.form.setContentsMargins(0, 4, 0, 0)
        layout.addWidget(self.form_host)
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
        self.description.setText(cls.description)
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

    def _on_activated(self, index: int) -> None:
        name = self.combo.itemData(index)
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
            presets.addItem(f"{label}  ({value:.4g} {spec.unit})", value)

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
        else:
            spin = QDoubleSpinBox()
            spin.setDecimals(_decimals_for(spec))
            spin.setRange(spec.minimum, spec.maximum)
            spin.setValue(spec.default)
            if spec.log_scale:
                spin.setStepType(QDoubleSpinBox.StepType.AdaptiveDecimalStepType)
        if spec.unit:
            spin.setSuffix(f" {spec.unit}")
        spin.setKeyboardTracking(False)
        spin.valueChanged.connect(lambda v, n=spec.name: self.parameterChanged.emit(n, v))
        return spin
