"""VQF, the versatile quaternion-based filter of Laidig & Seel (2023), via the ``vqf`` package.

D. Laidig and T. Seel, "VQF: Highly accurate IMU orientation estimation with bias estimation
and magnetic disturbance rejection", Information Fusion 91 (2023). The 6D (gyroscope and
accelerometer) part of the C++ implementation runs here: the gyroscope is integrated, the
accelerometer is low-pass filtered in an almost-inertial frame (time constant ``tauAcc``), and the
gyroscope bias is estimated during motion and, faster, at rest. With a magnetometer (the block
carries ``mag_ut`` and the ``magnetometer`` switch is on) the 9D part runs too: the heading
offset ``delta`` between the 6D earth frame and magnetic north is corrected from the field
(time constant ``tauMag``), about the vertical only, so the field never tilts the inclination;
while the field's norm or dip leaves the reference learnt undisturbed, the gyroscope alone
carries the heading (magnetic disturbance rejection). The output is then ``quat9D``:
sensor-to-earth in ENU, y toward magnetic north (VQF drives the earth-frame field's x to zero,
its y positive), the frame of BROAD's reference.

The magnetometer is slower than the accelerometer: a row without a new field sample (NaN)
goes to VQF as ``(0, 0, 0)``, which its ``updateMag`` skips, so the field update runs only on
real samples, and VQF runs it at the magnetometer's own period ``magTs``, learnt from the times
of the field rows (:meth:`VQFFilter._update_field_period`). Holding the last sample would feed
VQF the same field many times: its gain and its disturbance timers would run too fast.

Conventions: VQF's ``quat6D`` is ``(w, x, y, z)`` and rotates sensor-frame vectors into its earth
frame, z up, heading arbitrary: exactly this project's convention (see
:mod:`app.core.orientation`; ``tests/test_filter_vqf.py`` checks it on known poses), so the
quaternions are passed through unchanged.

Fixed sample period. VQF needs one sample time ``Ts``. It is the median time step of the
samples at hand (of the block, with up to the last :data:`RATE_HISTORY` steps before it), taken
when the filter starts (a stream that opens with a lone sample starts on a provisional Ts, and
that sample is replayed at the right Ts with the next block). Each block then goes through
``VQF.updateBatch``, so the state runs on across blocks. The VQF object is recreated when

- the stream restarts (first sample, a marked gap, a step longer than ``MAX_STEP_S`` or going
  back in time): orientation, low-pass and rest-detection states start afresh from the
  accelerometer, as every filter restarts; the gyroscope bias estimate and its uncertainty are
  carried over, since lost samples do not change the sensor's bias;
- the median step differs from ``Ts`` by more than :data:`RATE_TOLERANCE` (5 %): a new object
  with the new ``Ts`` continues from the current orientation, bias and heading offset (its
  low-pass and rest-detection states start afresh);
- the field period changes by more than that: a new object takes over the whole state.

A restart keeps the magnetic reference (the field norm and dip learnt undisturbed) with the
bias; the heading offset starts afresh and converges at once from the next field samples (VQF's
initial gain). Without a field the filter is exactly the 6D filter it was.

Parameters change without losing state: ``tauAcc`` through VQF's ``setTauAcc`` (which adapts
its low-pass states), the two bias estimators through their ``set...Enabled`` calls, and the
initial bias uncertainty (which VQF only reads at start-up, and as a cap on the uncertainty)
by a new object that takes over the complete state of the old one (so do the disturbance
thresholds); ``tauMag`` and the disturbance rejection through ``setTauMag`` and
``setMagDistRejectionEnabled``.
"""

from __future__ import annotations

from itertools import pairwise
from typing import Any

import numpy as np

from app.core.filters.base import MAGNETOMETER_PARAMETER, OrientationFilter, ParameterSpec
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

try:  # the filter is optional at import time: the app runs without the package
    import vqf as _vqf
except ImportError:  # pragma: no cover - exercised by a test that hides the package
    _vqf = None

VQF_AVAILABLE = _vqf is not None
"""True when the ``vqf`` package imports."""

MISSING_MESSAGE = "the VQF filter needs the 'vqf' package: pip install vqf"
RATE_TOLERANCE = 0.05
"""Relative change of the median time step that makes the filter recreate VQF with a new Ts."""
RATE_HISTORY = 64
"""Time steps remembered from earlier blocks, so that short live blocks give a steady median."""
RATE_SAMPLE_LIMIT = 4096
"""At most this many of a block's latest time steps enter the median (bounds its cost)."""
DEFAULT_SAMPLE_PERIOD_S = 0.01
"""Provisional Ts when a stream opens with a lone sample (that sample is replayed at the right
Ts as soon as the next block gives the rate)."""


class VQFUnavailableError(ImportError, ValueError):
    """The ``vqf`` package is missing (a ValueError too, so the GUI reports it like a bad name)."""


