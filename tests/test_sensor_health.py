"""The fault detector watches the live stream: lights, banner, messages, recordings, replay."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.faults.recording import recorded_fault_events
from app.core.pipeline import Pipeline
from app.core.recording import read_recording
from app.services.acquisition import Acquisition
from app.services.connection import Connection
from app.services.health import HealthMonitor, recorded_events_note
from app.services.recording_control import RecordingControl
from app.services.session import DeviceSession

TIMEOUT_MS = 20_000
STUCK = "sim://static?odr=104&realtime=0&fault=stuck:gz@2"


def test_the_health_monitor_finds_a_stuck_gyro_and_keeps_a_recording_s_events(tmp_path):
    events = []
    health = HealthMonitor()
    connection = Connection()
    pipeline = Pipeline()
    acquisition = Acquisition(connection, pipeline,
                              RecordingControl(on_error=print, on_status=lambda _s: None),
                              on_message=lambda *_: None, health=health,
                              on_events=events.extend)
    info = connection.open(STUCK)
    pipeline.configure(info.odr_hz)
    health.start(info)
    health.begin_recording()
    while pipeline.counters.samples < 104 * 5:
        acquisition.step()
    assert [(e.channel, e.kind) for e in events] == [("gz", "stuck")]
    assert 2.0 <= events[0].t <= 3.0
    assert health.health()["gz"] == "fault" and health.health()["gx"] == "ok"
    assert health.latest_fault() is events[0]
    target = tmp_path / "none.csv"
    assert health.end_recording(None, print) == 0  # nothing to store without a file
    health.begin_recording()
    health.reset()
    assert health.health()["gz"] == "ok"
    assert target.exists() is False
    connection.close()


def test_a_clean_stream_lights_green_and_stays_quiet():
    health = HealthMonitor()
    connection = Connection()
    pipeline = Pipeline()
    events = []
    acquisition = Acquisition(connection, pipeline,
                              RecordingControl(on_error=print, on_status=lambda _s: None),
                              on_message=lambda *_: None, health=health,
                              on_events=events.extend)
    info = connection.open("sim://wobble?odr=208&realtime=0&seed=3")
    pipeline.configure(info.odr_hz)
    health.start(info)
    while pipeline.counters.samples < 208 * 20:
        acquisition.step()
    assert events == []
    assert set(health.health().values()) == {"ok"}
    connection.close()


@pytest.fixture
def session(qtbot):
    session = DeviceSession()
    yield session
    session.shutdown()


def test_the_session_reports_faults_and_stores_them_in_the_recording(qtbot, session, tmp_path):
    statuses = []
    session.status.connect(statuses.append)
    found = []
    session.faultEvents.connect(found.extend)
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        session.requestConnect.emit("sim://static?odr=104&fault=stuck:gz@1.5")
    path = tmp_path / "faulty.csv"
    with qtbot.waitSignal(session.recordingChanged, timeout=TIMEOUT_MS):
        session.requestStartRecording.emit(str(path), "stuck gyro")
    qtbot.waitUntil(lambda: len(found) > 0, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: bool(statuses) and statuses[-1].fault.startswith("gz stuck"),
                    timeout=TIMEOUT_MS)
    assert statuses[-1].health["gz"] == "fault"
    messages = []
    session.deviceMessage.connect(lambda _level, text: messages.append(text))
    with qtbot.waitSignal(session.recordingChanged, timeout=TIMEOUT_MS):
        session.requestStopRecording.emit()
    qtbot.waitUntil(lambda: any("stored in faulty.csv" in m for m in messages),
                    timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: len(recorded_fault_events(read_recording(path).metadata)) > 0,
                    timeout=TIMEOUT_MS)
    stored = recorded_fault_events(read_recording(path).metadata)
    assert [(e.channel, e.kind) for e in stored] == [("gz", "stuck")]
    assert "1 fault event(s)" in recorded_events_note(read_recording(path).metadata)
    # The replay says what the recording holds, and the detector finds it again.
    notes = []
    session.deviceMessage.connect(lambda _level, text: notes.append(text))
    replayed = []
    session.faultEvents.connect(replayed.extend)
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        session.requestConnect.emit(str(path))
    qtbot.waitUntil(lambda: any("holds 1 fault event" in n for n in notes), timeout=TIMEOUT_MS)
    session.requestReplayControl.emit("speed", 0)
    qtbot.waitUntil(lambda: any(e.kind == "stuck" for e in replayed), timeout=TIMEOUT_MS)


def test_the_window_shows_the_lights_and_the_banner(qtbot, tmp_path, artifacts_dir):
    from PySide6.QtCore import QSettings

    from app.gui.main_window import MainWindow

    session = DeviceSession()
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(session, settings, "sim://static?odr=104&fault=stuck:gz@1", None)
    qtbot.addWidget(window)
    window.resize(1280, 800)
    window.show()
    try:
        qtbot.waitUntil(lambda: window.health_lights.state.get("gz") == "fault",
                        timeout=TIMEOUT_MS)
        assert window.health_lights.state["ax"] == "ok"
        assert window.banner.isVisible() and "cannot be trusted" in window.banner.label.text()
        assert "gz stuck" in window.messages.toPlainText()
        window.grab().save(f"{artifacts_dir}/sensor_fault.png")
        window.health_lights.resetRequested.emit()
        qtbot.waitUntil(lambda: "Fault detection reset" in window.messages.toPlainText(),
                        timeout=TIMEOUT_MS)
        image = window.health_lights.grab().toImage()
        assert image.width() > 50 and not np.all(np.asarray(image.constBits()) == 0)
    finally:
        session.shutdown()
