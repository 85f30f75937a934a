"""Capture of still accelerometer poses for the six-position and free-orientation fits.

:class:`PoseCapture` is fed uncalibrated sample blocks. When the board has been still for
``settle_s`` in an orientation not captured yet, it averages ``capture_s`` seconds of samples
and checks the result; every attempt ends in a :class:`CaptureEvent` that is either accepted
(the pose joins :attr:`PoseCapture.poses`) or rejected with a reason for the user:

- moved during capture (the stillness detector fired), or drifted slowly (the first and
  second halves of the capture point more than ``max_drift_deg`` apart);
- the reading is not 1 g within ``norm_tolerance`` (accelerated, or the wrong range);
- six-position mode: more than ``max_face_error_deg`` away from every axis-aligned pose;
- six-position mode: off its axis by more than :data:`MAX_FACE_TILT_DEG` once the chip's own
  offsets are taken out (:func:`face_tilts`); a pose captured earlier is checked again, and
  removed with a reason, as soon as its opposite faces make its offsets known;
- an orientation already captured: less than ``min_separation_deg`` from an earlier pose.

After each attempt, capture waits for the board to move before it tries again (so an
orientation left lying is not rejected over and over); :meth:`PoseCapture.request_capture`,
the "Capture" button, arms it at once.

Faces are named by the sensor axis that points up: ``"+z"`` is the board lying flat chip side
up, ``"-x"`` is standing on its +x edge, and so on. At rest the accelerometer measures "up",
so the nominal reading of face ``"+x"`` is ``(+g, 0, 0)``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from app.core.calibration_procedures.stillness import StillnessDetector
from app.core.orientation import up_in_sensor_frame
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

FACES: tuple[str, ...] = ("+z", "-z", "+x", "-x", "+y", "-y")
"""The six positions in the suggested order (that of the simulator's ``tour``)."""

FACE_DIRECTIONS: dict[str, np.ndarray] = {
    "+x": np.array([1.0, 0.0, 0.0]),
    "-x": np.array([-1.0, 0.0, 0.0]),
    "+y": np.array([0.0, 1.0, 0.0]),
    "-y": np.array([0.0, -1.0, 0.0]),
    "+z": np.array([0.0, 0.0, 1.0]),
    "-z": np.array([0.0, 0.0, -1.0]),
}
"""Up direction in the sensor frame (the nominal normalised reading) of each face."""

FACE_HINTS: dict[str, str] = {
    "+z": "flat, chip side up",
    "-z": "flat, upside down (chip side down)",
    "+x": "standing on its -x edge, +x pointing up",
    "-x": "standing on its +x edge, +x pointing down",
    "+y": "standing on its -y edge, +y pointing up",
    "-y": "standing on its +y edge, +y pointing down",
}
"""A line per face for the wizard's picture of the expected pose."""

SIX_POSITION = "six-position"
FREE = "free"

MAX_FACE_TILT_DEG = 2.0
"""Largest accepted angle (deg) between a six-face pose and its axis, offsets taken out.

A face of a box on a table is within about 1 deg of level (the table, the box's squareness),
and the raw chip's cross-axis coupling (about 1 %, two components) adds up to 0.8 deg; 2 deg
admits both. Beyond that the pose was misplaced: the six-face fit takes every pose as exactly
on its axis and turns a tilted face into about half its tilt of misalignment, so the tilt
errors after the calibration get worse (a 3.3 deg pose: 0.9 deg before, 2.2 deg after)."""

RAW_OFFSET_G = 0.02
"""The LSM6DSOX's zero-g offset, typical +-20 mg per axis, before a calibration."""

RAW_OFFSET_ALLOWANCE_DEG = math.degrees(math.atan(RAW_OFFSET_G))
"""What one unknown off-axis offset can add to a pose's angle to its axis (1.1 deg)."""


def identify_face(direction: np.ndarray) -> tuple[str, float]:
    """The face whose up direction is nearest to ``direction``, and the angle to it (deg)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    axis = int(np.argmax(np.abs(d)))
    face = ("+" if d[axis] >= 0.0 else "-") + "xyz"[axis]
    angle = math.degrees(math.acos(min(1.0, abs(float(d[axis])))))
    return face, angle


def angle_between_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle in degrees between two vectors (any length)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b))))


@dataclass(frozen=True)
class FaceTilt:
    """How far one six-face pose is off its axis (see :func:`face_tilts`).

    ``tilt_deg`` is the angle between the reading, less the offsets known so far, and the
    face's axis; ``limit_deg`` is :data:`MAX_FACE_TILT_DEG` plus what the off-axis offsets
    not known yet may add (:data:`RAW_OFFSET_ALLOWANCE_DEG` each, root-sum-square).
    """

    face: str
    tilt_deg: float
    limit_deg: float
    offsets_known: bool

    @property
    def too_tilted(self) -> bool:
        return self.tilt_deg > self.limit_deg


def face_offsets(poses: list[CapturedPose]) -> np.ndarray:
    """(3,) accelerometer offset per axis (m/s^2) from opposite faces; NaN where one is missing.

    Opposite faces read ``+(1 + s) g + b`` and ``-(1 + s) g + b`` along their axis, so half
    their sum is the offset ``b``, whatever the scale error ``s``; a face tilted by ``t``
    changes it by only ``g (1 - cos t)`` (1.7 mg at 3.3 deg).
    """
    by_face = {pose.face: pose for pose in poses}
    offsets = np.full(3, np.nan)
    for k, axis in enumerate("xyz"):
        plus, minus = by_face.get("+" + axis), by_face.get("-" + axis)
        if plus is not None and minus is not None:
            offsets[k] = 0.5 * (plus.accel_mean_m_s2[k] + minus.accel_mean_m_s2[k])
    return offsets


def face_tilts(poses: list[CapturedPose]) -> list[FaceTilt]:
    """Each six-face pose's angle to its axis, with the offsets known from opposite faces.

    The raw reading of a perfectly placed face is off its axis by the chip's off-axis offsets
    (up to about 1.6 deg): those are subtracted where both faces of their axis are captured,
    and allowed for where not, so a pose is judged exactly once its four neighbours are in.
    """
    offsets = face_offsets(poses)
    out: list[FaceTilt] = []
    for pose in poses:
        k = "xyz".index(pose.face[1])
        others = [j for j in range(3) if j != k]
        known = np.where(np.isfinite(offsets), offsets, 0.0)
        v = pose.accel_mean_m_s2 - known
        off_axis = math.hypot(*(float(v[j]) for j in others))
        tilt = math.degrees(math.atan2(off_axis, abs(float(v[k]))))
        unknown = sum(1 for j in others if not math.isfinite(offsets[j]))
        allowance = math.degrees(math.atan(RAW_OFFSET_G * math.sqrt(unknown)))
        out.append(FaceTilt(pose.face, tilt, MAX_FACE_TILT_DEG + allowance, unknown == 0))
    return out


def tilt_reason(tilt: FaceTilt, earlier: bool = False) -> str:
    """The sentence for a pose rejected by :func:`face_tilts`: which face, by how much."""
    if tilt.offsets_known:
        verb, limit = "is", f"at most {tilt.limit_deg:.1f}°, the sensor's offsets taken out"
    else:
        verb, limit = "reads", (f"at most {tilt.limit_deg:.1f}° while the sensor's offsets "
                                "are not known")
    head = (f"The {tilt.face} up pose captured earlier {verb} {tilt.tilt_deg:.1f}° off its "
            "axis" if earlier else f"{tilt.face} up {verb} {tilt.tilt_deg:.1f}° off its axis")
    return (f"{head} ({limit}); it is removed. Place the board flat on a face of a box on a "
            f"level table and capture {tilt.face} up again.")


@dataclass(frozen=True)
class CapturedPose:
    """One still pose: averages over the capture (uncalibrated, SI units).

    Attributes
    ----------
    accel_mean_m_s2 : (3,) mean specific force.
    accel_std_m_s2 : (3,) per-sample standard deviation (noise while still).
    gyro_mean_rad_s : (3,) mean angular rate (the gyro bias, if still).
    temperature_degc : mean temperature.
    samples : number of samples averaged.
    t_start_s, t_end_s : device time of the first and last sample.
    face : nearest face (``"+x"`` ...).
    face_error_deg : angle between the reading and that face's nominal direction.
    reference_up : (3,) true up direction in the sensor frame when the source knows it
        (simulator, recordings with reference), else None.
    """

    accel_mean_m_s2: np.ndarray
    accel_std_m_s2: np.ndarray
    gyro_mean_rad_s: np.ndarray
    temperature_degc: float
    samples: int
    t_start_s: float
    t_end_s: float
    face: str
    face_error_deg: float
    reference_up: np.ndarray | None = None

    @property
    def direction(self) -> np.ndarray:
        """Unit vector along the mean reading (the measured up direction)."""
        return self.accel_mean_m_s2 / np.linalg.norm(self.accel_mean_m_s2)

    @property
    def accel_std_error_m_s2(self) -> np.ndarray:
        """(3,) white-noise uncertainty of the mean, ``std / sqrt(n)``."""
        return self.accel_std_m_s2 / math.sqrt(self.samples)


@dataclass(frozen=True)
class CaptureEvent:
    """The outcome of one capture attempt; ``reason`` is a sentence for the user."""

    accepted: bool
    reason: str
    time_s: float
    pose: CapturedPose | None = None


class CaptureState(Enum):
    WAITING_FOR_STILL = "waiting for still"
    CAPTURING = "capturing"
    WAITING_FOR_MOTION = "waiting for the next orientation"
    COMPLETE = "complete"


class PoseCapture:
    """Automatic capture of still poses (see the module docstring).

    Parameters
    ----------
    detector : stillness detector (exclusive use: this object feeds it).
    mode : :data:`SIX_POSITION` (faces of a box; stops when all six are captured) or
        :data:`FREE` (any orientations; never stops, :attr:`enough` after ``min_poses``).
    capture_s : averaging time per pose.
    settle_s : still time required before a capture starts (the window comes on top).
    min_separation_deg : a pose closer than this to a captured one is a repeat.
    max_face_error_deg : six-position mode: largest accepted angle to the nearest face.
    max_drift_deg : largest accepted angle between the capture's first- and second-half means.
    norm_tolerance : accepted relative deviation of ``|a|`` from ``gravity``.
    min_poses : poses needed for a fit (6 for six-position, 12 for free).
    """

    def __init__(
        self,
        detector: StillnessDetector,
        mode: str = SIX_POSITION,
        capture_s: float = 3.0,
        settle_s: float = 0.5,
        min_separation_deg: float = 30.0,
        max_face_error_deg: float = 15.0,
        max_drift_deg: float = 0.05,
        norm_tolerance: float = 0.1,
        min_poses: int | None = None,
        gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
    ) -> None:
        if mode not in (SIX_POSITION, FREE):
            raise ValueError(f"unknown capture mode {mode!r}; use {SIX_POSITION!r} or {FREE!r}")
        self.detector = detector
        self.mode = mode
        self.capture_s = float(capture_s)
        self.settle_s = float(settle_s)
        self.min_separation_deg = float(min_separation_deg)
        self.max_face_error_deg = float(max_face_error_deg)
        self.max_drift_deg = float(max_drift_deg)
        self.norm_tolerance = float(norm_tolerance)
        self.min_poses = min_poses if min_poses is not None else (6 if mode == SIX_POSITION else 12)
        self.gravity_m_s2 = float(gravity_m_s2)
        self.samples_needed = max(4, math.ceil(self.capture_s * detector.noise.odr_hz))
        self.poses: list[CapturedPose] = []
        self.events: list[CaptureEvent] = []
        self.state = CaptureState.WAITING_FOR_STILL
        self._run_start_s: float | None = None
        self._parts: list[tuple[np.ndarray, ...]] = []
        self._count = 0

    # -- queries -----------------------------------------------------------------------------
    @property
    def progress(self) -> float:
        """Fraction 0..1 of the current pose's capture."""
        if self.state is not CaptureState.CAPTURING:
            return 0.0
        return min(1.0, self._count / self.samples_needed)

    @property
    def enough(self) -> bool:
        """True when the captured poses suffice for a fit."""
        if self.mode == SIX_POSITION:
            return not self.missing_faces
        return len(self.poses) >= self.min_poses

    @property
    def captured_faces(self) -> list[str]:
        return [pose.face for pose in self.poses]

    @property
    def missing_faces(self) -> list[str]:
        """Six-position mode: faces still to capture, in the suggested order."""
        have = set(self.captured_faces)
        return [face for face in FACES if face not in have]

    # -- control -----------------------------------------------------------------------------
    def request_capture(self) -> None:
        """Arm a capture now (the wizard's button); it starts as soon as the board is still."""
        if self.state is CaptureState.WAITING_FOR_MOTION:
            self.state = CaptureState.WAITING_FOR_STILL

    def reset(self) -> None:
        """Forget every pose and event and start over."""
        self.poses.clear()
        self.events.clear()
        self.state = CaptureState.WAITING_FOR_STILL
        self._run_start_s = None
        self._parts, self._count = [], 0

    def remove_pose(self, index: int) -> CapturedPose:
        """Drop a captured pose (e.g. the user wants to redo it)."""
        pose = self.poses.pop(index)
        if self.state is CaptureState.COMPLETE:
            self.state = CaptureState.WAITING_FOR_MOTION
        return pose

    # -- feeding -----------------------------------------------------------------------------
    def update(self, block: SampleBlock) -> list[CaptureEvent]:
        """Feed one block; returns the capture attempts it finished (possibly none)."""
        new_events: list[CaptureEvent] = []
        if len(block) == 0:
            return new_events
        flags = self.detector.update(block)  # kept running for the live stillness display
        if self.state is CaptureState.COMPLETE:
            return new_events
        t = np.asarray(block.t_s, dtype=np.float64)
        edges = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
        bounds = [0, *edges.tolist(), len(flags)]
        for start, stop in itertools.pairwise(bounds):
            if not flags[start]:
                self._run_start_s = None
                if self.state is CaptureState.CAPTURING:
                    held = self._count / self.detector.noise.odr_hz
                    new_events.append(
                        self._reject(
                            float(t[start]),
                            f"Moved during capture (after {held:.1f} s of {self.capture_s:g} s); "
                            "hold the board still until the capture completes.",
                        )
                    )
                if self.state is CaptureState.WAITING_FOR_MOTION:
                    self.state = CaptureState.WAITING_FOR_STILL
                continue
            if self._run_start_s is None:
                self._run_start_s = float(t[start])
            if self.state is CaptureState.WAITING_FOR_STILL:
                ready = np.flatnonzero(t[start:stop] >= self._run_start_s + self.settle_s)
                if len(ready) == 0:
                    continue
                start += int(ready[0])
                self.state = CaptureState.CAPTURING
                self._parts, self._count = [], 0
            if self.state is CaptureState.CAPTURING:
                take = min(stop - start, self.samples_needed - self._count)
                sl = slice(start, start + take)
                ref = None if block.reference_quat is None else block.reference_quat[sl]
                self._parts.append(
                    (t[sl], block.accel_m_s2[sl], block.gyro_rad_s[sl], block.temp_degc[sl], ref)  # type: ignore[arg-type]
                )
                self._count += take
                if self._count >= self.samples_needed:
                    new_events.extend(self._finish())
                    if self.state is CaptureState.COMPLETE:
                        break
        self.events.extend(new_events)
        return new_events

    # -- internals ---------------------------------------------------------------------------
    def _reject(self, time_s: float, reason: str, pose: CapturedPose | None = None) -> CaptureEvent:
        self._parts, self._count = [], 0
        self.state = CaptureState.WAITING_FOR_MOTION
        return CaptureEvent(False, reason, time_s, pose)

    def _finish(self) -> list[CaptureEvent]:
        t = np.concatenate([p[0] for p in self._parts])
        accel = np.vstack([p[1] for p in self._parts])
        gyro = np.vstack([p[2] for p in self._parts])
        temp = np.concatenate([p[3] for p in self._parts])
        refs = [p[4] for p in self._parts]
        reference_up = None
        if all(r is not None for r in refs):
            up = up_in_sensor_frame(np.vstack(refs)).mean(axis=0)
            reference_up = up / np.linalg.norm(up)
        mean = accel.mean(axis=0)
        face, face_error = identify_face(mean)
        pose = CapturedPose(
            accel_mean_m_s2=mean,
            accel_std_m_s2=accel.std(axis=0, ddof=1),
            gyro_mean_rad_s=gyro.mean(axis=0),
            temperature_degc=float(temp.mean()),
            samples=len(t),
            t_start_s=float(t[0]),
            t_end_s=float(t[-1]),
            face=face,
            face_error_deg=face_error,
            reference_up=reference_up,
        )
        end_s = float(t[-1])
        half = len(accel) // 2
        drift = angle_between_deg(accel[:half].mean(axis=0), accel[half:].mean(axis=0))
        if drift > self.max_drift_deg:
            return [self._reject(
                end_s,
                f"Moved slowly during capture ({drift:.2f} deg of drift, at most "
                f"{self.max_drift_deg:g} deg allowed); let the board rest and capture again.",
                pose,
            )]
        norm_g = float(np.linalg.norm(mean)) / self.gravity_m_s2
        if abs(norm_g - 1.0) > self.norm_tolerance:
            return [self._reject(
                end_s,
                f"The reading is {norm_g:.3f} g, not 1 g: is the board being accelerated, "
                "or is the sensor range wrong?",
                pose,
            )]
        if self.mode == SIX_POSITION and face_error > self.max_face_error_deg:
            return [self._reject(
                end_s,
                f"Not on a face: {face_error:.1f} deg from the nearest one ({face} up, at most "
                f"{self.max_face_error_deg:g} deg). Place the board flat on a face of the box.",
                pose,
            )]
        for index, other in enumerate(self.poses):
            angle = angle_between_deg(mean, other.accel_mean_m_s2)
            if angle < self.min_separation_deg:
                what = f"{other.face} up" if self.mode == SIX_POSITION else "orientation"
                return [self._reject(
                    end_s,
                    f"Orientation already captured: {angle:.1f} deg from pose {index + 1} "
                    f"({what}); at least {self.min_separation_deg:g} deg apart needed. "
                    "Turn the board to a new orientation.",
                    pose,
                )]
        if self.mode == SIX_POSITION:
            tilt = face_tilts([*self.poses, pose])[-1]
            if tilt.too_tilted:
                return [self._reject(end_s, tilt_reason(tilt), pose)]
        self.poses.append(pose)
        self._parts, self._count = [], 0
        events = [CaptureEvent(True, "", end_s, pose)]
        if self.mode == SIX_POSITION:
            events.extend(self._drop_tilted(end_s))
            if not any(kept is pose for kept in self.poses):
                self.state = CaptureState.WAITING_FOR_MOTION
                return events[1:]
        count = len(self.poses)
        if self.mode == SIX_POSITION:
            reason = f"Captured {face} up (pose {count} of {len(FACES)})."
        elif count < self.min_poses:
            reason = f"Captured orientation {count} ({self.min_poses} needed)."
        else:
            reason = f"Captured orientation {count} (enough for a fit; more make it better)."
        self.state = (
            CaptureState.COMPLETE
            if self.mode == SIX_POSITION and self.enough
            else CaptureState.WAITING_FOR_MOTION
        )
        events[0] = CaptureEvent(True, reason, end_s, pose)
        return events

    def _drop_tilted(self, time_s: float) -> list[CaptureEvent]:
        """Remove earlier poses found too far off their axis now that more offsets are known."""
        events: list[CaptureEvent] = []
        while True:
            tilts = face_tilts(self.poses)
            worst = max(range(len(tilts)), key=lambda i: tilts[i].tilt_deg - tilts[i].limit_deg,
                        default=None)
            if worst is None or not tilts[worst].too_tilted:
                return events
            pose = self.poses.pop(worst)
            events.append(CaptureEvent(False, tilt_reason(tilts[worst], earlier=True),
                                       time_s, pose))
