"""Gyro integration alone, ``alpha(t) = alpha(t-1) + G dt``: the drift that the fusion filters fix.

The thesis writes the integration per axis on angles; here it runs on the attitude quaternion
with the exact exponential, ``q <- q * exp(w dt / 2)`` (:func:`gyro_step`), so a rotation about
a fixed axis is integrated exactly (the angle is the running sum of ``G dt``) and nothing but
the gyro's own errors (bias, noise, scale) shows. The attitude starts, and after every restart
(first sample, gap, bad or long step) starts again, from the accelerometer's tilt with the
heading kept, unless that is switched off; then it starts level and holds across restarts.

The small njit helpers here (:func:`unit_positive`, :func:`usable_vector`, :func:`restart_tilt`)
and the base class :class:`AccelStartedFilter` are shared with the Madgwick and Mahony filters.
"""

from __future__ import annotations

import copy
import math
from typing import ClassVar

import numpy as np
from numba import njit

from app.core.filters.base import OrientationFilter, ParameterSpec
from app.core.filters.complementary import gyro_step, tilt_correct
from app.core.samples import SampleBlock


@njit(cache=True)
def unit_positive(qw, qx, qy, qz):  # pragma: no cover - compiled
    """Scale to unit norm with ``w >= 0`` (as :func:`app.core.quaternion.normalize`)."""
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    if qw < 0.0:
        norm = -norm
    return qw / norm, qx / norm, qy / norm, qz / norm


@njit(cache=True)
def usable_vector(x, y, z):  # pragma: no cover - compiled
    """True when (x, y, z) is finite and not zero, so that it can be normalised."""
    n2 = x * x + y * y + z * z
    return n2 > 0.0 and n2 < math.inf  # False for NaN too


@njit(cache=True)
def restart_tilt(qw, qx, qy, qz, ax, ay, az):  # pragma: no cover - compiled
    """Take the accelerometer's tilt, keep the heading; keep q if the sample is unusable."""
    if usable_vector(ax, ay, az):
        return tilt_correct(qw, qx, qy, qz, ax, ay, az, 1.0)
    return qw, qx, qy, qz


@njit(cache=True)
def _gyro_kernel(accel, gyro, dt, q0, from_accel, pending, out):  # pragma: no cover - compiled
    qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    for i in range(accel.shape[0]):
        step = dt[i]
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        if from_accel and (step <= 0.0 or pending) and usable_vector(ax, ay, az):
            qw, qx, qy, qz = tilt_correct(qw, qx, qy, qz, ax, ay, az, 1.0)
            pending = False
        elif step <= 0.0:
            pending = from_accel  # hold until a usable accelerometer sample
        else:
            gx, gy, gz = gyro[i, 0], gyro[i, 1], gyro[i, 2]
            if usable_vector(gx, gy, gz):  # a zero rate is a no-op; NaN must not spread
                qw, qx, qy, qz = gyro_step(qw, qx, qy, qz, gx, gy, gz, step)
        qw, qx, qy, qz = unit_positive(qw, qx, qy, qz)
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
    return pending


class AccelStartedFilter(OrientationFilter):
    """A filter whose restarts take the tilt from the next usable accelerometer sample.

    A restart (``dt == 0``) whose accelerometer sample is zero or not finite holds the attitude
    and leaves the restart pending, also across blocks, until a usable sample arrives (the gyro
    keeps propagating meanwhile). ``_extra_state`` names attributes that :meth:`warm_up` must
    leave untouched.
    """

    _extra_state: ClassVar[tuple[str, ...]] = ("_restart_pending",)

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._restart_pending = False

    def warm_up(self) -> None:
        saved = {key: copy.copy(getattr(self, key)) for key in self._extra_state}
        super().warm_up()
        for key, value in saved.items():
            setattr(self, key, value)

    def _inputs(self, block: SampleBlock) -> tuple[np.ndarray, ...]:
        """Contiguous float64 accel and gyro, the time steps and a copy of the attitude."""
        return (
            np.ascontiguousarray(block.accel_m_s2, dtype=np.float64),
            np.ascontiguousarray(block.gyro_rad_s, dtype=np.float64),
            self.time_steps(block),
            np.array(self._quat, dtype=np.float64),
        )


class GyroIntegration(AccelStartedFilter):
    """Pure gyro integration (exact quaternion exponential), started from the accelerometer."""

    name = "gyro"
    title = "Gyro integration"
    description = (
        "alpha(t) = alpha(t-1) + G dt on the attitude: smooth and fast, but drifts without bound "
        "with any gyro bias."
    )
    parameters = (
        ParameterSpec(
            "init_from_accel", "Start from accelerometer", "", True, False, True,
            "On: the first sample, and each restart after a gap, takes its tilt from the "
            "accelerometer. Off: start level and hold the attitude across gaps (pure gyro).",
            kind="bool",
        ),
    )

    def _process(self, block: SampleBlock) -> np.ndarray:
        out = np.empty((len(block), 4))
        self._restart_pending = _gyro_kernel(
            *self._inputs(block), bool(self._values["init_from_accel"]),
            self._restart_pending, out,
        )
        return out
