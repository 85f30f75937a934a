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

The normalised step makes the correction a constant-rate slew of at most about ``2 beta``
rad/s towards the accelerometer's tilt: a gyro bias below that is rejected, and the estimate
chatters by about ``2 beta dt`` per sample around the accelerometer's answer.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.filters.base import ParameterSpec
from app.core.filters.complementary import tilt_correct
from app.core.filters.gyro_integration import AccelStartedFilter, unit_positive, usable_vector
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


class MadgwickFilter(AccelStartedFilter):
    """Madgwick (2010) gradient-descent filter, IMU form, gain beta."""

    name = "madgwick"
    title = "Madgwick"
    description = (
        "Gradient-descent fusion (Madgwick 2010): the gyro rate minus a fixed-rate step beta "
        "towards the accelerometer's tilt."
    )
    parameters = (
        ParameterSpec(
            "beta", "Gain beta", "rad/s", 0.041, 0.0, 10.0,
            "Rate of the correction towards the accelerometer, sqrt(3/4) times the expected "
            "gyro error. Larger: faster convergence and bias rejection (up to about 2 beta), "
            "but more accelerometer noise and chatter of about 2 beta dt per sample. "
            "0: gyro only.",
        ),
    )

    def _process(self, block: SampleBlock) -> np.ndarray:
        out = np.empty((len(block), 4))
        self._restart_pending = _madgwick_kernel(
            *self._inputs(block), float(self._values["beta"]), self._restart_pending, out
        )
        return out
