"""Magnetometer calibration: hard iron, the full soft-iron matrix and the magnetometer's turn
against the accelerometer.

The model (binding, :class:`app.core.calibration.MagnetometerCalibration`) is
``m = soft_iron (raw - hard_iron)`` in the accelerometer's frame. A field measured at rest
keeps a constant strength ``F`` and a constant angle to gravity (the dip), whatever the
orientation. The peers (PX4, ArduPilot, QGroundControl) use only the first fact: an ellipsoid
fit gives the hard iron and a *symmetric* soft-iron matrix, and leaves any turn between the
magnetometer's axes and the accelerometer's in the heading (:func:`fit_ellipsoid`, kept for
comparison). :func:`fit_magnetometer` uses both, in the spirit of Kok and Schön's maximum
likelihood calibration with inertial sensors (IEEE Sensors J. 2016), in three well-conditioned
steps:

1. an algebraic ellipsoid fit (hard iron, symmetric soft iron), refined geometrically;
2. the turn, in closed form: with ``u`` the sphere-corrected field and ``a`` the unit gravity
   direction of the samples at rest (accelerometer norm near g, and a slow gyroscope when one
   is given), ``a' Q u`` must be constant, which is linear in the 9 entries of ``Q`` and the
   constant: the null vector of that system, projected onto the rotations;
   With a gyroscope and times, the gravity direction is the accelerometer's carried along
   by the gyroscope and averaged forward and backward in time (:func:`smoothed_gravity`), so
   the shaking of a hand tour hardly enters;
3. a joint robust least-squares refinement of all 12 parameters and the dip, the strength
   residuals and the dip residuals weighted by their own noise; samples far off the sphere
   (a disturbance) are dropped and the fit is repeated once.

The overall scale is not observable from a magnetometer alone (the chip's gain and the field's
strength trade against each other): the soft-iron matrix is normalised to determinant 1, so
``field_uT`` is the strength as the chip's own gain sees it, and a strength far from the
local WMM value shows a wrong gain or a disturbed place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from app.core.calibration import MagnetometerCalibration
from app.core.earth_field import EarthField
from app.core.magnetometer.coverage import coverage_mask
from app.core.samples import STANDARD_GRAVITY_M_S2

MIN_FIELD_SAMPLES = 50
"""Fewer field samples are refused (a 10-parameter fit needs many more in practice)."""
MIN_STILL_SAMPLES = 30
"""Fewer samples at rest cannot give the turn against the accelerometer."""
STILL_ACCEL_TOLERANCE = 0.05
"""A sample is at rest when its accelerometer norm is within this fraction of g ..."""
STILL_GYRO_RAD_S = 1.0
"""... and, when a gyroscope is given, it turns slower than this."""
PLANAR_RATIO = 0.15
"""A tour whose thinnest spread is below this fraction of its widest is planar: refused."""
GOOD_COVERAGE = 0.75
"""Below this fraction of the 80 sections the verdict is redo."""
OUTLIER_SIGMAS = 6.0
OUTLIER_FLOOR_FRACTION = 0.02
"""A sample is off the sphere when its strength residual exceeds this many robust standard
deviations and this fraction of the field."""
DISTURBED_FRACTION = 0.01
"""More outliers than this fraction of the samples: a disturbance during the tour."""
MAX_RESIDUAL_UT = 0.7
"""An RMS strength residual above this is redo: twice what the LIS3MDL's and LIS2MDL's own
noise leave in their low-noise modes (about 0.35 uT); more is a disturbance such as a motor."""
FIELD_TOLERANCE = 0.15
"""The fitted strength may differ from the WMM's by this fraction."""
DIP_TOLERANCE_DEG = 5.0
"""The fitted dip may differ from the WMM's by this much."""
MAX_ALIGNMENT_DEG = 10.0
"""A larger turn is no chip's mounting: an axis mapped wrongly."""


@dataclass(frozen=True)
class MagFitResult:
    """A fit's calibration, its verdict (``"good"`` or ``"redo"``) and the reasons for a redo."""

    calibration: MagnetometerCalibration
    verdict: str
    reasons: tuple[str, ...] = ()
    samples_used: int = 0
    still_samples: int = 0
    outliers: int = 0
    notes: tuple[str, ...] = field(default=())
    """Remarks that do not change the verdict (e.g. no accelerometer: no alignment)."""

    @property
    def good(self) -> bool:
        return self.verdict == "good"

    def to_json(self) -> dict[str, object]:
        """The calibration's binding JSON plus ``verdict``, ``reasons``, ``samples_used``."""
        return {**self.calibration.to_json(), "verdict": self.verdict,
                "reasons": list(self.reasons), "notes": list(self.notes),
                "samples_used": self.samples_used, "still_samples": self.still_samples,
                "outliers": self.outliers}


