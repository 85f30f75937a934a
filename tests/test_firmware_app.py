"""The app on the firmware: the main window connected to the firmware core on a pty.

The firmware's own messages (LOG packets) reach the user: an error on the banner and in the
Messages tab, the rest in the Messages tab.
"""

from __future__ import annotations

import os
import sys

import pytest
from fwcore import FirmwareCore, PtyBoard
from PySide6.QtCore import QSettings
from test_firmware_commands import RecordingBus

from app.gui import theme
from app.gui.main_window import MainWindow
from app.worker import DeviceSession
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
