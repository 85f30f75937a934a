"""Heading scoring (issue 32): BROAD's error split on known error rotations, the fixed turn of
the sensor frame, ``evaluate --turn`` and ``replay`` on a real slice, the 6-axis filters on a
source with a field, and the default filter for a source with a magnetometer."""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

from app.cli import main
from app.core import quaternion as quat
from app.core.evaluation import evaluate_filter, turned_source
from app.core.filters import (
    DEFAULT_FILTER,
    FILTERS,
    ONLINE_FILTERS,
    create_filter,
    default_filter_for,
)
from app.core.heading_metrics import (
    PROJECT_TURN_DEG,
    error_split_deg,
    heading_error_deg,
    turn_block,
    turn_quaternion,
    turn_reference,
    turn_vectors,
)
from app.core.pipeline import Pipeline
from app.core.samples import SampleBlock
from tests.broad_trials import trial_path

Z = np.array([0.0, 0.0, 1.0])
X = np.array([1.0, 0.0, 0.0])
TRIAL = "01_undisturbed_slow_rotation_A"


def random_quats(n: int, seed: int = 1) -> np.ndarray:
    return quat.normalize(np.random.default_rng(seed).normal(size=(n, 4)))


# -- the metric --------------------------------------------------------------------------------
@pytest.mark.parametrize(("heading", "tilt"), [(10.0, 0.0), (0.0, 7.0), (10.0, 7.0),
                                               (-170.0, 3.0), (45.0, 60.0)])
def test_the_split_of_a_known_error_rotation(heading, tilt):
    """q_est = e (x) q_ref with e = Rz(heading) Rx(tilt) (earth frame): the heading error is
    |heading|, the inclination error |tilt|, the total the angle of e."""
    error = quat.multiply(quat.from_axis_angle(Z, np.radians(heading)),
                          quat.from_axis_angle(X, np.radians(tilt)))
    reference = random_quats(50)
    estimate = quat.multiply(np.broadcast_to(error, reference.shape), reference)
    h, i, t = error_split_deg(estimate, reference)
    np.testing.assert_allclose(h, abs(heading), atol=1e-9)
    np.testing.assert_allclose(i, abs(tilt), atol=1e-9)
    total = np.degrees(2.0 * np.arccos(abs(error[0])))
    np.testing.assert_allclose(t, total, atol=1e-6)
    assert np.all(t >= np.maximum(h, i) - 1e-9)


def test_turning_the_sensor_frame_changes_no_error_and_turns_every_vector():
    """The turn: a' = R a (90 deg about z maps x to y), q' = q R^-1 keeps every earth-frame
    vector where it was, and the error quaternion, hence all three errors, is unchanged."""
    quarter = quat.from_axis_angle(Z, np.pi / 2)
    np.testing.assert_allclose(turn_vectors(quarter, np.array([[1.0, 0.0, 0.0]])),
                               [[0.0, 1.0, 0.0]], atol=1e-15)
    turn = turn_quaternion(PROJECT_TURN_DEG)
    reference = random_quats(40, 2)
    estimate = random_quats(40, 3)
    vectors = np.random.default_rng(4).normal(size=(40, 3))
    np.testing.assert_allclose(quat.rotate(turn_reference(turn, reference),
                                           turn_vectors(turn, vectors)),
                               quat.rotate(reference, vectors), atol=1e-12)
    before = error_split_deg(estimate, reference)
    after = error_split_deg(turn_reference(turn, estimate), turn_reference(turn, reference))
    np.testing.assert_allclose(after, before, atol=1e-9)
    assert turn_quaternion((0.0, 0.0, 90.0)) == pytest.approx(quarter)
    with pytest.raises(ValueError, match="three finite angles"):
        turn_quaternion((1.0, 2.0))


def test_a_6_axis_filter_scores_inclination_alike_turned_or_not_but_not_heading(real_slice):
    """Turned, the accelerometer and gyroscope say the same motion in other axes: the tilt
    estimate is the same, the heading the gyro carries from an arbitrary start is not."""
    _, block, mask = real_slice
    turned = turn_block(block, turn_quaternion(PROJECT_TURN_DEG))
    plain = evaluate_filter("gyro", block, repeats=1, score_mask=mask)
    other = evaluate_filter("gyro", turned, repeats=1, score_mask=mask)
    assert other.rmse_deg == pytest.approx(plain.rmse_deg, rel=1e-6)
    assert not plain.magnetic and not other.magnetic
    assert abs(other.heading_rmse_deg - plain.heading_rmse_deg) > 30.0


