"""Alarms and the measurement log in the main window, driven as a user would."""

from __future__ import annotations

import csv
import io
import json
import os

import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QApplication

from app.core.measurement_log import LOG_FILE_NAME
from app.gui import main_window as main_window_module
from app.gui import theme
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000
INTERACTIVE = "sim://interactive?odr=208&seed=4&errors=0"


@pytest.fixture
def log_path(tmp_path, monkeypatch):
    path = tmp_path / "data" / LOG_FILE_NAME
    monkeypatch.setattr(main_window_module, "default_log_path", lambda: path)
    return path


def open_window(qtbot, qapp, tmp_path, url: str = INTERACTIVE) -> MainWindow:
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(DeviceSession(), settings, url)
    qtbot.addWidget(window)
    window.resize(1280, 860)
    window.show()
    qtbot.waitUntil(lambda: window.session.device_info is not None, timeout=TIMEOUT_MS)
    return window


@pytest.fixture
def window(qtbot, qapp, tmp_path, log_path):
    window = open_window(qtbot, qapp, tmp_path)
    yield window
    window.close()


def tilt_simulator(qtbot, window: MainWindow, roll: float, pitch: float) -> None:
    qtbot.waitUntil(window.simulator_panel.roll_slider.isEnabled, timeout=TIMEOUT_MS)
    window.simulator_panel.set_target(roll, pitch, emit=True)


def test_a_tilt_beyond_the_limit_turns_the_display_red_and_shows_a_banner(
        qtbot, window, monkeypatch, artifacts_dir):
    beeps = []
    monkeypatch.setattr(QApplication, "beep", staticmethod(lambda: beeps.append(1)))
    row = window.alarm_panel.rows["tilt"]
    with qtbot.waitSignal(window.alarm_panel.alarmsChanged, timeout=TIMEOUT_MS):
        row.above.setValue(2.5)
    row.delay.setValue(0.2)
    window.alarm_panel.sound.setChecked(True)
    row.enabled.setChecked(True)
    assert window.alarm_panel.config().enabled[0].spec() == "tilt>2.5,hyst=0.1,delay=0.2"
    qtbot.waitUntil(lambda: window.level.isValid(), timeout=TIMEOUT_MS)
    assert not window.level.isAlarm() and window.readouts.alarmQuantities() == ()

    tilt_simulator(qtbot, window, 4.0, -3.0)  # 5° of tilt
    qtbot.waitUntil(lambda: window.readouts.alarmQuantities() == ("tilt",), timeout=TIMEOUT_MS)
    assert window.level.isAlarm() and window.level.property("alarm") is True
    assert window.readouts.property("alarm") is True
    assert window.alarm_banner.isVisible()
    assert "ALARM" in window.alarm_banner.label.text() and "tilt above 2.5°" in (
        window.alarm_banner.label.text())
    assert window.alarm_panel.rows["tilt"].state.text() == "ALARM"
    assert "tilt alarm raised" in window.messages.toPlainText()
    assert beeps == [1]
    value = window.readouts.valueLabel("tilt")
    # Styled by a property and the stylesheet (a font swap once cut "178.33" to "78.33").
    assert value.parentWidget().property("alarm") is True
    assert value.palette().color(value.foregroundRole()).name() == theme.ALARM_STATE
    qtbot.waitUntil(lambda: window.readouts.readoutText("tilt").startswith("5.0"),
                    timeout=TIMEOUT_MS)
    window.docks["alarms"].raise_()
    path = os.path.join(artifacts_dir, "alarm_active.png")
    assert window.grab().save(path)

    tilt_simulator(qtbot, window, 0.5, 0.5)
    qtbot.waitUntil(lambda: not window.level.isAlarm(), timeout=TIMEOUT_MS)
    assert window.readouts.alarmQuantities() == ()
    assert not window.alarm_banner.isVisible()
    assert "tilt alarm cleared" in window.messages.toPlainText()
    assert beeps == [1]  # a clear does not sound


def test_switching_an_alarm_off_while_raised_clears_the_display(qtbot, window):
    row = window.alarm_panel.rows["roll"]
    row.delay.setValue(0.0)
    row.enabled.setChecked(True)
    tilt_simulator(qtbot, window, 6.0, 0.0)
    qtbot.waitUntil(lambda: window.readouts.alarmQuantities() == ("roll",), timeout=TIMEOUT_MS)
    row.enabled.setChecked(False)
    qtbot.waitUntil(lambda: not window.level.isAlarm(), timeout=TIMEOUT_MS)
    assert "switched off" in window.messages.toPlainText()


def test_contradictory_limits_are_not_applied(qtbot, window):
    row = window.alarm_panel.rows["roll"]
    before = window.alarm_panel.config()
    row.below_on.setChecked(True)
    row.below.setValue(5.0)  # above the upper limit of 2
    assert "must be below" in window.alarm_panel.problem.text()
    assert window.alarm_panel.config() == before


