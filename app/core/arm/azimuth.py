"""The base column's angle (theta) measured from gravity and the magnetic field (JAMRIS).

An accelerometer cannot see a turn about the vertical, so without a magnetometer the column's
angle is typed. With one, each link's *global* orientation follows from a static placement,
as in the paper: the accelerometer and the (calibrated) field are averaged over the capture,
and the TRIAD frame of the two (up from gravity; east = field x up; north = up x east) is the
sensor's orientation in ENU with y toward magnetic north. Nothing is filtered: a placement is
static, and a capture that is not (the sensor moving) or whose field is not the earth's
(strength or dip off the reference: iron, a magnet, an uncalibrated chip) is refused with the
reason, never used.

Given the other joints (from gravity, :func:`~app.core.arm.kinematics.joint_angles_from_gravity`),
link ``i``'s frame in the base frame with the column at zero is ``R_i0``; its TRIAD frame is
``R_s = Rz(psi) R_i0`` where ``psi`` is the base's x axis turned by theta, counter-clockwise
from magnetic east. So ``psi`` is the turn about the vertical of ``R_s R_i0^T``, one estimate
per link with a magnetometer; they must agree (:data:`LINK_AGREEMENT_DEG`).

Two angles come out:

- the **magnetic azimuth** of the column (where the arm points, as a compass reads it:
  clockwise from magnetic north), absolute;
- **theta**, the column's joint angle (counter-clockwise seen from above, like every joint
  of a layout) from a zero: by default the base's x axis is magnetic north (theta = -azimuth),
  and :class:`ThetaZero` set at a placement makes that placement's direction theta = 0 (the
  user's reference direction on the table).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.core.arm.kinematics import ArmPose, forward, joint_angles_from_gravity
from app.core.arm.layout import ArmLayout
from app.core.field_check import (
    REST_MAX_FIELD_SPREAD_UT,
    FieldReference,
    check_disturbance,
    dip_deg,
    field_norm,
)
from app.core.samples import STANDARD_GRAVITY_M_S2

CAPTURE_STEADY_DEG = 0.5
"""RMS angle of the accelerometer's samples about their mean up to which a capture is still:
the LSM6DSOX's noise is about 0.1 degrees a sample; a hand settling moves it by degrees."""
CAPTURE_G_TOLERANCE = 0.03
"""``| |mean a| - g |`` up to this fraction of g (no sustained linear acceleration)."""
MIN_FIELD_SAMPLES = 3
MIN_HORIZONTAL_FIELD_DEG = 10.0
"""The field must make at least this angle with the vertical (else it has no north)."""
LINK_AGREEMENT_DEG = 3.0
"""The links' estimates of the column's turn must agree within this (else the field differs
between the sensors, or the layout does not describe the arm)."""
VERTICAL_AXIS_COS = math.cos(math.radians(1.0))


def _wrap(angle_deg: float) -> float:
    return float((angle_deg + 180.0) % 360.0 - 180.0)


@dataclass(frozen=True, slots=True)
class LinkCapture:
    """One link sensor's static capture: mean up and field (sensor frame) and its checks."""

    link: int
    up: np.ndarray | None
    """Unit vector up in the sensor frame (the mean accelerometer), None without samples."""
    field_ut: np.ndarray | None
    """Mean calibrated field (uT), None without a magnetometer or field samples."""
    samples: int
    field_samples: int
    norm_ut: float = math.nan
    dip_deg: float = math.nan
    steady: bool = False
    refused: str = ""
    """Why the capture cannot give an azimuth ('' when it can)."""

    @property
    def has_azimuth(self) -> bool:
        return not self.refused and self.field_ut is not None and self.up is not None

    def triad(self) -> np.ndarray:
        """(3, 3) sensor-to-ENU rotation (rows: east, north, up in the sensor frame)."""
        assert self.up is not None and self.field_ut is not None
        east = np.cross(self.field_ut, self.up)
        east /= np.linalg.norm(east)
        return np.vstack([east, np.cross(self.up, east), self.up])


