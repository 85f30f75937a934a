"""Before/after comparison: tilt error of still poses with and without a calibration.

For each pose the mean accelerometer reading (uncalibrated) is corrected by the "before" and
the "after" calibration, turned into angles with :mod:`app.core.orientation`, and compared
with a reference up direction. The reference is either known (the simulator's reference
quaternion, a precision wedge, a face of the box) or, for the face of a box, nominal.

Note on honesty: comparing a six-position fit with the very faces it was fitted to measures
only the fit residual (12 parameters from 18 numbers). An independent check uses poses that
were not in the fit, at known angles (e.g. the simulator's ``static`` poses, a sine bar).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.core.calibration import IDENTITY_CALIBRATION, SensorCalibration
from app.core.calibration_procedures.poses import FACE_DIRECTIONS, CapturedPose
from app.core.orientation import angles_from_up, up_in_sensor_frame
from app.core.samples import STANDARD_GRAVITY_M_S2

ROLL_UNDEFINED_ABOVE_PITCH_DEG = 80.0
"""Roll errors are reported as NaN where the reference pitch is steeper than this."""

WORSE_MARGIN_DEG = 0.01
"""A calibration is worse when its RMS tilt error exceeds the one before by more than this:
the readouts' resolution, below which a difference cannot be seen (nor trusted)."""


def calibrate_accel(calibration: SensorCalibration, accel_m_s2: np.ndarray) -> np.ndarray:
    """``A (a - b)`` for readings (..., 3): the pipeline's accelerometer correction."""
    return (np.asarray(accel_m_s2, dtype=np.float64) - calibration.accel_bias_m_s2) @ (
        calibration.accel_matrix.T
    )


def _wrap_deg(angle: np.ndarray) -> np.ndarray:
    return (np.asarray(angle) + 180.0) % 360.0 - 180.0


def _angle_between_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(cross, np.sum(a * b, axis=-1)))


@dataclass(frozen=True)
class TiltErrors:
    """Per-pose errors (degrees) of one calibration against the reference.

    Attributes
    ----------
    inclination_deg : (n,) angle between measured and reference up directions (>= 0).
    roll_deg, pitch_deg, tilt_deg : (n,) signed errors (measured - reference); roll is NaN
        where the reference is steeper than :data:`ROLL_UNDEFINED_ABOVE_PITCH_DEG`.
    norm_error_mg : (n,) ``|a_cal| - g``.
    """

    inclination_deg: np.ndarray
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    tilt_deg: np.ndarray
    norm_error_mg: np.ndarray

    @property
    def rms_deg(self) -> float:
        return float(np.sqrt(np.mean(self.inclination_deg**2)))

    @property
    def max_deg(self) -> float:
        return float(np.max(self.inclination_deg))

    @property
    def norm_rms_mg(self) -> float:
        return float(np.sqrt(np.mean(self.norm_error_mg**2)))


@dataclass(frozen=True)
class TiltComparison:
    """Errors before and after calibration over the same poses.

    Attributes
    ----------
    labels : one name per pose (face names, "roll 30 pitch -20", ...).
    reference_roll_deg, reference_pitch_deg, reference_tilt_deg : (n,) reference angles.
    before, after : :class:`TiltErrors`.
    """

    labels: tuple[str, ...]
    reference_roll_deg: np.ndarray
    reference_pitch_deg: np.ndarray
    reference_tilt_deg: np.ndarray
    before: TiltErrors
    after: TiltErrors

    def rows(self) -> list[dict[str, float | str]]:
        """One dict per pose (for a table widget or a report)."""
        return [
            {
                "pose": label,
                "roll_deg": float(self.reference_roll_deg[i]),
                "pitch_deg": float(self.reference_pitch_deg[i]),
                "tilt_deg": float(self.reference_tilt_deg[i]),
                "error_before_deg": float(self.before.inclination_deg[i]),
                "error_after_deg": float(self.after.inclination_deg[i]),
            }
            for i, label in enumerate(self.labels)
        ]


