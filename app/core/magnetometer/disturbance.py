"""Magnetic disturbance detection for a 9-axis filter: is the field the earth's, here?

Steel, magnets and motors near the sensor add their own field. The earth's field, seen from a
sensor that turns, keeps its strength ``|m|`` and its dip below the horizontal; a local field
does not (its strength and direction change as the sensor moves through it, and a field fixed
to the sensor, such as an attached magnet, adds a vector that turns with the sensor). So each
field sample's strength and dip (the dip from the filter's own tilt estimate, valid in motion)
are compared with a *reference*, as VQF does (Laidig & Seel 2023, Information Fusion 91,
sec. 3.4), with the same time constants:

- **Current field**: strength and dip low-passed over :attr:`DisturbanceSettings.current_tau`
  (0.05 s) against noise.
- **Disturbed** when the strength departs from the reference by more than ``norm_threshold``
  (fraction; VQF's 10 % here, the EKF's parameter defaults to 15 %: the band must clear the
  spread of an undisturbed but imperfectly calibrated sensor as it turns) or the dip by more
  than ``dip_threshold_deg``. It clears after
  ``min_undisturbed_s`` inside both bands; then the reference follows the field slowly
  (``ref_tau`` 20 s: the earth's field drifts with the place and the calibration's residual).
- **Rejection**: while disturbed the field is not used and the gyroscope carries the heading,
  for at most ``max_rejection_s`` (60 s); after that the field is used again at a reduced weight
  (``rejection_factor``: its noise variance times the factor squared), since a gyro-only
  heading drifts without bound. Undisturbed time pays the rejection budget back
  ``rejection_factor`` times as fast.
- **Fast re-acquisition** needs no rule of its own in the EKF: while the field is rejected the
  heading's variance grows with the gyro's noise and scale error, so the first undisturbed
  samples carry a large Kalman gain.
- **A new reference** (an attached magnet that becomes a new hard iron, a move to another
  room): a *candidate* follows the current field and restarts whenever the field leaves the
  candidate's bands; time counts towards it only while the sensor turns faster than
  ``new_min_gyro_dps`` (a field fixed to the sensor does not keep its strength and dip while it
  turns, the earth's does). After ``new_time_s`` (20 s) of consistent turning the candidate
  replaces the reference.
- **The first reference** is learnt at rest: the candidate also counts time while the filter's
  rest detector holds, until the first reference is set, provided it agrees with the World
  Magnetic Model's value (:class:`~app.core.field_check.FieldReference`, WMM's tolerances) when
  one is given. ``new_first_time_s`` (5 s) is enough then. Until a reference exists the field is
  used (the heading must come from somewhere) and the status says so.

API (for the window and the EKF)
--------------------------------
``QuaternionEKF.field_status`` (after each ``process``) is a :class:`FieldStatus` for the last
block: per row ``status`` (one of :data:`NO_SAMPLE`, :data:`OK`, :data:`LEARNING`,
:data:`REJECTED`, :data:`REDUCED`), ``norm_deviation`` (fraction, + above the reference),
``dip_deviation_deg`` (+ steeper), plus the current reference (a ``FieldReference``, None until
learnt), and ``reason`` / ``disturbed`` for the last field sample: ``reason`` is a line such as
``"field 23 % above normal"`` or ``"dip 12° steeper than normal"`` (empty when undisturbed).
``QuaternionEKF.set_field_reference(wmm_reference(place, date))`` gives the WMM value to check
the learnt reference against (``FieldStatus.wmm_message`` says when they disagree).
The compiled :func:`detector_step` and the state layout are for the EKF's kernel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from app.core.field_check import FieldReference, check_disturbance

# Status codes per row.
NO_SAMPLE = -1
OK = 0
LEARNING = 1
"""No reference yet: the field is used (it is all there is), not yet checked."""
REJECTED = 2
"""Disturbed: the field is not used, the gyroscope carries the heading."""
REDUCED = 3
"""Disturbed for longer than the rejection time: the field is used at a reduced weight."""

# Layout of the detector's state vector.
S_NORM, S_DIP, S_CURRENT_SET = 0, 1, 2  # current field, low-passed (uT, rad), 1 once set
S_REF_NORM, S_REF_DIP = 3, 4  # the reference (0 uT: none yet)
S_CAND_NORM, S_CAND_DIP, S_CAND_T = 5, 6, 7  # candidate for a new reference
S_UNDISTURBED_T, S_DISTURBED, S_REJECT_T = 8, 9, 10
S_GYRO_LP = 11  # 3: low-passed angular rate (rad/s), for the "turning" test
S_REF_SOURCE = 14  # 0 none, 1 learnt at rest, 2 learnt while turning
N_STATE = 15

# Layout of the settings vector (see DisturbanceSettings.as_array).
(C_NORM_TH, C_DIP_TH, C_REF_TAU, C_NEW_TIME, C_NEW_FIRST_TIME, C_NEW_MIN_GYRO,
 C_MIN_UNDISTURBED, C_MAX_REJECT, C_REJECT_FACTOR, C_CURRENT_TAU, C_WMM_NORM, C_WMM_DIP,
 C_WMM_NORM_TOL, C_WMM_DIP_TOL, C_ENABLED) = range(15)
N_SETTINGS = 15

GYRO_LP_TAU_S = 0.5
"""Time constant of the angular rate's low-pass for the "turning" test (VQF's rest filter)."""


@dataclass(frozen=True, slots=True)
class DisturbanceSettings:
    """The detector's thresholds and time constants (defaults: VQF's)."""

    norm_threshold: float = 0.1
    dip_threshold_deg: float = 10.0
    ref_tau_s: float = 20.0
    new_time_s: float = 20.0
    new_first_time_s: float = 5.0
    new_min_gyro_dps: float = 20.0
    min_undisturbed_s: float = 0.5
    max_rejection_s: float = 60.0
    rejection_factor: float = 2.0
    current_tau_s: float = 0.05
    enabled: bool = True

    def as_array(self, wmm: FieldReference | None = None) -> np.ndarray:
        """The settings vector of :func:`detector_step` (``wmm``: the value a first reference
        learnt at rest must agree with; None: no check)."""
        out = np.zeros(N_SETTINGS)
        out[C_NORM_TH] = self.norm_threshold
        out[C_DIP_TH] = math.radians(self.dip_threshold_deg)
        out[C_REF_TAU] = self.ref_tau_s
        out[C_NEW_TIME] = self.new_time_s
        out[C_NEW_FIRST_TIME] = self.new_first_time_s
        out[C_NEW_MIN_GYRO] = math.radians(self.new_min_gyro_dps)
        out[C_MIN_UNDISTURBED] = self.min_undisturbed_s
        out[C_MAX_REJECT] = self.max_rejection_s
        out[C_REJECT_FACTOR] = self.rejection_factor
        out[C_CURRENT_TAU] = self.current_tau_s
        if wmm is not None:
            out[C_WMM_NORM] = wmm.total_ut
            out[C_WMM_DIP] = math.radians(wmm.dip_deg)
            out[C_WMM_NORM_TOL] = wmm.field_tolerance
            out[C_WMM_DIP_TOL] = math.radians(wmm.dip_tolerance_deg)
        out[C_ENABLED] = 1.0 if self.enabled else 0.0
        return out


def new_state() -> np.ndarray:
    """A detector that has seen nothing."""
    return np.zeros(N_STATE)


@njit(cache=True, inline="always")
def _inside(norm, dip, ref_norm, ref_dip, norm_th, dip_th):  # pragma: no cover - compiled
    return abs(norm - ref_norm) < norm_th * ref_norm and abs(dip - ref_dip) < dip_th


@njit(cache=True)
def track_rate(state, wx, wy, wz, step):  # pragma: no cover - compiled
    """Low-pass the angular rate (every sample; ``step`` 0 restarts it)."""
    if step <= 0.0:
        state[S_GYRO_LP], state[S_GYRO_LP + 1], state[S_GYRO_LP + 2] = wx, wy, wz
        return
    alpha = step / (GYRO_LP_TAU_S + step)
    state[S_GYRO_LP] += alpha * (wx - state[S_GYRO_LP])
    state[S_GYRO_LP + 1] += alpha * (wy - state[S_GYRO_LP + 1])
    state[S_GYRO_LP + 2] += alpha * (wz - state[S_GYRO_LP + 2])


@njit(cache=True, inline="always")
def detector_step(state, settings, norm, dip, step, at_rest):  # pragma: no cover - compiled
    """One field sample (``|m|`` uT, dip rad positive down, ``step`` s since the previous field
    sample, ``at_rest`` the filter's rest detector); returns the status code and leaves the
    rejection's bookkeeping in ``state``."""
    if settings[C_ENABLED] == 0.0:
        return OK
    tau = settings[C_CURRENT_TAU]
    if state[S_CURRENT_SET] == 0.0 or tau <= 0.0 or step <= 0.0:
        state[S_NORM], state[S_DIP] = norm, dip
        state[S_CURRENT_SET] = 1.0
    else:
        alpha = step / (tau + step)
        state[S_NORM] += alpha * (norm - state[S_NORM])
        state[S_DIP] += alpha * (dip - state[S_DIP])
    norm, dip = state[S_NORM], state[S_DIP]
    norm_th, dip_th = settings[C_NORM_TH], settings[C_DIP_TH]
    k_ref = step / (settings[C_REF_TAU] + step) if settings[C_REF_TAU] > 0.0 else 1.0
    have_ref = state[S_REF_NORM] > 0.0
    # -- against the reference ------------------------------------------------------------
    if have_ref and _inside(norm, dip, state[S_REF_NORM], state[S_REF_DIP], norm_th, dip_th):
        state[S_UNDISTURBED_T] += step
        if state[S_UNDISTURBED_T] >= settings[C_MIN_UNDISTURBED]:
            state[S_DISTURBED] = 0.0
            state[S_REF_NORM] += k_ref * (norm - state[S_REF_NORM])
            state[S_REF_DIP] += k_ref * (dip - state[S_REF_DIP])
    else:
        state[S_UNDISTURBED_T] = 0.0
        state[S_DISTURBED] = 1.0
    # -- a candidate for a new reference ----------------------------------------------------
    if state[S_CAND_NORM] > 0.0 and _inside(norm, dip, state[S_CAND_NORM], state[S_CAND_DIP],
                                            norm_th, dip_th):
        rate2 = (state[S_GYRO_LP] ** 2 + state[S_GYRO_LP + 1] ** 2
                 + state[S_GYRO_LP + 2] ** 2)
        turning = rate2 >= settings[C_NEW_MIN_GYRO] ** 2
        wmm_norm = settings[C_WMM_NORM]
        agrees = wmm_norm <= 0.0 or (
            abs(state[S_CAND_NORM] - wmm_norm) <= settings[C_WMM_NORM_TOL] * wmm_norm
            and abs(state[S_CAND_DIP] - settings[C_WMM_DIP]) <= settings[C_WMM_DIP_TOL])
        learning_at_rest = not have_ref and at_rest and agrees
        if turning or learning_at_rest:
            state[S_CAND_T] += step
        state[S_CAND_NORM] += k_ref * (norm - state[S_CAND_NORM])
        state[S_CAND_DIP] += k_ref * (dip - state[S_CAND_DIP])
        if state[S_DISTURBED] != 0.0 and (
                state[S_CAND_T] >= settings[C_NEW_TIME]
                or (not have_ref and state[S_CAND_T] >= settings[C_NEW_FIRST_TIME])):
            state[S_REF_NORM] = state[S_CAND_NORM]
            state[S_REF_DIP] = state[S_CAND_DIP]
            state[S_REF_SOURCE] = 2.0 if turning else 1.0
            state[S_DISTURBED] = 0.0
            state[S_UNDISTURBED_T] = settings[C_MIN_UNDISTURBED]
            have_ref = True
    else:
        state[S_CAND_T] = 0.0
        state[S_CAND_NORM] = norm
        state[S_CAND_DIP] = dip
    # -- rejection --------------------------------------------------------------------------
    if not have_ref:
        return LEARNING
    if state[S_DISTURBED] != 0.0:
        if state[S_REJECT_T] <= settings[C_MAX_REJECT]:
            state[S_REJECT_T] += step
            return REJECTED
        return REDUCED
    state[S_REJECT_T] = max(state[S_REJECT_T] - settings[C_REJECT_FACTOR] * step, 0.0)
    return OK


@dataclass(frozen=True, slots=True)
class FieldStatus:
    """The detector's output for one block (see the module docstring)."""

    status: np.ndarray
    """(N,) int8 per row: NO_SAMPLE, OK, LEARNING, REJECTED or REDUCED."""
    norm_deviation: np.ndarray
    """(N,) the current field's strength against the reference, as a fraction (+: above);
    NaN without a field sample or a reference."""
    dip_deviation_deg: np.ndarray
    """(N,) the current dip against the reference's (+: steeper); NaN likewise."""
    reference: FieldReference | None
    """The reference at the end of the block (its tolerances: the detector's bands)."""
    wmm_message: str = ""
    """Non-empty when the reference departs from the WMM value the filter was given."""

    @property
    def last_row(self) -> int:
        """Index of the block's last field sample, -1 without one."""
        rows = np.flatnonzero(self.status != NO_SAMPLE)
        return int(rows[-1]) if rows.size else -1

    @property
    def disturbed(self) -> bool:
        """The last field sample was disturbed (rejected or used at reduced weight)."""
        row = self.last_row
        return row >= 0 and int(self.status[row]) in (REJECTED, REDUCED)

    @property
    def reason(self) -> str:
        """A line for the user about the last field sample (empty when all is well)."""
        row = self.last_row
        if row < 0:
            return ""
        return describe(int(self.status[row]), float(self.norm_deviation[row]),
                        float(self.dip_deviation_deg[row]), self.reference)


def describe(status: int, norm_deviation: float, dip_deviation_deg: float,
             reference: FieldReference | None) -> str:
    """The reason line for one row, e.g. ``"field 23 % above normal"``."""
    if status == LEARNING:
        return "learning the field: hold the sensor still"
    if status not in (REJECTED, REDUCED):
        return ""
    parts = []
    norm_band = reference.field_tolerance if reference is not None else 0.0
    dip_band = reference.dip_tolerance_deg if reference is not None else 0.0
    if math.isfinite(norm_deviation) and abs(norm_deviation) >= norm_band:
        side = "above" if norm_deviation > 0 else "below"
        parts.append(f"field {abs(norm_deviation) * 100:.0f} % {side} normal")
    if math.isfinite(dip_deviation_deg) and abs(dip_deviation_deg) >= dip_band:
        side = "steeper" if dip_deviation_deg > 0 else "flatter"
        parts.append(f"dip {abs(dip_deviation_deg):.0f}° {side} than normal")
    if not parts:
        parts.append("field settling after a disturbance")
    text = "; ".join(parts)
    if status == REDUCED:
        text += " (long disturbance: heading uses the field at reduced weight)"
    return text


def field_status(rows: np.ndarray, state: np.ndarray, settings: DisturbanceSettings,
                 wmm: FieldReference | None) -> FieldStatus:
    """Build a :class:`FieldStatus` from the kernel's per-row output (N, 3: status, norm
    deviation, dip deviation in rad) and the detector's state after the block."""
    reference = None
    message = ""
    if state[S_REF_NORM] > 0.0:
        how = "at rest" if state[S_REF_SOURCE] == 1.0 else "while turning"
        reference = FieldReference(float(state[S_REF_NORM]),
                                   math.degrees(float(state[S_REF_DIP])), f"learnt {how}",
                                   settings.norm_threshold, settings.dip_threshold_deg)
        if wmm is not None:
            check = check_disturbance(np.array([reference.total_ut]),
                                      np.array([reference.dip_deg]), wmm)
            if check.fraction > 0.0:
                message = "the learnt reference departs from the model: " + check.message
    return FieldStatus(rows[:, 0].astype(np.int8), rows[:, 1].copy(),
                       np.degrees(rows[:, 2]), reference, message)


class DisturbanceOwner:
    """The magnetic-disturbance side of a 9-axis filter that runs :func:`detector_step`:
    its settings from the filter's ``mag_*`` parameters, the WMM check and the last status.
    Mixed into the filters that share the EKF's heading model (``ekf``, ``vqf-heading``)."""

    _values: dict[str, Any]
    _field_reference: FieldReference | None = None
    _field_status: FieldStatus | None = None

    def set_field_reference(self, reference: FieldReference | None) -> None:
        """The World Magnetic Model's field here (``field_check.wmm_reference``): a first
        reference learnt at rest must agree with it; None: no such check."""
        self._field_reference = reference

    def disturbance_settings(self) -> DisturbanceSettings:
        v = self._values
        return DisturbanceSettings(
            norm_threshold=float(v["mag_norm_threshold"]) * 1e-2,
            dip_threshold_deg=float(v["mag_dip_threshold"]),
            max_rejection_s=float(v["mag_rejection_time"]),
            new_time_s=float(v["mag_new_time"]),
            enabled=bool(v["mag_rejection"]),
        )

    @property
    def field_status(self) -> FieldStatus | None:
        """The disturbance detector's output for the last non-empty block (None when it
        carried no field or the magnetometer is switched off)."""
        return self._field_status
