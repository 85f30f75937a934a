"""Forward kinematics of a measuring arm, from joint angles or from each link's gravity reading.

:func:`forward` turns joint angles into every joint's position and the end point in the base
frame, as x, y, z and as cylindrical R, Z and azimuth about the base's vertical axis (the
paper's R and Z). :func:`joint_angles_from_gravity` finds the joint angles from the up
direction each link's accelerometer sees: a hinge's angle follows from the up vectors of the
two links it joins, about the hinge's axis, as long as that axis is not vertical (a vertical
axis, like the JAMRIS column's, leaves gravity unchanged: its angle must come from elsewhere).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.core import quaternion as quat
from app.core.arm.layout import ArmLayout, ArmLayoutError
from app.core.orientation import up_in_sensor_frame

VERTICAL_AXIS_TOLERANCE_DEG = 10.0
"""A hinge whose axis is within this of vertical gets no angle from gravity."""
_UP = np.array([0.0, 0.0, 1.0])


def rotation_matrix(axis: Sequence[float], angle_rad: float) -> np.ndarray:
    """The 3x3 rotation by ``angle_rad`` about the unit vector ``axis`` (Rodrigues)."""
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1.0 - np.cos(angle_rad)) * (k @ k)


def cylindrical(points: np.ndarray, base: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """R, Z and azimuth (degrees, from +x towards +y) of points (..., 3) about the base axis."""
    relative = np.asarray(points, dtype=np.float64) - np.asarray(base, dtype=np.float64)
    radius = np.hypot(relative[..., 0], relative[..., 1])
    azimuth = np.degrees(np.arctan2(relative[..., 1], relative[..., 0]))
    return np.stack([radius, relative[..., 2], azimuth], axis=-1)


@dataclass(frozen=True, slots=True)
class ArmPose:
    """Where the arm is: every joint's position and the end point, in the base frame."""

    joint_angles_deg: np.ndarray
    """(n,) the angles the pose was computed from (without the links' offsets)."""
    rotations: np.ndarray
    """(n, 3, 3) each link's frame in the base frame."""
    points: np.ndarray
    """(n + 1, 3) the base, every joint after it, and the end point last."""
    unit: str = "mm"

    @property
    def end(self) -> np.ndarray:
        return self.points[-1]

    @property
    def cylindrical(self) -> np.ndarray:
        """R, Z, azimuth (degrees) of the end point about the base's vertical axis."""
        return cylindrical(self.points[-1], self.points[0])

    @property
    def radius(self) -> float:
        return float(self.cylindrical[0])

    @property
    def height(self) -> float:
        return float(self.cylindrical[1])

    @property
    def azimuth_deg(self) -> float:
        return float(self.cylindrical[2])

    def coordinates(self) -> dict[str, float]:
        """The end point as x, y, z, R, Z and azimuth_deg."""
        x, y, z = (float(v) for v in self.end)
        r, height, azimuth = (float(v) for v in self.cylindrical)
        return {"x": x, "y": y, "z": z, "R": r, "Z": height, "azimuth_deg": azimuth}


def _angles(layout: ArmLayout, joint_angles_deg) -> np.ndarray:
    angles = np.asarray(joint_angles_deg, dtype=np.float64).reshape(-1)
    if len(angles) != layout.n_joints:
        raise ArmLayoutError(f"{len(angles)} joint angles for {layout.n_joints} joints")
    if not np.all(np.isfinite(angles)):
        raise ArmLayoutError(f"joint angles must be finite, got {angles.tolist()}")
    return angles


def forward(layout: ArmLayout, joint_angles_deg: Sequence[float] | np.ndarray) -> ArmPose:
    """The pose for the given joint angles (degrees, one per link, offsets added here)."""
    angles = _angles(layout, joint_angles_deg)
    rotations = np.empty((layout.n_joints, 3, 3))
    points = np.empty((layout.n_joints + 1, 3))
    points[0] = layout.base_position
    frame = np.eye(3)
    for i, (link, angle) in enumerate(zip(layout.links, angles)):
        frame = frame @ rotation_matrix(link.axis, np.radians(link.offset_deg + angle))
        rotations[i] = frame
        points[i + 1] = points[i] + frame @ (link.length * np.asarray(link.direction))
    return ArmPose(angles, rotations, points, layout.unit)


def _wrap_deg(angle: float) -> float:
    return float((angle + 180.0) % 360.0 - 180.0)