def field_for_vqf(mag_ut: np.ndarray) -> np.ndarray:
    """The field rows as VQF takes them: contiguous float64, and ``(0, 0, 0)`` on rows without
    a new field sample (any non-finite component), which VQF's ``updateMag`` skips."""
    field = np.array(mag_ut, dtype=np.float64, order="C")
    field[~np.all(np.isfinite(field), axis=1)] = 0.0
    return field


MAG_STATE_CARRIED = ("magRefNorm", "magRefDip")
"""The magnetic reference (field norm and dip learnt while undisturbed) survives a restart, as
the gyroscope bias does: lost samples change neither the sensor nor its surroundings."""


class VQFFilter(OrientationFilter):
    """VQF orientation with gyroscope bias estimation (the C++ ``vqf.VQF``); 9D with a field."""

    name = "vqf"
    title = "VQF (Laidig & Seel 2023)"
    description = (
        "Gyro integration with accelerometer correction in an almost-inertial frame and "
        "gyroscope bias estimation during motion and at rest; with a magnetometer, heading "
        "from the field (VQF 9D, ENU with y to magnetic north), about the vertical only, "
        "with magnetic disturbance rejection."
    )
    uses_magnetometer = True
    parameters = (
        ParameterSpec(
            "tau_acc_s", "Accelerometer time constant", "s", 3.0, 0.1, 100.0,
            "Low-pass time constant of the accelerometer correction (VQF tauAcc). Smaller "
            "follows the accelerometer sooner; larger rejects linear acceleration better.",
            log_scale=True, presets=(("VQF default", 3.0),),
        ),
        MAGNETOMETER_PARAMETER,
        ParameterSpec(
            "tau_mag_s", "Magnetometer time constant", "s", 9.0, 0.5, 100.0,
            "Time constant of the heading correction from the magnetometer (VQF tauMag). "
            "Larger: less magnetometer noise and short disturbances in the heading.",
            log_scale=True, presets=(("VQF default", 9.0),),
        ),
        ParameterSpec(
            "mag_disturbance_rejection", "Magnetic disturbance rejection", "", True, 0, 1,
            "While the field's norm or dip leaves the reference learnt undisturbed, the "
            "gyroscope alone carries the heading (up to 60 s) (VQF magDistRejectionEnabled).",
            kind="bool",
        ),
        ParameterSpec(
            "mag_norm_threshold", "Field norm threshold", "", 0.1, 0.01, 1.0,
            "Relative difference of the field's norm from the learnt reference above which the "
            "field counts as disturbed (VQF magNormTh; 0.1: 10 %).",
            presets=(("VQF default", 0.1),),
        ),
        ParameterSpec(
            "mag_dip_threshold_deg", "Field dip threshold", "deg", 10.0, 1.0, 90.0,
            "Difference of the field's dip from the learnt reference above which the field "
            "counts as disturbed (VQF magDipTh).",
            presets=(("VQF default", 10.0),),
        ),
        ParameterSpec(
            "motion_bias_estimation", "Bias estimation in motion", "", True, 0, 1,
            "Estimate the gyroscope bias while the sensor moves (VQF motionBiasEstEnabled).",
            kind="bool",
        ),
        ParameterSpec(
            "rest_bias_estimation", "Bias estimation at rest", "", True, 0, 1,
            "Detect rest and estimate the gyroscope bias quickly then "
            "(VQF restBiasEstEnabled).",
            kind="bool",
        ),
        ParameterSpec(
            "bias_sigma_init_dps", "Initial bias uncertainty", "deg/s", 0.5, 0.01, 10.0,
            "Standard deviation of the gyroscope bias at start, also the largest the "
            "uncertainty grows to (VQF biasSigmaInit). Larger learns the bias faster.",
            log_scale=True,
        ),
    )

    def __init__(self, **values: Any) -> None:
        if _vqf is None:
            raise VQFUnavailableError(MISSING_MESSAGE, name="vqf")
        self._vqf: Any = None
        self._ts: float | None = None
        self._recent_dt = np.empty(0)
        self._pending: tuple[dict[str, Any] | None, np.ndarray, np.ndarray,
                             np.ndarray | None] | None = None
        self._mag_ts: float | None = None
        self._recent_mag_dt = np.empty(0)
        self._last_field_t: float | None = None
        super().__init__(**values)

    # -- VQF objects ------------------------------------------------------------------------
    def _vqf_params(self) -> dict[str, Any]:
        values = self._values
        return {
            "tauAcc": float(values["tau_acc_s"]),
            "motionBiasEstEnabled": bool(values["motion_bias_estimation"]),
            "restBiasEstEnabled": bool(values["rest_bias_estimation"]),
            "biasSigmaInit": float(values["bias_sigma_init_dps"]),
            "tauMag": float(values["tau_mag_s"]),
            "magDistRejectionEnabled": bool(values["mag_disturbance_rejection"]),
            "magNormTh": float(values["mag_norm_threshold"]),
            "magDipTh": float(values["mag_dip_threshold_deg"]),
        }

    def _new_vqf(self, ts: float, mag_ts: float | None = None) -> Any:
        return _vqf.VQF(ts, ts, ts if mag_ts is None else mag_ts, **self._vqf_params())

    def _bias_state(self) -> dict[str, Any] | None:
        """The current object's bias estimate and covariance, and its magnetic reference
        (None before the first)."""
        if self._vqf is None:
            return None
        state = self._vqf.state
        carried = {"bias": state["bias"], "biasP": state["biasP"]}
        if state["magRefNorm"] > 0.0:
            carried.update({key: state[key] for key in MAG_STATE_CARRIED})
        return carried

    def _start(
        self, ts: float, seed: np.ndarray | None, bias: dict[str, Any] | None
    ) -> None:
        """A new VQF with sample time ``ts``, continuing from quaternion ``seed`` if given.

        ``bias`` (from :meth:`_bias_state`) carries a bias estimate over.
        """
        new = self._new_vqf(ts, self._mag_ts)
        state = new.state
        if bias is not None:
            state.update(bias)
        if seed is not None:
            # Orientation = seed, and the accelerometer low-pass in its steady state for a
            # sensor at rest in that orientation, so the estimate continues without a jump.
            state["gyrQuat"] = [float(c) for c in seed]
            state["accQuat"] = [1.0, 0.0, 0.0, 0.0]
            steady = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
            coeffs = new.coeffs
            b, a = np.array(coeffs["accLpB"]), np.array(coeffs["accLpA"])
            state["lastAccLp"] = steady.tolist()
            state["accLpState"] = np.concatenate(
                [new.filterInitialState(x, b, a) for x in steady]
            ).tolist()
        new.state = state
        self._vqf = new
        self._ts = ts

    def _sample_period(self, steps: np.ndarray) -> float:
        """Median time step of ``steps`` and the remembered ones; updates the memory."""
        if len(steps):
            recent = np.concatenate([self._recent_dt, steps[-RATE_SAMPLE_LIMIT:]])
            self._recent_dt = recent[-RATE_HISTORY:]
        else:
            recent = self._recent_dt
        if len(recent) == 0:
            return self._ts if self._ts is not None else DEFAULT_SAMPLE_PERIOD_S
        return float(np.median(recent))

    def _parameters_changed(self) -> None:
        current = getattr(self, "_vqf", None)
        if current is None:
            return  # applied when the next VQF object is made
        wanted = self._vqf_params()
        have = current.params
        if wanted["tauAcc"] != have["tauAcc"]:
            current.setTauAcc(wanted["tauAcc"])
        if wanted["motionBiasEstEnabled"] != have["motionBiasEstEnabled"]:
            current.setMotionBiasEstEnabled(wanted["motionBiasEstEnabled"])
        if wanted["restBiasEstEnabled"] != have["restBiasEstEnabled"]:
            current.setRestBiasEstEnabled(wanted["restBiasEstEnabled"])
        if wanted["tauMag"] != have["tauMag"]:
            current.setTauMag(wanted["tauMag"])
        if wanted["magDistRejectionEnabled"] != have["magDistRejectionEnabled"]:
            current.setMagDistRejectionEnabled(wanted["magDistRejectionEnabled"])
        if any(wanted[key] != have[key] for key in ("biasSigmaInit", "magNormTh", "magDipTh")):
            # No setter: a new object with the new parameters takes over the whole state.
            self._take_over()

    def _take_over(self) -> None:
        """A new object (current parameters, Ts and field period) with the whole state of the
        current one."""
        assert self._ts is not None
        new = self._new_vqf(self._ts, self._mag_ts)
        new.state = self._vqf.state
        self._vqf = new

    # -- state ------------------------------------------------------------------------------
    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        super().reset(initial_quat, last_time_s)
        self._vqf = None
        self._ts = None
        self._recent_dt = np.empty(0)
        self._pending = None
        self._mag_ts = None
        self._recent_mag_dt = np.empty(0)
        self._last_field_t = None

    @property
    def sample_period_s(self) -> float | None:
        """The Ts the current VQF object runs at (None before the first sample)."""
        return self._ts

    @property
    def field_period_s(self) -> float | None:
        """The magnetometer's sample period VQF runs its field update at (None before the
        first field sample)."""
        return self._mag_ts

    @property
    def magnetic_disturbance(self) -> bool:
        """VQF's magnetic disturbance flag after the last sample (False without a field)."""
        return bool(self._vqf is not None and self._last_field_t is not None
                    and self._vqf.getMagDistDetected())

    @property
    def bias_estimate_rad_s(self) -> np.ndarray:
        """VQF's current gyroscope bias estimate (3,), rad/s (zeros before the first sample)."""
        if self._vqf is None:
            return np.zeros(3)
        return np.asarray(self._vqf.getBiasEstimate()[0], dtype=np.float64)

    def warm_up(self) -> None:
        """Nothing to compile; VQF is ready (and its state must not see made-up samples)."""

    # -- processing -------------------------------------------------------------------------
    def _field_rows(self, block: SampleBlock) -> np.ndarray | None:
        """The field as VQF takes it, or None when the block has none or the switch is off."""
        if block.mag_ut is None or not self._values["magnetometer"]:
            return None
        return field_for_vqf(block.mag_ut)

    def _update_field_period(self, t_s: np.ndarray, field: np.ndarray) -> None:
        """Learn the magnetometer's period from the times of the rows with a new field sample
        (VQF's heading gain and its disturbance timers run at it); a change over
        :data:`RATE_TOLERANCE` hands the whole state to an object with the new period."""
        rows = np.flatnonzero(np.any(field != 0.0, axis=1))
        if len(rows) == 0:
            return
        times = t_s[rows]
        if self._last_field_t is not None and times[0] > self._last_field_t:
            times = np.concatenate([[self._last_field_t], times])
        self._last_field_t = float(t_s[rows[-1]])
        steps = np.diff(times)
        steps = steps[np.isfinite(steps) & (steps > 0.0) & (steps <= 1.0)]
        if len(steps) == 0:
            return
        recent = np.concatenate([self._recent_mag_dt, steps[-RATE_SAMPLE_LIMIT:]])
        self._recent_mag_dt = recent[-RATE_HISTORY:]
        # The mean step, without lost samples (over twice the median): a magnetometer whose
        # rate is not a whole fraction of the accelerometer's arrives 2, 3, 2, 3... rows apart,
        # whose median is either, not the period.
        period = float(np.mean(recent[recent <= 2.0 * np.median(recent)]))
        if self._mag_ts is None or abs(period / self._mag_ts - 1.0) > RATE_TOLERANCE:
            self._mag_ts = period
            if self._vqf is not None:
                self._take_over()

    def _process(self, block: SampleBlock) -> np.ndarray:
        n = len(block)
        dt = self.time_steps(block)
        gyro = np.ascontiguousarray(block.gyro_rad_s, dtype=np.float64)
        accel = np.ascontiguousarray(block.accel_m_s2, dtype=np.float64)
        field = self._field_rows(block)
        output = "quat6D" if field is None else "quat9D"
        restarts = np.flatnonzero(dt == 0.0)
        edges = [0, *restarts[restarts > 0].tolist(), n]
        pieces = []
        for start, stop in pairwise(edges):
            restart = dt[start] == 0.0
            steps = dt[start + 1 : stop] if restart else dt[start:stop]
            ts = self._sample_period(steps)
            if restart:
                bias = self._bias_state()
                self._start(ts, None, bias)
                # A stream that opens with a lone sample gives no rate: Ts is provisional, and
                # the sample is replayed once the next block tells the rate.
                unknown_rate = len(self._recent_dt) == 0
                self._pending = (
                    (bias, gyro[start:stop].copy(), accel[start:stop].copy(),
                     None if field is None else field[start:stop].copy())
                    if unknown_rate else None
                )
            elif self._pending is not None:
                bias, gyro0, accel0, field0 = self._pending
                self._pending = None
                self._start(ts, None, bias)
                self._vqf.updateBatch(gyro0, accel0, field0 if field is not None else None)
            elif self._vqf is None:  # reset(initial_quat) asked to continue from a quaternion
                self._start(ts, self._quat, None)
            elif abs(ts / self._ts - 1.0) > RATE_TOLERANCE:  # type: ignore[operator]
                self._restart_at_rate(ts)
            if field is None:
                pieces.append(self._vqf.updateBatch(gyro[start:stop], accel[start:stop])[output])
                continue
            self._update_field_period(block.t_s[start:stop], field[start:stop])
            pieces.append(self._vqf.updateBatch(
                gyro[start:stop], accel[start:stop], field[start:stop])[output])
        return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)

    def _restart_at_rate(self, ts: float) -> None:
        """A new object at sample time ``ts`` continuing from the current orientation, bias and
        heading correction (its low-pass and rest-detection states start afresh)."""
        old = self._vqf.state
        self._start(ts, np.asarray(self._vqf.getQuat6D()), self._bias_state())
        state = self._vqf.state
        for key in ("delta", "kMagInit", "magDistDetected", "magRejectT", "magUndisturbedT",
                    "magCandidateNorm", "magCandidateDip", "magCandidateT"):
            state[key] = old[key]
        self._vqf.state = state
