"""The Joint dock, live: two sim://arm sensors, the joint readout and plot against the truth."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from PySide6.QtCore import QSettings

from app.gui import theme
from app.gui.joint_panel import JointPanel, parse_axes_text
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession
from drivers.sim.device import SimulatedDevice

ARM = "sim://arm?seed=3&odr=104&speed=16"
TIMEOUT_MS = 30_000


def joint_error_deg(estimate_deg: np.ndarray, truth_deg: np.ndarray) -> float:
    """RMS difference up to a sign and a constant offset (the angle's zero is arbitrary)."""
    best = math.inf
    for sign in (1.0, -1.0):
        d = np.radians(estimate_deg - sign * truth_deg)
        offset = math.atan2(np.sin(d).mean(), np.cos(d).mean())
        residual = np.degrees(np.angle(np.exp(1j * (d - offset))))
        best = min(best, float(np.sqrt(np.mean(residual ** 2))))
    return best


@pytest.fixture
def window(qtbot, qapp, tmp_path):
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, "sim://static?seed=2")
    qtbot.addWidget(window)
    window.resize(1400, 900)
    window.show()
    yield window
    window.close()


def test_the_joint_dock_shows_the_simulated_arms_joint_angle(qtbot, window, artifacts_dir):
    panel = window.joint_panel
    assert not window.docks["joint"].isVisible()
    window._show_joint(lambda: panel.add_arm(ARM))  # what "Simulated arm (2 links)" does
    assert window.docks["joint"].isVisible()
    qtbot.waitUntil(lambda: panel.group.connected_count() == 2, timeout=TIMEOUT_MS)
    stream = panel.stream
    assert stream is not None
    qtbot.waitUntil(lambda: len(stream.angles) > 0 and
                    stream.angles.latest(1)["device_t"][0] > 45.0, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: panel.value_deg is not None, timeout=TIMEOUT_MS)
    # The plot shows the stream's angles; after the axis settled they follow the truth.
    x, y = panel.curve.getData()
    assert x is not None and len(x) > 500 and int(np.isfinite(y).sum()) > 300
    rows = stream.angles.latest(len(stream.angles))
    late = rows["device_t"] > 20.0
    truth_source = SimulatedDevice(ARM + "&sensor=1")
    t_true = rows["device_t"][late] * truth_source.odr_hz / truth_source.true_odr_hz
    truth = truth_source.scenario.joint_angles_deg(t_true)[:, 0]
    assert joint_error_deg(rows["angle"][late], truth) < 4.0
    # The readout is the averaged angle, in the chosen unit.
    text = panel.readout.text()
    assert text.endswith("°") and abs(float(text[:-1]) - panel.value_deg) < 0.051
    assert "axis: estimated" in panel.quality.text()
    assert "shared clock" in panel.quality.text()
    assert panel.table.rowCount() == 2 and "shared clock" in panel.table.item(0, 1).text()
    assert window.grab().save(os.path.join(artifacts_dir, "joint_dock_sim_arm.png"))
    assert panel.grab().save(os.path.join(artifacts_dir, "joint_panel.png"))
    # Hold freezes the figure; radians change the unit.
    panel.hold_button.setChecked(True)
    held = panel.readout.text()
    qtbot.waitUntil(lambda: stream.angles.latest(1)["device_t"][0] > 50.0, timeout=TIMEOUT_MS)
    assert panel.readout.text() == held
    panel.hold_button.setChecked(False)
    panel.unit_combo.setCurrentIndex(1)
    qtbot.waitUntil(lambda: panel.readout.text().endswith(" rad"), timeout=TIMEOUT_MS)
    assert abs(float(panel.readout.text()[:-4])) <= math.pi + 1e-3


def test_entered_axes_and_bad_input(qtbot) -> None:
    panel = JointPanel()
    qtbot.addWidget(panel)
    try:
        j1, j2 = parse_axes_text("0,0,2:1,0,0")
        assert np.allclose(j1, [0, 0, 1]) and np.allclose(j2, [1, 0, 0])
        for bad in ("1,0,0", "a,b,c:1,0,0", "0,0,0:1,0,0"):
            with pytest.raises(ValueError):
                parse_axes_text(bad)
        assert not panel.start_joint()  # no sensors yet
        assert "two different sensors" in panel.quality.text()
        scenario = SimulatedDevice(ARM + "&sensor=1").scenario
        panel.group.add(ARM)
        panel.group.add(ARM + "&sensor=1")
        qtbot.waitUntil(lambda: panel.group.connected_count() == 2, timeout=TIMEOUT_MS)
        panel.axis_combo.setCurrentIndex(1)
        panel.axis_edit.setText("1,2")
        assert not panel.start_joint() and "Axis:" in panel.quality.text()
        axes = [scenario.axis_in_sensor(1, 0), scenario.axis_in_sensor(1, 1)]
        panel.axis_edit.setText(":".join(",".join(f"{v:.6f}" for v in a) for a in axes))
        assert panel.start_joint()
        qtbot.waitUntil(lambda: panel.value_deg is not None, timeout=TIMEOUT_MS)
        assert "axis: entered" in panel.quality.text()
    finally:
        panel.shutdown()


def test_a_session_recorded_in_the_dock_replays_in_sync(qtbot, tmp_path, artifacts_dir) -> None:
    panel = JointPanel()
    qtbot.addWidget(panel)
    panel.resize(1300, 380)
    try:
        panel.add_arm(ARM)
        qtbot.waitUntil(lambda: panel.group.connected_count() == 2, timeout=TIMEOUT_MS)
        manifest = panel.start_session_recording(tmp_path, "arm")
        assert manifest is not None
        first = panel.group.pipeline(0).samples
        start = first.total_written
        qtbot.waitUntil(lambda: first.total_written - start > 1500, timeout=TIMEOUT_MS)
        with qtbot.waitSignal(panel.group.sessionRecorded, timeout=TIMEOUT_MS):
            panel.group.stop_recording()
        frames: list = []
        panel.attitudesChanged.connect(frames.append)
        assert panel.open_session(manifest, speed=50.0)
        assert panel.group.connected_count() == 0 and panel.replay is not None
        assert panel.table.rowCount() == 2
        replay = panel.replay
        qtbot.waitUntil(lambda: replay.finished, timeout=TIMEOUT_MS)
        qtbot.waitUntil(lambda: panel.value_deg is not None, timeout=TIMEOUT_MS)
        # Both files went through their pipelines to the end, on one clock.
        for k, recording in enumerate(replay.recordings):
            assert replay.pipeline(k).samples.latest(1)["t"][0] == recording.t_s[-1]
        assert "replay" in panel.quality.text()
        # The replayed sensors' newest attitudes are published (3D view and Arm dock).
        final = [replay.pipeline(k).orientation.latest(1)["quat"][-1] for k in range(2)]
        qtbot.waitUntil(lambda: frames and frames[-1] is not None and all(
            np.array_equal(frames[-1].quaternions[k], final[k]) for k in range(2)),
            timeout=TIMEOUT_MS)
        assert panel.grab().save(os.path.join(artifacts_dir, "joint_panel_replay.png"))
        assert not panel.open_session(tmp_path / "missing.session.json")
        assert "cannot read" in panel.quality.text()
    finally:
        panel.shutdown()
