"""Joint angles between two IMUs on a hinge: sim://arm, the axis fit, the heading tracker, the
causal estimator and ``inclinometer joint``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app import cli
from app.core import quaternion as quat
from app.core.joint.alignment import align_to
from app.core.joint.axis import consistent_sign, estimate_hinge_axes
from app.core.joint.estimator import JointEstimator, hinge_angle
from app.core.joint.heading import HeadingTracker, heading_measurements
from app.core.joint.offline import joint_angle_offline
from app.core.recording.reader import read_recording
from app.core.samples import SampleBlock, convert_raw_block
from app.services.arm_recordings import JOINT_REFERENCE_COLUMN, record_arm
from drivers.errors import DeviceUrlError
from drivers.sim.device import SimulatedDevice
from drivers.sim.scenarios import Arm

SECONDS = 40.0
SKIP_S = 10.0


def _stream(url: str, seconds: float) -> tuple[SampleBlock, SimulatedDevice]:
    device = SimulatedDevice(url, realtime=False, block=8192)
    device.open()
    wanted = math.ceil(seconds * device.odr_hz)
    blocks = []
    while sum(len(b) for b in blocks) < wanted:
        raw = device.read(1.0)
        if raw is not None:
            blocks.append(convert_raw_block(raw))
    device.close()
    cat = np.concatenate
    return SampleBlock(
        cat([b.t_s for b in blocks])[:wanted], cat([b.accel_m_s2 for b in blocks])[:wanted],
        cat([b.gyro_rad_s for b in blocks])[:wanted], cat([b.temp_degc for b in blocks])[:wanted],
        cat([b.gap for b in blocks])[:wanted], cat([b.reference_quat for b in blocks])[:wanted],
    ), device


@pytest.fixture(scope="module")
def arm_pair():
    """40 s of a two-link arm at 208 Hz: both sensors' blocks, the scenario, the true angle."""
    url = "sim://arm?odr=208&seed=7"
    b1, d1 = _stream(url + "&sensor=0", SECONDS)
    b2, d2 = _stream(url + "&sensor=1", SECONDS)
    scenario = d2.scenario
    assert isinstance(scenario, Arm)
    truth = scenario.joint_angles_deg(np.arange(len(b1)) / d2.true_odr_hz)[:, 0]
    return b1, b2, d1, d2, scenario, truth


def rmse_up_to_sign_and_offset(estimate_deg: np.ndarray, truth_deg: np.ndarray) -> float:
    best = math.inf
    for sign in (1.0, -1.0):
        d = np.radians(sign * estimate_deg - truth_deg)
        e = np.angle(np.exp(1j * (d - np.angle(np.mean(np.exp(1j * d))))))
        best = min(best, math.degrees(math.sqrt(float(np.mean(e * e)))))
    return best


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(a @ b)))))


# -- sim://arm --
def test_arm_sensors_share_one_arm_and_clock_but_are_separate_units(arm_pair):
    b1, b2, d1, d2, scenario, truth = arm_pair
    np.testing.assert_array_equal(b1.t_s, b2.t_s)
    assert d1.unique_id != d2.unique_id
    assert not np.allclose(d1.unit_errors.gyro_bias_rad_s, d2.unit_errors.gyro_bias_rad_s)
    for device in (d1, d2):
        assert np.all(np.abs(device.unit_errors.gyro_bias_rad_s) <= math.radians(0.5))
    # The true orientations obey the hinge: the axis is one direction seen from both sensors,
    # and the relative orientation's angle about it is the true joint angle.
    j1 = scenario.axis_in_sensor(1, 0)
    j2 = scenario.axis_in_sensor(1, 1)
    e1 = quat.rotate(b1.reference_quat, j1)
    e2 = quat.rotate(b2.reference_quat, j2)
    assert np.max(np.linalg.norm(e1 - e2, axis=1)) < 1e-6
    true_angle = np.degrees(hinge_angle(b1.reference_quat, b2.reference_quat, j1, j2))
    assert rmse_up_to_sign_and_offset(true_angle, truth) < 1e-4
    assert truth.min() >= 10.0 and truth.max() <= 130.0
    assert truth.max() - truth.min() > 60.0


