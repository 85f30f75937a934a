"""The File menu's work: open a recording (it becomes the device), export the plots, export a
recording for other tools (MCAP, EuRoC/Kalibr), record.

Every dialog goes through :mod:`app.gui.file_dialogs` (it starts where the user last was).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QApplication, QInputDialog

from app.core.interop.imported import ImportInputError
from app.gui import file_dialogs
from app.services.devices import knows_truth_url, replay_url
from app.services.import_replay import NeedsMagScale, NeedsMapping, replay_file
from app.services.recording_control import recording_cost

MainWindow = Any
"""The window this part works for (not imported: the parts sit below
:mod:`app.gui.main_window`, which assembles them)."""

RECORDING_FILTER = "Recordings (*.csv)"
COMPRESSED_RECORDING_FILTER = "Compressed recordings (*.csv.gz)"
GENERIC_EXAMPLE = ("t=time:s,ax=acc_x:g,ay=acc_y:g,az=acc_z:g,gx=gyro_x:dps,gy=gyro_y:dps,"
                   "gz=gyro_z:dps")


def recordings_dir() -> Path:
    """Where recordings go by default: the user's documents folder."""
    from platformdirs import user_documents_dir

    return Path(user_documents_dir()) / "Inclinometer recordings"


class FileActions:
    """Open, export and record for ``window``."""

    def __init__(self, window: MainWindow) -> None:
        self.window = window

    def open_recording(self, path: str | None = None, mapping: str = "",
                       mag_au_ut: float | None = None) -> None:
        """Replay a recording through the whole pipeline (it becomes the device). Another
        tool's file (x-IMU3's Inertial.csv, a EuRoC/Kalibr imu0.csv, another CSV through a
        column mapping asked for here) is imported into a recording first."""
        window = self.window
        if path is None:
            path = file_dialogs.open_file_name(
                window, "Open recording", "Recordings and IMU logs (*.csv *.csv.gz);;"
                "All files (*)", recordings_dir())
            if not path:
                return
        QApplication.setOverrideCursor(Qt.CursorShape.WaitCursor)
        try:
            opened = replay_file(path, mapping=mapping, mag_au_ut=mag_au_ut)
        except NeedsMagScale:
            QApplication.restoreOverrideCursor()
            field, ok = QInputDialog.getDouble(
                window, "x-IMU3 magnetometer",
                "Its magnetometer is in arbitrary units: 1 a.u. is the field where it was "
                "calibrated.\nThat field in µT (about 50; Cancel: leave the magnetometer out):",
                50.0, 1.0, 1000.0, 1)
            self.open_recording(path, mapping, field if ok else 0.0)
            return
        except NeedsMapping as need:
            QApplication.restoreOverrideCursor()
            spec = self.ask_mapping(Path(path).name, need.header)
            if spec:
                self.open_recording(path, spec)
            return
        except (ImportInputError, OSError) as exc:
            QApplication.restoreOverrideCursor()
            window.show_error(f"Not opened: {exc}")
            return
        QApplication.restoreOverrideCursor()
        for warning in opened.warnings:
            window.log(f"Import: {warning}")
        if opened.source_format != "recording":
            what = "Imported" if opened.imported_now else "Opening the earlier import of"
            window.log(f"{what} {opened.source_format} {path} as {opened.path}")
        window.connect_device(replay_url(str(opened.path)))

    def ask_mapping(self, name: str, header: list[str]) -> str:
        """The column mapping of a CSV this program does not know (empty: cancelled)."""
        columns = ", ".join(header)
        spec, ok = QInputDialog.getText(
            self.window, "Import CSV",
            f"{name} has the columns:\n{columns[:400]}\n\nMap them as TARGET=COLUMN:UNIT "
            "(t, ax..az and gx..gz required; units s/ms/us/ns, g or m/s2, dps or rad/s; "
            "mx..mz in uT, temp in degC optional; a leading - flips an axis):",
            text=GENERIC_EXAMPLE)
        return spec.strip() if ok else ""

    def export_plots(self, path: str | None = None) -> None:
        """Save the plots as they are shown: PNG (raster) or SVG (vector), by file suffix."""
        window = self.window
        if path is None:
            path, _ = file_dialogs.save_file_name(
                window, "Export plots", "inclinometer-plots.png",
                "PNG image (*.png);;SVG drawing (*.svg)", recordings_dir(),
            )
            if not path:
                return
        try:
            window.plots.export(path)
        except (OSError, ValueError) as exc:
            window.show_error(f"Plots not exported: {exc}")
            return
        window.log(f"Exported the plots to {path}")

    def export_recording(self, source: str | None = None) -> Any:
        """File ▸ Export recording: the dialog (MCAP or EuRoC/Kalibr, ENU or NED), on the
        recording being replayed when there is one. Returns the dialog (shown, not modal)."""
        from app.gui.export_dialog import ExportDialog
        from app.services.export_job import replayed_recording

        window = self.window
        if source is None:
            info = window.session.device_info
            playing = replayed_recording(info.url if info is not None else None)
            source = str(playing) if playing is not None else None
        dialog = getattr(window, "export_dialog", None)
        if dialog is None:
            dialog = ExportDialog(window, source, recordings_dir())
            dialog.job.finished.connect(
                lambda summary: window.log(f"Exported {summary.rows} samples to "
                                           f"{summary.target} ({summary.frame.upper()})"))
            window.export_dialog = dialog
        elif source and not dialog.job.running:
            dialog.set_source(source)
        dialog.show()
        dialog.raise_()
        return dialog

    def start_recording(self, path: str, note: str = "") -> None:
        self.window.session.requestStartRecording.emit(path, note)

    def record(self, checked: bool) -> None:
        """File ▸ Record: ask where (with what it will cost) and start; unchecked: stop."""
        window = self.window
        session = window.session
        if not checked:
            session.requestStopRecording.emit()
            return
        window.record_action.setChecked(False)  # until the worker says it records
        info = session.device_info
        if info is None:
            window.show_error("Connect a device before recording.")
            return
        folder = recordings_dir()
        folder.mkdir(parents=True, exist_ok=True)
        name = time.strftime("inclinometer-%Y%m%d-%H%M%S.csv")
        cost = recording_cost(folder, info.odr_hz, reference=knows_truth_url(info.url))
        path, chosen = file_dialogs.save_file_name(
            window, f"Record to ({cost})", name,
            f"{RECORDING_FILTER};;{COMPRESSED_RECORDING_FILTER}", folder,
        )
        if not path:
            return
        if chosen == COMPRESSED_RECORDING_FILTER and not path.lower().endswith(".gz"):
            path += ".gz"
        window.log(f"Recording to {path}: {cost}")
        self.start_recording(path)

    def show_lsl(self, streams: str) -> None:
        """The worker's LSL outlet: the action's check and a line in the log."""
        self.window.lsl_action.setChecked(bool(streams))
        self.window.log(streams or "LSL: off")

    def show_recording(self, status) -> None:
        """The worker's recording status: the Record action and the status bar."""
        self.window.record_action.setChecked(
            status is not None and status.state == "recording")
        self.window.status_view.show_recording(status)
