"""Offline (acausal) filters for recorded sessions: they see the whole recording at once.

- :class:`EKFSmoother` (``ekf-smoother``): the quaternion EKF run forward *and* backward in
  time, the two tilt estimates fused per sample with their covariances (the two-filter form of
  the fixed-interval smoother: Fraser & Potter 1969, "The optimum linear smoother as a
  combination of two optimum linear filters", IEEE TAC 14(4)). Chosen over the
  Rauch-Tung-Striebel form for a physical reason: the EKF's gravity measurement is the
  accelerometer averaged over the *past* ``lp_tau`` seconds, so its error at any moment is the
  gyro's error accumulated over the averaging window. An RTS pass smooths the states but keeps
  every measurement as the causal filter saw it; the backward filter averages over the *future*
  window instead, and where the forward average lags a turn the backward one leads it. Near
  either end of the recording, and after each restart, one of the two is still converging: its
  large covariance gives it no weight there.
- :class:`OfflineVQF` (``vqf-offline``): ``vqf.offlineVQF`` (Laidig & Seel 2023), VQF's own
  acausal variant with a non-causal low-pass and bias estimate; 9D (heading from the
  magnetometer, ENU with y toward magnetic north) when the recording has a field. offlineVQF
  runs one sample time for all three sensors and takes every row's field as a measurement, so a
  magnetometer slower than the accelerometer is held: each row gets the latest field sample
  (rows before the first get the first).

Both are ``offline``: they are offered for recordings only (``replay``, ``evaluate``, the replay
window), never for a live stream, and each ``process`` call is taken as a whole recording.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from app.core import quaternion as quat
from app.core.filters.base import (
    MAGNETOMETER_PARAMETER,
    OrientationFilter,
    ParameterSpec,
    restart_flags,
)
from app.core.filters.ekf import QuaternionEKF
from app.core.filters.vqf_filter import MISSING_MESSAGE, VQFUnavailableError, _vqf
from app.core.orientation import quaternion_from_up, up_in_sensor_frame
from app.core.samples import SampleBlock


def restarts(t_s: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """Indices where a stream restarts (the first sample, marked gaps, bad or long steps)."""
    if len(t_s) == 0:
        return np.empty(0, dtype=np.intp)
    bad = restart_flags(np.diff(t_s), gap[1:])
    return np.concatenate([[0], np.flatnonzero(bad) + 1])


def reversed_block(block: SampleBlock) -> SampleBlock:
    """The block played backwards: time mirrored, rotation reversed, gaps kept in place.

    A gap flag marks the restart *before* its sample; backwards the restart comes before the
    sample that preceded it, so the flags move one sample earlier.
    """
    gap = np.zeros(len(block), dtype=bool)
    gap[:-1] = block.gap[1:]
    # Forward, the rate of sample k turns the attitude from k-1 to k. Backwards the step from
    # k+1 to k needs the rate of sample k+1, negated: the rates shift by one sample.
    gyro = np.empty_like(block.gyro_rad_s)
    if len(block):
        gyro[0] = -block.gyro_rad_s[-1]
        gyro[1:] = -block.gyro_rad_s[::-1][:-1]
    return SampleBlock(
        -block.t_s[::-1], block.accel_m_s2[::-1], gyro, block.temp_degc[::-1], gap[::-1],
    )


def align_up(base: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``base`` (N, 4) turned, per sample, by the smallest rotation that makes its up direction
    (sensor frame) ``up`` (N, 3, unit): the tilt of ``up``, the heading of ``base``."""
    current = up_in_sensor_frame(base)
    axis = np.cross(up, current)  # sensor frame: rotating `up` onto `current`
    sin = np.linalg.norm(axis, axis=1)
    cos = np.sum(up * current, axis=1)
    angle = np.arctan2(sin, cos)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(sin[:, None] > 1e-15, axis / sin[:, None], 0.0)
    # q_new = q r: the new up is R(r)^T current, so r is the body rotation taking up to current.
    turn = quat.from_rotation_vector(unit * angle[:, None])
    return quat.normalize(quat.multiply(base, turn))