def test_arm_rates_are_the_derivative_of_its_orientation():
    scenario = Arm(np.random.default_rng(3), links=3, sensor=2)
    t = np.linspace(0.0, 30.0, 500)
    analytic = scenario.motion(t).angular_rate_rad_s
    np.testing.assert_allclose(scenario.numerical_angular_rate(t), analytic, atol=1e-5)


def test_arm_rejects_a_sensor_beyond_its_links():
    with pytest.raises(DeviceUrlError, match="sensor=2"):
        SimulatedDevice("sim://arm?links=2&sensor=2")


def test_record_arm_writes_one_readable_file_per_sensor_with_the_truth(tmp_path):
    written = record_arm("sim://arm?odr=52&seed=2&links=3", 3.0, tmp_path)
    assert [w.path.name for w in written] == ["sensor0.csv", "sensor1.csv", "sensor2.csv"]
    recordings = [read_recording(w.path) for w in written]
    assert len({len(r) for r in recordings}) == 1
    assert JOINT_REFERENCE_COLUMN not in recordings[0].unknown_columns
    for k in (1, 2):
        ref = recordings[k].unknown_columns[JOINT_REFERENCE_COLUMN]
        assert np.all((ref >= 10.0) & (ref <= 130.0))
        axes = recordings[k].metadata["arm"]["true_axes"]
        assert f"joint_{k}_in_sensor_{k}" in axes
    assert recordings[1].has_reference
    with pytest.raises(ValueError, match="exists"):
        record_arm("sim://arm?odr=52&seed=2&links=3", 3.0, tmp_path)


# -- axis and heading --
def test_axis_fit_recovers_the_mounting_axis(arm_pair):
    b1, b2, _, _, scenario, _ = arm_pair
    found = estimate_hinge_axes(b1.gyro_rad_s, b2.gyro_rad_s)
    assert angle_deg(found.j1, scenario.axis_in_sensor(1, 0)) < 0.5
    assert angle_deg(found.j2, scenario.axis_in_sensor(1, 1)) < 0.5
    assert found.smallest_singular > 0.1
    assert found.well_determined


def test_axis_fit_reports_motion_that_cannot_show_the_axis():
    rng = np.random.default_rng(1)
    # Both sensors turn only about the hinge axis itself: every axis is consistent with it.
    rate = np.outer(rng.normal(size=2000), [0.0, 0.0, 1.0]) + 1e-4 * rng.normal(size=(2000, 3))
    found = estimate_hinge_axes(rate, rate)
    rich = estimate_hinge_axes(rng.normal(size=(2000, 3)), rng.normal(size=(2000, 3)))
    assert found.smallest_singular < 0.1 * rich.smallest_singular


def test_consistent_sign_flips_a_mirrored_axis(arm_pair):
    b1, b2, _, _, scenario, _ = arm_pair
    j1, j2 = scenario.axis_in_sensor(1, 0), scenario.axis_in_sensor(1, 1)
    np.testing.assert_array_equal(consistent_sign(j1, -j2, b1.reference_quat, b2.reference_quat),
                                  j2)


