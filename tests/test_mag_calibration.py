"""The magnetometer's calibration (#31 item 4): coverage, the fits against a known truth,
the verdicts, the refusals and ``inclinometer calibrate-mag`` end to end on a real file."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.cli import main
from app.core.calibration import MagnetometerCalibration, SensorCalibration
from app.core.calibration_procedures.profiles import (
    ProfileStore,
    SensorSettings,
    make_profile,
    read_profile_file,
)
from app.core.devices import DeviceInfo, MagnetometerInfo
from app.core.earth_field import DEFAULT_PLACE, earth_field
from app.core.magnetometer.coverage import (
    SECTIONS,
    CoverageTracker,
    completion_mask,
    mask_from_completion,
    section_centres,
    section_centres_az_el,
    section_of,
    section_outlines,
)
from app.core.magnetometer.fit import (
    MagFitResult,
    alignment_deg,
    fit_ellipsoid,
    fit_magnetometer,
    gyro_bias_from_tilt,
    rotation_angle_deg,
    smoothed_gravity,
)
from app.core.magnetometer.tours import (
    hand_tour,
    heading_errors_deg,
    pose_tour,
    random_unit,
    true_soft_iron,
)
from app.core.recording import UNIT_SCALE, RecordingWriter, recording_metadata
from app.core.samples import RawBlock

EARTH = earth_field(DEFAULT_PLACE, 2026.9)
UNIT = random_unit(3, hard_iron_ut=35.0, soft_fraction=0.05, turn_deg=1.8)


def turn_error_deg(estimate: np.ndarray, truth: np.ndarray) -> float:
    """The angle of the rotation left between two soft-iron matrices."""
    u, _, vt = np.linalg.svd(estimate @ np.linalg.inv(truth))
    return rotation_angle_deg(u @ vt)


@pytest.fixture(scope="module")
def full_tour():
    return pose_tour(UNIT, EARTH, seed=11, poses=300)


@pytest.fixture(scope="module")
def full_fit(full_tour) -> MagFitResult:
    return fit_magnetometer(full_tour.mag_ut, full_tour.accel_m_s2, t_s=full_tour.t_s,
                            expected=EARTH)


# -- coverage ---------------------------------------------------------------------------------
def test_the_80_sections_split_the_sphere_about_evenly_and_each_centre_is_its_own():
    directions = np.random.default_rng(0).normal(size=(40_000, 3))
    counts = np.bincount(section_of(directions), minlength=SECTIONS)
    assert counts.size == SECTIONS and counts.min() > 0.75 * 500 and counts.max() < 1.35 * 500
    np.testing.assert_array_equal(section_of(section_centres()), np.arange(SECTIONS))
    assert section_of(np.array([[0.0, 0.0, 0.0], [np.nan, 1.0, 0.0]])).tolist() == [-1, -1]
    outlines = section_outlines()
    assert len(outlines) == SECTIONS and all(o.shape[1] == 2 for o in outlines)
    assert np.all(np.abs(section_centres_az_el()[:, 1]) <= 90.0)


def test_the_completion_mask_is_mavlinks_ten_bytes_section_k_in_byte_k_div_8():
    mask = np.zeros(SECTIONS, dtype=bool)
    mask[[0, 9, 79]] = True
    data = completion_mask(mask)
    assert data == bytes([1, 2, 0, 0, 0, 0, 0, 0, 0, 0x80])
    np.testing.assert_array_equal(mask_from_completion(data), mask)


def test_the_tracker_fills_in_as_rows_arrive_ignores_nan_rows_and_finds_the_centre():
    tour = pose_tour(UNIT, EARTH, seed=2, poses=300)
    tracker = CoverageTracker()
    fractions = []
    for start in range(0, len(tour.mag_ut), 200):
        tracker.add(tour.mag_ut[start:start + 200])  # every other row is NaN
        fractions.append(tracker.fraction)
    assert fractions == sorted(fractions) and fractions[-1] > 0.9
    assert tracker.rows == int(np.all(np.isfinite(tour.mag_ut), axis=1).sum())
    np.testing.assert_allclose(tracker.centre_ut, UNIT.hard_iron_ut, atol=3.0)
    assert len(tracker.completion_mask()) == 10 and tracker.mask.sum() == round(
        tracker.fraction * 80)
    half = CoverageTracker(centre_ut=UNIT.hard_iron_ut)
    half.add(pose_tour(UNIT, EARTH, seed=2, half_sphere=True).mag_ut)
    assert 0.3 < half.fraction < 0.7


# -- the fit against the truth ------------------------------------------------------------------
def test_the_fit_recovers_hard_iron_soft_iron_and_the_turn(full_fit):
    cal = full_fit.calibration
    truth = true_soft_iron(UNIT)
    np.testing.assert_allclose(cal.hard_iron_ut, UNIT.hard_iron_ut, atol=0.5)
    assert np.max(np.abs(cal.soft_iron - truth)) < 0.005  # 0.5 % of a unit matrix
    assert turn_error_deg(cal.soft_iron, truth) < 0.2
    assert cal.extra["alignment_deg"] == pytest.approx(alignment_deg(truth), abs=0.2)
    assert cal.extra["alignment_deg"] > 1.0  # the unit's turn is 1.8 degrees
    gain = np.cbrt(np.linalg.det(UNIT.distortion))
    assert cal.field_ut == pytest.approx(EARTH.total_ut * gain, rel=0.005)
    assert cal.dip_deg == pytest.approx(EARTH.dip_deg, abs=0.3)
    assert cal.fitness_ut < 0.6 and cal.coverage >= 0.9
    assert full_fit.verdict == "good" and full_fit.reasons == ()


def test_the_plain_ellipsoid_fit_leaves_the_turn_in_the_heading(full_tour, full_fit):
    plain = fit_ellipsoid(full_tour.mag_ut)
    truth = true_soft_iron(UNIT)
    np.testing.assert_allclose(plain.hard_iron_ut, UNIT.hard_iron_ut, atol=0.5)
    assert np.allclose(plain.soft_iron, plain.soft_iron.T)  # symmetric: no turn in it
    assert turn_error_deg(plain.soft_iron, truth) == pytest.approx(UNIT.turn_deg, abs=0.3)
    test = pose_tour(UNIT, EARTH, seed=12, poses=200)  # a tour neither fit saw
    rows = np.all(np.isfinite(test.clean_mag_ut), axis=1)
    ours = heading_errors_deg(full_fit.calibration.apply(test.clean_mag_ut[rows]),
                              test.rotations[rows])
    theirs = heading_errors_deg(plain.apply(test.clean_mag_ut[rows]), test.rotations[rows])
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    assert rms(ours) < 0.5
    assert rms(theirs) > 0.6 * UNIT.turn_deg and rms(theirs) > 3 * rms(ours)


def test_the_gyroscope_carries_gravity_through_a_shaken_hand_tour():
    tour = hand_tour(UNIT, EARTH, seed=4, seconds=30.0, linear_m_s2=0.3, gyro_bias_rad_s=0.01)
    bias = gyro_bias_from_tilt(tour.accel_m_s2, tour.gyro_rad_s, tour.t_s)
    # the bias (0.6 deg/s per axis) is found to a fraction of itself through the shaking
    assert np.linalg.norm(bias - 0.01) < 0.5 * np.linalg.norm([0.01] * 3)
    up = smoothed_gravity(tour.accel_m_s2, tour.gyro_rad_s - bias, tour.t_s)
    true_up = tour.rotations[:, 2, :]  # the earth's z axis in sensor coordinates
    raw = tour.accel_m_s2 / np.linalg.norm(tour.accel_m_s2, axis=1, keepdims=True)
    angle = lambda a: np.degrees(np.arccos(np.clip(np.sum(a * true_up, 1), -1, 1)))  # noqa
    assert np.sqrt(np.mean(angle(up) ** 2)) < 0.7 * np.sqrt(np.mean(angle(raw) ** 2))


# -- verdicts and refusals -----------------------------------------------------------------------
def test_a_half_sphere_tour_is_redo_for_coverage():
    tour = pose_tour(UNIT, EARTH, seed=5, half_sphere=True)
    result = fit_magnetometer(tour.mag_ut, tour.accel_m_s2, expected=EARTH)
    assert result.verdict == "redo" and result.calibration.coverage < 0.75
    assert any("too little coverage" in reason for reason in result.reasons)


@pytest.mark.parametrize("peak_ut", [40.0, 150.0])
def test_a_magnet_passing_during_the_tour_is_redo_and_left_out(peak_ut):
    tour = pose_tour(UNIT, EARTH, seed=6, disturbance_ut=peak_ut)
    result = fit_magnetometer(tour.mag_ut, tour.accel_m_s2, t_s=tour.t_s, expected=EARTH)
    assert result.verdict == "redo" and result.outliers > 10
    assert any("disturbance during the tour" in reason and "t = " in reason
               for reason in result.reasons)
    np.testing.assert_allclose(result.calibration.hard_iron_ut, UNIT.hard_iron_ut, atol=1.0)


def test_a_noisy_field_as_near_a_running_motor_is_redo_for_its_residual():
    tour = pose_tour(UNIT, EARTH, seed=10)
    noisy = tour.mag_ut + np.random.default_rng(3).normal(scale=1.0, size=tour.mag_ut.shape)
    result = fit_magnetometer(noisy, tour.accel_m_s2, expected=EARTH)
    assert result.verdict == "redo" and result.calibration.fitness_ut > 0.7
    assert any("residual is large" in reason for reason in result.reasons)
    assert fit_magnetometer(tour.mag_ut, tour.accel_m_s2, expected=EARTH).verdict == "good"


def test_a_field_far_from_the_wmm_is_redo():
    tour = pose_tour(UNIT, EARTH, seed=7, field_scale=1.3)
    result = fit_magnetometer(tour.mag_ut, tour.accel_m_s2, expected=EARTH)
    assert result.verdict == "redo"
    assert any("far from the local WMM value" in reason for reason in result.reasons)
    assert fit_magnetometer(tour.mag_ut, tour.accel_m_s2).verdict == "good"  # no reference


def test_without_an_accelerometer_the_fit_is_the_ellipsoid_and_says_so():
    tour = pose_tour(UNIT, EARTH, seed=8)
    result = fit_magnetometer(tour.mag_ut)
    assert result.calibration.extra["method"] == "ellipsoid"
    assert result.calibration.extra["alignment_deg"] is None
    assert math.isnan(result.calibration.dip_deg)
    assert any("not estimated" in note for note in result.notes)


def test_bad_tours_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="no field samples"):
        fit_magnetometer(np.full((500, 3), np.nan))
    tour = pose_tour(UNIT, EARTH, seed=9)
    rows = np.flatnonzero(np.all(np.isfinite(tour.mag_ut), axis=1))
    with pytest.raises(ValueError, match="too few field samples"):
        fit_magnetometer(tour.mag_ut[rows[:20]])
    angles = np.linspace(0, 4 * np.pi, 400)  # turned about z only: a flat circle
    flat = np.column_stack([20 * np.cos(angles), 20 * np.sin(angles), np.full(400, -45.0)])
    with pytest.raises(ValueError, match="flat"):
        fit_magnetometer(flat + UNIT.hard_iron_ut)
    with pytest.raises(ValueError, match="never changed"):
        fit_magnetometer(np.tile([10.0, 20.0, 30.0], (100, 1)))
    with pytest.raises(ValueError, match="shape"):
        fit_magnetometer(tour.mag_ut, tour.accel_m_s2[:10])


# -- the command ------------------------------------------------------------------------------
def write_tour(path, tour, unique_id: str = "MAG-UNIT-1") -> None:
    magnetometer = MagnetometerInfo("LIS3MDL", 155.0, 400.0, 100.0 / 6842, address=0x1C,
                                    mode="ultra-high-performance", path="bus")
    info = DeviceInfo("sim://static", "Bench", unique_id, "LSM6DSOX", 100.0, 104.0, 4, 250,
                      magnetometer=magnetometer)
    writer = RecordingWriter(path, recording_metadata(device=info)).start()
    n = len(tour.t_s)
    for start in range(0, n, 50):
        rows = slice(start, start + 50)
        count = len(tour.t_s[rows])
        writer.write(RawBlock(tour.t_s[rows], tour.accel_m_s2[rows], tour.gyro_rad_s[rows],
                              np.full(count, 25.0), UNIT_SCALE, mag_raw=tour.mag_ut[rows]))
    assert writer.close().state == "stopped"


@pytest.fixture(scope="module")
def tour_file(tmp_path_factory):
    """A minute's tour by hand: turned continuously and shaken, the gyroscope biased."""
    path = tmp_path_factory.mktemp("tour") / "tour.csv"
    write_tour(path, hand_tour(UNIT, EARTH, seed=21))
    return path


