"""The simulator panel: pick a motion scenario and sensor settings, tilt the virtual sensor."""

from __future__ import annotations

from urllib.parse import urlsplit

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QLabel,
    QPushButton,
    QSlider,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from app.core.devices import DeviceDescriptor
from app.services.devices import SENSOR_CHOICES, SimulatorSettings

SLIDER_STEPS_PER_DEG = 10


class SimulatorPanel(QWidget):
    """Builds ``sim://`` URLs and sends attitude targets to an interactive simulator."""

    deviceRequested = Signal(str)
    targetChanged = Signal(float, float)  # roll, pitch in degrees

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)

        setup = QGroupBox("Simulated LSM6DSOX")
        form = QFormLayout(setup)
        self.scenario_combo = QComboBox()
        self.scenario_combo.currentIndexChanged.connect(self._scenario_chosen)
        form.addRow("Motion", self.scenario_combo)
        self.odr_combo = QComboBox()
        for odr in SENSOR_CHOICES.odr_hz:
            self.odr_combo.addItem(f"{odr:g} Hz", odr)
        self.odr_combo.setCurrentIndex(self.odr_combo.findData(104.0))
        form.addRow("Data rate", self.odr_combo)
        self.accel_fs_combo = QComboBox()
        for fs in SENSOR_CHOICES.accel_fs_g:
            self.accel_fs_combo.addItem(f"±{fs} g", fs)
        self.accel_fs_combo.setCurrentIndex(self.accel_fs_combo.findData(4))
        form.addRow("Accel range", self.accel_fs_combo)
        self.gyro_fs_combo = QComboBox()
        for fs in SENSOR_CHOICES.gyro_fs_dps:
            self.gyro_fs_combo.addItem(f"±{fs} °/s", fs)
        self.gyro_fs_combo.setCurrentIndex(self.gyro_fs_combo.findData(250))
        form.addRow("Gyro range", self.gyro_fs_combo)
        self.seed_spin = QSpinBox()
        self.seed_spin.setRange(0, 999_999)
        self.seed_spin.setValue(1)
        self.seed_spin.setToolTip("The seed picks the simulated unit: its errors and its id")
        form.addRow("Unit (seed)", self.seed_spin)
        self.apply_button = QPushButton("Start simulator")
        self.apply_button.clicked.connect(lambda: self.deviceRequested.emit(self.url()))
        form.addRow(self.apply_button)
        layout.addWidget(setup)

        self.tilt_group = QGroupBox("Tilt the virtual sensor")
        grid = QGridLayout(self.tilt_group)
        self.roll_slider, self.roll_spin = self._axis_controls(180.0)
        self.pitch_slider, self.pitch_spin = self._axis_controls(90.0)
        grid.addWidget(QLabel("Roll"), 0, 0)
        grid.addWidget(self.roll_slider, 0, 1)
        grid.addWidget(self.roll_spin, 0, 2)
        grid.addWidget(QLabel("Pitch"), 1, 0)
        grid.addWidget(self.pitch_slider, 1, 1)
        grid.addWidget(self.pitch_spin, 1, 2)
        self.level_button = QPushButton("Level")
        self.level_button.setToolTip("Put the virtual sensor back flat")
        self.level_button.clicked.connect(lambda: self.set_target(0.0, 0.0, emit=True))
        grid.addWidget(self.level_button, 2, 2)
        self.tilt_hint = QLabel("Choose the 'interactive' motion to tilt the sensor by hand.")
        self.tilt_hint.setObjectName("dimLabel")
        self.tilt_hint.setWordWrap(True)
        grid.addWidget(self.tilt_hint, 3, 0, 1, 3)
        layout.addWidget(self.tilt_group)
        layout.addStretch(1)
        self.set_interactive(False)

    def _axis_controls(self, limit_deg: float) -> tuple[QSlider, QDoubleSpinBox]:
        slider = QSlider(Qt.Orientation.Horizontal)
        steps = int(limit_deg * SLIDER_STEPS_PER_DEG)
        slider.setRange(-steps, steps)
        spin = QDoubleSpinBox()
        spin.setRange(-limit_deg, limit_deg)
        spin.setDecimals(1)
        spin.setSuffix(" °")
        spin.setKeyboardTracking(False)
        slider.valueChanged.connect(lambda v, s=spin: self._slider_moved(s, v))
        spin.valueChanged.connect(lambda v, sl=slider: self._spin_changed(sl, v))
        return slider, spin

    def _slider_moved(self, spin: QDoubleSpinBox, value: int) -> None:
        spin.blockSignals(True)
        spin.setValue(value / SLIDER_STEPS_PER_DEG)
        spin.blockSignals(False)
        self._emit_target()

    def _spin_changed(self, slider: QSlider, value: float) -> None:
        slider.blockSignals(True)
        slider.setValue(round(value * SLIDER_STEPS_PER_DEG))
        slider.blockSignals(False)
        self._emit_target()

    def _emit_target(self) -> None:
        self.targetChanged.emit(self.roll_spin.value(), self.pitch_spin.value())

    # -- public -----------------------------------------------------------------------------
    def set_scenarios(self, simulators: list[DeviceDescriptor]) -> None:
        """List the simulator's scenarios (descriptors of kind ``simulator``)."""
        self.scenario_combo.clear()
        for descriptor in simulators:
            if urlsplit(descriptor.url).query:  # a variant (e.g. with a magnetometer), not a motion
                continue
            scenario = urlsplit(descriptor.url).netloc
            self.scenario_combo.addItem(scenario, scenario)
            self.scenario_combo.setItemData(
                self.scenario_combo.count() - 1, descriptor.description,
                Qt.ItemDataRole.ToolTipRole,
            )

    def settings(self) -> SimulatorSettings:
        """The chosen settings."""
        return SimulatorSettings(
            scenario=str(self.scenario_combo.currentData()),
            odr_hz=float(self.odr_combo.currentData()),
            accel_fs_g=int(self.accel_fs_combo.currentData()),
            gyro_fs_dps=int(self.gyro_fs_combo.currentData()),
            seed=self.seed_spin.value(),
            roll_deg=self.roll_spin.value(), pitch_deg=self.pitch_spin.value(),
        )

    def url(self) -> str:
        """The ``sim://`` URL for the chosen settings."""
        return self.settings().url()

    def _scenario_chosen(self, index: int) -> None:
        """A motion was picked: offer the full scales it needs (a hand-held motion turns
        faster than ±250 °/s and would clip)."""
        scenario = self.scenario_combo.itemData(index)
        if scenario is None:
            return
        defaults = SimulatorSettings.defaults(str(scenario))
        self._select(self.accel_fs_combo, defaults.accel_fs_g)
        self._select(self.gyro_fs_combo, defaults.gyro_fs_dps)

    @staticmethod
    def _select(combo: QComboBox, value: object) -> None:
        found = combo.findData(value)
        if found >= 0:
            combo.setCurrentIndex(found)

    def show_url(self, url: str) -> None:
        """Reflect a connected ``sim://`` URL in the controls."""
        settings = SimulatorSettings.from_url(url)
        if settings is None:
            self.set_interactive(False)
            return
        self._select(self.scenario_combo, settings.scenario)
        self._select(self.odr_combo, settings.odr_hz)
        self._select(self.accel_fs_combo, settings.accel_fs_g)
        self._select(self.gyro_fs_combo, settings.gyro_fs_dps)
        self.seed_spin.setValue(min(settings.seed, self.seed_spin.maximum()))
        self.set_interactive(settings.scenario == "interactive")

    def set_interactive(self, enabled: bool) -> None:
        for widget in (self.roll_slider, self.roll_spin, self.pitch_slider, self.pitch_spin,
                       self.level_button):
            widget.setEnabled(enabled)
        self.tilt_hint.setVisible(not enabled)

    def set_target(self, roll_deg: float, pitch_deg: float, emit: bool = False) -> None:
        for spin, value in ((self.roll_spin, roll_deg), (self.pitch_spin, pitch_deg)):
            spin.blockSignals(True)
            spin.setValue(value)
            spin.blockSignals(False)
        for slider, value in ((self.roll_slider, roll_deg), (self.pitch_slider, pitch_deg)):
            slider.blockSignals(True)
            slider.setValue(round(value * SLIDER_STEPS_PER_DEG))
            slider.blockSignals(False)
        if emit:
            self._emit_target()
