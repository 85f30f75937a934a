"""The measuring arm's third coordinate (#32): the column's angle theta from each link's
gravity and magnetic field, per static capture; R, theta, Z and their repeatability, end to
end on sim://arm?column=1 with magnetometers."""

from __future__ import annotations

import datetime as dt
import json
import math

import numpy as np
import pytest

from app import cli
from app.core import quaternion as quat
from app.core.arm import (
    COLUMN_AZIMUTH,
    ArmLayout,
    Link,
    Placements,
    ThetaZero,
    capture_link,
    forward,
    jamris_layout,
    measure_theta,
    placement_pose,
)
from app.core.arm.layout import ALONG_X, PITCH_UP
from app.core.earth_field import earth_field
from app.core.field_check import wmm_reference
from app.core.recording.reader import read_recording
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.services.arm_recordings import THETA_REFERENCE_COLUMN, record_arm_placements
from drivers.sim.scenarios import Arm

DATE = "2026-06-01"
FIELD = earth_field(when=dt.date(2026, 6, 1)).enu_magnetic_ut()
REFERENCE = wmm_reference(when=dt.date(2026, 6, 1))
THETA_TOLERANCE_DEG = 1.0
"""Measured against the truth: the units' accelerometer bias (2 mg after calibration) tilts
the TRIAD frame by about 0.1 degrees, which the steep field (dip 68 degrees at the default
place) turns into up to 0.3 degrees of heading; 1 degree leaves room."""
LENGTH_TOLERANCE_MM = 1.0


# -- the core, on exact synthetic captures ------------------------------------------------------
def _link_frames(layout: ArmLayout, angles_deg, base_yaw_deg: float) -> list[np.ndarray]:
    """Each link's frame (link -> ENU) for the base's x axis at ``base_yaw_deg`` from east."""
    yaw = np.radians(base_yaw_deg)
    base = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0],
                     [0.0, 0.0, 1.0]])
    return [base @ r for r in forward(layout, angles_deg).rotations]


def _captures(layout, angles_deg, base_yaw_deg, field=FIELD, n=100, wobble=0.0, seed=0):
    rng = np.random.default_rng(seed)
    captures = [None]
    for link, frame in enumerate(_link_frames(layout, angles_deg, base_yaw_deg)[1:], start=1):
        up = frame.T @ np.array([0.0, 0.0, 1.0]) * STANDARD_GRAVITY_M_S2
        accel = up + wobble * rng.normal(size=(n, 3))
        mag = np.tile(frame.T @ field, (n, 1))
        mag[1::2] = np.nan  # the magnetometer runs slower: NaN rows between its samples
        captures.append(capture_link(link, accel, mag, REFERENCE))
    return captures


def test_theta_and_azimuth_from_exact_captures():
    layout = jamris_layout()
    for theta, shoulder, elbow, yaw in ((30.0, 20.0, -60.0, 10.0), (-150.0, 60.0, -100.0, 170.0),
                                        (179.0, 10.0, -20.0, -80.0)):
        captures = _captures(layout, [theta, shoulder, elbow], yaw)
        zero = ThetaZero(yaw)  # the base's x axis
        measured = measure_theta(layout, captures, zero)
        assert measured.ok, measured.refused
        assert measured.theta_deg == pytest.approx(theta, abs=1e-6)
        assert measured.azimuth_deg == pytest.approx((90.0 - yaw - theta) % 360.0, abs=1e-6)
        assert measured.spread_deg < 1e-6
        # Without a zero the base's x is magnetic north: theta = -azimuth.
        north = measure_theta(layout, captures)
        assert north.theta_deg == pytest.approx(((-measured.azimuth_deg) + 180) % 360 - 180,
                                                abs=1e-6)
        placed = placement_pose(layout, captures, zero)
        assert placed.theta_source == "measured"
        np.testing.assert_allclose(placed.pose.joint_angles_deg, [theta, shoulder, elbow],
                                   atol=1e-6)


