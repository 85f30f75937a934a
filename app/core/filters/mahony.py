"""Mahony's explicit complementary filter with gyro-bias estimation (PI on the attitude error).

Source: R. Mahony, T. Hamel, J.-M. Pflimlin, "Nonlinear complementary filters on the special
orthogonal group", IEEE Trans. Automatic Control 53(5), 2008, eqs. (32) and (48), with the
single vector direction "up" (the normalised accelerometer ``a``). Per sample::

    v     = conj(q) (x) (0, 0, 1) (x) q       estimated up in the sensor frame
    e     = a x v                               (omega_mes)
    b    -= ki e dt                             gyro-bias estimate, b = -ki * integral(e dt)
    w     = gyro - b + kp e
    q     = normalise(q (x) exp(w dt / 2))     or, as Mahony's code, q + 0.5 q (x) (0, w) dt

The bias estimate ``b`` is kept as the state rather than ``integral(e dt)``: the two are the same
for a fixed ``ki``, but with ``b`` a change of ``ki`` mid-stream does not make the corrected rate
jump, and ``ki = 0`` freezes the estimate (it is zero after a reset, so ``ki = 0`` from the start
disables the integral). The bias survives restarts (gaps); only :meth:`reset` clears it.

Linearised about the truth, the tilt error obeys ``e'' + kp e' + ki e = 0``: the defaults
kp = 1 /s, ki = 0.3 /s^2 (also the ``ahrs`` package's defaults) give a natural frequency of
0.55 rad/s with damping 0.91 (0.1 % overshoot), so a constant gyro bias is learnt within about
ten seconds, while tilt noise from the accelerometer is filtered with a time constant near 1 s.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.filters.base import ParameterSpec
from app.core.filters.complementary import gyro_step, tilt_correct
from app.core.filters.gyro_integration import AccelStartedFilter, unit_positive, usable_vector
from app.core.samples import SampleBlock


@njit(cache=True)
def _mahony_kernel(accel, gyro, dt, q0, bias, kp, ki, exact, pending, out):  # pragma: no cover
    qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    bx, by, bz = bias[0], bias[1], bias[2]
    for i in range(accel.shape[0]):
        step = dt[i]
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        if (step <= 0.0 or pending) and usable_vector(ax, ay, az):
            # (Re)start: the accelerometer's tilt, heading kept; the bias estimate stays.
            qw, qx, qy, qz = tilt_correct(qw, qx, qy, qz, ax, ay, az, 1.0)
            pending = False
        elif step <= 0.0:
            pending = True  # hold until a usable accelerometer sample
        else:
            wx, wy, wz = gyro[i, 0], gyro[i, 1], gyro[i, 2]
            if not wx * wx + wy * wy + wz * wz < math.inf:  # NaN or inf: trust the bias only
                wx = 0.0
                wy = 0.0
                wz = 0.0
            if usable_vector(ax, ay, az):
                norm = math.sqrt(ax * ax + ay * ay + az * az)
                ax /= norm
                ay /= norm
                az /= norm
                # v = R(q)^T e_z, the third row of R(q).
                vx = 2.0 * (qx * qz - qw * qy)
                vy = 2.0 * (qw * qx + qy * qz)
                vz = 1.0 - 2.0 * (qx * qx + qy * qy)
                ex = ay * vz - az * vy
                ey = az * vx - ax * vz
                ez = ax * vy - ay * vx
                bx -= ki * ex * step
                by -= ki * ey * step
                bz -= ki * ez * step
                wx += kp * ex
                wy += kp * ey
                wz += kp * ez
            wx -= bx
            wy -= by
            wz -= bz
            if exact:
                qw, qx, qy, qz = gyro_step(qw, qx, qy, qz, wx, wy, wz, step)
            else:
                h = 0.5 * step
                qw, qx, qy, qz = (
                    qw + h * (-qx * wx - qy * wy - qz * wz),
                    qx + h * (qw * wx + qy * wz - qz * wy),
                    qy + h * (qw * wy - qx * wz + qz * wx),
                    qz + h * (qw * wz + qx * wy - qy * wx),
                )
        qw, qx, qy, qz = unit_positive(qw, qx, qy, qz)
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
    bias[0] = bx
    bias[1] = by
    bias[2] = bz
    return pending


class MahonyFilter(AccelStartedFilter):
    """Mahony et al. (2008) explicit complementary filter: PI correction and gyro-bias estimate."""

    name = "mahony"
    title = "Mahony"
    description = (
        "Nonlinear complementary filter (Mahony 2008): the gyro corrected by kp times the tilt "
        "error, with ki learning the gyro bias."
    )
    _extra_state = (*AccelStartedFilter._extra_state, "_bias")
    parameters = (
        ParameterSpec(
            "kp", "Proportional gain kp", "1/s", 1.0, 0.0, 100.0,
            "How fast the attitude is pulled towards the accelerometer's tilt; roughly a "
            "complementary filter with tau = 1/kp. 0: no correction.",
        ),
        ParameterSpec(
            "ki", "Integral gain ki", "1/s^2", 0.3, 0.0, 10.0,
            "How fast the gyro bias is learnt (damping kp / (2 sqrt(ki))). 0 stops learning: "
            "the bias estimate keeps its value, which is zero after a reset.",
        ),
        ParameterSpec(
            "exact_integration", "Exact rotation step", "", True, False, True,
            "On: rotate by the corrected rate with the exact quaternion exponential. Off: the "
            "first-order step q + 0.5 q (0, w) dt of Mahony's code and the ahrs package; the two "
            "differ by about (w dt)^3 / 12 rad per sample.",
            kind="bool",
        ),
    )

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._bias = np.zeros(3)

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """The current gyro-bias estimate (sensor frame, rad/s)."""
        return self._bias.copy()

    def _process(self, block: SampleBlock) -> np.ndarray:
        out = np.empty((len(block), 4))
        bias = self._bias.copy()
        self._restart_pending = _mahony_kernel(
            *self._inputs(block),
            bias,
            float(self._values["kp"]),
            float(self._values["ki"]),
            bool(self._values["exact_integration"]),
            self._restart_pending,
            out,
        )
        self._bias = bias
        return out
