"""The board's health in the window: the Device dock's counters and the message with its reason.

The main window connects to the emulated NUCLEO on a pseudo-terminal, which loses one packet's
samples to an injected sensor FIFO overrun.
"""

from __future__ import annotations

import os
import sys

import pytest
from PySide6.QtCore import QSettings

from app.gui import theme
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession
from drivers.emulated_nucleo import EmulatedNucleo, NucleoFaults

TIMEOUT_MS = 20_000
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals")


def test_the_device_dock_shows_the_boards_counters_and_an_overrun_is_explained(
        qtbot, qapp, tmp_path, artifacts_dir) -> None:
    board = EmulatedNucleo("static", odr_hz=208.0, seed=11,
                           faults=NucleoFaults(overrun_seqs=frozenset({30})))
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, board.port)
    qtbot.addWidget(window)
    panel = window.device_panel
    try:
        window.resize(1280, 1300)
        window.show()
        window.docks["device"].raise_()
        qtbot.waitUntil(lambda: panel.board_box.isVisible(), timeout=TIMEOUT_MS)
        assert panel.board_values["reset_cause"].text() == "power-on"
        # The overrun (packet 30, ~0.15 s in) shows in the next STATUS, a second later.
        qtbot.waitUntil(lambda: panel.board_values["fifo_overruns"].text() == "1",
                        timeout=TIMEOUT_MS)
        lost = board.stats.samples_dropped
        assert lost > 0
        qtbot.waitUntil(
            lambda: f"board: sensor FIFO overrun, {lost} samples lost"
            in window.messages.toPlainText(), timeout=TIMEOUT_MS)
        assert theme.ALARM_RED in panel.board_values["fifo_overruns"].styleSheet()
        assert panel.board_values["i2c_retries"].styleSheet() == ""
        sent = int(panel.board_values["samples_sent"].text().replace(",", ""))
        assert 0 < sent <= board.stats.samples_sent
        qapp.processEvents()
        window.grab().save(os.path.join(artifacts_dir, "board_status_dock.png"))
        # Another device: the board's counters go away until it sends its own.
        session.requestConnect.emit("sim://static?realtime=0")
        qtbot.waitUntil(lambda: not panel.board_box.isVisible(), timeout=TIMEOUT_MS)
    finally:
        window.close()
        session.shutdown()
        board.close()
