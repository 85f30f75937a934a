"""Quaternion EKF: an error-state (multiplicative) Kalman filter for tilt, with gyro-bias states.

State and error state
---------------------
The attitude is held as a unit quaternion ``q`` (sensor to earth, earth z up) and a gyro-bias
estimate ``b`` (rad/s, sensor frame). The Kalman filter runs on the *error* of that state
(Markley 2003, "Attitude error representations for Kalman filtering", JGCD 26(2); Sola 2017,
"Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508, sec. 7):
``q_true = exp(dtheta) * q`` with ``dtheta`` a small rotation vector in the *earth* frame (a
"global" or left error), and ``b_true = b + db``. Of ``dtheta`` only the two horizontal
components are kept, so the error state is 5-dimensional: ``x = (dtheta_x, dtheta_y, db_x,
db_y, db_z)``.

Why this form rather than ``[q (4), b (3)]`` or the 6-state ``[dtheta (3), db (3)]``:

- a 4-component quaternion in an additive EKF has a covariance that is singular along ``q``
  (the norm) and is renormalised by hand; the rotation-vector error has exactly the three (here
  two) degrees of freedom the attitude has, so the covariance stays full-rank and well scaled;
- with the error in the earth frame, the heading error ``dtheta_z`` is never measured by the
  accelerometer and never feeds back into the tilt (``dtheta' = dtheta - R(q) db dt``: the
  earth-frame error is constant when the bias is right). Dropping it is an exact
  marginalisation for the tilt, and it removes the one state whose variance grows without bound
  (at rest a 6-state filter's heading variance grows as (vertical bias uncertainty x t)^2: about
  160 rad^2 after an hour with the default 0.2 dps, next to tilt variances of 1e-8, a condition
  number of 1e10 that erodes the tilt block's precision). The bias component along
  the vertical is unobservable while the sensor does not turn; its variance grows only by the
  bias random walk and it is learnt as soon as the sensor tilts;
- the correction is a rotation about a horizontal earth axis, as in the complementary filter,
  so it never disturbs the heading.

Process model (per step ``dt``)::

    q <- q * exp((w_measured - b) dt / 2)               (exact exponential, as gyro_step)
    F = [[I2, -dt R2], [0, I3]]     R2 = first two rows of R(q) (body -> earth)
    Q = diag(Ng^2 dt / 2 * I2, Nb^2 dt * I3)
    P <- F P F^T + Q

``Ng`` is the gyro white-noise density (LSM6DSOX: 3.8 mdps/sqrt(Hz)); ``Ng^2 dt / 2`` is the
variance of one step's angle noise when the per-sample rate noise is ``Ng sqrt(ODR / 2)`` (the
datasheet's density over the ODR/2 bandwidth, the simulator's convention). ``Nb`` is a bias
random walk (rate random walk).

Measurement model: the gravity direction
----------------------------------------
The accelerometer is rotated into the earth frame with the current estimate,
``f = R(q) a``, and low-passed there (two cascaded first-order stages with time constant
``lp_tau``), as VQF does with a second-order Butterworth in its almost-inertial frame (Laidig &
Seel 2023, "VQF: Highly accurate IMU orientation estimation with bias estimation and magnetic
disturbance rejection", Information Fusion 91). The residual
is the rotation that takes the filtered, *normalised* up direction ``v = f_lp / |f_lp|`` onto
earth z, about a horizontal axis::

    z = atan2(|v_xy|, v_z) * (v_y, -v_x) / |v_xy|       (= dtheta_xy to first order),  H = [I2 0]

Two things make this work where a per-sample "normalised accelerometer vs predicted gravity"
residual fails:

1. Averaging before normalising. ``a / |a|`` is not linear in the linear acceleration, so
   zero-mean vibration does not average out after normalisation: in the simulator's vibration
   scenario (1 g at 30 Hz, mostly vertical) a per-sample residual settles about 6 degrees off.
   Filtered in the earth frame, the vibration averages out first.
2. Filtering in the earth frame. Each correction ``exp(d)`` of the estimate is applied to the
   filter states too (they were rotated into the earth frame with the old estimate), so the
   filtered vector carries the *current* tilt error without lag; only the linear acceleration
   and noise are low-passed.

After a restart (first sample, gap, bad step) the tilt is taken from the running mean of the
accelerometer (earth frame) for the first ``lp_tau`` seconds, gain 1, as VQF initialises its
low-pass; then the Kalman update takes over with tilt variance ``tilt_initial^2`` and the bias
and its covariance kept.

Adaptive measurement noise (linear-acceleration rejection)
-----------------------------------------------------------
The residual's noise per sample is::

    sigma^2 = Na^2 / (2 dt) * (1 + ((|f_lp| - g) / (g * tolerance))^2)

i.e. ``sigma0^2 + k (|a| - g)^2`` with ``sigma0^2 = Na^2 / (2 dt)`` and ``k = sigma0^2 /
(g tolerance)^2``, applied to the *filtered* magnitude: while the sensor is being accelerated
the accelerometer's weight drops (by half at a deviation of one ``tolerance``) and the gyro
carries the attitude. Using the filtered magnitude matters: the per-sample magnitude would weigh
the samples of a vibration cycle where ``|a|`` happens to equal g, and those have a large
horizontal component (about 2 d_z d_h g for a vibration along d): a per-sample law settles 20
degrees off in the vibration scenario. ``Na`` is deliberately far above the datasheet's
70 ug/sqrt(Hz): it also stands for the hand tremor and small accelerations of real use, and it
sets the time constant at rest: with the defaults a tilt seen by the accelerometer alone is
followed with a time constant of about 3 s (30 s without the bias states, ``Na / Ng``).

Accuracy (simulated LSM6DSOX at 208 Hz, static errors compensated, seeds 1-3, 120 s each,
inclination RMSE after 10 s; VQF's online filter in brackets): at rest 0.008-0.012 (0.007-0.012)
degree, slow tilting 0.024-0.026 (0.023-0.029), hand-held wobble 0.06-0.08 (0.07-0.11),
vibration 0.02 (0.02-0.11), translation 0.12 (0.30-0.32), tour of the six faces 0.10-0.11
(0.10-0.11). Over the whole run, start included, within 1.1x of VQF on every scenario.

Noted limits: the heading is integrated gyro only (no magnetometer); the tilt is referred to the
accelerometer, so any uncompensated accelerometer bias tilts it (20 mg = 1.1 degrees).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.filters.base import OrientationFilter, ParameterSpec
from app.core.filters.complementary import gyro_step
from app.core.filters.gyro_integration import unit_positive
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

N_STATES = 5
"""Error state: horizontal earth-frame tilt error (2), gyro-bias error (3)."""


@njit(cache=True)
def _rotate_horizontal(ew, ex, ey, vx, vy, vz):  # pragma: no cover - compiled
    """Rotate (vx, vy, vz) by the unit quaternion (ew, ex, ey, 0): v + 2w(u x v) + 2u x (u x v)."""
    tx = 2.0 * ey * vz
    ty = -2.0 * ex * vz
    tz = 2.0 * (ex * vy - ey * vx)
    return vx + ew * tx + ey * tz, vy + ew * ty - ex * tz, vz + ew * tz + ex * ty - ey * tx


@njit(cache=True)
def tilt_residual(vx, vy, vz):  # pragma: no cover - compiled
    """Horizontal earth-frame rotation vector turning the direction (vx, vy, vz) onto +z.

    Exact for any angle: ``atan2(|v_xy|, v_z)`` about ``(v_y, -v_x) / |v_xy|``; upside down
    (``v_xy = 0``, ``v_z < 0``) any horizontal axis will do and +x is taken.
    """
    s = math.sqrt(vx * vx + vy * vy)
    if s > 1e-300:
        angle = math.atan2(s, vz)
        return angle * vy / s, -angle * vx / s
    if vz < 0.0:
        return math.pi, 0.0
    return 0.0, 0.0


@njit(cache=True)
def _ekf_kernel(
    accel, gyro, dt, quat, bias, cov, lowpass, gyro_var_density, bias_var_density,
    accel_var_density, tolerance, lp_tau, tilt0_var, estimate_bias, gravity, out,
):  # pragma: no cover - compiled
    """Run the filter over a block; ``quat``, ``bias``, ``cov`` and ``lowpass`` are updated.

    ``lowpass`` = (y1 (3), y2 (3), samples since restart, seconds since restart).
    Densities are squared: rad^2/s (gyro), rad^2/s^3 (bias walk), (fraction of g)^2 s (accel).
    """
    qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
    bx, by, bz = bias[0], bias[1], bias[2]
    # Covariance, upper triangle: tilt block p, tilt-bias block c0./c1., bias block b..
    p00, p01, p11 = cov[0, 0], cov[0, 1], cov[1, 1]
    c00, c01, c02 = cov[0, 2], cov[0, 3], cov[0, 4]
    c10, c11, c12 = cov[1, 2], cov[1, 3], cov[1, 4]
    b00, b01, b02 = cov[2, 2], cov[2, 3], cov[2, 4]
    b11, b12, b22 = cov[3, 3], cov[3, 4], cov[4, 4]
    y1x, y1y, y1z = lowpass[0], lowpass[1], lowpass[2]
    y2x, y2y, y2z = lowpass[3], lowpass[4], lowpass[5]
    count, since = lowpass[6], lowpass[7]
    if not estimate_bias:
        c00 = c01 = c02 = c10 = c11 = c12 = 0.0
        b00 = b01 = b02 = b11 = b12 = b22 = 0.0
    inv_tol2 = 0.0 if tolerance <= 0.0 else 1.0 / (tolerance * tolerance)
    for i in range(accel.shape[0]):
        step = dt[i]
        if step > 0.0:
            # ---- predict ---------------------------------------------------------------
            wx, wy, wz = gyro[i, 0], gyro[i, 1], gyro[i, 2]
            if not wx * wx + wy * wy + wz * wz < math.inf:  # NaN/inf: trust the bias only
                wx = wy = wz = 0.0
            qw, qx, qy, qz = gyro_step(qw, qx, qy, qz, wx - bx, wy - by, wz - bz, step)
            if estimate_bias:
                # G = -dt R2: how a body-frame bias error turns the earth-frame tilt.
                g00 = -step * (1.0 - 2.0 * (qy * qy + qz * qz))
                g01 = -step * 2.0 * (qx * qy - qw * qz)
                g02 = -step * 2.0 * (qx * qz + qw * qy)
                g10 = -step * 2.0 * (qx * qy + qw * qz)
                g11 = -step * (1.0 - 2.0 * (qx * qx + qz * qz))
                g12 = -step * 2.0 * (qy * qz - qw * qx)
                # m = Pbb G^T (columns m0., m1.)
                m00 = b00 * g00 + b01 * g01 + b02 * g02
                m01 = b01 * g00 + b11 * g01 + b12 * g02
                m02 = b02 * g00 + b12 * g01 + b22 * g02
                m10 = b00 * g10 + b01 * g11 + b02 * g12
                m11 = b01 * g10 + b11 * g11 + b12 * g12
                m12 = b02 * g10 + b12 * g11 + b22 * g12
                # Ptt += G Pbt + Ptb G^T + G Pbb G^T;  Ptb += G Pbb;  Pbb += Qb
                p00 += 2.0 * (g00 * c00 + g01 * c01 + g02 * c02) + (
                    g00 * m00 + g01 * m01 + g02 * m02
                )
                p01 += (
                    (g00 * c10 + g01 * c11 + g02 * c12)
                    + (g10 * c00 + g11 * c01 + g12 * c02)
                    + (g00 * m10 + g01 * m11 + g02 * m12)
                )
                p11 += 2.0 * (g10 * c10 + g11 * c11 + g12 * c12) + (
                    g10 * m10 + g11 * m11 + g12 * m12
                )
                c00 += m00
                c01 += m01
                c02 += m02
                c10 += m10
                c11 += m11
                c12 += m12
                q_bias = bias_var_density * step
                b00 += q_bias
                b11 += q_bias
                b22 += q_bias
            q_tilt = 0.5 * gyro_var_density * step
            p00 += q_tilt
            p11 += q_tilt
        else:
            # ---- restart: tilt from the accelerometer, bias and its covariance kept -------
            p00 = p11 = tilt0_var
            p01 = 0.0
            c00 = c01 = c02 = c10 = c11 = c12 = 0.0
            count = 0.0
            since = 0.0
        since += step
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        norm2 = ax * ax + ay * ay + az * az
        if norm2 > 0.0 and norm2 < math.inf:
            # f = R(q) a, the specific force in the earth frame (m/s^2).
            tx = 2.0 * (qy * az - qz * ay)
            ty = 2.0 * (qz * ax - qx * az)
            tz = 2.0 * (qx * ay - qy * ax)
            fx = ax + qw * tx + qy * tz - qz * ty
            fy = ay + qw * ty + qz * tx - qx * tz
            fz = az + qw * tz + qx * ty - qy * tx
            warming = step == 0.0 or since < lp_tau
            if lp_tau > 0.0:
                count += 1.0
                # A running mean until the exponential forgets faster (start-up).
                alpha = max(step / (lp_tau + step), 1.0 / count)
                y1x += alpha * (fx - y1x)
                y1y += alpha * (fy - y1y)
                y1z += alpha * (fz - y1z)
                if warming:
                    y2x, y2y, y2z = y1x, y1y, y1z
                else:
                    y2x += alpha * (y1x - y2x)
                    y2y += alpha * (y1y - y2y)
                    y2z += alpha * (y1z - y2z)
                vx, vy, vz = y2x, y2y, y2z
            else:
                vx, vy, vz = fx, fy, fz
            z0, z1 = tilt_residual(vx, vy, vz)
            if warming:
                d0 = z0
                d1 = z1
            else:
                # ---- Kalman update, H = [I2 0] ------------------------------------------
                excess = math.sqrt(vx * vx + vy * vy + vz * vz) / gravity - 1.0
                r = 0.5 * accel_var_density / step * (1.0 + excess * excess * inv_tol2)
                s00 = p00 + r
                s11 = p11 + r
                det = s00 * s11 - p01 * p01
                i00 = s11 / det
                i01 = -p01 / det
                i11 = s00 / det
                k00 = p00 * i00 + p01 * i01
                k01 = p00 * i01 + p01 * i11
                k10 = p01 * i00 + p11 * i01
                k11 = p01 * i01 + p11 * i11
                d0 = k00 * z0 + k01 * z1
                d1 = k10 * z0 + k11 * z1
                if estimate_bias:
                    kb00 = c00 * i00 + c10 * i01
                    kb01 = c00 * i01 + c10 * i11
                    kb10 = c01 * i00 + c11 * i01
                    kb11 = c01 * i01 + c11 * i11
                    kb20 = c02 * i00 + c12 * i01
                    kb21 = c02 * i01 + c12 * i11
                    # The bias error is in the sensor frame like b: b_true = b + db.
                    bx += kb00 * z0 + kb01 * z1
                    by += kb10 * z0 + kb11 * z1
                    bz += kb20 * z0 + kb21 * z1
                    # P <- P - K H P (rows of H P are the first two rows of P).
                    b00 -= kb00 * c00 + kb01 * c10
                    b01 -= kb00 * c01 + kb01 * c11
                    b02 -= kb00 * c02 + kb01 * c12
                    b11 -= kb10 * c01 + kb11 * c11
                    b12 -= kb10 * c02 + kb11 * c12
                    b22 -= kb20 * c02 + kb21 * c12
                    n00 = c00 - (k00 * c00 + k01 * c10)
                    n01 = c01 - (k00 * c01 + k01 * c11)
                    n02 = c02 - (k00 * c02 + k01 * c12)
                    c10 = c10 - (k10 * c00 + k11 * c10)
                    c11 = c11 - (k10 * c01 + k11 * c11)
                    c12 = c12 - (k10 * c02 + k11 * c12)
                    c00, c01, c02 = n00, n01, n02
                n00 = p00 - (k00 * p00 + k01 * p01)
                n01 = p01 - (k00 * p01 + k01 * p11)
                p11 = p11 - (k10 * p01 + k11 * p11)
                p00, p01 = n00, n01
            # ---- inject the tilt correction: q <- exp(d) q, d = (d0, d1, 0) earth frame ----
            angle = math.sqrt(d0 * d0 + d1 * d1)
            if angle > 0.0:
                half = 0.5 * angle
                k = math.sin(half) / angle
                ew = math.cos(half)
                ex = d0 * k
                ey = d1 * k
                qw, qx, qy, qz = (
                    ew * qw - ex * qx - ey * qy,
                    ew * qx + ex * qw + ey * qz,
                    ew * qy - ex * qz + ey * qw,
                    ew * qz + ex * qy - ey * qx,
                )
                # The filtered vectors were rotated with the old estimate: rotate them too.
                y1x, y1y, y1z = _rotate_horizontal(ew, ex, ey, y1x, y1y, y1z)
                y2x, y2y, y2z = _rotate_horizontal(ew, ex, ey, y2x, y2y, y2z)
        qw, qx, qy, qz = unit_positive(qw, qx, qy, qz)
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
    quat[0], quat[1], quat[2], quat[3] = qw, qx, qy, qz
    bias[0], bias[1], bias[2] = bx, by, bz
    cov[0, 0], cov[0, 1], cov[1, 1] = p00, p01, p11
    cov[0, 2], cov[0, 3], cov[0, 4] = c00, c01, c02
    cov[1, 2], cov[1, 3], cov[1, 4] = c10, c11, c12
    cov[2, 2], cov[2, 3], cov[2, 4] = b00, b01, b02
    cov[3, 3], cov[3, 4], cov[4, 4] = b11, b12, b22
    for row in range(N_STATES):
        for col in range(row):
            cov[row, col] = cov[col, row]
    lowpass[0], lowpass[1], lowpass[2] = y1x, y1y, y1z
    lowpass[3], lowpass[4], lowpass[5] = y2x, y2y, y2z
    lowpass[6], lowpass[7] = count, since


class QuaternionEKF(OrientationFilter):
    """Error-state quaternion EKF with gyro-bias estimation and acceleration rejection.

    See the module docstring for the model. The state survives between blocks and across
    parameter changes; a restart (gap) re-takes the tilt from the accelerometer and keeps the
    bias estimate.
    """

    name = "ekf"
    title = "Quaternion EKF"
    description = (
        "Error-state Kalman filter: gyro propagation with bias estimation, corrected by the "
        "low-passed gravity direction; the accelerometer's weight drops under acceleration."
    )
    parameters = (
        ParameterSpec(
            "gyro_noise", "Gyro noise density", "mdps/√Hz", 3.8, 0.1, 1000.0,
            "White rate noise of the gyroscope (LSM6DSOX datasheet: 3.8 mdps/√Hz, "
            "6.6e-5 rad/s/√Hz). Larger: trust the gyro less, follow the accelerometer faster.",
            log_scale=True,
        ),
        ParameterSpec(
            "bias_drift", "Gyro bias drift", "mdps/√s", 3.0, 0.0, 1000.0,
            "Random walk of the gyro bias: how fast the filter lets its bias estimate move. "
            "The default follows self-heating (0.01 dps/°C over a few °C in minutes), well "
            "above the chip's few °/h bias instability. 0: a constant bias (the estimate "
            "settles and then stops moving).",
            log_scale=True,
        ),
        ParameterSpec(
            "bias_initial", "Initial bias uncertainty", "dps", 0.2, 0.0, 10.0,
            "1-sigma gyro bias expected at start (after calibration; an uncalibrated "
            "LSM6DSOX has up to ±1 dps). Used at reset.",
            log_scale=True,
        ),
        ParameterSpec(
            "accel_noise", "Accelerometer noise density", "µg/√Hz", 2000.0, 10.0, 1e6,
            "Measurement noise of the gravity direction at rest. Far above the datasheet's "
            "70 µg/√Hz on purpose: it also covers tremor and small motions, and sets the time "
            "constant at rest (about 3 s with the defaults). Larger: smoother, slower.",
            log_scale=True,
        ),
        ParameterSpec(
            "accel_tolerance", "Acceleration tolerance", "mg", 15.0, 0.0, 1e4,
            "Deviation of the low-passed |a| from 1 g at which the accelerometer's weight "
            "halves: sigma^2 = sigma0^2 (1 + ((|a| - g) / tolerance)^2). Smaller rejects "
            "linear acceleration harder. 0 switches the adaptation off.",
            log_scale=True,
        ),
        ParameterSpec(
            "lp_tau", "Accelerometer low-pass", "s", 0.2, 0.0, 10.0,
            "Time constant of the two low-pass stages applied to the accelerometer in the "
            "earth frame before normalising; removes vibration. Also the start-up averaging "
            "time after a restart. 0: use each sample as it is (vibration then biases the tilt).",
            log_scale=True,
        ),
        ParameterSpec(
            "tilt_initial", "Initial tilt uncertainty", "deg", 30.0, 0.01, 180.0,
            "1-sigma tilt error assumed once the start-up averaging after a restart ends.",
            log_scale=True,
        ),
        ParameterSpec(
            "estimate_bias", "Estimate gyro bias", "", True, False, True,
            "Off: no bias states; the bias estimate keeps its value (zero after a reset).",
            kind="bool",
        ),
    )

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._bias = np.zeros(3)
        self._lowpass = np.zeros(8)
        tilt_var = math.radians(float(self._values["tilt_initial"])) ** 2
        self._cov = np.diag([tilt_var, tilt_var, 0.0, 0.0, 0.0])
        self._reset_bias_covariance()
        if initial_quat is not None:
            # Taking over mid-stream: no start-up averaging; the given attitude is trusted like
            # a settled estimate (1 degree), not like a fresh start.
            self._lowpass[7] = np.inf
            self._cov[:2, :2] = np.eye(2) * min(tilt_var, math.radians(1.0) ** 2)

    def _reset_bias_covariance(self) -> None:
        sigma = math.radians(float(self._values["bias_initial"]))
        on = bool(self._values["estimate_bias"])
        self._cov[2:, :] = 0.0
        self._cov[:, 2:] = 0.0
        self._cov[2:, 2:] = np.eye(3) * (sigma * sigma if on else 0.0)
        self._bias_states_on = on

    def _parameters_changed(self) -> None:
        on = bool(self._values["estimate_bias"])
        if hasattr(self, "_cov") and on != self._bias_states_on:
            self._reset_bias_covariance()  # switched on: start from the initial uncertainty

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """The current gyro-bias estimate (sensor frame, rad/s)."""
        return self._bias.copy()

    @property
    def covariance(self) -> np.ndarray:
        """Error-state covariance (5, 5): tilt (rad, earth x and y) then gyro bias (rad/s)."""
        return self._cov.copy()

    def _process(self, block: SampleBlock) -> np.ndarray:
        v = self._values
        out = np.empty((len(block), 4))
        quat = np.array(self._quat, dtype=np.float64)
        bias = self._bias.copy()
        cov = self._cov.copy()
        lowpass = self._lowpass.copy()
        _ekf_kernel(
            np.ascontiguousarray(block.accel_m_s2, dtype=np.float64),
            np.ascontiguousarray(block.gyro_rad_s, dtype=np.float64),
            self.time_steps(block),
            quat, bias, cov, lowpass,
            math.radians(float(v["gyro_noise"]) * 1e-3) ** 2,
            math.radians(float(v["bias_drift"]) * 1e-3) ** 2,
            (float(v["accel_noise"]) * 1e-6) ** 2,
            float(v["accel_tolerance"]) * 1e-3,
            float(v["lp_tau"]),
            math.radians(float(v["tilt_initial"])) ** 2,
            bool(v["estimate_bias"]),
            STANDARD_GRAVITY_M_S2,
            out,
        )
        self._bias, self._cov, self._lowpass = bias, cov, lowpass
        return out
