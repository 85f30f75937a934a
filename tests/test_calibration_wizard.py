"""The calibration wizard, driven through the simulator's scripted tour of six faces."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from PySide6.QtCore import QSettings

from app.core.calibration_procedures import ProfileStore
from app.gui import theme
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession
from drivers.sim.device import SimulatedDevice

TIMEOUT_MS = 60_000
# A fast tour: 8 s per face, played ten times faster than real time.
TOUR = "sim://tour?odr=104&seed=4&hold=8&speed=25"


@pytest.fixture
def store(tmp_path) -> ProfileStore:
    return ProfileStore(tmp_path / "profiles")


@pytest.fixture
def window(qtbot, qapp, tmp_path, store):
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession(profile_store=store)
    window = MainWindow(session, settings, TOUR)
    qtbot.addWidget(window)
    window.resize(1280, 860)
    window.show()
    qtbot.waitUntil(lambda: session.device_info is not None, timeout=TIMEOUT_MS)
    yield window
    window.close()


def test_wizard_completes_on_the_tour_and_recovers_the_units_errors(
    qtbot, window, store, artifacts_dir
):
    session = window.session
    wizard = window.open_calibration_wizard()
    assert wizard is not None
    wizard.intro.gyro_seconds.setValue(2.0)
    wizard.grab().save(os.path.join(artifacts_dir, "wizard_1_intro.png"))
    wizard.next()
    qtbot.waitUntil(wizard.gyro_page.isComplete, timeout=TIMEOUT_MS)
    wizard.grab().save(os.path.join(artifacts_dir, "wizard_2_gyro.png"))
    wizard.next()
    qtbot.waitUntil(lambda: len(wizard.poses_page.capture.poses) >= 3, timeout=TIMEOUT_MS)
    wizard.grab().save(os.path.join(artifacts_dir, "wizard_3_poses.png"))
    qtbot.waitUntil(wizard.poses_page.isComplete, timeout=TIMEOUT_MS)
    wizard.next()
    results = wizard.results_page
    assert results.fit is not None, results.error
    assert results.fit.residual_norm_rms_mg < 0.5
    assert results.comparison.rowCount() == 6
    wizard.grab().save(os.path.join(artifacts_dir, "wizard_4_results.png"))

    with qtbot.waitSignal(session.calibrationChanged, timeout=TIMEOUT_MS) as blocker:
        wizard.accept()
    profile = blocker.args[0]
    assert profile is not None
    # Stored for the device, and shown as active.
    assert store.load_for_device(session.device_info.unique_id) is not None
    assert window.status_calibration.text().startswith("Calibrated")

    # The fit found the simulated unit's true errors (same seed = same unit).
    truth = SimulatedDevice(TOUR).unit_errors
    temperature = profile.temperature_degc
    true_bias = truth.accel_bias_m_s2 + truth.accel_bias_tc_m_s2_per_degc * (temperature - 25.0)
    recovered = profile.calibration.accel_bias_m_s2
    assert np.max(np.abs(recovered - true_bias)) / 9.80665e-3 < 1.0  # mg


def test_a_corrupt_profile_is_reported_and_nothing_is_lost(qtbot, qapp, tmp_path, store):
    unique_id = SimulatedDevice("sim://static?seed=5").unique_id
    path = store.path_for(unique_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("{ this is not json")
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession(profile_store=store)
    window = MainWindow(session, settings, "sim://static?seed=5")
    qtbot.addWidget(window)
    window.show()
    try:
        qtbot.waitUntil(lambda: window.banner.isVisible(), timeout=TIMEOUT_MS)
        assert "Calibration profile not loaded" in window.banner.label.text()
        assert window.status_calibration.text() == "Uncalibrated"
        assert path.read_text() == "{ this is not json"  # untouched
        qtbot.waitUntil(lambda: session.pipeline.counters.samples > 10, timeout=TIMEOUT_MS)
    finally:
        window.close()


def test_a_foreign_profile_is_refused_on_import(qtbot, window, store, tmp_path):
    foreign = tmp_path / "foreign.json"
    foreign.write_text(json.dumps({"format": "something else"}))
    window.import_profile(str(foreign))
    assert window.banner.isVisible()
    assert "Profile not imported" in window.banner.label.text()
    assert window.status_calibration.text() == "Uncalibrated"


def test_tare_makes_the_current_attitude_level(qtbot, window):
    session = window.session
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        window.connect_device("sim://static?roll=12&pitch=-5&odr=104&speed=25")
    # Let the filter settle (30 s of device time) before taring, as a user would.
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 3000, timeout=TIMEOUT_MS)
    with qtbot.waitSignal(session.tareChanged, timeout=TIMEOUT_MS):
        window.tare_action.trigger()
    assert window.status_tare.text().startswith("TARE")
    total = session.pipeline.counters.samples
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > total + 100, timeout=TIMEOUT_MS)
    latest = session.pipeline.orientation.latest(50)
    assert abs(np.mean(latest["roll"])) < 0.1
    assert abs(np.mean(latest["pitch"])) < 0.1
    with qtbot.waitSignal(session.tareChanged, timeout=TIMEOUT_MS):
        window.clear_tare_action.trigger()
    assert window.status_tare.text() == ""


def test_static_statistics_and_reversal_from_the_measure_panel(qtbot, window):
    session = window.session
    panel = window.measure_panel
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        window.connect_device("sim://interactive?roll=1.0&pitch=0.5&odr=104&speed=25&errors=0")
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 2000, timeout=TIMEOUT_MS)

    panel.duration.setValue(5.0)
    panel.start_statistics()
    qtbot.waitUntil(lambda: panel.stats_progress.value() == 1000, timeout=TIMEOUT_MS)
    roll_mean = float(panel.stats_table.item(0, 1).text())
    assert roll_mean == pytest.approx(1.0, abs=0.05)
    assert float(panel.stats_table.item(0, 2).text()) < 0.05  # std at rest

    # Position 1 reads surface slope + offset; turned by 180 degrees, slope changes sign.
    # The virtual "surface" here is the simulator's attitude, so turn it by hand.
    panel.first_button.click()
    qtbot.waitUntil(panel.second_button.isEnabled, timeout=TIMEOUT_MS)
    session.requestSimulatorTarget.emit(-1.0, -0.5)
    total = session.pipeline.counters.samples
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > total + 3000, timeout=TIMEOUT_MS)
    panel.second_button.click()
    qtbot.waitUntil(panel.tare_button.isEnabled, timeout=TIMEOUT_MS)
    result = panel.reversal
    assert result.slope_roll_deg == pytest.approx(1.0, abs=0.05)
    assert result.slope_pitch_deg == pytest.approx(0.5, abs=0.05)
    assert abs(result.offset_roll_deg) < 0.05 and abs(result.offset_pitch_deg) < 0.05
