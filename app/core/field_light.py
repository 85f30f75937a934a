"""The window's magnetic disturbance light: one state and a short reason, from the field's
strength and dip over the newest samples against a reference (:mod:`app.core.field_check`).

The light's input is this small dataclass, so the detector behind it can change (a filter's
own disturbance detector may feed it later) without the widget knowing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.field_check import FieldReference, check_disturbance

NO_FIELD = "no field"
NO_REFERENCE = "no reference"
CLEAN = "ok"
DISTURBED = "disturbed"


@dataclass(frozen=True, slots=True)
class FieldLight:
    """What the disturbance light shows."""

    state: str
    """:data:`CLEAN`, :data:`DISTURBED`, :data:`NO_FIELD` (no magnetometer) or
    :data:`NO_REFERENCE` (nothing to compare with)."""
    reason: str = ""
    """Why it is disturbed, e.g. ``field 23 % above normal · dip 9° off``; empty otherwise."""
    reference: str = ""
    """What the field was compared with (the reference's source)."""

    @property
    def disturbed(self) -> bool:
        return self.state == DISTURBED


UNCALIBRATED_NOTE = "magnetometer not calibrated"
"""Added to the reason when the field has no calibration: a board's own hard iron alone turns
the dip by tens of degrees, so the cause may be the sensor, not its surroundings."""


def field_light(norm_ut: np.ndarray, dip_deg: np.ndarray, reference: FieldReference | None,
                calibrated: bool = True) -> FieldLight:
    """The light for the newest field samples (``|m|`` in uT and dip in degrees, NaN dip: not
    known): disturbed when any of them departs from ``reference`` by more than its tolerances,
    with the largest departure of each kind as the reason (and :data:`UNCALIBRATED_NOTE` when
    not ``calibrated``)."""
    norm_ut = np.asarray(norm_ut, dtype=float).ravel()
    dip_deg = np.asarray(dip_deg, dtype=float).ravel()
    if not len(norm_ut):
        return FieldLight(NO_FIELD)
    if reference is None:
        return FieldLight(NO_REFERENCE)
    check = check_disturbance(norm_ut, dip_deg, reference)
    if not np.any(check.disturbed):
        return FieldLight(CLEAN, "", reference.source)
    parts = []
    spread = reference.field_tolerance * reference.total_ut
    off = np.abs(norm_ut - reference.total_ut)
    if np.any(off > spread):
        worst = norm_ut[int(np.nanargmax(off))]
        percent = (worst / reference.total_ut - 1.0) * 100.0
        parts.append(f"field {abs(percent):.0f} % {'above' if percent > 0 else 'below'} normal")
    with np.errstate(invalid="ignore"):
        dip_off = np.abs(dip_deg - reference.dip_deg)
    if np.any(dip_off > reference.dip_tolerance_deg):
        parts.append(f"dip {float(np.nanmax(dip_off)):.0f}° off")
    if not calibrated:
        parts.append(UNCALIBRATED_NOTE)
    return FieldLight(DISTURBED, " · ".join(parts), reference.source)
