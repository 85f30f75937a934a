"""The founding MSc thesis's linear Kalman filter on Euler angles, implemented as written.

Model (the thesis's matrices; I3 the 3x3 identity, dt the sample step)::

    x = [theta_x, theta_y, theta_z, b_x, b_y, b_z]       angles (rad), gyro biases (rad/s)
    A = [[I3, -dt I3], [0, I3]]    B = [[dt I3], [0]]    u = gyro rates    H = [I3 0]
    Q = q I6    R = r I3    P0 = p I6              (thesis defaults q = 1e-5, r = 50, p = 0)

    predict   x = A x + B u             P = A P A^T + Q
    correct   K = P H^T (H P H^T + R)^-1
              x = x + K (z - H x)       P = (I - K H) P

All matrices are block-diagonal per axis, so the filter is exactly three independent 2-state
filters ``(theta_i, b_i)``; the kernel runs them as such (the test compares it with the 6x6
matrix form). Only the ratios ``q : r : p`` matter (scaling all three scales P and leaves K and
the estimates unchanged), so the thesis's numbers work whether read in degrees or radians.
``Q`` is per *step*, not per second, as in the thesis: the same q, r give a different time
constant at another sample rate. At 256 Hz (the rate of the thesis's complementary-filter
presets) the defaults reach a steady-state angle gain of 0.0019 per sample, a time constant of
about 2 s, and learn a constant gyro bias within a minute (the tests check the gain against the
fixed point of the Riccati equation).

Measurements and signs
----------------------
- ``z_x`` = roll = ``atan2(a_y, a_z)`` (the app's roll, positive when +y is raised).
- ``z_y`` = the thesis's ``alpha = atan(A_x / sqrt(A_y^2 + A_z^2))`` written as
  ``atan2(a_x, hypot(a_y, a_z))``. At rest the accelerometer reads "up", so this is positive
  when +x is raised: exactly the app's pitch, no sign change on the accelerometer side.
- The gyro y rate has the *opposite* sign: a positive rate about +y lowers the +x side, so the
  pitch rate is ``-w_y`` (for small roll). The input is therefore ``u = (w_x, -w_y, w_z)`` and
  the state ``b_y`` estimates *minus* the y gyro bias.
- ``theta_z`` has no accelerometer measurement. The thesis keeps ``H = [I3 0]`` and ``R = r I3``;
  the faithful reading taken here sets ``z_z`` to the predicted ``theta_z``, so its innovation is
  zero: ``theta_z`` is pure gyro integration and ``b_z`` never moves. This gives the same
  estimates as "H measures only x and y" (the axes are independent); only ``P`` for the z axis
  differs (it is shrunk as if measured). ``theta_z`` is the heading and does not affect the
  tilt.

The innovation ``z - H x`` is wrapped to (-pi, pi], and the angle states are kept in (-pi, pi],
so roll passes +-180 degrees without a jump. The output quaternion is
``Rz(theta_z) Ry(-theta_y) Rx(theta_x)`` (:func:`app.core.orientation.quaternion_from_roll_pitch`).
A restart (first sample, gap, bad step) sets roll and pitch from the accelerometer, keeps the
heading and the bias estimates, and resets the angle rows of P to ``p``.

Where the per-axis Euler model stops being valid
------------------------------------------------
The filter treats body rates as Euler-angle rates. The exact kinematics of this convention are::

    roll'  = w_x - tan(pitch) (sin(roll) w_y + cos(roll) w_z)
    pitch' = -cos(roll) w_y + sin(roll) w_z
    yaw'   = (sin(roll) w_y + cos(roll) w_z) / cos(pitch)

so the model is right only while ``tan(pitch)`` and ``sin(roll)`` are small or the rates about
the other axes are zero: a rotation about z while tilted, or about y while rolled, feeds the
wrong angle, and at large roll *and* pitch the prediction is simply wrong; the accelerometer
correction then pulls the angles back with its time constant (about 2 s at 256 Hz). The
simulator's tour (turns through pitch 90 and upside down) shows it: errors of tens of degrees
during the turns. The accelerometer angles are also taken sample by sample, so strong vibration
biases them (6 degrees in the simulator's vibration scenario). At pitch
+-90 degrees the Euler angles are singular: roll = atan2(a_y, a_z) has nothing to measure and
follows the noise, and a gyro path over the top (pitch past 90 degrees) leaves a state the
measurement ``|z_y| <= 90`` can only drag back. Roll itself wraps at +-180 degrees (handled by
the wrapped innovation, so upside down is fine). The quaternion filters (EKF, complementary) have
none of these limits.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.filters.base import OrientationFilter, ParameterSpec
from app.core.orientation import angles_from_quaternion
from app.core.samples import SampleBlock

TWO_PI = 2.0 * math.pi


@njit(cache=True)
def wrap_angle(angle):  # pragma: no cover - compiled
    """Wrap to (-pi, pi]."""
    return angle - TWO_PI * math.ceil((angle - math.pi) / TWO_PI)


@njit(cache=True)
def kalman_axis_step(theta, bias, p00, p01, p11, rate, dt, z, measured, q, r):  # pragma: no cover
    """One predict (dt > 0) and correct (``measured``) step of one axis's 2-state filter.

    State (theta, bias); A = [[1, -dt], [0, 1]], B = [dt, 0], H = [1, 0], Q = q I2, R = r.
    Returns the new theta, bias and covariance entries (P symmetric: p00, p01, p11).
    """
    if dt > 0.0:
        theta = theta + dt * (rate - bias)
        p00 = p00 - 2.0 * dt * p01 + dt * dt * p11 + q
        p01 = p01 - dt * p11
        p11 = p11 + q
    if measured:
        s = p00 + r
        if s > 0.0:
            k0 = p00 / s
            k1 = p01 / s
            innovation = wrap_angle(z - theta)
            theta = theta + k0 * innovation
            bias = bias + k1 * innovation
            # P = (I - K H) P, written out (it stays symmetric: p10 = (1 - k0) p01).
            p11 = p11 - k1 * p01
            p00 = (1.0 - k0) * p00
            p01 = (1.0 - k0) * p01
    return wrap_angle(theta), bias, p00, p01, p11


@njit(cache=True)
def euler_to_quat(roll, pitch, yaw):  # pragma: no cover - compiled
    """``Rz(yaw) Ry(-pitch) Rx(roll)`` with ``w >= 0`` (as quaternion_from_roll_pitch)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(-0.5 * pitch), math.sin(-0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    qw = cr * cp * cy + sr * sp * sy
    qx = sr * cp * cy - cr * sp * sy
    qy = cr * sp * cy + sr * cp * sy
    qz = cr * cp * sy - sr * sp * cy
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    if qw < 0.0:
        norm = -norm
    return qw / norm, qx / norm, qy / norm, qz / norm


@njit(cache=True)
def _thesis_kernel(accel, gyro, dt, angles, bias, cov, q, r, p, out):  # pragma: no cover
    """``angles`` (3,), ``bias`` (3,) and ``cov`` (3 axes, [p00, p01, p11]) are updated."""
    tx, ty, tz = angles[0], angles[1], angles[2]
    bx, by, bz = bias[0], bias[1], bias[2]
    x00, x01, x11 = cov[0, 0], cov[0, 1], cov[0, 2]
    y00, y01, y11 = cov[1, 0], cov[1, 1], cov[1, 2]
    z00, z01, z11 = cov[2, 0], cov[2, 1], cov[2, 2]
    for i in range(accel.shape[0]):
        step = dt[i]
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        norm2 = ax * ax + ay * ay + az * az
        usable = norm2 > 0.0 and norm2 < math.inf
        roll_acc = math.atan2(ay, az) if usable else 0.0
        pitch_acc = math.atan2(ax, math.sqrt(ay * ay + az * az)) if usable else 0.0
        if step > 0.0:
            wx, wy, wz = gyro[i, 0], gyro[i, 1], gyro[i, 2]
            if not wx * wx + wy * wy + wz * wz < math.inf:  # NaN/inf: no rate, bias only
                wx = wy = wz = 0.0
            tx, bx, x00, x01, x11 = kalman_axis_step(
                tx, bx, x00, x01, x11, wx, step, roll_acc, usable, q, r
            )
            ty, by, y00, y01, y11 = kalman_axis_step(
                ty, by, y00, y01, y11, -wy, step, pitch_acc, usable, q, r
            )
            # z_z = the predicted theta_z: zero innovation, P shrinks as if measured.
            tz, bz, z00, z01, z11 = kalman_axis_step(
                tz, bz, z00, z01, z11, wz, step, tz + step * (wz - bz), True, q, r
            )
        else:
            if usable:
                tx = roll_acc
                ty = pitch_acc
            x00 = y00 = z00 = p
            x01 = y01 = z01 = 0.0
        qw, qx, qy, qz = euler_to_quat(tx, ty, tz)
        out[i, 0] = qw
        out[i, 1] = qx
        out[i, 2] = qy
        out[i, 3] = qz
    angles[0], angles[1], angles[2] = tx, ty, tz
    bias[0], bias[1], bias[2] = bx, by, bz
    cov[0, 0], cov[0, 1], cov[0, 2] = x00, x01, x11
    cov[1, 0], cov[1, 1], cov[1, 2] = y00, y01, y11
    cov[2, 0], cov[2, 1], cov[2, 2] = z00, z01, z11


class ThesisKalman(OrientationFilter):
    """The thesis's linear Kalman filter: per-axis Euler angles and gyro biases."""

    name = "kalman-thesis"
    title = "Kalman (thesis)"
    reference_only = True
    description = (
        "The thesis's linear Kalman filter on roll, pitch and yaw with gyro-bias states "
        "(Q = q I, R = r I, P0 = p I): faithful, so only valid for moderate tilts."
    )
    parameters = (
        ParameterSpec(
            "q", "Process noise q", "rad²", 1e-5, 1e-12, 1e3,
            "Q = q I6, added every sample to the angles' and biases' variance (per step, as in "
            "the thesis). Larger: follow the accelerometer and learn the bias faster. Only "
            "q : r : p matters.",
            log_scale=True,
        ),
        ParameterSpec(
            "r", "Measurement noise r", "rad²", 50.0, 1e-9, 1e6,
            "R = r I3, the variance of the accelerometer's roll and pitch. Larger: smoother, "
            "slower. The thesis's 50 with q = 1e-5 gives a time constant of about 2 s at "
            "256 Hz (0.0019 per sample).",
            log_scale=True,
        ),
        ParameterSpec(
            "p", "Initial covariance p", "rad²", 0.0, 0.0, 1e6,
            "P0 = p I6 at reset; after a restart (gap) the angle rows are set to p again. "
            "0 (the thesis): start fully trusting the accelerometer's first sample.",
        ),
    )

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._angles = np.zeros(3)
        if initial_quat is not None:
            q = np.asarray(initial_quat, dtype=np.float64)
            angles = angles_from_quaternion(q)
            w, x, y, z = q
            yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
            self._angles = np.array(
                [math.radians(angles.roll_deg), math.radians(angles.pitch_deg), yaw]
            )
        self._bias = np.zeros(3)
        p = float(self._values["p"])
        self._cov = np.tile([p, 0.0, p], (3, 1))

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """Bias estimate in the sensor frame (rad/s), un-doing the y sign of the state."""
        return self._bias * np.array([1.0, -1.0, 1.0])

    @property
    def state(self) -> np.ndarray:
        """The thesis's state x = [theta_x, theta_y, theta_z, b_x, b_y, b_z] (b_y for -w_y)."""
        return np.concatenate([self._angles, self._bias])

    @property
    def covariance(self) -> np.ndarray:
        """The thesis's 6x6 P, assembled from the three per-axis 2x2 blocks."""
        cov = np.zeros((6, 6))
        for axis, (p00, p01, p11) in enumerate(self._cov):
            cov[axis, axis] = p00
            cov[axis, axis + 3] = cov[axis + 3, axis] = p01
            cov[axis + 3, axis + 3] = p11
        return cov

    def _process(self, block: SampleBlock) -> np.ndarray:
        out = np.empty((len(block), 4))
        angles, bias, cov = self._angles.copy(), self._bias.copy(), self._cov.copy()
        v = self._values
        _thesis_kernel(
            np.ascontiguousarray(block.accel_m_s2, dtype=np.float64),
            np.ascontiguousarray(block.gyro_rad_s, dtype=np.float64),
            self.time_steps(block),
            angles, bias, cov, float(v["q"]), float(v["r"]), float(v["p"]), out,
        )
        self._angles, self._bias, self._cov = angles, bias, cov
        return out
