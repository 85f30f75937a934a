"""The Allan variance page: the plot and table of a simulated static recording, and the button
that sets the running EKF's noise parameters (seen in the worker's filter) with its source."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
from PySide6.QtCore import QSettings

from app.cli import main
from app.gui import theme
from app.gui.allan_page import SETTINGS_KEY, AllanPage
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000


@pytest.fixture(scope="module")
def static_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("allan-gui") / "static.csv"
    assert main(["record", "--device", "sim://static?odr=26&seed=2&realtime=0",
                 "--duration", "6m", str(path)]) == 0
    return path


def test_allan_page_plots_and_tabulates_a_static_recording(qtbot, qapp, static_csv,
                                                           artifacts_dir):
    theme.apply_theme(qapp)
    page = AllanPage()
    qtbot.addWidget(page)
    page.show()
    result = page.load_recording(static_csv)
    assert result is not None
    # Issue 34: the noise density in both conventions, each named (8 rows, were 6).
    assert page.table.rowCount() == 8
    assert page.table.item(0, 0).text() == "Gyro noise density, datasheet (1-sided)"
    gyro_density = float(page.table.item(0, 2).text())
    assert gyro_density == pytest.approx(3.8e-3, rel=0.1)
    assert page.table.item(1, 0).text() == "Gyro noise density, Allan/Kalibr (τ = 1 s)"
    assert float(page.table.item(1, 2).text()) == pytest.approx(gyro_density / math.sqrt(2),
                                                                rel=1e-3)
    assert "N·√(fs/2)" in page.table.item(1, 2).toolTip()
    # Three measured curves, three fitted ones and the asymptotes per plot.
    assert len(page.gyro_plot.getPlotItem().listDataItems()) >= 7
    proposed = page.proposed_parameters()
    assert set(proposed) == {"ekf", "ekf-smoother", "vqf-heading"}
    assert proposed["ekf"]["gyro_noise"] == pytest.approx(3.8, rel=0.1)  # mdps/rtHz
    assert proposed["ekf"]["accel_noise"] == pytest.approx(70.0, rel=0.1)  # ug/rtHz
    page.grab().save(os.path.join(artifacts_dir, "allan_page.png"))


def test_the_button_sets_the_running_ekf_and_records_the_source(qtbot, qapp, tmp_path,
                                                                 static_csv):
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, "sim://static?odr=52&seed=3", "ekf")
    qtbot.addWidget(window)
    window.show()
    qtbot.waitUntil(lambda: session.device_info is not None, timeout=TIMEOUT_MS)
    assert session.pipeline.filter.name == "ekf"
    page = window.open_allan_page()
    qtbot.addWidget(page)
    assert page.load_recording(static_csv) is not None
    before = session.pipeline.filter.get_parameter("gyro_noise")
    proposed = page.apply_to_filters()["ekf"]
    assert not math.isclose(before, proposed["gyro_noise"])
    qtbot.waitUntil(lambda: math.isclose(session.pipeline.filter.get_parameter("gyro_noise"),
                                         proposed["gyro_noise"]), timeout=TIMEOUT_MS)
    assert session.pipeline.filter.get_parameter("accel_noise") == pytest.approx(
        proposed["accel_noise"])
    # A 6-minute record sets the noise densities, not the bias drift (needs 30 minutes).
    assert "bias_drift" not in proposed
    log = window.messages.toPlainText()
    assert "ekf: " in log and "gyro_noise = " in log and "Allan analysis of static.csv" in log
    # Kept in the window's one settings file (the INI), not in a QSettings() of its own.
    assert "Allan analysis of static.csv" in settings.value(SETTINGS_KEY)
    assert not QSettings().value(SETTINGS_KEY)
    assert "Allan analysis of static.csv" in page.applied_label.text()
    page.close()
    window.close()


def test_the_wizards_finish_page_saves_the_report(qtbot, qapp, tmp_path):
    theme.apply_theme(qapp)
    from app.core.calibration_procedures import ProfileStore

    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession(profile_store=ProfileStore(tmp_path / "profiles"))
    window = MainWindow(session, settings, "sim://tour?odr=104&seed=4&hold=8&speed=10")
    qtbot.addWidget(window)
    window.show()
    qtbot.waitUntil(lambda: session.device_info is not None, timeout=TIMEOUT_MS)
    wizard = window.open_calibration_wizard()
    wizard.intro.gyro_seconds.setValue(2.0)
    wizard.next()
    qtbot.waitUntil(wizard.gyro_page.isComplete, timeout=TIMEOUT_MS)
    wizard.next()
    qtbot.waitUntil(wizard.poses_page.isComplete, timeout=TIMEOUT_MS)
    wizard.next()
    results = wizard.results_page
    html_path = results.save_report(str(tmp_path / "wizard.html"))
    pdf_path = results.save_report(str(tmp_path / "wizard.pdf"))
    text = Path(html_path).read_text(encoding="utf-8")
    assert session.device_info.unique_id in text and "+z up" in text and "-y up" in text
    assert Path(pdf_path).read_bytes()[:4] == b"%PDF"
    wizard.close()
    window.close()
