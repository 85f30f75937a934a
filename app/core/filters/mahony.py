"""Mahony's explicit complementary filter with gyro-bias estimation (PI on the attitude error).

Source: R. Mahony, T. Hamel, J.-M. Pflimlin, "Nonlinear complementary filters on the special
orthogonal group", IEEE Trans. Automatic Control 53(5), 2008, eqs. (32) and (48), with the
single vector direction "up" (the normalised accelerometer ``a``). Per sample::

    v     = conj(q) (x) (0, 0, 1) (x) q       estimated up in the sensor frame
    e     = a x v                               (omega_mes)
    b    -= ki e dt                             gyro-bias estimate, b = -ki * integral(e dt)
    w     = gyro - b + kp e
    q     = normalise(q (x) exp(w dt / 2))     or, as Mahony's code, q + 0.5 q (x) (0, w) dt

MARG form (eq. (48) with two directions, as the ``ahrs`` package's ``updateMARG``): with a field
``m`` (normalised), its expected direction ``v_m = R(q)^T b / |b|`` with the earth-frame reference
``b = (0, |h_xy|, h_z)``, ``h = R(q) m`` (ENU, y toward magnetic north:
:mod:`app.core.filters.marg`), adds ``m x v_m`` to the error: ``e = a x v + m x v_m``. Without a
field in the block (no magnetometer, or the switch off) the IMU form runs, exactly as before.

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

import copy
import math

import numpy as np
from numba import njit

from app.core.filters.base import MAGNETOMETER_PARAMETER, ParameterSpec
from app.core.filters.complementary import gyro_step, tilt_correct
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
def _mahony_kernel(accel, gyro, dt, q0, bias, kp, ki, exact, pending, out):  # pragma: no cover
    """The IMU form (no field)."""
    field = np.empty((0, 3))
    held = np.full(3, np.nan)
    pending, _ = _mahony_marg_kernel(accel, gyro, field, dt, q0, bias, kp, ki, exact, held,
                                     pending, False, out)
    return pending


@njit(cache=True)
def _mahony_marg_kernel(accel, gyro, field, dt, q0, bias, kp, ki, exact, held, pending,
                        heading_pending, out):  # pragma: no cover - compiled
    """Both forms: ``field`` (N, 3) for MARG, or (0, 3) for the IMU form."""
    qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    bx, by, bz = bias[0], bias[1], bias[2]
    marg = field.shape[0] > 0
    for i in range(accel.shape[0]):
        step = dt[i]
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        mx, my, mz, have_field = 0.0, 0.0, 0.0, False
        if marg:
            if step <= 0.0:  # a restart forgets the held field: the sensor may have turned
                held[0] = np.nan
                heading_pending = True
            # The held field turns with the corrected rate of the previous step's bias.
            mx, my, mz, have_field = step_field(field, i, held, gyro[i, 0] - bx,
                                                gyro[i, 1] - by, gyro[i, 2] - bz, step)
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
                if have_field:
                    norm = math.sqrt(mx * mx + my * my + mz * mz)
                    mx /= norm
                    my /= norm
                    mz /= norm
                    hx, hy, hz = field_in_earth(qw, qx, qy, qz, mx, my, mz)
                    ry = math.sqrt(hx * hx + hy * hy)
                    # v_m = R^T (0, ry, hz), normalised: ry * (row y of R) + hz * (row z).
                    ux = ry * 2.0 * (qx * qy + qw * qz) + hz * vx
                    uy = ry * (1.0 - 2.0 * (qx * qx + qz * qz)) + hz * vy
                    uz = ry * 2.0 * (qy * qz - qw * qx) + hz * vz
                    norm = math.sqrt(ux * ux + uy * uy + uz * uz)
                    if norm > 0.0:
                        ux /= norm
                        uy /= norm
                        uz /= norm
                        ex += my * uz - mz * uy
                        ey += mz * ux - mx * uz
                        ez += mx * uy - my * ux
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
        if heading_pending and not pending and have_field:
            qw, qx, qy, qz = heading_from_field(qw, qx, qy, qz, mx, my, mz)
            heading_pending = False
        qw, qx, qy, qz = unit_positive(qw, qx, qy, qz)
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
    bias[0] = bx
    bias[1] = by
    bias[2] = bz
    return pending, heading_pending


class MahonyFilter(AccelStartedFilter):
    """Mahony et al. (2008) explicit complementary filter: PI correction and gyro-bias estimate."""

    name = "mahony"
    uses_magnetometer = True
    title = "Mahony"
    description = (
        "Nonlinear complementary filter (Mahony 2008): the gyro corrected by kp times the tilt "
        "error, with ki learning the gyro bias; with a magnetometer (MARG form) the field's "
        "direction error too (ENU, y to magnetic north)."
    )
    _extra_state = (*AccelStartedFilter._extra_state, "_bias", "_held_field",
                    "_heading_pending")
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
        MAGNETOMETER_PARAMETER,
    )

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._bias = np.zeros(3)
        self._held_field = no_field()
        self._heading_pending = initial_quat is None

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """The current gyro-bias estimate (sensor frame, rad/s)."""
        return self._bias.copy()

    def warm_up(self) -> None:
        """Compile both forms: the IMU kernel (the base class's block) and the MARG one."""
        super().warm_up()
        copy.deepcopy(self)._process(warm_up_block())

    def _process(self, block: SampleBlock) -> np.ndarray:
        out = np.empty((len(block), 4))
        bias = self._bias.copy()
        gains = (float(self._values["kp"]), float(self._values["ki"]),
                 bool(self._values["exact_integration"]))
        if block.mag_ut is None or not self._values["magnetometer"]:
            self._restart_pending = _mahony_kernel(
                *self._inputs(block), bias, *gains, self._restart_pending, out,
            )
        else:
            accel, gyro, dt, q0 = self._inputs(block)
            field = np.ascontiguousarray(block.mag_ut, dtype=np.float64)
            self._restart_pending, self._heading_pending = _mahony_marg_kernel(
                accel, gyro, field, dt, q0, bias, *gains, self._held_field,
                self._restart_pending, self._heading_pending, out,
            )
        self._bias = bias
        return out
