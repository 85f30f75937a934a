"""The main window, driven like a user would: it shows live data, switches and survives errors."""

from __future__ import annotations

import os

import pytest
from PySide6.QtCore import QSettings, Qt

from app.core.filters import DEFAULT_FILTER
from app.gui import theme
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000


@pytest.fixture
def window(qtbot, qapp, tmp_path):
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, "sim://wobble?odr=208&seed=3&speed=4")
    qtbot.addWidget(window)
    window.resize(1280, 860)
    window.show()
    qtbot.waitUntil(lambda: session.device_info is not None, timeout=TIMEOUT_MS)
    yield window
    window.close()


def curve_points(curve) -> int:
    return 0 if curve.xData is None else len(curve.xData)


def test_window_shows_live_data(qtbot, window, artifacts_dir):
    pipeline = window.session.pipeline
    qtbot.waitUntil(lambda: pipeline.counters.samples > 600, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: window.level.isValid(), timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: curve_points(window.plots.accel_curves[2]) > 300, timeout=TIMEOUT_MS)
    assert window.readouts.isEnabled()
    assert "Streaming" in window.device_bar.status_label.text() or "Hz" in (
        window.device_bar.status_label.text()
    )
    # The angle plot shows the estimate and the simulator's truth.
    assert window.plots.angle_curves["roll"].isVisible()
    assert window.plots.angle_curves["ref_roll"].isVisible()
    assert window.truth_label.text().startswith("Simulator truth")
    assert window.plots.legend_entries(window.plots.angle_plot) == [
        "roll", "pitch", "true roll", "true pitch"]
    path = os.path.join(artifacts_dir, "main_window.png")
    assert window.grab().save(path)


def test_filter_switch_from_the_panel(qtbot, window):
    panel = window.filter_panel
    qtbot.waitUntil(lambda: panel.current_filter == DEFAULT_FILTER, timeout=TIMEOUT_MS)
    index = panel.combo.findData("accel")
    with qtbot.waitSignal(window.session.filterChanged, timeout=TIMEOUT_MS):
        panel.combo.setCurrentIndex(index)
        panel.combo.activated.emit(index)
    assert window.session.pipeline.filter.name == "accel"
    qtbot.waitUntil(lambda: "Accelerometer" in window.status_filter.text(), timeout=TIMEOUT_MS)


def test_interactive_simulator_follows_the_sliders(qtbot, window):
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device("sim://interactive?odr=208")
    qtbot.waitUntil(window.simulator_panel.roll_slider.isEnabled, timeout=TIMEOUT_MS)
    window.simulator_panel.set_target(12.0, -7.0, emit=True)

    def true_roll() -> float:
        latest = window.session.pipeline.orientation.latest(1)["ref_roll"]
        return float(latest[0]) if len(latest) else float("nan")

    qtbot.waitUntil(lambda: abs(true_roll() - 12.0) < 0.01, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: abs(window.level.roll() - 12.0) < 2.0, timeout=TIMEOUT_MS)


def test_device_failure_shows_a_banner_and_the_app_keeps_running(qtbot, window):
    with qtbot.waitSignal(window.session.disconnected, timeout=TIMEOUT_MS):
        window.connect_device("sim://static?fail_after=0.3")
    qtbot.waitUntil(lambda: window.banner.isVisible(), timeout=TIMEOUT_MS)
    assert "unplugged" in window.banner.label.text()
    # The error and the disconnection are two queued signals: the banner can show before the
    # device bar has taken the second one.
    qtbot.waitUntil(lambda: "error" in window.device_bar.status_label.text().lower(),
                    timeout=TIMEOUT_MS)
    assert "unplugged" in window.messages.toPlainText()
    # Reconnecting clears the banner and streams again.
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device("sim://static")
    assert not window.banner.isVisible()


def test_display_units_and_hold(qtbot, window):
    window.unit_combo.setCurrentIndex(window.unit_combo.findData("mm/m"))
    assert window.presenter.settings.unit == "mm/m"
    qtbot.waitUntil(lambda: window.level.isValid(), timeout=TIMEOUT_MS)
    window.hold_button.setChecked(True)
    assert window.presenter.settings.hold
    window.range_combo.setCurrentIndex(window.range_combo.findData(30.0))
    assert window.level.fullScale() == 30.0


def test_compared_filters_are_overlaid_and_scored(qtbot, window):
    panel = window.filter_panel
    qtbot.waitUntil(lambda: panel.current_filter == DEFAULT_FILTER, timeout=TIMEOUT_MS)
    item = next(
        panel.compare_list.item(row) for row in range(panel.compare_list.count())
        if panel.compare_list.item(row).data(Qt.ItemDataRole.UserRole) == "accel"
    )
    with qtbot.waitSignal(window.session.comparisonsChanged, timeout=TIMEOUT_MS) as blocker:
        item.setCheckState(Qt.CheckState.Checked)
    assert blocker.args[0] == ["accel"]
    curves = window.plots.comparison_curves["accel"]
    qtbot.waitUntil(lambda: curve_points(curves[0]) > 10, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: panel.error_table.rowCount() == 2, timeout=TIMEOUT_MS)
    assert panel.error_table.item(1, 0).text() == "Accelerometer only"
    assert panel.error_table.item(1, 1).text().endswith("°")


def test_simulator_panel_shows_the_connected_units_attitude(qtbot, window):
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device("sim://interactive?roll=4&pitch=-2.5&seed=9")
    panel = window.simulator_panel
    assert panel.roll_spin.value() == 4.0
    assert panel.pitch_spin.value() == -2.5
    assert panel.seed_spin.value() == 9
    assert panel.url().startswith("sim://interactive?")


def test_parameters_spanning_decades_are_edited_in_scientific_notation(qtbot, window):
    panel = window.filter_panel
    index = panel.combo.findData("kalman-thesis")
    with qtbot.waitSignal(window.session.filterChanged, timeout=TIMEOUT_MS):
        panel.combo.setCurrentIndex(index)
        panel.combo.activated.emit(index)
    qtbot.waitUntil(lambda: panel.current_filter == "kalman-thesis", timeout=TIMEOUT_MS)
    spin = panel._controls["q"]
    assert spin.text().startswith("1e-05")
    with qtbot.waitSignal(window.session.filterChanged, timeout=TIMEOUT_MS):
        spin.lineEdit().setText("3e-7")
        spin.interpretText()
    assert window.session.pipeline.filter.get_parameter("q") == pytest.approx(3e-7)
