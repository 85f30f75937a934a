"""The compass's controls: magnetic or true north, degrees or mils, and the declination (from
the World Magnetic Model at a place and date, or typed in). The settings are
:class:`app.core.heading.HeadingSettings`, kept in the ``heading`` settings section and handed
to the session, which stores the declination with each recording."""

from __future__ import annotations

from datetime import date

from PySide6.QtCore import QDate, QObject, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QDateEdit,
    QDialog,
    QDialogButtonBox,
    QDoubleSpinBox,
    QFormLayout,
    QGridLayout,
    QLabel,
    QPushButton,
    QRadioButton,
    QVBoxLayout,
    QWidget,
)

from app.core.earth_field import DEFAULT_PLACE, Place
from app.core.heading import (
    HEADING_UNITS,
    Declination,
    HeadingSettings,
    typed_declination,
    wmm_declination,
)


class HeadingBar(QWidget):
    """North, unit and the declination button, under the compass."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.north_combo = QComboBox()
        self.north_combo.addItem("magnetic N", "magnetic")
        self.north_combo.addItem("true N", "true")
        self.north_combo.setToolTip("Heading from magnetic north, or true north (magnetic + "
                                    "declination)")
        self.unit_combo = QComboBox()
        for unit in HEADING_UNITS.values():
            self.unit_combo.addItem("°" if unit.key == "deg" else unit.suffix, unit.key)
        self.unit_combo.setToolTip("Heading in degrees or NATO mils (6400 to the circle)")
        self.declination_button = QPushButton("Decl…")
        self.declination_button.setToolTip("Set the magnetic declination (WMM or typed)")
        # Two rows: the compass column stays narrow (it must fit beside the bubble at 1366).
        layout = QGridLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(4)
        layout.addWidget(self.north_combo, 0, 0)
        layout.addWidget(self.unit_combo, 0, 1)
        layout.addWidget(self.declination_button, 1, 0, 1, 2)
        for combo in (self.north_combo, self.unit_combo):  # never narrower than their words
            widest = max(combo.fontMetrics().horizontalAdvance(combo.itemText(i))
                         for i in range(combo.count()))
            combo.setMinimumWidth(max(combo.sizeHint().width(), widest + 44))

    def show_settings(self, settings: HeadingSettings) -> None:
        for combo, value in ((self.north_combo, settings.north), (self.unit_combo, settings.unit)):
            combo.blockSignals(True)
            combo.setCurrentIndex(combo.findData(value))
            combo.blockSignals(False)
        declination = settings.declination
        self.declination_button.setToolTip(
            "Magnetic declination: " + ("not set" if declination is None
                                        else declination.describe()))


class DeclinationDialog(QDialog):
    """Ask for the declination: the World Magnetic Model's at a place and date, or typed."""

    def __init__(self, current: Declination | None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Magnetic declination")
        self.wmm = QRadioButton("From the World Magnetic Model")
        self.typed = QRadioButton("Typed in")
        place = current.place if current is not None and current.place else DEFAULT_PLACE
        when = current.when if current is not None and current.when else date.today()
        self.latitude = self._spin(-90.0, 90.0, 4, "°N", place.latitude_deg)
        self.longitude = self._spin(-180.0, 360.0, 4, "°E", place.longitude_deg)
        self.altitude = self._spin(-1000.0, 850_000.0, 0, " m", place.altitude_m)
        self.date = QDateEdit(QDate(when.year, when.month, when.day))
        self.date.setCalendarPopup(True)
        self.date.setDisplayFormat("yyyy-MM-dd")
        self.degrees = self._spin(-180.0, 180.0, 2, "° (east +)",
                                  0.0 if current is None else current.declination_deg)
        (self.typed if current is not None and current.source == "typed" else self.wmm
         ).setChecked(True)
        self.problem = QLabel("")
        self.problem.setWordWrap(True)
        form = QFormLayout()
        form.addRow(self.wmm)
        form.addRow("Latitude", self.latitude)
        form.addRow("Longitude", self.longitude)
        form.addRow("Altitude", self.altitude)
        form.addRow("Date", self.date)
        form.addRow(self.typed)
        form.addRow("Declination", self.degrees)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok
                                   | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(self.problem)
        layout.addWidget(buttons)
        self.result_declination: Declination | None = None

    @staticmethod
    def _spin(low: float, high: float, decimals: int, suffix: str, value: float
              ) -> QDoubleSpinBox:
        spin = QDoubleSpinBox()
        spin.setRange(low, high)
        spin.setDecimals(decimals)
        spin.setSuffix(suffix)
        spin.setValue(value)
        return spin

    def declination(self) -> Declination:
        """What the fields say (ValueError for a place or date the model refuses)."""
        if self.typed.isChecked():
            return typed_declination(self.degrees.value())
        qdate = self.date.date()
        place = Place(self.latitude.value(), self.longitude.value(), self.altitude.value())
        return wmm_declination(place, date(qdate.year(), qdate.month(), qdate.day()))

    def accept(self) -> None:
        try:
            self.result_declination = self.declination()
        except ValueError as exc:
            self.problem.setText(str(exc))
            return
        super().accept()


class HeadingControls(QObject):
    """Keeps the heading settings and hands them on: to the compass's feed
    (``settingsChanged``) and the declination to the session (``declinationChanged``)."""

    settingsChanged = Signal(object)  # HeadingSettings
    declinationChanged = Signal(object)  # Declination or None

    def __init__(self, bar: HeadingBar, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.bar = bar
        self.settings = HeadingSettings()
        self.ask = self._ask  # tests replace the dialog
        bar.north_combo.currentIndexChanged.connect(lambda _i: self._on_north())
        bar.unit_combo.currentIndexChanged.connect(lambda _i: self._on_unit())
        bar.declination_button.clicked.connect(self.edit_declination)
        bar.show_settings(self.settings)

    # -- settings (a section of the user settings) ----------------------------------------------
    def settings_dict(self) -> dict:
        return self.settings.to_dict()

    def apply_settings(self, stored: dict) -> None:
        """Stored settings (ValueError when not valid: the caller reports it)."""
        self.use(HeadingSettings.from_dict(stored))

    def use(self, settings: HeadingSettings) -> None:
        declination_changed = settings.declination != self.settings.declination
        self.settings = settings
        self.bar.show_settings(settings)
        self.settingsChanged.emit(settings)
        if declination_changed:
            self.declinationChanged.emit(settings.declination)

    # -- the controls ---------------------------------------------------------------------------
    def _on_north(self) -> None:
        north = self.bar.north_combo.currentData()
        declination = self.settings.declination
        if north == "true" and declination is None:
            declination = self.ask(None)
            if declination is None:  # cancelled: still magnetic
                self.bar.show_settings(self.settings)
                return
        self.use(HeadingSettings(north, self.settings.unit, declination))

    def _on_unit(self) -> None:
        self.use(HeadingSettings(self.settings.north, self.bar.unit_combo.currentData(),
                                 self.settings.declination))

    def edit_declination(self) -> None:
        declination = self.ask(self.settings.declination)
        if declination is not None:
            self.use(HeadingSettings(self.settings.north, self.settings.unit, declination))

    def _ask(self, current: Declination | None) -> Declination | None:
        dialog = DeclinationDialog(current, self.bar.window())
        if dialog.exec() == QDialog.DialogCode.Accepted:
            return dialog.result_declination
        return None
