"""app/cli/ as a package: commands imported only when they run, no GUI in the command line,
replay's one summary for both paths, one writer of the calibration JSON keys."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.cli.dispatch import COMMANDS
from app.core.calibration import (
    SensorCalibration,
    TemperatureCompensation,
    calibration_json_text,
    calibration_to_json,
)
from app.core.calibration_procedures.profiles import SensorSettings, make_profile
from app.core.recording.format import calibration_from_json
from app.core.recording.format import calibration_to_json as recording_calibration_json
from app.services.replay_export import ReplayRequest, replay_recording

REPO = Path(__file__).resolve().parents[1]
PROBE = """
import contextlib, io, sys
from app import launcher
argv = sys.argv[1:]
with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):
    launcher.cli.build_parser().parse_args(argv)
print(",".join(sorted(m for m in sys.modules if m.startswith(("app.cli.", "app.gui", "PySide6")))))
"""


def loaded_after_parsing(*argv: str) -> set[str]:
    done = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True,
                          cwd=REPO, env={"PYTHONPATH": str(REPO)}, check=True, timeout=60)
    return set(filter(None, done.stdout.strip().split(",")))


def test_help_imports_no_command_and_no_qt():
    assert loaded_after_parsing("--help") == {"app.cli.dispatch", "app.cli.errors"}


def test_a_command_imports_its_own_module_only():
    loaded = loaded_after_parsing("diagnose", "x.csv")
    assert "app.cli.diagnose" in loaded
    others = {f"app.cli.{module}" for _, module, _ in COMMANDS} - {"app.cli.diagnose"}
    assert not loaded & others
    assert not any(name.startswith(("app.gui", "PySide6")) for name in loaded)


def test_no_command_module_and_no_document_imports_qt_widgets_or_the_gui():
    modules = [f"app.cli.{module}" for _, module, _ in COMMANDS]
    modules += ["app.documents.calibration_report", "app.documents.fault_plots"]
    code = ("import importlib, sys\n"
            f"for name in {modules!r}: importlib.import_module(name)\n"
            "print(sorted(m for m in sys.modules if m.startswith(('app.gui', "
            "'PySide6.QtWidgets', 'pyqtgraph'))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, env={"PYTHONPATH": str(REPO)}, check=True, timeout=120)
    assert done.stdout.strip() == "[]", done.stdout


def test_a_command_error_names_its_command_and_its_exit_status(tmp_path, capsys):
    code = main(["joint", str(tmp_path / "a.csv"), "--out", str(tmp_path / "j.csv")])
    assert code == 2
    err = capsys.readouterr().err
    assert err == ("inclinometer joint: give two recordings (A.csv B.csv) or a session "
                   "manifest (.session.json)\n")


def test_replay_gives_one_summary_for_the_streamed_and_the_whole_file_path(tmp_path):
    wobble = REPO / "resources" / "recordings" / "wobble-104hz.csv"  # with a reference
    streamed = replay_recording(ReplayRequest(wobble, tmp_path / "s.csv", filters=["ekf"]))
    notes: list[str] = []
    whole = replay_recording(ReplayRequest(wobble, tmp_path / "w.csv",
                                           filters=["ekf", "vqf-offline"]), note=notes.append)
    assert streamed.streamed and not whole.streamed and not notes
    assert (streamed.rows, streamed.scored_rows, streamed.masked, streamed.calibration_name) == (
        whole.rows, whole.scored_rows, whole.masked, whole.calibration_name)
    assert streamed.rows > 3000 and 0 < streamed.scored_rows < streamed.rows
    assert streamed.duration_s == pytest.approx(whole.duration_s)
    ekf_streamed, = streamed.filters
    ekf_whole = next(line for line in whole.filters if line.name == "ekf")
    assert [line.name for line in whole.filters] == ["ekf", "vqf-offline"]
    assert ekf_streamed.final_roll_deg == pytest.approx(ekf_whole.final_roll_deg, abs=1e-6)
    assert ekf_streamed.final_pitch_deg == pytest.approx(ekf_whole.final_pitch_deg, abs=1e-6)
    assert ekf_streamed.errors["rmse_deg"] == pytest.approx(ekf_whole.errors["rmse_deg"],
                                                            rel=1e-6)
    assert ekf_streamed.errors["rmse_deg"] < 5.0


def test_the_calibration_keys_are_written_by_one_function():
    temperature = TemperatureCompensation(25.0, accel_k1=np.array([1e-3, 0.0, -2e-3]),
                                          gyro_k1=np.array([0.0, 1e-5, 0.0]))
    calibration = SensorCalibration(accel_bias_m_s2=np.array([0.1, -0.2, 0.05]),
                                    gyro_bias_rad_s=np.array([1e-3, 0.0, -1e-3]),
                                    name="unit 7", temperature=temperature)
    keys = calibration_to_json(calibration)
    assert list(keys)[:4] == ["accel_bias_m_s2", "accel_matrix", "gyro_bias_rad_s",
                              "gyro_matrix"]
    assert keys["temperature_reference_degc"] == 25.0
    profile = make_profile("ABC", calibration, SensorSettings(104.0, 4, 250))
    assert profile.to_json_dict()["parameters"] == keys
    assert recording_calibration_json(calibration) == {"name": "unit 7", **keys}
    back = calibration_from_json(json.loads(calibration_json_text(
        recording_calibration_json(calibration))))
    assert np.allclose(back.accel_bias_m_s2, calibration.accel_bias_m_s2)
    assert np.allclose(back.temperature.accel_k1, temperature.accel_k1)
    with pytest.raises(ValueError):
        calibration_json_text({"accel_bias_m_s2": [float("nan"), 0.0, 0.0]})
