"""VQF's tilt with the EKF's heading filter: VQF 9D's architecture, the EKF's field update.

VQF 9D (Laidig & Seel 2023, Information Fusion 91) is a 6D filter (gyroscope and
accelerometer, heading arbitrary) plus one more state, the heading offset ``delta`` between the
6D earth frame and magnetic north: ``q9 = Rz(delta) (x) q6``. Turning about the earth vertical
never moves the inclination, so the 9D filter's inclination *is* the 6D filter's. This filter
keeps that architecture and VQF 6D itself (an internal :class:`~app.core.filters.vqf_filter.
VQFFilter` with its magnetometer switch off: rate, restarts, gaps and block continuity are
its), and replaces VQF's own field update of ``delta`` with the EKF's heading filter
(:mod:`app.core.filters.ekf`, "Heading from the magnetic field") and its disturbance detector
(:mod:`app.core.magnetometer.disturbance`):

- ``delta``'s variance grows per sample by ``(Ng^2 + (ks |w|)^2 T_s) dt``: the gyro's white
  noise and its scale-factor error while it turns, exactly the EKF's heading process noise
  (the gyro's heading error is in ``q6`` and ``delta`` must follow it). ``T_s`` =
  :data:`SCALE_ERROR_TIME_S`, the correlation time the EKF gives the scale error's rate error
  (its ``lp_tau`` default).
- At a field row: ``q = Rz(delta) (x) q6``, the field projected into the earth frame,
  ``m_e = R(q) m``, and the residual ``psi = atan2(m_e,x, m_e,y)`` (ENU, y magnetic north).
  The detector sees the projected field's strength and dip; unless it rejects the sample, a
  scalar Kalman update ``delta += k psi`` with measurement variance

      r = (Nm^2 + (t_m w_v)^2 T + tan^2(dip) P_tilt tau_acc) / dt_m

  as the EKF's (``w_v`` the rate about the vertical, ``T`` = 1 s, ``dt_m`` the time since the
  previous field sample). Where the EKF has its own tilt covariance, this filter has no tilt
  covariance: ``P_tilt`` is fixed at :data:`TILT_SIGMA_DEG` (1 degree), the size of VQF's tilt
  error on hand-held motion, and it lasts about VQF's gravity averaging time ``tau_acc``.
  The term only matters on steep fields with a poor tilt; at 1 degree it is a few percent of
  ``Nm^2``.
- The first field sample after a restart (and after a stretch without a field) sets ``delta``
  with gain 1, as the EKF does; a restart of VQF (first sample, gap, bad step) starts
  ``delta`` afresh (VQF's 6D heading starts afresh too).
- The rest flag the detector learns its first reference with is the EKF's rest test with its
  defaults (gyro within 2 dps of its 0.5 s low-pass and that low-pass below 2 dps, the
  accelerometer within 50 mg of its own, for 1.5 s: VQF's own rest thresholds too).
- The gyroscope enters only the heading's process noise and the detector's "turning" test, raw
  (VQF's bias estimate, under a degree per second, is not passed per sample); so the result
  does not depend on where a stream is cut into blocks.

Without a field, or with the ``magnetometer`` switch off, ``delta`` stays where it was (zero
from the start): the output is VQF 6D's, bit for bit, until a field arrives.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from app.core.filters.base import MAGNETOMETER_PARAMETER, OrientationFilter, ParameterSpec
from app.core.filters.ekf import QuaternionEKF
from app.core.filters.vqf_filter import VQFFilter
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

SCALE_ERROR_TIME_S = 2.0
"""Correlation time of the gyro scale error's rate error in the heading's process noise (the
EKF's, its ``lp_tau`` default)."""
TILT_SIGMA_DEG = 1.0
"""VQF's tilt error on hand-held motion (1-sigma), the tilt variance in the field's heading
noise (a tilt error ``d`` about the field's horizontal direction turns its heading by
``tan(dip) d``)."""
MOTION_WINDOW_S = 1.0
"""The time over which the field's timing error turns its heading (the EKF's)."""
REST_FILTER_S = 0.5
REST_GYRO_DPS = 2.0
REST_ACCEL_MG = 50.0
REST_TIME_S = 1.5
"""The rest test for learning the first field reference (the EKF's defaults, VQF's too)."""

# Layout of the heading state vector.
_DELTA, _VAR, _SINCE, _REST = 0, 1, 2, 3
_GL, _AL = 4, 7
N_HEAD = 10

_TILT_PARAMETERS = ("tau_acc_s", "motion_bias_estimation", "rest_bias_estimation",
                    "bias_sigma_init_dps")
_HEADING_PARAMETERS = ("gyro_noise", "gyro_scale_error", "mag_noise", "mag_timing",
                       "mag_rejection", "mag_norm_threshold", "mag_dip_threshold",
                       "mag_rejection_time", "mag_new_time")


def _specs(cls: type[OrientationFilter], names: tuple[str, ...]) -> tuple[ParameterSpec, ...]:
    return tuple(cls.parameter_spec(name) for name in names)


def new_head() -> np.ndarray:
    """A heading state that has seen nothing (no heading yet: variance -1)."""
    head = np.zeros(N_HEAD)
    head[_VAR] = -1.0
    return head


@njit(cache=True)
def _heading_kernel(
    q6, gyro, accel, dt, mag, head, mag_state, mag_settings, gyro_var_density, scale_var,
    mag_var_density, timing_var, tilt_coupling, rest_gyro2, rest_accel2, out_field, out,
):  # pragma: no cover - compiled
    """Heading offset ``delta`` over a block of 6D quaternions ``q6`` (N, 4); ``out`` (N, 4)
    receives ``Rz(delta) (x) q6`` (``q6`` itself while ``delta`` is exactly 0).

    ``head`` (see the module's layout) and ``mag_state`` are updated; ``mag`` (N, 3) uT with
    NaN rows; ``out_field`` (N, 3) receives the detector's output per row (status, strength
    deviation, dip deviation in rad). Squared densities: rad^2/s (gyro), rad^2 s (field);
    ``tilt_coupling`` = tilt variance times its duration (rad^2 s)."""
    rest_clip = math.sqrt(rest_gyro2)
    for i in range(q6.shape[0]):
        step = dt[i]
        wx, wy, wz = gyro[i, 0], gyro[i, 1], gyro[i, 2]
        w2 = wx * wx + wy * wy + wz * wz
        if not w2 < math.inf:
            wx = wy = wz = w2 = 0.0
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        if step > 0.0:
            if head[_VAR] >= 0.0:
                head[_VAR] += (gyro_var_density + scale_var * w2) * step
            head[_SINCE] += step
            track_rate(mag_state, wx, wy, wz, step)
            alpha = step / (REST_FILTER_S + step)
            head[_GL] += alpha * (wx - head[_GL])
            head[_GL + 1] += alpha * (wy - head[_GL + 1])
            head[_GL + 2] += alpha * (wz - head[_GL + 2])
            head[_AL] += alpha * (ax - head[_AL])
            head[_AL + 1] += alpha * (ay - head[_AL + 1])
            head[_AL + 2] += alpha * (az - head[_AL + 2])
            gyro_dev = ((wx - head[_GL]) ** 2 + (wy - head[_GL + 1]) ** 2
                        + (wz - head[_GL + 2]) ** 2)
            accel_dev = ((ax - head[_AL]) ** 2 + (ay - head[_AL + 1]) ** 2
                         + (az - head[_AL + 2]) ** 2)
            still = (gyro_dev < rest_gyro2 and accel_dev < rest_accel2
                     and abs(head[_GL]) < rest_clip and abs(head[_GL + 1]) < rest_clip
                     and abs(head[_GL + 2]) < rest_clip)
            head[_REST] = head[_REST] + step if still else 0.0
        else:  # VQF restarted: its heading starts afresh, and so does delta
            head[_DELTA] = 0.0
            head[_VAR] = -1.0
            head[_SINCE] = 0.0
            head[_REST] = 0.0
            head[_GL], head[_GL + 1], head[_GL + 2] = wx, wy, wz
            head[_AL], head[_AL + 1], head[_AL + 2] = ax, ay, az
            track_rate(mag_state, wx, wy, wz, 0.0)
        pw, px, py, pz = q6[i, 0], q6[i, 1], q6[i, 2], q6[i, 3]
        mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
        m2 = mx * mx + my * my + mz * mz
        if m2 > 0.0 and m2 < math.inf:
            half = 0.5 * head[_DELTA]
            c = math.cos(half)
            s = math.sin(half)
            qw = c * pw - s * pz
            qx = c * px - s * py
            qy = c * py + s * px
            qz = c * pz + s * pw
            # m_e = R(q) m
            tx = 2.0 * (qy * mz - qz * my)
            ty = 2.0 * (qz * mx - qx * mz)
            tz = 2.0 * (qx * my - qy * mx)
            ex = mx + qw * tx + qy * tz - qz * ty
            ey = my + qw * ty + qz * tx - qx * tz
            ez = mz + qw * tz + qx * ty - qy * tx
            norm = math.sqrt(ex * ex + ey * ey + ez * ez)
            dip = math.asin(max(-1.0, min(1.0, -ez / norm)))
            since = head[_SINCE]
            at_rest = head[_REST] >= REST_TIME_S
            status = detector_step(mag_state, mag_settings, norm, dip, since, at_rest)
            out_field[i, 0] = status
            ref = mag_state[S_REF_NORM]
            if ref > 0.0:
                out_field[i, 1] = norm / ref - 1.0
                out_field[i, 2] = dip - mag_state[S_REF_DIP]
            else:
                out_field[i, 1] = math.nan
                out_field[i, 2] = math.nan
            head[_SINCE] = 0.0
            h2 = ex * ex + ey * ey
            if status != REJECTED and h2 > 0.0:
                # Rate about the earth vertical: R(q6) w, z component.
                yaw_rate = (2.0 * (px * pz - pw * py) * wx + 2.0 * (py * pz + pw * px) * wy
                            + (1.0 - 2.0 * (px * px + py * py)) * wz)
                r = (mag_var_density + timing_var * yaw_rate * yaw_rate * MOTION_WINDOW_S
                     + tilt_coupling * ez * ez / h2) / max(since, 1e-3)
                if status == REDUCED:
                    factor = mag_settings[disturbance.C_REJECT_FACTOR]
                    r *= factor * factor
                if head[_VAR] < 0.0:  # no heading yet: take the field's
                    gain = 1.0
                    head[_VAR] = r
                else:
                    gain = head[_VAR] / (head[_VAR] + r)
                    head[_VAR] *= 1.0 - gain
                delta = head[_DELTA] + gain * math.atan2(ex, ey)
                if delta > math.pi:  # one turn at most: |gain psi| <= pi
                    delta -= 2.0 * math.pi
                elif delta < -math.pi:
                    delta += 2.0 * math.pi
                head[_DELTA] = delta
        else:
            out_field[i, 0] = NO_SAMPLE
            out_field[i, 1] = math.nan
            out_field[i, 2] = math.nan
        if head[_DELTA] == 0.0:
            out[i, 0], out[i, 1], out[i, 2], out[i, 3] = pw, px, py, pz
        else:
            half = 0.5 * head[_DELTA]
            c = math.cos(half)
            s = math.sin(half)
            qw = c * pw - s * pz
            if qw < 0.0:  # the same rotation, w >= 0 as VQF gives it
                c, s = -c, -s
                qw = -qw
            out[i, 0] = qw
            out[i, 1] = c * px - s * py
            out[i, 2] = c * py + s * px
            out[i, 3] = c * pz + s * pw


class VQFHeadingFilter(DisturbanceOwner, OrientationFilter):
    """VQF 6D's tilt, and the EKF's heading filter for the offset to magnetic north."""

    name = "vqf-heading"
    title = "VQF tilt + field heading"
    description = (
        "VQF 6D (gyro integration, gravity averaged in an almost-inertial frame, gyro bias "
        "estimation) for the tilt; with a magnetometer, the heading offset to magnetic north "
        "from the EKF's heading filter (a scalar Kalman filter about the vertical only, with "
        "magnetic disturbance rejection), so the inclination is VQF 6D's exactly."
    )
    uses_magnetometer = True
    parameters = (
        *_specs(VQFFilter, _TILT_PARAMETERS),
        MAGNETOMETER_PARAMETER,
        *_specs(QuaternionEKF, _HEADING_PARAMETERS),
    )


    def __init__(self, **values: Any) -> None:
        self._tilt = VQFFilter(magnetometer=False)
        super().__init__(**values)

    def _parameters_changed(self) -> None:
        tilt = getattr(self, "_tilt", None)
        if tilt is None:
            return
        for name in _TILT_PARAMETERS:
            if tilt.get_parameter(name) != self._values[name]:
                tilt.set_parameter(name, self._values[name])

    @property
    def heading_offset_rad(self) -> float:
        """``delta``: the turn about the vertical from VQF's 6D earth frame to ENU."""
        return float(self._head[_DELTA])

    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        # Taking over from a quaternion: VQF continues from it (heading included), and the
        # next field sample sets the heading afresh, as the EKF does.
        self._tilt.reset(initial_quat, last_time_s)
        self._head = new_head()
        self._heading_tracked = True
        self._mag_state = disturbance.new_state()
        self._field_status: FieldStatus | None = None

    def warm_up(self) -> None:
        """Compile the heading kernel on a copy (VQF itself needs nothing)."""
        n = 4
        t = np.arange(n) * 0.01
        block = SampleBlock(t, np.tile([0.0, 0.0, 9.81], (n, 1)), np.zeros((n, 3)),
                            np.zeros(n), np.zeros(n, dtype=bool), None,
                            np.tile([0.0, 20.0, -40.0], (n, 1)))
        probe = VQFHeadingFilter(**self._values)
        probe._process(block)

    def _process(self, block: SampleBlock) -> np.ndarray:
        dt = self.time_steps(block)
        q6 = self._tilt_quaternions(block)
        use_mag = block.mag_ut is not None and bool(self._values["magnetometer"])
        if not use_mag:
            # The gyro carries the heading: delta stays (0 from the start: VQF 6D exactly).
            self._heading_tracked = False
            self._field_status = None
            if self._head[_DELTA] == 0.0:  # restarts keep it 0
                return q6
            return self._turned(q6, dt)
        head = self._head.copy()
        if not self._heading_tracked:
            head[_VAR] = -1.0  # no variance kept without a field: the next sample sets it
        self._heading_tracked = True
        mag_state = self._mag_state.copy()
        settings = self.disturbance_settings()
        field_rows = np.empty((len(block), 3))
        out = np.empty((len(block), 4))
        v = self._values
        _heading_kernel(
            q6, np.ascontiguousarray(block.gyro_rad_s, dtype=np.float64),
            np.ascontiguousarray(block.accel_m_s2, dtype=np.float64), dt,
            np.ascontiguousarray(block.mag_ut, dtype=np.float64), head, mag_state,
            settings.as_array(self._field_reference),
            math.radians(float(v["gyro_noise"]) * 1e-3) ** 2,
            (float(v["gyro_scale_error"]) * 1e-2) ** 2 * SCALE_ERROR_TIME_S,
            math.radians(float(v["mag_noise"])) ** 2,
            (float(v["mag_timing"]) * 1e-3) ** 2,
            math.radians(TILT_SIGMA_DEG) ** 2 * float(v["tau_acc_s"]),
            math.radians(REST_GYRO_DPS) ** 2,
            (REST_ACCEL_MG * 1e-3 * STANDARD_GRAVITY_M_S2) ** 2,
            field_rows, out,
        )
        self._head, self._mag_state = head, mag_state
        self._field_status = disturbance.field_status(field_rows, mag_state, settings,
                                                      self._field_reference)
        return out

    def _tilt_quaternions(self, block: SampleBlock) -> np.ndarray:
        """VQF 6D over ``block``, as ``self._tilt.process(block).quat`` without the angles
        ``process`` also computes (a quarter of this filter's time, and unused here)."""
        tilt = self._tilt
        q6 = tilt._process(block)
        # OrientationFilter.process's bookkeeping, which VQFFilter reads at its next block.
        tilt._quat = q6[-1].copy()
        tilt._has_state = True
        tilt._last_t = float(block.t_s[-1])
        return q6

    def _turned(self, q6: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """``Rz(delta) (x) q6`` without a field: delta held, restarts set it to 0."""
        n = len(q6)
        mag = np.full((n, 3), np.nan)
        head = self._head.copy()
        head[_VAR] = -1.0
        out = np.empty((n, 4))
        # The kernel with no field rows only holds delta and zeroes it at restarts; its
        # detector state is a throwaway copy.
        _heading_kernel(q6, np.zeros((n, 3)), np.zeros((n, 3)), dt, mag, head,
                        self._mag_state.copy(), self.disturbance_settings().as_array(),
                        0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, np.empty((n, 3)), out)
        self._head[_DELTA] = head[_DELTA]
        return out
