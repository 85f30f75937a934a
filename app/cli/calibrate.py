"""``inclinometer calibrate RECORDING [--method six-position|free] --out FILE.json [--save]``:
the wizard's stillness detection, pose capture and fit on a recorded tour (or on ``--device URL
--seconds N``); prints the poses, residuals, uncertainties and tilt errors, writes the
calibration JSON, ``--save`` stores it as the device's profile, ``--report`` writes an HTML or
PDF report (:mod:`app.documents.calibration_report`).

Exit status: 0 done, 1 the data does not calibrate (the message says why), 2 bad usage or a
file that cannot be read.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from app.cli import lab
from app.cli.errors import finite
from app.core.calibration_procedures.offline import (
    OfflineCalibration,
    OfflineCalibrationError,
    calibrate_stream,
    calibration_json,
    compare_with_truth,
)
from app.core.calibration_procedures.profiles import (
    ProfileStore,
    make_profile,
    utc_now_iso,
)
from app.core.calibration_procedures.tilt_comparison import worsening
from app.core.devices import printable
from app.services.calibration_runs import CapturedStream


def add_arguments(calibrate: argparse.ArgumentParser) -> None:
    """The options of ``calibrate``; it runs :func:`calibrate_command`."""
    calibrate.set_defaults(handler=calibrate_command)
    calibrate.description = (
        "Run the calibration wizard's stillness detection, pose capture and fit on a "
        "recording of uncalibrated samples (or on --seconds of a live --device). Prints "
        "the poses found and rejected (with reasons), the fit's residuals and "
        "uncertainties and the tilt error before and after; writes the calibration as "
        "JSON (accel_bias_m_s2, accel_matrix, gyro_bias_rad_s, gyro_matrix; "
        "a_cal = A (a_raw - b_a)). A simulator recording is compared with its true errors."
    )
    calibrate.add_argument("recording", nargs="?", metavar="RECORDING",
                           help="a recording (format v1) of the board resting in each pose")
    calibrate.add_argument("--method", choices=("six-position", "free"), default="six-position",
                           help="six faces of a box (default) or >= 12 free orientations")
    calibrate.add_argument("--out", metavar="FILE.json", help="write the calibration JSON here")
    calibrate.add_argument("--save", action="store_true",
                           help="store the result as the device's calibration profile (refused "
                           "when it makes the tilt error worse, unless --force)")
    calibrate.add_argument("--force", action="store_true",
                           help="with --save: store it even when the tilt error gets worse")
    calibrate.add_argument("--report", metavar="FILE.html|FILE.pdf",
                           help="write a calibration report (HTML, or PDF through Qt)")
    calibrate.add_argument("--overwrite", action="store_true",
                           help="replace --out and --report files that exist")
    calibrate.add_argument("--device", metavar="URL",
                           help="calibrate from a live device instead of a recording")
    calibrate.add_argument("--seconds", type=float, metavar="N",
                           help="with --device: how many seconds to read")
    calibrate.add_argument("--gyro-seconds", type=float, default=10.0, metavar="S",
                           help="still time for the gyro bias step (default %(default)g; "
                           "without such a stretch the poses' mean is used)")
    calibrate.add_argument("--profile-dir", metavar="DIR", help=argparse.SUPPRESS)


def print_summary(result: OfflineCalibration, label: str, stream: CapturedStream,
                  out: TextIO) -> None:
    fit = result.fit
    s = result.settings
    print(f"{label}: {result.duration_s:.1f} s, {result.samples} samples at {s.odr_hz:.4g} Hz "
          f"(+-{s.accel_fs_g} g, +-{s.gyro_fs_dps} dps), {result.still_s:.1f} s still", file=out)
    if stream.unique_id:
        print(f"device {printable(stream.unique_id)}", file=out)
    print(f"method {result.method}: {len(result.poses)} poses accepted, "
          f"{len(result.rejected)} rejected", file=out)
    print(f"  {'#':>2}  {'face':<4}  {'t (s)':>13}  {'T (degC)':>8}  {'|a|-g (mg)':>10}  "
          f"{'tilt err before':>15}  {'after (deg)':>11}", file=out)
    for i, pose in enumerate(result.poses):
        temp = pose.temperature_degc
        print(f"  {i + 1:>2}  {pose.face:<4}  {pose.t_start_s:6.1f}-{pose.t_end_s:6.1f}  "
              f"{temp if math.isfinite(temp) else math.nan:8.2f}  "
              f"{fit.norm_errors_mg[i]:10.3f}  "
              f"{result.comparison.before.inclination_deg[i]:15.3f}  "
              f"{result.comparison.after.inclination_deg[i]:11.4f}", file=out)
    for event in result.rejected:
        print(f"  rejected at t = {event.time_s:.1f} s: {event.reason}", file=out)
    print("accelerometer fit (a_meas = M a_true + b), value +- 1 sigma per axis x, y, z:",
          file=out)
    print(f"  bias (mg)          {lab.vec(fit.bias_mg, '+.3f')}   +- "
          f"{lab.vec(fit.bias_std_mg, '.3f', 7)}", file=out)
    print(f"  scale error (%)    {lab.vec(100 * fit.scale_error, '+.4f')}   +- "
          f"{lab.vec(100 * fit.scale_error_std, '.4f', 7)}", file=out)
    nonortho = ", ".join(f"{k} {v:+.3f}" for k, v in fit.non_orthogonality_deg.items())
    print(f"  non-orthogonality (deg): {nonortho}", file=out)
    print(f"  residual: {fit.residual_norm_rms_mg:.3f} mg RMS of |a| - 1 g"
          + ("" if not math.isfinite(fit.residual_component_rms_mg) else
             f", {fit.residual_component_rms_mg:.3f} mg RMS per component"), file=out)
    gyro_dps = np.degrees(result.gyro_bias_rad_s)
    gyro_std = np.degrees(result.gyro_bias_std_rad_s)
    print(f"gyro bias (dps)      {lab.vec(gyro_dps, '+.4f')}   +- {lab.vec(gyro_std, '.4f', 7)}",
          file=out)
    print(f"  from the {result.gyro_source}", file=out)
    c = result.comparison
    against = ("the reference orientation" if result.comparison_reference == "truth"
               else "the nominal faces")
    print(f"tilt error over the poses, against {against}: before max {c.before.max_deg:.3f} "
          f"deg (RMS {c.before.rms_deg:.3f}), after max {c.after.max_deg:.4f} deg "
          f"(RMS {c.after.rms_deg:.4f})", file=out)
    for note in result.notes:
        print(f"note: {note}", file=out)


def print_truth(result: OfflineCalibration, unit_errors: dict[str, Any], out: TextIO) -> None:
    truth = compare_with_truth(result, unit_errors)
    temp = truth.temperature_degc
    at = f" at {temp:.2f} degC" if math.isfinite(temp) else ""
    print(f"against the simulator's true unit errors{at} (recovered / truth / error):", file=out)
    for name, unit, recovered, true in truth.rows:
        print(f"  {name + ' (' + unit + ')':<32}{lab.vec(recovered, '+.4f')}", file=out)
        print(f"  {'  truth':<32}{lab.vec(true, '+.4f')}", file=out)
        print(f"  {'  error':<32}{lab.vec(recovered - true, '+.4f')}", file=out)


def write_calibration_report(result, profile, stream, label: str, path: Path) -> None:
    """The report (:mod:`app.documents.calibration_report`, painted by Qt: loaded only now,
    a headless lab machine may not have Qt's graphics libraries)."""
    _app = lab.qt_for_documents()
    from app.documents.calibration_report import report_from_offline, write_report

    report = report_from_offline(result, profile, stream.device, label, stream.unit_errors)
    write_report(report, path)


def calibrate_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``calibrate`` sub-command."""
    out = sys.stdout if out is None else out
    lab.check_outputs(args)
    finite(args.gyro_seconds, "--gyro-seconds", positive=True, maximum=lab.MAX_SECONDS)
    stream, label = lab.load_stream(args, out)
    lab.check_save(args, stream, label)
    try:
        result = calibrate_stream(stream.block, stream.settings, method=args.method,
                                  gyro_seconds=args.gyro_seconds)
    except OfflineCalibrationError as exc:
        raise lab.failed(args, f"{label}: cannot calibrate: {exc}") from None
    print_summary(result, label, stream, out)
    if stream.unit_errors:
        print_truth(result, stream.unit_errors, out)
    created = utc_now_iso()
    document = calibration_json(result, stream.unique_id, label, created)
    profile = make_profile(
        stream.unique_id or "unknown", result.calibration, result.settings,
        method=result.fit.method, temperature_degc=result.temperature_degc,
        residuals=result.residuals(), created_utc=created,
        notes=f"inclinometer calibrate {label}",
    )
    worse = worsening(result.comparison)
    refused = bool(args.save and worse and not args.force)
    if worse:
        print(f"warning: {worse}", file=out)
    lab.write_outputs(args, out, document,
                      lambda path: write_calibration_report(result, profile, stream, label, path))
    if args.save and not refused:
        store = ProfileStore(args.profile_dir)
        path = store.save(profile)
        print(f"saved as the profile of device {printable(stream.unique_id)}: {path}",
              file=out)
    out.flush()
    if refused:
        raise lab.failed(args, f"not saved: {worse} Redo the poses, or --force to save it all "
                         "the same")
    return 0


