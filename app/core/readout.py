"""What the instrument displays: angles averaged over a short time window, in a unit.

A tilt meter shows a steady figure, not the last noisy sample. Averaging is done on the up
vector (not on the angles), so it is exact across the +-180 degree wrap. The units
(degrees, % grade, mm/m, in/ft, 1:n) and their texts are here too, so that views only show
what they are given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.orientation import (
    TiltAngles,
    angles_from_up,
    quaternion_from_roll_pitch,
    up_in_sensor_frame,
)
from app.core.quaternion import rotate


def averaged_angles(quat: np.ndarray) -> TiltAngles | None:
    """Angles (floats, degrees) of the mean up direction of quaternions (N, 4); None if empty."""
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    quat = quat[np.all(np.isfinite(quat), axis=1)]
    if len(quat) == 0:
        return None
    mean_up = up_in_sensor_frame(quat).mean(axis=0)
    angles = angles_from_up(mean_up)
    return TiltAngles(*(float(v) for v in (  # type: ignore[arg-type]
        angles.roll_deg, angles.pitch_deg, angles.tilt_deg, angles.direction_deg
    )))


@dataclass(frozen=True, slots=True)
class SlopeUnit:
    """A unit the readouts can show an inclination in."""

    key: str
    title: str  # in a unit menu
    suffix: str  # after the number ("" for a ratio, whose text says what it is)


SLOPE_UNITS: dict[str, SlopeUnit] = {
    unit.key: unit for unit in (
        SlopeUnit("deg", "degrees", "°"),
        SlopeUnit("percent", "% grade", "%"),
        SlopeUnit("mm/m", "mm/m", "mm/m"),
        SlopeUnit("in/ft", "in/ft", "in/ft"),
        SlopeUnit("ratio", "1:n ratio", ""),
    )
}
"""The display units by key, in menu order."""

UNIT_SYMBOLS: dict[str, str] = {"deg": "°", "dps": "°/s", "deg/s": "°/s", "deg/h": "°/h"}
"""How the window writes a parameter's or figure's unit: the degree sign for angles and °/s
for rates (the ASCII names stay in the command line, JSON and recordings)."""


def unit_symbol(unit: str) -> str:
    """``unit`` as the window writes it (:data:`UNIT_SYMBOLS`; any other unit unchanged)."""
    return UNIT_SYMBOLS.get(unit, unit)


RATIO_LIMIT = 10_000.0
"""A ratio flatter than 1:10000 (0.0057°, under the readouts' 0.01 resolution) reads 1:∞."""
LEVEL_RATIO_TEXT = "1:∞"

_TANGENT_SCALE = {"percent": 100.0, "mm/m": 1000.0, "in/ft": 12.0}
SLOPE_LIMIT = 999.995
"""A slope (%, mm/m, in/ft) this steep or steeper reads :data:`OVER_TEXT`: past 45° in
mm/m, 84° in %, 89° in in/ft a levelling unit says little, and its figures would not fit
the readouts (whose widest text is "−999.99")."""
OVER_TEXT = "OVER"


def slope_from_angle(angle_deg: np.ndarray | float, unit: str) -> np.ndarray | float:
    """Express an inclination (degrees) in a levelling unit (a key of :data:`SLOPE_UNITS`).

    ``percent`` (grade), ``mm/m`` and ``in/ft`` are the rise per run; ``ratio`` is n of
    "1 in n" (the run per unit rise), signed like the angle and infinite when level.
    """
    if unit == "deg":
        return angle_deg
    tangent = np.tan(np.radians(angle_deg))
    if unit in _TANGENT_SCALE:
        return _TANGENT_SCALE[unit] * tangent
    if unit == "ratio":
        with np.errstate(divide="ignore"):
            run = np.divide(1.0, tangent)
        # tan(-0.0) is -0.0: 1/-0.0 is -inf; a level reading has no sign.
        run = np.where(tangent == 0.0, np.inf, run)
        return float(run) if np.ndim(run) == 0 else run
    raise ValueError(f"unknown slope unit {unit!r}; use one of {', '.join(SLOPE_UNITS)}")


def format_slope(value: float, unit: str, signed: bool = False) -> str:
    """The text of a value already in ``unit``: two decimals (``+1.23``, ``-0.45``), or for
    a ratio ``1:57.3`` (``-1:57.3`` when signed and negative) with 3 significant figures
    up to 1:9999, and ``1:∞`` flatter than :data:`RATIO_LIMIT`; a slope past
    :data:`SLOPE_LIMIT` reads ``OVER`` (signed like the value). NaN (and other non-finite
    values in degrees) give ``""``. Negative zero is shown as zero."""
    if unit == "ratio":
        if np.isnan(value):
            return ""
        run = abs(float(value))
        if run >= RATIO_LIMIT:
            return LEVEL_RATIO_TEXT
        if run >= 100.0:
            text = f"1:{run:.0f}"
        elif run >= 10.0:
            text = f"1:{run:.1f}"
        else:
            text = f"1:{run:.2f}"
        sign = "-" if value < 0 else "+"
        return f"{sign}{text}" if signed or sign == "-" else text
    if not np.isfinite(value) and unit not in _TANGENT_SCALE:
        return ""
    if np.isnan(value):
        return ""
    if unit in _TANGENT_SCALE and abs(value) >= SLOPE_LIMIT:
        sign = "-" if value < 0 else "+"
        return f"{sign}{OVER_TEXT}" if signed or sign == "-" else OVER_TEXT
    text = f"{value:+.2f}" if signed else f"{value:.2f}"
    if text in ("-0.00", "+0.00"):
        return "+0.00" if signed else "0.00"
    return text


UNDEFINED = "—"
"""The text of a figure that has no meaning (the direction of a level reading)."""


def format_direction(direction_deg: float, tilt_text: str) -> str:
    """The tilt direction as shown: ``123.4`` (one decimal, 360.0 shown as 0.0), or
    :data:`UNDEFINED` when the tilt, as displayed (``tilt_text``, from :func:`format_slope`),
    is level or below the display resolution ("0.00", "1:∞"): the direction of a tilt that
    reads zero is only noise (after a tare it would be a random bearing). ``""`` when
    ``direction_deg`` is not finite (no data)."""
    if not np.isfinite(direction_deg):
        return ""
    if tilt_is_zero(tilt_text):
        return UNDEFINED
    text = f"{direction_deg % 360.0:.1f}"
    return "0.0" if text == "360.0" else text


def tilt_is_zero(tilt_text: str) -> bool:
    """Whether a tilt's displayed text (:func:`format_slope`) reads level: every digit of a
    decimal text is zero, or the ratio is ``1:∞``."""
    if tilt_text == LEVEL_RATIO_TEXT:
        return True
    digits = [c for c in tilt_text if c.isdigit()]
    return bool(digits) and ":" not in tilt_text and not any(c != "0" for c in digits)


@dataclass(frozen=True, slots=True)
class TruthComparison:
    """A simulator's truth over the readouts' averaging window, and how far off the shown
    reading is (degrees)."""

    roll_deg: float
    pitch_deg: float
    reading_error_deg: float
    """Angle between the averaged estimate's and the averaged truth's up directions: the
    error of the figures on the screen."""
    sample_rms_deg: float
    """RMS of the per-sample inclination errors in the same window."""


def compare_to_truth(
    quat: np.ndarray, ref_roll_deg: np.ndarray, ref_pitch_deg: np.ndarray,
    incl_error_deg: np.ndarray, tare_quat: np.ndarray | None = None,
) -> TruthComparison | None:
    """The truth averaged exactly like :func:`averaged_angles` averages the estimate (mean
    up vector over the same rows), so the truth line and the readouts describe the same
    time; None when no row has a truth (not a simulator) or no estimate.

    ``quat`` are the quaternions the readouts show; after a tare they are in the tared frame
    (``tare_quat``, the tare's rotation T: shown = q * conj(T)), and the truth is turned into
    that frame for the reading error. The truth's angles stay the simulator's own."""
    ref_roll = np.asarray(ref_roll_deg, dtype=np.float64).ravel()
    ref_pitch = np.asarray(ref_pitch_deg, dtype=np.float64).ravel()
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    keep = np.isfinite(ref_roll) & np.isfinite(ref_pitch) & np.all(np.isfinite(quat), axis=1)
    if not np.any(keep):
        return None
    truth_up = up_in_sensor_frame(
        quaternion_from_roll_pitch(ref_roll[keep], ref_pitch[keep])).mean(axis=0)
    estimate_up = up_in_sensor_frame(quat[keep]).mean(axis=0)
    truth = angles_from_up(truth_up)
    if tare_quat is not None:
        truth_up = rotate(np.asarray(tare_quat, dtype=np.float64), truth_up)
    cosine = np.dot(truth_up, estimate_up) / (
        np.linalg.norm(truth_up) * np.linalg.norm(estimate_up))
    error = float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))
    errors = np.asarray(incl_error_deg, dtype=np.float64).ravel()[keep]
    errors = errors[np.isfinite(errors)]
    rms = float(np.sqrt(np.mean(errors ** 2))) if len(errors) else float("nan")
    return TruthComparison(float(truth.roll_deg), float(truth.pitch_deg), error, rms)


def reading_text(roll: float, pitch: float, tilt: float, unit: str) -> str:
    """One line for the clipboard, values already in ``unit``: ``Roll 1.23° Pitch -0.45°
    Tilt 1.31°`` (a ratio: ``Roll 1:46.6 ...``)."""
    suffix = SLOPE_UNITS[unit].suffix
    gap = "" if suffix in ("°", "") else " "
    parts = [
        f"{name} {format_slope(value, unit)}{gap}{suffix}"
        for name, value in (("Roll", roll), ("Pitch", pitch), ("Tilt", tilt))
    ]
    return " ".join(parts)
def averaged_angle_deg(angles_deg: np.ndarray) -> float | None:
    """Circular mean (degrees, -180 ... 180) of angles in degrees, NaNs left out; None if empty.

    Averaged on the unit circle like the tilt readout's up vector, so exact across the wrap.
    """
    angles = np.asarray(angles_deg, dtype=np.float64).ravel()
    angles = angles[np.isfinite(angles)]
    if len(angles) == 0:
        return None
    rad = np.radians(angles)
    return float(np.degrees(np.arctan2(np.sin(rad).mean(), np.cos(rad).mean())))