def test_calibrate_mag_writes_the_binding_json_and_a_summary(tour_file, tmp_path, capsys):
    out = tmp_path / "mag.json"
    assert main(["calibrate-mag", str(tour_file), "--json", str(out),
                 "--place", "52.5125,13.3269", "--date", "2026-11-27"]) == 0
    document = json.loads(out.read_text())
    assert list(document) == ["magnetometer"]
    body = document["magnetometer"]
    for key in ("hard_iron_uT", "soft_iron", "field_uT", "dip_deg", "fitness_uT", "coverage",
                "alignment_deg", "method", "verdict", "reasons"):
        assert key in body, key
    assert body["verdict"] == "good" and body["reasons"] == []
    assert body["wmm"]["field_uT"] == pytest.approx(EARTH.total_ut, rel=1e-3)
    cal = MagnetometerCalibration.from_json(body)
    np.testing.assert_allclose(cal.hard_iron_ut, UNIT.hard_iron_ut, atol=0.5)
    assert turn_error_deg(cal.soft_iron, true_soft_iron(UNIT)) < 0.2
    text = capsys.readouterr().out
    for word in ("hard iron", "soft iron", "alignment", "field", "dip", "residual",
                 "coverage", "verdict      good"):
        assert word in text, word
    # an existing output is refused without --overwrite, and left as it was
    before = out.read_bytes()
    assert main(["calibrate-mag", str(tour_file), "--json", str(out)]) == 2
    assert out.read_bytes() == before
    assert "exists" in capsys.readouterr().err
    # the recording itself is never the output, even with --overwrite
    recorded = tour_file.read_bytes()
    assert main(["calibrate-mag", str(tour_file), "--json", str(tour_file), "--overwrite"]) == 2
    assert tour_file.read_bytes() == recorded