def test_a_folded_forearm_agrees_with_the_upper_arm():
    """The forearm pointing back over the column (its horizontal direction turned by 180
    degrees) gives the same column angle: each link's whole frame is compared, not its
    direction."""
    layout = jamris_layout()
    captures = _captures(layout, [40.0, 70.0, -150.0], 25.0)
    measured = measure_theta(layout, captures, ThetaZero(25.0))
    assert measured.theta_deg == pytest.approx(40.0, abs=1e-6)
    assert all(math.isfinite(p) for p in measured.link_psi_deg[1:])


def test_a_disturbed_or_moving_capture_is_refused_with_the_reason():
    layout = jamris_layout()
    angles = [30.0, 20.0, -60.0]
    magnet = FIELD + np.array([30.0, 0.0, 0.0])  # a steady extra field: strength and dip off
    captures = _captures(layout, angles, 10.0, field=magnet)
    placed = placement_pose(layout, captures)
    assert placed.pose is None and "field disturbed" in placed.refused
    assert "upper arm" not in placed.refused and "link 1" in placed.refused
    moving = _captures(layout, angles, 10.0, wobble=0.5)
    placed = placement_pose(layout, moving)
    assert placed.pose is None and "not steady" in placed.refused
    # One link in a field the other does not see (a magnet beside the forearm) and no
    # reference to catch it: the links' headings disagree.
    captures = _captures(layout, angles, 10.0)
    frame = _link_frames(layout, angles, 10.0)[2]
    turned = quat.rotate(quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), math.radians(10.0)),
                         FIELD)
    accel = np.tile(frame.T @ np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2]), (20, 1))
    captures[2] = capture_link(2, accel, np.tile(frame.T @ turned, (20, 1)), None)
    measured = measure_theta(layout, captures)
    assert not measured.ok and "differ by 10.0°" in measured.refused


def test_theta_stays_typed_without_a_magnetometer_and_needs_a_column():
    layout = jamris_layout()
    frames = _link_frames(layout, [30.0, 20.0, -60.0], 10.0)
    captures = [None] + [capture_link(k, np.tile(f.T @ [0, 0, STANDARD_GRAVITY_M_S2], (20, 1)),
                                      None, REFERENCE) for k, f in enumerate(frames[1:], 1)]
    placed = placement_pose(layout, captures, known_deg=[12.5, None, None])
    assert placed.theta is None and placed.theta_source == "typed"
    np.testing.assert_allclose(placed.pose.joint_angles_deg, [12.5, 20.0, -60.0], atol=1e-6)
    no_column = ArmLayout((Link("upper", 300.0, PITCH_UP, ALONG_X),))
    measured = measure_theta(no_column, [_captures(layout, [0, 20, -60], 0)[1]])
    assert not measured.ok and "no column" in measured.refused


def test_theta_statistics_are_circular():
    placements = Placements()
    for angle in (179.0, -179.0, 178.0):
        rad = math.radians(angle)
        placements.capture(np.array([[100 * math.cos(rad), 100 * math.sin(rad), 0.0]]),
                           "measured", (90.0 - angle) % 360.0)
    stats = placements.statistics()
    assert stats["azimuth_deg"].mean == pytest.approx(179.333, abs=1e-3)
    assert stats["azimuth_deg"].range == pytest.approx(3.0)
    assert stats["azimuth_deg"].sd == pytest.approx(np.std([179, 181, 178], ddof=1))
    assert stats[COLUMN_AZIMUTH].range == pytest.approx(3.0)
    assert placements.theta_sources == ("measured",) * 3
    lines = placements.to_csv().splitlines()
    assert lines[2].split(",")[-2:][0] == "measured"
    with pytest.raises(ValueError, match="theta_source"):
        placements.capture(np.zeros((1, 3)), "guessed")


