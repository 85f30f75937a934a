"""What the instrument displays: angles averaged over a short time window, in a unit.

A tilt meter shows a steady figure, not the last noisy sample. Averaging is done on the up
vector (not on the angles), so it is exact across the +-180 degree wrap. The units
(degrees, % grade, mm/m, in/ft, 1:n) and their texts are here too, so that views only show
what they are given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.orientation import TiltAngles, angles_from_up, up_in_sensor_frame


def averaged_angles(quat: np.ndarray) -> TiltAngles | None:
    """Angles (floats, degrees) of the mean up direction of quaternions (N, 4); None if empty."""
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    quat = quat[np.all(np.isfinite(quat), axis=1)]
    if len(quat) == 0:
        return None
    mean_up = up_in_sensor_frame(quat).mean(axis=0)
    angles = angles_from_up(mean_up)
    return TiltAngles(*(float(v) for v in (
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

RATIO_LIMIT = 10_000.0
"""A ratio flatter than 1:10000 (0.0057°, under the readouts' 0.01 resolution) reads 1:∞."""
LEVEL_RATIO_TEXT = "1:∞"

_TANGENT_SCALE = {"percent": 100.0, "mm/m": 1000.0, "in/ft": 12.0}


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
    up to 1:9999, and ``1:∞`` flatter than :data:`RATIO_LIMIT`. Non-finite values (other
    than a level ratio) give ``""``. Negative zero is shown as zero."""
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
    if not np.isfinite(value):
        return ""
    text = f"{value:+.2f}" if signed else f"{value:.2f}"
    if text in ("-0.00", "+0.00"):
        return "+0.00" if signed else "0.00"
    return text


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
