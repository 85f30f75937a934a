"""File > Export recording: a recording as MCAP (Foxglove, ROS 2) or EuRoC/Kalibr CSV.

The dialog only gathers the choices (recording, format, axis convention, target) and shows
the result; :class:`app.services.export_job.ExportJob` runs the export off the GUI thread.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from app.core.interop.euroc import readme_path
from app.core.interop.frames import DESCRIPTIONS
from app.gui import file_dialogs
from app.services.export_job import ExportJob
from app.services.interop_export import ExportRequest, ExportSummary

FORMAT_CHOICES = (
    ("mcap", "MCAP: sensor_msgs/Imu + MagneticField (Foxglove, ROS 2)", ".mcap"),
    ("euroc", "EuRoC/Kalibr CSV: imu0.csv (Kalibr's bag creator)", ".csv"),
)
FRAME_CHOICES = (("enu", "ENU (ROS REP 103)"), ("ned", "NED (north-east-down)"))


class ExportDialog(QDialog):
    """Choose and run an export; ``exported(summary)`` when one is written."""

    def __init__(self, parent: QWidget | None = None, source: str | Path | None = None,
                 folder: Path | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Export recording")
        self.folder = folder
        self.job = ExportJob(self)
        self.job.finished.connect(self._finished)
        self.job.failed.connect(self._failed)
        self.job.warned.connect(self._warned)
        self.summary: ExportSummary | None = None
        self.warnings: list[str] = []
        layout = QVBoxLayout(self)
        form = QFormLayout()
        self.source_edit = QLineEdit(str(source) if source else "")
        self.source_edit.setPlaceholderText("a recording (.csv, .csv.gz)")
        form.addRow("Recording:", self._with_button(self.source_edit, self._choose_source))
        self.format_combo = QComboBox()
        for key, title, _ in FORMAT_CHOICES:
            self.format_combo.addItem(title, key)
        form.addRow("Format:", self.format_combo)
        self.frame_combo = QComboBox()
        for key, title in FRAME_CHOICES:
            self.frame_combo.addItem(title, key)
        form.addRow("Axes:", self.frame_combo)
        self.target_edit = QLineEdit()
        form.addRow("Save as:", self._with_button(self.target_edit, self._choose_target))
        self.replace_box = QCheckBox("Replace existing files")
        form.addRow("", self.replace_box)
        layout.addLayout(form)
        self.note = QLabel()
        self.note.setWordWrap(True)
        self.note.setObjectName("dimLabel")
        layout.addWidget(self.note)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        layout.addWidget(self.status)
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close)
        self.export_button = self.buttons.addButton(
            "Export", QDialogButtonBox.ButtonRole.ActionRole)
        self.export_button.clicked.connect(self.start_export)
        self.buttons.rejected.connect(self.reject)
        layout.addWidget(self.buttons)
        self.format_combo.currentIndexChanged.connect(self._format_changed)
        self.frame_combo.currentIndexChanged.connect(self._update_note)
        self.source_edit.editingFinished.connect(lambda: self._format_changed(suggest=True))
        self._format_changed()
        self.adjustSize()
        self.resize(max(640, self.width()), self.sizeHint().height())

    def _with_button(self, edit: QLineEdit, action) -> QWidget:
        row = QWidget()
        box = QHBoxLayout(row)
        box.setContentsMargins(0, 0, 0, 0)
        box.addWidget(edit, 1)
        button = QPushButton("Browse…")
        button.clicked.connect(action)
        box.addWidget(button)
        return row

    @property
    def format(self) -> str:
        return str(self.format_combo.currentData())

    @property
    def frame(self) -> str:
        return str(self.frame_combo.currentData())

    def _suggested_target(self) -> str:
        source = Path(self.source_edit.text().strip())
        if not self.source_edit.text().strip():
            return ""
        if self.format == "euroc":
            return str(source.with_name("imu0.csv"))
        stem = source.name.removesuffix(".gz").removesuffix(".csv")
        return str(source.with_name(f"{stem}.mcap"))

    def _format_changed(self, *_: object, suggest: bool = True) -> None:
        if suggest:
            self.target_edit.setText(self._suggested_target())
        self._update_note()

    def _update_note(self, *_: object) -> None:
        what = ("Orientation from the recording's filter, run over it as Replay does; "
                "magnetic field in tesla when recorded; the recording's metadata and these "
                "conventions in MCAP metadata records." if self.format == "mcap" else
                "Integer nanoseconds, rad/s, m/s²; the conventions go in a README beside it "
                "(Kalibr's bag creator reads files named imu*.csv and skips the others).")
        self.note.setText(f"{what} Axes: {DESCRIPTIONS[self.frame]}. Timestamps: the "
                          "recording's t (device clock) in nanoseconds.")

    def set_source(self, path: str | Path) -> None:
        """Export this recording (the target is suggested anew)."""
        self.source_edit.setText(str(path))
        self._format_changed()

    def _choose_source(self) -> None:
        path = file_dialogs.open_file_name(
            self, "Recording to export", "Recordings (*.csv *.csv.gz);;All files (*)",
            self.folder)
        if path:
            self.set_source(path)

    def _choose_target(self) -> None:
        suffix = dict((k, s) for k, _, s in FORMAT_CHOICES)[self.format]
        suggested = self.target_edit.text() or f"export{suffix}"
        path, _ = file_dialogs.save_file_name(
            self, "Export to", Path(suggested).name, f"*{suffix}", self.folder)
        if path:
            self.target_edit.setText(path)
            self.replace_box.setChecked(Path(path).exists())  # the dialog asked already

    def request(self) -> ExportRequest | None:
        """The export the fields describe; None (and a message) when one is missing."""
        source, target = self.source_edit.text().strip(), self.target_edit.text().strip()
        if not source or not target:
            self.status.setText("Choose a recording and where to save the export.")
            return None
        return ExportRequest(Path(source), Path(target), self.format, frame=self.frame,
                             overwrite=self.replace_box.isChecked())

    def start_export(self) -> bool:
        """Start the export in the background; False when the fields are incomplete."""
        request = self.request()
        if request is None or not self.job.start(request):
            return False
        self.summary, self.warnings = None, []
        self.export_button.setEnabled(False)
        self.status.setText(f"Exporting {request.source.name}…")
        return True

    def _finished(self, summary: ExportSummary) -> None:
        self.summary = summary
        self.export_button.setEnabled(True)
        what = (f"{summary.rows} Imu and {summary.mag_rows} MagneticField messages"
                if summary.format == "mcap" else f"{summary.rows} samples")
        extra = (f" and {readme_path(summary.target).name}" if summary.format == "euroc"
                 else "")
        self.status.setText(f"Wrote {summary.target.name}{extra}: {what}, "
                            f"{summary.duration_s:.1f} s, {summary.frame.upper()}."
                            + (f" {len(self.warnings)} warning(s): {self.warnings[0]}"
                               if self.warnings else ""))

    def _failed(self, message: str) -> None:
        self.export_button.setEnabled(True)
        self.status.setText(f"Not exported: {message}")

    def _warned(self, message: str) -> None:
        self.warnings.append(message)
