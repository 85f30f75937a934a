"""Quaternion EKF: an error-state (multiplicative) Kalman filter for tilt, with gyro-bias states,
and a heading from the magnetic field that never moves the tilt.

State and error state
---------------------
The attitude is held as a unit quaternion ``q`` (sensor to earth, earth z up) and a gyro-bias
estimate ``b`` (rad/s, sensor frame). The Kalman filter runs on the *error* of that state
(Markley 2003, "Attitude error representations for Kalman filtering", JGCD 26(2); Sola 2017,
"Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508, sec. 7):
``q_true = exp(dtheta) * q`` with ``dtheta`` a small rotation vector in the *earth* frame, and
``b_true = b + db``. Of ``dtheta`` only the two horizontal components are kept, so the error
state is ``x = (dtheta_x, dtheta_y, db_x, db_y, db_z)``: the heading error is never measured by
the accelerometer and never feeds back into the tilt, so dropping it is an exact
marginalisation for the tilt and removes the one state whose variance grows without bound.

Process model (per step ``dt``)::

    q <- q * exp((w_measured - b) dt / 2)               (exact exponential)
    F = [[I2, -dt R2], [0, I3]]     R2 = first two rows of R(q) (body -> earth)
    Q_tilt = (Ng^2 / 2 + (ks |w|)^2 lp_tau) dt,   Q_bias = Nb^2 dt

``Ng`` is the gyro white-noise density; ``ks`` the gyro's scale-factor and cross-axis
uncertainty (a fraction): uncalibrated MEMS gyros are off by a few tenths of a percent, so
during a fast turn the integrated angle is off in proportion to the angle turned. That error is
systematic over the accelerometer's averaging window, hence the ``lp_tau`` in its variance.
``Nb`` is the bias random walk.

Measurement: gravity averaged in an almost-inertial frame
---------------------------------------------------------
Real hand-held motion has its linear acceleration at 0.5-1.5 Hz and several m/s^2 (BROAD,
Laidig et al. 2021): no rejection by ``|a|`` can see a horizontal acceleration (it barely
changes ``|a|``), and no low-pass of a fraction of a second removes it. What removes it is
physics: the hand does not go anywhere, so its acceleration averages out over seconds. As VQF
does (Laidig & Seel 2023, Information Fusion 91), the specific force is rotated into the earth
frame with the current estimate, ``f = R(q) a``, and low-passed there by a second-order
Butterworth filter with time constant ``lp_tau`` (seconds; cut-off ``sqrt(2) / (2 pi lp_tau)``,
a delay of ``lp_tau`` at low frequency). Every correction ``exp(d)`` of the estimate is applied to
the filter's states too, so the filtered vector carries the *current* tilt error without lag:
only linear acceleration, noise and recent gyro errors are averaged. The residual is the
rotation that takes the filtered up direction ``v = f_lp / |f_lp|`` onto earth z::

    z = atan2(|v_xy|, v_z) * (v_y, -v_x) / |v_xy|

**The low-pass in the measurement model.** A gyro-bias error turns the estimate at the rate
``-R2 db``; the filtered vector sees that turn late, so the residual is ``z = dtheta + M db``
with ``M = D - LP(D)``, ``D`` the running sum of ``R2 dt`` and ``LP`` the same Butterworth
filter: ``H = [I2, M]``. Without ``M`` the bias states would be corrected from residuals a
second and more old and the loop oscillates; with it the bias is learnt from the averaged
gravity as fast as the averaging allows.

**Adaptive measurement noise.** The residual's variance per sample is::

    sigma^2 = (Na^2 + s_h / g^2 * lp_tau / (1 + (2 pi f_m lp_tau / sqrt 2)^4)) / (2 dt)

``Na`` is the floor (sensor noise and tremor after averaging). The second term is the
horizontal linear acceleration that leaks through the low-pass: ``s_h`` is the mean square of
the horizontal earth-frame specific force over the last second (the motion's strength), and the
fraction is the Butterworth filter's power gain at the typical frequency ``f_m`` of hand motion
(1 Hz; real hand-held translation peaks at 0.7-1.3 Hz) times its correlation time ``lp_tau``.
So while the sensor is being carried the accelerometer is trusted less in proportion to how
hard it is carried, and the gyro holds the attitude; while it only turns it is trusted fully.

Rest detection for the gyro bias
--------------------------------
As VQF: the sensor is at rest when, for ``rest_time`` seconds, the gyro stays within
``rest_gyro`` of its 0.5 s low-pass, the accelerometer within ``rest_accel`` of its own, and the
low-passed rate is itself below ``rest_gyro`` on every axis. At rest the true rate is zero, so
every gyro sample measures the bias directly: ``z = w - b``, ``H = [0, I3]``, noise
``Ng^2 / (2 dt)`` per sample. The bias (and through its covariance the tilt) is learnt in a few
seconds of rest.

After a restart (first sample, gap, bad step) the tilt is taken from the running mean of the
accelerometer (earth frame) for the first ``lp_tau`` seconds, gain 1, as VQF initialises its
low-pass; then the Kalman update takes over with tilt variance ``tilt_initial^2`` and the bias
and its covariance kept.

Tried and left out (BROAD's twelve tuning trials): chi-square gating of the innovation (soft,
inflating ``S`` until the innovation is plausible at 13.8 = chi2(2, 0.999)) made the mean worse
(0.86 against 0.82 degrees): the low-passed residual is strongly autocorrelated, so large
innovations are slow, real tilt changes the filter must follow, not outliers. The former
rejection by the low-passed ``|a|`` did not see horizontal acceleration at all.

Accuracy: ``benchmarks/filter_accuracy.py`` (BROAD's twelve trials, the simulator's scenarios,
and the sensitivity of the mean to each parameter).

Heading from the magnetic field (9-axis)
---------------------------------------
With a field (``SampleBlock.mag_ut``, NaN rows: no new sample) and the ``magnetometer`` switch
on, the output is sensor-to-earth in ENU with y toward magnetic north. The heading is a filter
of its own, a scalar Kalman filter beside the tilt's, and it never moves the tilt:

- The field sample is projected into the earth frame with the current estimate,
  ``m_e = R(q) m``; the residual is its horizontal direction's angle east of north,
  ``psi = atan2(m_e,x, m_e,y)`` (exact for any angle, independent of the tilt's Jacobian).
- The correction turns the estimate about the earth vertical alone, ``q <- Rz(k psi) q``, and
  with it every earth-frame state of the tilt filter (the low-passed specific force, the
  bias-to-tilt sums, the tilt covariance): the tilt filter then runs exactly as it would in the
  turned earth frame, so the tilt (up in the sensor frame) is the 6-axis filter's to float
  precision, now and later. The heading has no cross-covariance with the bias states: the field
  never teaches the gyro bias (that would tilt the inclination through the gyro).
- Heading variance grows by ``(Ng^2 + (ks |w|)^2 lp_tau) dt`` (gyro noise and scale error, as
  for the tilt). Measurement variance per sample::

      r = (Nm^2 + (t_m w_v)^2 T + tan^2(dip) P_n lp_tau) / dt_m

  ``Nm`` the field heading's noise density (``mag_noise``: sensor noise and the calibration's
  residual, which changes as the sensor turns: on BROAD it is large, the gyro holds the heading
  over tens of seconds), ``t_m`` the field's timing uncertainty against the gyro times the
  vertical rate ``w_v`` (a late field sample is turned by ``t_m w_v``; ``T`` =
  :data:`MOTION_WINDOW_S`), ``P_n`` the tilt variance about the field's horizontal direction
  (a tilt error ``d`` turns the projected field's heading by ``tan(dip) d``), ``dt_m`` the time
  since the previous field sample. The first field sample after a restart sets the heading
  (gain 1); later ones average it in, like VQF's ``kMagInit``.
- Disturbances: :mod:`app.core.magnetometer.disturbance` (strength and dip against a reference
  learnt here; rejected samples leave the heading to the gyro, whose growing variance gives a
  fast re-acquisition afterwards). ``field_status`` exposes its output for the window.

Noted limits: the tilt is referred to the accelerometer, so any uncompensated accelerometer
bias tilts it (20 mg = 1.1 degrees); the heading is only as good as the magnetometer's
calibration (a residual of a few percent is a few degrees of heading).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.filters.base import MAGNETOMETER_PARAMETER, OrientationFilter, ParameterSpec
from app.core.filters.complementary import gyro_step
from app.core.filters.gyro_integration import unit_positive
from app.core.magnetometer import disturbance
from app.core.magnetometer.disturbance import (
    NO_SAMPLE,
    REDUCED,
    REJECTED,
    S_REF_DIP,
    S_REF_NORM,
    DisturbanceOwner,
    FieldStatus,
    detector_step,
    track_rate,
)
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

N_STATES = 5
"""Error state: horizontal earth-frame tilt error (2), gyro-bias error (3)."""

REST_FILTER_S = 0.5
"""Time constant of the low-passes the rest detector compares the raw signals with (VQF's)."""
MOTION_WINDOW_S = 1.0
"""Time constant of the running mean square of the horizontal specific force (motion strength)."""

# Layout of the filter's auxiliary state vector (``_aux``).
_Y, _V = 0, 3  # Butterworth low-pass of f: output (3) and its rate (3)
_D, _LD, _LV = 6, 12, 18  # running sum of R2 dt (2x3), its low-pass (2x3) and rate (2x3)
_GL, _AL = 24, 27  # rest detector: low-passed gyro (3) and accelerometer (3)
_COUNT, _SINCE, _REST, _MOTION = 30, 31, 32, 33
N_AUX = 34


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
def _correct(quat, aux, d0, d1):  # pragma: no cover - compiled
    """Apply the earth-frame tilt correction exp((d0, d1, 0)) to q and to the low-pass states."""
    angle = math.sqrt(d0 * d0 + d1 * d1)
    if angle <= 0.0:
        return
    half = 0.5 * angle
    k = math.sin(half) / angle
    ew = math.cos(half)
    ex = d0 * k
    ey = d1 * k
    qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
    quat[0] = ew * qw - ex * qx - ey * qy
    quat[1] = ew * qx + ex * qw + ey * qz
    quat[2] = ew * qy - ex * qz + ey * qw
    quat[3] = ew * qz + ex * qy - ey * qx
    # The filtered vectors were rotated with the old estimate: rotate them too.
    for j in (_Y, _V):
        aux[j], aux[j + 1], aux[j + 2] = _rotate_horizontal(
            ew, ex, ey, aux[j], aux[j + 1], aux[j + 2]
        )


@njit(cache=True, inline="always")
def _turn(quat, aux, P, angle):  # pragma: no cover - compiled
    """Turn the estimate by ``angle`` (rad) about the earth vertical, and every earth-frame
    state with it (the low-passed specific force, the bias-to-tilt sums, the tilt covariance):
    the filter then runs exactly as it would have in the turned earth frame, so its tilt
    (sensor frame) is unchanged now and later."""
    half = 0.5 * angle
    c = math.cos(half)
    s = math.sin(half)
    qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
    quat[0] = c * qw - s * qz
    quat[1] = c * qx - s * qy
    quat[2] = c * qy + s * qx
    quat[3] = c * qz + s * qw
    cc = c * c - s * s
    ss = 2.0 * s * c
    for j in (_Y, _V):
        x, y = aux[j], aux[j + 1]
        aux[j] = cc * x - ss * y
        aux[j + 1] = ss * x + cc * y
    for base in (_D, _LD, _LV):
        for k in range(3):
            x, y = aux[base + k], aux[base + 3 + k]
            aux[base + k] = cc * x - ss * y
            aux[base + 3 + k] = ss * x + cc * y
    p00, p01, p11 = P[0, 0], P[0, 1], P[1, 1]
    a00 = cc * p00 - ss * p01
    a01 = cc * p01 - ss * p11
    a10 = ss * p00 + cc * p01
    a11 = ss * p01 + cc * p11
    P[0, 0] = a00 * cc - a01 * ss
    P[1, 1] = a10 * ss + a11 * cc
    P[0, 1] = P[1, 0] = a10 * cc - a11 * ss
    for k in range(2, 5):
        x, y = P[0, k], P[1, k]
        P[0, k] = P[k, 0] = cc * x - ss * y
        P[1, k] = P[k, 1] = ss * x + cc * y


@njit(cache=True, inline="always")
def _heading_update(  # pragma: no cover - compiled
    quat, aux, P, head, mag_state, mag_settings, mag_var_density, timing_var, tilt_coupling,
    yaw_rate, mx, my, mz, at_rest, field_row,
):
    """One field sample: disturbance check, then a scalar Kalman update of the heading alone
    (the field's horizontal direction in the earth frame against north, +y). ``field_row``
    receives (status, strength deviation, dip deviation in rad)."""
    qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
    tx = 2.0 * (qy * mz - qz * my)
    ty = 2.0 * (qz * mx - qx * mz)
    tz = 2.0 * (qx * my - qy * mx)
    ex = mx + qw * tx + qy * tz - qz * ty
    ey = my + qw * ty + qz * tx - qx * tz
    ez = mz + qw * tz + qx * ty - qy * tx
    norm = math.sqrt(ex * ex + ey * ey + ez * ez)
    dip = math.asin(max(-1.0, min(1.0, -ez / norm)))
    since = head[1]
    status = detector_step(mag_state, mag_settings, norm, dip, since, at_rest)
    field_row[0] = status
    ref = mag_state[S_REF_NORM]
    if ref > 0.0:
        field_row[1] = norm / ref - 1.0
        field_row[2] = dip - mag_state[S_REF_DIP]
    else:
        field_row[1] = math.nan
        field_row[2] = math.nan
    head[1] = 0.0
    if status == REJECTED or ex * ex + ey * ey <= 0.0:
        return
    h2 = ex * ex + ey * ey
    # A tilt error about the field's horizontal direction n turns its heading by tan(dip)
    # times that error, and the tilt error lasts about the gravity averaging time.
    tilt_n = (ex * ex * P[0, 0] + ey * ey * P[1, 1] + 2.0 * ex * ey * P[0, 1]) / h2
    r = (mag_var_density + timing_var * yaw_rate * yaw_rate * MOTION_WINDOW_S
         + tilt_coupling * ez * ez / h2 * tilt_n) / max(since, 1e-3)
    if status == REDUCED:
        factor = mag_settings[disturbance.C_REJECT_FACTOR]
        r *= factor * factor
    if head[0] < 0.0:  # no heading yet: take the field's
        gain = 1.0
        head[0] = r
    else:
        gain = head[0] / (head[0] + r)
        head[0] *= 1.0 - gain
    _turn(quat, aux, P, gain * math.atan2(ex, ey))


@njit(cache=True)
def _ekf_kernel(  # noqa: C901 - one compiled pass: a split costs a call per sample
    accel, gyro, dt, quat, bias, cov, aux, gyro_var_density, scale_var, bias_var_density,
    accel_var_density, lp_tau, motion_gain, tilt0_var, estimate_bias, rest_gyro2, rest_accel2,
    rest_time, rest_clip, gravity, mag, head, mag_state, mag_settings, mag_var_density,
    timing_var, tilt_time, out_field, out, out_var,
):  # pragma: no cover - compiled
    """Run the filter over a block; ``quat``, ``bias``, ``cov`` and ``aux`` are updated.

    Densities are squared: rad^2/s (gyro), rad^2/s^3 (bias walk), (fraction of g)^2 s (accel);
    ``scale_var`` is the squared gyro scale uncertainty, ``motion_gain`` the low-pass leak of
    the motion's power (s), ``rest_*2`` squared thresholds (rad^2/s^2, m^2/s^4). When
    ``out_var`` has a row per sample it receives the tilt-error variance (rad^2, the mean of
    the two horizontal axes) after each sample; an empty ``out_var`` skips that.

    Heading: ``mag`` (N, 3) uT with NaN rows, or empty (no heading update at all: the 6-axis
    filter, bit for bit); ``head`` = (heading variance rad^2, -1 before the first field
    sample; time since the last field sample), ``mag_state`` / ``mag_settings`` the
    disturbance detector's, ``mag_var_density`` the field heading's noise density (rad^2 s);
    ``out_field`` (N, 3) or empty receives the detector's output per row.
    """
    keep_var = out_var.shape[0] == accel.shape[0]
    use_mag = mag.shape[0] == accel.shape[0]
    keep_field = use_mag and out_field.shape[0] == accel.shape[0]
    P = cov
    G = np.zeros((2, 3))
    GPbb = np.zeros((2, 3))
    H = np.zeros((2, 5))
    PHt = np.zeros((5, 2))
    K = np.zeros((5, 2))
    row = np.zeros(5)
    wc = math.sqrt(2.0) / lp_tau if lp_tau > 0.0 else 0.0
    if not estimate_bias:
        P[:2, 2:] = 0.0
        P[2:, :] = 0.0
    for i in range(accel.shape[0]):
        step = dt[i]
        wx, wy, wz = gyro[i, 0], gyro[i, 1], gyro[i, 2]
        if not wx * wx + wy * wy + wz * wz < math.inf:  # NaN/inf: trust the bias only
            wx, wy, wz = bias[0], bias[1], bias[2]
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        if step > 0.0:
            # ---- predict ---------------------------------------------------------------
            qw, qx, qy, qz = gyro_step(quat[0], quat[1], quat[2], quat[3],
                                       wx - bias[0], wy - bias[1], wz - bias[2], step)
            quat[0], quat[1], quat[2], quat[3] = qw, qx, qy, qz
            # G = -dt R2: how a body-frame bias error turns the earth-frame tilt.
            G[0, 0] = -step * (1.0 - 2.0 * (qy * qy + qz * qz))
            G[0, 1] = -step * 2.0 * (qx * qy - qw * qz)
            G[0, 2] = -step * 2.0 * (qx * qz + qw * qy)
            G[1, 0] = -step * 2.0 * (qx * qy + qw * qz)
            G[1, 1] = -step * (1.0 - 2.0 * (qx * qx + qz * qz))
            G[1, 2] = -step * 2.0 * (qy * qz - qw * qx)
            if estimate_bias:
                # Ptt += G Pbt + Ptb G^T + G Pbb G^T;  Ptb += G Pbb;  Pbb += Qb
                for r in range(2):
                    for c in range(3):
                        GPbb[r, c] = (G[r, 0] * P[2, 2 + c] + G[r, 1] * P[3, 2 + c]
                                      + G[r, 2] * P[4, 2 + c])
                for r in range(2):
                    for c in range(r, 2):
                        s = 0.0
                        for k in range(3):
                            s += G[r, k] * P[2 + k, c] + P[r, 2 + k] * G[c, k]
                            s += GPbb[r, k] * G[c, k]
                        P[r, c] += s
                    for c in range(3):
                        P[r, 2 + c] += GPbb[r, c]
                q_bias = bias_var_density * step
                P[2, 2] += q_bias
                P[3, 3] += q_bias
                P[4, 4] += q_bias
            q_tilt = (0.5 * gyro_var_density
                      + scale_var * (wx * wx + wy * wy + wz * wz) * lp_tau) * step
            P[0, 0] += q_tilt
            P[1, 1] += q_tilt
            P[1, 0] = P[0, 1]
            for r in range(2):
                for c in range(3):
                    P[2 + c, r] = P[r, 2 + c]
                    aux[_D + 3 * r + c] -= G[r, c]  # D += R2 dt
            if use_mag:
                if head[0] >= 0.0:
                    head[0] += (gyro_var_density
                                + scale_var * (wx * wx + wy * wy + wz * wz) * lp_tau) * step
                head[1] += step
                track_rate(mag_state, wx - bias[0], wy - bias[1], wz - bias[2], step)
        else:
            # ---- restart: tilt from the accelerometer, bias and its covariance kept -------
            P[0, 0] = P[1, 1] = tilt0_var
            P[0, 1] = P[1, 0] = 0.0
            P[:2, 2:] = 0.0
            P[2:, :2] = 0.0
            aux[_COUNT] = 0.0
            aux[_SINCE] = 0.0
            aux[_REST] = 0.0
            aux[_GL], aux[_GL + 1], aux[_GL + 2] = wx, wy, wz
            aux[_AL], aux[_AL + 1], aux[_AL + 2] = ax, ay, az
            if use_mag:  # the heading after a gap is unknown: taken afresh from the field
                head[0] = -1.0
                head[1] = 0.0
                track_rate(mag_state, wx, wy, wz, 0.0)
        aux[_SINCE] += step
        # ---- rest: the gyro measures its own bias -------------------------------------
        if estimate_bias and step > 0.0 and rest_time > 0.0:
            alpha = step / (REST_FILTER_S + step)
            aux[_GL] += alpha * (wx - aux[_GL])
            aux[_GL + 1] += alpha * (wy - aux[_GL + 1])
            aux[_GL + 2] += alpha * (wz - aux[_GL + 2])
            aux[_AL] += alpha * (ax - aux[_AL])
            aux[_AL + 1] += alpha * (ay - aux[_AL + 1])
            aux[_AL + 2] += alpha * (az - aux[_AL + 2])
            gyro_dev = (wx - aux[_GL]) ** 2 + (wy - aux[_GL + 1]) ** 2 + (wz - aux[_GL + 2]) ** 2
            accel_dev = (ax - aux[_AL]) ** 2 + (ay - aux[_AL + 1]) ** 2 + (az - aux[_AL + 2]) ** 2
            still = (gyro_dev < rest_gyro2 and accel_dev < rest_accel2
                     and abs(aux[_GL]) < rest_clip and abs(aux[_GL + 1]) < rest_clip
                     and abs(aux[_GL + 2]) < rest_clip)
            aux[_REST] = aux[_REST] + step if still else 0.0
            if aux[_REST] >= rest_time:
                r = 0.5 * gyro_var_density / step
                for axis in range(3):
                    j = 2 + axis
                    rate = wx if axis == 0 else (wy if axis == 1 else wz)
                    innovation = rate - bias[axis]
                    s = P[j, j] + r
                    for k in range(5):
                        row[k] = P[j, k]
                    for k in range(3):
                        bias[k] += row[2 + k] / s * innovation
                    for a in range(5):
                        for b in range(5):
                            P[a, b] -= row[a] * row[b] / s
                    _correct(quat, aux, row[0] / s * innovation, row[1] / s * innovation)
        # ---- update: the averaged gravity direction -----------------------------------
        norm2 = ax * ax + ay * ay + az * az
        if norm2 > 0.0 and norm2 < math.inf:
            qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
            # f = R(q) a, the specific force in the earth frame (m/s^2).
            tx = 2.0 * (qy * az - qz * ay)
            ty = 2.0 * (qz * ax - qx * az)
            tz = 2.0 * (qx * ay - qy * ax)
            fx = ax + qw * tx + qy * tz - qz * ty
            fy = ay + qw * ty + qz * tx - qx * tz
            fz = az + qw * tz + qx * ty - qy * tx
            horizontal = (fx * fx + fy * fy) / (gravity * gravity)
            if step > 0.0:
                aux[_MOTION] += step / (MOTION_WINDOW_S + step) * (horizontal - aux[_MOTION])
            warming = step == 0.0 or aux[_SINCE] < lp_tau
            if lp_tau > 0.0:
                if warming or aux[_COUNT] == 0.0:
                    # A running mean until the low-pass takes over (start-up).
                    aux[_COUNT] += 1.0
                    alpha = 1.0 / aux[_COUNT]
                    aux[_Y] += alpha * (fx - aux[_Y])
                    aux[_Y + 1] += alpha * (fy - aux[_Y + 1])
                    aux[_Y + 2] += alpha * (fz - aux[_Y + 2])
                    for k in range(3):
                        aux[_V + k] = 0.0
                    for k in range(6):
                        aux[_LD + k] = aux[_D + k]
                        aux[_LV + k] = 0.0
                else:
                    # Second-order Butterworth, backward Euler (stable for any step).
                    a2 = step * wc * wc
                    den = 1.0 + step * math.sqrt(2.0) * wc + step * a2
                    u0 = fx - aux[_Y]
                    u1 = fy - aux[_Y + 1]
                    u2 = fz - aux[_Y + 2]
                    aux[_V] = (aux[_V] + a2 * u0) / den
                    aux[_V + 1] = (aux[_V + 1] + a2 * u1) / den
                    aux[_V + 2] = (aux[_V + 2] + a2 * u2) / den
                    aux[_Y] += step * aux[_V]
                    aux[_Y + 1] += step * aux[_V + 1]
                    aux[_Y + 2] += step * aux[_V + 2]
                    for k in range(6):
                        aux[_LV + k] = (aux[_LV + k] + a2 * (aux[_D + k] - aux[_LD + k])) / den
                        aux[_LD + k] += step * aux[_LV + k]
                vx, vy, vz = aux[_Y], aux[_Y + 1], aux[_Y + 2]
            else:
                vx, vy, vz = fx, fy, fz
            z0, z1 = tilt_residual(vx, vy, vz)
            if warming:
                _correct(quat, aux, z0, z1)
            else:
                # ---- Kalman update, H = [I2, M], M = D - LP(D) ------------------------------
                for r in range(2):
                    H[r, 0] = 1.0 - r
                    H[r, 1] = float(r)
                    for c in range(3):
                        H[r, 2 + c] = (aux[_D + 3 * r + c] - aux[_LD + 3 * r + c]
                                       if estimate_bias else 0.0)
                for a in range(5):
                    for r in range(2):
                        PHt[a, r] = (P[a, 0] * H[r, 0] + P[a, 1] * H[r, 1] + P[a, 2] * H[r, 2]
                                     + P[a, 3] * H[r, 3] + P[a, 4] * H[r, 4])
                noise = 0.5 * (accel_var_density + motion_gain * aux[_MOTION]) / step
                s00 = noise
                s01 = 0.0
                s11 = noise
                for k in range(5):
                    s00 += H[0, k] * PHt[k, 0]
                    s01 += H[0, k] * PHt[k, 1]
                    s11 += H[1, k] * PHt[k, 1]
                det = s00 * s11 - s01 * s01
                i00 = s11 / det
                i01 = -s01 / det
                i11 = s00 / det
                for a in range(5):
                    K[a, 0] = PHt[a, 0] * i00 + PHt[a, 1] * i01
                    K[a, 1] = PHt[a, 0] * i01 + PHt[a, 1] * i11
                if estimate_bias:
                    for k in range(3):
                        bias[k] += K[2 + k, 0] * z0 + K[2 + k, 1] * z1
                # P <- P - K H P = P - K (P H^T)^T, kept symmetric.
                for a in range(5):
                    for b in range(a, 5):
                        value = P[a, b] - (K[a, 0] * PHt[b, 0] + K[a, 1] * PHt[b, 1])
                        P[a, b] = value
                        P[b, a] = value
                _correct(quat, aux, K[0, 0] * z0 + K[0, 1] * z1, K[1, 0] * z0 + K[1, 1] * z1)
        # ---- heading: the field's horizontal direction (tilt untouched) ---------------------
        if use_mag:
            mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
            if mx * mx + my * my + mz * mz > 0.0 and mx * mx + my * my + mz * mz < math.inf:
                at_rest = rest_time > 0.0 and aux[_REST] >= rest_time
                qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
                yaw_rate = (2.0 * (qx * qz - qw * qy) * (wx - bias[0])
                            + 2.0 * (qy * qz + qw * qx) * (wy - bias[1])
                            + (1.0 - 2.0 * (qx * qx + qy * qy)) * (wz - bias[2]))
                _heading_update(quat, aux, P, head, mag_state, mag_settings, mag_var_density,
                                timing_var, tilt_time, yaw_rate, mx, my, mz,
                                at_rest, row[:3])
                if keep_field:
                    out_field[i, 0], out_field[i, 1], out_field[i, 2] = row[0], row[1], row[2]
            elif keep_field:
                out_field[i, 0] = NO_SAMPLE
                out_field[i, 1] = math.nan
                out_field[i, 2] = math.nan
        qw, qx, qy, qz = unit_positive(quat[0], quat[1], quat[2], quat[3])
        quat[0], quat[1], quat[2], quat[3] = qw, qx, qy, qz
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
        if keep_var:
            out_var[i] = 0.5 * (P[0, 0] + P[1, 1])


def butterworth_power_gain(tau_s: float, frequency_hz: float) -> float:
    """Power gain of the second-order Butterworth low-pass (time constant ``tau_s``) at a
    frequency: ``1 / (1 + (2 pi f tau / sqrt 2)^4)``; 1 without a low-pass."""
    if tau_s <= 0.0:
        return 1.0
    ratio = 2.0 * math.pi * frequency_hz * tau_s / math.sqrt(2.0)
    return 1.0 / (1.0 + ratio**4)


class QuaternionEKF(DisturbanceOwner, OrientationFilter):
    """Error-state quaternion EKF with gyro-bias estimation, for real hand-held motion.

    See the module docstring for the model. The state survives between blocks and across
    parameter changes; a restart (gap) re-takes the tilt from the accelerometer and keeps the
    bias estimate.
    """

    name = "ekf"
    title = "Quaternion EKF"
    uses_magnetometer = True
    description = (
        "Error-state Kalman filter: gyro propagation with bias estimation (in motion and, "
        "faster, at rest), corrected by gravity averaged over seconds in an almost-inertial "
        "frame; the accelerometer's weight drops in proportion to how hard the sensor is moved. "
        "With a magnetometer, heading from the field (about the vertical only), with magnetic "
        "disturbance rejection."
    )
    parameters = (
        ParameterSpec(
            "gyro_noise", "Gyro noise density", "mdps/√Hz", 3.8, 0.1, 1000.0,
            "White rate noise of the gyroscope (LSM6DSOX datasheet: 3.8 mdps/√Hz). Also the "
            "noise of the bias measured at rest.",
            log_scale=True,
        ),
        ParameterSpec(
            "gyro_scale_error", "Gyro scale uncertainty", "%", 0.3, 0.0, 10.0,
            "Scale-factor and cross-axis uncertainty of the gyroscope: during a turn the "
            "integrated angle is off by this fraction of the angle turned, so the filter leans "
            "on the accelerometer more while the sensor turns fast. 0: a perfect gyro.",
        ),
        ParameterSpec(
            "bias_drift", "Gyro bias drift", "mdps/√s", 3.0, 0.0, 1000.0,
            "Random walk of the gyro bias: how fast the filter lets its bias estimate move. "
            "The default follows self-heating (0.01 dps/°C over a few °C in minutes), well "
            "above the chip's few °/h bias instability. 0: a constant bias.",
            log_scale=True,
        ),
        ParameterSpec(
            "bias_initial", "Initial bias uncertainty", "dps", 0.5, 0.0, 10.0,
            "1-sigma gyro bias expected at start (an uncalibrated LSM6DSOX has up to ±1 dps). "
            "Used at reset.",
            log_scale=True,
        ),
        ParameterSpec(
            "accel_noise", "Gravity noise floor", "µg/√Hz", 100.0, 1.0, 1e6,
            "Noise density of the averaged gravity direction when the sensor is not carried "
            "(sensor noise and tremor left after the low-pass). Larger: smoother, slower.",
            log_scale=True,
        ),
        ParameterSpec(
            "lp_tau", "Gravity averaging time", "s", 2.0, 0.0, 30.0,
            "Time constant of the second-order low-pass applied to the accelerometer in the "
            "earth frame: hand motion averages out over it (a hand does not go anywhere). "
            "Also the start-up averaging time after a restart. 0: each sample as it is.",
            log_scale=True,
        ),
        ParameterSpec(
            "motion_frequency", "Typical motion frequency", "Hz", 1.0, 0.0, 100.0,
            "Frequency of the linear acceleration the sensor is carried with (hand-held: "
            "0.7-1.3 Hz). Sets how much of the motion's strength leaks through the low-pass, "
            "and so how much the accelerometer is trusted less while the sensor is moved. "
            "0: no adaptation (the accelerometer is always trusted alike).",
        ),
        ParameterSpec(
            "rest_gyro", "Rest: gyro threshold", "dps", 2.0, 0.0, 100.0,
            "The sensor is at rest while the gyro stays within this of its 0.5 s average "
            "(and that average below it); at rest every gyro sample measures the bias.",
        ),
        ParameterSpec(
            "rest_accel", "Rest: accelerometer threshold", "mg", 50.0, 0.0, 1000.0,
            "At rest the accelerometer stays within this of its 0.5 s average.",
        ),
        ParameterSpec(
            "rest_time", "Rest: minimum time", "s", 1.5, 0.0, 60.0,
            "How long both must hold before the bias is taken from the gyro. 0: off.",
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
        MAGNETOMETER_PARAMETER,
        ParameterSpec(
            "mag_noise", "Field heading noise density", "°·√s", 16.0, 0.01, 1000.0,
            "Noise density of the heading read from the magnetic field (sensor noise and the "
            "calibration's residual, which changes as the sensor turns). Against the gyro's "
            "noise and scale error it sets how fast the heading follows the field: slowly at "
            "rest, faster while the sensor turns fast.",
            log_scale=True,
        ),
        ParameterSpec(
            "mag_timing", "Field timing uncertainty", "ms", 5.0, 0.0, 1000.0,
            "How far the field sample may be off in time against the gyroscope (the "
            "magnetometer's output period, its filter's delay): while the sensor turns about "
            "the vertical this turns the field's heading by the rate times the lag, so the "
            "field is trusted less the faster the sensor turns.",
        ),
        ParameterSpec(
            "mag_rejection", "Magnetic disturbance rejection", "", True, False, True,
            "While the field's strength or dip departs from the reference learnt here, the "
            "gyroscope carries the heading. Off: every field sample is used.",
            kind="bool",
        ),
        ParameterSpec(
            "mag_norm_threshold", "Disturbance: field strength band", "%", 15.0, 0.1, 100.0,
            "The field is disturbed while its strength departs from the reference by more "
            "than this. It must clear the spread an undisturbed sensor shows while it turns "
            "(the calibration's residual: up to 10 % on BROAD's sensor, whose 5 % band rejects "
            "good field; VQF uses 10 %).",
        ),
        ParameterSpec(
            "mag_dip_threshold", "Disturbance: dip band", "deg", 10.0, 0.1, 90.0,
            "The field is disturbed while its dip departs from the reference by more than "
            "this.",
        ),
        ParameterSpec(
            "mag_rejection_time", "Disturbance: longest rejection", "s", 60.0, 0.0, 3600.0,
            "After this long disturbed the field is used again at a reduced weight (a "
            "gyro-only heading drifts without bound).",
        ),
        ParameterSpec(
            "mag_new_time", "Disturbance: new field after", "s", 20.0, 0.1, 3600.0,
            "A field that keeps its strength and dip for this long while the sensor turns "
            "becomes the new reference (a magnet attached for good, another room).",
        ),
    )


    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._bias = np.zeros(3)
        self._aux = np.zeros(N_AUX)
        self._head = np.array([-1.0, 0.0])
        self._heading_tracked = True
        self._mag_state = disturbance.new_state()
        self._field_status: FieldStatus | None = None
        tilt_var = math.radians(float(self._values["tilt_initial"])) ** 2
        self._cov = np.diag([tilt_var, tilt_var, 0.0, 0.0, 0.0])
        self._reset_bias_covariance()
        if initial_quat is not None:
            # Taking over mid-stream: no start-up averaging; the given attitude is trusted like
            # a settled estimate (1 degree), not like a fresh start.
            self._aux[_SINCE] = np.inf
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

    @property
    def at_rest(self) -> bool:
        """True while the rest detector holds (the bias is being measured directly)."""
        return bool(self._aux[_REST] >= float(self._values["rest_time"]) > 0.0)

    def kernel_arguments(self) -> tuple:
        """The parameter arguments of the compiled kernel, in SI units (for the smoother)."""
        v = self._values
        tau = float(v["lp_tau"])
        frequency = float(v["motion_frequency"])
        if frequency <= 0.0:
            motion_gain = 0.0
        elif tau <= 0.0:
            motion_gain = MOTION_WINDOW_S  # no low-pass: the whole motion reaches the update
        else:
            motion_gain = tau * butterworth_power_gain(tau, frequency)
        rest_gyro = math.radians(float(v["rest_gyro"]))
        rest_accel = float(v["rest_accel"]) * 1e-3 * STANDARD_GRAVITY_M_S2
        return (
            math.radians(float(v["gyro_noise"]) * 1e-3) ** 2,
            (float(v["gyro_scale_error"]) * 1e-2) ** 2,
            math.radians(float(v["bias_drift"]) * 1e-3) ** 2,
            (float(v["accel_noise"]) * 1e-6) ** 2,
            tau,
            motion_gain,
            math.radians(float(v["tilt_initial"])) ** 2,
            bool(v["estimate_bias"]),
            rest_gyro * rest_gyro,
            rest_accel * rest_accel,
            float(v["rest_time"]),
            rest_gyro,
            STANDARD_GRAVITY_M_S2,
        )

    def _process(self, block: SampleBlock) -> np.ndarray:
        return self.run_with_variance(block, np.empty(0))

    def run_with_variance(self, block: SampleBlock, tilt_var: np.ndarray) -> np.ndarray:
        """Quaternions for ``block`` (state carried on); ``tilt_var`` (N,) or empty receives
        the tilt-error variance per sample (rad^2)."""
        n = len(block)
        out = np.empty((n, 4))
        quat = np.array(self._quat, dtype=np.float64)
        bias = self._bias.copy()
        cov = self._cov.copy()
        aux = self._aux.copy()
        head = self._head.copy()
        mag_state = self._mag_state.copy()
        use_mag = block.mag_ut is not None and bool(self._values["magnetometer"])
        mag = (np.ascontiguousarray(block.mag_ut, dtype=np.float64) if use_mag
               else np.empty((0, 3)))
        field_rows = np.empty((n, 3)) if use_mag else np.empty((0, 3))
        if use_mag and not self._heading_tracked:
            # The heading ran on the gyro alone (switch off, no field): its variance was not
            # kept, so the next field sample sets it afresh.
            head[0] = -1.0
        self._heading_tracked = use_mag
        settings = self.disturbance_settings()
        _ekf_kernel(
            np.ascontiguousarray(block.accel_m_s2, dtype=np.float64),
            np.ascontiguousarray(block.gyro_rad_s, dtype=np.float64),
            self.time_steps(block),
            quat, bias, cov, aux,
            *self.kernel_arguments(),
            mag, head, mag_state, settings.as_array(self._field_reference),
            math.radians(float(self._values["mag_noise"])) ** 2,
            (float(self._values["mag_timing"]) * 1e-3) ** 2,
            float(self._values["lp_tau"]),
            field_rows, out, tilt_var,
        )
        self._bias, self._cov, self._aux = bias, cov, aux
        self._head, self._mag_state = head, mag_state
        self._field_status = (disturbance.field_status(field_rows, mag_state, settings,
                                                       self._field_reference)
                              if use_mag else None)
        return out