# -- helpers ---------------------------------------------------------------------------------
def _field_rows(mag_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The finite rows of an (N, 3) field and their indices; ValueError for bad input."""
    mag = np.asarray(mag_ut, dtype=np.float64)
    if mag.ndim != 2 or mag.shape[1] != 3:
        raise ValueError(f"the field must be N rows of 3 (mx, my, mz), not shape {mag.shape}")
    rows = np.flatnonzero(np.all(np.isfinite(mag), axis=1))
    if rows.size == 0:
        raise ValueError("no field samples: every mx, my, mz row is empty (NaN)")
    if rows.size < MIN_FIELD_SAMPLES:
        raise ValueError(f"too few field samples: {rows.size}, at least {MIN_FIELD_SAMPLES} "
                         "are needed (turn the sensor through every direction for a minute)")
    return mag[rows], rows


def _check_spread(x: np.ndarray) -> None:
    """Refuse a planar (or linear) tour: its ellipsoid is not determined."""
    centred = x - x.mean(axis=0)
    spread = np.sqrt(np.maximum(np.linalg.eigvalsh(centred.T @ centred / len(x)), 0.0))
    if spread[-1] <= 0:
        raise ValueError("the field never changed during the tour: the sensor was not turned")
    if spread[0] < PLANAR_RATIO * spread[-1]:
        raise ValueError(
            f"the tour is flat: the field moved in a plane (thinnest spread "
            f"{spread[0]:.2g} uT against {spread[-1]:.2g} uT), which leaves the ellipsoid "
            "undetermined; turn the sensor about every axis, not only one")


def _sqrtm_spd(m: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh(m)
    return (v * np.sqrt(w)) @ v.T


def _det_normalised(matrix: np.ndarray) -> tuple[np.ndarray, float]:
    """``matrix / det**(1/3)`` and that scale."""
    scale = float(np.cbrt(np.linalg.det(matrix)))
    return matrix / scale, scale


def _polar_rotation(matrix: np.ndarray) -> np.ndarray:
    """The rotation factor Q of ``matrix = Q P`` (P symmetric positive definite)."""
    u, _, vt = np.linalg.svd(matrix)
    q = u @ vt
    if np.linalg.det(q) < 0:
        u[:, -1] *= -1
        q = u @ vt
    return q


def rotation_angle_deg(rotation: np.ndarray) -> float:
    """The angle of a rotation matrix, degrees."""
    return math.degrees(math.acos(float(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))))


def alignment_deg(soft_iron: np.ndarray) -> float:
    """The turn a soft-iron matrix holds: its polar rotation's angle, degrees."""
    return rotation_angle_deg(_polar_rotation(soft_iron))


def _robust_sigma(r: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


# -- the ellipsoid -----------------------------------------------------------------------------
def _algebraic_ellipsoid(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hard iron and symmetric W with ``|W (x - h)| = 1`` (least squares on the quadric)."""
    mean = x.mean(axis=0)
    scale = float(np.sqrt(np.mean(np.sum((x - mean) ** 2, axis=1))))
    y = (x - mean) / scale
    design = np.column_stack([
        y[:, 0] ** 2, y[:, 1] ** 2, y[:, 2] ** 2, 2 * y[:, 0] * y[:, 1], 2 * y[:, 0] * y[:, 2],
        2 * y[:, 1] * y[:, 2], 2 * y[:, 0], 2 * y[:, 1], 2 * y[:, 2], np.ones(len(y))])
    _, vectors = np.linalg.eigh(design.T @ design)
    p = vectors[:, 0]
    m = np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])
    if np.trace(m) < 0:
        m, p = -m, -p
    eig = np.linalg.eigvalsh(m)
    if eig[0] <= 0:
        raise ValueError("the field samples do not lie on an ellipsoid (a disturbance, or a "
                         "tour too small to fit): no calibration")
    centre = -np.linalg.solve(m, p[6:9])
    k = float(centre @ m @ centre - p[9])
    if k <= 0:
        raise ValueError("the field samples do not lie on an ellipsoid: no calibration")
    w = _sqrtm_spd(m / k) / scale
    return mean + scale * centre, w


def _sym(p: np.ndarray) -> np.ndarray:
    return np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])


def _gauss_newton(residuals_jacobian, start: np.ndarray, robust_scale: float | None = None,
                  iterations: int = 30) -> np.ndarray:
    """Levenberg-Marquardt on the normal equations (few parameters, many residuals), with
    soft-L1 weights (iteratively reweighted) when ``robust_scale`` is given."""
    q = start.astype(np.float64).copy()

    def cost_of(r: np.ndarray) -> float:
        if robust_scale is None:
            return float(r @ r)
        z = (r / robust_scale) ** 2
        return float(np.sum(2.0 * (np.sqrt(1.0 + z) - 1.0)))

    r, jac = residuals_jacobian(q)
    cost = cost_of(r)
    damping = 1e-6
    for _ in range(iterations):
        weights = (np.ones_like(r) if robust_scale is None
                   else 1.0 / np.sqrt(1.0 + (r / robust_scale) ** 2))
        jw = jac * weights[:, None]
        normal = jw.T @ jac
        gradient = jw.T @ r
        improved = False
        for _ in range(10):
            step = np.linalg.solve(normal + damping * np.diag(np.diag(normal)), -gradient)
            trial = q + step
            r_new, jac_new = residuals_jacobian(trial)
            new_cost = cost_of(r_new)
            if np.isfinite(new_cost) and new_cost <= cost:
                q, r, jac = trial, r_new, jac_new
                improved = cost - new_cost > 1e-10 * max(cost, 1e-30)
                cost = new_cost
                damping = max(damping / 10.0, 1e-9)
                break
            damping *= 10.0
        if not improved or np.max(np.abs(step)) < 1e-10 * (1.0 + np.max(np.abs(q))):
            break
    return q


def _strength_terms(d: np.ndarray, matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
    """``|L d|``, d|L d|/dL (N, 9, row-major) and d|L d|/dh (N, 3) for ``d = x - h``."""
    v = d @ matrix.T
    n = np.linalg.norm(v, axis=1)
    unit = v / n[:, None]
    d_matrix = np.einsum("ni,nj->nij", unit, d).reshape(-1, 9)
    return n, d_matrix, -unit @ matrix


_SYM_INDEX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _refine_sphere(x: np.ndarray, hard: np.ndarray, w: np.ndarray) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """Geometric refinement of hard iron and symmetric W: ``|W (x - h)| - 1`` least squares
    (what the peers' Levenberg-Marquardt fits minimise)."""

    def residuals_jacobian(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, d_full, d_hard = _strength_terms(x - q[:3], _sym(q[3:]))
        g = d_full.reshape(-1, 3, 3)
        d_sym = np.column_stack([g[:, i, j] if i == j else g[:, i, j] + g[:, j, i]
                                 for i, j in _SYM_INDEX])
        return n - 1.0, np.column_stack([d_hard, d_sym])

    start = np.concatenate([hard, [w[i, j] for i, j in _SYM_INDEX]])
    q = _gauss_newton(residuals_jacobian, start)
    return q[:3], _sym(q[3:])


def _ellipsoid(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Hard iron, symmetric soft iron of determinant 1, field strength."""
    hard, w = _algebraic_ellipsoid(x)
    hard, w = _refine_sphere(x, hard, w)
    if np.any(np.linalg.eigvalsh(w) <= 0):
        raise ValueError("the field samples do not lie on an ellipsoid: no calibration")
    soft, scale = _det_normalised(w)
    return hard, soft, 1.0 / scale


SPHERE_TRIM_FRACTION = 0.1
"""Before the ellipsoid, samples further than this fraction of the radius (or 6 robust
standard deviations) off a sphere are set aside: soft iron of a few % stays inside, a magnet
passing by does not."""


def _sphere_keep(x: np.ndarray, rounds: int = 6) -> np.ndarray:
    """Samples on a robustly fitted sphere (linear fit, trimmed and repeated): a strong
    disturbance must not drag the ellipsoid's start away."""
    keep = np.ones(len(x), dtype=bool)
    for _ in range(rounds):
        xs = x[keep]
        design = np.column_stack([2.0 * xs, np.ones(len(xs))])
        solution, *_ = np.linalg.lstsq(design, np.einsum("ij,ij->i", xs, xs), rcond=None)
        centre = solution[:3]
        radius = np.linalg.norm(x - centre, axis=1)
        middle = float(np.median(radius[keep]))
        limit = max(OUTLIER_SIGMAS * _robust_sigma(radius[keep]),
                    SPHERE_TRIM_FRACTION * middle)
        new = np.abs(radius - middle) <= limit
        if np.count_nonzero(new) < MIN_FIELD_SAMPLES or np.array_equal(new, keep):
            break
        keep = new
    return keep


def fit_ellipsoid(mag_ut: np.ndarray) -> MagnetometerCalibration:
    """The peers' fit: hard iron and a symmetric soft-iron matrix (offsets, scales, symmetric
    cross terms), no turn against the accelerometer. Raises ValueError like
    :func:`fit_magnetometer`."""
    x, _ = _field_rows(mag_ut)
    _check_spread(x)
    hard, soft, strength = _ellipsoid(x)
    m = (x - hard) @ soft.T
    residual = np.linalg.norm(m, axis=1) - strength
    return MagnetometerCalibration(
        hard_iron_ut=hard, soft_iron=soft, field_ut=strength,
        fitness_ut=float(np.sqrt(np.mean(residual ** 2))),
        coverage=float(np.count_nonzero(coverage_mask(m))) / 80.0,
        extra={"alignment_deg": 0.0, "method": "ellipsoid"})


# -- the turn ------------------------------------------------------------------------------------
def _closed_form_turn(u: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The rotation Q that makes ``a_i . Q u_i`` most nearly constant (u sphere-corrected
    field, a unit gravity directions)."""
    design = np.column_stack([np.einsum("ni,nj->nij", a, u).reshape(-1, 9), -np.ones(len(u))])
    norms = np.linalg.norm(design, axis=0).clip(1e-12)
    _, vectors = np.linalg.eigh((design / norms).T @ (design / norms))
    q = (vectors[:, 0] / norms)[:9].reshape(3, 3)
    if np.linalg.det(q) < 0:
        q = -q
    return _polar_rotation(q)


def _still_rows(accel: np.ndarray, gyro: np.ndarray | None) -> np.ndarray:
    """Rows at rest: accelerometer norm near g (and a slow gyroscope when given)."""
    norm = np.linalg.norm(accel, axis=1)
    still = np.abs(norm - STANDARD_GRAVITY_M_S2) < STILL_ACCEL_TOLERANCE * STANDARD_GRAVITY_M_S2
    if gyro is not None:
        still &= np.linalg.norm(gyro, axis=1) < STILL_GYRO_RAD_S
    return still & np.all(np.isfinite(accel), axis=1)


GRAVITY_TIME_CONSTANT_S = 5.0
"""The gyroscope-aided gravity direction trusts the accelerometer over this time."""
GYRO_DISAGREEMENT_DEG = 5.0
"""A gyroscope-carried gravity further than this (median) from the accelerometer's is not
used (a saturated, unsynchronised or wrongly mapped gyroscope)."""
MAX_STEP_S = 0.1
"""A longer step between rows (a gap) restarts the gravity filter."""


def rotation_matrices(w: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations for rotation vectors (N, 3) (Rodrigues, vectorised)."""
    w = np.asarray(w, dtype=np.float64).reshape(-1, 3)
    angle = np.linalg.norm(w, axis=1)
    k = w / np.where(angle > 0, angle, 1.0)[:, None]
    kx = np.zeros((len(w), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx[:, 1, 0], kx[:, 2, 0], kx[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    return (np.eye(3) + np.sin(angle)[:, None, None] * kx
            + (1.0 - np.cos(angle))[:, None, None] * (kx @ kx))


BIAS_WINDOW_S = 0.1
"""The span over which :func:`gyro_bias_from_tilt` compares the gyroscope with the accelerometer."""


def gyro_bias_from_tilt(accel_m_s2: np.ndarray, gyro_rad_s: np.ndarray, t_s: np.ndarray,
                        window_s: float = BIAS_WINDOW_S) -> np.ndarray:
    """The gyroscope's bias (3,) as the accelerometer's direction sees it during a tour.

    A fixed direction turns in the sensor frame as ``da/dt = -w x a``; over a short window
    the accelerometer's direction change plus the gyroscope's integral of ``w x a`` leaves
    ``b x (integral of a dt)``, linear in the bias ``b``: a least-squares fit over every
    window. (A bias about gravity is not seen in one window, but a tour through every
    orientation sees every axis.) Zero when nothing is left to fit."""
    accel = np.asarray(accel_m_s2, dtype=np.float64)
    gyro = np.asarray(gyro_rad_s, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    n = len(t)
    if n < 3:
        return np.zeros(3)
    unit = accel / np.linalg.norm(accel, axis=1, keepdims=True)
    dts = np.diff(t)
    typical = float(np.median(dts)) if np.all(np.isfinite(dts)) else math.nan
    if not typical > 0:
        return np.zeros(3)
    lag = max(1, round(window_s / typical))
    if n <= lag:
        return np.zeros(3)
    cross = np.cross(gyro, unit)
    # trapezoids of w x a and of a, per step, then sums over ``lag`` steps by cumulative sums
    step_cross = 0.5 * (cross[1:] + cross[:-1]) * dts[:, None]
    step_unit = 0.5 * (unit[1:] + unit[:-1]) * dts[:, None]
    ok_step = (np.all(np.isfinite(step_cross), axis=1) & np.all(np.isfinite(step_unit), axis=1)
               & (dts > 0) & (dts <= MAX_STEP_S))
    step_cross[~ok_step] = 0.0
    step_unit[~ok_step] = 0.0

    def window_sum(values: np.ndarray) -> np.ndarray:
        total = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
        return total[lag:] - total[:-lag]

    sum_cross = window_sum(step_cross)
    sum_unit = window_sum(step_unit)
    whole = window_sum(ok_step[:, None].astype(np.float64))[:, 0] == lag
    change = unit[lag:] - unit[:-lag]
    # change = -(sum (w - b) x a dt) = -sum_cross + b x sum_unit = -sum_cross - [sum_unit]x b
    rhs = change + sum_cross
    ok = whole & np.all(np.isfinite(rhs), axis=1)
    if np.count_nonzero(ok) < 10:
        return np.zeros(3)
    s = sum_unit[ok]
    design = np.zeros((len(s), 3, 3))
    design[:, 0, 1], design[:, 0, 2], design[:, 1, 2] = s[:, 2], -s[:, 1], s[:, 0]
    design[:, 1, 0], design[:, 2, 0], design[:, 2, 1] = -s[:, 2], s[:, 1], -s[:, 0]
    solution, *_ = np.linalg.lstsq(design.reshape(-1, 3), rhs[ok].reshape(-1), rcond=None)
    return solution


def smoothed_gravity(accel_m_s2: np.ndarray, gyro_rad_s: np.ndarray, t_s: np.ndarray,
                     time_constant_s: float = GRAVITY_TIME_CONSTANT_S) -> np.ndarray:
    """(N, 3) unit 'up' directions in the sensor frame: the accelerometer's direction carried
    along by the gyroscope and pulled toward the accelerometer over ``time_constant_s``, run
    forward and backward in time and averaged (the gyroscope's bias pulls the two runs in
    opposite directions; the shaking of a hand averages out). The gyroscope shares the
    accelerometer's chip, so its axes are the accelerometer's. A step longer than
    ``MAX_STEP_S`` (a gap) restarts both runs there."""
    accel = np.asarray(accel_m_s2, dtype=np.float64)
    gyro = np.asarray(gyro_rad_s, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    norm = np.linalg.norm(accel, axis=1)
    unit = accel / np.where(norm > 0, norm, np.nan)[:, None]
    dts = np.diff(t)
    joined = ((dts > 0) & (dts <= MAX_STEP_S) & np.all(np.isfinite(gyro[:-1]), axis=1)
              & np.all(np.isfinite(gyro[1:]), axis=1))
    # E_k turns row k's axes into row k+1's: a fixed vector's coordinates go by E_k^T.
    rates = np.where(joined[:, None], 0.5 * (gyro[:-1] + gyro[1:]), 0.0)
    steps = rotation_matrices(rates * np.where(joined, dts, 0.0)[:, None])
    alphas = np.where(joined, dts, 0.0) / (time_constant_s + np.where(joined, dts, 0.0))
    valid = np.all(np.isfinite(unit), axis=1)
    forward = _carry(unit, valid, steps, alphas, joined, True)
    backward = _carry(unit, valid, steps, alphas, joined, False)
    both = forward + backward
    return both / np.linalg.norm(both, axis=1, keepdims=True)


@njit(cache=True)
def _carry(unit: np.ndarray, valid: np.ndarray, steps: np.ndarray, alphas: np.ndarray,
           joined: np.ndarray, forward: bool) -> np.ndarray:  # pragma: no cover (compiled)
    """One run of :func:`smoothed_gravity`'s filter, forward or backward in time."""
    n = unit.shape[0]
    out = np.full((n, 3), np.nan)
    current = np.zeros(3)
    have = False
    for i in range(n):
        k = i if forward else n - 1 - i
        link = k - 1 if forward else k  # the step between k and the row before it in the run
        if have and 0 <= link < n - 1 and joined[link]:
            e = steps[link]
            moved = np.zeros(3)
            for r in range(3):
                for c in range(3):
                    moved[r] += (e[c, r] if forward else e[r, c]) * current[c]
            current = moved
            if valid[k]:
                alpha = alphas[link]
                current = (1.0 - alpha) * current + alpha * unit[k]
                current = current / np.sqrt(np.sum(current * current))
        elif valid[k]:
            current = unit[k].copy()
            have = True
        else:
            have = False
        if have:
            out[k] = current
    return out


TURN_WINDOW_S = 0.2
"""The span between the two field samples the gyroscope's turn links."""


def gyro_pairs(rows: np.ndarray, gyro_rad_s: np.ndarray, t_s: np.ndarray,
               window_s: float = TURN_WINDOW_S) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Field samples about ``window_s`` apart, linked by the gyroscope's turn between them:
    ``(i, j, P)`` with ``i``, ``j`` indices into ``rows`` (the rows with a field sample) and
    ``P`` (M, 3, 3) carrying a fixed vector's sensor coordinates from row ``rows[i]`` to
    ``rows[j]``. Steps across a gap are never bridged."""
    gyro = np.asarray(gyro_rad_s, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3, 3)))
    if len(t) < 3 or len(rows) < 2:
        return empty
    dts = np.diff(t)
    typical = float(np.median(dts))
    if not typical > 0:
        return empty
    lag = max(1, round(window_s / typical))
    joined = ((dts > 0) & (dts <= MAX_STEP_S) & np.all(np.isfinite(gyro[:-1]), axis=1)
              & np.all(np.isfinite(gyro[1:]), axis=1))
    rates = np.where(joined[:, None], 0.5 * (gyro[:-1] + gyro[1:]), 0.0)
    steps = rotation_matrices(rates * np.where(joined, dts, 0.0)[:, None])
    targets = rows + lag
    j = np.searchsorted(rows, targets)
    found = (j < len(rows)) & (targets < len(t))
    found[found] &= rows[j[found]] == targets[found]
    first = np.flatnonzero(found)
    if first.size == 0:
        return empty
    second = j[first]
    start_rows = rows[first]
    broken = np.concatenate([[0], np.cumsum(~joined)])
    whole = broken[start_rows + lag] - broken[start_rows] == 0
    first, second, start_rows = first[whole], second[whole], start_rows[whole]
    carried = np.broadcast_to(np.eye(3), (len(first), 3, 3)).copy()
    for offset in range(lag):
        carried = np.transpose(steps[start_rows + offset], (0, 2, 1)) @ carried
    return first, second, carried


def _joint(x: np.ndarray, hard: np.ndarray, matrix: np.ndarray, strength: float,
           still: np.ndarray, a: np.ndarray, sin_dip: float,
           pairs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
           dip_correlation: float = 1.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Robust joint least squares over hard iron, the full matrix and the dip.

    Residuals: ``|L (x - h)| - F`` on every sample, ``a . L (x - h) + F sin(dip)`` on the
    samples at rest, and, with ``pairs`` ``(i, j, P)`` from the gyroscope,
    ``L (x_j - h) - P L (x_i - h)`` (the calibrated field must turn as the gyroscope says);
    each divided by its robust noise from the start values, the dip's also by the square root
    of ``dip_correlation`` (how many rows its errors stay alike: a smoothed gravity's errors
    are no longer independent from row to row). F is held (the scale is fixed afterwards by
    det = 1)."""
    xs = x[still]
    count = len(x)

    def turning(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        assert pairs is not None
        first, second, carried = pairs
        h, lmat, _ = split(q)
        d1, d2 = x[first] - h, x[second] - h
        residual = d2 @ lmat.T - np.einsum("nij,nj->ni", carried, d1 @ lmat.T)
        jac_l = (np.einsum("ia,nb->niab", np.eye(3), d2)
                 - np.einsum("nia,nb->niab", carried, d1)).reshape(-1, 3, 9)
        jac_h = -lmat + carried @ lmat
        jac = np.concatenate([jac_h, jac_l, np.zeros((len(first), 3, 1))], axis=2)
        return residual.reshape(-1), jac.reshape(-1, 13)

    def split(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        return q[:3], q[3:12].reshape(3, 3), float(q[12])

    def parts(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        h, lmat, s = split(q)
        n, d_full, d_hard = _strength_terms(x - h, lmat)
        jac_strength = np.column_stack([d_hard, d_full, np.zeros(count)])
        dip_r = np.einsum("ij,ij->i", (xs - h) @ lmat.T, a) + strength * s
        jac_dip = np.column_stack([-a @ lmat, np.einsum("ni,nj->nij", a, xs - h).reshape(-1, 9),
                                   np.full(len(xs), strength)])
        return n - strength, jac_strength, dip_r, jac_dip

    start = np.concatenate([hard, matrix.ravel(), [sin_dip]])
    r_strength, _, r_dip, _ = parts(start)
    sigma_strength = max(_robust_sigma(r_strength), 1e-3 * strength)
    sigma_dip = max(_robust_sigma(r_dip), 1e-3 * strength) * math.sqrt(dip_correlation)
    sigma_turn = 1.0
    if pairs is not None:
        sigma_turn = max(_robust_sigma(turning(start)[0]), 1e-3 * strength)

    def residuals_jacobian(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rs, js, rd, jd = parts(q)
        residual = [rs / sigma_strength, rd / sigma_dip]
        jacobian = [js / sigma_strength, jd / sigma_dip]
        if pairs is not None:
            rt, jt = turning(q)
            residual.append(rt / sigma_turn)
            jacobian.append(jt / sigma_turn)
        return np.concatenate(residual), np.vstack(jacobian)

    return split(_gauss_newton(residuals_jacobian, start, robust_scale=3.0))


def fit_magnetometer(mag_ut: np.ndarray, accel_m_s2: np.ndarray | None = None, *,
                     t_s: np.ndarray | None = None, gyro_rad_s: np.ndarray | None = None,
                     expected: EarthField | None = None) -> MagFitResult:
    """Calibrate the magnetometer from a tour through every direction.

    ``mag_ut`` (N, 3) raw field in uT, NaN rows where no field sample arrived;
    ``accel_m_s2`` (N, 3) the accelerometer on the same rows (without it there is no turn:
    the result is the ellipsoid fit, said in ``notes``); ``gyro_rad_s`` (N, 3) optional, to
    keep only slowly turning samples for the gravity direction; ``t_s`` optional, to name
    when a disturbance happened; ``expected`` the local WMM field, for the verdict.

    Raises ValueError (with the reason) for NaN-only input, too few field samples, a flat
    tour or samples that fit no ellipsoid.
    """
    x, rows = _field_rows(mag_ut)
    _check_spread(x)
    reasons: list[str] = []
    notes: list[str] = []
    accel = gyro = up = pairs_all = None
    dip_correlation = 1.0
    if accel_m_s2 is not None:
        accel = np.asarray(accel_m_s2, dtype=np.float64)
        if accel.shape != np.shape(mag_ut):
            raise ValueError(f"the accelerometer's shape {accel.shape} does not match the "
                             f"field's {np.shape(mag_ut)}")
    if gyro_rad_s is not None:
        gyro = np.asarray(gyro_rad_s, dtype=np.float64)
        if gyro.shape != np.shape(mag_ut):
            raise ValueError(f"the gyroscope's shape {gyro.shape} does not match the "
                             f"field's {np.shape(mag_ut)}")
    times = None if t_s is None else np.asarray(t_s, dtype=np.float64)
    if times is not None and times.shape != (np.shape(mag_ut)[0],):
        raise ValueError(f"t_s has shape {times.shape}, not ({np.shape(mag_ut)[0]},)")
    if accel is not None:
        if gyro is not None and times is not None:
            bias = gyro_bias_from_tilt(accel, gyro, times)
            up = smoothed_gravity(accel, gyro - bias, times, GRAVITY_TIME_CONSTANT_S)[rows]
            direct = accel[rows] / np.linalg.norm(accel[rows], axis=1, keepdims=True)
            apart = np.degrees(np.arccos(np.clip(np.sum(up * direct, axis=1), -1.0, 1.0)))
            if np.nanmedian(apart) > GYRO_DISAGREEMENT_DEG:
                notes.append(f"the gyroscope does not follow the accelerometer (their gravity "
                             f"directions differ by {np.nanmedian(apart):.1f} deg in the "
                             "median): gravity from the accelerometer alone")
                up = direct
            else:
                step = float(np.median(np.diff(np.asarray(t_s, float))))
                dip_correlation = max(1.0, GRAVITY_TIME_CONSTANT_S / step) if step > 0 else 1.0
                pairs_all = gyro_pairs(rows, np.asarray(gyro_rad_s, float) - bias,
                                       np.asarray(t_s, float))
            gyro = None  # the gyroscope has done its part: a fast turn no longer matters
        else:
            norm = np.linalg.norm(accel, axis=1, keepdims=True)
            up = (accel / np.where(norm > 0, norm, np.nan))[rows]
        accel = accel[rows]
        gyro = None if gyro is None else gyro[rows]
    times = None if times is None else times[rows]

    keep = _sphere_keep(x)
    hard, soft, strength = _ellipsoid(x[keep])
    matrix, sin_dip, method = soft, math.nan, "ellipsoid"
    still_count = 0
    if accel is None:
        notes.append("no accelerometer: the turn between the magnetometer's axes and the "
                     "accelerometer's was not estimated (plain ellipsoid fit)")
    for round_ in range(3):  # fit, drop the samples off the sphere, fit again
        xk = x[keep]
        if round_ > 0:
            hard, soft, strength = _ellipsoid(xk)
            if method == "ellipsoid":
                matrix = soft
        if accel is None:
            still = np.zeros(len(xk), dtype=bool)
        else:
            still = _still_rows(accel[keep], None if gyro is None else gyro[keep])
            still &= np.all(np.isfinite(up[keep]), axis=1)
        still_count = int(np.count_nonzero(still))
        if accel is not None and still_count >= MIN_STILL_SAMPLES:
            a = up[keep][still]
            spread = np.linalg.eigvalsh(np.cov(a.T))
            if spread[0] < 0.01:
                reasons.append("the gravity direction hardly changed during the tour, so the "
                               "turn against the accelerometer cannot be found: tilt the "
                               "sensor in every direction, not only turn it about one axis")
                break
            u = (xk[still] - hard) @ soft.T
            turn = _closed_form_turn(u, a)
            start = turn @ soft
            sin_dip = float(-np.median(np.einsum("ij,ij->i", u @ turn.T, a)) / strength)
            pairs = None
            if pairs_all is not None and len(pairs_all[0]) >= MIN_STILL_SAMPLES:
                first, second, carried = pairs_all
                both = keep[first] & keep[second]
                position = np.cumsum(keep) - 1
                pairs = (position[first[both]], position[second[both]], carried[both])
            hard, full, sin_dip = _joint(xk, hard, start, strength, still, a, sin_dip, pairs,
                                         dip_correlation)
            matrix, scale = _det_normalised(full)
            strength = strength / scale
            method = ("ellipsoid + gravity + gyroscope (joint)" if pairs is not None
                      else "ellipsoid + gravity (joint)")
        elif accel is not None:
            reasons.append(f"too few samples at rest ({still_count}, at least "
                           f"{MIN_STILL_SAMPLES}) to find the turn against the accelerometer: "
                           "pause now and then while turning the sensor")
            break
        m = (x - hard) @ matrix.T
        residual = np.linalg.norm(m, axis=1) - strength
        sigma = _robust_sigma(residual[keep])
        limit = max(OUTLIER_SIGMAS * sigma, OUTLIER_FLOOR_FRACTION * strength)
        outside = np.abs(residual) > limit
        if not outside.any() or (~outside).sum() < MIN_FIELD_SAMPLES:
            break
        if np.array_equal(keep, ~outside):
            break
        keep = ~outside

    m = (x - hard) @ matrix.T
    residual = np.linalg.norm(m, axis=1) - strength
    outliers = int(np.count_nonzero(~keep))
    fitness = float(np.sqrt(np.mean(residual[keep] ** 2)))
    coverage = float(np.count_nonzero(coverage_mask(m[keep]))) / 80.0
    dip = math.degrees(math.asin(float(np.clip(sin_dip, -1, 1)))) if math.isfinite(
        sin_dip) else math.nan
    turn_deg = alignment_deg(matrix) if method != "ellipsoid" else 0.0

    if coverage < GOOD_COVERAGE:
        reasons.append(f"too little coverage: the tour reached {coverage:.0%} of the sphere's "
                       f"80 sections (at least {GOOD_COVERAGE:.0%} are needed); turn the "
                       "sensor through every direction")
    if outliers > DISTURBED_FRACTION * len(x):
        worst = int(np.argmax(np.abs(residual)))
        when = "" if times is None else f", the worst at t = {times[worst]:.1f} s"
        reasons.append(f"a disturbance during the tour: the field's strength left the fitted "
                       f"sphere on {outliers} samples ({outliers / len(x):.1%}) by up to "
                       f"{abs(residual[worst]):.1f} uT{when} (a magnet, steel or a motor "
                       "nearby?); those samples were left out")
    if fitness > MAX_RESIDUAL_UT:
        reasons.append(f"the fit's residual is large: {fitness:.2f} uT RMS (more than "
                       f"{MAX_RESIDUAL_UT:g} uT, twice the chip's own noise): a disturbance "
                       "(a motor nearby?), or a field "
                       "that changed during the tour")
    if expected is not None:
        if abs(strength - expected.total_ut) > FIELD_TOLERANCE * expected.total_ut:
            reasons.append(f"the field is far from the local WMM value: {strength:.1f} uT "
                           f"against {expected.total_ut:.1f} uT (more than "
                           f"{FIELD_TOLERANCE:.0%} off): iron nearby, or a wrong gain")
        if math.isfinite(dip) and abs(dip - expected.dip_deg) > DIP_TOLERANCE_DEG:
            reasons.append(f"the dip is far from the local WMM value: {dip:.1f} deg against "
                           f"{expected.dip_deg:.1f} deg (more than {DIP_TOLERANCE_DEG:g} "
                           "deg off): iron nearby")
    if turn_deg > MAX_ALIGNMENT_DEG:
        reasons.append(f"the magnetometer's axes are turned by {turn_deg:.1f} deg against "
                       f"the accelerometer's, more than a chip's mounting "
                       f"({MAX_ALIGNMENT_DEG:g} deg): check the axis mapping")
    calibration = MagnetometerCalibration(
        hard_iron_ut=hard, soft_iron=matrix, field_ut=strength, dip_deg=dip,
        fitness_ut=fitness, coverage=coverage,
        extra={"alignment_deg": turn_deg if method != "ellipsoid" else None,
               "method": method})
    return MagFitResult(calibration, "redo" if reasons else "good", tuple(reasons),
                        samples_used=int(np.count_nonzero(keep)), still_samples=still_count,
                        outliers=outliers, notes=tuple(notes))
