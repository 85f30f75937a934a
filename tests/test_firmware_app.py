"""The app on the firmware: the main window connected to the firmware core on a pty.

The firmware's own messages (LOG packets) reach the user: an error on the banner and in the
Messages tab, the rest in the Messages tab.
"""

from __future__ import annotations

import os
import sys

import pytest
from fwcore import FirmwareCore, PtyBoard
from PySide6.QtCore import QSettings, Qt
from PySide6.QtWidgets import QDockWidget
from test_firmware_commands import RecordingBus

from app.gui import theme
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox
from drivers.sim.options import SimOptions

TIMEOUT_MS = 20_000
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals")


def test_the_window_streams_from_the_firmware_and_shows_its_messages(
        qtbot, qapp, tmp_path, firmware_lib, artifacts_dir) -> None:
    bus = RecordingBus(EmulatedLsm6dsox(SimOptions("wobble", seed=12)))
    board = PtyBoard(lambda: FirmwareCore(firmware_lib, bus, unique_id=bytes(range(12))))
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, f"{board.port}?odr=208")
    qtbot.addWidget(window)
    try:
        window.resize(1280, 860)
        window.show()
        qtbot.waitUntil(lambda: session.device_info is not None, timeout=TIMEOUT_MS)
        assert session.device_info.name == "NUCLEO-F746ZG"
        pipeline = session.pipeline
        qtbot.waitUntil(lambda: pipeline.counters.samples > 300, timeout=TIMEOUT_MS)
        qtbot.waitUntil(lambda: "streaming 2" in window.messages.toPlainText(),
                        timeout=TIMEOUT_MS)

        bus.present = False  # the sensor's cable comes loose; the board stays connected
        qtbot.waitUntil(lambda: window.banner.isVisible(), timeout=TIMEOUT_MS)
        assert "NUCLEO-F746ZG: the LSM6DSOX at 0x6A stopped answering" in (
            window.banner.label.text())
        assert os.path.isdir(artifacts_dir)
        window.grab().save(os.path.join(artifacts_dir, "firmware_sensor_lost.png"))

        before = pipeline.counters.samples
        bus.present = True
        qtbot.waitUntil(lambda: "the LSM6DSOX answers again" in window.messages.toPlainText(),
                        timeout=TIMEOUT_MS)
        qtbot.waitUntil(lambda: pipeline.counters.samples > before + 100, timeout=TIMEOUT_MS)
        assert pipeline.counters.gaps >= 1  # the outage is marked in the data
    finally:
        window.close()
        session.shutdown()
        board.close()


def test_the_sensor_self_test_from_the_device_panel(qtbot, qapp, tmp_path, firmware_lib,
                                                    artifacts_dir) -> None:
    chip = EmulatedLsm6dsox(SimOptions("static", seed=13))
    board = PtyBoard(lambda: FirmwareCore(firmware_lib, chip, unique_id=bytes(range(12))))
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, f"{board.port}?odr=104")
    qtbot.addWidget(window)
    panel = window.device_panel
    try:
        window.resize(1280, 860)
        window.show()
        window.docks["device"].raise_()
        qtbot.waitUntil(panel.self_test_button.isEnabled, timeout=TIMEOUT_MS)
        pipeline = session.pipeline
        qtbot.waitUntil(lambda: pipeline.counters.samples > 100, timeout=TIMEOUT_MS)
        with qtbot.waitSignal(session.selfTestFinished, timeout=TIMEOUT_MS) as finished:
            qtbot.mouseClick(panel.self_test_button, Qt.MouseButton.LeftButton)
            assert not panel.self_test_button.isEnabled()  # one at a time
        report, error = finished.args
        assert error == "" and report.passed
        expected = chip.self_test_response.accel_mg
        assert all(abs(a - e) < 5 for a, e in zip(report.accel_delta_mg, expected, strict=True))
        changes = " / ".join(f"{v:.0f}" for v in report.accel_delta_mg)
        assert panel.self_test_result.text().splitlines()[:2] == [
            "Self-test passed", f"accelerometer pass: change {changes} mg"]
        assert "Self-test passed" in window.messages.toPlainText()
        qapp.processEvents()  # lay the panel out again before the screenshot
        window.grab().save(os.path.join(artifacts_dir, "firmware_self_test.png"))
        # Streaming resumes after the pause, which is marked as a gap.
        before = pipeline.counters.samples
        qtbot.waitUntil(lambda: pipeline.counters.samples > before + 50, timeout=TIMEOUT_MS)
        assert pipeline.counters.gaps >= 1
    finally:
        window.close()
        session.shutdown()
        board.close()


def test_a_device_without_a_self_test_says_so(qtbot) -> None:
    session = DeviceSession()
    try:
        with qtbot.waitSignal(session.selfTestAvailable, timeout=TIMEOUT_MS) as available:
            session.requestConnect.emit("sim://static?realtime=0")
        assert available.args == [False]
        with qtbot.waitSignal(session.selfTestFinished, timeout=TIMEOUT_MS) as finished:
            session.requestSelfTest.emit()
        report, error = finished.args
        assert report is None and "has no self-test" in error
    finally:
        session.shutdown()


def test_a_look_alike_lsm6dso32_is_named_in_the_messages_tab(
        qtbot, qapp, tmp_path, firmware_lib, artifacts_dir) -> None:
    chip = EmulatedLsm6dsox(SimOptions("static", seed=12), part="LSM6DSO32")
    board = PtyBoard(lambda: FirmwareCore(firmware_lib, chip, unique_id=bytes(range(12))))
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, f"{board.port}?odr=208")
    qtbot.addWidget(window)
    try:
        window.resize(1280, 860)
        window.show()
        qtbot.waitUntil(lambda: "LSM6DSO32" in window.messages.toPlainText(),
                        timeout=TIMEOUT_MS)
        text = window.messages.toPlainText()
        assert "sensor: accelerometer reads 0.5" in text and "ranges are double" in text
        window.findChild(QDockWidget, "dock-messages").raise_()  # the tab, for the screenshot
        window.grab().save(os.path.join(artifacts_dir, "lookalike_lsm6dso32.png"))
    finally:
        window.close()
        board.close()
