"""Temperature compensation: gyroscope and accelerometer bias against die temperature.

:func:`fit_temperature` takes an *uncalibrated* stream in which the board rests while its
temperature moves (a warm-up after power-up, or still poses held at several temperatures) and
fits, per axis::

    b(T) = c_pose + k1 (T - T0) + k2 (T - T0)^2

Steps:

1. **Still samples** come from the wizard's own :class:`~.stillness.StillnessDetector`; still
   stretches shorter than :data:`MIN_SEGMENT_S` are dropped (a pause in handling, not a pose).
2. **Poses**: consecutive still segments whose gravity directions agree within
   :data:`SAME_POSE_DEG` form one pose. The gyroscope reads its bias at rest in any pose; the
   accelerometer reads bias *plus gravity*, so every pose gets its own intercept ``c_pose`` and
   only the slope and curvature are shared.
3. **Bins**: within each pose, still samples are averaged in temperature bins (width
   ``span / TARGET_BINS``, at least :data:`MIN_BIN_DEGC`; bins with under
   :data:`MIN_BIN_S` of data are dropped). Every temperature counts alike, however long the
   board sat at it, and the bias random walk inside a bin averages out instead of making
   thousands of correlated residuals.
4. **Degree** (per sensor, the three axes together): the linear and the quadratic model are
   fitted by least squares to the bin means, and the quadratic is kept only when the span is
   at least :data:`QUADRATIC_MIN_SPAN_DEGC` *and* it lowers the small-sample Akaike criterion
   (AICc, summed over the axes) by more than :data:`QUADRATIC_MIN_AIC_GAIN`; the bins count
   as ``n_eff = n (1 - rho) / (1 + rho)`` independent points, ``rho`` the lag-1
   autocorrelation of the quadratic's residuals, so that the slow wander of a bias random
   walk is not taken for curvature (real curvature leaves white residuals). The physical
   reason: over a few degrees a MEMS bias is linear in temperature to within its noise (the
   curvature of the drift needs a wide span to show, and fitted on a narrow one it only
   follows the random walk and extrapolates wildly); over tens of degrees the LSM6DSOX's
   zero-rate level bends, and then the quadratic earns its extra three parameters. A gain of
   10 in AICc is "essentially no support for the simpler model" (Burnham & Anderson).

Too narrow a span (under :data:`MIN_SPAN_DEGC`) is refused with
:class:`TemperatureFitError`: the slope's error is about the bias drift not caused by
temperature (the random walk, ~0.001 dps in half an hour) divided by the span.

A limit of one static pose: the accelerometer's *sensitivity* also drifts with temperature
(``scale_tc``), and on the axis gravity loads that looks exactly like a bias drift of
``scale_tc x g``. The fit takes it as bias: exact in that pose (level, the pose of a tilt
meter), off by about ``scale_tc x delta g`` in others. The gyroscope has no such ambiguity
(no rate at rest).

:meth:`TemperatureFit.compensation` gives the :class:`~app.core.calibration.
TemperatureCompensation`; :func:`merge_temperature` puts it on an existing calibration (a
six-position one): that calibration's biases stay as ``b0`` at its own temperature and the
fitted curve supplies only the change from there.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.core.calibration import SensorCalibration, TemperatureCompensation, calibration_to_json
from app.core.calibration_procedures.offline import JSON_FORMAT, JSON_VERSION
from app.core.calibration_procedures.profiles import SensorSettings
from app.core.calibration_procedures.stillness import SensorNoise, StillnessDetector
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

MIN_SPAN_DEGC = 3.0
"""Narrowest temperature span (of the still data) that gives a slope."""
QUADRATIC_MIN_SPAN_DEGC = 10.0
"""Narrowest span on which a quadratic term is considered at all."""
QUADRATIC_MIN_AIC_GAIN = 10.0
"""AICc improvement (summed over three axes) the quadratic needs to be chosen."""
MIN_SEGMENT_S = 2.0
"""Shorter still stretches are not used."""
SAME_POSE_DEG = 2.0
"""Still segments whose gravity directions differ by less than this are one pose."""
TARGET_BINS = 40
MIN_BIN_DEGC = 0.05
MIN_BIN_S = 1.0
FEED_S = 0.5
REFERENCE_TEMP_DEGC = 25.0
"""The simulator's (and the datasheet's) reference temperature, for truth comparisons."""

LINEAR, QUADRATIC = 1, 2


class TemperatureFitError(ValueError):
    """The stream gives no temperature fit; the message says why, for the user."""


@dataclass(frozen=True)
class SensorTemperatureFit:
    """One sensor's fit (accelerometer in m/s^2, gyroscope in rad/s), about ``T0``.

    Attributes
    ----------
    degree : :data:`LINEAR` or :data:`QUADRATIC` (the chosen model).
    intercepts : (poses, 3) the bias (gyro) or reading (accel) of each pose at ``T0``.
    k1, k2 : (3,) the chosen model's coefficients (``k2`` zero for a linear one).
    k1_std, k2_std : (3,) their 1-sigma uncertainties.
    rms : (3,) residual RMS of the chosen model at the bin means.
    aicc : ``{1: linear, 2: quadratic}`` AICc summed over the axes (NaN when not computed).
    """

    degree: int
    intercepts: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    k1_std: np.ndarray
    k2_std: np.ndarray
    rms: np.ndarray
    aicc: dict[int, float]

    def change(self, delta_t: np.ndarray) -> np.ndarray:
        """Bias change (N, 3) at ``T - T0`` (N,)."""
        d = np.asarray(delta_t, dtype=np.float64).reshape(-1, 1)
        return d * self.k1 + d * d * self.k2


@dataclass(frozen=True)
class TemperatureFit:
    """Everything :func:`fit_temperature` found (see the module docstring).

    ``bin_temp_degc`` (B,), ``bin_pose`` (B,), ``bin_samples`` (B,), ``bin_gyro_rad_s`` (B, 3)
    and ``bin_accel_m_s2`` (B, 3) are the averaged points the models were fitted to;
    ``pose_up`` (poses, 3) is each pose's measured gravity direction (unit vectors).
    """

    reference_temp_degc: float
    temp_min_degc: float
    temp_max_degc: float
    gyro: SensorTemperatureFit
    accel: SensorTemperatureFit
    bin_temp_degc: np.ndarray
    bin_pose: np.ndarray
    bin_samples: np.ndarray
    bin_gyro_rad_s: np.ndarray
    bin_accel_m_s2: np.ndarray
    pose_up: np.ndarray
    segments: int
    still_s: float
    duration_s: float
    samples: int
    settings: SensorSettings
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def span_degc(self) -> float:
        return self.temp_max_degc - self.temp_min_degc

    @property
    def poses(self) -> int:
        return len(self.pose_up)

    @property
    def gyro_bias_at_reference_rad_s(self) -> np.ndarray:
        """The gyroscope's (absolute) bias at ``T0``: no rate at rest in any pose."""
        return self.gyro.intercepts.mean(axis=0)

    def compensation(self, reference_temp_degc: float | None = None) -> TemperatureCompensation:
        """The fitted terms, about ``T0`` or re-centred on ``reference_temp_degc``."""
        model = TemperatureCompensation(
            reference_temp_degc=self.reference_temp_degc,
            accel_k1=self.accel.k1.copy(), accel_k2=self.accel.k2.copy(),
            gyro_k1=self.gyro.k1.copy(), gyro_k2=self.gyro.k2.copy(),
        )
        return model if reference_temp_degc is None else model.recentred(reference_temp_degc)

    def summary(self) -> dict[str, Any]:
        """Plain numbers for a profile's ``residuals`` and the JSON file."""
        def sensor(fit: SensorTemperatureFit) -> dict[str, Any]:
            return {
                "model": "quadratic" if fit.degree == QUADRATIC else "linear",
                "k1_std": fit.k1_std.tolist(), "k2_std": fit.k2_std.tolist(),
                "residual_rms": fit.rms.tolist(),
                "aicc_linear": _finite(fit.aicc.get(LINEAR, math.nan)),
                "aicc_quadratic": _finite(fit.aicc.get(QUADRATIC, math.nan)),
            }
        return {
            "reference_temp_degc": self.reference_temp_degc,
            "temp_min_degc": self.temp_min_degc, "temp_max_degc": self.temp_max_degc,
            "span_degc": self.span_degc, "poses": self.poses, "segments": self.segments,
            "bins": len(self.bin_temp_degc), "still_s": self.still_s,
            "gyro": sensor(self.gyro), "accel": sensor(self.accel),
            "criterion": (f"quadratic only with a span >= {QUADRATIC_MIN_SPAN_DEGC:g} degC and "
                          f"an AICc gain > {QUADRATIC_MIN_AIC_GAIN:g}"),
        }


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