# -- a real slice ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def real_slice(tmp_path_factory) -> tuple[str, SampleBlock, np.ndarray]:
    """Trial 01 from 5 s before its movement phase to 10 s into it (the head kept), as a
    file, its samples and its movement rows."""
    from app.core.recording.reader import read_recording

    lines = trial_path(TRIAL).read_text().splitlines()
    body = [k for k, line in enumerate(lines) if line and line[0].isdigit()]
    start = next(k for k in body if lines[k].endswith(",1"))
    chosen = lines[start - 1428: start + 2857]  # 285.7 Hz
    path = tmp_path_factory.mktemp("broad") / "slice.csv"
    path.write_text("\n".join(lines[:body[0]] + chosen) + "\n")
    recording = read_recording(path)
    return str(path), recording.sample_block(None), recording.columns["movement"] > 0


def test_evaluate_turn_reports_heading_and_total_on_a_real_slice(real_slice, capsys):
    path = real_slice[0]
    code = main(["evaluate", path, "--turn", "--filter", "vqf", "gyro", "--repeats", "1",
                 "--json", "-"])
    assert code == 0
    document = json.loads(capsys.readouterr().out)
    assert document["settings"]["turn_deg"] == list(PROJECT_TURN_DEG)
    source = document["sources"][0]
    assert source["magnetometer"] is True
    vqf, gyro = source["filters"]["vqf"], source["filters"]["gyro"]
    assert vqf["heading_from_magnetometer"] and not gyro["heading_from_magnetometer"]
    assert vqf["heading_rmse_deg"] < 5.0  # the magnetometer finds north
    assert gyro["heading_rmse_deg"] > 30.0  # the trap: no luck once turned
    assert vqf["total_rmse_deg"] >= max(vqf["heading_rmse_deg"], vqf["rmse_deg"])
    # The printed table, and another turn given in degrees.
    assert main(["evaluate", path, "--turn", "0,0,0", "--filter", "vqf", "gyro",
                 "--repeats", "1"]) == 0
    printed = capsys.readouterr().out
    assert "heading deg" in printed and "total deg" in printed
    gyro_line = re.search(r"^\s+gyro\s+\S+\s+\S+\s+(\S+)", printed, re.M).group(1)
    assert gyro_line.startswith("(")  # a 6-axis heading is marked meaningless
    assert "means nothing" in printed


def test_a_bad_turn_is_refused_with_one_line(real_slice, capsys):
    path = real_slice[0]
    assert main(["evaluate", path, "--turn", "20,-30", "--filter", "gyro"]) == 2
    assert "RX,RY,RZ" in capsys.readouterr().err


