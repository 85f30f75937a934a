"""The measuring arm: forward kinematics, joint angles from gravity, layouts and repeatability."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.arm import (
    ArmLayout,
    ArmLayoutError,
    Link,
    Placements,
    forward,
    jamris_layout,
    joint_angles_from_gravity,
    pose_from_link_quaternions,
    up_in_link_frame,
)
from app.core.orientation import quaternion_from_roll_pitch


def planar_two_link(l1: float = 300.0, l2: float = 200.0) -> ArmLayout:
    return ArmLayout((Link("a", l1), Link("b", l2)))


def test_planar_two_link_at_known_angles_gives_known_r_and_z():
    pose = forward(planar_two_link(), [30.0, -60.0])  # second link 30 degrees below horizontal
    r = 300 * np.cos(np.radians(30)) + 200 * np.cos(np.radians(-30))
    z = 300 * np.sin(np.radians(30)) + 200 * np.sin(np.radians(-30))
    assert pose.radius == pytest.approx(r, abs=1e-9)
    assert pose.height == pytest.approx(z, abs=1e-9)
    assert pose.end == pytest.approx([r, 0.0, z], abs=1e-9)
    assert pose.points[1] == pytest.approx([300 * np.cos(np.radians(30)), 0, 150], abs=1e-9)


def test_jamris_arm_turns_its_plane_with_the_column():
    layout = jamris_layout(column=100.0, upper=300.0, fore=250.0)
    pose = forward(layout, [90.0, 90.0, -90.0])  # column turned to +y, upper arm up, fore level
    assert pose.end == pytest.approx([0.0, 250.0, 400.0], abs=1e-9)
    c = pose.coordinates()
    assert (c["R"], c["Z"], c["azimuth_deg"]) == pytest.approx((250.0, 400.0, 90.0))


def test_lengths_offsets_and_base_position_move_the_end_point():
    layout = ArmLayout((Link("a", 100.0, offset_deg=90.0),), base_position=(1.0, 2.0, 3.0))
    pose = forward(layout, [0.0])
    assert pose.end == pytest.approx([1.0, 2.0, 103.0])
    assert pose.radius == pytest.approx(0.0, abs=1e-9) and pose.height == pytest.approx(100.0)
    assert forward(layout.with_lengths([50.0]), [-90.0]).end == pytest.approx([51.0, 2.0, 3.0])


def test_joint_angles_come_back_from_the_links_up_vectors():
    layout = jamris_layout()
    truth = np.array([40.0, 25.0, -70.0])
    pose = forward(layout, truth)
    ups = [rotation.T @ [0.0, 0.0, 1.0] for rotation in pose.rotations]
    angles, observed = joint_angles_from_gravity(layout, ups, known_deg=[40.0, None, None])
    # The column's axis is vertical: gravity cannot see it, its angle is the one given.
    assert observed.tolist() == [False, True, True]
    assert angles == pytest.approx(truth, abs=1e-9)


def test_joint_angle_beyond_vertical_keeps_its_sign_and_size():
    layout = planar_two_link()
    for truth in ([120.0, -150.0], [-30.0, 170.0], [95.0, 10.0]):
        pose = forward(layout, truth)
        ups = [rotation.T @ [0.0, 0.0, 1.0] for rotation in pose.rotations]
        angles, observed = joint_angles_from_gravity(layout, ups)
        assert observed.all()
        assert angles == pytest.approx(truth, abs=1e-9)


def test_pose_from_sensor_quaternions_ignores_each_sensors_heading():
    # Sensors with x along the link: link elevations of 20 and -10 degrees are their pitches.
    # Without a magnetometer each sensor's heading is arbitrary; gravity alone fixes the joints.
    layout = planar_two_link()
    q1 = quaternion_from_roll_pitch(0.0, 20.0, 33.0)
    q2 = quaternion_from_roll_pitch(0.0, -10.0, -80.0)
    pose, observed = pose_from_link_quaternions(layout, [q1, q2])
    assert observed.all()
    assert pose.joint_angles_deg == pytest.approx([20.0, -30.0], abs=1e-9)
    assert pose.end == pytest.approx(forward(layout, [20.0, -30.0]).end, abs=1e-9)


def test_a_mounting_rotation_turns_the_sensor_into_the_link_frame():
    # The sensor is mounted with its y axis along the link: mount rotates sensor to link frame.
    mount = quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), -np.pi / 2)
    link_q = quaternion_from_roll_pitch(0.0, 25.0)  # the link, pitched up 25 degrees
    sensor_q = quat.multiply(link_q, mount)  # sensor-to-earth = link-to-earth * sensor-to-link
    up = up_in_link_frame(sensor_q, mount)
    assert up == pytest.approx([np.sin(np.radians(25)), 0.0, np.cos(np.radians(25))], abs=1e-9)


def test_layout_round_trips_through_json_and_rejects_bad_input():
    layout = jamris_layout(120.0, 310.5, 280.0)
    again = ArmLayout.from_json(layout.to_json())
    assert again == layout
    assert forward(again, [10, 20, 30]).end == pytest.approx(forward(layout, [10, 20, 30]).end)
    data = json.loads(layout.to_json())
    data["links"][1]["length"] = -1
    with pytest.raises(ArmLayoutError, match="length must be >= 0"):
        ArmLayout.from_dict(data)
    data["links"][1]["length"] = 1
    data["links"][1]["axis"] = [0, 0, 0]
    with pytest.raises(ArmLayoutError, match="non-zero"):
        ArmLayout.from_dict(data)
    with pytest.raises(ArmLayoutError, match=r"not (valid )?JSON"):
        ArmLayout.from_json("{")
    with pytest.raises(ArmLayoutError, match="4 lengths for 3 links"):
        layout.with_lengths([1, 2, 3, 4])
    with pytest.raises(ArmLayoutError, match="2 joint angles for 3"):
        forward(layout, [1, 2])


def test_repeatability_statistics_of_placements_with_known_spread():
    placements = Placements()
    rng = np.random.default_rng(3)
    tips = np.array([[100.0, 0.0, 50.0], [100.4, 0.0, 49.5], [99.6, 0.0, 50.5], [100.0, 0.0, 50.0]])
    for tip in tips:
        noise = rng.normal(0.0, 0.01, (50, 3))
        noise -= noise.mean(axis=0)  # each window averages to the placement exactly
        placements.capture(tip + noise)
    stats = placements.statistics()
    assert stats["x"].n == 4
    assert stats["x"].mean == pytest.approx(100.0)
    assert stats["x"].sd == pytest.approx(np.std(tips[:, 0], ddof=1))
    assert (stats["Z"].min, stats["Z"].max) == pytest.approx((49.5, 50.5))
    assert stats["R"].range == pytest.approx(0.8)
    text = placements.to_csv()
    lines = [line for line in text.splitlines() if not line.startswith("#")]
    assert lines[0].split(",") == ["placement", "samples", "x", "y", "z", "R", "Z", "azimuth_deg",
                                   "theta_from", "column_azimuth_deg"]
    assert lines[1].split(",")[1] == "50"
    sd_row = next(line for line in lines if line.startswith("sd,"))
    assert float(sd_row.split(",")[2]) == pytest.approx(stats["x"].sd)
    placements.remove_last()
    assert len(placements) == 3
    with pytest.raises(ValueError, match="no valid end point"):
        placements.capture(np.full((3, 3), np.nan))
    assert len(placements) == 3


def test_a_joint_angle_measured_otherwise_wins_over_gravity():
    layout = jamris_layout()
    ups = [None, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])]  # both links level
    angles, observed = joint_angles_from_gravity(layout, ups, measured_deg=[None, None, 30.0])
    assert observed.tolist() == [False, True, True]
    assert angles[1] == pytest.approx(0.0, abs=1e-9) and angles[2] == pytest.approx(30.0)
    angles, _ = joint_angles_from_gravity(layout, ups, measured_deg=[None, None, float("nan")])
    assert angles[2] == pytest.approx(0.0, abs=1e-9)  # NaN: not measured, gravity decides
    with pytest.raises(ArmLayoutError):
        joint_angles_from_gravity(layout, ups, measured_deg=[1.0])
