"""The measuring arm (JAMRIS): its layout, its kinematics and the repeatability of its tip."""

from app.core.arm.azimuth import (
    LinkCapture,
    PlacementPose,
    ThetaMeasurement,
    ThetaZero,
    capture_link,
    measure_theta,
    placement_pose,
)
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
from app.core.arm.repeatability import (
    COLUMN_AZIMUTH,
    COORDINATES,
    CYLINDRICAL,
    CoordinateStats,
    Placements,
)

__all__ = [
    "COLUMN_AZIMUTH",
    "COORDINATES",
    "CYLINDRICAL",
    "ArmLayout",
    "ArmLayoutError",
    "ArmPose",
    "CoordinateStats",
    "Link",
    "LinkCapture",
    "PlacementPose",
    "Placements",
    "ThetaMeasurement",
    "ThetaZero",
    "capture_link",
    "cylindrical",
    "forward",
    "jamris_layout",
    "joint_angles_from_gravity",
    "measure_theta",
    "placement_pose",
    "pose_from_link_quaternions",
    "rotation_matrix",
    "up_in_link_frame",
]
