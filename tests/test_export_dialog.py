"""File > Export recording: the dialog runs the export off the GUI thread and shows the result."""

from __future__ import annotations

import os
import threading

import pytest
from PySide6.QtCore import QSettings

from app.cli import main
from app.core.interop.euroc import EUROC_HEADER, readme_path
from app.gui import theme
from app.gui.export_dialog import ExportDialog
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000


@pytest.fixture(scope="module")
def wobble_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("export-gui") / "wobble.csv"
    assert main(["record", "--device", "sim://wobble?odr=104&seed=2&realtime=0&mag=lis3mdl",
                 "--duration", "2s", str(path)]) == 0
    return path


def test_the_dialog_exports_euroc_in_ned_off_the_gui_thread(qtbot, qapp, wobble_csv, tmp_path,
                                                           artifacts_dir):
    theme.apply_theme(qapp)
    dialog = ExportDialog(None, wobble_csv, tmp_path)
    qtbot.addWidget(dialog)
    dialog.show()
    assert dialog.format == "mcap"
    assert dialog.target_edit.text() == str(wobble_csv.with_name("wobble.mcap"))
    dialog.format_combo.setCurrentIndex(dialog.format_combo.findData("euroc"))
    assert dialog.target_edit.text() == str(wobble_csv.with_name("imu0.csv"))
    dialog.frame_combo.setCurrentIndex(dialog.frame_combo.findData("ned"))
    assert "NED" in dialog.note.text() and "imu*.csv" in dialog.note.text()
    target = tmp_path / "imu0.csv"
    dialog.target_edit.setText(str(target))
    ran_in = []
    dialog.job.finished.connect(lambda _: ran_in.append(threading.current_thread()))
    with qtbot.waitSignal(dialog.job.finished, timeout=TIMEOUT_MS) as finished:
        assert dialog.start_export()
        assert not dialog.export_button.isEnabled()
        worker = dialog.job._thread
    assert worker is not threading.main_thread() and worker.name == "recording-export"
    assert ran_in == [threading.main_thread()]  # the result is handled in the GUI thread
    summary = finished.args[0]
    assert summary.frame == "ned" and summary.rows > 100
    assert target.read_text().splitlines()[0] == EUROC_HEADER
    assert "frame: NED" in readme_path(target).read_text()
    assert "Wrote imu0.csv and imu0.README.txt" in dialog.status.text()
    assert dialog.export_button.isEnabled()
    dialog.grab().save(os.path.join(artifacts_dir, "export_dialog.png"))
    # Again without "Replace existing files": refused, said in the dialog, the file kept.
    before = target.read_bytes()
    with qtbot.waitSignal(dialog.job.failed, timeout=TIMEOUT_MS) as failed:
        assert dialog.start_export()
    assert "exists" in failed.args[0] and "Not exported" in dialog.status.text()
    assert target.read_bytes() == before


def test_file_menu_opens_the_dialog_on_the_recording_being_replayed(qtbot, qapp, tmp_path,
                                                                    wobble_csv):
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, "sim://static?odr=52&seed=3")
    qtbot.addWidget(window)
    window.show()
    qtbot.waitUntil(lambda: session.device_info is not None, timeout=TIMEOUT_MS)
    window.export_recording_action.trigger()
    dialog = window.export_dialog
    assert dialog.isVisible() and dialog.source_edit.text() == ""  # a simulator: no file
    window.files.open_recording(str(wobble_csv))
    qtbot.waitUntil(lambda: session.device_info is not None
                    and "wobble" in session.device_info.url, timeout=TIMEOUT_MS)
    window.export_recording_action.trigger()
    assert window.export_dialog is dialog and dialog.source_edit.text() == str(wobble_csv)
    assert dialog.target_edit.text() == str(wobble_csv.with_name("wobble.mcap"))
    dialog.close()
    window.close()