# -- finding the still data ------------------------------------------------------------------------
def still_mask(block: SampleBlock, settings: SensorSettings) -> np.ndarray:
    """Per-sample flags: inside a still window of the wizard's detector (N,) bool."""
    noise = SensorNoise.lsm6dsox(settings.odr_hz, settings.accel_fs_g, settings.gyro_fs_dps)
    detector = StillnessDetector(noise)
    n = len(block)
    ends = np.zeros(n, dtype=bool)
    size = max(8, round(FEED_S * settings.odr_hz))
    for start in range(0, n, size):
        rows = slice(start, min(n, start + size))
        ends[rows] = detector.update(SampleBlock(
            t_s=block.t_s[rows], accel_m_s2=block.accel_m_s2[rows],
            gyro_rad_s=block.gyro_rad_s[rows], temp_degc=block.temp_degc[rows],
            gap=block.gap[rows]))
    # A still window ending at sample i covers the window's samples before it too.
    w = detector.window
    counts = np.concatenate([[0], np.cumsum(ends)])
    index = np.arange(n)
    return (counts[np.minimum(index + w, n)] - counts[index]) > 0


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


# -- least squares ---------------------------------------------------------------------------------
def _aicc(rss: float, n: float, k: int) -> float:
    if n - k - 1 <= 0:
        return math.nan
    rss = max(rss, 1e-300)
    return n * math.log(rss / n) + 2 * k + 2 * k * (k + 1) / (n - k - 1)


