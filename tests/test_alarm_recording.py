"""Alarm crossings in recordings: ``record --alarm`` prints and stores them, the worker stores
them with the fault events, and a replay reads them back (note and marks)."""

from __future__ import annotations

import re
import threading

import pytest

from app.cli import main
from app.core.alarms import (
    AlarmConfig,
    AlarmMonitor,
    alarm_events_metadata,
    parse_alarm,
    recorded_alarm_events,
)
from app.core.pipeline import Pipeline
from app.core.recording import read_recording
from app.services.acquisition import Acquisition
from app.services.connection import Connection
from app.services.health import HealthMonitor
from app.services.recording_control import RecordingControl
from app.services.replay_control import recorded_alarm_marks, recorded_alarms_note
from drivers.replay import ReplayDevice

# Roll swings +-10° with a 4 s period (pitch stays near 0): above 5° from 1/3 s to 5/3 s.
SWING = "sim://slow-tilt?odr=104&realtime=0&amplitude=10&roll_period=4&pitch_period=1000&seed=2"


def test_record_prints_each_crossing_and_stores_them(tmp_path, capsys):
    out = tmp_path / "swing.csv"
    assert main(["record", "--device", SWING, "--duration", "6", "--quiet",
                 "--alarm", "roll>5,hyst=0.5,delay=0.2", "--alarm", "|pitch|>3", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    crossings = [line for line in printed if " alarm " in line]
    assert [re.match(r"roll alarm (\w+) at", line)[1] for line in crossings] == [
        "raised", "cleared", "raised", "cleared"]
    times = [float(re.search(r"at (\d+\.\d+) s", line)[1]) for line in crossings]
    # Roll passes 5° at 1/3 s and 4 + 1/3 s; 0.2 s later it is raised (filter lag: < 0.1 s).
    assert times[0] == pytest.approx(1 / 3 + 0.2, abs=0.1)
    assert times[2] == pytest.approx(4 + 1 / 3 + 0.2, abs=0.1)
    assert "(roll>5,hyst=0.5,delay=0.2)" in crossings[0]
    assert printed[-1].startswith(f"{out}: ")  # the summary comes after the crossings
    recording = read_recording(out)
    stored = recorded_alarm_events(recording.metadata)
    assert [(e.state, round(e.t, 2)) for e in stored] == [
        ("raised", times[0]), ("cleared", times[1]), ("raised", times[2]),
        ("cleared", times[3])]
    assert recording.metadata["alarms"] == ["roll>5,hyst=0.5,delay=0.2",
                                            "|pitch|>3,hyst=0.1,delay=0.5"]
    # A replay finds them: a note for Messages and marks on the overview.
    assert "4 alarm crossing(s)" in recorded_alarms_note(recording.metadata)
    replay = ReplayDevice(f"replay://{out}")
    replay.open()
    try:
        marks = recorded_alarm_marks(replay)
    finally:
        replay.close()
    start = float(recording.t_s[0])
    assert marks == pytest.approx((stored[0].t - start, stored[2].t - start))


def test_record_refuses_a_bad_alarm_and_records_nothing(tmp_path, capsys):
    out = tmp_path / "x.csv"
    assert main(["record", "--device", SWING, "--alarm", "yaw>2", str(out)]) == 2
    assert "--alarm: alarm 'yaw>2': no quantity 'yaw'" in capsys.readouterr().err
    assert not out.exists()


def test_a_recording_without_alarms_has_no_alarm_keys(tmp_path, capsys):
    out = tmp_path / "plain.csv"
    assert main(["record", "--device", SWING, "--duration", "1", "--quiet", str(out)]) == 0
    assert " alarm " not in capsys.readouterr().out
    metadata = read_recording(out).metadata
    assert "alarms" not in metadata and "alarm_events" not in metadata


def test_the_live_acquisition_stores_crossings_with_the_fault_events(tmp_path):
    crossings = []
    connection, pipeline, health = Connection(), Pipeline(), HealthMonitor()
    alarms = AlarmMonitor(AlarmConfig((parse_alarm("roll>5,hyst=0.5,delay=0.2"),)))
    recording = RecordingControl(on_error=print, on_status=lambda _s: None)
    acquisition = Acquisition(connection, pipeline, recording, on_message=lambda *_: None,
                              health=health, alarms=alarms, on_alarms=crossings.extend)
    info = connection.open(SWING)
    pipeline.configure(info.odr_hz)
    health.start(info)
    path = tmp_path / "live.csv"
    recording.start(connection.device, pipeline, str(path), "", extra={"alarms": ["roll>5"]})
    health.begin_recording()
    alarms.begin_recording()
    while len(crossings) < 2:
        acquisition.step()
    status = recording.stop()
    connection.close()
    assert [e.state for e in crossings[:2]] == ["raised", "cleared"]
    assert alarms.active() == () or crossings[-1].raised
    kept = alarms.end_recording()
    assert kept == crossings
    saved = []
    health.end_recording(status.path, saved.append,
                         also=alarm_events_metadata(kept, alarms.config))
    for thread in threading.enumerate():
        if thread.name == "save-fault-events":
            thread.join(10)
    assert saved == []
    metadata = read_recording(path).metadata
    assert recorded_alarm_events(metadata) == crossings
    assert metadata["alarms"] == ["roll>5,hyst=0.5,delay=0.2"]


@pytest.fixture
def session(qtbot):
    from app.services.session import DeviceSession

    session = DeviceSession()
    yield session
    session.shutdown()


def test_the_session_stores_crossings_and_fault_events_in_one_recording(qtbot, session,
                                                                         tmp_path):
    from app.core.faults.recording import recorded_fault_events

    timeout = 15_000
    crossings, faults, messages = [], [], []
    session.alarmEvents.connect(crossings.extend)
    session.faultEvents.connect(faults.extend)
    session.deviceMessage.connect(lambda _level, text: messages.append(text))
    with qtbot.waitSignal(session.connected, timeout=timeout):
        session.requestConnect.emit("sim://interactive?odr=104&roll=4&errors=0"
                                    "&fault=stuck:gz@2")
    path = tmp_path / "both.csv"
    with qtbot.waitSignal(session.recordingChanged, timeout=timeout):
        session.requestStartRecording.emit(str(path), "")
    # Watched from now on: the raise comes after the delay, inside the recording.
    session.requestAlarms.emit(AlarmConfig((parse_alarm("roll>2,delay=0.2"),)))
    qtbot.waitUntil(lambda: bool(crossings) and bool(faults), timeout=timeout)
    with qtbot.waitSignal(session.recordingChanged, timeout=timeout):
        session.requestStopRecording.emit()
    qtbot.waitUntil(lambda: any("alarm crossing(s) stored in both.csv" in m for m in messages),
                    timeout=timeout)
    qtbot.waitUntil(lambda: "alarm_events" in read_recording(path).metadata, timeout=timeout)
    metadata = read_recording(path).metadata
    assert recorded_alarm_events(metadata) == crossings[:1]
    assert crossings[0].raised and crossings[0].value > 2
    assert [(e.channel, e.kind) for e in recorded_fault_events(metadata)] == [("gz", "stuck")]
    assert metadata["alarms"] == ["roll>2,hyst=0.1,delay=0.2"]  # in force at the end
    # Replayed: the note, and the raise marked for the overview.
    statuses = []
    session.status.connect(statuses.append)
    with qtbot.waitSignal(session.connected, timeout=timeout):
        session.requestConnect.emit(str(path))
    qtbot.waitUntil(lambda: any("holds 1 alarm crossing(s)" in m for m in messages),
                    timeout=timeout)
    qtbot.waitUntil(lambda: any(s.alarm_marks_s for s in statuses), timeout=timeout)
    marks = next(s.alarm_marks_s for s in statuses if s.alarm_marks_s)
    start = float(read_recording(path).t_s[0])
    assert marks == pytest.approx((crossings[0].t - start,))
