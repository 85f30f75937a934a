"""`inclinometer tune` (issue 35): grid and random points, folds by trial, the held-out score,
the same bits on one process, two processes and a two-worker Dask LocalCluster, and
`evaluate --jobs`."""

from __future__ import annotations

import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.cli.tune import TerminalProgress
from app.core.filters import FILTERS
from app.services.tuning import cv, grid
from app.services.tuning.grid import Axis
from app.services.tuning.study import plan_chunks, sensitivity_points
from tests.broad_trials import trial_path

TRIALS = ("01_undisturbed_slow_rotation_A", "24_disturbed_tapping_A")
ROWS_BEFORE, ROWS_AFTER = 300, 900
"""A slice of each trial: 1 s of the rest before the movement and about 3 s of it."""
STUDIED = ["runs", "results", "best", "cross_validation", "cross_validated_rmse_deg",
           "sensitivity"]


@pytest.fixture(scope="module")
def slices(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Short slices of two BROAD trials (a rotation and a disturbed one), movement included."""
    folder = tmp_path_factory.mktemp("slices")
    made = []
    for stem in TRIALS:
        lines = trial_path(stem).read_text().splitlines()
        comments = [line for line in lines if line.startswith("#")]
        header, rows = lines[len(comments)], lines[len(comments) + 1:]
        start = next(i for i, row in enumerate(rows) if row.endswith(",1"))
        path = folder / f"{stem}.csv"
        path.write_text("\n".join([*comments, header,
                                   *rows[start - ROWS_BEFORE:start + ROWS_AFTER]]) + "\n")
        made.append(path)
    return made


@pytest.fixture(scope="module")
def serial(slices: list[Path], tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The study of :func:`tune` on one process, with its plot (``document["png"]``)."""
    folder = tmp_path_factory.mktemp("serial")
    document = tune(slices, folder / "t.json", "--jobs", "1", "--png", str(folder / "t.png"))
    document["png"] = (folder / "t.png").read_bytes()
    return document


def tune(slices: list[Path], out: Path, *extra: str) -> dict:
    code = main(["tune", *map(str, slices), "--param", "ekf.lp_tau=1,2",
                 "--param", "ekf.estimate_bias=true,false", "--json", str(out), *extra])
    assert code == 0
    return json.loads(out.read_text())


def studied(document: dict) -> dict:
    return {key: document[key] for key in STUDIED if key in document}


def spec(filter_name: str, name: str):
    return FILTERS[filter_name].parameter_spec(name)


# -- points ----------------------------------------------------------------------------------
def test_a_grid_is_the_product_of_the_axes_last_fastest():
    axes = [Axis("ekf", spec("ekf", "lp_tau"), values=(1.0, 2.0)),
            Axis("ekf", spec("ekf", "estimate_bias"), values=(True, False))]
    assert grid.grid_points(axes) == [
        {"lp_tau": 1.0, "estimate_bias": True}, {"lp_tau": 1.0, "estimate_bias": False},
        {"lp_tau": 2.0, "estimate_bias": True}, {"lp_tau": 2.0, "estimate_bias": False}]
    ranged = [Axis("ekf", spec("ekf", "lp_tau"), low=0.5, high=8.0)]
    with pytest.raises(ValueError, match="--random"):
        grid.grid_points(ranged)


def test_a_random_search_is_seeded_distinct_and_within_its_ranges():
    axes = [Axis("ekf", spec("ekf", "lp_tau"), low=0.5, high=8.0),
            Axis("ekf", spec("ekf", "estimate_bias"), values=(True, False))]
    first = grid.random_points(axes, 30, seed=7)
    assert first == grid.random_points(axes, 30, seed=7)
    assert first != grid.random_points(axes, 30, seed=8)
    taus = np.array([p["lp_tau"] for p in first])
    assert len(first) == 30 and np.all((taus >= 0.5) & (taus <= 8.0))
    assert np.median(taus) < 4.25  # log-uniform (lp_tau is log-scale): median near 2
    listed = [Axis("ekf", spec("ekf", "estimate_bias"), values=(True, False))]
    assert sorted(p["estimate_bias"] for p in grid.random_points(listed, 10, 0)) == [False,
                                                                                       True]


def test_sensitivity_steps_halve_and_double_reals_and_take_neighbours_of_the_rest():
    axes = [Axis("ekf", spec("ekf", "lp_tau"), values=(1.0, 2.0)),
            Axis("ekf", spec("ekf", "motion_frequency"), values=(0.0, 1.0)),
            Axis("ekf", spec("ekf", "estimate_bias"), values=(True,))]
    points = grid.grid_points(axes)
    optimum = {"lp_tau": 2.0, "motion_frequency": 0.0, "estimate_bias": True}
    steps = {(name, step): point for name, step, point in
             sensitivity_points(axes, points, optimum)}
    assert steps[("lp_tau", "x0.5")] == {**optimum, "lp_tau": 1.0}
    assert steps[("lp_tau", "x2")] == {**optimum, "lp_tau": 4.0}
    assert steps[("motion_frequency", "x2")] is None  # zero stays zero
    assert steps[("estimate_bias", "other")] == {**optimum, "estimate_bias": False}
    assert grid.scaled(spec("ekf", "lp_tau"), 20.0, 2.0) == 30.0  # clipped to its range


def test_chunks_cover_every_run_once_and_keep_one_recording_each():
    for points, sources, workers in ((100, 12, 2), (4, 2, 2), (7, 3, 1), (1, 2, 8)):
        chunks = plan_chunks(points, sources, workers)
        runs = sorted((s, p) for s, members in chunks for p in members)
        assert runs == [(s, p) for s in range(sources) for p in range(points)]
        if workers > 1:
            assert len(chunks) >= min(points * sources, 4 * workers)
    assert len(plan_chunks(100, 12, 1)) == 12  # serial: one task per recording


# -- folds -----------------------------------------------------------------------------------
def test_broad_groups_come_from_the_file_names():
    assert cv.broad_group("/x/24_disturbed_tapping_A.csv") == "disturbed"
    assert cv.broad_group("04_undisturbed_slow_rotation_with_breaks_A") == "rotation"
    assert cv.broad_group("15_undisturbed_fast_translation_A.csv") == "translation"
    assert cv.broad_group("my_walk.csv") is None
    with pytest.raises(ValueError, match=r"my_walk\.csv: the file name names no group"):
        cv.group_folds(["01_undisturbed_slow_rotation_A", "my_walk.csv"])
    folds = cv.group_folds(["01_slow_rotation", "24_disturbed_x", "06_fast_rotation"])
    assert [(f.name, f.held_out) for f in folds] == [("rotation", [0, 2]),
                                                     ("disturbed", [1])]


def test_held_out_scores_come_from_parameters_chosen_without_that_trial():
    rmse = np.array([[1.0, 1.0, 1.0, 4.0],    # point 0: best on trials 0-2
                     [2.0, 2.0, 2.0, 1.0]])   # point 1: best on trial 3
    usable = np.ones_like(rmse, dtype=bool)
    result = cv.cross_validate(rmse, usable, cv.kfold(4, 4), "loo")
    # holding out trial 0 leaves 1, 2, 3: point 0 averages 2.0 there, point 1 5/3
    assert [f.chosen_point for f in result.folds] == [1, 1, 1, 0]
    assert result.held_out_per_trial == [2.0, 2.0, 2.0, 4.0]
    assert result.cross_validated_rmse_deg == 2.5
    assert cv.best_point(rmse, usable, [0, 1, 2, 3]) == 0  # 1.75 each in sample: the earliest
    usable[1, 0] = False  # point 1 failed on trial 0: not chosen where trial 0 trains
    result = cv.cross_validate(rmse, usable, cv.kfold(4, 4), "loo")
    assert [f.chosen_point for f in result.folds] == [1, 0, 0, 0]
    assert result.held_out_per_trial[1:] == [1.0, 1.0, 4.0]
    assert math.isnan(result.held_out_per_trial[0])  # chosen without trial 0, failed on it
    assert math.isnan(result.cross_validated_rmse_deg)  # a failure is never averaged away
    with pytest.raises(ValueError, match="--folds must be from 2"):
        cv.kfold(3, 4)


# -- the command -----------------------------------------------------------------------------
def test_tune_scores_a_point_as_evaluate_does(slices, serial, tmp_path):
    document = serial
    assert main(["evaluate", *map(str, slices), "--filter", "ekf", "--param", "ekf.lp_tau=1",
                 "--param", "ekf.estimate_bias=false", "--repeats", "1",
                 "--json", str(tmp_path / "e.json")]) == 0
    evaluated = json.loads((tmp_path / "e.json").read_text())
    entry = next(r for r in document["results"]
                 if r["params"] == {"lp_tau": 1.0, "estimate_bias": False})
    for source in evaluated["sources"]:
        assert entry["trials"][Path(source["label"]).stem] == source["filters"]["ekf"][
            "rmse_deg"]
    assert entry["rmse_deg"] == evaluated["mean"]["ekf"]["rmse_deg"]
    assert len(document["results"]) == 4
    folds = document["cross_validation"]["folds"]
    assert [f["held_out"] for f in folds] == [[TRIALS[0]], [TRIALS[1]]]
    for fold, trial in zip(folds, reversed(TRIALS), strict=True):  # chosen on the other
        chosen = min(document["results"], key=lambda r: (r["trials"][trial], r["point"]))
        assert fold["params"] == chosen["params"]
    held = [document["results"][f["chosen_point"]]["trials"][f["held_out"][0]] for f in folds]
    assert document["cross_validated_rmse_deg"] == pytest.approx(np.mean(held), abs=0)
    assert {(row["param"], row["step"]) for row in document["sensitivity"]} >= {
        ("lp_tau", "x0.5"), ("lp_tau", "x2"), ("estimate_bias", "other")}


def test_two_processes_give_the_bits_of_one(slices, serial, tmp_path):
    parallel = tune(slices, tmp_path / "two.json", "--jobs", "2")
    assert parallel["run"]["workers"] == 2
    assert studied(parallel) == studied(serial)


def test_leave_one_group_out_holds_out_each_broad_group(slices, serial, tmp_path, capsys):
    document = tune(slices, tmp_path / "groups.json", "--jobs", "1", "--groups")
    assert "runs (" not in capsys.readouterr().err  # no progress line off a terminal
    validation = document["cross_validation"]
    assert validation["scheme"] == "leave-one-group-out"
    assert [(f["name"], f["held_out"]) for f in validation["folds"]] == [
        ("rotation", [TRIALS[0]]), ("disturbed", [TRIALS[1]])]
    assert document["results"] == serial["results"]  # the same runs, other folds


def test_a_two_worker_dask_cluster_gives_the_bits_of_one_process(slices, serial, tmp_path):
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                      dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://")
        shared = tune(slices, tmp_path / "dask.json", "--scheduler", address)
        sent = tune(slices, tmp_path / "sent.json", "--scheduler", address, "--scatter")
    assert shared["run"]["workers"] == 2
    assert studied(shared) == studied(serial)
    assert studied(sent) == studied(serial)


def test_evaluate_on_two_processes_gives_the_errors_of_one(slices, tmp_path):
    outputs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"e{jobs}.json"
        assert main(["evaluate", *map(str, slices), "--filter", "vqf", "--jobs", jobs,
                     "--json", str(out)]) == 0
        document = json.loads(out.read_text())
        outputs.append([(s["label"], {name: (f["rmse_deg"], f["max_deg"], f["flag"])
                                      for name, f in s["filters"].items()})
                        for s in document["sources"]])
    assert outputs[0] == outputs[1]
    assert len(outputs[0]) == 2


def test_the_png_plots_each_parameter(serial):
    data = serial["png"]
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width = int.from_bytes(data[16:20], "big")
    assert width > 600  # two panels side by side


@pytest.mark.parametrize(("option", "message"), [
    ("ekf.lp_taus=1,2", "ekf has no parameter 'lp_taus'"),
    ("ekf.lp_tau=1,200", "outside"),
    ("ekf.lp_tau=1..4", "needs --random"),
    ("nope.x=1", "no filter 'nope'"),
    ("ekf.lp_tau=1,,2", "an empty value"),
])
def test_a_bad_parameter_is_one_clear_line(slices, tmp_path, capsys, option, message):
    code = main(["tune", *map(str, slices), "--param", option, "--json",
                 str(tmp_path / "x.json")])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_one_filter_per_study_and_two_recordings_at_least(slices, tmp_path, capsys):
    out = str(tmp_path / "x.json")
    assert main(["tune", *map(str, slices), "--param", "ekf.lp_tau=1", "--param",
                 "vqf.tau_acc_s=2", "--json", out]) == 2
    assert "one filter per study" in capsys.readouterr().err
    assert main(["tune", str(slices[0]), "--param", "ekf.lp_tau=1,2", "--json", out]) == 2
    assert "two recordings or more" in capsys.readouterr().err
    assert main(["tune", *map(str, slices), "--param", "ekf.lp_tau=1", "--folds", "3",
                 "--json", out]) == 2
    assert "--folds must be from 2 to the number of trials (2)" in capsys.readouterr().err


def test_progress_asked_for_goes_to_stderr(slices, tmp_path, capsys):
    tune(slices, tmp_path / "p.json", "--jobs", "1", "--progress")
    err = capsys.readouterr().err
    assert "8/8 runs (100 %)" in err  # the grid's 4 points on 2 recordings
    done = re.findall(r"(\d+)/(\d+) runs \(100 %\)", err)[-1]  # then the sensitivity's
    assert done[0] == done[1] and int(done[1]) > 8


def test_the_progress_line_tells_the_runs_done_and_the_time_left():
    out = io.StringIO()
    progress = TerminalProgress(out)
    progress.extend(10)
    progress.advance(5)
    progress.advance(5)
    progress.close()
    last = out.getvalue().rstrip("\n").split("\r")[-1]
    assert "10/10 runs (100 %)" in last and "0:00 left" in last