# -- the simulator ------------------------------------------------------------------------------
def test_column_arm_is_still_while_held_and_its_rates_are_the_derivative():
    scenario = Arm(np.random.default_rng(5), column=True, sensor=1, hold=1.0, transition=1.0)
    t = np.linspace(0.0, 6.0, 601)
    motion = scenario.motion(t)
    np.testing.assert_allclose(scenario.numerical_angular_rate(t), motion.angular_rate_rad_s,
                               atol=1e-4)
    held = np.zeros(len(t), dtype=bool)
    for start, end in scenario.placement_windows(3):
        held |= (t > start + 0.01) & (t < end - 0.01)
    assert np.all(motion.angular_rate_rad_s[held] == 0.0)
    assert np.all(motion.linear_accel_m_s2[held] == 0.0)
    assert np.max(np.abs(motion.angular_rate_rad_s[~held])) > 0.1
    # The sensor's x runs along its link: its heading is the base's turned by theta.
    x = quat.rotate(motion.orientation_quat, np.array([1.0, 0.0, 0.0]))
    heading = np.degrees(np.arctan2(x[:, 1], x[:, 0]))
    theta = scenario.column_angles_deg(t)[:, 0]
    np.testing.assert_allclose((heading - scenario.base_yaw_deg - theta + 180) % 360 - 180, 0,
                               atol=1e-9)


URL = f"sim://arm?column=1&mag=lis3mdl&date={DATE}&hold=1.2&transition=0.8"


def test_measured_theta_r_and_z_match_the_truth_over_placements(tmp_path):
    written, measured = record_arm_placements(f"{URL}&seed=3&spots=6", 1.0, tmp_path,
                                              placements=6)
    assert [row.refused for row in measured.rows] == [""] * 6
    thetas = [row.truth["azimuth_deg"] for row in measured.rows]
    assert np.ptp(thetas) > 60.0  # the placements point in different directions
    for row in measured.rows:
        for name, tolerance in (("R", LENGTH_TOLERANCE_MM), ("Z", LENGTH_TOLERANCE_MM),
                                ("azimuth_deg", THETA_TOLERANCE_DEG),
                                (COLUMN_AZIMUTH, THETA_TOLERANCE_DEG)):
            error = row.measured[name] - row.truth[name]
            if name in ("azimuth_deg", COLUMN_AZIMUTH):
                error = (error + 180.0) % 360.0 - 180.0
            assert abs(error) < tolerance, (row.index, name, row.measured, row.truth)
    assert measured.zero.source == "placement 1"
    assert measured.rows[0].measured["theta_deg"] == pytest.approx(0.0, abs=1e-9)
    # The files carry the field and the truth of theta.
    recording = read_recording(written[0].path)
    assert recording.has_magnetometer
    theta_ref = recording.unknown_columns[THETA_REFERENCE_COLUMN]
    assert np.ptp(theta_ref) > 60.0
    column = recording.metadata["arm"]["column"]
    assert 0.0 <= column["base_azimuth_deg"] < 360.0


def test_a_disturbed_capture_is_refused_and_the_rest_measured(tmp_path):
    # Placement 3 is held over 4.0-5.2 s (device clock within a few ppm): a magnet passes.
    url = f"{URL}&seed=4&spots=1&magdist=magnet@3.8-5.4"
    _written, measured = record_arm_placements(url, 1.0, tmp_path, placements=5)
    refused = [row.index for row in measured.rows if row.refused]
    assert refused == [2]
    assert "field disturbed" in measured.rows[2].refused
    assert measured.rows[2].measured is None
    assert len(measured.placements) == 4


def test_repeatability_over_one_spot(tmp_path):
    url = f"{URL}&seed=7&spots=1&scatter=0.5"
    _written, measured = record_arm_placements(url, 1.0, tmp_path, placements=8)
    stats = measured.placements.statistics()
    rows = [row for row in measured.rows if row.measured is not None]
    assert len(rows) == 8
    for name in ("R", "azimuth_deg", "Z"):
        values = np.array([row.measured[name] for row in rows])
        truth = np.array([row.truth[name] for row in rows])
        assert stats[name].n == 8
        mean = (np.degrees(np.angle(np.exp(1j * np.radians(values)).mean()))
                if name == "azimuth_deg" else values.mean())  # theta's mean is circular
        assert stats[name].mean == pytest.approx(mean, abs=1e-9)
        assert stats[name].sd == pytest.approx(values.std(ddof=1), rel=1e-9)
        assert stats[name].range == pytest.approx(np.ptp(values), rel=1e-9)
        # The spread is the placements' (scatter 0.5 degrees per joint), seen truly.
        assert stats[name].sd == pytest.approx(truth.std(ddof=1),
                                               abs=0.3 if name == "azimuth_deg" else 0.5)
    assert 0.1 < stats["azimuth_deg"].sd < 2.0


