"""Madgwick's gradient-descent orientation filter, IMU form (gyro + accelerometer).

Source: S. O. H. Madgwick, "An efficient orientation filter for inertial and inertial/magnetic
sensor arrays", report, University of Bristol, 2010, as in the thesis listing. Per sample,
with the accelerometer ``a`` normalised::

    f    = [2(q1 q3 - q0 q2) - ax,  2(q0 q1 + q2 q3) - ay,  2(0.5 - q1^2 - q2^2) - az]
    step = J^T f / |J^T f|
    qdot = 0.5 q (x) (0, w) - beta step
    q    = normalise(q + qdot dt)           (first-order integration, as Madgwick does)

Conventions: Madgwick's ``^S_E q`` is called "the orientation of the earth frame relative to the
sensor frame", but his objective function reads ``f = q* (x) d_E (x) q - s_S``, i.e. it maps
earth vectors into the sensor frame with ``q* v q``. That is exactly our sensor-to-earth
quaternion (``v_earth = q v_sensor q*``): the formulas apply unchanged, ``f``'s first three terms
are :func:`app.core.orientation.up_in_sensor_frame`, and the body rate multiplies on the right.

MARG form (the report's section 3.4, with a magnetometer): the objective gains the field's
rows, ``f_m = R(q)^T b - m`` with ``m`` the normalised field and ``b`` its earth-frame reference
(:mod:`app.core.filters.marg`: ENU, y toward magnetic north, so ``b = (0, b_y, b_z)`` where the
report has ``(b_x, 0, b_z)``), and ``J^T f`` sums both parts before the one normalised step.
Without a field in the block (no magnetometer, or the switch off) the IMU form above runs,
exactly as before.

The normalised step makes the correction a constant-rate slew of at most about ``2 beta``
rad/s towards the accelerometer's tilt: a gyro bias below that is rejected, and the estimate
chatters by about ``2 beta dt`` per sample around the accelerometer's answer.
"""

from __future__ import annotations

import copy
import math

import numpy as np
from numba import njit

from app.core.filters.base import MAGNETOMETER_PARAMETER, ParameterSpec
from app.core.filters.complementary import tilt_correct
from app.core.filters.gyro_integration import AccelStartedFilter, unit_positive, usable_vector
from app.core.filters.marg import (
    field_in_earth,
    heading_from_field,
    no_field,
    step_field,
    warm_up_block,
)
from app.core.samples import SampleBlock


@njit(cache=True)
def madgwick_step(qw, qx, qy, qz, gx, gy, gz, ax, ay, az, beta, dt):  # pragma: no cover
    """One IMU update of a unit quaternion; the accelerometer part is skipped if unusable."""
    if not gx * gx + gy * gy + gz * gz < math.inf:  # NaN or inf: no gyro information
        gx = 0.0
        gy = 0.0
        gz = 0.0
    # Rate of change from the gyro, 0.5 q (x) (0, w)
    dw = 0.5 * (-qx * gx - qy * gy - qz * gz)
    dx = 0.5 * (qw * gx + qy * gz - qz * gy)
    dy = 0.5 * (qw * gy - qx * gz + qz * gx)
    dz = 0.5 * (qw * gz + qx * gy - qy * gx)
    if usable_vector(ax, ay, az):
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        ax /= norm
        ay /= norm
        az /= norm
        # Objective function for the earth's up d = (0, 0, 1), and J^T f with its Jacobian J.
        f0 = 2.0 * (qx * qz - qw * qy) - ax
        f1 = 2.0 * (qw * qx + qy * qz) - ay
        f2 = 2.0 * (0.5 - qx * qx - qy * qy) - az
        s0 = -2.0 * qy * f0 + 2.0 * qx * f1
        s1 = 2.0 * qz * f0 + 2.0 * qw * f1 - 4.0 * qx * f2
        s2 = -2.0 * qw * f0 + 2.0 * qz * f1 - 4.0 * qy * f2
        s3 = 2.0 * qx * f0 + 2.0 * qy * f1
        s_norm = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3)
        if s_norm > 0.0:  # zero when converged exactly (or exactly upside down: a saddle)
            k = beta / s_norm
            dw -= k * s0
            dx -= k * s1
            dy -= k * s2
            dz -= k * s3
    # First-order integration, then back onto the unit sphere.
    return unit_positive(qw + dw * dt, qx + dx * dt, qy + dy * dt, qz + dz * dt)


