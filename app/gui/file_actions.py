"""The File menu's work: open a recording (it becomes the device), export the plots, export a
recording for other tools (MCAP, EuRoC/Kalibr), record.

Every dialog goes through :mod:`app.gui.file_dialogs` (it starts where the user last was).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from app.gui import file_dialogs
from app.services.devices import knows_truth_url, replay_url
from app.services.recording_control import recording_cost

MainWindow = Any
"""The window this part works for (not imported: the parts sit below
:mod:`app.gui.main_window`, which assembles them)."""

RECORDING_FILTER = "Recordings (*.csv)"
COMPRESSED_RECORDING_FILTER = "Compressed recordings (*.csv.gz)"


def recordings_dir() -> Path:
    """Where recordings go by default: the user's documents folder."""
    from platformdirs import user_documents_dir

    return Path(user_documents_dir()) / "Inclinometer recordings"


class FileActions:
    """Open, export and record for ``window``."""

    def __init__(self, window: MainWindow) -> None:
        self.window = window

    def open_recording(self, path: str | None = None) -> None:
        """Replay a recording through the whole pipeline (it becomes the device)."""
        if path is None:
            path = file_dialogs.open_file_name(
                self.window, "Open recording", "Recordings (*.csv *.csv.gz);;All files (*)",
                recordings_dir())
            if not path:
                return
        self.window.connect_device(replay_url(path))

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

    def show_recording(self, status) -> None:
        """The worker's recording status: the Record action and the status bar."""
        self.window.record_action.setChecked(
            status is not None and status.state == "recording")
        self.window.status_view.show_recording(status)
