"""Causal hinge-joint angle from two 6-axis IMUs, without magnetometers.

Per pair of simultaneous samples (:meth:`JointEstimator.update`, any block size, live or
replayed):

1. each link's 6D orientation by VQF (:class:`~app.core.filters.vqf_filter.VQFFilter`, with
   its gyroscope-bias estimate);
2. the hinge axis ``j1``, ``j2`` in the sensors' frames: given, or estimated from the gyroscopes
   (:func:`~app.core.joint.axis.estimate_hinge_axes`) on the samples so far, re-estimated
   as the motion grows (every :data:`AXIS_REFIT_S` s over the last :data:`AXIS_WINDOW_S` s);
3. the heading offset between the two orientation estimates from the hinge constraint
   (:class:`~app.core.joint.heading.HeadingTracker`);
4. the angle of the relative orientation about the hinge, ``theta_ori``, fused with the
   integral of the gyroscopes' difference about the axis, ``d theta / dt = j2 . w2 - j1 . w1``
   (bias-corrected): a second-order complementary filter (time constant ``fusion_tau_s``) that
   takes the short-term shape from the gyroscopes, which have neither the accelerometers'
   disturbance nor the heading's lag, and the long-term level from ``theta_ori``, also tracking
   the remaining rate bias.

The angle's zero is where a fixed perpendicular of ``j2`` lines up with one of ``j1`` (an
arbitrary but constant offset); its sign follows the right-hand rule about ``j1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.core import quaternion as quat
from app.core.filters.vqf_filter import VQFFilter
from app.core.joint.axis import (
    AxisEstimate,
    consistent_sign,
    estimate_hinge_axes,
    tangent_basis,
)
from app.core.joint.heading import HeadingTracker, heading_measurements, heading_quaternion
from app.core.samples import SampleBlock

CHUNK = 64
"""Samples per VQF step inside an update, so that the bias estimate follows within a block."""
AXIS_FIRST_S = 5.0
"""Seconds of motion before an estimated axis is first used (the angle is NaN until then)."""
AXIS_REFIT_S = 10.0
AXIS_WINDOW_S = 120.0
AXIS_LIVE_SAMPLES = 6000
"""Samples a live refit uses (spread over the window): keeps a refit near 0.1 s."""
AXIS_SEARCHES = 3
"""Refits that also search afresh from random starts (later ones refine the axis in use)."""
DEFAULT_FUSION_TAU_S = 3.0


@dataclass
class JointBlock:
    """Per-sample output of :meth:`JointEstimator.update` (all (N,))."""

    angle_deg: np.ndarray
    """The fused joint angle (NaN before the axis is known)."""
    orientation_angle_deg: np.ndarray
    """The angle of the heading-corrected relative orientation alone."""
    heading_offset_deg: np.ndarray


def hinge_angle(quat1: np.ndarray, quat2: np.ndarray, j1: np.ndarray,
                j2: np.ndarray) -> np.ndarray:
    """(N,) angle (rad) of sensor 2 relative to sensor 1 about the hinge, both quaternions in one
    earth frame: a fixed perpendicular of ``j2`` against one of ``j1``, about ``j1``."""
    u1 = tangent_basis(j1)[:, 0]
    u2 = tangent_basis(j2)[:, 0]
    v = quat.rotate_inverse(quat1, quat.rotate(quat2, u2))
    return np.arctan2(np.cross(u1, v) @ j1, v @ u1)


class JointEstimator:
    """Causal joint angle of a hinge between sensor 1 and sensor 2 (see the module docstring).

    Parameters
    ----------
    axes : ``(j1, j2)`` known axes in the sensors' frames, or None to estimate them.
    fusion_tau_s : time constant of the gyroscope / orientation fusion (0: orientation only).
    heading : the heading tracker (default: :class:`HeadingTracker` with its defaults).
    vqf_parameters : parameters of both links' VQF (:class:`VQFFilter`'s names).
    """

    def __init__(self, axes: tuple[np.ndarray, np.ndarray] | None = None,
                 fusion_tau_s: float = DEFAULT_FUSION_TAU_S,
                 heading: HeadingTracker | None = None,
                 vqf_parameters: dict[str, float] | None = None) -> None:
        self.fixed_axes = axes is not None
        self.axes: tuple[np.ndarray, np.ndarray] | None = None
        if axes is not None:
            j1, j2 = (np.asarray(a, dtype=np.float64) for a in axes)
            self.axes = (j1 / np.linalg.norm(j1), j2 / np.linalg.norm(j2))
        self.axis_estimate: AxisEstimate | None = None
        self.fusion_tau_s = fusion_tau_s
        self.heading = heading if heading is not None else HeadingTracker()
        self.vqf1 = VQFFilter(**(vqf_parameters or {}))
        self.vqf2 = VQFFilter(**(vqf_parameters or {}))
        self._history: list[np.ndarray] = []  # (n, 15): t, w1, w2 (bias-corrected), q1, q2
        self._next_fit_t = -math.inf
        self._fits = 0
        self._theta = math.nan
        self._rate_bias = 0.0
        self._last_t: float | None = None

    # -- axes -------------------------------------------------------------------------------
    def _maybe_fit_axes(self, t: float) -> None:
        if self.fixed_axes or t < self._next_fit_t or not self._history:
            return
        data = np.concatenate(self._history)
        keep = data[:, 0] >= t - AXIS_WINDOW_S
        data = data[keep]
        self._history = [data]
        if data[-1, 0] - data[0, 0] < AXIS_FIRST_S:
            self._next_fit_t = data[0, 0] + AXIS_FIRST_S
            return
        w1, w2 = data[:, 1:4], data[:, 4:7]
        try:
            if self.axes is not None:
                found = estimate_hinge_axes(w1, w2, start=self.axes, limit=AXIS_LIVE_SAMPLES)
            if self.axes is None or self._fits < AXIS_SEARCHES:
                # A search from random starts, against a local minimum of early, poor motion.
                fresh = estimate_hinge_axes(w1, w2, limit=AXIS_LIVE_SAMPLES)
                if self.axes is None or fresh.residual_rms_rad_s < found.residual_rms_rad_s:
                    found = fresh
        except ValueError:  # too little motion so far
            self._next_fit_t = t + 1.0
            return
        self._fits += 1
        j1 = found.j1 if self.axes is None or found.j1 @ self.axes[0] >= 0 else -found.j1
        # The relative sign from the whole window's orientations, each time: the first few
        # seconds may show too little of the axis' inclination to be sure of it.
        j2 = consistent_sign(j1, found.j2, data[:, 7:11], data[:, 11:15])
        if self.axes is not None and j2 @ self.axes[1] < 0:
            self.heading.reset()  # it was mirrored: heading and angle start afresh
            self._theta = math.nan
        self.axes = (j1, j2)
        self.axis_estimate = found
        self._next_fit_t = t + AXIS_REFIT_S

    # -- processing ---------------------------------------------------------------------------
    def update(self, block1: SampleBlock, block2: SampleBlock) -> JointBlock:
        """Joint angle for simultaneous samples: ``block1`` of sensor 1, ``block2`` of sensor 2
        (same length; their times must match, sensor 1's are used)."""
        n = len(block1)
        if len(block2) != n:
            raise ValueError(f"the two sensors' blocks differ in length ({n} and {len(block2)})")
        out = JointBlock(np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan))
        for start in range(0, n, CHUNK):
            stop = min(n, start + CHUNK)
            self._update_chunk(_slice(block1, start, stop), _slice(block2, start, stop),
                               out, start)
        return out

    def _update_chunk(self, b1: SampleBlock, b2: SampleBlock, out: JointBlock,
                      offset: int) -> None:
        bias1 = self.vqf1.bias_estimate_rad_s
        bias2 = self.vqf2.bias_estimate_rad_s
        q1 = self.vqf1.process(b1).quat
        q2 = self.vqf2.process(b2).quat
        w1 = b1.gyro_rad_s - bias1
        w2 = b2.gyro_rad_s - bias2
        t = b1.t_s
        n = len(t)
        if not self.fixed_axes:
            self._history.append(np.column_stack([t, w1, w2, q1, q2]))
            self._maybe_fit_axes(float(t[-1]))
        if self.axes is None:
            return
        j1, j2 = self.axes
        dt = np.diff(t, prepend=t[0] if self._last_t is None else self._last_t)
        restart = (dt <= 0) | (dt > 0.5) | b1.gap | b2.gap
        dt = np.where(restart, 0.0, dt)
        self._last_t = float(t[-1])
        delta = self.heading.update(heading_measurements(q1, j1, q2, j2), dt)
        q1c = quat.multiply(heading_quaternion(delta), q1)
        theta_ori = hinge_angle(q1c, q2, j1, j2)
        rate = w2 @ j2 - w1 @ j1
        fused = self._fuse(theta_ori, rate, dt)
        sl = slice(offset, offset + n)
        out.angle_deg[sl] = np.degrees(fused)
        out.orientation_angle_deg[sl] = np.degrees(theta_ori)
        out.heading_offset_deg[sl] = np.degrees(delta)

    def _fuse(self, theta_ori: np.ndarray, rate: np.ndarray, dt: np.ndarray) -> np.ndarray:
        out = np.empty(len(theta_ori))
        tau = self.fusion_tau_s
        theta, bias = self._theta, self._rate_bias
        for i in range(len(out)):
            measured = float(theta_ori[i])
            if not math.isfinite(measured):
                out[i] = theta
                continue
            h = float(dt[i])
            if not math.isfinite(theta) or tau <= 0.0:
                theta = measured
                out[i] = theta
                continue
            theta += (float(rate[i]) - bias) * h
            e = math.remainder(measured - theta, 2.0 * math.pi)
            k1 = min(2.0 * h / tau, 1.0)
            k2 = h / (tau * tau)
            theta += k1 * e
            bias -= k2 * e
            theta = math.remainder(theta, 2.0 * math.pi)
            out[i] = theta
        self._theta, self._rate_bias = theta, bias
        return out


def _slice(block: SampleBlock, start: int, stop: int) -> SampleBlock:
    return SampleBlock(
        block.t_s[start:stop], block.accel_m_s2[start:stop], block.gyro_rad_s[start:stop],
        block.temp_degc[start:stop], block.gap[start:stop],
        None if block.reference_quat is None else block.reference_quat[start:stop],
    )
