"""The wizard's calibration run on a recorded stream: headless, for scripts and the lab.

:func:`calibrate_stream` feeds uncalibrated samples (a recording, or seconds of a live device)
through the very procedures the wizard uses: :class:`~.stillness.StillnessDetector`,
:class:`~.poses.PoseCapture`, :class:`~.gyro_bias.GyroBiasCalibration`, then
:func:`~.accel_fit.fit_six_position` or :func:`~.accel_fit.fit_free_poses`, and returns every
intermediate result (:class:`OfflineCalibration`) for a summary, a JSON file, a profile or a
report. The stream is fed in pieces of :data:`FEED_S` seconds, as the wizard's timer does.

The gyro bias is the wizard's gyro step (``gyro_seconds`` of stillness, the first still
stretch long enough). A recording without one (a tour holding each face 6 s) falls back to
the mean of the still poses' gyro readings, weighted by their samples; :attr:`gyro_source`
says which was used.

Bad input raises :class:`OfflineCalibrationError` with a message for the user: motion
everywhere (no still stretch at all), too few poses, faces missing, a fit that fails.

:func:`calibration_json` writes the binding JSON of ``inclinometer calibrate --out``: the keys
``accel_bias_m_s2`` [3], ``accel_matrix`` [3][3], ``gyro_bias_rad_s`` [3], ``gyro_matrix``
[3][3] in the convention of the recording format's ``calibration`` key
(``a_cal = A (a_raw - b_a)``), plus descriptive keys a reader may ignore.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.core.calibration import SensorCalibration, calibration_to_json
from app.core.calibration_procedures.accel_fit import (
    AccelFit,
    CalibrationFitError,
    fit_free_poses,
    fit_six_position,
)
from app.core.calibration_procedures.gyro_bias import (
    DEFAULT_DURATION_S,
    GyroBiasCalibration,
    GyroBiasResult,
    GyroBiasState,
)
from app.core.calibration_procedures.poses import (
    FACES,
    FREE,
    SIX_POSITION,
    CapturedPose,
    CaptureEvent,
    PoseCapture,
)
from app.core.calibration_procedures.profiles import SensorSettings
from app.core.calibration_procedures.stillness import SensorNoise, StillnessDetector
from app.core.calibration_procedures.tilt_comparison import TiltComparison, compare_poses
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

FEED_S = 0.5
"""Seconds of samples per update (the wizard feeds 0.1 s; the result does not depend on it)."""
METHODS = (SIX_POSITION, FREE)
JSON_FORMAT = "inclinometer-calibration"
JSON_VERSION = 1


class OfflineCalibrationError(ValueError):
    """The stream cannot be calibrated; the message says why, for the user."""


@dataclass(frozen=True)
class OfflineCalibration:
    """Everything one headless calibration run found.

    Attributes
    ----------
    method : :data:`SIX_POSITION` or :data:`FREE`.
    settings : sensor settings of the stream.
    events : every capture attempt, accepted or rejected (with its reason).
    poses : the accepted poses.
    fit : the accelerometer fit.
    gyro_bias_rad_s, gyro_bias_std_rad_s : (3,) the gyro bias and its uncertainty.
    gyro_source : in words, where the gyro bias came from.
    gyro_result : the wizard's gyro-step result, None when the poses' mean was used.
    calibration : the combined :class:`SensorCalibration`.
    comparison : tilt error of every pose before (raw) and after (calibrated).
    comparison_reference : ``"truth"`` (the stream's reference orientation) or ``"face"``
        (the nominal faces: then the after-errors only show the fit residual).
    samples, duration_s, still_s : the stream's length and how much of it was still.
    temperature_degc : mean temperature of the poses (NaN when unknown).
    """

    method: str
    settings: SensorSettings
    events: tuple[CaptureEvent, ...]
    poses: tuple[CapturedPose, ...]
    fit: AccelFit
    gyro_bias_rad_s: np.ndarray
    gyro_bias_std_rad_s: np.ndarray
    gyro_source: str
    gyro_result: GyroBiasResult | None
    calibration: SensorCalibration
    comparison: TiltComparison
    comparison_reference: str
    samples: int
    duration_s: float
    still_s: float
    temperature_degc: float = math.nan
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def rejected(self) -> list[CaptureEvent]:
        return [event for event in self.events if not event.accepted]

    def residuals(self) -> dict[str, Any]:
        """Plain numbers for a profile's ``residuals`` (the wizard's keys, and a few more)."""
        return {
            **self.fit.summary(),
            "gyro_bias_std_dps": np.degrees(self.gyro_bias_std_rad_s).tolist(),
            "gyro_bias_source": self.gyro_source,
            "tilt_error_before_max_deg": self.comparison.before.max_deg,
            "tilt_error_after_max_deg": self.comparison.after.max_deg,
            "tilt_error_reference": self.comparison_reference,
            "rejected_poses": len(self.rejected),
        }


def _pieces(block: SampleBlock, size: int) -> list[SampleBlock]:
    n = len(block)
    out = []
    for start in range(0, n, size):
        rows = slice(start, min(n, start + size))
        out.append(SampleBlock(
            t_s=block.t_s[rows], accel_m_s2=block.accel_m_s2[rows],
            gyro_rad_s=block.gyro_rad_s[rows], temp_degc=block.temp_degc[rows],
            gap=block.gap[rows],
            reference_quat=None if block.reference_quat is None else block.reference_quat[rows],
        ))
    return out


def _gyro_from_poses(poses: list[CapturedPose]) -> tuple[np.ndarray, np.ndarray]:
    weights = np.array([pose.samples for pose in poses], dtype=np.float64)
    means = np.array([pose.gyro_mean_rad_s for pose in poses])
    bias = weights @ means / weights.sum()
    if len(poses) >= 2:
        std_error = means.std(axis=0, ddof=1) / math.sqrt(len(poses))
    else:
        std_error = np.full(3, np.nan)
    return bias, std_error


def calibrate_stream(
    block: SampleBlock,
    settings: SensorSettings,
    method: str = SIX_POSITION,
    gyro_seconds: float = DEFAULT_DURATION_S,
    min_poses: int | None = None,
) -> OfflineCalibration:
    """Run the wizard's capture and fit over an *uncalibrated* stream (see the module doc).

    Raises :class:`OfflineCalibrationError` with a reason when the stream does not calibrate.
    """
    if method not in METHODS:
        raise OfflineCalibrationError(
            f"unknown method {method!r}; use {' or '.join(METHODS)}")
    n = len(block)
    if n < 8:
        raise OfflineCalibrationError(f"the stream holds {n} samples: nothing to calibrate")
    noise = SensorNoise.lsm6dsox(settings.odr_hz, settings.accel_fs_g, settings.gyro_fs_dps)
    capture = PoseCapture(StillnessDetector(noise), mode=method, min_poses=min_poses)
    gyro_step = GyroBiasCalibration(StillnessDetector(noise), duration_s=gyro_seconds)
    watcher = StillnessDetector(noise)
    still_samples = 0
    size = max(8, round(FEED_S * settings.odr_hz))
    for piece in _pieces(block, size):
        still_samples += int(watcher.update(piece).sum())
        capture.update(piece)
        if gyro_step.state is not GyroBiasState.DONE:
            gyro_step.update(piece)
    duration = float(block.t_s[-1] - block.t_s[0])
    still_s = still_samples / settings.odr_hz
    poses = list(capture.poses)
    rejected = [event for event in capture.events if not event.accepted]
    reasons = "".join(f"\n  rejected at t = {e.time_s:.1f} s: {e.reason}" for e in rejected)
    if still_samples == 0:
        raise OfflineCalibrationError(
            f"motion everywhere: the sensor is never still in the {duration:.1f} s given "
            f"(a still window is {watcher.window_s:g} s with every axis within "
            f"{watcher.k:g} x its noise). Record the board resting in each pose for at "
            "least 4 s.")
    if method == SIX_POSITION and capture.missing_faces:
        have = ", ".join(capture.captured_faces) or "none"
        raise OfflineCalibrationError(
            f"faces missing for the six-position fit: {', '.join(capture.missing_faces)} "
            f"(captured: {have}; {len(rejected)} attempt(s) rejected). Each face must be "
            "held still for about 4 s." + reasons)
    if method == FREE and not capture.enough:
        raise OfflineCalibrationError(
            f"too few poses for the free (ellipsoid) fit: {len(poses)} of "
            f"{capture.min_poses} needed ({len(rejected)} attempt(s) rejected). Hold the "
            "board still in more, clearly different orientations." + reasons)
    try:
        fit = fit_six_position(poses) if method == SIX_POSITION else fit_free_poses(poses)
    except CalibrationFitError as exc:
        raise OfflineCalibrationError(f"the fit failed: {exc}") from None
    notes: list[str] = []
    if gyro_step.state is GyroBiasState.DONE and gyro_step.result is not None:
        result = gyro_step.result
        gyro_bias, gyro_std = result.bias_rad_s, result.std_error_rad_s
        source = f"gyro step: {result.duration_s:.1f} s still ({result.samples} samples)"
    else:
        result = None
        gyro_bias, gyro_std = _gyro_from_poses(poses)
        source = (f"mean of the {len(poses)} still poses (no still stretch of "
                  f"{gyro_seconds:g} s for the gyro step)")
    calibration = fit.to_calibration(gyro_bias, name=f"{fit.method} (headless)")
    reference = "truth" if all(p.reference_up is not None for p in poses) else "face"
    if reference == "face":
        notes.append("No reference orientation: the tilt errors are against the nominal "
                     "faces, so 'after' shows the fit residual only.")
    comparison = compare_poses(poses, calibration, reference=reference)
    return OfflineCalibration(
        method=method, settings=settings, events=tuple(capture.events), poses=tuple(poses),
        fit=fit, gyro_bias_rad_s=np.asarray(gyro_bias, float),
        gyro_bias_std_rad_s=np.asarray(gyro_std, float), gyro_source=source,
        gyro_result=result, calibration=calibration, comparison=comparison,
        comparison_reference=reference, samples=n, duration_s=duration, still_s=still_s,
        temperature_degc=fit.temperature_degc, notes=tuple(notes),
    )


# -- against a simulator's truth ------------------------------------------------------------------
@dataclass(frozen=True)
class TruthComparison:
    """Recovered parameters against a simulated unit's true ones at the poses' temperature.

    Each row: ``(name, unit, recovered (3,), truth (3,))``.
    """

    temperature_degc: float
    rows: tuple[tuple[str, str, np.ndarray, np.ndarray], ...]

    def errors(self) -> dict[str, np.ndarray]:
        return {name: recovered - truth for name, _, recovered, truth in self.rows}


def _offdiagonal(matrix: np.ndarray) -> np.ndarray:
    """(xy, xz, yz, yx, zx, zy) of a 3x3 matrix."""
    return np.array([matrix[0, 1], matrix[0, 2], matrix[1, 2],
                     matrix[1, 0], matrix[2, 0], matrix[2, 1]])


def compare_with_truth(result: OfflineCalibration, unit_errors: Mapping[str, Any]
                       ) -> TruthComparison:
    """Recovered vs true parameters of a simulated unit (the recording's ``simulator`` key).

    The truth is taken at the poses' mean temperature (biases move with temperature:
    ``bias + bias_tc (T - 25)``, scale ``(1 + scale_tc (T - 25))``).
    """
    u = {key: np.asarray(value, dtype=np.float64) for key, value in unit_errors.items()
         if key.startswith(("accel_", "gyro_"))}
    temperature = result.temperature_degc
    delta = 0.0 if not math.isfinite(temperature) else temperature - 25.0
    accel_m = (np.eye(3) + np.diag(u["accel_scale_error"])) @ (np.eye(3) + u["accel_cross_axis"])
    accel_m = accel_m * (1.0 + delta * u.get("accel_scale_tc_per_degc", np.zeros(3)))[:, None]
    accel_bias = u["accel_bias_m_s2"] + delta * u.get("accel_bias_tc_m_s2_per_degc", 0.0)
    gyro_bias = u["gyro_bias_rad_s"] + delta * u.get("gyro_bias_tc_rad_s_per_degc", 0.0)
    fit = result.fit
    g = STANDARD_GRAVITY_M_S2
    rows = [
        ("accel bias", "mg", fit.bias_m_s2 / g * 1e3, accel_bias / g * 1e3),
        ("accel scale error", "%", 100.0 * (np.diag(fit.matrix) - 1.0),
         100.0 * (np.diag(accel_m) - 1.0)),
        ("accel cross-axis xy xz yz", "%", 100.0 * _offdiagonal(fit.cross_axis)[:3],
         100.0 * _offdiagonal(accel_m / np.diag(accel_m)[:, None] - np.eye(3))[:3]),
        ("accel cross-axis yx zx zy", "%", 100.0 * _offdiagonal(fit.cross_axis)[3:],
         100.0 * _offdiagonal(accel_m / np.diag(accel_m)[:, None] - np.eye(3))[3:]),
        ("gyro bias", "mdps", np.degrees(result.gyro_bias_rad_s) * 1e3,
         np.degrees(gyro_bias) * 1e3),
    ]
    return TruthComparison(temperature, tuple(rows))


# -- JSON ---------------------------------------------------------------------------------------
def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def calibration_json(
    result: OfflineCalibration,
    device_unique_id: str = "",
    source: str = "",
    created_utc: str = "",
) -> dict[str, Any]:
    """The binding calibration JSON (see the module docstring) with descriptive extras."""
    cal = result.calibration
    fit = result.fit
    return {
        **calibration_to_json(cal),
        "format": JSON_FORMAT,
        "format_version": JSON_VERSION,
        "convention": "a_cal = A (a_raw - b_a), w_cal = G (w_raw - b_g); SI units",
        "name": cal.name,
        "method": result.method,
        "device_unique_id": device_unique_id,
        "source": source,
        "created_utc": created_utc,
        "temperature_degc": _finite(result.temperature_degc),
        "sensor_settings": {
            "sensor": result.settings.sensor, "odr_hz": result.settings.odr_hz,
            "accel_fs_g": result.settings.accel_fs_g, "gyro_fs_dps": result.settings.gyro_fs_dps,
        },
        "uncertainty": {
            "accel_bias_m_s2": fit.bias_std_m_s2.tolist(),
            "accel_model_matrix": fit.matrix_std.tolist(),
            "gyro_bias_rad_s": [_finite(v) for v in result.gyro_bias_std_rad_s],
        },
        "fit": {
            "residual_norm_rms_mg": _finite(fit.residual_norm_rms_mg),
            "residual_component_rms_mg": _finite(fit.residual_component_rms_mg),
            "poses": fit.n_poses,
            "gyro_bias_source": result.gyro_source,
        },
        "poses": [
            {
                "face": pose.face, "t_start_s": pose.t_start_s, "t_end_s": pose.t_end_s,
                "samples": pose.samples, "temperature_degc": _finite(pose.temperature_degc),
                "accel_mean_m_s2": pose.accel_mean_m_s2.tolist(),
                "norm_error_mg": float(fit.norm_errors_mg[i]),
                "tilt_error_before_deg": float(result.comparison.before.inclination_deg[i]),
                "tilt_error_after_deg": float(result.comparison.after.inclination_deg[i]),
            }
            for i, pose in enumerate(result.poses)
        ],
        "rejected": [{"t_s": e.time_s, "reason": e.reason} for e in result.rejected],
        "tilt_error_reference": result.comparison_reference,
    }


__all__ = [
    "FACES", "METHODS", "OfflineCalibration", "OfflineCalibrationError", "TruthComparison",
    "calibrate_stream", "calibration_json", "compare_with_truth",
]