def test_calibrate_mag_saves_into_the_devices_profile_keeping_its_other_terms(
        tour_file, tmp_path, capsys):
    store = ProfileStore(tmp_path / "profiles")
    accel_matrix = np.diag([1.01, 0.99, 1.0])
    store.save(make_profile("MAG-UNIT-1", SensorCalibration(accel_matrix=accel_matrix,
                                                             name="bench"),
                            SensorSettings(104.0, 4, 250), method="six-position"))
    assert main(["calibrate-mag", str(tour_file), "--save",
                 "--profile-dir", str(store.base_dir)]) == 0
    profile = read_profile_file(store.path_for("MAG-UNIT-1"))
    np.testing.assert_array_equal(profile.calibration.accel_matrix, accel_matrix)
    mag = profile.calibration.magnetometer
    assert mag is not None and profile.method == "six-position + magnetometer"
    np.testing.assert_allclose(mag.hard_iron_ut, UNIT.hard_iron_ut, atol=0.5)
    assert len(store.history("MAG-UNIT-1")) == 1  # the old profile was kept
    assert "saved in the profile" in capsys.readouterr().out


def test_a_redo_is_not_saved_without_force(tmp_path, capsys):
    path = tmp_path / "half.csv"
    write_tour(path, pose_tour(UNIT, EARTH, seed=5, half_sphere=True), unique_id="HALF-1")
    store = ProfileStore(tmp_path / "profiles")
    args = ["calibrate-mag", str(path), "--save", "--profile-dir", str(store.base_dir)]
    assert main(args) == 1
    assert "not saved" in capsys.readouterr().err and not store.exists("HALF-1")
    assert main([*args, "--force"]) == 0
    assert store.load("HALF-1").calibration.magnetometer is not None