def _fit_sensor(delta: np.ndarray, pose: np.ndarray, values: np.ndarray, poses: int,
                quadratic_allowed: bool) -> SensorTemperatureFit:
    """Linear and quadratic least squares per axis, shared slopes, one intercept per pose."""
    n = len(delta)
    indicator = (pose[:, None] == np.arange(poses)[None, :]).astype(np.float64)
    designs = {LINEAR: np.hstack([indicator, delta[:, None]])}
    if quadratic_allowed:
        designs[QUADRATIC] = np.hstack([indicator, delta[:, None], (delta * delta)[:, None]])
    fits: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
    for degree, design in designs.items():
        k = design.shape[1]
        coef, _, rank, _ = np.linalg.lstsq(design, values, rcond=None)
        if rank < k:
            raise TemperatureFitError("the temperatures do not determine the fit (all bins "
                                      "of a pose at one temperature?)")
        residual = values - design @ coef
        rss = np.sum(residual * residual, axis=0)
        cov_unit = np.linalg.inv(design.T @ design)
        std = np.sqrt(np.outer(np.diag(cov_unit), rss / max(1, n - k)))  # (k, 3)
        fits[degree] = (coef, std, rss, residual)
    # Bins in temperature order are independent only if what the model leaves is white; a
    # bias random walk leaves a slow wander that any extra term "explains". The largest
    # model's residuals give the lag-1 autocorrelation rho per axis, and both criteria count
    # n_eff = n (1 - rho) / (1 + rho) independent bins: genuine curvature leaves white
    # residuals under the quadratic (rho ~ 0, n_eff ~ n), a walk does not.
    largest = fits[max(fits)][3]
    same_pose = pose[1:] == pose[:-1]
    n_eff = np.full(3, float(n))
    for axis in range(3):
        r = largest[:, axis] - largest[:, axis].mean()
        denominator = float(r @ r)
        if denominator > 0.0 and same_pose.any():
            rho = float(np.sum((r[1:] * r[:-1])[same_pose])) / denominator
            rho = min(max(rho, 0.0), 0.95)
            n_eff[axis] = n * (1.0 - rho) / (1.0 + rho)
    results: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, float]] = {}
    for degree, (coef, std, rss, _) in fits.items():
        k = designs[degree].shape[1]
        aicc = float(sum(_aicc(float(rss[a]) * n_eff[a] / n, n_eff[a], k) for a in range(3)))
        results[degree] = (coef, std, np.sqrt(rss / n), aicc)
    aiccs = {degree: r[3] for degree, r in results.items()}
    degree = LINEAR
    if (QUADRATIC in results and math.isfinite(aiccs[QUADRATIC]) and math.isfinite(aiccs[LINEAR])
            and aiccs[LINEAR] - aiccs[QUADRATIC] > QUADRATIC_MIN_AIC_GAIN):
        degree = QUADRATIC
    coef, std, rms, _ = results[degree]
    zeros = np.zeros(3)
    return SensorTemperatureFit(
        degree=degree, intercepts=coef[:poses].copy(), k1=coef[poses].copy(),
        k2=coef[poses + 1].copy() if degree == QUADRATIC else zeros,
        k1_std=std[poses].copy(), k2_std=std[poses + 1].copy() if degree == QUADRATIC else zeros,
        rms=rms, aicc={LINEAR: aiccs[LINEAR], QUADRATIC: aiccs.get(QUADRATIC, math.nan)},
    )


