"""The window opens other tools' IMU files for replay (detected by content, imported once) and
streams over Lab Streaming Layer from File ▸ Stream over LSL (issue 34, items 3 and 4)."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QInputDialog

from app.core.recording import read_recording
from app.gui import theme
from app.gui.main_window import MainWindow
from app.services import import_replay
from app.services.lsl_outlet import source_id
from app.services.session import DeviceSession
from tests.test_interop_import import write_euroc, write_ximu3
from tests.test_lsl_outlet import LOOPBACK_CONFIG

TIMEOUT_MS = 30_000


@pytest.fixture
def window(qtbot, qapp, tmp_path, monkeypatch):
    monkeypatch.setattr(import_replay, "imported_dir", lambda: tmp_path / "imported")
    config = tmp_path / "lsl_api.cfg"
    config.write_text(LOOPBACK_CONFIG)
    monkeypatch.setenv("LSLAPICFG", str(config))  # liblsl on this machine alone
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(DeviceSession(), settings, "sim://static?odr=104&seed=8")
    qtbot.addWidget(window)
    window.resize(1280, 860)
    window.show()
    qtbot.waitUntil(lambda: window.session.device_info is not None, timeout=TIMEOUT_MS)
    yield window
    window.close()


def test_open_recording_imports_other_tools_files_once_and_replays_them(qtbot, window, tmp_path,
                                                                       monkeypatch):
    n = 400
    rng = np.random.default_rng(1)
    t_ns = 1403636579758555392 + np.arange(n, dtype=np.int64) * 5_000_000
    src = write_euroc(tmp_path / "imu0.csv", t_ns, rng.normal(0, 0.01, (n, 3)),
                      rng.normal([0, 0, 9.81], 0.01, (n, 3)))
    session = window.session
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS) as opened:
        window.open_recording(str(src))
    imported = list((tmp_path / "imported").iterdir())
    assert len(imported) == 1 and imported[0].name.startswith("imu0-euroc-")
    assert str(imported[0]) in opened.args[0].url
    assert len(read_recording(imported[0])) == n
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 100, timeout=TIMEOUT_MS)
    assert "Imported euroc" in window.messages.toPlainText()
    # Opened again: the same import, not a second one.
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        window.open_recording(str(src))
    assert list((tmp_path / "imported").iterdir()) == imported
    assert "Opening the earlier import of euroc" in window.messages.toPlainText()

    # A bad file: one line, and the device it had stays.
    bad = tmp_path / "bad" / "imu0.csv"
    bad.parent.mkdir()
    bad.write_text(src.read_text().replace(f"\n{t_ns[1]},", "\n15x,"))
    url = session.device_info.url
    window.open_recording(str(bad))
    assert "Not opened: imu0.csv: line 3, column 'timestamp [ns]'" in (
        window.messages.toPlainText())
    assert session.device_info.url == url

    # A CSV of no known format: its mapping is asked for.
    src = tmp_path / "phone.csv"
    rows = "\n".join(f"{i * 10},0.0,0.0,1.0,0.5,0,0" for i in range(300))
    src.write_text("ms,x,y,z,wx,wy,wz\n" + rows + "\n")
    asked = []

    def answer(_parent, _title, label, text=""):
        asked.append(label)
        return "t=ms:ms,ax=x:g,ay=y:g,az=z:g,gx=wx:dps,gy=wy:dps,gz=wz:dps", True

    monkeypatch.setattr(QInputDialog, "getText", answer)
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.open_recording(str(src))
    assert "ms, x, y, z, wx, wy, wz" in asked[0]
    imported_csv, = (tmp_path / "imported").glob("phone-csv-*.csv")
    recording = read_recording(imported_csv)
    assert recording.metadata["imported_from"]["format"] == "csv"
    np.testing.assert_allclose(recording.gyro_rad_s[0], [np.radians(0.5), 0, 0])

    # An x-IMU3 log: the field its magnetometer's a.u. stands for is asked for.
    monkeypatch.setattr(QInputDialog, "getDouble", lambda *_args: (48.0, True))
    root = write_ximu3(tmp_path / "log")
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.open_recording(str(next(root.iterdir()) / "Inertial.csv"))
    imported_x, = (tmp_path / "imported").glob("*-x-imu3-*.csv")
    recording = read_recording(imported_x)
    assert recording.metadata["magnetometer"]["ut_per_unit"] == 48.0
    assert np.nanmax(np.abs(recording.mag_ut)) == pytest.approx(0.8012 * 48.0)


def test_file_menu_switches_the_lsl_outlet_and_an_inlet_receives(qtbot, window):
    import pylsl

    session = window.session
    info = session.device_info
    with qtbot.waitSignal(session.lslChanged, timeout=TIMEOUT_MS) as on:
        window.lsl_action.trigger()
    assert source_id(info, "imu") in on.args[0] and window.lsl_action.isChecked()
    found = pylsl.resolve_byprop("source_id", source_id(info, "orientation"), 1, 5.0)
    inlet = pylsl.StreamInlet(found[0])
    inlet.open_stream(5.0)
    got: list[list[float]] = []

    def received() -> bool:
        chunk, _stamps = inlet.pull_chunk(timeout=0.0)
        got.extend(chunk)
        return len(got) > 20

    qtbot.waitUntil(received, timeout=TIMEOUT_MS)
    assert np.allclose(np.linalg.norm(np.asarray(got), axis=1), 1.0)
    with qtbot.waitSignal(session.lslChanged, timeout=TIMEOUT_MS) as off:
        window.lsl_action.trigger()
    assert off.args[0] == "" and not window.lsl_action.isChecked()
    assert "LSL: off" in window.messages.toPlainText()
