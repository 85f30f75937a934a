"""The magnetic field as the views show it: its strength, its dip against gravity, and whether
it is disturbed.

Per field sample (rows where the magnetometer delivered one; it runs slower than the
accelerometer):

- ``norm``: ``|m|`` in uT. It does not depend on the orientation, so it is valid in motion.
- ``dip``: the angle between the field and the horizontal plane, positive when the field points
  below it (as the World Magnetic Model's inclination). "Down" is the direction opposite the
  low-passed accelerometer (:data:`GRAVITY_TAU_S`): at rest it measures gravity's reaction,
  pointing up. While the sensor moves the accelerometer is not gravity alone, and a low-pass
  lags a turn, so a dip is given only where the sensor is *steady*: ``|a|`` within
  :data:`STEADY_G_TOLERANCE` of g and the low-passed direction within
  :data:`STEADY_ANGLE_DEG` of the sample's own. Elsewhere it is NaN (refused, not guessed).
  An acceleration held for longer than the low-pass's time reads as a tilt, as it does to any
  attitude from the accelerometer alone.

A :class:`FieldReference` is what the field should read: the local WMM values (place and date,
:func:`wmm_reference`) or values learnt at rest (:func:`learned_reference`).
:func:`check_disturbance` compares samples with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import date, datetime

import numpy as np
from numba import njit

from app.core.earth_field import DEFAULT_PLACE, Place, earth_field
from app.core.samples import STANDARD_GRAVITY_M_S2

GRAVITY_TAU_S = 0.1
"""Time constant of the accelerometer's low-pass that gives gravity's direction: it averages
the accelerometer's noise (about 10 samples at 104 Hz) but lags a turn little."""
STEADY_G_TOLERANCE = 0.03
"""``| |a| - g |`` up to this fraction of g counts as steady (no linear acceleration; an
uncalibrated accelerometer's scale and offset errors stay well under it)."""
STEADY_ANGLE_DEG = 3.0
"""The sample's accelerometer direction within this of the low-passed one counts as steady
(the dip is then off by less than this: well inside the disturbance check's tolerances)."""
WMM_FIELD_TOLERANCE = 0.15
WMM_DIP_TOLERANCE_DEG = 8.0
"""Against the WMM main field: the model holds no local anomaly and a building's steel moves
the field by several uT and degrees indoors, so only a clear departure counts."""
LEARNED_FIELD_TOLERANCE = 0.05
LEARNED_DIP_TOLERANCE_DEG = 3.0
"""Against the field learnt at rest in the same place: a closer check."""


@njit(cache=True)
def _lowpass(t, accel, state, tau):  # pragma: no cover (compiled)
    """Exponential low-pass of (N, 3) ``accel`` with its own time step; state = [x, y, z,
    t_last] (t_last NaN: start from the first sample). Returns the (N, 3) filtered values."""
    n = accel.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        if math.isnan(state[3]) or t[i] <= state[3]:
            state[0], state[1], state[2] = accel[i, 0], accel[i, 1], accel[i, 2]
        else:
            alpha = 1.0 - math.exp(-(t[i] - state[3]) / tau)
            for k in range(3):
                state[k] += alpha * (accel[i, k] - state[k])
        state[3] = t[i]
        out[i, 0], out[i, 1], out[i, 2] = state[0], state[1], state[2]
    return out


def field_norm(mag_ut: np.ndarray) -> np.ndarray:
    """(N, 3) field -> (N,) ``|m|`` in uT (NaN rows stay NaN)."""
    return np.sqrt(np.einsum("ij,ij->i", mag_ut, mag_ut))


def dip_deg(mag_ut: np.ndarray, accel_m_s2: np.ndarray) -> np.ndarray:
    """The field's angle below the horizontal plane normal to ``accel`` (which points up at
    rest), in degrees, positive down; (N,) from (N, 3) each."""
    down = -accel_m_s2 / np.linalg.norm(accel_m_s2, axis=1, keepdims=True)
    vertical = np.einsum("ij,ij->i", mag_ut, down)
    horizontal = np.linalg.norm(mag_ut - vertical[:, None] * down, axis=1)
    return np.degrees(np.arctan2(vertical, horizontal))