def capture_link(link: int, accel_m_s2: np.ndarray, mag_ut: np.ndarray | None,
                 reference: FieldReference | None, name: str = "") -> LinkCapture:
    """Average one sensor's samples over a capture and check them.

    ``accel_m_s2`` (N, 3) calibrated; ``mag_ut`` (N, 3) calibrated field with NaN rows (no
    new sample), or None without a magnetometer. ``reference`` is what the field should read
    (None: its strength and dip are not checked, only its steadiness). ``name`` names the
    link in the reasons (default ``link N``).
    """
    name = name or f"link {link}"
    accel = np.asarray(accel_m_s2, dtype=np.float64).reshape(-1, 3)
    accel = accel[np.all(np.isfinite(accel), axis=1)]
    if len(accel) == 0:
        return LinkCapture(link, None, None, 0, 0, refused="no samples in the capture")
    mean = accel.mean(axis=0)
    up = mean / np.linalg.norm(mean)
    cosines = np.clip((accel @ up) / np.linalg.norm(accel, axis=1), -1.0, 1.0)
    wobble = float(np.degrees(np.sqrt(np.mean(np.arccos(cosines) ** 2))))
    g_off = abs(float(np.linalg.norm(mean)) / STANDARD_GRAVITY_M_S2 - 1.0)
    steady = wobble <= CAPTURE_STEADY_DEG and g_off <= CAPTURE_G_TOLERANCE
    reasons = []
    if not steady:
        reasons.append(f"{name} not steady (accelerometer {wobble:.2f}° RMS, "
                       f"|a| {g_off:.1%} off g)")
    if mag_ut is None:
        return LinkCapture(link, up, None, len(accel), 0, steady=steady,
                           refused="; ".join(reasons))
    mag = np.asarray(mag_ut, dtype=np.float64).reshape(-1, 3)
    mag = mag[np.all(np.isfinite(mag), axis=1)]
    if len(mag) < MIN_FIELD_SAMPLES:
        reasons.append(f"{name}: {len(mag)} field samples in the capture (at least "
                       f"{MIN_FIELD_SAMPLES})")
        return LinkCapture(link, up, None, len(accel), len(mag), steady=steady,
                           refused="; ".join(reasons))
    norms = field_norm(mag)
    dips = dip_deg(mag, np.broadcast_to(mean, mag.shape))
    field_mean = mag.mean(axis=0)
    spread = float(np.sqrt(np.sum(mag.var(axis=0))))
    if spread > REST_MAX_FIELD_SPREAD_UT * math.sqrt(3.0):
        reasons.append(f"{name}: the field moved during the capture ({spread:.1f} µT)")
    if reference is not None:
        disturbance = check_disturbance(norms, dips, reference)
        if disturbance.fraction > 0.0:
            reasons.append(f"{name}: {disturbance.message}")
    horizontal_deg = 90.0 - abs(float(np.median(dips)))
    if horizontal_deg < MIN_HORIZONTAL_FIELD_DEG:
        reasons.append(f"{name}: the field is within {horizontal_deg:.0f}° of vertical "
                       "(no north to find)")
    return LinkCapture(link, up, field_mean, len(accel), len(mag), float(np.median(norms)),
                       float(np.median(dips)), steady, "; ".join(reasons))


@dataclass(frozen=True, slots=True)
class ThetaZero:
    """Where theta is 0: the column's turn ``psi`` (counter-clockwise from magnetic east,
    degrees) of the base's x axis. The default is magnetic north (90)."""

    psi_deg: float = 90.0
    source: str = "magnetic north"

    def theta(self, psi_deg: float) -> float:
        return _wrap(psi_deg - self.psi_deg)


@dataclass(frozen=True, slots=True)
class ThetaMeasurement:
    """The column's angle from one placement's captures."""

    theta_deg: float
    """The column's joint angle from :class:`ThetaZero` (NaN when refused)."""
    azimuth_deg: float
    """Where the column points, clockwise from magnetic north, 0-360 (NaN when refused)."""
    psi_deg: float
    """The column's turn counter-clockwise from magnetic east (for :class:`ThetaZero`)."""
    link_psi_deg: tuple[float, ...]
    """Each link's estimate of ``psi`` (NaN for a link without a usable capture)."""
    spread_deg: float
    refused: str = ""
    """Why theta is not measured ('' when it is)."""

    @property
    def ok(self) -> bool:
        return not self.refused


def column_joint(layout: ArmLayout) -> int | None:
    """The joint whose angle a magnetometer measures: the first, if its axis is vertical."""
    axis = np.asarray(layout.links[0].axis)
    return 0 if abs(float(axis[2])) >= VERTICAL_AXIS_COS else None


def _refused(n: int, reason: str) -> ThetaMeasurement:
    return ThetaMeasurement(math.nan, math.nan, math.nan, (math.nan,) * n, math.nan, reason)