def test_record_arm_prints_and_writes_the_placements(tmp_path, capsys):
    out = tmp_path / "placements.json"
    url = f"{URL}&seed=4&spots=1&magdist=magnet@3.8-5.4"
    assert cli.main(["record-arm", url, str(tmp_path / "run"), "--duration", "1",
                     "--placements", "4", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "  3 refused: upper arm" in text
    assert "repeatability over 3 accepted placements of 4" in text
    document = json.loads(out.read_text())
    assert [row["refused"] is None for row in document["rows"]] == [True, True, False, True]
    stats = document["repeatability"]["statistics"]
    assert stats["R"]["n"] == 3 and stats["azimuth_deg"]["sd"] is not None
    assert document["repeatability"]["placements"][0]["theta_from"] == "measured"


@pytest.mark.parametrize(("url", "message"), [
    ("sim://arm?mag=lis3mdl", "column=1"),
    ("sim://arm?column=1", "mag=lis3mdl"),
])
def test_record_arm_placements_need_a_column_arm_with_magnetometers(tmp_path, capsys, url,
                                                                    message):
    assert cli.main(["record-arm", url, str(tmp_path), "--duration", "1",
                     "--placements", "2"]) == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_placement_options_need_a_column_arm():
    from drivers.errors import DeviceUrlError
    from drivers.sim.device import SimulatedDevice
    with pytest.raises(DeviceUrlError, match="hold place a column arm: add column=1"):
        SimulatedDevice("sim://arm?hold=2")


def test_the_pipelines_rings_give_a_capture_as_the_window_reads_them():
    """What the window hands the Arm panel: each sensor's pipeline's newest accelerometer
    and calibrated field (app.services.group_attitudes.sensor_windows)."""
    from app.core.calibration import MagnetometerCalibration, SensorCalibration
    from app.core.pipeline import Pipeline
    from app.services.group_attitudes import sensor_windows
    from drivers.sim.device import SimulatedDevice

    device = SimulatedDevice(f"{URL}&seed=3&realtime=0&block=8")
    pipeline = Pipeline(device.odr_hz)
    pipeline.set_calibration(SensorCalibration(
        name="magnetometer", magnetometer=MagnetometerCalibration.from_json(
            device.unit_errors.magnetometer.calibration_json())))
    device.open()
    hold_end = device.scenario.placement_windows(1)[0][1]
    while pipeline.samples.total_written < (hold_end - 0.1) * device.odr_hz:
        raw = device.read(1.0)
        if raw is not None:
            pipeline.process(raw)
    device.close()
    (window,) = sensor_windows([pipeline], [1], 1.0)
    assert window.link == 1 and window.mag_ut is not None
    assert 90 <= len(window.accel_m_s2) <= 115 and 70 <= len(window.mag_ut) <= 90  # 104/80 Hz
    capture = capture_link(1, window.accel_m_s2, window.mag_ut, REFERENCE)
    assert capture.refused == "" and capture.steady
    assert capture.norm_ut == pytest.approx(REFERENCE.total_ut, abs=1.0)
    assert capture.dip_deg == pytest.approx(REFERENCE.dip_deg, abs=1.0)
    # The same samples before the magnetometer's calibration (this unit's hard iron is tens
    # of uT): refused, never turned into an azimuth.
    raw = pipeline.field.window(1.0, ["raw_mag"])["raw_mag"]
    uncalibrated = capture_link(1, window.accel_m_s2, raw, REFERENCE)
    assert "field disturbed" in uncalibrated.refused and not uncalibrated.has_azimuth
