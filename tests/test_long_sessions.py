"""Long recordings are scored and replayed in pieces with the same results as whole."""

from __future__ import annotations

import numpy as np
import pytest

from app.cli import main
from app.core import evaluation
from app.core.orientation import quaternion_from_roll_pitch
from app.core.recording import RecordingWriter, recording_metadata
from app.core.scoring import ErrorAccumulator, error_statistics
from drivers.sim.device import SimulatedDevice


@pytest.fixture(scope="module")
def wobble(tmp_path_factory):
    path = tmp_path_factory.mktemp("long") / "wobble.csv"
    device = SimulatedDevice("sim://wobble?odr=833&realtime=0&block=900&seed=4")
    info = device.open()
    writer = RecordingWriter(path, recording_metadata(device=info)).start()
    for _ in range(60):  # 54 000 rows, 65 s
        writer.write(device.read(1.0))
    assert writer.close().error is None
    return path


def angles(path) -> np.ndarray:
    """The numbers of an angles file (metadata and header row left out)."""
    rows = [line for line in path.read_text().splitlines() if not line.startswith("#")][1:]
    return np.loadtxt(rows, delimiter=",")


@pytest.mark.parametrize("pieces", [7, 777, 100_000])
def test_error_accumulator_gives_error_statistics_in_pieces(pieces):
    rng = np.random.default_rng(3)
    n = 120_000  # over 2 x 1024 bins: they are merged several times
    t = np.arange(n) / 100.0
    roll = rng.normal(0.0, 1.0, n) + np.where(np.arange(n) > 0.8 * n, 9.0, 0.0)
    quat = quaternion_from_roll_pitch(roll, np.zeros(n))
    quat[::101] = np.nan
    reference = quaternion_from_roll_pitch(np.zeros(n), np.zeros(n))
    want = error_statistics(quat, reference, t, 2.0)
    accumulator = ErrorAccumulator()
    scored = t >= 2.0
    for start in range(0, n, pieces):
        stop = start + pieces
        accumulator.add(quat[start:stop], reference[start:stop], scored[start:stop])
    got = accumulator.result()
    assert got["scored"] == want["scored"] and got["nan"] == want["nan"]
    assert got["rmse_deg"] == pytest.approx(want["rmse_deg"], rel=1e-12)
    assert got["max_deg"] == want["max_deg"]
    assert got["diverged"] == want["diverged"] is True


def test_a_recording_scored_in_pieces_scores_as_a_whole_one(wobble, monkeypatch):
    filters = ["ekf", "vqf", "mahony", "ekf-smoother"]
    whole = evaluation.evaluate_source(evaluation.recording_source(str(wobble)), filters,
                                       repeats=1)
    monkeypatch.setattr(evaluation, "STREAM_MIN_BYTES", 0)
    source = evaluation.recording_source(str(wobble))
    assert source.pieces is not None  # read in pieces, not at once
    pieces = evaluation.evaluate_source(source, filters, repeats=1)
    assert (pieces.samples, pieces.scored_samples, pieces.gaps) == (
        whole.samples, whole.scored_samples, whole.gaps)
    assert pieces.duration_s == pytest.approx(whole.duration_s)
    for a, b in zip(pieces.scores, whole.scores, strict=True):
        assert a.name == b.name and a.flag == b.flag == "ok"
        assert a.rmse_deg == pytest.approx(b.rmse_deg, rel=1e-9)
        assert a.max_deg == pytest.approx(b.max_deg, rel=1e-12)
        assert a.scored_samples == b.scored_samples


def test_streamed_replay_writes_what_the_whole_file_replay_writes(wobble, tmp_path, capsys):
    streamed, whole = tmp_path / "streamed.csv", tmp_path / "whole.csv"
    assert main(["replay", str(wobble), "--filter", "vqf", "--out", str(streamed)]) == 0
    printed = capsys.readouterr().out
    # An offline filter in the list takes the whole-file path; its online partner's columns
    # must be the same numbers as the streamed run's.
    assert main(["replay", str(wobble), "--filter", "vqf", "ekf-smoother", "--out",
                 str(whole)]) == 0
    capsys.readouterr()
    a, b = angles(streamed), angles(whole)
    assert a.shape[0] == b.shape[0] == 54_000
    np.testing.assert_array_equal(a[:, :9], b[:, :9])  # t and vqf's angles and quaternion
    assert "54000 rows" in printed and "vqf" in printed


def test_replay_all_leaves_the_offline_smoothers_out_of_a_long_recording(wobble, tmp_path,
                                                                        capsys, monkeypatch):
    import app.services.replay_export as replay_export

    monkeypatch.setattr(replay_export, "WHOLE_FILE_OFFLINE_BYTES", 0)
    target = tmp_path / "all.csv"
    assert main(["replay", str(wobble), "--filter", "all", "--out", str(target)]) == 0
    printed = capsys.readouterr().out
    assert "'all' leaves out ekf-smoother, vqf-offline" in printed
    header = next(line for line in target.read_text().splitlines() if not line.startswith("#"))
    assert "vqf.roll" in header and "gyro.roll" in header
    assert "ekf-smoother" not in header
    # Named explicitly, a smoother still runs (whole file in memory).
    assert main(["replay", str(wobble), "--filter", "ekf-smoother", "--out",
                 str(target), "--overwrite"]) == 0
    assert "ekf-smoother.roll" in target.read_text()