# -- the fit ---------------------------------------------------------------------------------------
def fit_temperature(
    block: SampleBlock,
    settings: SensorSettings,
    reference_temp_degc: float | None = None,
    min_span_degc: float = MIN_SPAN_DEGC,
) -> TemperatureFit:
    """Fit bias against temperature on an *uncalibrated* stream (see the module docstring).

    ``reference_temp_degc`` is ``T0`` (default: the middle of the still data's temperatures).
    Raises :class:`TemperatureFitError` with a reason: no temperature, motion everywhere,
    too narrow a span, too few bins.
    """
    n = len(block)
    if n < 8:
        raise TemperatureFitError(f"the stream holds {n} samples: nothing to fit")
    temp = np.asarray(block.temp_degc, dtype=np.float64)
    if not np.any(np.isfinite(temp)):
        raise TemperatureFitError("the stream has no temperature (its 'temp' column is empty "
                                  "or missing): a temperature fit needs the die temperature")
    duration = float(block.t_s[-1] - block.t_s[0])
    mask = still_mask(block, settings) & np.isfinite(temp)
    min_run = max(8, round(MIN_SEGMENT_S * settings.odr_hz))
    runs = [(a, b) for a, b in _runs(mask) if b - a >= min_run]
    if not runs:
        raise TemperatureFitError(
            f"motion everywhere: no still stretch of {MIN_SEGMENT_S:g} s or more in the "
            f"{duration:.1f} s given. Record the board resting while it warms up.")
    # Poses: consecutive segments with the same gravity direction.
    pose_of_run = []
    ups: list[np.ndarray] = []
    for a, b in runs:
        mean = block.accel_m_s2[a:b].mean(axis=0)
        up = mean / max(np.linalg.norm(mean), 1e-12)
        for index, known in enumerate(ups):
            if math.degrees(math.acos(min(1.0, float(up @ known)))) < SAME_POSE_DEG:
                pose_of_run.append(index)
                break
        else:
            pose_of_run.append(len(ups))
            ups.append(up)
    still_index = np.concatenate([np.arange(a, b) for a, b in runs])
    still_pose = np.concatenate([np.full(b - a, p) for (a, b), p in zip(runs, pose_of_run,
                                                                        strict=True)])
    still_temp = temp[still_index]
    t_min, t_max = float(still_temp.min()), float(still_temp.max())
    span = t_max - t_min
    if span < min_span_degc:
        raise TemperatureFitError(
            f"the temperature spans only {span:.2f} degC over the still data ({t_min:.2f} to "
            f"{t_max:.2f} degC); a slope needs at least {min_span_degc:g} degC. Record from a "
            "cold start for longer (the board warms by a few degC in the first minutes), or "
            "hold it still at several temperatures (a chamber, a fridge, a warm room).")
    width = max(MIN_BIN_DEGC, span / TARGET_BINS)
    min_bin = max(4, round(MIN_BIN_S * settings.odr_hz))
    edges_index = np.floor((still_temp - t_min) / width).astype(np.int64)
    keys = edges_index * len(ups) + still_pose
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.diff(np.concatenate([[-1], sorted_keys])))
    stops = np.append(starts[1:], len(sorted_keys))
    bin_temp, bin_pose, bin_count, bin_gyro, bin_accel = [], [], [], [], []
    for a, b in zip(starts, stops, strict=True):  # type: ignore[assignment]
        if b - a < min_bin:
            continue
        rows = still_index[order[a:b]]
        bin_temp.append(float(temp[rows].mean()))
        bin_pose.append(int(still_pose[order[a]]))
        bin_count.append(b - a)
        bin_gyro.append(block.gyro_rad_s[rows].mean(axis=0))
        bin_accel.append(block.accel_m_s2[rows].mean(axis=0))
    if len(bin_temp) < 2 * len(ups) + 3:
        raise TemperatureFitError(
            f"too few temperature bins with {MIN_BIN_S:g} s of still data each: "
            f"{len(bin_temp)} (need {2 * len(ups) + 3}); the board must rest longer at each "
            "temperature.")
    temps = np.array(bin_temp)
    poses = np.array(bin_pose)
    t0 = 0.5 * (t_min + t_max) if reference_temp_degc is None else float(reference_temp_degc)
    delta = temps - t0
    quadratic = span >= QUADRATIC_MIN_SPAN_DEGC and len(temps) >= len(ups) + 4
    gyro = _fit_sensor(delta, poses, np.array(bin_gyro), len(ups), quadratic)
    accel = _fit_sensor(delta, poses, np.array(bin_accel), len(ups), quadratic)
    notes = []
    if not quadratic:
        notes.append(f"Span {span:.1f} degC: only the linear model was considered (a "
                     f"quadratic needs >= {QUADRATIC_MIN_SPAN_DEGC:g} degC).")
    if len(ups) == 1:
        notes.append("One pose: on the axis gravity loads, the accelerometer's sensitivity "
                     "drift is taken as bias drift (exact in this pose).")
    return TemperatureFit(
        reference_temp_degc=t0, temp_min_degc=t_min, temp_max_degc=t_max, gyro=gyro,
        accel=accel, bin_temp_degc=temps, bin_pose=poses,
        bin_samples=np.array(bin_count, dtype=np.int64), bin_gyro_rad_s=np.array(bin_gyro),
        bin_accel_m_s2=np.array(bin_accel), pose_up=np.array(ups), segments=len(runs),
        still_s=len(still_index) / settings.odr_hz, duration_s=duration, samples=n,
        settings=settings, notes=tuple(notes),
    )


