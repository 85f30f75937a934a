"""Hinge-axis estimation from two gyroscopes (the kinematic constraint of Seel et al. 2012).

For a hinge joint with axis ``j1`` in sensor 1's frame and ``j2`` in sensor 2's, the angular
velocity of either link differs from the other's only along the axis, so its part
perpendicular to the axis has the same length seen from both sensors::

    || w1 x j1 || = || w2 x j2 ||        for every sample

T. Seel, T. Schauer, J. Raisch, "Joint axis and position estimation from inertial measurement
data by exploiting kinematic constraints", IEEE CCA 2012; F. Olsson et al., "Accelerometer
and gyroscope based joint axis estimation", Sensors 20 (2020). :func:`estimate_hinge_axes`
minimises the squared residuals over the two unit vectors by Gauss-Newton (Levenberg-Marquardt
damping) on the spheres, from several starting points, and reports how well the motion
determined the axes: the smallest singular value of the normalised Jacobian and the axes' 1-sigma
uncertainty from the residuals (the Gauss-Newton covariance). The signs of ``j1`` and ``j2``
are not observable from gyroscopes alone; :func:`consistent_sign` fixes them with the
orientations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MAX_SAMPLES = 20_000
"""At most this many samples (evenly spread over the moving ones) enter the fit."""
MIN_RATE_RAD_S = math.radians(5.0)
"""Samples where both sensors turn slower than this carry little information and are left out."""
STARTS = 8
ITERATIONS = 40


@dataclass(frozen=True)
class AxisEstimate:
    """A hinge axis in both sensors' frames and how well the motion determined it.

    Attributes
    ----------
    j1, j2 : (3,) unit axis in sensor 1's and sensor 2's frame.
    residual_rms_rad_s : RMS of ``||w1 x j1|| - ||w2 x j2||`` at the solution.
    smallest_singular : smallest singular value of the Jacobian divided by sqrt(samples), rad/s
        per rad of axis change: how strongly the motion pins the axes down (0: not at all).
    uncertainty_deg : (2,) 1-sigma angular uncertainty of ``j1`` and ``j2`` (largest direction).
    samples : samples used.
    """

    j1: np.ndarray
    j2: np.ndarray
    residual_rms_rad_s: float
    smallest_singular: float
    uncertainty_deg: np.ndarray
    samples: int

    @property
    def well_determined(self) -> bool:
        """True when both axes are known to within 2 degrees (1 sigma)."""
        return bool(np.all(self.uncertainty_deg < 2.0))


def tangent_basis(j: np.ndarray) -> np.ndarray:
    """(3, 2) two orthonormal vectors perpendicular to unit ``j``."""
    helper = np.eye(3)[int(np.argmin(np.abs(j)))]
    a = np.cross(j, helper)
    a /= np.linalg.norm(a)
    return np.column_stack([a, np.cross(j, a)])


def _residuals(w1: np.ndarray, w2: np.ndarray, j1: np.ndarray, j2: np.ndarray,
               jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
    p1 = w1 @ j1
    p2 = w2 @ j2
    f1 = np.sqrt(np.maximum(np.einsum("ij,ij->i", w1, w1) - p1 * p1, 1e-12))
    f2 = np.sqrt(np.maximum(np.einsum("ij,ij->i", w2, w2) - p2 * p2, 1e-12))
    r = f1 - f2
    if not jacobian:
        return r, None
    b1, b2 = tangent_basis(j1), tangent_basis(j2)
    jac = np.hstack([-(p1 / f1)[:, None] * (w1 @ b1), (p2 / f2)[:, None] * (w2 @ b2)])
    return r, jac


def _refine(w1: np.ndarray, w2: np.ndarray, j1: np.ndarray, j2: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, float]:
    damping = 1e-3
    r, jac = _residuals(w1, w2, j1, j2, True)
    cost = float(r @ r)
    for _ in range(ITERATIONS):
        assert jac is not None
        h = jac.T @ jac
        g = jac.T @ r
        step = -np.linalg.solve(h + damping * np.diag(np.diag(h) + 1e-12), g)
        n1 = j1 + tangent_basis(j1) @ step[:2]
        n2 = j2 + tangent_basis(j2) @ step[2:]
        n1 /= np.linalg.norm(n1)
        n2 /= np.linalg.norm(n2)
        r_new, jac_new = _residuals(w1, w2, n1, n2, True)
        cost_new = float(r_new @ r_new)
        if cost_new < cost:
            converged = cost - cost_new < 1e-12 * max(cost, 1e-30)
            j1, j2, r, jac, cost = n1, n2, r_new, jac_new, cost_new
            damping = max(damping * 0.3, 1e-9)
            if converged or float(np.abs(step).max()) < 1e-10:
                break
        else:
            damping *= 10.0
            if damping > 1e8:
                break
    return j1, j2, cost


def select_samples(w1: np.ndarray, w2: np.ndarray, limit: int = MAX_SAMPLES) -> np.ndarray:
    """Indices of the informative samples (either sensor turning), at most ``limit`` of them."""
    moving = np.flatnonzero((np.linalg.norm(w1, axis=1) > MIN_RATE_RAD_S)
                            | (np.linalg.norm(w2, axis=1) > MIN_RATE_RAD_S))
    if len(moving) > limit:
        moving = moving[np.linspace(0, len(moving) - 1, limit).round().astype(int)]
    return moving


def estimate_hinge_axes(
    gyro1: np.ndarray, gyro2: np.ndarray, *, start: tuple[np.ndarray, np.ndarray] | None = None,
    seed: int = 0, limit: int = MAX_SAMPLES,
) -> AxisEstimate:
    """The hinge axis in both sensors' frames from simultaneous gyroscope samples (N, 3), rad/s.

    ``start``: an earlier estimate to refine (then a single start); otherwise the best of
    :data:`STARTS` random starting points. ``limit``: at most this many samples, evenly spread
    over the moving ones. Raises ValueError when fewer than 20 samples move.
    """
    w1 = np.asarray(gyro1, dtype=np.float64)
    w2 = np.asarray(gyro2, dtype=np.float64)
    rows = select_samples(w1, w2, limit)
    if len(rows) < 20:
        raise ValueError("too little motion to estimate the hinge axis (fewer than 20 samples "
                         "turning faster than 5 deg/s)")
    w1, w2 = w1[rows], w2[rows]
    if start is not None:
        candidates = [(np.asarray(start[0], float), np.asarray(start[1], float))]
    else:
        rng = np.random.default_rng(seed)
        raw = rng.normal(size=(STARTS, 2, 3))
        candidates = [(a / np.linalg.norm(a), b / np.linalg.norm(b)) for a, b in raw]
    best = None
    for j1, j2 in candidates:
        found = _refine(w1, w2, j1 / np.linalg.norm(j1), j2 / np.linalg.norm(j2))
        if best is None or found[2] < best[2]:
            best = found
    assert best is not None
    j1, j2, cost = best
    r, jac = _residuals(w1, w2, j1, j2, True)
    assert jac is not None
    n = len(r)
    singular = np.linalg.svd(jac, compute_uv=False)
    sigma2 = cost / max(n - 4, 1)
    cov = sigma2 * np.linalg.pinv(jac.T @ jac)
    unc = np.degrees(np.sqrt([np.linalg.eigvalsh(cov[:2, :2]).max(),
                              np.linalg.eigvalsh(cov[2:, 2:]).max()]))
    return AxisEstimate(j1, j2, math.sqrt(cost / n), float(singular.min() / math.sqrt(n)),
                        unc, n)


def consistent_sign(j1: np.ndarray, j2: np.ndarray, quat1: np.ndarray,
                    quat2: np.ndarray) -> np.ndarray:
    """``j2`` or ``-j2``: the sign whose earth-frame inclination matches ``j1``'s.

    With each link's 6D orientation (N, 4) (heading arbitrary), the hinge axis seen from both
    links must make the same angle with the vertical; the wrong sign mirrors it.
    """
    from app.core import quaternion as quat

    z1 = quat.rotate(quat1, j1)[:, 2]
    z2 = quat.rotate(quat2, j2)[:, 2]
    return j2 if float(z1 @ z2) >= 0.0 else -j2