def test_heading_tracker_follows_a_drifting_offset():
    rng = np.random.default_rng(4)
    n, dt = 6000, 0.01
    t = np.arange(n) * dt
    offset = 0.7 + 0.002 * t  # rad, drifting 0.11 deg/s
    axis = np.column_stack([np.cos(0.3 * t), np.sin(0.2 * t), 0.5 + 0.3 * np.sin(0.1 * t)])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    rotated = np.column_stack([np.cos(offset) * axis[:, 0] - np.sin(offset) * axis[:, 1],
                               np.sin(offset) * axis[:, 0] + np.cos(offset) * axis[:, 1],
                               axis[:, 2]])
    rotated[:, :2] += 0.01 * rng.normal(size=(n, 2))
    # Sensor frames equal to the two earth frames; the axis is x in both sensors' frames.
    q1 = _quat_taking_x_to(axis)
    q2 = _quat_taking_x_to(rotated / np.linalg.norm(rotated, axis=1, keepdims=True))
    x = np.array([1.0, 0.0, 0.0])
    z = heading_measurements(q1, x, q2, x)
    estimate = HeadingTracker().update(z, np.full(n, dt))
    error = np.degrees(np.angle(np.exp(1j * (estimate - offset))))[n // 2:]
    assert np.sqrt(np.mean(error**2)) < 0.3


def _quat_taking_x_to(v: np.ndarray) -> np.ndarray:
    """(N, 4) rotations taking the x axis to the unit vectors ``v`` (N, 3)."""
    x = np.array([1.0, 0.0, 0.0])
    axis = np.cross(x, v)
    angle = np.arccos(np.clip(v @ x, -1.0, 1.0))
    return quat.from_axis_angle(axis, angle)


# -- joint angle --
def test_joint_angle_with_estimated_axis_is_accurate(arm_pair):
    b1, b2, _, _, scenario, truth = arm_pair
    result = joint_angle_offline(b1, b2)
    scored = b1.t_s >= SKIP_S
    assert rmse_up_to_sign_and_offset(result.angles.angle_deg[scored], truth[scored]) < 1.0
    assert angle_deg(result.j1, scenario.axis_in_sensor(1, 0)) < 0.5
    assert result.axis_spread_deg < 2.0


def test_live_estimator_is_causal_and_converges(arm_pair):
    b1, b2, _, _, _, truth = arm_pair

    def run(blocks1, blocks2) -> np.ndarray:
        estimator = JointEstimator()
        return np.concatenate([estimator.update(x, y).angle_deg
                               for x, y in zip(blocks1, blocks2, strict=True)])

    size = 52
    cuts = list(range(0, len(b1), size))
    whole = run(*([_slice(b, c, c + size) for c in cuts] for b in (b1, b2)))
    # Later samples never change earlier output: the first half alone gives the same numbers.
    half = cuts[len(cuts) // 2]
    first = run(*([_slice(b, c, c + size) for c in cuts if c < half] for b in (b1, b2)))
    np.testing.assert_array_equal(first, whole[:half])
    assert np.isnan(whole[0])  # no axis yet
    late = b1.t_s >= 20.0
    assert rmse_up_to_sign_and_offset(whole[late], truth[late]) < 1.5


def test_given_axes_are_used_as_they_are(arm_pair):
    b1, b2, _, _, scenario, truth = arm_pair
    j1, j2 = scenario.axis_in_sensor(1, 0), scenario.axis_in_sensor(1, 1)
    result = joint_angle_offline(b1, b2, (3.0 * j1, j2))
    np.testing.assert_allclose(result.j1, j1)
    assert result.axis_estimate is None
    scored = b1.t_s >= SKIP_S
    assert rmse_up_to_sign_and_offset(result.angles.angle_deg[scored], truth[scored]) < 1.0


def _slice(block: SampleBlock, start: int, stop: int) -> SampleBlock:
    return SampleBlock(block.t_s[start:stop], block.accel_m_s2[start:stop],
                       block.gyro_rad_s[start:stop], block.temp_degc[start:stop],
                       block.gap[start:stop])


def test_alignment_interpolates_a_second_recording_on_its_own_clock(arm_pair):
    b1, b2, *_ = arm_pair
    n = 400
    shifted = _slice(b2, 1, n)
    shifted.t_s = shifted.t_s - 0.5 * (b2.t_s[1] - b2.t_s[0])  # half a sample early
    aligned, covered, how = align_to(_slice(b1, 0, n), shifted)
    assert "interpolated" in how
    assert len(aligned) == n
    assert not covered[0] and not covered[-1] and covered[1:-1].all()
    same, all_rows, how = align_to(_slice(b1, 0, n), _slice(b2, 0, n))
    assert how == "row by row" and all_rows.all()
    np.testing.assert_array_equal(same.gyro_rad_s, b2.gyro_rad_s[:n])


# -- inclinometer joint --
@pytest.fixture(scope="module")
def arm_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("arm")
    record_arm("sim://arm?odr=104&seed=5", 25.0, folder)
    return folder / "sensor0.csv", folder / "sensor1.csv"


def _read_joint(path: Path) -> tuple[list[str], list[str], np.ndarray]:
    lines = path.read_text(encoding="utf-8").splitlines()
    comments = [line for line in lines if line.startswith("#")]
    rest = [line for line in lines if not line.startswith("#")]
    values = np.array([[float(x) if x else math.nan for x in row.split(",")]
                       for row in rest[1:]])
    return comments, rest[0].split(","), values


def test_cli_joint_writes_t_and_joint_deg_for_every_row(arm_files, tmp_path, capsys):
    a, b = arm_files
    out = tmp_path / "j.csv"
    assert cli.main(["joint", str(a), str(b), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "axis in A:" in printed and "smallest singular value" in printed
    comments, header, values = _read_joint(out)
    assert comments[0] == "# inclinometer-joint 1"
    assert header == ["t", "joint_deg"]
    recording_a = read_recording(a)
    np.testing.assert_array_equal(values[:, 0], recording_a.t_s)
    truth = read_recording(b).unknown_columns[JOINT_REFERENCE_COLUMN]
    scored = values[:, 0] >= SKIP_S
    assert rmse_up_to_sign_and_offset(values[scored, 1], truth[scored]) < 1.5


def test_cli_joint_with_fewer_rows_in_b_keeps_one_row_per_row_of_a(arm_files, tmp_path):
    a, b = arm_files
    lines = b.read_text(encoding="utf-8").splitlines(keepends=True)
    header_at = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    thinned = tmp_path / "b_thinned.csv"  # every third row dropped, the last 100 rows too
    rows = [line for i, line in enumerate(lines[header_at + 1:-100]) if i % 3 != 2]
    thinned.write_text("".join(lines[:header_at + 1] + rows), encoding="utf-8")
    out = tmp_path / "j.csv"
    assert cli.main(["joint", str(a), str(thinned), "--out", str(out), "--axis",
                     "1,0,0:0,1,0"]) == 0
    comments, _, values = _read_joint(out)
    assert len(values) == len(read_recording(a))
    assert np.isnan(values[-1, 1]) and np.isfinite(values[len(values) // 2, 1])
    assert any("interpolated" in line for line in comments)


@pytest.mark.parametrize("axis", ["1,0:0,1,0", "a,b,c:1,0,0", "0,0,0:1,0,0", "1,0,0"])
def test_cli_joint_rejects_a_malformed_axis(arm_files, tmp_path, capsys, axis):
    a, b = arm_files
    out = tmp_path / "j.csv"
    assert cli.main(["joint", str(a), str(b), "--out", str(out), "--axis", axis]) == 2
    assert "--axis" in capsys.readouterr().err
    assert not out.exists()


def test_cli_joint_reports_a_missing_file_and_keeps_an_existing_output(arm_files, tmp_path,
                                                                        capsys):
    a, _ = arm_files
    assert cli.main(["joint", str(a), str(tmp_path / "none.csv"), "--out",
                     str(tmp_path / "j.csv")]) == 2
    assert "none.csv" in capsys.readouterr().err
    existing = tmp_path / "keep.csv"
    existing.write_text("mine", encoding="utf-8")
    assert cli.main(["joint", str(a), str(a), "--out", str(existing)]) == 2
    assert existing.read_text(encoding="utf-8") == "mine"


def test_cli_record_arm_writes_every_sensor_and_refuses_other_scenarios(tmp_path, capsys):
    target = tmp_path / "arm"
    assert cli.main(["record-arm", "sim://arm?links=3&odr=26&seed=9", str(target),
                     "--duration", "2"]) == 0
    assert sorted(p.name for p in target.iterdir()) == [
        "sensor0.csv", "sensor1.csv", "sensor2.csv"]
    assert "sensor 2" in capsys.readouterr().out
    assert cli.main(["record-arm", "sim://wobble", str(tmp_path / "other")]) == 2
    assert "not a measuring arm" in capsys.readouterr().err
    assert not (tmp_path / "other").exists()


def test_vqf_parameters_reach_both_links_filters():
    estimator = JointEstimator(vqf_parameters={"bias_sigma_init_dps": 1.0})
    assert estimator.vqf1.get_parameter("bias_sigma_init_dps") == 1.0
    assert estimator.vqf2.get_parameter("bias_sigma_init_dps") == 1.0
    with pytest.raises(ValueError, match="outside"):
        JointEstimator(vqf_parameters={"tau_acc_s": -1.0})