def test_replay_writes_and_prints_heading_and_total_errors(real_slice, tmp_path, capsys):
    path, _, mask = real_slice
    out = tmp_path / "angles.csv"
    assert main(["replay", path, "--filter", "vqf", "gyro", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "heading deg" in printed
    lines = out.read_text().splitlines()
    head = next(line for line in lines if line.startswith("# filters"))
    frames = {f["name"]: f["earth_frame"] for f in json.loads(head.split(": ", 1)[1])}
    assert frames["vqf"].startswith("ENU") and frames["gyro"].startswith("z up")
    rows = [line for line in lines if not line.startswith("#")]
    names = rows[0].split(",")
    assert "vqf.heading_error" in names and "vqf.total_error" in names
    table = np.array([[float(v) for v in row.split(",")] for row in rows[1:]])
    heading = table[mask, names.index("vqf.heading_error")]
    rmse = float(np.sqrt(np.mean(heading**2)))
    shown = float(re.search(r"^\s+vqf(?:\s+\S+){4}\s+(\S+)", printed, re.M).group(1))
    assert shown == pytest.approx(rmse, abs=2e-3)


# -- 6-axis filters on a source with a field, and the default ---------------------------------
def test_every_filter_runs_on_a_source_with_a_field_and_6_axis_ones_ignore_it(real_slice):
    block = real_slice[1]
    sparse = block.mag_ut.copy()
    sparse[np.arange(len(sparse)) % 3 != 0] = np.nan  # a slower magnetometer
    with_field = dataclasses.replace(block, mag_ut=sparse)
    without = dataclasses.replace(block, mag_ut=None)
    for name, cls in FILTERS.items():
        out = create_filter(name).process(with_field).quat
        assert np.all(np.isfinite(out)), name
        if not cls.uses_magnetometer:
            np.testing.assert_array_equal(out, create_filter(name).process(without).quat)


def test_a_source_with_a_magnetometer_gets_the_9_axis_default():
    assert default_filter_for(False) == DEFAULT_FILTER
    nine = default_filter_for(True)
    assert FILTERS[nine].uses_magnetometer and nine in ONLINE_FILTERS
    assert Pipeline(104.0, has_magnetometer=True).filter.name == nine
    assert Pipeline(104.0).filter.name == DEFAULT_FILTER
    assert Pipeline(104.0, "mahony", has_magnetometer=True).filter.name == "mahony"


def test_turned_source_turns_what_the_filters_see(real_slice):
    from app.core.evaluation import StreamSource

    block = real_slice[1]
    turn = turn_quaternion(PROJECT_TURN_DEG)
    source = turned_source(StreamSource("s", lambda: [block]), turn)
    (seen,) = list(source.blocks())
    np.testing.assert_allclose(seen.mag_ut, turn_vectors(turn, block.mag_ut))
    assert heading_error_deg(seen.reference_quat, turn_reference(turn, block.reference_quat)
                             ).max() < 1e-9


def test_the_simulators_true_errors_undo_its_magnetometers_iron_and_turn_too():
    """measured = S R b + h (soft iron, the chips' turn, hard iron): the compensating
    calibration gives b back in the accelerometer's frame, so a simulated 9-axis heading is
    scored without the board's iron in it."""
    from app.core.evaluation import calibration_from_unit_errors
    from drivers.sim.error_model import MagnetometerErrors, UnitErrors

    unit = dataclasses.replace(UnitErrors.draw(5), magnetometer=MagnetometerErrors.draw(5))
    mag = unit.magnetometer
    truth = np.random.default_rng(0).normal(size=(20, 3)) * 40.0
    measured = truth @ (mag.soft_iron @ mag.alignment).T + mag.hard_iron_ut
    n = len(truth)
    block = SampleBlock(np.arange(n) * 0.01, np.tile([0.0, 0.0, 9.8], (n, 1)), np.zeros((n, 3)),
                        np.full(n, 25.0), np.zeros(n, bool), None, measured)
    calibrated = calibration_from_unit_errors(unit).apply(block)
    np.testing.assert_allclose(calibrated.mag_ut, truth, atol=1e-9)
    assert calibration_from_unit_errors(UnitErrors.draw(5)).magnetometer is None


def test_a_stream_scored_in_pieces_gives_the_same_heading_as_whole(real_slice):
    """A long recording is scored piece by piece (memory that does not grow): the heading and
    total errors accumulate to what the whole stream gives."""
    from app.core.evaluation import StreamSource, evaluate_source, split_block

    _, block, mask = real_slice
    turned = turn_block(block, turn_quaternion(PROJECT_TURN_DEG))
    whole = StreamSource("whole", lambda: [turned], score_mask=mask)
    pieces = StreamSource("pieces", lambda: [turned], pieces=lambda: (
        (piece, mask[k * 1000:(k + 1) * 1000])
        for k, piece in enumerate(split_block(turned, 1000))))
    filters = ["vqf", "madgwick", "gyro"]
    one = evaluate_source(whole, filters, repeats=1, block=1000)
    other = evaluate_source(pieces, filters, repeats=1, block=1000)
    assert one.has_field and other.has_field
    for name in filters:
        a, b = one.score(name), other.score(name)
        assert b.heading_rmse_deg == pytest.approx(a.heading_rmse_deg, rel=1e-9)
        assert b.total_rmse_deg == pytest.approx(a.total_rmse_deg, rel=1e-9)
        assert a.magnetic == b.magnetic == FILTERS[name].uses_magnetometer
