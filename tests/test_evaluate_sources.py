"""`inclinometer evaluate` over several sources, the `movement` score mask, --param, --json,
offline filters, and the reference-only label (issue 13, items 1 and 5)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from app.cli import main
from app.core import evaluation
from app.core.filters import FILTERS, create_filter
from app.core.filters.base import OrientationFilter
from app.core.orientation import inclination_error_deg, quaternion_from_roll_pitch
from app.core.recording.reader import parse_recording, read_recording
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

BROAD = Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "broad"
SMALL_TRIALS = ("32_disturbed_attached_magnet_1cm", "30_disturbed_stationary_magnet_C")
needs_broad = pytest.mark.skipif(
    not BROAD.is_dir(), reason=f"the BROAD trials are not at {BROAD} (shared datasets absent)"
)

ODR = 100.0


# -- synthetic recordings whose errors are known -------------------------------------------
def synthetic_recording(path: Path, *, seconds: float = 10.0, movement: bool = True,
                        text_flag: bool = False) -> Path:
    """A level sensor whose reference is rolled 10 degrees at rest and 2 degrees in motion.

    The accelerometer says level, so the ``accel`` filter's inclination error is exactly the
    reference's roll: 10 degrees where ``movement`` is 0 (t < 1 s and t >= 4 s), 2 degrees
    where it is 1 (1 s <= t < 4 s). The reference is unknown (empty) for 1.5 s <= t < 1.6 s.
    """
    n = round(seconds * ODR)
    t = np.arange(n) / ODR
    moving = (t >= 1.0) & (t < 4.0)
    ref = quaternion_from_roll_pitch(np.where(moving, 2.0, 10.0), 0.0)
    unknown = (t >= 1.5) & (t < 1.6)
    names = "t,ax,ay,az,gx,gy,gz,qw,qx,qy,qz" + (",movement" if movement else "")
    lines = ["# inclinometer-recording 1", names]
    for k in range(n):
        quat = ",,," if unknown[k] else ",".join(repr(float(v)) for v in ref[k])
        row = f"{float(t[k])!r},0,0,{STANDARD_GRAVITY_M_S2!r},0,0,0,{quat}"
        if movement:
            flag = ("yes" if moving[k] else "no") if text_flag else ("1" if moving[k] else "0")
            row += "," + flag
        lines.append(row)
    path.write_text("\n".join(lines) + "\n")
    return path


def expected_scored(seconds: float = 10.0) -> int:
    t = np.arange(round(seconds * ODR)) / ODR
    return int(np.count_nonzero((t >= 1.0) & (t < 4.0) & ~((t >= 1.5) & (t < 1.6))))


def test_a_score_mask_chooses_exactly_the_rows_and_replaces_the_skip():
    n = 1000
    t = np.arange(n) / ODR
    quat = quaternion_from_roll_pitch(np.where(t < 5.0, 1.0, 3.0), 0.0)
    reference = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    reference[10] = np.nan
    mask = t < 0.5  # inside the 2 s a skip would drop
    stats = evaluation.error_statistics(quat, reference, t, skip_s=2.0, score_mask=mask)
    assert stats["scored"] == 49  # 50 rows, one without a reference
    assert stats["rmse_deg"] == pytest.approx(1.0, rel=1e-9)
    unmasked = evaluation.error_statistics(quat, reference, t, skip_s=2.0)
    assert unmasked["scored"] == 800
    assert unmasked["rmse_deg"] == pytest.approx(math.sqrt((300 * 1 + 500 * 9) / 800), rel=1e-9)
    with pytest.raises(ValueError, match="shape"):
        evaluation.error_statistics(quat, reference, t, score_mask=mask[:-1])


def test_recording_score_mask_reads_the_movement_column(tmp_path):
    with_flag = read_recording(synthetic_recording(tmp_path / "a.csv"))
    assert "movement" in with_flag.unknown_columns
    mask = evaluation.recording_score_mask(with_flag)
    assert mask is not None and mask.dtype == bool
    assert np.array_equal(mask, (with_flag.t_s >= 1.0) & (with_flag.t_s < 4.0))
    without = read_recording(synthetic_recording(tmp_path / "b.csv", movement=False))
    assert evaluation.recording_score_mask(without) is None
    # An empty flag is not 1; a flag given as floats counts where it equals 1.
    odd = parse_recording(b"# inclinometer-recording 1\nt,ax,ay,az,gx,gy,gz,movement\n"
                          b"0,0,0,9.8,0,0,0,1.0\n0.01,0,0,9.8,0,0,0,\n0.02,0,0,9.8,0,0,0,2\n")
    assert evaluation.recording_score_mask(odd).tolist() == [True, False, False]
    text = read_recording(synthetic_recording(tmp_path / "c.csv", text_flag=True))
    with pytest.raises(ValueError, match="'movement' column holds text"):
        evaluation.recording_score_mask(text)


def test_evaluate_scores_only_the_movement_rows_of_a_recording(tmp_path, capsys):
    path = synthetic_recording(tmp_path / "moving.csv")
    assert main(["evaluate", str(path), "--filter", "accel", "--repeats", "1"]) == 0
    printed = capsys.readouterr().out
    assert f"scored: rows with movement == 1 ({expected_scored()} samples)" in printed
    assert "first 2 s not scored" not in printed
    rmse, largest = re.search(r"^\s+accel\s+(\S+)\s+(\S+)", printed, re.M).groups()
    assert float(rmse) == pytest.approx(2.0, abs=1e-3)  # the 10 degrees at rest never count
    assert float(largest) == pytest.approx(2.0, abs=1e-3)
    # Without the column: today's rule, the first 2 s skipped, the rest phase after 4 s scored.
    plain = synthetic_recording(tmp_path / "plain.csv", movement=False)
    assert main(["evaluate", str(plain), "--filter", "accel", "--repeats", "1"]) == 0
    printed = capsys.readouterr().out
    assert "first 2 s not scored" in printed
    rmse = float(re.search(r"^\s+accel\s+(\S+)", printed, re.M).group(1))
    assert rmse == pytest.approx(math.sqrt((200 * 4 + 600 * 100) / 800), abs=1e-3)


def test_replay_rmse_follows_the_movement_rows(tmp_path, capsys):
    path = synthetic_recording(tmp_path / "moving.csv")
    assert main(["replay", str(path), "--filter", "accel", "--out",
                 str(tmp_path / "angles.csv")]) == 0
    printed = capsys.readouterr().out
    assert f"scored rows with movement == 1 with a reference: {expected_scored()} of 1000 rows" \
        in printed
    rmse = float(re.search(r"^\s+accel(?:\s+\S+){2}\s+(\S+)", printed, re.M).group(1))
    assert rmse == pytest.approx(2.0, abs=1e-3)


# -- several sources, globs, JSON ------------------------------------------------------------
def test_several_recordings_by_glob_give_one_row_each_and_a_mean(tmp_path, capsys):
    folder = tmp_path / "trials"
    folder.mkdir()
    synthetic_recording(folder / "a.csv")
    synthetic_recording(folder / "b.csv", movement=False)
    out_json = tmp_path / "scores.json"
    # The glob arrives unexpanded (quoted in a shell): the command expands it.
    code = main(["evaluate", str(folder / "*.csv"), "--filter", "accel", "gyro",
                 "--repeats", "1", "--json", str(out_json)])
    assert code == 0
    printed = capsys.readouterr().out
    rows = {line.split()[0]: line.split() for line in printed.splitlines() if line.split()}
    assert rows["source"] == ["source", "scored", "accel", "gyro"]
    assert rows["a"][1] == str(expected_scored())
    a, b = float(rows["a"][2]), float(rows["b"][2])
    assert a == pytest.approx(2.0, abs=1e-3)
    assert b == pytest.approx(math.sqrt((200 * 4 + 600 * 100) / 800), abs=1e-3)
    mean_row = next(line for line in printed.splitlines() if line.startswith("mean of 2"))
    assert float(mean_row.split()[3]) == pytest.approx((a + b) / 2, abs=2e-3)
    worst_row = next(line for line in printed.splitlines() if line.startswith("worst"))
    assert float(worst_row.split()[1]) == pytest.approx(max(a, b), abs=1e-3)

    document = json.loads(out_json.read_text())
    assert [Path(s["label"]).name for s in document["sources"]] == ["a.csv", "b.csv"]
    first, second = document["sources"]
    assert first["masked"] is True and second["masked"] is False
    assert first["scored_samples"] == expected_scored() and first["samples"] == 1000
    assert first["rate_hz"] == pytest.approx(ODR)
    assert first["duration_s"] == pytest.approx(9.99)
    for source in document["sources"]:
        assert set(source["filters"]) == {"accel", "gyro"}
        score = source["filters"]["accel"]
        assert set(score) >= {"rmse_deg", "max_deg", "samples_per_s", "flag", "message"}
        assert score["flag"] == "ok" and score["samples_per_s"] > 0
    rmses = [s["filters"]["accel"]["rmse_deg"] for s in document["sources"]]
    assert f"{rmses[0]:.3f}" == rows["a"][2] and f"{rmses[1]:.3f}" == rows["b"][2]
    assert document["mean"]["accel"]["rmse_deg"] == pytest.approx(np.mean(rmses), rel=1e-12)
    assert document["mean"]["accel"]["worst_rmse_deg"] == pytest.approx(max(rmses), rel=1e-12)
    assert document["mean"]["accel"]["sources"] == 2
    assert [f["name"] for f in document["filters"]] == ["accel", "gyro"]


def test_sources_of_every_kind_mix(tmp_path, capsys):
    path = synthetic_recording(tmp_path / "a.csv")
    assert main(["evaluate", str(path), "sim://static?odr=52&seed=2", "--seconds", "3",
                 "--filter", "accel", "--repeats", "1", "--json", "-"]) == 0
    captured = capsys.readouterr()
    document = json.loads(captured.out)  # stdout holds the JSON alone
    labels = [s["label"] for s in document["sources"]]
    assert labels == [str(path), "sim://static?odr=52&seed=2"]
    assert [s["masked"] for s in document["sources"]] == [True, False]
    assert document["sources"][1]["scoring"] == "after the first 2 s"
    assert "mean of 2" in captured.err  # the table went to stderr


def test_bad_sources_exit_2_with_a_clear_message(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "nothing*.csv")]) == 2
    assert "nothing*.csv: no file matches" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "missing.csv")]) == 2
    assert "missing.csv: no such file" in capsys.readouterr().err
    assert main(["evaluate", "no-such-thing"]) == 2
    assert "no such file, and not a device URL" in capsys.readouterr().err
    good = synthetic_recording(tmp_path / "good.csv")
    assert main(["evaluate", str(good), "sim://static", "/dev/ttyACM9"]) == 2
    assert "only sources that know their true orientation" in capsys.readouterr().err
    assert main(["evaluate", str(good), "--json", str(tmp_path / "no" / "dir.json")]) == 2
    assert "no such directory" in capsys.readouterr().err


# -- --param ---------------------------------------------------------------------------------
def _evaluate_json(capsys, *args: str) -> dict:
    assert main(["evaluate", *args, "--repeats", "1", "--json", "-"]) == 0
    return json.loads(capsys.readouterr().out)


def test_param_sets_a_filter_parameter(capsys):
    source = ["sim://wobble?odr=104&seed=4", "--seconds", "5", "--filter", "madgwick", "ekf"]
    default = _evaluate_json(capsys, *source)
    changed = _evaluate_json(capsys, *source, "--param", "madgwick.beta=0.5",
                             "--param", "ekf.estimate_bias=false")
    rmse = {name: [d["sources"][0]["filters"][name]["rmse_deg"] for d in (default, changed)]
            for name in ("madgwick", "ekf")}
    assert abs(rmse["madgwick"][0] - rmse["madgwick"][1]) > 1e-3
    assert abs(rmse["ekf"][0] - rmse["ekf"][1]) > 1e-6
    parameters = {f["name"]: f["parameters"] for f in changed["filters"]}
    assert parameters["madgwick"]["beta"] == 0.5
    assert parameters["ekf"]["estimate_bias"] is False
    defaults = {f["name"]: f["parameters"] for f in default["filters"]}
    assert defaults["madgwick"]["beta"] == FILTERS["madgwick"]().get_parameter("beta")


@pytest.mark.parametrize("param, message", [
    ("madgwick.beta=abc", "is not a number"),
    ("madgwick.beta=99", "is outside"),
    ("madgwick.nosuch=1", "madgwick has no parameter 'nosuch'"),
    ("nosuch.beta=1", "no filter 'nosuch'"),
    ("madgwick-beta", "write FILTER.NAME=VALUE"),
    ("ekf.estimate_bias=maybe", "true or false"),
    ("vqf.tau_acc_s=2", "'vqf' is not among those run"),
])
def test_a_bad_param_exits_2(param, message, tmp_path, capsys):
    for command in (["evaluate", "sim://static", "--filter", "madgwick", "ekf"],
                    ["replay", str(synthetic_recording(tmp_path / "r.csv", seconds=1.0)),
                     "--filter", "madgwick", "ekf", "--out", str(tmp_path / "o.csv")]):
        assert main([*command, "--param", param]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "o.csv").exists()


def test_replay_param_changes_the_recorded_parameters(tmp_path, capsys):
    from app.services.recorder import record_device
    from drivers.sim.device import SimulatedDevice

    source = tmp_path / "run.csv"
    record_device(SimulatedDevice("sim://wobble?odr=104&seed=2", realtime=False), source,
                  duration_s=5.0, filter_name="madgwick")

    def replay_rmse(*extra: str) -> float:
        assert main(["replay", str(source), "--out", str(tmp_path / "angles.csv"),
                     "--overwrite", *extra]) == 0
        printed = capsys.readouterr().out
        return float(re.search(r"^\s+madgwick(?:\s+\S+){2}\s+(\S+)", printed, re.M).group(1))

    assert replay_rmse() != replay_rmse("--param", "madgwick.beta=1.5")
    header = (tmp_path / "angles.csv").read_text().splitlines()[:6]
    assert any('"beta": 1.5' in line for line in header)


# -- offline filters -------------------------------------------------------------------------
class OfflineProbe(OrientationFilter):
    """An 'acausal' test filter: records the length of every ``process`` call."""

    name = "offline-probe"
    title = "Offline probe"
    offline = True
    calls: ClassVar[list[int]] = []

    def process(self, block: SampleBlock):
        type(self).calls.append(len(block))
        return super().process(block)

    def _process(self, block: SampleBlock) -> np.ndarray:
        return np.tile([1.0, 0.0, 0.0, 0.0], (len(block), 1))


class OnlineProbe(OfflineProbe):
    name = "online-probe"
    offline = False
    calls: ClassVar[list[int]] = []


def test_an_offline_filter_gets_the_whole_stream_in_one_call():
    n = 1000
    t = np.arange(n) / ODR
    stream = SampleBlock(t, np.tile([0.0, 0.0, STANDARD_GRAVITY_M_S2], (n, 1)), np.zeros((n, 3)),
                         np.zeros(n), np.zeros(n, bool), np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))
    OfflineProbe.calls.clear()
    OnlineProbe.calls.clear()
    scores = evaluation.evaluate(stream, [OfflineProbe, OnlineProbe], block=64, repeats=1)
    assert OfflineProbe.calls == [n]
    assert OnlineProbe.calls == [64] * 15 + [40]
    assert [s.flag for s in scores] == ["ok", "ok"]


def test_replay_gives_an_offline_filter_the_whole_recording(tmp_path, monkeypatch):
    from app.core.recording.export import run_filters

    monkeypatch.setitem(FILTERS, OfflineProbe.name, OfflineProbe)
    monkeypatch.setitem(FILTERS, OnlineProbe.name, OnlineProbe)
    recording = read_recording(synthetic_recording(tmp_path / "r.csv"))
    OfflineProbe.calls.clear()
    OnlineProbe.calls.clear()
    outputs = run_filters(recording, ["online-probe", "offline-probe"], block=300)
    assert OfflineProbe.calls == [1000]
    assert OnlineProbe.calls == [300, 300, 300, 100]
    assert [len(o.quat) for o in outputs] == [1000, 1000]
    assert np.array_equal(outputs[1].quat, np.tile([1.0, 0.0, 0.0, 0.0], (1000, 1)))


# -- reference-only filters ------------------------------------------------------------------
def test_the_thesis_kalman_filter_is_marked_a_reference(capsys):
    assert FILTERS["kalman-thesis"].reference_only
    assert [n for n, cls in FILTERS.items() if cls.reference_only] == ["kalman-thesis"]
    assert main(["evaluate", "sim://static?odr=52", "--seconds", "3", "--repeats", "1",
                 "--filter", "kalman-thesis", "accel"]) == 0
    assert "kalman-thesis: Kalman (thesis), kept as a reference implementation, not for " \
        "measurement" in capsys.readouterr().out


def test_the_filter_list_labels_a_reference_only_filter(qtbot):
    from PySide6.QtCore import Qt

    from app.gui.filter_panel import FilterPanel

    panel = FilterPanel()
    qtbot.addWidget(panel)
    for name, cls in FILTERS.items():
        index = panel.combo.findData(name)
        text = panel.combo.itemText(index)
        tooltip = panel.combo.itemData(index, Qt.ItemDataRole.ToolTipRole)
        item = next(panel.compare_list.item(r) for r in range(panel.compare_list.count())
                    if panel.compare_list.item(r).data(Qt.ItemDataRole.UserRole) == name)
        marked = "not for measurement"
        assert (marked in text) == cls.reference_only, name
        assert (marked in tooltip) == cls.reference_only, name
        assert (marked in item.text()) == cls.reference_only, name
        assert item.checkState() == Qt.CheckState.Unchecked
    assert panel.compared_filters() == []


# -- the BROAD trials ------------------------------------------------------------------------
def _hand_rmse(path: Path, name: str) -> tuple[float, float, int]:
    """RMSE over movement == 1 rows with a reference, and over the skip rule, by hand."""
    recording = read_recording(path)
    stream = recording.sample_block(recording.calibration)
    quat, _ = evaluation.run_filter(create_filter(name), stream)
    reference = recording.reference_quat
    rows = (recording.columns["movement"] == 1.0) & np.all(np.isfinite(reference), axis=1)
    errors = inclination_error_deg(quat[rows], reference[rows])
    skip_rows = (recording.t_s >= recording.t_s[0] + 2.0) & np.all(np.isfinite(reference), axis=1)
    skipped = inclination_error_deg(quat[skip_rows], reference[skip_rows])
    return (float(np.sqrt(np.mean(errors**2))), float(np.sqrt(np.mean(skipped**2))),
            int(rows.sum()))


@needs_broad
def test_broad_trials_are_scored_on_their_movement_phase(tmp_path, capsys):
    # Two trials by a glob (as a quoted shell argument), three filters, one run each.
    pattern = str(BROAD / "3[02]_*.csv")
    document = _evaluate_json(capsys, pattern, "--filter", "ekf", "vqf", "madgwick")
    labels = [Path(s["label"]).stem for s in document["sources"]]
    assert labels == sorted(SMALL_TRIALS)
    for source in document["sources"]:
        path = Path(source["label"])
        rmse, rmse_skip, scored = _hand_rmse(path, "vqf")
        assert source["masked"] is True and source["scored_samples"] == scored
        assert source["samples"] > scored > 0.5 * source["samples"] - 20000
        measured = source["filters"]["vqf"]["rmse_deg"]
        assert measured == pytest.approx(rmse, rel=1e-9)
        assert abs(rmse - rmse_skip) > 0.01  # the mask changes which rows count
        assert source["filters"]["vqf"]["flag"] == "ok"
    by_trial = {Path(s["label"]).stem: s["filters"]["vqf"]["rmse_deg"]
                for s in document["sources"]}
    # VQF (the reference package, defaults) against the dataset README's figures.
    assert by_trial["32_disturbed_attached_magnet_1cm"] == pytest.approx(0.56, abs=0.006)
    assert by_trial["30_disturbed_stationary_magnet_C"] == pytest.approx(1.25, abs=0.006)
    for name in ("ekf", "vqf", "madgwick"):
        values = [s["filters"][name]["rmse_deg"] for s in document["sources"]]
        assert document["mean"][name]["rmse_deg"] == pytest.approx(np.mean(values), rel=1e-12)


@needs_broad
def test_replay_of_a_broad_trial_scores_the_movement_phase(tmp_path, capsys):
    path = BROAD / f"{SMALL_TRIALS[0]}.csv"
    assert main(["replay", str(path), "--filter", "vqf", "--out",
                 str(tmp_path / "angles.csv")]) == 0
    printed = capsys.readouterr().out
    rmse, rmse_skip, scored = _hand_rmse(path, "vqf")
    assert f"scored rows with movement == 1 with a reference: {scored} of" in printed
    shown = re.search(r"^\s+vqf(?:\s+\S+){2}\s+(\S+)", printed, re.M).group(1)
    assert shown == f"{rmse:.3f}" and shown != f"{rmse_skip:.3f}"
