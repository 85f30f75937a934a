"""Complementary filter, ``alpha = K (alpha + w dt) + (1 - K) alpha_acc`` with ``K = tau/(tau+dt)``.

The thesis writes it per axis on Euler angles, which breaks at the +-180 degree wrap and at
large tilts. Here the same blend runs on the attitude itself: the gyro propagates the
quaternion, then the estimate is rotated a fraction ``1 - K`` of the way towards the
accelerometer's gravity direction about a horizontal axis. For small angles this is exactly the
thesis's per-axis formula; it holds upside down and at 90 degrees, and leaves yaw alone.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.filters.base import OrientationFilter, ParameterSpec
from app.core.samples import SampleBlock


@njit(cache=True, fastmath=False)
def _quat_mul(aw, ax, ay, az, bw, bx, by, bz):  # pragma: no cover - compiled
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@njit(cache=True)
def tilt_correct(qw, qx, qy, qz, ax, ay, az, fraction):  # pragma: no cover - compiled
    """Rotate q about a horizontal earth axis ``fraction`` of the way to the measured up."""
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    if not (norm > 0.0 and math.isfinite(norm)) or fraction <= 0.0:
        return qw, qx, qy, qz  # no usable gravity direction: keep the attitude
    ax /= norm
    ay /= norm
    az /= norm
    # v = R(q) a: the measured up direction seen in the earth frame.
    tx = 2.0 * (qy * az - qz * ay)
    ty = 2.0 * (qz * ax - qx * az)
    tz = 2.0 * (qx * ay - qy * ax)
    vx = ax + qw * tx + qy * tz - qz * ty
    vy = ay + qw * ty + qz * tx - qx * tz
    vz = az + qw * tz + qx * ty - qy * tx
    # Rotation taking v to earth z: axis v x ez = (vy, -vx, 0), angle atan2(|v x ez|, vz).
    s = math.sqrt(vx * vx + vy * vy)
    angle = math.atan2(s, vz) * fraction
    if s > 1e-12:
        ux = vy / s
        uy = -vx / s
    elif vz < 0.0:
        ux = 1.0  # exactly upside down: any horizontal axis will do
        uy = 0.0
    else:
        return qw, qx, qy, qz
    half = 0.5 * angle
    sh = math.sin(half)
    return _quat_mul(math.cos(half), ux * sh, uy * sh, 0.0, qw, qx, qy, qz)


@njit(cache=True)
def gyro_step(qw, qx, qy, qz, gx, gy, gz, dt):  # pragma: no cover - compiled
    """Propagate q by the body rate (gx, gy, gz) rad/s over dt with the exact exponential."""
    rx = gx * dt
    ry = gy * dt
    rz = gz * dt
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if not angle >= 1e-12 or not math.isfinite(angle):  # no rotation, or an unusable sample
        return qw, qx, qy, qz
    half = 0.5 * angle
    k = math.sin(half) / angle
    return _quat_mul(qw, qx, qy, qz, math.cos(half), rx * k, ry * k, rz * k)


@njit(cache=True)
def _complementary_kernel(accel, gyro, dt, q0, tau, out):  # pragma: no cover - compiled
    qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    for i in range(accel.shape[0]):
        step = dt[i]
        if step > 0.0:
            qw, qx, qy, qz = gyro_step(qw, qx, qy, qz, gyro[i, 0], gyro[i, 1], gyro[i, 2], step)
            fraction = step / (tau + step)  # 1 - K
        else:
            fraction = 1.0  # restart: take the accelerometer's tilt, keep the heading
        qw, qx, qy, qz = tilt_correct(
            qw, qx, qy, qz, accel[i, 0], accel[i, 1], accel[i, 2], fraction
        )
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if qw < 0.0:
            norm = -norm
        qw /= norm
        qx /= norm
        qy /= norm
        qz /= norm
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz


class ComplementaryFilter(OrientationFilter):
    """Gyro integration blended with the accelerometer tilt, time constant tau."""

    name = "complementary"
    title = "Complementary"
    description = "Gyro for fast motion, accelerometer for the long term; K = tau / (tau + dt)."
    parameters = (
        ParameterSpec(
            "tau_s", "Time constant tau", "s", 0.5, 0.001, 100.0,
            "Below tau the gyro dominates, above it the accelerometer. K = tau / (tau + dt).",
            log_scale=True,
            # The thesis's presets K = 0.95 / 0.98 / 0.995 at 256 Hz, as tau = K dt / (1 - K).
            presets=(
                ("K=0.95 @ 256 Hz", 0.95 / 256 / 0.05),
                ("K=0.98 @ 256 Hz", 0.98 / 256 / 0.02),
                ("K=0.995 @ 256 Hz", 0.995 / 256 / 0.005),
            ),
        ),
    )

    def _process(self, block: SampleBlock) -> np.ndarray:
        out = np.empty((len(block), 4))
        _complementary_kernel(
            np.ascontiguousarray(block.accel_m_s2),
            np.ascontiguousarray(block.gyro_rad_s),
            self.time_steps(block),
            self._quat,
            float(self._values["tau_s"]),
            out,
        )
        return out