class EKFSmoother(QuaternionEKF):
    """The EKF forward and backward, fused by covariance (a two-filter smoother); offline."""

    name = "ekf-smoother"
    title = "EKF smoother (offline)"
    description = (
        "Offline: the quaternion EKF run forward and backward over the whole recording, the two "
        "tilts fused by their covariances. Uses the future: for recordings only."
    )
    offline = True

    def _process(self, block: SampleBlock) -> np.ndarray:
        values = self.parameter_values()
        n = len(block)
        forward_var = np.empty(n)
        backward_var = np.empty(n)
        ahead = QuaternionEKF(**values)
        forward = ahead.run_with_variance(block, forward_var)
        back = QuaternionEKF(**values)
        if values["estimate_bias"]:
            # The bias hardly moves over a recording: the backward pass starts from the bias
            # the forward pass ended with (negated, as time runs backwards) and its covariance.
            back._bias = -ahead._bias
            back._cov[2:, 2:] = ahead._cov[2:, 2:]
        backward = back.run_with_variance(reversed_block(block), backward_var)
        backward_var = backward_var[::-1]
        up_f = up_in_sensor_frame(forward)
        up_b = up_in_sensor_frame(backward[::-1])
        # Inverse-variance weights; the up directions are averaged on the sphere.
        w_f = 1.0 / np.maximum(forward_var, 1e-30)
        w_b = 1.0 / np.maximum(backward_var, 1e-30)
        up = (w_f[:, None] * up_f + w_b[:, None] * up_b) / (w_f + w_b)[:, None]
        norm = np.linalg.norm(up, axis=1)
        usable = np.isfinite(norm) & (norm > 1e-9)
        up[usable] /= norm[usable, None]
        up[~usable] = up_f[~usable]
        return align_up(forward, up)


class OfflineVQF(OrientationFilter):
    """VQF's offline variant (``vqf.offlineVQF``): acausal low-pass and bias; offline."""

    name = "vqf-offline"
    title = "VQF offline (Laidig & Seel 2023)"
    description = (
        "Offline: VQF's acausal variant over the whole recording (non-causal low-pass and bias "
        "estimation). Uses the future: for recordings only."
    )
    offline = True
    uses_magnetometer = True
    parameters = (
        ParameterSpec(
            "tau_acc_s", "Accelerometer time constant", "s", 3.0, 0.1, 100.0,
            "Low-pass time constant of the accelerometer correction (VQF tauAcc).",
            log_scale=True,
        ),
        ParameterSpec(
            "bias_sigma_init_dps", "Initial bias uncertainty", "deg/s", 0.5, 0.01, 10.0,
            "Standard deviation of the gyroscope bias at start (VQF biasSigmaInit).",
            log_scale=True,
        ),
        MAGNETOMETER_PARAMETER,
        ParameterSpec(
            "mag_disturbance_rejection", "Magnetic disturbance rejection", "", True, 0, 1,
            "Where the field's norm or dip leaves the reference learnt undisturbed, the "
            "gyroscope alone carries the heading (VQF magDistRejectionEnabled).",
            kind="bool",
        ),
    )

    def __init__(self, **values: Any) -> None:
        if _vqf is None:
            raise VQFUnavailableError(MISSING_MESSAGE, name="vqf")
        super().__init__(**values)

    def _process(self, block: SampleBlock) -> np.ndarray:
        params = {"tauAcc": float(self._values["tau_acc_s"]),
                  "biasSigmaInit": float(self._values["bias_sigma_init_dps"]),
                  "magDistRejectionEnabled": bool(self._values["mag_disturbance_rejection"])}
        out = np.empty((len(block), 4))
        starts = restarts(block.t_s, block.gap)
        use_field = block.mag_ut is not None and bool(self._values["magnetometer"])
        for first, stop in zip(starts, [*starts[1:], len(block)], strict=True):
            gyro = np.ascontiguousarray(block.gyro_rad_s[first:stop], dtype=np.float64)
            accel = np.ascontiguousarray(block.accel_m_s2[first:stop], dtype=np.float64)
            field = held_field(block.mag_ut[first:stop]) if use_field else None  # type: ignore[index]
            if stop - first < 2:
                norm = np.linalg.norm(accel, axis=1, keepdims=True)
                out[first:stop] = quaternion_from_up(accel / np.where(norm > 0, norm, 1.0))
                continue
            ts = float(np.median(np.diff(block.t_s[first:stop])))
            bad = ~np.all(np.isfinite(gyro), axis=1) | ~np.all(np.isfinite(accel), axis=1)
            if bad.any():  # VQF takes no NaN: hold the gyro still, the accelerometer as before
                gyro[bad] = 0.0
                accel[bad] = np.where(np.isfinite(accel[bad]), accel[bad], 0.0)
            result = _vqf.offlineVQF(gyro, accel, field, ts, params)
            chosen = "quat6D" if field is None else "quat9D"
            out[first:stop] = quat.normalize(np.asarray(result[chosen], dtype=np.float64))
        return out


def held_field(mag_ut: np.ndarray) -> np.ndarray | None:
    """Each row's latest field sample (rows before the first take the first), contiguous
    float64; None when no row has one."""
    field = np.asarray(mag_ut, dtype=np.float64)
    have = np.all(np.isfinite(field), axis=1)
    if not have.any():
        return None
    index = np.where(have, np.arange(len(field)), -1)
    index = np.maximum.accumulate(index)
    index[index < 0] = np.flatnonzero(have)[0]
    return np.ascontiguousarray(field[index])

