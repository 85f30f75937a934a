"""The one acquisition session: headless record, the window, captures and diagnose share a loop."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.core.faults.recording import recorded_fault_events
from app.core.pipeline import Pipeline
from app.core.recording import read_recording
from app.services import acquisition
from app.services.acquisition import Acquisition, Subscriber, Until
from app.services.calibration_runs import capture_device
from app.services.connection import Connection
from app.services.diagnosis import diagnose_events
from app.services.health import HealthMonitor
from app.services.recorder import record_device
from drivers.base import Device
from drivers.errors import DeviceError, DeviceIOError
from drivers.registry import create_device
from drivers.replay import ReplayDevice
from drivers.sim.device import SIMULATOR_REFERENCE, SimulatedDevice

ROOT = Path(__file__).resolve().parents[1]

STUCK = "sim://wobble?fault=stuck:gz@2&realtime=0&seed=4"


@pytest.fixture
def sessions(monkeypatch) -> list[Acquisition]:
    """Every session that streams, so a test can see a consumer went through one."""
    seen: list[Acquisition] = []
    original = Acquisition.stream

    def stream(self, until, timeout_s=acquisition.READ_TIMEOUT_S):
        seen.append(self)
        return original(self, until, timeout_s)

    monkeypatch.setattr(Acquisition, "stream", stream)
    return seen


def test_headless_record_prints_a_stuck_gyro_as_it_happens_and_stores_it(tmp_path, capsys):
    out = tmp_path / "stuck.csv"
    assert main(["record", "--device", STUCK, "--duration", "5", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    stuck = [line for line in printed if line.startswith("sensor gz stuck (fault) at ")]
    assert len(stuck) == 1
    # printed while recording: before the closing summary line
    assert printed.index(stuck[0]) < next(i for i, line in enumerate(printed)
                                          if line.startswith(f"{out}: "))
    events = recorded_fault_events(read_recording(out).metadata)
    faults = [e for e in events if e.severity == "fault"]
    assert [(e.channel, e.kind) for e in faults] == [("gz", "stuck")]
    assert 2.0 <= faults[0].t <= 3.0
    assert f"at {faults[0].t:.2f} s" in stuck[0]


def test_record_and_the_window_store_the_same_fault_events(tmp_path):
    headless = tmp_path / "headless.csv"
    outcome = record_device(SimulatedDevice(STUCK), headless, duration_s=4.0)
    assert outcome.reason == "duration"
    # The window's way: the worker's session (no board round trip, stored in a thread).
    window = tmp_path / "window.csv"
    health = HealthMonitor()
    session = Acquisition(Connection(), Pipeline(), health=health, ask_board_status=False)
    info = session.open(STUCK)
    health.start(info)
    session.start_recording(window, "")
    end = session.run(Until(duration_s=4.0))
    closed = session.stop_recording(background=True)
    session.close()
    for thread in threading.enumerate():
        if thread.name == acquisition.CLOSING_THREAD:
            thread.join(10)
    assert end.reason == "duration" and closed is not None
    ours = recorded_fault_events(read_recording(window).metadata)
    theirs = recorded_fault_events(read_recording(headless).metadata)
    assert [(e.channel, e.kind) for e in theirs] == [(e.channel, e.kind) for e in ours]
    assert ("gz", "stuck") in [(e.channel, e.kind) for e in ours]
    assert [e.t for e in theirs] == pytest.approx([e.t for e in ours])
    assert outcome.fault_events == theirs and closed.fault_events == ours


def test_a_calibration_capture_goes_through_the_session_and_stops_at_its_duration(sessions):
    progress: list[float] = []
    stream = capture_device("sim://static?realtime=0&odr=104", 1.5, progress=progress.append)
    assert len(sessions) == 1 and sessions[0].pipeline is None
    t = stream.block.t_s
    assert t[-1] < t[0] + 1.5 <= t[-1] + 1.5 / len(t) * 2  # cut inside the last block
    assert len(t) == pytest.approx(1.5 * stream.settings.odr_hz, abs=1)
    assert stream.note == "" and progress and progress == sorted(progress)
    assert stream.unit_errors is not None  # a simulator's truth, declared by the driver


def test_a_capture_says_when_the_device_failed(sessions):
    stream = capture_device("sim://static?realtime=0&fail_after=0.5", 3.0)
    assert stream.note.startswith("the device failed after 0.")
    assert "fail_after" in stream.note and len(sessions) == 1


def test_diagnose_goes_through_the_session_and_finds_what_record_stored(tmp_path, sessions):
    events = list(diagnose_events(STUCK, seconds=4.0))
    assert len(sessions) == 1
    assert ("gz", "stuck") in [(e.channel, e.kind) for e in events]
    path = tmp_path / "r.csv"
    stored = record_device(SimulatedDevice(STUCK), path, duration_s=4.0).fault_events
    # the same stream, the same detector stage, the same events
    assert [(e.channel, e.kind, round(e.t, 6)) for e in events] == [
        (e.channel, e.kind, round(e.t, 6)) for e in stored]


def test_diagnose_reads_a_simulator_unpaced_unless_the_url_says(sessions):
    list(diagnose_events("sim://static", seconds=30.0))  # 30 s of device time at once
    assert sessions[0].connection.device is None  # closed at the end
    assert SimulatedDevice.unpaced_url("sim://static") == "sim://static?realtime=0"
    assert SimulatedDevice.unpaced_url("sim://static?odr=52") == "sim://static?odr=52&realtime=0"
    assert SimulatedDevice.unpaced_url("sim://static?realtime=1") == "sim://static?realtime=1"
    assert Device.unpaced_url("replay://x.csv") == "replay://x.csv"


class _Collect(Subscriber):
    def __init__(self) -> None:
        self.blocks = 0
        self.messages: list[str] = []

    def on_block(self, block) -> None:
        self.blocks += 1

    def on_message(self, level: int, text: str) -> None:
        self.messages.append(text)


def test_the_stop_conditions_cut_and_say_why():
    seen = _Collect()
    session = Acquisition(Connection(), subscribers=[seen])
    session.open("sim://static?realtime=0&odr=104&block=50")
    end = session.run(Until(samples=120))
    assert (end.reason, end.samples, seen.blocks) == ("samples", 120, 3)
    stop = threading.Event()
    stop.set()
    assert session.run(Until(stop=stop)).reason == "stopped"
    calls = []
    end = session.run(Until(when=lambda: calls.append(1) or len(calls) == 2))
    assert (end.reason, end.samples) == ("done", 100)
    session.close()
    failing = Acquisition(Connection())
    failing.open("sim://static?realtime=0&fail_after=0.3")
    end = failing.run(Until(duration_s=5.0))
    assert end.reason == "device" and isinstance(end.error, DeviceIOError)
    assert end.samples == pytest.approx(0.3 * 104, abs=2)
    failing.close()


def test_a_replay_ends_the_run_at_its_end(tmp_path):
    path = tmp_path / "short.csv"
    record_device(SimulatedDevice("sim://static?realtime=0&odr=104"), path, duration_s=1.0)
    session = Acquisition(Connection(), Pipeline())
    session.open(f"replay://{path}?speed=0")
    end = session.run(Until(duration_s=60.0))
    session.close()
    assert end.reason == "end" and end.samples == len(read_recording(path))


def test_the_look_alike_check_runs_for_headless_consumers():
    seen = _Collect()
    session = Acquisition(Connection(), subscribers=[seen])
    session.open("sim://static?realtime=0&accel_fs=4&odr=104")
    session.run(Until(when=lambda: session.lookalike.done, wall_s=30.0))
    session.close()
    assert session.lookalike.done
    assert session.lookalike.accel_g == pytest.approx(1.0, abs=0.03)


# -- declared capabilities ------------------------------------------------------------------
class _Bare(Device):
    """A driver that declares nothing beyond the template."""

    def _open(self):  # pragma: no cover - never opened
        raise NotImplementedError

    def _read(self, timeout_s):  # pragma: no cover
        return None

    def _close(self):  # pragma: no cover
        pass


def test_a_device_without_capabilities_answers_with_the_declared_defaults():
    device = _Bare("bare://x")
    assert not (device.replayable or device.steerable or device.knows_truth)
    assert device.at_end is False and device.last_block_generation is None
    assert device.recording is None and device.recorded_calibration is None
    assert device.is_steerable is False and device.reference_source is None
    assert device.unit_errors is None and device.device_clock_origin_s is None
    assert device.request_status() is None and device.supports_self_test is False
    with pytest.raises(DeviceError, match="cannot be tilted"):
        device.set_target_attitude(1.0, 2.0)
    with pytest.raises(DeviceError, match="no self-test"):
        device.self_test()


def test_the_drivers_declare_what_they_have(tmp_path):
    interactive = SimulatedDevice("sim://interactive")
    static = SimulatedDevice("sim://static")
    assert SimulatedDevice.steerable and SimulatedDevice.knows_truth
    assert interactive.is_steerable and not static.is_steerable
    assert static.reference_source == SIMULATOR_REFERENCE and static.unit_errors is not None
    assert ReplayDevice.replayable and not SimulatedDevice.replayable
    path = tmp_path / "ref.csv"
    record_device(SimulatedDevice("sim://static?realtime=0"), path, duration_s=0.5)
    replay = create_device(str(path))
    replay.open()
    try:
        assert replay.reference_source == SIMULATOR_REFERENCE  # as the recording says
        assert replay.last_block_generation == 0 and not replay.at_end
    finally:
        replay.close()
    assert np.isfinite(interactive.set_target_attitude(5.0, 0.0))


_KERNELS_SCRIPT = """
import sys
from PySide6.QtCore import QCoreApplication
from app.core.faults import carry, detector, magnetometer, motion
from app.core import field_check
from app.core.filters import vqf_heading
from app.services import worker as worker_module