@njit(cache=True)
def _madgwick_kernel(accel, gyro, dt, q0, beta, pending, out):  # pragma: no cover - compiled
    qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    for i in range(accel.shape[0]):
        step = dt[i]
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        if (step <= 0.0 or pending) and usable_vector(ax, ay, az):
            # (Re)start: the accelerometer's tilt, heading kept.
            qw, qx, qy, qz = unit_positive(*tilt_correct(qw, qx, qy, qz, ax, ay, az, 1.0))
            pending = False
        elif step <= 0.0:
            pending = True  # hold until a usable accelerometer sample
        else:
            qw, qx, qy, qz = madgwick_step(
                qw, qx, qy, qz, gyro[i, 0], gyro[i, 1], gyro[i, 2], ax, ay, az, beta, step
            )
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
    return pending


@njit(cache=True)
def madgwick_marg_step(qw, qx, qy, qz, gx, gy, gz, ax, ay, az, mx, my, mz, beta,
                       dt):  # pragma: no cover - compiled
    """One MARG update; the IMU update when the field is unusable, none when the accelerometer
    is (as the report's code)."""
    if not (usable_vector(ax, ay, az) and usable_vector(mx, my, mz)):
        return madgwick_step(qw, qx, qy, qz, gx, gy, gz, ax, ay, az, beta, dt)
    if not gx * gx + gy * gy + gz * gz < math.inf:
        gx = 0.0
        gy = 0.0
        gz = 0.0
    dw = 0.5 * (-qx * gx - qy * gy - qz * gz)
    dx = 0.5 * (qw * gx + qy * gz - qz * gy)
    dy = 0.5 * (qw * gy - qx * gz + qz * gx)
    dz = 0.5 * (qw * gz + qx * gy - qy * gx)
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    ax /= norm
    ay /= norm
    az /= norm
    norm = math.sqrt(mx * mx + my * my + mz * mz)
    mx /= norm
    my /= norm
    mz /= norm
    hx, hy, hz = field_in_earth(qw, qx, qy, qz, mx, my, mz)
    by = math.sqrt(hx * hx + hy * hy)
    bz = hz
    # Rows y and z of R(q): R^T e_y and R^T e_z.
    r1x = 2.0 * (qx * qy + qw * qz)
    r1y = 1.0 - 2.0 * (qx * qx + qz * qz)
    r1z = 2.0 * (qy * qz - qw * qx)
    r2x = 2.0 * (qx * qz - qw * qy)
    r2y = 2.0 * (qw * qx + qy * qz)
    r2z = 1.0 - 2.0 * (qx * qx + qy * qy)
    f0 = r2x - ax
    f1 = r2y - ay
    f2 = r2z - az
    f3 = by * r1x + bz * r2x - mx
    f4 = by * r1y + bz * r2y - my
    f5 = by * r1z + bz * r2z - mz
    # J^T f: d(r2)/dq against the gravity rows, d(by r1 + bz r2)/dq against the field rows.
    s0 = (-2.0 * qy * f0 + 2.0 * qx * f1
          + f3 * (2.0 * by * qz - 2.0 * bz * qy) + f4 * (2.0 * bz * qx)
          + f5 * (-2.0 * by * qx))
    s1 = (2.0 * qz * f0 + 2.0 * qw * f1 - 4.0 * qx * f2
          + f3 * (2.0 * by * qy + 2.0 * bz * qz) + f4 * (-4.0 * by * qx + 2.0 * bz * qw)
          + f5 * (-2.0 * by * qw - 4.0 * bz * qx))
    s2 = (-2.0 * qw * f0 + 2.0 * qz * f1 - 4.0 * qy * f2
          + f3 * (2.0 * by * qx - 2.0 * bz * qw) + f4 * (2.0 * bz * qz)
          + f5 * (2.0 * by * qz - 4.0 * bz * qy))
    s3 = (2.0 * qx * f0 + 2.0 * qy * f1
          + f3 * (2.0 * by * qw + 2.0 * bz * qx) + f4 * (-4.0 * by * qz + 2.0 * bz * qy)
          + f5 * (2.0 * by * qy))
    s_norm = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3)
    if s_norm > 0.0:
        k = beta / s_norm
        dw -= k * s0
        dx -= k * s1
        dy -= k * s2
        dz -= k * s3
    return unit_positive(qw + dw * dt, qx + dx * dt, qy + dy * dt, qz + dz * dt)