def worsening(comparison: TiltComparison, margin_deg: float = WORSE_MARGIN_DEG) -> str:
    """A sentence when the calibration makes the RMS tilt error worse, else ``""``.

    A result that makes the instrument read worse than before must not be applied silently;
    the sentence names both figures and the worst pose.
    """
    before, after = comparison.before.rms_deg, comparison.after.rms_deg
    if not after > before + margin_deg:
        return ""
    worst = int(np.argmax(comparison.after.inclination_deg - comparison.before.inclination_deg))
    return (f"This calibration makes the tilt error worse: {before:.2f}° RMS before, "
            f"{after:.2f}° after (worst: {comparison.labels[worst]}, "
            f"{comparison.before.inclination_deg[worst]:.2f}° → "
            f"{comparison.after.inclination_deg[worst]:.2f}°).")


def tilt_errors(
    accel_means_m_s2: np.ndarray,
    reference_up: np.ndarray,
    calibration: SensorCalibration,
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
) -> TiltErrors:
    """Errors of ``calibration`` applied to mean readings (n, 3) against reference up (n, 3)."""
    measured = calibrate_accel(calibration, np.asarray(accel_means_m_s2).reshape(-1, 3))
    reference = np.asarray(reference_up, dtype=np.float64).reshape(-1, 3)
    got = angles_from_up(measured)
    want = angles_from_up(reference)
    roll = _wrap_deg(got.roll_deg - want.roll_deg)
    roll = np.where(np.abs(want.pitch_deg) > ROLL_UNDEFINED_ABOVE_PITCH_DEG, np.nan, roll)
    return TiltErrors(
        inclination_deg=_angle_between_deg(measured, reference),
        roll_deg=roll,
        pitch_deg=got.pitch_deg - want.pitch_deg,
        tilt_deg=got.tilt_deg - want.tilt_deg,
        norm_error_mg=(np.linalg.norm(measured, axis=1) - gravity_m_s2) / gravity_m_s2 * 1e3,
    )


def compare_tilt(
    accel_means_m_s2: np.ndarray,
    reference_up: np.ndarray,
    after: SensorCalibration,
    before: SensorCalibration = IDENTITY_CALIBRATION,
    labels: Sequence[str] | None = None,
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
) -> TiltComparison:
    """Tilt errors of uncalibrated mean readings (n, 3) corrected by ``before`` and ``after``."""
    reference = np.asarray(reference_up, dtype=np.float64).reshape(-1, 3)
    want = angles_from_up(reference)
    n = len(reference)
    if labels is None:
        labels = [f"roll {r:.1f} pitch {p:.1f}" for r, p in zip(want.roll_deg, want.pitch_deg)]
    if len(labels) != n:
        raise ValueError("one label per pose is needed")
    return TiltComparison(
        labels=tuple(labels),
        reference_roll_deg=np.asarray(want.roll_deg),
        reference_pitch_deg=np.asarray(want.pitch_deg),
        reference_tilt_deg=np.asarray(want.tilt_deg),
        before=tilt_errors(accel_means_m_s2, reference, before, gravity_m_s2),
        after=tilt_errors(accel_means_m_s2, reference, after, gravity_m_s2),
    )


def reference_up_from_quaternions(reference_quat: np.ndarray) -> np.ndarray:
    """Mean up direction (3,) of reference quaternions (N, 4) (a still pose's truth)."""
    up = up_in_sensor_frame(np.asarray(reference_quat, dtype=np.float64)).reshape(-1, 3)
    mean = up.mean(axis=0)
    return mean / np.linalg.norm(mean)


def compare_poses(
    poses: Sequence[CapturedPose],
    after: SensorCalibration,
    before: SensorCalibration = IDENTITY_CALIBRATION,
    reference: str = "truth",
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
) -> TiltComparison:
    """:func:`compare_tilt` over captured poses.

    ``reference="truth"`` uses each pose's known up direction (``CapturedPose.reference_up``,
    from a source that knows it) and falls back to the nominal face; ``reference="face"``
    always uses the nominal face direction (see the module note on what that measures).
    """
    if reference not in ("truth", "face"):
        raise ValueError(f"reference must be 'truth' or 'face', not {reference!r}")
    ups = []
    for pose in poses:
        if reference == "truth" and pose.reference_up is not None:
            ups.append(pose.reference_up)
        else:
            ups.append(FACE_DIRECTIONS[pose.face])
    return compare_tilt(
        np.array([pose.accel_mean_m_s2 for pose in poses]),
        np.array(ups),
        after,
        before,
        labels=[f"{pose.face} up" for pose in poses],
        gravity_m_s2=gravity_m_s2,
    )
