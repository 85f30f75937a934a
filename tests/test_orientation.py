"""Orientation conventions on known poses, including near 90 degrees and upside down."""

from __future__ import annotations

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.orientation import (
    angles_from_quaternion,
    angles_from_up,
    inclination_error_deg,
    quaternion_from_roll_pitch,
    quaternion_from_up,
    up_in_sensor_frame,
)
from app.core.readout import slope_from_angle

G = 9.80665


def test_level_sensor_reads_zero_angles():
    angles = angles_from_up(np.array([0.0, 0.0, G]))
    assert angles.roll_deg == pytest.approx(0.0)
    assert angles.pitch_deg == pytest.approx(0.0)
    assert angles.tilt_deg == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("up", "roll", "pitch", "tilt", "direction"),
    [
        # +x side raised by 30 degrees: gravity's up direction leans towards +x.
        ((np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))), 0.0, 30.0, 30.0, 0.0),
        # +y side raised by 20 degrees.
        ((0.0, np.sin(np.radians(20)), np.cos(np.radians(20))), 20.0, 0.0, 20.0, 90.0),
        # -y side raised.
        ((0.0, -np.sin(np.radians(10)), np.cos(np.radians(10))), -10.0, 0.0, 10.0, 270.0),
        # Upside down: roll is 180, tilt is 180.
        ((0.0, 0.0, -1.0), 180.0, 0.0, 180.0, 0.0),
        # Standing on the -x edge, +x straight up: pitch +90.
        ((1.0, 0.0, 0.0), 0.0, 90.0, 90.0, 0.0),
    ],
)
def test_known_poses(up, roll, pitch, tilt, direction):
    angles = angles_from_up(np.array(up) * G)
    assert angles.roll_deg == pytest.approx(roll, abs=1e-9)
    assert angles.pitch_deg == pytest.approx(pitch, abs=1e-9)
    assert angles.tilt_deg == pytest.approx(tilt, abs=1e-9)
    assert angles.direction_deg == pytest.approx(direction, abs=1e-9)


def test_roll_pitch_quaternion_round_trip_over_the_sphere():
    rng = np.random.default_rng(3)
    roll = rng.uniform(-179.0, 179.0, 2000)
    pitch = rng.uniform(-89.0, 89.0, 2000)
    yaw = rng.uniform(-180.0, 180.0, 2000)
    q = quaternion_from_roll_pitch(roll, pitch, yaw)
    angles = angles_from_quaternion(q)
    np.testing.assert_allclose(angles.roll_deg, roll, atol=1e-9)
    np.testing.assert_allclose(angles.pitch_deg, pitch, atol=1e-9)


def test_up_vector_matches_rotating_earth_z_into_the_sensor_frame():
    q = quaternion_from_roll_pitch(25.0, -40.0, 70.0)
    direct = quat.rotate_inverse(q, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(up_in_sensor_frame(q), direct, atol=1e-12)
    # and u = (sin pitch, sin roll cos pitch, cos roll cos pitch)
    r, p = np.radians(25.0), np.radians(-40.0)
    np.testing.assert_allclose(
        direct, [np.sin(p), np.sin(r) * np.cos(p), np.cos(r) * np.cos(p)], atol=1e-12
    )


def test_near_ninety_degrees_pitch_tilt_stays_exact_while_roll_is_ill_conditioned():
    up = np.array([1.0, 1e-9, -1e-9])
    angles = angles_from_up(up)
    assert angles.pitch_deg == pytest.approx(90.0, abs=1e-6)
    assert angles.tilt_deg == pytest.approx(90.0, abs=1e-6)
    # Tiny noise swings roll by large amounts there; tilt and direction do not care.
    other = angles_from_up(np.array([1.0, 1e-9, 1e-9]))
    assert abs(other.roll_deg - angles.roll_deg) > 45.0
    assert other.tilt_deg == pytest.approx(angles.tilt_deg, abs=1e-6)
    assert other.direction_deg == pytest.approx(angles.direction_deg, abs=1e-3)


def test_quaternion_from_up_reproduces_the_up_vector():
    rng = np.random.default_rng(5)
    up = rng.normal(size=(500, 3))
    q = quaternion_from_up(up)
    np.testing.assert_allclose(
        up_in_sensor_frame(q), up / np.linalg.norm(up, axis=1, keepdims=True), atol=1e-12
    )


def test_inclination_error_ignores_yaw_and_measures_tilt_difference():
    a = quaternion_from_roll_pitch(10.0, 0.0, 0.0)
    b = quaternion_from_roll_pitch(10.0, 0.0, 123.0)
    assert inclination_error_deg(a, b) == pytest.approx(0.0, abs=1e-9)
    c = quaternion_from_roll_pitch(12.5, 0.0, 0.0)
    assert inclination_error_deg(a, c) == pytest.approx(2.5, abs=1e-9)


def test_slope_units():
    assert slope_from_angle(45.0, "percent") == pytest.approx(100.0)
    assert slope_from_angle(np.degrees(np.arctan(0.001)), "mm/m") == pytest.approx(1.0)
    assert slope_from_angle(3.0, "deg") == 3.0
    with pytest.raises(ValueError, match="unknown slope unit"):
        slope_from_angle(1.0, "furlongs")


def test_quaternion_helpers_agree():
    rng = np.random.default_rng(9)
    rotvec = rng.normal(size=(100, 3))
    q = quat.from_rotation_vector(rotvec)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    back = quat.to_rotation_vector(q)
    # Same rotation (angles above pi wrap to the other side of the axis).
    np.testing.assert_allclose(
        quat.angle_between(quat.from_rotation_vector(back), q), 0.0, atol=1e-6
    )
    half = quat.slerp(quat.IDENTITY, q, 0.5)
    np.testing.assert_allclose(
        quat.angle_between(quat.multiply(half, half), q), 0.0, atol=1e-6
    )
