"""The window starts whatever is wrong with the files it reads at start, keeps a copy of each
damaged one aside (``NAME.corrupt-<time>``) and says so.

Each case starts the real :class:`MainWindow` on a settings INI or a ``measurements.json``
damaged one way (a value of the wrong type, JSON nested 100 000 deep, an integer of 5000 digits,
NaN, a file too large), as found by issue 36 (``geometry=hello`` aborted the app, exit 134).
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest
from PySide6.QtCore import QSettings

from app.core import bounded_input
from app.core.measurement_log import LOG_FILE_NAME, default_log_path
from app.gui import theme
from app.gui import user_settings as user_settings_module
from app.gui.main_window import MainWindow
from app.gui.user_settings import ini_problem
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000
DEVICE = "sim://static?odr=52&seed=1"
DEEP = "[" * 100_000 + "]" * 100_000


@pytest.fixture(autouse=True)
def _own_data_dir(qapp, tmp_path, monkeypatch):
    """The measurement log and profiles of each test in its own folder; the default theme."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    theme.apply_theme(qapp)
    yield
    theme.apply_theme(qapp)


def start(qtbot, settings_path: Path) -> MainWindow:
    window = MainWindow(DeviceSession(), QSettings(str(settings_path), QSettings.Format.IniFormat),
                        DEVICE)
    qtbot.addWidget(window)
    window.show()
    return window


def ini_with(path: Path, values: dict[str, object]) -> bytes:
    """A settings file written by QSettings itself (so only the values are wrong)."""
    settings = QSettings(str(path), QSettings.Format.IniFormat)
    for key, value in values.items():
        settings.setValue(key, value)
    settings.sync()
    del settings
    return path.read_bytes()


def raw_ini(path: Path, text: str) -> bytes:
    path.write_text(text, encoding="utf-8")
    return path.read_bytes()


SETTINGS_DAMAGE = {
    "geometry is text": lambda p: raw_ini(p, "[General]\ngeometry=hello\nunit=percent\n"),
    "window state is a number": lambda p: raw_ini(p, "[General]\nwindow_state=12\n"),
    "averaging is not a number": lambda p: raw_ini(p, "[General]\naveraging_s=soon\n"),
    "a section nested 100000 deep": lambda p: ini_with(p, {"sections/alarms": DEEP}),
    "a section with a 5000-digit integer": lambda p: ini_with(
        p, {"sections/alarms": '{"enabled": ' + "9" * 5000 + "}"}),
    "a section holding NaN": lambda p: ini_with(p, {"sections/alarms": '{"x": NaN}'}),
    "a section that is a list": lambda p: ini_with(p, {"sections/alarms": "[1, 2]"}),
    "filter parameters nested deep": lambda p: ini_with(
        p, {"filter_parameters/complementary": DEEP}),
}


@pytest.mark.parametrize("damage", list(SETTINGS_DAMAGE))
def test_the_window_starts_on_a_damaged_settings_file(qtbot, tmp_path, damage):
    path = tmp_path / "settings.ini"
    original = SETTINGS_DAMAGE[damage](path)
    window = start(qtbot, path)
    try:
        assert window.banner.isVisible() and "damaged" in window.banner.label.text()
        kept = list(tmp_path.glob("settings.ini.corrupt-*"))
        assert len(kept) == 1 and kept[0].read_bytes() == original  # nothing lost
        assert str(kept[0]) in window.messages.toPlainText()
        assert window.unit_combo.currentData() == "deg"  # the defaults
    finally:
        window.close()
    # What the window saved on closing is sound, and starts without a word.
    assert ini_problem(path.read_bytes()) is None
    again = start(qtbot, path)
    try:
        assert "damaged" not in again.messages.toPlainText()
    finally:
        again.close()
    assert len(list(tmp_path.glob("settings.ini.corrupt-*"))) == 1


def test_a_settings_file_too_large_is_moved_aside(qtbot, tmp_path, monkeypatch):
    monkeypatch.setattr(user_settings_module, "MAX_SETTINGS_BYTES", 4096)
    path = tmp_path / "settings.ini"
    original = raw_ini(path, "[General]\n" + "".join(f"k{i}=v\n" for i in range(2000)))
    window = start(qtbot, path)
    try:
        assert "larger than" in window.banner.label.text()
        kept = list(tmp_path.glob("settings.ini.corrupt-*"))
        assert len(kept) == 1 and kept[0].read_bytes() == original
    finally:
        window.close()


