"""Accelerometer model fits: six positions (known orientations) and the ellipsoid (free poses).

Model and conventions
---------------------
``a_meas = M a_true + b`` with ``a_true`` the true specific force (``g`` times the up direction
at rest), ``M`` a 3x3 matrix holding scale and misalignment, ``b`` the bias (m/s^2). Row ``j``
of ``M`` is the sensitive direction of channel ``j`` (times its scale). The pipeline applies
the inverse, ``a_cal = A (a_raw - b)`` with ``A = M^-1`` (:meth:`AccelFit.to_calibration`).

Twelve numbers describe ``M`` and ``b``: 3 bias, 3 scale, and 6 off-diagonal terms, which are
3 *non-orthogonality* angles (between the channels' sensitive axes; a symmetric part) and a
small *rotation* of the sensor frame as a whole (3; an antisymmetric part: the chip is soldered
a little askew, the board sits askew in its housing). :class:`AccelFit` reports them apart.

Six positions (:func:`fit_known_orientations`, :func:`fit_six_position`)
    The board lies on each face of a box; the true up direction of every pose is known
    (axis-aligned), so ``a_meas = M a_true + b`` is linear in the unknowns and is solved by
    least squares. The default ``model="full"`` fits all 9 entries of ``M``: the box then
    defines the instrument frame, and the rotation part is what keeps the tilt error small
    when the chip sits askew (simulated unit 1 is 0.39 degree askew; without the rotation
    part its tilt error stays at 0.23-0.39 degree). ``model="symmetric"`` (9 parameters:
    ``M`` symmetric, the polar factor closest to the raw axes) and ``model="lower"``
    (lower-triangular: channel x defines the frame, as in Tedaldi et al. 2014) assume the
    chip is not rotated against the box; they are kept for comparison, and their component
    residual shows the rotation they cannot fit (3.2 and 1.4 mg for unit 1, against 0.02).

    **Placement.** The fit trusts the faces. A board rotated on the box as a whole is
    absorbed into ``M`` (the box becomes the frame, harmless). A *single* face tilted by
    ``delta`` (a box that is not square, a crumb under one face) biases the misalignment term
    of that column by about ``delta / 2`` and the bias of the affected cross axis by about
    ``g delta / 6`` (1 degree: 0.5 degree of misalignment and 2.9 mg of bias). Scale only
    moves by ``delta^2 / 4`` plus the cross-axis term times ``delta / 2`` (about 1e-4 at
    1 degree and 1 % cross-axis). The component residual
    (:attr:`AccelFit.component_residuals_mg`: about ``g delta / 3`` on both faces of the
    affected pair, in the cross channel) reveals such a face. So a 1 mg bias needs faces
    square to about 0.3 degree, and the misalignment is as good as the box.

Free orientations (:func:`fit_ellipsoid`)
    With no box, only ``|a_true| = g`` is known: ``|A (a_meas - b)| = g`` for every pose, a
    point on an ellipsoid. Any rotation ``R A`` fits equally well, so only 9 of the 12
    parameters are observable (3 bias, 3 scale, 3 non-orthogonality); ``A`` is taken
    symmetric (the calibrated frame closest to the raw axes, the matrix square root of the
    ellipsoid's quadric). The frame rotation stays uncorrected: a tilt error up to the size
    of the chip's rotation part (0.39 degree for simulated unit 1, up to about 0.7 degree
    across units). A tare at level removes it at that attitude only; the rotation about the
    vertical remains as about ``sin(tilt)`` times itself (0.25 degree at 60 degrees of tilt
    for unit 1). The ellipsoid is therefore a fallback: for 0.05 degree use the six positions.
    Needs >= 12 poses spread over the sphere.

Uncertainties come from the least-squares covariance ``s^2 (J^T J)^-1`` with ``s^2`` the larger
of the residual variance (placement, temperature drift) and the white-noise variance of the
pose means.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.core import quaternion as quat
from app.core.calibration import SensorCalibration
from app.core.calibration_procedures.gyro_bias import GyroBiasResult
from app.core.calibration_procedures.poses import FACE_DIRECTIONS, CapturedPose
from app.core.samples import STANDARD_GRAVITY_M_S2

AXES = "xyz"
MODELS = ("full", "symmetric", "lower")
SIX_POSITION_METHOD = "six-position"
ELLIPSOID_METHOD = "ellipsoid"
MIN_ELLIPSOID_POSES = 12


class CalibrationFitError(ValueError):
    """The poses do not determine the model (too few, or not spread enough)."""


def _unit(j: int, k: int) -> np.ndarray:
    e = np.zeros((3, 3))
    e[j, k] = 1.0
    return e


def matrix_basis(model: str) -> list[tuple[str, np.ndarray]]:
    """Named 3x3 basis matrices whose weighted sum is ``M`` under ``model``."""
    if model == "full":
        return [(f"M_{AXES[j]}{AXES[k]}", _unit(j, k)) for j in range(3) for k in range(3)]
    basis = [(f"M_{a}{a}", _unit(j, j)) for j, a in enumerate(AXES)]
    if model == "symmetric":
        pairs = [(0, 1), (0, 2), (1, 2)]
        basis += [(f"M_{AXES[j]}{AXES[k]}", _unit(j, k) + _unit(k, j)) for j, k in pairs]
        return basis
    if model == "lower":
        pairs = [(1, 0), (2, 0), (2, 1)]
        return basis + [(f"M_{AXES[j]}{AXES[k]}", _unit(j, k)) for j, k in pairs]
    raise ValueError(f"unknown model {model!r}; use one of {', '.join(MODELS)}")


@dataclass(frozen=True)
class AccelFit:
    """A fitted accelerometer model ``a_meas = M a_true + b`` and its quality.

    Attributes
    ----------
    method : :data:`SIX_POSITION_METHOD` or :data:`ELLIPSOID_METHOD`.
    model : ``"full"``, ``"symmetric"`` or ``"lower"`` (the ellipsoid fit is symmetric).
    bias_m_s2 : (3,) ``b``.
    matrix : (3, 3) ``M``.
    covariance : (12, 12) covariance of ``(M row-major, b)``; zero rows for fixed entries.
    residual_norm_rms_mg : RMS over poses of ``|A (a - b)| - g``, mg.
    residual_component_rms_mg : RMS of the per-component residual of the known-orientation
        fit, mg (NaN for the ellipsoid, whose residual is the norm).
    norm_errors_mg : (n,) ``|A (a - b)| - g`` per pose, mg.
    component_residuals_mg : (n, 3) per pose (six-position), or None.
    n_poses, dof : poses used and residual degrees of freedom.
    temperature_degc : mean temperature of the poses (NaN when unknown).
    """

    method: str
    model: str
    bias_m_s2: np.ndarray
    matrix: np.ndarray
    covariance: np.ndarray
    residual_norm_rms_mg: float
    residual_component_rms_mg: float
    norm_errors_mg: np.ndarray
    component_residuals_mg: np.ndarray | None
    n_poses: int
    dof: int
    temperature_degc: float = math.nan
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2

    # -- the correction -----------------------------------------------------------------------
    @property
    def correction_matrix(self) -> np.ndarray:
        """``A = M^-1``, what the pipeline multiplies by."""
        return np.linalg.inv(self.matrix)

    def calibrate(self, accel_m_s2: np.ndarray) -> np.ndarray:
        """``A (a - b)`` for readings (..., 3)."""
        return (np.asarray(accel_m_s2) - self.bias_m_s2) @ self.correction_matrix.T

    def to_calibration(
        self,
        gyro: GyroBiasResult | np.ndarray | None = None,
        name: str = "calibrated",
    ) -> SensorCalibration:
        """A :class:`SensorCalibration` with this accelerometer model and a gyro bias."""
        if isinstance(gyro, GyroBiasResult):
            gyro_bias = gyro.bias_rad_s
        else:
            gyro_bias = np.zeros(3) if gyro is None else np.asarray(gyro, dtype=np.float64)
        return SensorCalibration(
            accel_bias_m_s2=np.array(self.bias_m_s2, dtype=np.float64),
            accel_matrix=self.correction_matrix,
            gyro_bias_rad_s=np.array(gyro_bias, dtype=np.float64),
            name=name,
        )

    # -- parameters and uncertainties ---------------------------------------------------------
    @property
    def matrix_std(self) -> np.ndarray:
        """(3, 3) standard deviation of each entry of ``M`` (0 where fixed by the model)."""
        return np.sqrt(np.maximum(np.diag(self.covariance)[:9], 0.0)).reshape(3, 3)

    @property
    def bias_std_m_s2(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.covariance)[9:], 0.0))

    @property
    def bias_mg(self) -> np.ndarray:
        return self.bias_m_s2 / self.gravity_m_s2 * 1e3

    @property
    def bias_std_mg(self) -> np.ndarray:
        return self.bias_std_m_s2 / self.gravity_m_s2 * 1e3

    @property
    def scale_error(self) -> np.ndarray:
        """(3,) ``diag(M) - 1``: the sensitivity error of each channel (0.01 = 1 %)."""
        return np.diag(self.matrix) - 1.0

    @property
    def scale_error_std(self) -> np.ndarray:
        return np.diag(self.matrix_std)

    @property
    def cross_axis(self) -> np.ndarray:
        """(3, 3) ``diag(M)^-1 M - I`` (the simulator's ``cross_axis`` form; zero diagonal)."""
        return self.matrix / np.diag(self.matrix)[:, None] - np.eye(3)

    @property
    def non_orthogonality_deg(self) -> dict[str, float]:
        """90 degrees minus the angle between the channels' sensitive axes, per pair."""
        rows = self.matrix / np.linalg.norm(self.matrix, axis=1, keepdims=True)
        out = {}
        for j, k in ((0, 1), (0, 2), (1, 2)):
            cosine = float(np.clip(rows[j] @ rows[k], -1.0, 1.0))
            out[AXES[j] + AXES[k]] = 90.0 - math.degrees(math.acos(cosine))
        return out

    @property
    def frame_rotation_deg(self) -> np.ndarray:
        """(3,) rotation vector (degrees) of the rotation factor ``R`` of ``M = R K``.

        ``K`` symmetric positive definite (polar decomposition): the sensor frame's rotation
        against the frame the fit was referred to (the box; zero for the symmetric models).
        """
        u, _, vt = np.linalg.svd(self.matrix)
        rotation = u @ vt
        return np.degrees(quat.to_rotation_vector(_quaternion_from_matrix(rotation)))

    def summary(self) -> dict[str, object]:
        """Plain numbers for a profile or a report (mg, %, degrees)."""
        return {
            "method": self.method,
            "model": self.model,
            "poses": self.n_poses,
            "residual_norm_rms_mg": self.residual_norm_rms_mg,
            "residual_component_rms_mg": self.residual_component_rms_mg,
            "bias_mg": self.bias_mg.tolist(),
            "bias_std_mg": self.bias_std_mg.tolist(),
            "scale_error_percent": (100.0 * self.scale_error).tolist(),
            "scale_error_std_percent": (100.0 * self.scale_error_std).tolist(),
            "non_orthogonality_deg": self.non_orthogonality_deg,
            "frame_rotation_deg": self.frame_rotation_deg.tolist(),
            "temperature_degc": self.temperature_degc,
        }


def _quaternion_from_matrix(r: np.ndarray) -> np.ndarray:
    """Unit quaternion ``q`` with ``quaternion.rotate(q, v) == r @ v`` (Shepperd's method)."""
    m00, m11, m22 = r[0, 0], r[1, 1], r[2, 2]
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [s / 4, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = [(r[2, 1] - r[1, 2]) / s, s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4]
    return quat.normalize(np.array(q, dtype=np.float64))


def _noise_floor(std_errors: np.ndarray | None) -> float:
    """Mean white-noise variance of one component of a pose mean (0 when unknown)."""
    if std_errors is None:
        return 0.0
    return float(np.mean(np.square(std_errors)))


def _mean_temperature(poses: Sequence[CapturedPose]) -> float:
    temps = [p.temperature_degc for p in poses if math.isfinite(p.temperature_degc)]
    return float(np.mean(temps)) if temps else math.nan


# -- known orientations (six positions) ---------------------------------------------------------
def fit_known_orientations(
    accel_means_m_s2: np.ndarray,
    reference_up: np.ndarray,
    model: str = "full",
    mean_std_errors_m_s2: np.ndarray | None = None,
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
    temperature_degc: float = math.nan,
) -> AccelFit:
    """Least-squares ``a_meas = M a_true + b`` for poses of known up direction.

    Parameters
    ----------
    accel_means_m_s2 : (n, 3) mean readings, one per pose.
    reference_up : (n, 3) true up direction of each pose in the (box's) sensor frame.
    model : ``"full"`` (default), ``"symmetric"`` or ``"lower"``; see the module docstring.
    mean_std_errors_m_s2 : (n, 3) white-noise uncertainty of each mean (noise floor of ``s``).
    """
    means = np.asarray(accel_means_m_s2, dtype=np.float64).reshape(-1, 3)
    up = np.asarray(reference_up, dtype=np.float64).reshape(-1, 3)
    if len(means) != len(up):
        raise ValueError("one reference direction per pose is needed")
    basis = matrix_basis(model)
    p = len(basis) + 3
    n = len(means)
    if 3 * n < p:
        raise CalibrationFitError(f"{n} poses cannot determine {p} parameters")
    a_true = gravity_m_s2 * up / np.linalg.norm(up, axis=1, keepdims=True)
    x = np.zeros((3 * n, p))
    for m, (_, e) in enumerate(basis):
        x[:, m] = (a_true @ e.T).reshape(-1)
    x[:, len(basis) :] = np.tile(np.eye(3), (n, 1))
    y = means.reshape(-1)
    normal = x.T @ x
    if np.linalg.matrix_rank(normal, tol=1e-9 * np.max(np.abs(normal))) < p:
        raise CalibrationFitError(
            "the poses do not determine the model: each axis needs to point both up and down "
            "(all six faces)"
        )
    theta, *_ = np.linalg.lstsq(x, y, rcond=None)
    residual = y - x @ theta
    dof = 3 * n - p
    s2 = max(float(residual @ residual) / dof if dof > 0 else 0.0,
             _noise_floor(mean_std_errors_m_s2))
    cov_theta = s2 * np.linalg.inv(normal)
    matrix = sum(theta[m] * e for m, (_, e) in enumerate(basis))
    bias = theta[len(basis) :]
    jac = np.zeros((12, p))  # d(M row-major, b) / d(theta)
    for m, (_, e) in enumerate(basis):
        jac[:9, m] = e.reshape(-1)
    jac[9:, len(basis) :] = np.eye(3)
    covariance = jac @ cov_theta @ jac.T
    norm_errors = _norm_errors_mg(means, bias, np.linalg.inv(matrix), gravity_m_s2)
    mg = 1e3 / gravity_m_s2
    return AccelFit(
        method=SIX_POSITION_METHOD,
        model=model,
        bias_m_s2=bias,
        matrix=matrix,
        covariance=covariance,
        residual_norm_rms_mg=float(np.sqrt(np.mean(norm_errors**2))),
        residual_component_rms_mg=float(np.sqrt(np.mean(residual**2))) * mg,
        norm_errors_mg=norm_errors,
        component_residuals_mg=residual.reshape(n, 3) * mg,
        n_poses=n,
        dof=dof,
        temperature_degc=temperature_degc,
        gravity_m_s2=gravity_m_s2,
    )


def fit_six_position(
    poses: Sequence[CapturedPose],
    model: str = "full",
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
) -> AccelFit:
    """The six-position fit of captured poses, each taken as lying exactly on its face."""
    if len(poses) < 6:
        raise CalibrationFitError(f"the six-position fit needs six poses, not {len(poses)}")
    faces = {pose.face for pose in poses}
    missing = [face for face in FACE_DIRECTIONS if face not in faces]
    if missing:
        raise CalibrationFitError(f"faces missing for the six-position fit: {', '.join(missing)}")
    return fit_known_orientations(
        np.array([pose.accel_mean_m_s2 for pose in poses]),
        np.array([FACE_DIRECTIONS[pose.face] for pose in poses]),
        model=model,
        mean_std_errors_m_s2=np.array([pose.accel_std_error_m_s2 for pose in poses]),
        gravity_m_s2=gravity_m_s2,
        temperature_degc=_mean_temperature(poses),
    )


def _norm_errors_mg(
    means: np.ndarray, bias: np.ndarray, correction: np.ndarray, gravity_m_s2: float
) -> np.ndarray:
    calibrated = (means - bias) @ correction.T
    return (np.linalg.norm(calibrated, axis=1) - gravity_m_s2) / gravity_m_s2 * 1e3


# -- free orientations (ellipsoid) ---------------------------------------------------------------
_SYMMETRIC_BASIS = matrix_basis("symmetric")


def _algebraic_ellipsoid(x: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Initial ``(A, b)`` from the algebraic quadric fit, or None when it is not an ellipsoid."""
    px, py, pz = x[:, 0], x[:, 1], x[:, 2]
    d = np.column_stack(
        [px * px, py * py, pz * pz, 2 * px * py, 2 * px * pz, 2 * py * pz,
         2 * px, 2 * py, 2 * pz, np.ones(len(x))]
    )
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    v = vt[-1]
    q = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    lin = v[6:9]
    try:
        center = -np.linalg.solve(q, lin)
    except np.linalg.LinAlgError:
        return None
    r = float(center @ q @ center - v[9])
    if r == 0.0:
        return None
    q = q / r
    w, vec = np.linalg.eigh(q)
    if np.any(w <= 0.0):
        return None
    return (vec * np.sqrt(w)) @ vec.T, center


def fit_ellipsoid(
    accel_means_m_s2: np.ndarray,
    mean_std_errors_m_s2: np.ndarray | None = None,
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
    temperature_degc: float = math.nan,
    min_poses: int = MIN_ELLIPSOID_POSES,
    max_iterations: int = 100,
) -> AccelFit:
    """Ellipsoid fit ``|A (a - b)| = g`` with ``A`` symmetric over >= ``min_poses`` poses.

    Algebraic quadric fit for a start, then Levenberg-Marquardt on the norm residuals; see
    the module docstring for what is (not) observable.
    """
    means = np.asarray(accel_means_m_s2, dtype=np.float64).reshape(-1, 3)
    n = len(means)
    if n < min_poses:
        raise CalibrationFitError(f"the ellipsoid fit needs at least {min_poses} poses, not {n}")
    x = means / gravity_m_s2  # work in g
    start = _algebraic_ellipsoid(x)
    if start is None:
        a0, b0 = np.eye(3) / np.mean(np.linalg.norm(x, axis=1)), np.zeros(3)
    else:
        a0, b0 = start
    theta = np.array([a0[0, 0], a0[1, 1], a0[2, 2], a0[0, 1], a0[0, 2], a0[1, 2], *b0])

    def unpack(th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a = sum(th[m] * e for m, (_, e) in enumerate(_SYMMETRIC_BASIS))
        return a, th[6:]

    def residual_and_jacobian(th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b = unpack(th)
        d = x - b
        u = d @ a.T
        norm = np.linalg.norm(u, axis=1)
        jac = np.empty((n, 9))
        for m, (_, e) in enumerate(_SYMMETRIC_BASIS):
            jac[:, m] = np.sum(u * (d @ e.T), axis=1) / norm
        jac[:, 6:] = -(u @ a) / norm[:, None]
        return norm - 1.0, jac

    r, jac = residual_and_jacobian(theta)
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(max_iterations):
        jtj = jac.T @ jac
        step = np.linalg.solve(jtj + lam * np.diag(np.diag(jtj)), -jac.T @ r)
        r_new, jac_new = residual_and_jacobian(theta + step)
        cost_new = float(r_new @ r_new)
        if cost_new <= cost:
            theta, r, jac = theta + step, r_new, jac_new
            converged = cost - cost_new <= 1e-15 * max(cost, 1e-30) or np.max(np.abs(step)) < 1e-13
            cost = cost_new
            lam = max(lam / 10.0, 1e-12)
            if converged:
                break
        else:
            lam *= 10.0
            if lam > 1e12:
                break
    jtj = jac.T @ jac
    if np.linalg.cond(jtj) > 1e12:
        raise CalibrationFitError(
            "the poses do not determine the ellipsoid: spread them over all directions "
            "(each axis up and down, and in between)"
        )
    dof = n - 9
    floor = 0.0
    if mean_std_errors_m_s2 is not None:
        directions = x / np.linalg.norm(x, axis=1, keepdims=True)
        along = np.sum(np.square(directions * np.asarray(mean_std_errors_m_s2)), axis=1)
        floor = float(np.mean(along)) / gravity_m_s2**2
    s2 = max(cost / dof if dof > 0 else 0.0, floor)
    cov_theta = s2 * np.linalg.inv(jtj)  # in g units
    a, b_g = unpack(theta)
    matrix = np.linalg.inv(a)
    # d(M)/d(theta_m) = -M E_m M for the matrix parameters; b scales by g.
    jacobian = np.zeros((12, 9))
    for m, (_, e) in enumerate(_SYMMETRIC_BASIS):
        jacobian[:9, m] = -(matrix @ e @ matrix).reshape(-1)
    jacobian[9:, 6:] = gravity_m_s2 * np.eye(3)
    covariance = jacobian @ cov_theta @ jacobian.T
    bias = b_g * gravity_m_s2
    norm_errors = r * 1e3
    return AccelFit(
        method=ELLIPSOID_METHOD,
        model="symmetric",
        bias_m_s2=bias,
        matrix=matrix,
        covariance=covariance,
        residual_norm_rms_mg=float(np.sqrt(np.mean(norm_errors**2))),
        residual_component_rms_mg=math.nan,
        norm_errors_mg=norm_errors,
        component_residuals_mg=None,
        n_poses=n,
        dof=dof,
        temperature_degc=temperature_degc,
        gravity_m_s2=gravity_m_s2,
    )


def fit_free_poses(
    poses: Sequence[CapturedPose],
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
    min_poses: int = MIN_ELLIPSOID_POSES,
) -> AccelFit:
    """The ellipsoid fit of captured poses."""
    return fit_ellipsoid(
        np.array([pose.accel_mean_m_s2 for pose in poses]).reshape(-1, 3),
        mean_std_errors_m_s2=np.array([pose.accel_std_error_m_s2 for pose in poses]).reshape(-1, 3),
        gravity_m_s2=gravity_m_s2,
        temperature_degc=_mean_temperature(poses),
        min_poses=min_poses,
    )
