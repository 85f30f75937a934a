"""The Measurement log panel: stored readings in an editable table (app/core/measurement_log.py).

*Store* (or Space anywhere in the window) asks ``reading_source`` for the current reading and
appends it with the label typed beside the button (a reading that was not steady is stored
flagged: the panel says so, and its row carries a warning sign, an amber text and the reason
as a tooltip); labels are edited in the table, rows
deleted with Delete, copied with Ctrl+C (tab-separated, for a spreadsheet) and the whole log
exported as CSV.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from PySide6.QtCore import QEvent, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QGuiApplication, QKeyEvent, QKeySequence
from PySide6.QtWidgets import (
    QAbstractItemView,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QSizePolicy,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.core.measurement_log import Measurement, MeasurementLog
from app.gui import theme
from app.gui.file_dialogs import save_file_name

UNIT_SUFFIX = {"deg": "°", "percent": " %", "mm/m": " mm/m"}
HEADERS = ("Time", "Label", "Roll", "Pitch", "Tilt", "Direction", "Heading", "Window",
           "Filter", "Calibration", "Device")
LABEL_COLUMN = 1
LABEL_WIDTH_PX = 200


def _angle(value: float, spread: float, unit: str) -> str:
    suffix = UNIT_SUFFIX.get(unit, f" {unit}")
    return f"{value:+.3f} ± {spread:.3f}{suffix}"


def _heading(entry: Measurement) -> str:
    """``123.4 ± 0.2° true``, ``2187 ± 3 mil magnetic``; a dash without a heading."""
    if not math.isfinite(entry.heading):
        return "—"
    if entry.heading_unit == "mil":
        return f"{entry.heading:.0f} ± {entry.heading_std:.0f} mil {entry.heading_north}"
    return f"{entry.heading:.1f} ± {entry.heading_std:.1f}° {entry.heading_north}"


class _LogTable(QTableWidget):
    """A table that keeps Ctrl+C and Delete for itself while it has the focus (a window-wide
    shortcut on the same keys would otherwise take them)."""

    copyRequested = Signal()
    deleteRequested = Signal()

    def event(self, event: QEvent) -> bool:
        if event.type() == QEvent.Type.ShortcutOverride and isinstance(event, QKeyEvent) and (
            event.matches(QKeySequence.StandardKey.Copy)
            or event.key() in (Qt.Key.Key_Delete, Qt.Key.Key_Backspace)
        ) and self.state() != QAbstractItemView.State.EditingState:
            event.accept()
            return True
        return super().event(event)

    def keyPressEvent(self, event: QKeyEvent) -> None:
        if self.state() != QAbstractItemView.State.EditingState:
            if event.matches(QKeySequence.StandardKey.Copy):
                self.copyRequested.emit()
                return
            if event.key() in (Qt.Key.Key_Delete, Qt.Key.Key_Backspace):
                self.deleteRequested.emit()
                return
        super().keyPressEvent(event)


class MeasurementLogPanel(QWidget):
    """The stored readings; ``problem(str)`` for whatever the user must be told."""

    problem = Signal(str)

    def __init__(self, log: MeasurementLog,
                 reading_source: Callable[[str], Measurement | None],
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.log = log
        self.reading_source = reading_source
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 2, 4, 4)
        bar = QHBoxLayout()
        self.store_button = QPushButton("Store reading")
        self.store_button.setToolTip("Store the reading the readouts show: mean and standard "
                                     "deviation over the averaging time (Space)")
        self.store_button.clicked.connect(lambda: self.store())
        self.label_edit = QLineEdit()
        self.label_edit.setPlaceholderText("label for the next reading (e.g. the spot)")
        self.label_edit.returnPressed.connect(lambda: self.store())
        self.delete_button = QPushButton("Delete")
        self.delete_button.setToolTip("Delete the selected rows (Delete)")
        self.delete_button.clicked.connect(self.delete_selected)
        self.copy_button = QPushButton("Copy")
        self.copy_button.setToolTip("Copy the selected rows, or all, tab-separated for a "
                                    "spreadsheet (Ctrl+C in the table)")
        self.copy_button.clicked.connect(self.copy_to_clipboard)
        self.export_button = QPushButton("Export CSV…")
        self.export_button.clicked.connect(lambda: self.export_csv())
        bar.addWidget(self.store_button)
        bar.addWidget(self.label_edit, 1)
        for button in (self.delete_button, self.copy_button, self.export_button):
            bar.addWidget(button)
        layout.addLayout(bar)
        self.table = _LogTable(0, len(HEADERS))
        self.table.setHorizontalHeaderLabels(HEADERS)
        self.table.horizontalHeaderItem(HEADERS.index("Window")).setToolTip(
            "Averaging time · samples averaged")
        self.table.verticalHeader().setVisible(False)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.DoubleClicked
                                   | QAbstractItemView.EditTrigger.EditKeyPressed
                                   | QAbstractItemView.EditTrigger.AnyKeyPressed)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(LABEL_COLUMN, QHeaderView.ResizeMode.Interactive)
        header.setSectionResizeMode(len(HEADERS) - 1, QHeaderView.ResizeMode.Stretch)
        self.table.setColumnWidth(LABEL_COLUMN, LABEL_WIDTH_PX)
        self.table.itemChanged.connect(self._on_item_changed)
        self.table.copyRequested.connect(self.copy_to_clipboard)
        self.table.deleteRequested.connect(self.delete_selected)
        layout.addWidget(self.table, 1)
        self.note = QLabel()
        self.note.setObjectName("dimLabel")
        # Long paths must not widen the dock (and squeeze the rest of the window).
        self.note.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        layout.addWidget(self.note)
        self._refill()

    # -- actions ----------------------------------------------------------------------------
    def store(self, label: str | None = None) -> Measurement | None:
        """Store the current reading with ``label`` (default: the label field); None (and a
        message) when there is no reading."""
        text = self.label_edit.text().strip() if label is None else label
        reading = self.reading_source(text or f"#{len(self.log) + 1}")
        if reading is None:
            self.problem.emit("No reading to store: connect a device first.")
            return None
        try:
            self.log.add(reading)
        except OSError as exc:
            self.problem.emit(f"The reading is in the table but the log could not be saved "
                              f"to {self.log.path}: {exc}")
        self.label_edit.clear()
        self._refill()
        self.table.scrollToBottom()
        if reading.warning:
            self.note.setText(f"⚠ Stored, flagged: {reading.warning}.")
            self.note.setStyleSheet(f"color: {theme.WARN_AMBER}; font-weight: bold;")
        return reading

    def delete_selected(self) -> None:
        rows = self._selected_rows()
        if rows:
            self._save(lambda: self.log.remove(rows))
            self._refill()

    def copy_to_clipboard(self) -> str:
        """Copy the selected rows (all when none is selected), with a header line, as
        tab-separated text; returns it."""
        rows = self._selected_rows() or None
        text = self.log.csv_text("\t", rows)
        QGuiApplication.clipboard().setText(text)
        count = len(self.log) if rows is None else len(rows)
        self.note.setText(f"Copied {count} reading(s) to the clipboard.")
        return text

    def export_csv(self, path: str | None = None) -> None:
        if path is None:
            path, _ = save_file_name(self, "Export the measurement log", "measurements.csv",
                                     "CSV (*.csv)")
            if not path:
                return
        try:
            self.log.export_csv(path)
        except OSError as exc:
            self.problem.emit(f"The log was not exported: {exc}")
            return
        self.note.setText(f"Exported {len(self.log)} reading(s) to {path}.")

    # -- internals --------------------------------------------------------------------------
    def _save(self, change: Callable[[], None]) -> None:
        try:
            change()
        except OSError as exc:
            self.problem.emit(f"The measurement log could not be saved to {self.log.path}: "
                              f"{exc}")

    def _selected_rows(self) -> list[int]:
        return sorted({index.row() for index in self.table.selectionModel().selectedRows()})

    def _on_item_changed(self, item: QTableWidgetItem) -> None:
        row = item.row()
        if (item.column() == LABEL_COLUMN and 0 <= row < len(self.log)
                and item.text() != self.log.entries[row].label):
            self._save(lambda: self.log.set_label(row, item.text()))

    def _refill(self) -> None:
        self.table.blockSignals(True)
        try:
            self.table.setRowCount(len(self.log))
            for r, entry in enumerate(self.log.entries):
                mark = "⚠ " if entry.flagged else ""
                texts = (
                    mark + entry.time.replace("T", " ")[:19], entry.label,
                    _angle(entry.roll, entry.roll_std, entry.unit),
                    _angle(entry.pitch, entry.pitch_std, entry.unit),
                    _angle(entry.tilt, entry.tilt_std, entry.unit),
                    f"{entry.direction_deg:.1f}°", _heading(entry),
                    f"{entry.window_s:g} s · {entry.samples}",
                    entry.filter, entry.calibration, entry.device.split(" (")[0],
                )
                for c, text in enumerate(texts):
                    item = QTableWidgetItem(text)
                    if c != LABEL_COLUMN:
                        item.setFlags(item.flags() & ~Qt.ItemFlag.ItemIsEditable)
                    if c == len(texts) - 1:
                        item.setToolTip(entry.device)
                    if entry.flagged:
                        item.setForeground(QBrush(QColor(theme.WARN_AMBER)))
                        if c != len(texts) - 1:
                            item.setToolTip(entry.warning)
                    if 2 <= c <= 7:
                        item.setTextAlignment(Qt.AlignmentFlag.AlignRight
                                              | Qt.AlignmentFlag.AlignVCenter)
                    self.table.setItem(r, c, item)
        finally:
            self.table.blockSignals(False)
        self.note.setStyleSheet("")
        where = f" · saved in {self.log.path}" if self.log.path else " · not saved"
        self.note.setText(f"{len(self.log)} reading(s){where}. Mean ± standard deviation "
                          "over the averaging time.")