# -- putting it on a calibration -------------------------------------------------------------------
def merge_temperature(
    fit: TemperatureFit,
    base: SensorCalibration | None = None,
    base_temp_degc: float | None = None,
    name: str | None = None,
) -> tuple[SensorCalibration, str]:
    """The calibration with the fitted temperature terms, and how it was put together.

    - ``base`` with a known ``base_temp_degc``: its biases and matrices stay, valid at its own
      temperature; the fitted curve, re-centred there, supplies the change from it.
    - ``base`` without a temperature: the same, its biases taken as valid at the fit's ``T0``.
    - no ``base``: identity matrices, the gyro bias the fit's own at ``T0``, the accelerometer
      bias zero at ``T0`` (one static pose cannot tell bias from gravity) plus its drift.
    """
    if base is not None and not base.is_identity:
        if base_temp_degc is not None and math.isfinite(base_temp_degc):
            model = fit.compensation(float(base_temp_degc))
            how = (f"the temperature terms added to calibration {base.name!r}, whose biases "
                   f"hold at its {base_temp_degc:.2f} degC")
            if not fit.temp_min_degc - 1.0 <= base_temp_degc <= fit.temp_max_degc + 1.0:
                how += (f" (outside the fitted {fit.temp_min_degc:.1f} to "
                        f"{fit.temp_max_degc:.1f} degC: extrapolated)")
        else:
            model = fit.compensation()
            how = (f"the temperature terms added to calibration {base.name!r}, whose "
                   f"temperature is unknown: its biases taken as valid at "
                   f"{fit.reference_temp_degc:.2f} degC")
        calibration = base.with_temperature(model)
        if name is not None:
            calibration = SensorCalibration(
                calibration.accel_bias_m_s2, calibration.accel_matrix,
                calibration.gyro_bias_rad_s, calibration.gyro_matrix, name, model)
        return calibration, how
    model = fit.compensation()
    calibration = SensorCalibration(
        gyro_bias_rad_s=fit.gyro_bias_at_reference_rad_s.copy(), name=name or "temperature",
        temperature=model)
    return calibration, ("no earlier calibration: the gyro bias and both drifts from the "
                         f"fit at {fit.reference_temp_degc:.2f} degC, no accelerometer "
                         "bias or scale correction")