def test_a_section_its_owner_rejects_is_reported_and_a_copy_kept(qtbot, tmp_path):
    path = tmp_path / "settings.ini"
    original = ini_with(path, {"sections/alarms": json.dumps({"limits": "not a list"}),
                               "unit": "percent"})
    window = start(qtbot, path)
    try:
        qtbot.waitUntil(lambda: "alarms settings are not valid" in window.messages.toPlainText(),
                        timeout=TIMEOUT_MS)
        assert window.unit_combo.currentData() == "percent"  # the rest of the file is used
        kept = list(tmp_path.glob("settings.ini.corrupt-*"))
        assert len(kept) == 1 and kept[0].read_bytes() == original
        assert str(kept[0]) in window.messages.toPlainText()
    finally:
        window.close()


LOG_DAMAGE = {
    "nested 100000 deep": DEEP.encode(),
    "an integer of 5000 digits": b'{"format": "inclinometer-measurement-log", "version": '
                                 + b"1" * 5000 + b', "entries": []}',
    "NaN": b'{"format": "inclinometer-measurement-log", "version": NaN, "entries": []}',
    "an entry of the wrong type": json.dumps({"format": "inclinometer-measurement-log",
                                              "version": 1, "entries": [[[]]]}).encode(),
    "too large": b" " * 5000 + b"{}",
}
"""(The log's limit is lowered to 4 kB for "too large".)"""


@pytest.mark.parametrize("damage", list(LOG_DAMAGE))
def test_the_window_starts_on_a_damaged_measurement_log(qtbot, tmp_path, monkeypatch, damage):
    from app.core import measurement_log

    monkeypatch.setattr(measurement_log, "MAX_LOG_BYTES", 4096 if damage == "too large"
                        else bounded_input.MAX_JSON_BYTES)
    log_path = default_log_path()
    assert log_path.name == LOG_FILE_NAME and str(tmp_path) in str(log_path)
    log_path.parent.mkdir(parents=True)
    log_path.write_bytes(LOG_DAMAGE[damage])
    window = start(qtbot, tmp_path / "settings.ini")
    try:
        qtbot.waitUntil(lambda: "measurement log" in window.banner.label.text(),
                        timeout=TIMEOUT_MS)
        assert "damaged" in window.banner.label.text()
        kept = list(log_path.parent.glob(LOG_FILE_NAME + ".corrupt-*"))
        assert len(kept) == 1 and kept[0].read_bytes() == LOG_DAMAGE[damage]
        assert not log_path.exists() and len(window.log_panel.log) == 0
    finally:
        window.close()


@pytest.mark.parametrize("damage", ["nested 100000 deep", "an integer of 5000 digits"])
def test_the_window_connects_with_a_damaged_calibration_profile(qtbot, tmp_path, damage):
    """A profile is left where it is (profiles are never changed by reading: the message says
    so); the device runs uncalibrated and the window says why."""
    from app.core.calibration_procedures.profiles import ProfileStore
    from drivers.sim.error_model import unique_id_for_seed

    path = ProfileStore().path_for(unique_id_for_seed(1))  # the device DEVICE opens
    assert str(tmp_path) in str(path)
    path.parent.mkdir(parents=True)
    path.write_bytes(LOG_DAMAGE[damage])
    window = start(qtbot, tmp_path / "settings.ini")
    try:
        qtbot.waitUntil(lambda: "Calibration profile not loaded" in window.messages.toPlainText(),
                        timeout=TIMEOUT_MS)
        text = window.messages.toPlainText()
        assert ("nested more than" in text) if "nested" in damage else ("5000 digits" in text)
        assert "left untouched" in text and path.read_bytes() == LOG_DAMAGE[damage]
        assert window.status_calibration.text() == "Uncalibrated"
    finally:
        window.close()


@pytest.mark.timeout(60)
def test_a_fifo_in_place_of_the_settings_file_is_moved_aside(qtbot, tmp_path, monkeypatch):
    """QSettings reads its file when constructed: a FIFO there blocked the start for ever."""
    from app.gui.user_settings import SETTINGS_ENV, create_settings

    path = tmp_path / "settings.ini"
    os.mkfifo(path)
    monkeypatch.setenv(SETTINGS_ENV, str(path))
    window = MainWindow(DeviceSession(), create_settings(), DEVICE)
    qtbot.addWidget(window)
    try:
        assert "not a regular file" in window.banner.label.text()
        kept = list(tmp_path.glob("settings.ini.corrupt-*"))
        assert len(kept) == 1 and stat.S_ISFIFO(kept[0].stat().st_mode)
        assert str(kept[0]) in window.messages.toPlainText()
    finally:
        window.close()
    assert ini_problem(path.read_bytes()) is None  # a new, regular file