def measure_theta(layout: ArmLayout, captures: Sequence[LinkCapture | None],
                  zero: ThetaZero = ThetaZero(),
                  known_deg: Sequence[float | None] | None = None) -> ThetaMeasurement:
    """Theta of one placement from its links' captures (None for a link without a sensor).

    The other joints come from gravity (``known_deg`` where gravity cannot see them, as in
    :func:`joint_angles_from_gravity`). Refused (``refused`` says why, theta NaN) when the
    layout has no column at its base, no link gives a usable azimuth, or the links disagree.
    """
    n = layout.n_joints
    if len(captures) != n:
        raise ValueError(f"{len(captures)} captures for {n} links")
    if column_joint(layout) is None:
        return _refused(n, "the layout has no column about the vertical at its base: theta "
                           "is measured for the first joint only")
    notes = [c.refused for c in captures if c is not None and c.refused]
    if notes:  # a link moving or in a disturbed field: the whole placement is wrong
        return _refused(n, "; ".join(notes))
    ups = [None if c is None or c.up is None else c.up for c in captures]
    known: list[float | None] = list(known_deg) if known_deg is not None else [None] * n
    known[0] = 0.0
    angles, _observed = joint_angles_from_gravity(layout, ups, known)
    rotations = forward(layout, angles).rotations
    psi = np.full(n, np.nan)
    for i, capture in enumerate(captures):
        if capture is None or not capture.has_azimuth:
            continue
        turn = capture.triad() @ rotations[i].T  # base (column at 0) -> ENU
        psi[i] = math.degrees(math.atan2(turn[1, 0] - turn[0, 1], turn[0, 0] + turn[1, 1]))
    used = np.isfinite(psi)
    if not np.any(used):
        return _refused(n, "no link has a magnetometer")
    vectors = np.exp(1j * np.radians(psi[used]))
    mean_psi = math.degrees(float(np.angle(vectors.mean())))
    spread = float(max(abs(_wrap(p - mean_psi)) for p in psi[used]))
    if spread > LINK_AGREEMENT_DEG:
        return ThetaMeasurement(
            math.nan, math.nan, mean_psi, tuple(float(p) for p in psi), spread,
            f"the links' headings differ by {2 * spread:.1f}° (more than "
            f"{2 * LINK_AGREEMENT_DEG:.0f}°): the field differs between the sensors, or the "
            "layout does not describe the arm")
    return ThetaMeasurement(zero.theta(mean_psi), float((90.0 - mean_psi) % 360.0), mean_psi,
                            tuple(float(p) for p in psi), spread)


def circular_mean_deg(angles_deg: np.ndarray) -> float:
    """The mean direction of angles (degrees, -180..180]; NaN without any."""
    angles = np.asarray(angles_deg, dtype=np.float64)
    angles = angles[np.isfinite(angles)]
    if len(angles) == 0:
        return math.nan
    return math.degrees(float(np.angle(np.exp(1j * np.radians(angles)).mean())))


def unwrap_about(angles_deg: np.ndarray, centre_deg: float) -> np.ndarray:
    """Angles moved by whole turns to within 180 degrees of ``centre_deg``."""
    angles = np.asarray(angles_deg, dtype=np.float64)
    return centre_deg + (angles - centre_deg + 180.0) % 360.0 - 180.0


@dataclass(frozen=True, slots=True)
class PlacementPose:
    """One captured placement: the pose (None when refused), its theta, and why not."""

    pose: ArmPose | None
    theta: ThetaMeasurement | None
    """None when no link has a magnetometer (theta typed)."""
    refused: str = ""

    @property
    def theta_source(self) -> str:
        return "typed" if self.theta is None else "measured"

    @property
    def column_azimuth_deg(self) -> float:
        return math.nan if self.theta is None else self.theta.azimuth_deg


def placement_pose(layout: ArmLayout, captures: Sequence[LinkCapture | None],
                   zero: ThetaZero = ThetaZero(),
                   known_deg: Sequence[float | None] | None = None) -> PlacementPose:
    """The pose of one static placement from its links' captures.

    Hinges come from gravity; the column's angle is measured when a link has a magnetometer
    (:func:`measure_theta`), else it is ``known_deg[0]`` (typed). Refused when a link moved
    or its field is disturbed, or theta cannot be measured though a magnetometer is there.
    """
    n = layout.n_joints
    if len(captures) != n:
        raise ValueError(f"{len(captures)} captures for {n} links")
    notes = [c.refused for c in captures if c is not None and c.refused]
    if notes:
        return PlacementPose(None, None, "; ".join(notes))
    known: list[float | None] = list(known_deg) if known_deg is not None else [None] * n
    theta = None
    if any(c is not None and c.field_ut is not None for c in captures):
        theta = measure_theta(layout, captures, zero, known)
        if not theta.ok:
            return PlacementPose(None, theta, theta.refused)
        known[0] = theta.theta_deg
    ups = [None if c is None else c.up for c in captures]
    angles, _observed = joint_angles_from_gravity(layout, ups, known)
    return PlacementPose(forward(layout, angles), theta)
