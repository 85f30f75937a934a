"""``inclinometer record``, ``replay`` and ``evaluate IN.csv`` on small files."""

from __future__ import annotations

import io
import os
import re
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.cli.devices import list_devices
from app.core.evaluation import calibration_from_unit_errors
from app.core.recording import RecordingWarning, read_recording
from app.services.recorder import record_device
from drivers.sim.device import SimulatedDevice

ROOT = Path(__file__).resolve().parent.parent


def read_angles(path: Path) -> dict[str, np.ndarray]:
    """An angles export as columns (the numbers are exact: written with repr)."""
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    names = lines[0].split(",")
    rows = np.array([[float(x) if x else np.nan for x in line.split(",")] for line in lines[1:]])
    return {name: rows[:, k] for k, name in enumerate(names)}


def test_record_from_the_simulator_as_fast_as_possible(tmp_path, capsys):
    out = tmp_path / "tour.csv"
    code = main(["record", "--device", "sim://tour?odr=104&realtime=0&seed=3",
                 "--duration", "12", "--filter", "madgwick", "--compare", "ekf,vqf",
                 "--compare", "accel", "--note", "bench run", "--quiet", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    recording = read_recording(out)
    assert f"{out}: {len(recording)} rows, 12.0 s of device time (duration reached)" in printed
    odr = recording.device["odr_hz"]
    assert len(recording) == int(np.ceil(12.0 * odr))  # every sample with t < 12 s
    assert recording.t_s[-1] < 12.0 <= recording.t_s[-1] + 1.0 / odr
    assert recording.filter_name == "madgwick" and recording.note == "bench run"
    assert [c["name"] for c in recording.metadata["comparison_filters"]] == ["ekf", "vqf",
                                                                            "accel"]
    assert recording.has_reference
    assert recording.metadata["reference"] == {"source": "the simulator's true orientation"}
    assert recording.metadata["simulator"]["unit_errors"]["seed"] == 3


def test_record_a_realtime_simulator(tmp_path, capsys):
    out = tmp_path / "live.csv"
    assert main(["record", "--device", "sim://static?odr=104", "--duration", "0.3",
                 "--quiet", str(out)]) == 0
    recording = read_recording(out)
    assert recording.device["extra"]["realtime"] is True
    assert len(recording) == int(np.ceil(0.3 * recording.device["odr_hz"]))


def test_record_refuses_bad_arguments_and_existing_files(tmp_path, capsys):
    out = tmp_path / "x.csv"
    assert main(["record", "--device", "nosuch://x", str(out)]) == 2
    assert "no driver for nosuch://" in capsys.readouterr().err
    assert main(["record", "--device", "sim://static", "--filter", "nope", str(out)]) == 2
    assert "no filter 'nope'" in capsys.readouterr().err
    assert main(["record", "--device", "sim://static", "--duration", "soon", str(out)]) == 2
    assert "--duration 'soon'" in capsys.readouterr().err
    out.write_text("keep me")
    assert main(["record", "--device", "sim://static?realtime=0", "--duration", "1",
                 str(out)]) == 1
    assert "exists" in capsys.readouterr().err and out.read_text() == "keep me"


def test_replay_exports_exactly_the_angles_of_the_live_run(tmp_path, capsys):
    sim = SimulatedDevice("sim://translation?odr=208&seed=9", realtime=False, block=6)
    source = tmp_path / "run.csv"
    outcome = record_device(sim, source, duration_s=6.0, filter_name="vqf",
                            comparisons=["ekf", "mahony"],
                            calibration=calibration_from_unit_errors(sim.unit_errors))
    live = outcome.pipeline
    n = live.counters.samples
    angles = tmp_path / "angles.csv"
    assert main(["replay", str(source), "--filter", "vqf", "ekf", "mahony",
                 "--out", str(angles)]) == 0
    printed = capsys.readouterr().out
    assert f"{angles}: {n} rows" in printed and "true errors of seed 9" in printed
    assert re.search(r"^\s+vqf\s+-?\d+\.\d{3}\s+-?\d+\.\d{3}\s+\d+\.\d{3}", printed, re.M)
    table = read_angles(angles)
    assert np.array_equal(table["t"], live.orientation.latest(n)["t"])
    for name in ("roll", "pitch", "tilt", "direction"):
        assert np.array_equal(table[f"vqf.{name}"], live.orientation.latest(n)[name])
    for other in ("ekf", "mahony"):
        buffer = live.comparison_buffers[other].latest(n)
        assert np.array_equal(table[f"{other}.roll"], buffer["roll"])
        assert np.array_equal(table[f"{other}.pitch"], buffer["pitch"])
        assert np.array_equal(table[f"{other}.inclination_error"], buffer["incl_error"])
    assert np.array_equal(table["vqf.inclination_error"], live.orientation.latest(n)["incl_error"])
    assert {"reference.roll", "vqf.qw", "ekf.qz"} <= set(table)
    # --raw drops the recorded calibration: other numbers.
    raw = tmp_path / "raw.csv"
    assert main(["replay", str(source), "--raw", "--out", str(raw)]) == 0
    assert "no calibration" in capsys.readouterr().out
    assert not np.array_equal(read_angles(raw)["vqf.roll"], table["vqf.roll"])
    assert main(["replay", str(source), "--out", str(source)]) == 2
    assert "overwrite the recording" in capsys.readouterr().err


def test_evaluate_scores_a_recording_against_its_reference(tmp_path, capsys):
    source = tmp_path / "wobble.csv"
    assert main(["record", "--device", "sim://wobble?odr=104&realtime=0", "--duration", "10",
                 "--quiet", str(source)]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(source), "--filter", "ekf", "accel"]) == 0
    printed = capsys.readouterr().out
    assert f"{source} (recorded calibration 'uncalibrated' applied)" in printed
    assert "10 s, " in printed and "first 2 s not scored" in printed
    scores = dict(re.findall(r"^\s+(ekf|accel)\s+(\d+\.\d+)", printed, re.M))
    assert set(scores) == {"ekf", "accel"} and float(scores["ekf"]) < 10.0
    assert main(["evaluate", f"replay://{source}", "--raw", "--filter", "ekf"]) == 0
    assert "raw samples (--raw)" in capsys.readouterr().out

    plain = tmp_path / "plain.csv"
    plain.write_text("# inclinometer-recording 1\nt,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n")
    assert main(["evaluate", str(plain)]) == 2
    assert "no reference orientation" in capsys.readouterr().err
    garbled = tmp_path / "garbled.csv"
    garbled.write_text("# inclinometer-recording 1\nt,ax,ay,az,gx,gy,gz\n0,0,0,x,0,0,0\n")
    assert main(["evaluate", str(garbled)]) == 2
    assert "line 3: column 'az' holds 'x'" in capsys.readouterr().err


def test_the_sample_recordings_are_listed_as_devices():
    out = io.StringIO()
    assert list_devices(out) == 0
    listing = out.getvalue()
    assert re.search(r"^replay://\S+tour-104hz\.csv\s+recording\s+Sample recording", listing,
                     re.M)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_ctrl_c_stops_a_recording_cleanly_and_keeps_the_file(tmp_path):
    out = tmp_path / "stopped.csv"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    process = subprocess.Popen(
        [sys.executable, "-m", "app", "record", "--device", "sim://wobble?odr=208", str(out)],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        for line in process.stderr:  # wait until rows are on disk
            if re.search(r"[1-9]\d* rows on disk", line):
                break
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, stderr
    assert "(stopped by Ctrl-C)" in stdout
    rows = int(re.search(r": (\d+) rows", stdout).group(1))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)  # no incomplete last row
        recording = read_recording(out)
    assert len(recording) == rows > 0