@dataclass(frozen=True, slots=True)
class FieldRows:
    """The field samples of one block: time, calibrated field, the accelerometer at the
    same row, its low-passed direction, ``|m|``, dip (NaN where not steady)."""

    t_s: np.ndarray
    mag_ut: np.ndarray
    accel_m_s2: np.ndarray
    norm_ut: np.ndarray
    dip_deg: np.ndarray
    rows: np.ndarray
    """Their row indices in the block."""

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


class FieldMonitor:
    """Turns blocks (time, calibrated accel, calibrated field with NaN rows) into
    :class:`FieldRows`, keeping the low-pass's state between blocks."""

    def __init__(self, tau_s: float = GRAVITY_TAU_S) -> None:
        self.tau_s = float(tau_s)
        self._state = np.full(4, np.nan)

    def reset(self) -> None:
        self._state = np.full(4, np.nan)

    def update(self, t_s: np.ndarray, accel_m_s2: np.ndarray, mag_ut: np.ndarray) -> FieldRows:
        gravity = _lowpass(np.ascontiguousarray(t_s, dtype=np.float64),
                           np.ascontiguousarray(accel_m_s2, dtype=np.float64),
                           self._state, self.tau_s)
        rows = np.flatnonzero(np.isfinite(mag_ut).all(axis=1))
        mag = np.asarray(mag_ut[rows], dtype=np.float64)
        accel = np.asarray(accel_m_s2[rows], dtype=np.float64)
        smooth = gravity[rows]
        with np.errstate(invalid="ignore", divide="ignore"):
            dip = dip_deg(mag, smooth)
            a_norm = np.linalg.norm(accel, axis=1)
            s_norm = np.linalg.norm(smooth, axis=1)
            cosine = np.einsum("ij,ij->i", accel, smooth) / (a_norm * s_norm)
        steady = ((np.abs(a_norm - STANDARD_GRAVITY_M_S2)
                   <= STEADY_G_TOLERANCE * STANDARD_GRAVITY_M_S2)
                  & (cosine >= math.cos(math.radians(STEADY_ANGLE_DEG))))
        dip = np.where(steady, dip, np.nan)
        return FieldRows(np.asarray(t_s[rows], dtype=np.float64), mag, accel,
                         field_norm(mag), dip, rows)


@dataclass(frozen=True, slots=True)
class FieldReference:
    """What the field should read here: strength (uT), dip (degrees, positive down), the
    tolerances a sample may depart by, and where the values came from."""

    total_ut: float
    dip_deg: float
    source: str
    field_tolerance: float = WMM_FIELD_TOLERANCE
    """Fraction of ``total_ut``."""
    dip_tolerance_deg: float = WMM_DIP_TOLERANCE_DEG

    @property
    def field_band_ut(self) -> tuple[float, float]:
        spread = self.field_tolerance * self.total_ut
        return self.total_ut - spread, self.total_ut + spread


def wmm_reference(place: Place = DEFAULT_PLACE, when: date | datetime | float | None = None
                  ) -> FieldReference:
    """The World Magnetic Model's field at ``place`` on ``when`` (default today). Raises
    ValueError for a date outside the model's span."""
    field = earth_field(place, when)
    source = (f"WMM {field.year:.1f} at {place.latitude_deg:.2f}°, "
              f"{place.longitude_deg:.2f}°")
    return FieldReference(field.total_ut, field.dip_deg, source)


def learned_reference(norm_ut: np.ndarray, dip: np.ndarray) -> FieldReference:
    """The field learnt from samples taken at rest (median strength and dip). Raises
    ValueError when there is no steady sample to learn from."""
    norm_ut = np.asarray(norm_ut, dtype=float)
    dip = np.asarray(dip, dtype=float)
    good = np.isfinite(norm_ut) & np.isfinite(dip)
    if not np.any(good):
        raise ValueError("no steady field sample to learn the reference from")
    return FieldReference(float(np.median(norm_ut[good])), float(np.median(dip[good])),
                          f"learnt at rest ({int(np.count_nonzero(good))} samples)",
                          LEARNED_FIELD_TOLERANCE, LEARNED_DIP_TOLERANCE_DEG)


@dataclass(frozen=True, slots=True)
class Disturbance:
    """Which samples depart from the reference, and a line for the user."""

    disturbed: np.ndarray
    """(N,) bool: the strength or (where known) the dip outside the reference's band."""
    fraction: float
    """Share of the samples disturbed (0 without samples)."""
    message: str
    """Empty when none is."""


