"""Accelerometer calibration against the simulator's injected errors.

The truth to compare with is the simulated unit's errors *at the temperature of the poses*
(``measured = (1 + scale_tc dT) M true + bias + bias_tc dT + walk``, ``dT = T - 25``): the
fit sees exactly that. Over the minute of a tour the die warms by about 0.5 degC, so the
temperature terms move by about 0.05 mg and 0.005 %, and the accelerometer's random walk by
a few hundredths of a mg: far below the 1 mg and 0.05 % targets, which are asserted as such.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from app.core.calibration_procedures import (
    FACE_DIRECTIONS,
    FREE,
    SIX_POSITION,
    CalibrationFitError,
    CaptureState,
    PoseCapture,
    SensorNoise,
    StillnessDetector,
    compare_poses,
    compare_tilt,
    fit_ellipsoid,
    fit_free_poses,
    fit_known_orientations,
    fit_six_position,
)
from app.core.calibration_procedures.accel_fit import AccelFit
from app.core.orientation import angles_from_up, up_in_sensor_frame
from app.core.samples import STANDARD_GRAVITY_M_S2 as G
from app.core.samples import SampleBlock, convert_raw_block
from drivers.registry import open_device

MG = G * 1e-3
TILT_POSES = [  # (roll, pitch, yaw) across +-60 degrees of tilt
    (0.0, 0.0, 0.0), (60.0, 0.0, 10.0), (-60.0, 0.0, -30.0), (0.0, 60.0, 45.0),
    (0.0, -60.0, 90.0), (40.0, 40.0, 0.0), (-35.0, 45.0, 120.0), (25.0, -50.0, -60.0),
    (-45.0, -40.0, 180.0), (15.0, 10.0, 0.0),
]


def capture_for(dev, mode: str = SIX_POSITION, **kwargs) -> PoseCapture:
    info = dev.info
    noise = SensorNoise.lsm6dsox(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps)
    return PoseCapture(StillnessDetector(noise), mode=mode, **kwargs)


def run_tour(seed: int, hold: float = 6.0, **kwargs) -> tuple[object, PoseCapture]:
    url = f"sim://tour?hold={hold}&odr=104&realtime=0&block=256&seed={seed}&errors=1"
    dev = open_device(url)
    capture = capture_for(dev, **kwargs)
    limit = 6 * (hold + 2.0) + 4.0
    while capture.state is not CaptureState.COMPLETE:
        block = convert_raw_block(dev.read(1.0))
        capture.update(block)
        assert block.t_s[-1] < limit, [e.reason for e in capture.events]
    return dev, capture


def true_accel_model(dev, temperature_degc: float) -> tuple[np.ndarray, np.ndarray]:
    """The unit's accelerometer ``(M, b)`` at a temperature, walk included."""
    unit = dev.unit_errors
    dt = temperature_degc - 25.0
    matrix = np.diag(1.0 + dt * unit.accel_scale_tc_per_degc) @ unit.accel_matrix
    bias = unit.accel_bias_m_s2 + dt * unit.accel_bias_tc_m_s2_per_degc
    walk = dev.measurement.accel_walk
    return matrix, bias + (0.0 if walk is None else walk.current)