# -- against a simulator's truth -------------------------------------------------------------------
@dataclass(frozen=True)
class TemperatureTruth:
    """A simulated unit's true coefficients, as this fit should see them.

    ``accel_k1`` is the *apparent* slope in the fit's first pose: the bias coefficient plus the
    sensitivity coefficient times the gravity that axis carries (see the module docstring);
    ``accel_bias_k1`` is the bias coefficient alone. The simulator's drift is linear (k2 = 0).
    """

    gyro_k1: np.ndarray
    gyro_bias_at_reference: np.ndarray
    accel_k1: np.ndarray
    accel_bias_k1: np.ndarray


def truth_of(fit: TemperatureFit, unit_errors: Mapping[str, Any]) -> TemperatureTruth:
    """The true coefficients of a simulated unit (a recording's ``simulator.unit_errors``)."""
    u = {key: np.asarray(value, dtype=np.float64) for key, value in unit_errors.items()
         if key.startswith(("accel_", "gyro_"))}
    accel_m = (np.eye(3) + np.diag(u["accel_scale_error"])) @ (np.eye(3) + u["accel_cross_axis"])
    # The true specific force of the first pose, from its measured direction (close enough
    # for a term that is 1e-4 of it).
    force = fit.pose_up[0] * STANDARD_GRAVITY_M_S2
    bias_tc = u.get("accel_bias_tc_m_s2_per_degc", np.zeros(3))
    scale_tc = u.get("accel_scale_tc_per_degc", np.zeros(3))
    gyro_tc = u.get("gyro_bias_tc_rad_s_per_degc", np.zeros(3))
    return TemperatureTruth(
        gyro_k1=gyro_tc,
        gyro_bias_at_reference=u["gyro_bias_rad_s"]
        + gyro_tc * (fit.reference_temp_degc - REFERENCE_TEMP_DEGC),
        accel_k1=bias_tc + scale_tc * (accel_m @ force),
        accel_bias_k1=bias_tc,
    )


__all__ = [
    "LINEAR", "MIN_SPAN_DEGC", "QUADRATIC", "SensorTemperatureFit", "TemperatureFit",
    "TemperatureFitError", "TemperatureTruth", "fit_temperature", "merge_temperature",
    "still_mask", "truth_of",
]


def temperature_calibration_json(fit: Any, calibration: SensorCalibration, how: str,
                                 device_unique_id: str, source: str,
                                 created_utc: str) -> dict[str, Any]:
    """The ``calibrate-temperature --out`` document: the binding calibration keys with the
    temperature terms, then descriptive extras (as :func:`offline.calibration_json`)."""
    return {
        **calibration_to_json(calibration),
        "format": JSON_FORMAT,
        "format_version": JSON_VERSION,
        "convention": ("a_cal = A (a_raw - b_a(T)), w_cal = G (w_raw - b_g(T)), b(T) = b + "
                       "tc1 (T - T0) + tc2 (T - T0)^2 (T: die temperature, NaN: b); SI units"),
        "name": calibration.name,
        "method": "temperature",
        "device_unique_id": device_unique_id,
        "source": source,
        "created_utc": created_utc,
        "merged": how,
        "temperature_fit": fit.summary(),
    }