def joint_angles_from_gravity(
    layout: ArmLayout,
    ups: Sequence[np.ndarray | None],
    known_deg: Sequence[float | None] | None = None,
    vertical_tolerance_deg: float = VERTICAL_AXIS_TOLERANCE_DEG,
    measured_deg: Sequence[float | None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles (degrees) from the up direction seen on each link, and which were observed.

    ``ups[i]`` is the up direction in link ``i``'s frame (its accelerometer reading, turned
    into the link's frame), or None for a link without a sensor. A joint whose axis is
    (nearly) vertical, or whose link has no sensor, takes ``known_deg[i]`` (0 if that is None).
    ``measured_deg[i]``, when given and finite, is joint ``i``'s angle measured by other means
    (a joint filter on the two links' sensors): it wins over gravity and counts as observed.
    The base is taken as level. Returns ``(angles, observed)``.
    """
    n = layout.n_joints
    if len(ups) != n:
        raise ArmLayoutError(f"{len(ups)} up vectors for {n} links")
    known = list(known_deg) if known_deg is not None else [None] * n
    if len(known) != n:
        raise ArmLayoutError(f"{len(known)} known angles for {n} links")
    measured_angles = list(measured_deg) if measured_deg is not None else [None] * n
    if len(measured_angles) != n:
        raise ArmLayoutError(f"{len(measured_angles)} measured angles for {n} links")
    angles = np.zeros(n)
    observed = np.zeros(n, dtype=bool)
    cos_tolerance = np.cos(np.radians(vertical_tolerance_deg))
    frame = np.eye(3)
    up_previous = _UP.copy()
    for i, link in enumerate(layout.links):
        axis = np.asarray(link.axis)
        measured = None if ups[i] is None else np.asarray(ups[i], dtype=np.float64).reshape(3)
        usable = (
            measured is not None and np.all(np.isfinite(measured))
            and np.linalg.norm(measured) > 0
            and abs(float((frame @ axis) @ _UP)) < cos_tolerance
        )
        given = measured_angles[i]
        if given is not None and np.isfinite(given):
            angles[i] = _wrap_deg(float(given))
            observed[i] = True
            usable = False  # the next joint's reference is this link's modelled up
        elif usable:
            # u_i = Rot(axis, -theta) u_{i-1}: theta is the angle from u_i to u_{i-1} about axis.
            assert measured is not None  # usable says so
            cross = np.cross(measured, up_previous)
            along = measured - axis * (axis @ measured)
            previous = up_previous - axis * (axis @ up_previous)
            theta = np.degrees(np.arctan2(axis @ cross, along @ previous))
            angles[i] = _wrap_deg(theta - link.offset_deg)
            observed[i] = True
        else:
            angles[i] = 0.0 if known[i] is None else float(known[i])  # type: ignore[arg-type]
        frame = frame @ rotation_matrix(axis, np.radians(link.offset_deg + angles[i]))  # type: ignore[arg-type]
        up_previous = measured / np.linalg.norm(measured) if usable else frame.T @ _UP  # type: ignore[operator, arg-type]
    return angles, observed


def up_in_link_frame(q: np.ndarray, mount: np.ndarray | None = None) -> np.ndarray:
    """The up direction in a link's frame from its sensor's orientation quaternion.

    ``mount`` rotates sensor-frame vectors into the link frame (None: the sensor's axes are
    the link's, x along the link and z up when the joint is at zero).
    """
    up = up_in_sensor_frame(np.asarray(q, dtype=np.float64))
    return up if mount is None else quat.rotate(mount, up)


def pose_from_link_quaternions(
    layout: ArmLayout,
    quaternions: Sequence[np.ndarray | None],
    known_deg: Sequence[float | None] | None = None,
    mounts: Sequence[np.ndarray | None] | None = None,
    measured_deg: Sequence[float | None] | None = None,
) -> tuple[ArmPose, np.ndarray]:
    """The pose from each link's sensor orientation (None for a link without one).

    Only gravity is used (heading is not observable without a magnetometer), so vertical
    joints take ``known_deg``; ``measured_deg`` overrides joints measured otherwise (see
    :func:`joint_angles_from_gravity`). Returns the pose and which joints were observed.
    """
    if len(quaternions) != layout.n_joints:
        raise ArmLayoutError(f"{len(quaternions)} orientations for {layout.n_joints} links")
    mounts = list(mounts) if mounts is not None else [None] * layout.n_joints
    ups = [
        None if q is None else up_in_link_frame(q, mount)
        for q, mount in zip(quaternions, mounts)
    ]
    angles, observed = joint_angles_from_gravity(layout, ups, known_deg,
                                                 measured_deg=measured_deg)
    return forward(layout, angles), observed  # type: ignore[arg-type]