def polar_factors(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``M = R K``: rotation ``R`` and symmetric positive definite ``K``."""
    u, s, vt = np.linalg.svd(matrix)
    return u @ vt, vt.T @ np.diag(s) @ vt


def static_mean(roll: float, pitch: float, yaw: float, seconds: float = 2.0, seed: int = 1):
    """Mean uncalibrated reading and true up direction of a still pose."""
    dev = open_device(
        f"sim://static?roll={roll}&pitch={pitch}&yaw={yaw}&odr=104&realtime=0"
        f"&block={int(seconds * 110)}&seed={seed}"
    )
    block = convert_raw_block(dev.read(1.0))
    up = up_in_sensor_frame(block.reference_quat).mean(axis=0)
    return block, block.accel_m_s2.mean(axis=0), up / np.linalg.norm(up)


@pytest.fixture(scope="module")
def tour_seed1():
    dev, capture = run_tour(1)
    return dev, capture, fit_six_position(capture.poses)


# -- six positions -----------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_six_position_recovers_bias_scale_and_misalignment(seed):
    dev, capture = run_tour(seed)
    assert [e.accepted for e in capture.events] == [True] * 6
    assert sorted(capture.captured_faces) == sorted(FACE_DIRECTIONS)
    fit = fit_six_position(capture.poses)
    true_m, true_b = true_accel_model(dev, fit.temperature_degc)
    # The targets of the issue: bias within 1 mg, scale within 0.05 %.
    bias_error_mg = np.abs(fit.bias_m_s2 - true_b) / MG
    scale_error = np.abs(np.diag(fit.matrix) - np.diag(true_m))
    assert np.all(bias_error_mg < 1.0)
    assert np.all(scale_error < 0.05e-2)
    # What is actually reached (exact faces, 3 s per pose): some hundredths of a mg, a few ppm.
    assert np.all(bias_error_mg < 0.1)
    assert np.all(scale_error < 0.01e-2)
    # Misalignment: with exact faces (the simulator's) it is limited by noise and drift only.
    cross_true = true_m / np.diag(true_m)[:, None] - np.eye(3)
    assert np.max(np.abs(fit.cross_axis - cross_true)) < 1e-4  # 0.006 degree
    # Uncertainties are of the right size: errors within a few reported sigmas.
    assert np.all(bias_error_mg < 6.0 * fit.bias_std_mg + 0.02)
    assert fit.residual_norm_rms_mg < 0.1 and fit.residual_component_rms_mg < 0.1


def test_six_position_calibration_reaches_005_degree_across_60_degrees(tour_seed1):
    _, _, fit = tour_seed1
    calibration = fit.to_calibration(name="six-position test")
    means, ups, angle_errors = [], [], []
    for roll, pitch, yaw in TILT_POSES:
        block, mean, up = static_mean(roll, pitch, yaw)
        means.append(mean)
        ups.append(up)
        # Through the pipeline's calibration stage, sample by sample.
        calibrated = calibration.apply(block)
        assert isinstance(calibrated, SampleBlock)
        got = angles_from_up(calibrated.accel_m_s2.mean(axis=0))
        want = angles_from_up(up)
        angle_errors += [got.roll_deg - want.roll_deg, got.pitch_deg - want.pitch_deg]
    comparison = compare_tilt(np.array(means), np.array(ups), calibration)
    assert comparison.after.max_deg <= 0.05
    assert np.max(np.abs(angle_errors)) <= 0.05
    assert np.max(np.abs(comparison.after.norm_error_mg)) < 0.5
    # Without calibration the same poses are off by tenths of a degree up to about a degree.
    assert comparison.before.max_deg > 0.3
    assert comparison.after.max_deg < comparison.before.max_deg / 10.0


def test_before_after_over_the_captured_faces(tour_seed1):
    _, capture, fit = tour_seed1
    comparison = compare_poses(capture.poses, fit.to_calibration(), reference="truth")
    assert comparison.labels == ("+z up", "-z up", "+x up", "-x up", "+y up", "-y up")
    assert comparison.before.max_deg > 0.5
    assert comparison.after.max_deg < 0.01
    rows = comparison.rows()
    assert rows[0]["pose"] == "+z up" and rows[0]["error_after_deg"] < 0.01


def test_symmetric_model_cannot_absorb_the_frame_rotation(tour_seed1):
    """Why the six-position default is the full matrix: the chip's rotation part."""
    dev, capture, full = tour_seed1
    symmetric = fit_six_position(capture.poses, model="symmetric")
    lower = fit_six_position(capture.poses, model="lower")
    rotation, _ = polar_factors(true_accel_model(dev, full.temperature_degc)[0])
    rotation_deg = math.degrees(math.acos((np.trace(rotation) - 1.0) / 2.0))
    assert rotation_deg > 0.2  # this unit is soldered 0.39 degree askew
    np.testing.assert_allclose(np.linalg.norm(full.frame_rotation_deg), rotation_deg, atol=0.01)
    for restricted in (symmetric, lower):
        # The model mismatch shows as a component residual of about g * (rotation angle).
        assert restricted.residual_component_rms_mg > 30 * full.residual_component_rms_mg
        means = np.array([p.accel_mean_m_s2 for p in capture.poses])
        ups = np.array([p.reference_up for p in capture.poses])
        tilt = compare_tilt(means, ups, restricted.to_calibration())
        assert tilt.after.max_deg > 0.1


def test_a_tilted_face_shifts_misalignment_by_half_its_tilt():
    """Pose placement: one face off by delta -> ~delta/2 misalignment, ~g delta/6 bias."""
    rng = np.random.default_rng(5)
    true_m = np.eye(3) + rng.uniform(-0.01, 0.01, (3, 3))
    true_b = rng.uniform(-0.2, 0.2, 3)
    faces = list(FACE_DIRECTIONS)
    nominal = np.array([FACE_DIRECTIONS[f] for f in faces])
    delta = math.radians(1.0)
    actual = nominal.copy()
    actual[faces.index("+z")] = [0.0, math.sin(delta), math.cos(delta)]  # +z face tilted 1 deg
    means = G * actual @ true_m.T + true_b
    exact = fit_known_orientations(G * nominal @ true_m.T + true_b, nominal)
    tilted = fit_known_orientations(means, nominal)
    np.testing.assert_allclose(exact.matrix, true_m, atol=1e-12)
    assert exact.residual_component_rms_mg < 1e-9
    m_error = tilted.matrix - true_m
    assert m_error[1, 2] == pytest.approx(true_m[1, 1] * delta / 2.0, rel=0.02)
    bias_error = tilted.bias_m_s2 - true_b
    assert bias_error[1] == pytest.approx(G * true_m[1, 1] * delta / 6.0, rel=0.02)
    assert abs(bias_error[1]) / MG == pytest.approx(2.9, abs=0.1)
    # Scale barely moves: by delta^2 / 4 and by the cross-axis term times delta / 2.
    expected = true_m[2, 1] * math.sin(delta) / 2.0 - true_m[2, 2] * (1.0 - math.cos(delta)) / 2.0
    assert m_error[2, 2] == pytest.approx(expected, rel=0.02)
    assert np.max(np.abs(np.diag(m_error))) < 2e-4
    # The component residual reveals the bad face: g delta / 3 on its pair.
    assert tilted.residual_component_rms_mg > 2.0
    y_residuals = np.abs(tilted.component_residuals_mg[:, 1])
    assert {faces[i] for i in np.flatnonzero(y_residuals > 5.0)} == {"+z", "-z"}  # g delta / 3


def test_six_position_needs_all_faces(tour_seed1):
    _, capture, _ = tour_seed1
    with pytest.raises(CalibrationFitError, match="six poses"):
        fit_six_position(capture.poses[:5])
    with pytest.raises(CalibrationFitError, match="faces missing"):
        fit_six_position([*capture.poses[:5], capture.poses[0]])


# -- free orientations (ellipsoid) -------------------------------------------------------------
def fibonacci_attitudes(n: int) -> list[tuple[float, float]]:
    """Roll and pitch of ``n`` up directions spread evenly over the sphere."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    r = np.sqrt(1.0 - z * z)
    angles = angles_from_up(np.column_stack([r * np.cos(phi), r * np.sin(phi), z]))
    return list(zip(angles.roll_deg.tolist(), angles.pitch_deg.tolist()))


@pytest.fixture(scope="module")
def free_poses_seed1():
    dev = open_device("sim://interactive?odr=104&realtime=0&block=104&seed=1&errors=1")
    capture = capture_for(dev, mode=FREE)
    for roll, pitch in fibonacci_attitudes(16):
        dev.set_target_attitude(roll, pitch)
        for _ in range(7):  # 1.5 s glide at most, then still
            capture.update(convert_raw_block(dev.read(1.0)))
    return dev, capture


def test_ellipsoid_fit_recovers_bias_scale_and_non_orthogonality(free_poses_seed1):
    dev, capture = free_poses_seed1
    assert len(capture.poses) == 16 and all(e.accepted for e in capture.events)
    assert capture.enough
    fit = fit_free_poses(capture.poses)
    assert fit.n_poses == 16 and fit.dof == 7
    true_m, true_b = true_accel_model(dev, fit.temperature_degc)
    _, true_k = polar_factors(true_m)
    bias_error_mg = np.abs(fit.bias_m_s2 - true_b) / MG
    assert np.all(bias_error_mg < 1.0)
    assert np.all(bias_error_mg < 0.1)
    assert np.all(np.abs(np.diag(fit.matrix) - np.diag(true_m)) < 0.05e-2)
    # The symmetric factor is what an ellipsoid can see; it matches to noise level.
    assert np.max(np.abs(fit.matrix - true_k)) < 2e-4
    for pair, angle in fit.non_orthogonality_deg.items():
        rows = true_m / np.linalg.norm(true_m, axis=1, keepdims=True)
        j, k = "xyz".index(pair[0]), "xyz".index(pair[1])
        true_angle = 90.0 - math.degrees(math.acos(rows[j] @ rows[k]))
        assert angle == pytest.approx(true_angle, abs=0.01)
    np.testing.assert_allclose(fit.frame_rotation_deg, 0.0, atol=1e-9)
    assert fit.residual_norm_rms_mg < 0.1
    assert np.all(bias_error_mg < 6.0 * fit.bias_std_mg + 0.02)


def test_ellipsoid_leaves_the_frame_rotation_as_a_tilt_error(free_poses_seed1):
    """Only 9 of 12 parameters are observable: the chip's rotation remains, as predicted."""
    dev, capture = free_poses_seed1
    fit = fit_free_poses(capture.poses)
    true_m, _ = true_accel_model(dev, fit.temperature_degc)
    rotation, true_k = polar_factors(true_m)
    comparison = compare_poses(capture.poses, fit.to_calibration(), reference="truth")
    # calibrated = K^-1 R K a_true: the up direction turned by (nearly) the chip's rotation.
    turned = np.array([np.linalg.solve(true_k, rotation @ true_k @ p.reference_up)
                       for p in capture.poses])
    ups = np.array([p.reference_up for p in capture.poses])
    predicted = np.degrees(np.arctan2(np.linalg.norm(np.cross(turned, ups), axis=1),
                                      np.sum(turned * ups, axis=1)))
    np.testing.assert_allclose(comparison.after.inclination_deg, predicted, atol=0.01)
    assert comparison.after.max_deg > 0.2  # not a tilt meter of 0.05 degree without a box
    assert comparison.after.max_deg < comparison.before.max_deg


def test_ellipsoid_needs_twelve_spread_poses(free_poses_seed1):
    _, capture = free_poses_seed1
    with pytest.raises(CalibrationFitError, match="at least 12"):
        fit_free_poses(capture.poses[:11])
    # Twelve poses all around one axis (a cone) do not determine the ellipsoid.
    angles = np.radians(np.arange(12) * 30.0)
    cone = G * np.column_stack([0.5 * np.cos(angles), 0.5 * np.sin(angles), np.full(12, 0.866)])
    with pytest.raises(CalibrationFitError, match="spread"):
        fit_ellipsoid(cone)


def test_fit_result_converts_to_a_pipeline_calibration(tour_seed1):
    _, _, fit = tour_seed1
    assert isinstance(fit, AccelFit)
    gyro_bias = np.array([0.001, -0.002, 0.003])
    cal = fit.to_calibration(gyro_bias, name="unit test")
    np.testing.assert_allclose(cal.accel_matrix @ fit.matrix, np.eye(3), atol=1e-12)
    np.testing.assert_array_equal(cal.accel_bias_m_s2, fit.bias_m_s2)
    np.testing.assert_array_equal(cal.gyro_bias_rad_s, gyro_bias)
    assert cal.name == "unit test" and not cal.is_identity
    summary = fit.summary()
    assert summary["method"] == "six-position" and len(summary["bias_mg"]) == 3


# -- capture: rejections -----------------------------------------------------------------------
def test_a_pose_moved_during_capture_is_rejected_with_a_reason():
    # Held 2 s only: the capture (0.5 s window + 0.5 s settling + 3 s) cannot finish.
    dev = open_device("sim://tour?hold=2&odr=104&realtime=0&block=128&seed=1")
    capture = capture_for(dev)
    while dev_time(capture) < 9.0:
        capture.update(convert_raw_block(dev.read(1.0)))
    assert capture.poses == []
    assert len(capture.events) >= 2
    first = capture.events[0]
    assert not first.accepted
    assert first.reason.startswith("Moved during capture (after 1.")
    assert "of 3 s" in first.reason
    assert 2.0 <= first.time_s < 2.2  # the tour's first turn starts at 2 s


def dev_time(capture: PoseCapture) -> float:
    return capture.detector.last_time_s or 0.0


def test_slow_drift_during_capture_is_rejected():
    # 0.05 dps: too slow for the stillness window, caught by the half-capture comparison.
    dev = open_device(
        "sim://slow-tilt?amplitude=30&roll_period=3600&pitch_period=3600"
        "&odr=104&realtime=0&block=128&seed=1"
    )
    capture = capture_for(dev, mode=FREE)
    while not capture.events:
        capture.update(convert_raw_block(dev.read(1.0)))
    event = capture.events[0]
    assert not event.accepted
    assert event.reason.startswith("Moved slowly during capture")
    assert event.pose is not None  # the rejected averages are kept for display


def test_repeated_and_off_face_orientations_are_rejected():
    dev = open_device("sim://interactive?roll=0&pitch=0&odr=104&realtime=0&block=104&seed=1")
    capture = capture_for(dev)

    def hold(roll: float, pitch: float, seconds: int = 7) -> None:
        dev.set_target_attitude(roll, pitch)
        for _ in range(seconds):
            capture.update(convert_raw_block(dev.read(1.0)))

    hold(0.0, 0.0)
    hold(180.0, 0.0)
    hold(8.0, 5.0)  # back on +z, a little askew
    hold(45.0, 0.0)  # between two faces
    reasons = [e.reason for e in capture.events]
    assert [e.accepted for e in capture.events] == [True, True, False, False], reasons
    assert reasons[2].startswith("Orientation already captured")
    assert "from pose 1 (+z up)" in reasons[2]
    assert re.match(r"Not on a face: 4\d\.\d deg from the nearest one", reasons[3])
    assert capture.captured_faces == ["+z", "-z"]
    assert capture.missing_faces == ["+x", "-x", "+y", "-y"]
    # Lying still after a rejection does not retry by itself; the button does.
    hold(45.0, 0.0)
    assert len(capture.events) == 4
    capture.request_capture()
    hold(45.0, 0.0)
    assert len(capture.events) == 5 and not capture.events[4].accepted


def test_a_reading_that_is_not_one_g_is_rejected():
    noise = SensorNoise.lsm6dsox(104.0)
    capture = PoseCapture(StillnessDetector(noise), mode=FREE)
    n = 600
    rng = np.random.default_rng(0)
    block = SampleBlock(
        t_s=np.arange(n) / 104.0,
        accel_m_s2=np.array([0.0, 0.0, 1.3 * G]) + rng.normal(0.0, noise.accel_rms_m_s2, (n, 3)),
        gyro_rad_s=rng.normal(0.0, noise.gyro_rms_rad_s, (n, 3)),
        temp_degc=np.full(n, 25.0),
        gap=np.zeros(n, dtype=bool),
    )
    events = capture.update(block)
    assert len(events) == 1 and not events[0].accepted
    assert events[0].reason.startswith("The reading is 1.300 g, not 1 g")