def test_the_measurement_log_stores_edits_exports_copies_and_survives_a_restart(
        qtbot, qapp, tmp_path, log_path, artifacts_dir):
    window = open_window(qtbot, qapp, tmp_path)
    panel = window.log_panel
    window.docks["log"].raise_()
    tilt_simulator(qtbot, window, 1.5, -0.5)
    qtbot.waitUntil(lambda: abs(window.level.roll() - 1.5) < 0.05
                    and abs(window.level.pitch() + 0.5) < 0.05, timeout=TIMEOUT_MS)
    panel.label_edit.setText("north corner")
    window.store_action.trigger()  # what Space does
    qtbot.keyClick(window.level, Qt.Key.Key_Space)  # and Space itself, with the focus elsewhere
    panel.label_edit.setText("typed")
    qtbot.keyClick(panel.label_edit, Qt.Key.Key_Space)  # a text field keeps Space for typing
    assert panel.label_edit.text() == "typed " and len(panel.log) == 2
    panel.label_edit.clear()
    panel.store("east corner")
    assert len(panel.log) == 3 and panel.table.rowCount() == 3
    first = panel.log.entries[0]
    assert first.label == "north corner" and panel.log.entries[1].label == "#2"
    assert first.roll == pytest.approx(1.5, abs=0.1)
    assert first.pitch == pytest.approx(-0.5, abs=0.1)
    assert 0 < first.roll_std < 0.05 and first.samples > 50
    assert first.unit == "deg" and first.window_s == window.presenter.settings.averaging_s
    assert first.filter == window.session.pipeline.filter.name
    assert first.calibration == "uncalibrated" and "SIM-" in first.device
    # Hold keeps the reading shown: what is stored while the sensor moves on.
    window.hold_button.setChecked(True)
    held = window.readouts.readoutText("roll")
    tilt_simulator(qtbot, window, 3.0, -0.5)
    latest_roll = lambda: float(window.session.pipeline.orientation.latest(1)["roll"][0])  # noqa: E731
    qtbot.waitUntil(lambda: latest_roll() > 2.5, timeout=TIMEOUT_MS)
    on_hold = panel.store("held")
    assert f"{on_hold.roll:+.2f}" == held.rstrip("°").replace("−", "-")
    window.hold_button.setChecked(False)
    window.grab().save(os.path.join(artifacts_dir, "measurement_log.png"))
    panel.grab().save(os.path.join(artifacts_dir, "measurement_log_dock.png"))
    panel.table.selectRow(3)
    qtbot.keyClick(panel.table, Qt.Key.Key_Delete)
    # Edit a label in the table, delete a row.
    panel.table.item(1, 1).setText("south corner")
    assert panel.log.entries[1].label == "south corner"
    panel.table.selectRow(2)
    qtbot.keyClick(panel.table, Qt.Key.Key_Delete)
    assert [e.label for e in panel.log.entries] == ["north corner", "south corner"]
    panel.table.clearSelection()
    text = panel.copy_to_clipboard()
    assert QGuiApplication.clipboard().text() == text
    rows = list(csv.reader(io.StringIO(text), delimiter="\t"))
    assert rows[0][:4] == ["time", "label", "roll", "roll_std"] and len(rows) == 3
    assert rows[2][1] == "south corner"
    exported = tmp_path / "log.csv"
    panel.export_csv(str(exported))
    assert list(csv.reader(exported.open()))[1][1] == "north corner"
    window.close()
    # A restart finds the log as it was left.
    stored = json.loads(log_path.read_text())
    assert [e["label"] for e in stored["entries"]] == ["north corner", "south corner"]
    again = open_window(qtbot, qapp, tmp_path)
    try:
        assert [e.label for e in again.log_panel.log.entries] == ["north corner",
                                                                  "south corner"]
        assert again.log_panel.table.item(0, 1).text() == "north corner"
        assert again.log_panel.log.entries[0] == first
    finally:
        again.close()


def test_a_corrupt_log_starts_empty_with_a_message_and_is_kept_aside(
        qtbot, qapp, tmp_path, log_path):
    log_path.parent.mkdir(parents=True)
    log_path.write_text('{"format": "inclinometer-measurement-log", "version": 1, "entr')
    window = open_window(qtbot, qapp, tmp_path)
    try:
        assert len(window.log_panel.log) == 0
        qtbot.waitUntil(lambda: window.banner.isVisible(), timeout=TIMEOUT_MS)
        assert "measurement log" in window.banner.label.text()
        assert "damaged" in window.banner.label.text()
        kept = list(log_path.parent.glob(f"{LOG_FILE_NAME}.corrupt-*"))
        assert len(kept) == 1 and kept[0].read_text().endswith('"entr')
        assert str(kept[0]) in window.banner.label.text()
        window.log_panel.store("after")
        assert json.loads(log_path.read_text())["entries"][0]["label"] == "after"
        assert kept[0].exists()
    finally:
        window.close()


def test_a_replay_shows_its_recorded_crossings_in_messages_and_on_the_overview(
        qtbot, qapp, tmp_path, log_path):
    from app.cli import main

    source = tmp_path / "swing.csv"
    swing = ("sim://slow-tilt?odr=104&realtime=0&amplitude=10&roll_period=4&pitch_period=1000"
             "&seed=2")
    assert main(["record", "--device", swing, "--duration", "6", "--quiet",
                 "--alarm", "roll>5,hyst=0.5,delay=0.2", str(source)]) == 0
    window = open_window(qtbot, qapp, tmp_path, f"replay://{source}")
    try:
        assert "holds 4 alarm crossing(s)" in window.messages.toPlainText()
        overview = window.replay_bar.overview
        qtbot.waitUntil(lambda: len(overview.alarm_marks()) == 2, timeout=TIMEOUT_MS)
        first, second = overview.alarm_marks()
        assert first == pytest.approx(0.53, abs=0.1) and second == pytest.approx(4.53, abs=0.1)
    finally:
        window.close()
