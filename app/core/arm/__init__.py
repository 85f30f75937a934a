"""The measuring arm (JAMRIS): its layout, its kinematics and the repeatability of its tip."""

from app.core.arm.kinematics import (
    ArmPose,
    cylindrical,
    forward,
    joint_angles_from_gravity,
    pose_from_link_quaternions,
    rotation_matrix,
    up_in_link_frame,
)
from app.core.arm.layout import ArmLayout, ArmLayoutError, Link, jamris_layout
from app.core.arm.repeatability import COORDINATES, CoordinateStats, Placements

__all__ = [
    "COORDINATES",
    "ArmLayout",
    "ArmLayoutError",
    "ArmPose",
    "CoordinateStats",
    "Link",
    "Placements",
    "cylindrical",
    "forward",
    "jamris_layout",
    "joint_angles_from_gravity",
    "pose_from_link_quaternions",
    "rotation_matrix",
    "up_in_link_frame",
]