def check_disturbance(norm_ut: np.ndarray, dip: np.ndarray, reference: FieldReference
                      ) -> Disturbance:
    """Compare field samples (``|m|`` and dip, NaN dip: not known) with ``reference``."""
    norm_ut = np.asarray(norm_ut, dtype=float)
    dip = np.asarray(dip, dtype=float)
    spread = reference.field_tolerance * reference.total_ut
    field_off = np.abs(norm_ut - reference.total_ut) > spread
    with np.errstate(invalid="ignore"):
        dip_off = np.abs(dip - reference.dip_deg) > reference.dip_tolerance_deg
    disturbed = field_off | dip_off
    n = len(disturbed)
    if not n or not np.any(disturbed):
        return Disturbance(disturbed, 0.0, "")
    parts = []
    if np.any(field_off):
        worst = norm_ut[field_off][np.argmax(np.abs(norm_ut[field_off] - reference.total_ut))]
        parts.append(f"|m| {worst:.1f} µT against {reference.total_ut:.1f} µT")
    if np.any(dip_off):
        worst = dip[dip_off][np.argmax(np.abs(dip[dip_off] - reference.dip_deg))]
        parts.append(f"dip {worst:+.1f}° against {reference.dip_deg:+.1f}°")
    fraction = float(np.count_nonzero(disturbed)) / n
    return Disturbance(disturbed, fraction,
                       f"field disturbed in {fraction:.0%} of samples: {'; '.join(parts)} "
                       f"({reference.source})")


REST_MAX_FIELD_SPREAD_UT = 1.0
REST_MAX_DIP_SPREAD_DEG = 1.0
"""Samples learnt from must be this still (standard deviation): the field of a sensor turned
or carried is not a reference."""


def learn_at_rest(norm_ut: np.ndarray, dip: np.ndarray) -> FieldReference:
    """:func:`learned_reference` from samples that must have been taken at rest; raises
    ValueError saying why not (no steady sample, or the field moved)."""
    norm_ut = np.asarray(norm_ut, dtype=float)
    dip = np.asarray(dip, dtype=float)
    good = np.isfinite(norm_ut) & np.isfinite(dip)
    if np.count_nonzero(good) < 2:
        raise ValueError("no steady field sample to learn the reference from: hold the "
                         "sensor still")
    spread_ut, spread_deg = float(np.std(norm_ut[good])), float(np.std(dip[good]))
    if spread_ut > REST_MAX_FIELD_SPREAD_UT or spread_deg > REST_MAX_DIP_SPREAD_DEG:
        raise ValueError(f"the field moved while learning ({spread_ut:.1f} µT, "
                         f"{spread_deg:.1f}° spread): hold the sensor still, away from "
                         f"moving iron")
    return learned_reference(norm_ut, dip)


@dataclass(frozen=True, slots=True)
class ReferenceSettings:
    """Where and when the WMM reference is computed (a user setting): the place, and the
    date (None: today)."""

    place: Place = DEFAULT_PLACE
    when: date | None = None

    def reference(self) -> FieldReference:
        return wmm_reference(self.place, self.when)

    def to_dict(self) -> dict[str, object]:
        return {"latitude_deg": self.place.latitude_deg,
                "longitude_deg": self.place.longitude_deg,
                "altitude_m": self.place.altitude_m,
                "date": None if self.when is None else self.when.isoformat()}

    @classmethod
    def from_dict(cls, value: dict[str, object]) -> ReferenceSettings:
        """Inverse of :meth:`to_dict`; raises ValueError naming what is wrong."""
        numbers = {}
        for key in ("latitude_deg", "longitude_deg", "altitude_m"):
            item = value.get(key, getattr(DEFAULT_PLACE, key))
            if isinstance(item, bool) or not isinstance(item, int | float) \
                    or not math.isfinite(item):
                raise ValueError(f"the field reference's {key!r} is not a number")
            numbers[key] = float(item)
        text = value.get("date")
        when = None
        if text is not None:
            try:
                when = date.fromisoformat(str(text))
            except ValueError:
                raise ValueError(f"the field reference's date {text!r} is not YYYY-MM-DD") \
                    from None
        settings = cls(Place(**numbers), when)
        settings.reference()  # a date outside the model's span is refused now, not later
        return settings
