"""Level reference: tare (current attitude as zero) and the reversal procedure.

Tare
----
Subtracting roll and pitch offsets is only right for small angles: roll and pitch do not add
(``u = (sin p, sin r cos p, cos r cos p)``). :class:`TareReference` instead stores a rotation
``T`` of the sensor frame: the smallest rotation that turns the up direction measured at tare
time into the z axis. Later readings are rotated by it (``u' = T u``) before the angles are
taken, so the tared attitude reads exactly level and a sensor mounted askew by any angle on a
platform reads the platform's roll and pitch at every attitude (the platform being level at
tare time). One tare fixes two axes only: if the sensor is also turned about the vertical
against the platform (heading misalignment), that part is not observable from one tare and
roll and pitch mix by that angle (a second tare about a known platform axis would fix it).
An upside-down tare uses a half turn about the sensor x axis.

Reversal (two-position) procedure
---------------------------------
On a surface with a small slope, take a reading ``m1`` (roll, pitch), turn the instrument
180 degrees about the vertical (about the surface normal: it stays on the surface, e.g.
against the same stop) and read ``m2``. A half turn about z reverses the sensor's x and y
axes and keeps z, so the surface's slope enters both roll and pitch with the opposite sign
while the instrument's own offset (sensor mounted askew, accelerometer zero offset) keeps its
sign:

    m1 = offset + slope,   m2 = offset - slope
    offset = (m1 + m2) / 2 per axis,   slope = (m1 - m2) / 2 per axis

``offset`` is what the instrument reads on a truly level surface (subtract it, or use
:attr:`ReversalResult.tare`); ``slope`` is the surface's own roll (rising towards the
instrument's +y side in the first position) and pitch (rising towards +x in the first
position). These formulas hold to first order; :func:`reversal` solves the geometry exactly
from the two up vectors: the base normal seen by the sensor is ``(u1 + u2) / |u1 + u2|``
(unit ``u``), since the half turn flips the horizontal part of ``u`` in the base frame. A turn
that misses 180 degrees by ``e`` (rad) leaves an error of about ``slope * e / 2`` in the offset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.core import quaternion as quat
from app.core.orientation import TiltAngles, angles_from_up, up_in_sensor_frame

_EZ = np.array([0.0, 0.0, 1.0])


def up_from_roll_pitch(roll_deg: np.ndarray | float, pitch_deg: np.ndarray | float) -> np.ndarray:
    """Up direction in the sensor frame (..., 3) for roll and pitch in degrees."""
    r = np.radians(np.asarray(roll_deg, dtype=np.float64))
    p = np.radians(np.asarray(pitch_deg, dtype=np.float64))
    r, p = np.broadcast_arrays(r, p)
    return np.stack([np.sin(p), np.sin(r) * np.cos(p), np.cos(r) * np.cos(p)], axis=-1)


def _rotation_to_z(up: np.ndarray) -> np.ndarray:
    """Smallest rotation (quaternion) taking the direction ``up`` onto +z."""
    u = np.asarray(up, dtype=np.float64).reshape(3)
    norm = float(np.linalg.norm(u))
    if not math.isfinite(norm) or norm == 0.0:
        raise ValueError("the reference up direction must be a finite, non-zero vector")
    u = u / norm
    axis = np.cross(u, _EZ)
    sin_angle = float(np.linalg.norm(axis))
    cos_angle = float(u[2])
    if sin_angle < 1e-12:
        if cos_angle > 0.0:
            return quat.IDENTITY.copy()
        return quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), math.pi)
    return quat.normalize(quat.from_axis_angle(axis, math.atan2(sin_angle, cos_angle)))


@dataclass(frozen=True)
class TareReference:
    """A level reference: rotation ``T`` (quaternion) from the sensor frame to the tared frame.

    Build one with :meth:`from_up` (e.g. from a still accelerometer mean), :meth:`from_angles`
    or :meth:`from_quaternion`; apply it with :meth:`apply_up`, :meth:`apply_angles` or
    :meth:`apply_quaternion`.
    """

    quaternion: np.ndarray

    @classmethod
    def identity(cls) -> TareReference:
        return cls(quat.IDENTITY.copy())

    @classmethod
    def from_up(cls, up: np.ndarray) -> TareReference:
        """Tare at the attitude whose up direction (sensor frame, any length) is ``up``."""
        return cls(_rotation_to_z(up))

    @classmethod
    def from_angles(cls, roll_deg: float, pitch_deg: float) -> TareReference:
        """Tare at the attitude that reads ``roll_deg``, ``pitch_deg``."""
        return cls.from_up(up_from_roll_pitch(roll_deg, pitch_deg))

    @classmethod
    def from_quaternion(cls, q: np.ndarray) -> TareReference:
        """Tare at a sensor-to-earth orientation (e.g. the filter's current quaternion)."""
        return cls.from_up(up_in_sensor_frame(np.asarray(q, dtype=np.float64).reshape(4)))

    @property
    def is_identity(self) -> bool:
        return bool(np.allclose(self.quaternion, quat.IDENTITY, atol=1e-15))

    @property
    def reference_up(self) -> np.ndarray:
        """The up direction (sensor frame) that reads level after the tare."""
        return quat.rotate_inverse(self.quaternion, _EZ)

    @property
    def reference_angles(self) -> TiltAngles:
        """The (untared) roll, pitch, tilt of the tared attitude, degrees."""
        return angles_from_up(self.reference_up)

    def apply_up(self, up: np.ndarray) -> np.ndarray:
        """Up directions (..., 3) in the tared frame (accelerometer readings work too)."""
        return quat.rotate(self.quaternion, np.asarray(up, dtype=np.float64))

    def apply_quaternion(self, q: np.ndarray) -> np.ndarray:
        """Sensor-to-earth quaternions (..., 4) to tared-frame-to-earth: ``q * conj(T)``."""
        return quat.normalize(quat.multiply(q, quat.conjugate(self.quaternion)))

    def apply_angles(
        self, roll_deg: np.ndarray | float, pitch_deg: np.ndarray | float
    ) -> TiltAngles:
        """Tared roll, pitch, tilt and direction from untared roll and pitch (degrees)."""
        return angles_from_up(self.apply_up(up_from_roll_pitch(roll_deg, pitch_deg)))

    def to_list(self) -> list[float]:
        """``[w, x, y, z]`` for a profile."""
        return [float(v) for v in self.quaternion]

    @classmethod
    def from_list(cls, values: list[float]) -> TareReference:
        q = np.asarray(values, dtype=np.float64)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or np.linalg.norm(q) == 0.0:
            raise ValueError(f"a tare quaternion needs four finite numbers, not {values!r}")
        return cls(quat.normalize(q))


@dataclass(frozen=True)
class ReversalResult:
    """Instrument offset and surface slope from two readings 180 degrees apart (degrees).

    Attributes
    ----------
    offset_roll_deg, offset_pitch_deg : the reading on a level surface (the instrument's own
        offset), in its own axes.
    slope_roll_deg, slope_pitch_deg : the surface's slope in the axes of the first position
        (roll: rising towards +y; pitch: rising towards +x).
    slope_deg : angle of the surface normal from the vertical.
    tare : level reference that removes the offset (the base's normal becomes "level").
    """

    offset_roll_deg: float
    offset_pitch_deg: float
    slope_roll_deg: float
    slope_pitch_deg: float
    slope_deg: float
    tare: TareReference


def reversal(up_first: np.ndarray, up_second: np.ndarray) -> ReversalResult:
    """Exact reversal from the up directions (e.g. calibrated accelerometer means) of both."""
    u1 = np.asarray(up_first, dtype=np.float64).reshape(3)
    u2 = np.asarray(up_second, dtype=np.float64).reshape(3)
    u1 = u1 / np.linalg.norm(u1)
    u2 = u2 / np.linalg.norm(u2)
    normal = u1 + u2
    if np.linalg.norm(normal) < 1e-6:
        raise ValueError("the two readings are opposite: was the instrument turned over?")
    tare = TareReference.from_up(normal)
    offset = angles_from_up(normal)
    slope = angles_from_up(tare.apply_up(u1))
    return ReversalResult(
        offset_roll_deg=float(offset.roll_deg),
        offset_pitch_deg=float(offset.pitch_deg),
        slope_roll_deg=float(slope.roll_deg),
        slope_pitch_deg=float(slope.pitch_deg),
        slope_deg=float(slope.tilt_deg),
        tare=tare,
    )


def reversal_from_angles(
    roll_first_deg: float, pitch_first_deg: float, roll_second_deg: float, pitch_second_deg: float
) -> ReversalResult:
    """:func:`reversal` from the roll and pitch read in the two positions."""
    return reversal(
        up_from_roll_pitch(roll_first_deg, pitch_first_deg),
        up_from_roll_pitch(roll_second_deg, pitch_second_deg),
    )


def reversal_first_order(
    first: tuple[float, float], second: tuple[float, float]
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The textbook per-axis formulas: ``offset = (m1 + m2) / 2``, ``slope = (m1 - m2) / 2``.

    ``first`` and ``second`` are ``(roll, pitch)``; returns ``(offset, slope)`` as
    ``(roll, pitch)`` pairs. Good to first order in the angles (use :func:`reversal`).
    """
    offset = ((first[0] + second[0]) / 2.0, (first[1] + second[1]) / 2.0)
    slope = ((first[0] - second[0]) / 2.0, (first[1] - second[1]) / 2.0)
    return offset, slope