def test_calibrate_mag_refuses_bad_input_in_one_line(tmp_path, capsys):
    assert main(["calibrate-mag", str(tmp_path / "none.csv"), "--json",
                 str(tmp_path / "o.json")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["calibrate-mag", str(tmp_path / "none.csv")]) == 2
    assert "--json OUT and/or --save" in capsys.readouterr().err
    assert main(["calibrate-mag", "x.csv", "--json", str(tmp_path / "o.json"),
                 "--place", "95,10"]) == 2
    assert "latitude" in capsys.readouterr().err
    empty = tmp_path / "nomag.csv"
    writer = RecordingWriter(empty, recording_metadata()).start()
    n = 100
    writer.write(RawBlock(np.arange(n) / 100.0, np.tile([0, 0, 9.8], (n, 1)), np.zeros((n, 3)),
                          np.full(n, 25.0), UNIT_SCALE))
    writer.close()
    assert main(["calibrate-mag", str(empty), "--json", str(tmp_path / "o.json")]) == 1
    err = capsys.readouterr().err
    assert "no magnetometer" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o.json").exists()


def test_old_profiles_without_the_magnetometer_still_load(tmp_path):
    store = ProfileStore(tmp_path)
    path = store.save(make_profile("OLD-1", SensorCalibration(name="old"),
                                   SensorSettings(104.0, 4, 250)))
    data = json.loads(path.read_text())
    assert "magnetometer" not in data["parameters"]
    assert store.load("OLD-1").calibration.magnetometer is None