kernels = {"fault detector": detector._scan, "band filter": motion._band_filter,
           "noise test": detector._noise_ratios, "bias carry": carry._carry_sums,
           "magnetometer check": magnetometer._scan_field,
           "9-axis default filter": vqf_heading._heading_kernel,
           "field monitor": field_check._lowpass}
app = QCoreApplication([])
opened = {}
real_open = worker_module.Connection.open

def open_(self, url):
    opened.update({name: bool(kernel.signatures) for name, kernel in kernels.items()})
    app.quit()
    return real_open(self, url)

worker_module.Connection.open = open_
from app.services.session import DeviceSession
session = DeviceSession()
session.requestConnect.emit("sim://static?realtime=0&mag=lis3mdl")
app.exec()
session.shutdown()
print(opened)
"""


def test_the_window_loads_every_kernel_a_stream_needs_before_it_opens_the_device():
    """Loaded at the first block, the 9-axis default filter and the fault detector's kernels
    cost a live sensor 10-80 samples at every start (its FIFO overflowed meanwhile). Checked
    in a fresh interpreter, where nothing is loaded yet."""
    result = subprocess.run([sys.executable, "-c", _KERNELS_SCRIPT], capture_output=True,
                            text=True, timeout=300, cwd=ROOT,
                            env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    assert result.returncode == 0, result.stderr
    opened = ast.literal_eval(result.stdout.strip().splitlines()[-1])
    assert opened == {"fault detector": True, "band filter": True, "noise test": True,
                      "bias carry": True, "magnetometer check": True,
                      "9-axis default filter": True, "field monitor": True}


def test_record_loads_the_filters_before_it_opens_the_device(tmp_path, monkeypatch):
    """A realtime device opened first overflowed while the filters compiled (the first
    block came seconds late on a busy machine: samples lost, a link gap event)."""
    from app.cli import record  # the command's own names (bound when it was imported)

    order: list[str] = []
    real_warm_up, real_create = record.warm_up_kernels, record.create_device
    monkeypatch.setattr(record, "warm_up_kernels",
                        lambda *a: order.append("warm up") or real_warm_up(*a))
    monkeypatch.setattr(record, "create_device",
                        lambda url: order.append("create") or real_create(url))
    out = tmp_path / "r.csv"
    assert main(["record", "--device", "sim://static?realtime=0", "--duration", "0.5",
                 "--quiet", str(out)]) == 0
    assert order[:2] == ["warm up", "create"]