@njit(cache=True)
def _madgwick_marg_kernel(accel, gyro, field, dt, q0, beta, held, pending, heading_pending,
                          out):  # pragma: no cover - compiled
    qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    for i in range(accel.shape[0]):
        step = dt[i]
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        gx, gy, gz = gyro[i, 0], gyro[i, 1], gyro[i, 2]
        if step <= 0.0:  # a restart forgets the held field: the sensor may have turned
            held[0] = np.nan
            heading_pending = True
        mx, my, mz, have_field = step_field(field, i, held, gx, gy, gz, step)
        if (step <= 0.0 or pending) and usable_vector(ax, ay, az):
            qw, qx, qy, qz = unit_positive(*tilt_correct(qw, qx, qy, qz, ax, ay, az, 1.0))
            pending = False
        elif step <= 0.0:
            pending = True
        else:
            qw, qx, qy, qz = madgwick_marg_step(qw, qx, qy, qz, gx, gy, gz, ax, ay, az,
                                                mx, my, mz, beta, step)
        if heading_pending and not pending and have_field:
            qw, qx, qy, qz = unit_positive(*heading_from_field(qw, qx, qy, qz, mx, my, mz))
            heading_pending = False
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
    return pending, heading_pending


class MadgwickFilter(AccelStartedFilter):
    """Madgwick (2010) gradient-descent filter, IMU form, gain beta; MARG form with a field."""

    name = "madgwick"
    uses_magnetometer = True
    _extra_state = (*AccelStartedFilter._extra_state, "_held_field", "_heading_pending")
    title = "Madgwick"
    description = (
        "Gradient-descent fusion (Madgwick 2010): the gyro rate minus a fixed-rate step beta "
        "towards the accelerometer's tilt; with a magnetometer (MARG form) towards the "
        "field's heading too (ENU, y to magnetic north)."
    )
    parameters = (
        ParameterSpec(
            "beta", "Gain beta", "rad/s", 0.041, 0.0, 10.0,
            "Rate of the correction towards the accelerometer, sqrt(3/4) times the expected "
            "gyro error. Larger: faster convergence and bias rejection (up to about 2 beta), "
            "but more accelerometer noise and chatter of about 2 beta dt per sample. "
            "0: gyro only.",
        ),
        MAGNETOMETER_PARAMETER,
    )

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._held_field = no_field()
        self._heading_pending = initial_quat is None

    def warm_up(self) -> None:
        """Compile both forms: the IMU kernel (the base class's block) and the MARG one."""
        super().warm_up()
        copy.deepcopy(self)._process(warm_up_block())

    def _process(self, block: SampleBlock) -> np.ndarray:
        out = np.empty((len(block), 4))
        if block.mag_ut is None or not self._values["magnetometer"]:
            self._restart_pending = _madgwick_kernel(
                *self._inputs(block), float(self._values["beta"]), self._restart_pending, out
            )
            return out
        accel, gyro, dt, q0 = self._inputs(block)
        field = np.ascontiguousarray(block.mag_ut, dtype=np.float64)
        self._restart_pending, self._heading_pending = _madgwick_marg_kernel(
            accel, gyro, field, dt, q0, float(self._values["beta"]), self._held_field,
            self._restart_pending, self._heading_pending, out,
        )
        return out
