"""The session's parts without Qt: connection, acquisition, recording, replay, calibration, status.

Each runs on real devices (the simulator, the emulated NUCLEO on a pty, a replayed file) and
real files; the Qt worker only wires them (tests/test_worker.py covers the wiring).
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from app.core.calibration import SensorCalibration
from app.core.calibration_procedures import ProfileStore, make_profile
from app.core.pipeline import Pipeline
from app.core.recording import read_recording
from app.services.acquisition import Acquisition
from app.services.calibration_state import CalibrationState, sensor_settings
from app.services.connection import Connection, SelfTestUnavailableError
from app.services.devices import (
    SENSOR_CHOICES,
    SimulatorSettings,
    available_devices,
    is_replay_url,
    replay_url,
)
from app.services.recording_control import RecordingControl
from app.services.replay_control import (
    ReplayCommandError,
    replay_command,
    replay_position,
    restore_recorded_filter,
)
from app.services.stream_status import StatusMeter
from drivers.emulated_nucleo import EmulatedNucleo
from drivers.errors import DeviceIOError

DEADLINE_S = 20.0


def parts(url: str = "sim://static?odr=208&realtime=0&seed=4"):
    """A connection, a pipeline, a recording control and an acquisition over ``url``."""
    pipeline = Pipeline()
    connection = Connection()
    errors: list[str] = []
    recording = RecordingControl(on_error=errors.append, on_status=lambda _status: None)
    messages: list[tuple[int, str]] = []
    acquisition = Acquisition(connection, pipeline, recording,
                              on_message=lambda level, text: messages.append((level, text)))
    info = connection.open(url)
    pipeline.configure(info.odr_hz)
    return connection, pipeline, recording, acquisition, messages


def stream(acquisition: Acquisition, samples: int) -> int:
    """Step until ``samples`` have gone through (each step reads at most one block)."""
    done = 0
    deadline = time.monotonic() + DEADLINE_S
    while done < samples:
        assert time.monotonic() < deadline, f"only {done} of {samples} samples arrived"
        done += acquisition.step()
    return done


# -- connection and acquisition ------------------------------------------------------------
def test_acquisition_moves_samples_into_the_pipeline_and_nothing_without_a_device():
    connection, pipeline, _rec, acquisition, _msgs = parts()
    assert acquisition.last_sample_time() is None
    done = stream(acquisition, 1000)
    assert pipeline.counters.samples == done
    t = pipeline.samples.latest(done)["t"]
    assert np.all(np.diff(t) > 0)
    assert acquisition.last_sample_time() == pytest.approx(t[-1])
    assert connection.close() == (True, False)
    assert connection.close() == (False, False)  # closing twice is harmless
    assert acquisition.step() == 0


def test_a_simulator_cannot_be_awaited_after_a_failure():
    connection, _p, _rec, acquisition, _msgs = parts("sim://static?odr=416&fail_after=0.2")
    with pytest.raises(DeviceIOError):
        stream(acquisition, 10**6)
    # No USB serial number: nothing to wait for, the caller ends the session.
    assert connection.await_board("unplugged", acquisition.last_sample_time()) is None
    assert connection.device is not None and not connection.awaiting


def test_self_test_is_refused_clearly_without_one():
    connection, *_ = parts()
    with pytest.raises(SelfTestUnavailableError, match="no self-test"):
        connection.self_test()


def test_an_unplugged_board_is_awaited_and_its_time_axis_runs_on():
    board = EmulatedNucleo("static", odr_hz=104.0, seed=12)
    try:
        connection, pipeline, _rec, acquisition, _msgs = parts(board.port)
        info = connection.device.info
        stream(acquisition, 150)
        report = connection.self_test()  # the board runs ST's self-test
        assert report.passed
        board.close()
        deadline = time.monotonic() + DEADLINE_S
        with pytest.raises(DeviceIOError):
            while time.monotonic() < deadline:
                acquisition.step()
        last_t = acquisition.last_sample_time()
        message = connection.await_board("the cable was pulled", last_t)
        assert message is not None and info.extra["usb_serial"] in message
        assert connection.awaiting and connection.device is None
        assert connection.try_reconnect() is None  # still unplugged
        board.replug()
        deadline = time.monotonic() + DEADLINE_S
        back = None
        while back is None:
            assert time.monotonic() < deadline, "the board did not come back"
            back = connection.try_reconnect()
        assert back.unique_id == info.unique_id
        before = pipeline.counters.samples
        stream(acquisition, 50)
        rows = pipeline.samples.latest(pipeline.counters.samples, ["t", "gap"])
        assert np.all(np.diff(rows["t"]) > 0)  # time runs on across the outage
        assert rows["gap"][before] == 1.0  # and the outage is marked
        assert not connection.awaiting
        connection.close()
    finally:
        board.close()


# -- recording -----------------------------------------------------------------------------
def test_recording_control_writes_what_the_pipeline_saw(tmp_path):
    connection, pipeline, recording, acquisition, _msgs = parts()
    path = tmp_path / "live.csv"
    with pytest.raises(ValueError, match="Connect a device"):
        recording.start(None, pipeline, str(path), "")
    status = recording.start(connection.device, pipeline, str(path), "bench test")
    assert recording.active and status.error is None
    done = stream(acquisition, 600)
    final = recording.stop()
    assert final is not None and final.error is None and not recording.active
    assert recording.stop() is None
    recorded = read_recording(path)
    assert len(recorded.t_s) == done
    assert recorded.note == "bench test"
    np.testing.assert_allclose(recorded.t_s, pipeline.samples.latest(done)["t"], atol=1e-6)
    connection.close()


# -- replay --------------------------------------------------------------------------------
@pytest.fixture
def replay_file(tmp_path):
    connection, pipeline, recording, acquisition, _msgs = parts(
        "sim://wobble?odr=104&realtime=0&seed=5")
    pipeline.set_filter("mahony")
    path = tmp_path / "wobble.csv"
    recording.start(connection.device, pipeline, str(path), "")
    stream(acquisition, 1040)
    recording.stop()
    connection.close()
    return path


def test_replay_controls_and_the_recorded_filter(replay_file):
    pipeline = Pipeline()
    connection = Connection()
    info = connection.open(replay_url(replay_file) + "?paused=1")
    device = connection.device
    restored = restore_recorded_filter(device, pipeline)
    assert restored.orientation_filter is not None and pipeline.filter.name == "mahony"
    assert not restored.error
    pipeline.configure(info.odr_hz)
    position, duration, playing, *_ = replay_position(device)
    assert duration > 9.0
    assert duration == pytest.approx(read_recording(replay_file).duration_s)
    assert position == 0.0 and not playing
    replay_command(device, pipeline, "seek", 4.0)
    assert replay_position(device)[0] == pytest.approx(4.0, abs=0.02)
    with pytest.raises(ReplayCommandError, match="No further gap"):
        replay_command(device, pipeline, "next_gap", None)
    with pytest.raises(ReplayCommandError, match="No further bookmark"):
        replay_command(device, pipeline, "next_bookmark", None)
    replay_command(device, pipeline, "add_bookmark", None)
    replay_command(device, pipeline, "seek", 1.0)
    replay_command(device, pipeline, "next_bookmark", None)
    assert replay_position(device)[0] == pytest.approx(4.0, abs=0.02)
    with pytest.raises(ReplayCommandError, match="unknown replay command"):
        replay_command(device, pipeline, "rewind", None)
    connection.close()


def test_replay_commands_leave_other_devices_alone():
    connection, pipeline, *_ = parts()
    assert replay_position(connection.device) is None
    replay_command(connection.device, pipeline, "seek", 3.0)  # nothing happens, no error
    assert restore_recorded_filter(connection.device, pipeline).orientation_filter is None
    connection.close()


# -- calibration and tare ------------------------------------------------------------------
def test_calibration_state_applies_the_stored_profile_and_reports_a_bad_one(tmp_path):
    connection, pipeline, _rec, acquisition, _msgs = parts()
    info = connection.device.info
    store = ProfileStore(tmp_path / "profiles")
    state = CalibrationState(pipeline, store)
    assert state.load_for(info, connection.device) == [] and state.profile is None

    calibration = SensorCalibration(gyro_bias_rad_s=np.array([0.01, -0.02, 0.003]), name="t")
    profile = make_profile(info.unique_id, calibration, sensor_settings(info), method="test")
    assert state.use(profile) == ""
    assert state.profile is profile
    np.testing.assert_allclose(pipeline.calibration.gyro_bias_rad_s, [0.01, -0.02, 0.003])

    fresh = CalibrationState(Pipeline(), store)
    assert fresh.load_for(info, connection.device) == []
    assert fresh.profile is not None and fresh.profile.calibration.name == "t"

    store.path_for(info.unique_id).write_text(json.dumps({"format": "nonsense"}))
    problems = CalibrationState(Pipeline(), store).load_for(info, connection.device)
    assert len(problems) == 1 and problems[0].startswith("Calibration profile not loaded")

    with pytest.raises(ValueError, match="Nothing to tare"):
        CalibrationState(Pipeline(), store).tare()
    stream(acquisition, 300)
    reference = state.tare()
    assert state.tare_reference is reference
    assert state.set_tare(None) is None
    connection.close()


# -- status and the device catalogue -------------------------------------------------------
def test_status_meter_measures_rate_and_load_on_its_clock():
    now = [100.0]
    meter = StatusMeter(window_s=2.0, clock=lambda: now[0])
    meter.reset(filter_cpu_s=0.0)
    assert meter.measure(0, 0.0) == (0.0, 0.0)
    for step in range(1, 21):
        now[0] += 0.25
        rate, load = meter.measure(step * 52, step * 0.025)
    assert rate == pytest.approx(208.0)
    assert load == pytest.approx(0.1)


def test_simulator_settings_round_trip_and_scenario_full_scales():
    settings = SimulatorSettings("interactive", 52.0, 2, 500, 7, roll_deg=12.5, pitch_deg=-3.0)
    assert SimulatorSettings.from_url(settings.url()) == settings
    assert SimulatorSettings.from_url("sim://nosuch") is None
    handheld = SimulatorSettings.defaults("handheld")
    assert handheld.gyro_fs_dps > 250  # a hand-held motion needs more than the default
    assert handheld.gyro_fs_dps in SENSOR_CHOICES.gyro_fs_dps
    assert "roll" not in handheld.url()
    scenarios = [d for d in available_devices() if d.kind == "simulator"]
    assert any(d.url.startswith("sim://handheld") for d in scenarios)
    assert is_replay_url(replay_url("/tmp/a b.csv")) and not is_replay_url("sim://static")
    assert not is_replay_url("not a url")


def test_status_meter_starts_afresh_when_the_count_restarts():
    now = [0.0]
    meter = StatusMeter(window_s=2.0, clock=lambda: now[0])
    meter.reset(0.0)
    for step in range(1, 9):
        now[0] += 0.25
        meter.measure(step * 100, 0.0)
    now[0] += 0.25
    rate, _load = meter.measure(10, 0.0)  # a seek cleared the pipeline's counters
    assert rate == 0.0
    now[0] += 0.25
    rate, _load = meter.measure(110, 0.0)
    assert rate == pytest.approx(400.0)


@pytest.mark.parametrize(("part", "warned"), [("lsm6dso32", True), ("lsm6dsox", False)])
def test_a_look_alike_part_reading_half_the_acceleration_is_a_device_message(part, warned):
    url = f"lsm6dsox://emulated?scenario=static&odr=208&seed=3&part={part}"
    connection, _pipeline, _rec, acquisition, messages = parts(url)
    deadline = time.monotonic() + DEADLINE_S
    while not acquisition.lookalike.done:
        assert time.monotonic() < deadline, "no verdict on a sensor at rest"
        acquisition.step()
    connection.close()
    warnings = [text for level, text in messages if level == 2 and "at rest" in text]
    assert acquisition.lookalike.accel_g == pytest.approx(0.5 if warned else 1.0, abs=0.03)
    if warned:
        assert len(warnings) == 1 and "LSM6DSO32" in warnings[0]
        assert warnings[0].startswith("sensor: accelerometer reads 0.5")
    else:
        assert warnings == []
