"""Every hostile input of issue 36 through every command that takes it: exit status 2 and one
line on stderr, never a traceback (the corpus: tests/hostile_corpus.py).

In-process through ``app.cli.main`` for speed; a few through the real command in a
subprocess. benchmarks/hostile_inputs.py prints the same corpus as a table.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from hostile_corpus import (
    RATE_HZ,
    corpus_cases,
    pipe_path,
    recording_text,
    write_files,
)

import app.cli.devices as cli_devices
import app.cli.errors as cli_errors
from app.cli import main

CASES = corpus_cases(Path("/corpus"))
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("hostile")
    write_files(root)
    return root


def run(argv: list[str], capsys) -> tuple[int, str]:
    """``inclinometer ARGV`` in-process: (exit status, stderr)."""
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    return code, capsys.readouterr().err


def assert_one_line(code: int, err: str, expected: int = 2) -> str:
    assert code == expected, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("inclinometer"), err
    return lines[0]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("index", range(len(CASES)),
                         ids=[f"{c.command}:{c.input}" for c in CASES])
def test_a_hostile_input_ends_in_one_line_and_exit_2(index, corpus, capsys):
    case = corpus_cases(corpus)[index]
    code, err = run(list(case.argv), capsys)
    assert_one_line(code, err)
    outputs = [Path(a) for a in case.argv if a.startswith(str(corpus)) and "/rec-" in a]
    assert not any(p.exists() for p in outputs), "a refused record must not leave a file"


def test_a_pipe_as_the_recording_is_refused_by_replay_evaluate_and_allan(tmp_path, capsys):
    data = recording_text(rows=50).encode()
    for argv in (["replay", "{}", "--out", str(tmp_path / "a.csv")], ["evaluate", "{}"],
                 ["allan", "{}"], ["export", "{}", "--format", "mcap", str(tmp_path / "a.mcap")]):
        path, fd = pipe_path(data)
        try:
            code, err = run([a.replace("{}", path) for a in argv], capsys)
        finally:
            os.close(fd)
        line = assert_one_line(code, err)
        assert path in line
    assert not (tmp_path / "a.csv").exists() and not (tmp_path / "a.mcap").exists()


def test_an_invalid_recorded_calibration_is_refused_unless_raw(corpus, capsys):
    source = str(corpus / "bad-calibration.csv")
    line = assert_one_line(*run(["replay", source, "--out", str(corpus / "x.csv")], capsys))
    assert "recorded calibration is invalid" in line and "--raw" in line
    code, err = run(["replay", source, "--raw", "--out", str(corpus / "raw.csv")], capsys)
    assert code == 0, err
    assert (corpus / "raw.csv").stat().st_size > 0
    line = assert_one_line(*run(["export", source, "--format", "euroc",
                                 str(corpus / "imu0.csv")], capsys))
    assert "recorded calibration is invalid" in line and "--raw" in line
    assert not (corpus / "imu0.csv").exists()


def test_odr_1e9_is_refused_where_1000_snaps(capsys):
    from drivers.sim.options import parse_sim_url

    line = assert_one_line(*run(["diagnose", "sim://static?odr=1e9", "--seconds", "0.1"],
                                capsys))
    assert "outside the LSM6DSOX's rates" in line
    assert parse_sim_url("sim://static?odr=1000").odr_nominal_hz == 833.0


def test_allan_json_writes_a_figure_it_cannot_give_as_null(corpus, monkeypatch, capsys):
    """A NaN figure (here the first gyro axis's noise density) is null in the JSON file,
    which stays valid JSON; the other figures are kept."""
    from dataclasses import replace

    import app.core.allan as allan

    real = allan.analyse_static

    def with_a_nan(*args, **kwargs):
        result = real(*args, **kwargs)
        axes = result.gyro.axes
        gyro = replace(result.gyro, axes=(replace(axes[0], noise_density=float("nan")),
                                          *axes[1:]))
        return replace(result, gyro=gyro)

    monkeypatch.setattr(allan, "analyse_static", with_a_nan)
    # Allan needs 30 s at rest for a noise density: a still board for 40 s.
    still = corpus / "still-40s.csv"
    still.write_text(recording_text(rows=int(40 * RATE_HZ)), encoding="utf-8")
    target = corpus / "allan.json"
    code, err = run(["allan", str(still), "--json", str(target)], capsys)
    assert code == 0, err
    document = json.loads(target.read_text(encoding="utf-8"))
    density = document["gyro"]["noise_density"]
    assert density[0] is None
    assert all(isinstance(v, float) for v in density[1:])


def test_a_warning_is_one_line_without_python_source(tmp_path, capsys):
    path = tmp_path / "meta.csv"
    text = recording_text(rows=200)
    path.write_text(text.replace("# device:", "# note: not json\n# device:", 1),
                    encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        code, err = run(["diagnose", str(path)], capsys)
    assert code == 0, err
    warned = [line for line in err.splitlines() if "warning:" in line]
    assert warned and all(line.startswith("inclinometer: warning: ") for line in warned), err
    assert ".py:" not in err and "warnings.warn" not in err


def test_an_unexpected_error_is_one_line_naming_the_crash_log(tmp_path, monkeypatch, capsys):
    def broken(args):
        raise ZeroDivisionError("a bug")

    log = tmp_path / "logs" / "crash.log"
    monkeypatch.setattr(cli_devices, "run", broken)
    monkeypatch.setattr(cli_errors, "crash_log_path", lambda: log)
    monkeypatch.delenv(cli_errors.DEBUG_ENV, raising=False)
    line = assert_one_line(*run(["devices"], capsys), expected=1)
    assert "internal error (ZeroDivisionError: a bug)" in line and str(log) in line
    assert "Traceback" in log.read_text(encoding="utf-8")
    with pytest.raises(ZeroDivisionError):
        main(["--debug", "devices"])
    monkeypatch.setenv(cli_errors.DEBUG_ENV, "1")
    with pytest.raises(ZeroDivisionError):
        main(["devices"])


@pytest.mark.timeout(60)
def test_the_real_command_gives_one_line_and_exit_2(corpus):
    """Two inputs through ``python -m app``, one a pipe from bash's process substitution
    (benchmarks/hostile_inputs.py runs the whole corpus this way)."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "QT_QPA_PLATFORM": "offscreen"}
    env.pop(cli_errors.DEBUG_ENV, None)
    good = corpus / "good.csv"
    commands = [
        [sys.executable, "-m", "app", "record", "--device", "sim://static?odr=" + "9" * 400,
         str(corpus / "rec-sub.csv")],
        ["bash", "-c", f'"{sys.executable}" -m app replay <(cat "{good}") --out '
                       f'"{corpus / "pipe.csv"}"'],
    ]
    for argv in commands:
        done = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=REPO,
                              timeout=60, check=False)
        assert_one_line(done.returncode, done.stderr)
    assert not (corpus / "pipe.csv").exists()


def test_terminal_escapes_from_a_device_or_a_file_are_shown_not_obeyed():
    assert cli_errors.printable("SIM-\x1b[31mRED\x1b[0m\x9b") == "SIM-\\x1b[31mRED\\x1b[0m\\x9b"
    line = cli_errors.one_line(ValueError("bad id '\x1b]0;owned\x07'\r\nsecond line"))
    assert "\x1b" not in line and "\x07" not in line and "\n" not in line
    assert line == "bad id '\\x1b]0;owned\\x07' second line"


@pytest.mark.parametrize("poison", [float("nan"), float("inf"), 1e308])
def test_the_allan_analysis_refuses_samples_no_sensor_gives(poison):
    """The window's Allan panel calls the analysis directly: it refuses them too."""
    import numpy as np

    from app.core.allan import analyse_static

    rng = np.random.default_rng(1)
    gyro = rng.normal(0.0, 1e-3, (2000, 3))
    accel = rng.normal(0.0, 1e-2, (2000, 3)) + np.array([0.0, 0.0, 9.81])
    gyro[700, 1] = poison
    with pytest.raises(ValueError, match="not finite or beyond"):
        analyse_static(gyro, accel, 100.0)
