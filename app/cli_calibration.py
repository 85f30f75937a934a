"""The calibration lab's sub-commands of ``inclinometer``.

``inclinometer calibrate RECORDING [--method six-position|free] --out FILE.json [--save]``
    the wizard's stillness detection, pose capture and fit on a recorded tour (or on
    ``--device URL --seconds N``); prints the poses, residuals, uncertainties and tilt errors,
    writes the calibration JSON, ``--save`` stores it as the device's profile, ``--report``
    writes an HTML or PDF report.
``inclinometer allan RECORDING [--json OUT]``
    Allan deviation of a static recording: noise density, bias instability and random walk
    per axis of the gyroscope and the accelerometer.
``inclinometer calibrate-temperature RECORDING [--out FILE.json] [--save] [--report FILE]``
    gyroscope and accelerometer bias against die temperature, fitted on a recording of the
    board resting while it warms up (linear, or quadratic when the span and the AICc say
    so); merged with the device's profile (or ``--base FILE.json``) when there is one.

Exit status: 0 done, 1 the data does not calibrate (the message says why), 2 bad usage or a
file that cannot be read.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from app.cli_errors import CommandError, check_output_folder, finite, one_line
from app.core.devices import printable
from app.core.safe_output import (
    OutputRefused,
    check_output,
    output_path,
    write_error_message,
    write_output,
)

if TYPE_CHECKING:
    from app.core.calibration_procedures.offline import OfflineCalibration
    from app.services.calibration_runs import CapturedStream

CALIBRATION_COMMANDS = ("calibrate", "allan", "calibrate-temperature")
EXIT_FAILED = 1
EXIT_USAGE = 2
DEFAULT_ACCEL_FS_G = 4
DEFAULT_GYRO_FS_DPS = 250
MAX_SECONDS = 7 * 86400.0
"""The longest ``--seconds`` and ``--gyro-seconds`` (a week)."""


class _Usage(CommandError):
    """Bad arguments or an unreadable input: exit 2."""


class _Failed(Exception):
    """The data does not give a result: exit 1."""


def add_calibration_parsers(commands: argparse._SubParsersAction) -> None:
    calibrate = commands.add_parser(
        "calibrate",
        help="calibrate from a recorded six-face tour or free poses (headless wizard)",
        description=(
            "Run the calibration wizard's stillness detection, pose capture and fit on a "
            "recording of uncalibrated samples (or on --seconds of a live --device). Prints "
            "the poses found and rejected (with reasons), the fit's residuals and "
            "uncertainties and the tilt error before and after; writes the calibration as "
            "JSON (accel_bias_m_s2, accel_matrix, gyro_bias_rad_s, gyro_matrix; "
            "a_cal = A (a_raw - b_a)). A simulator recording is compared with its true errors."
        ),
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

    allan = commands.add_parser(
        "allan",
        help="Allan deviation of a static recording: noise density, bias instability, "
        "random walk",
        description=(
            "Allan deviation (allantools) of every gyroscope and accelerometer axis of a "
            "recording of the sensor at rest, and the noise model fitted to it: noise density "
            "(dps/sqrt(Hz), ug/sqrt(Hz)), bias instability (deg/h, ug) and bias random walk "
            "(deg/h/sqrt(h), ug/sqrt(h)). A temperature that moves is regressed out first "
            "(--keep-temperature keeps it). Noise density and random walk come from the "
            "time series' likelihood (white noise + bias random walk, the walk as the posterior "
            "median, its relative 1-sigma uncertainty printed); --method allan-fit reads them "
            "off the Allan curve instead. Record at least 30 minutes; the gyroscope's random "
            "walk needs an hour or more (30 minutes leave it uncertain by about 50 %)."
        ),
    )
    allan.add_argument("recording", nargs="?", metavar="RECORDING",
                       help="a recording (format v1) of the sensor lying still")
    allan.add_argument("--json", metavar="OUT", help="write the figures as JSON ('-': stdout)")
    allan.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    allan.add_argument("--device", metavar="URL", help="read a live device instead")
    allan.add_argument("--seconds", type=float, metavar="N", help="with --device: how long")
    allan.add_argument("--keep-temperature", action="store_true",
                       help="do not regress the temperature out before the analysis")
    allan.add_argument("--method", choices=("likelihood", "allan-fit"), default="likelihood",
                       help="estimator of noise density and random walk (default %(default)s)")

    temperature = commands.add_parser(
        "calibrate-temperature",
        help="fit gyro and accelerometer bias against temperature (a warm-up recording)",
        description=(
            "Fit the gyroscope and accelerometer biases against the die temperature, "
            "b(T) = b0 + k1 (T - T0) + k2 (T - T0)^2, on a recording of the board resting "
            "while its temperature moves (from power-up, in a chamber, or still poses at "
            "several temperatures; still stretches are found by the wizard's stillness "
            "detection). The quadratic term is used only with a span of 10 degC or more and "
            "a clear AICc gain. The terms are added to the device's profile (or to --base "
            "FILE.json from 'inclinometer calibrate --out'), whose biases stay as b0 at its "
            "own temperature; without one, the gyro bias comes from the fit."
        ),
    )
    temperature.add_argument("recording", nargs="?", metavar="RECORDING",
                             help="a recording (format v1) of the board at rest, warming")
    temperature.add_argument("--out", metavar="FILE.json",
                             help="write the calibration JSON (binding keys plus the "
                             "temperature terms)")
    temperature.add_argument("--save", action="store_true",
                             help="store the result as the device's calibration profile")
    temperature.add_argument("--report", metavar="FILE.html|FILE.pdf",
                             help="write a report with the coefficients and a plot")
    temperature.add_argument("--overwrite", action="store_true",
                             help="replace --out and --report files that exist")
    temperature.add_argument("--base", metavar="FILE.json",
                             help="merge with this calibration JSON instead of the profile")
    temperature.add_argument("--no-merge", action="store_true",
                             help="ignore the device's profile: temperature terms alone")
    temperature.add_argument("--reference-temp", type=float, metavar="DEGC",
                             help="T0 of a calibration without a base (default: mid-span)")
    temperature.add_argument("--min-span", type=float, default=3.0, metavar="DEGC",
                             help="refuse narrower temperature spans (default %(default)g)")
    temperature.add_argument("--device", metavar="URL", help="read a live device instead")
    temperature.add_argument("--seconds", type=float, metavar="N", help="with --device: how long")
    temperature.add_argument("--profile-dir", metavar="DIR", help=argparse.SUPPRESS)


# -- input -------------------------------------------------------------------------------------
def _settings_from_device(device: dict[str, Any], rate_hz: float, out: TextIO):
    from app.core.calibration_procedures.profiles import SensorSettings

    odr = device.get("odr_hz")
    accel_fs = device.get("accel_fs_g")
    gyro_fs = device.get("gyro_fs_dps")
    if not isinstance(odr, int | float) or odr <= 0:
        odr = rate_hz
    if not isinstance(accel_fs, int) or not isinstance(gyro_fs, int):
        print(f"note: the recording does not name its full scales; assuming +-"
              f"{DEFAULT_ACCEL_FS_G} g and +-{DEFAULT_GYRO_FS_DPS} dps", file=out)
        accel_fs, gyro_fs = DEFAULT_ACCEL_FS_G, DEFAULT_GYRO_FS_DPS
    return SensorSettings(float(odr), accel_fs, gyro_fs, str(device.get("sensor") or "LSM6DSOX"))


def load_stream(args: argparse.Namespace, out: TextIO) -> tuple[CapturedStream, str]:
    """The samples to work on (a recording or a live device) and a label for them."""
    from app.core.recording.errors import RecordingError
    from app.core.recording.reader import read_recording
    from app.services.calibration_runs import CapturedStream, capture_device
    from drivers.errors import DeviceError

    if args.device is not None:
        if args.recording is not None:
            raise _Usage("give a RECORDING or --device URL, not both")
        if args.seconds is None:
            raise _Usage("--device needs --seconds N (how long to read)")
        finite(args.seconds, "--seconds", positive=True, maximum=MAX_SECONDS)
        print(f"reading {args.seconds:g} s from {args.device} ...", file=out)
        out.flush()
        try:
            stream = capture_device(args.device, args.seconds)
        except (DeviceError, ValueError) as exc:
            raise _Usage(str(exc)) from None
        if stream.note:
            print(f"note: {stream.note}", file=out)
        return stream, args.device
    if args.recording is None:
        raise _Usage("give a RECORDING (or --device URL --seconds N)")
    if args.seconds is not None:
        raise _Usage("--seconds goes with --device")
    path = Path(args.recording)
    if not path.is_file():
        raise _Usage(f"{path}: no such file" if not path.exists() else f"{path}: not a file")
    try:
        recording = read_recording(path)
    except RecordingError as exc:
        raise _Usage(str(exc)) from None
    except OSError as exc:
        raise _Usage(f"{path}: cannot read the recording: {exc.strerror or exc}") from None
    calibration = recording.calibration
    if calibration is not None and not calibration.is_identity:
        print(f"note: the recording was made with calibration {calibration.name!r}; its raw "
              "samples are used", file=out)
    simulator = recording.metadata.get("simulator")
    unit = simulator.get("unit_errors") if isinstance(simulator, dict) else None
    stream = CapturedStream(
        block=recording.sample_block(),
        settings=_settings_from_device(recording.device, recording.rate_hz, out),
        device=recording.device,
        unit_errors=unit if isinstance(unit, dict) else None,
    )
    return stream, str(path)


# -- printing ----------------------------------------------------------------------------------
def _vec(values: np.ndarray, spec: str, width: int = 10) -> str:
    return "".join(f"{format(float(v), spec):>{width}}" for v in values)


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
    print(f"  bias (mg)          {_vec(fit.bias_mg, '+.3f')}   +- "
          f"{_vec(fit.bias_std_mg, '.3f', 7)}", file=out)
    print(f"  scale error (%)    {_vec(100 * fit.scale_error, '+.4f')}   +- "
          f"{_vec(100 * fit.scale_error_std, '.4f', 7)}", file=out)
    nonortho = ", ".join(f"{k} {v:+.3f}" for k, v in fit.non_orthogonality_deg.items())
    print(f"  non-orthogonality (deg): {nonortho}", file=out)
    print(f"  residual: {fit.residual_norm_rms_mg:.3f} mg RMS of |a| - 1 g"
          + ("" if not math.isfinite(fit.residual_component_rms_mg) else
             f", {fit.residual_component_rms_mg:.3f} mg RMS per component"), file=out)
    gyro_dps = np.degrees(result.gyro_bias_rad_s)
    gyro_std = np.degrees(result.gyro_bias_std_rad_s)
    print(f"gyro bias (dps)      {_vec(gyro_dps, '+.4f')}   +- {_vec(gyro_std, '.4f', 7)}",
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
    from app.core.calibration_procedures.offline import compare_with_truth

    truth = compare_with_truth(result, unit_errors)
    temp = truth.temperature_degc
    at = f" at {temp:.2f} degC" if math.isfinite(temp) else ""
    print(f"against the simulator's true unit errors{at} (recovered / truth / error):", file=out)
    for name, unit, recovered, true in truth.rows:
        print(f"  {name + ' (' + unit + ')':<32}{_vec(recovered, '+.4f')}", file=out)
        print(f"  {'  truth':<32}{_vec(true, '+.4f')}", file=out)
        print(f"  {'  error':<32}{_vec(recovered - true, '+.4f')}", file=out)


def write_calibration_report(result, profile, stream, label: str, path: Path) -> None:
    """The report through Qt (a QGuiApplication is made when none runs, offscreen is fine)."""
    import os

    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")  # a lab script, no screen
    from PySide6.QtGui import QGuiApplication

    from app.gui.calibration_report import report_from_offline, write_report

    _app = QGuiApplication.instance() or QGuiApplication(["inclinometer"])
    report = report_from_offline(result, profile, stream.device, label, stream.unit_errors)
    write_report(report, path)


# -- commands ----------------------------------------------------------------------------------
def _check_outputs(args: argparse.Namespace) -> None:
    """``--out``, ``--save`` and ``--report`` of ``calibrate`` and ``calibrate-temperature``:
    at least one, into folders that exist, a report named .html or .pdf (raises _Usage)."""
    if args.out is None and not args.save and args.report is None:
        raise _Usage("say what to do with the result: --out FILE.json, --save and/or "
                     "--report FILE")
    for option, value in (("--out", args.out), ("--report", args.report)):
        if value is not None:
            check_output_folder(value, option)
    if args.report is not None and Path(args.report).suffix.lower() not in (
            ".html", ".htm", ".pdf"):
        raise _Usage(f"--report {args.report}: name an .html or a .pdf file")
    for option, value in (("--out", args.out), ("--report", args.report)):
        if value is not None:
            try:
                check_output(value, inputs=_input_paths(args), overwrite=args.overwrite,
                             option=option)
            except OutputRefused as exc:
                raise _Usage(str(exc)) from None
    if args.out is not None and args.report is not None and (
            Path(args.out).absolute() == Path(args.report).absolute()):
        raise _Usage("--out and --report name the same file")


def _input_paths(args: argparse.Namespace) -> list[Path]:
    """The files a command reads (the recording, --base): no output may be one of them."""
    from drivers.replay import recording_path

    paths = []
    for value in (getattr(args, "recording", None), getattr(args, "base", None)):
        if value:
            try:
                paths.append(recording_path(value) if "://" in value else Path(value))
            except ValueError:  # not a replay URL: nothing on disk to protect
                continue
    return paths


def _write_outputs(args: argparse.Namespace, out: TextIO, json_document: dict[str, Any] | None,
                   report: Callable[[Path], None]) -> int:
    """Write ``--out`` (the JSON) and ``--report`` safely; 0, or EXIT_FAILED (said why)."""
    written = []
    for option, value in (("--out", args.out), ("--report", args.report)):
        if value is None:
            continue
        try:
            with output_path(value, inputs=_input_paths(args), overwrite=args.overwrite,
                             option=option, keep_suffix=True) as temporary:
                if option == "--out":
                    text = json.dumps(json_document, indent=2, allow_nan=False) + "\n"
                    temporary.write_bytes(text.encode("utf-8"))
                else:
                    report(temporary)
        except OSError as exc:
            command = getattr(args, "command", "calibrate")
            done = f" ({', '.join(written)} written)" if written else ""
            print(f"inclinometer {command}: {write_error_message(exc, value, option)}{done}",
                  file=sys.stderr)
            return EXIT_FAILED
        written.append(value)
        print(f"wrote {value}" if option == "--out" else f"wrote the report {value}", file=out)
    return 0


def _check_save(args: argparse.Namespace, stream: CapturedStream, label: str) -> None:
    if args.save and not stream.unique_id:
        raise _Usage(f"{label}: the device has no unique id, so --save cannot name its "
                     "profile; use --out FILE.json")


def calibrate_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``calibrate`` sub-command."""
    from app.core.calibration_procedures.offline import (
        OfflineCalibrationError,
        calibrate_stream,
        calibration_json,
    )
    from app.core.calibration_procedures.profiles import (
        ProfileStore,
        make_profile,
        utc_now_iso,
    )
    from app.core.calibration_procedures.tilt_comparison import worsening

    out = sys.stdout if out is None else out
    try:
        _check_outputs(args)
        finite(args.gyro_seconds, "--gyro-seconds", positive=True, maximum=MAX_SECONDS)
        stream, label = load_stream(args, out)
        _check_save(args, stream, label)
        try:
            result = calibrate_stream(stream.block, stream.settings, method=args.method,
                                      gyro_seconds=args.gyro_seconds)
        except OfflineCalibrationError as exc:
            raise _Failed(f"{label}: cannot calibrate: {exc}") from None
    except _Usage as exc:
        print(f"inclinometer calibrate: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except _Failed as exc:
        print(f"inclinometer calibrate: {exc}", file=sys.stderr)
        return EXIT_FAILED
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
    status = _write_outputs(
        args, out, document,
        lambda path: write_calibration_report(result, profile, stream, label, path))
    if status:
        return status
    if args.save and not refused:
        store = ProfileStore(args.profile_dir)
        path = store.save(profile)
        print(f"saved as the profile of device {printable(stream.unique_id)}: {path}",
              file=out)
    out.flush()
    if refused:
        print(f"inclinometer calibrate: not saved: {worse} Redo the poses, or --force to save "
              "it all the same", file=sys.stderr)
        return EXIT_FAILED
    return 0


def calibration_command(args: argparse.Namespace) -> int:
    """Run the calibration-lab sub-command ``args.command`` names."""
    if args.command == "allan":
        return allan_command(args)
    if args.command == "calibrate-temperature":
        return temperature_command(args)
    return calibrate_command(args)


# -- allan ---------------------------------------------------------------------------------------
def _allan_rows(result) -> list[tuple[str, str, str, np.ndarray, float]]:
    """(sensor, figure, unit, values (3,), SI-to-unit factor) in the familiar units."""
    from app.core.samples import STANDARD_GRAVITY_M_S2

    deg = 180.0 / math.pi
    ug = 1e6 / STANDARD_GRAVITY_M_S2
    g, a = result.gyro, result.accel
    return [
        ("gyro", "noise density", "dps/rtHz", g.noise_density, deg),
        ("gyro", "bias instability", "deg/h", g.bias_instability, deg * 3600.0),
        ("gyro", "random walk", "deg/h/rth", g.random_walk, deg * 3600.0 * 60.0),
        ("accel", "noise density", "ug/rtHz", a.noise_density, ug),
        ("accel", "bias instability", "ug", a.bias_instability, ug),
        ("accel", "random walk", "ug/rth", a.random_walk, ug * 60.0),
    ]


def allan_truth(unit_errors: dict[str, Any], accel_fs_g: int) -> dict[str, dict[str, float]]:
    """A simulated unit's noise figures in SI units (every axis alike).

    Noise densities are the datasheet's (what the simulator adds), random walks the unit's;
    the bias instability has no term of its own in the simulator: its truth is the floor where
    white noise meets the walk, ``min sqrt(N^2 / 2 tau + K^2 tau / 3) / 0.664``.
    """
    from app.core.allan import FLICKER_FACTOR
    from app.core.calibration_procedures.stillness import (
        ACCEL_NOISE_G_PER_SQRT_HZ_16G,
        ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS,
        GYRO_NOISE_DPS_PER_SQRT_HZ,
    )
    from app.core.samples import STANDARD_GRAVITY_M_S2

    density_g = ACCEL_NOISE_G_PER_SQRT_HZ_16G if accel_fs_g == 16 else (
        ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS)
    out = {}
    for sensor, n, k in (
        ("gyro", math.radians(GYRO_NOISE_DPS_PER_SQRT_HZ),
         float(unit_errors["gyro_bias_walk_rad_s_per_sqrt_s"])),
        ("accel", density_g * STANDARD_GRAVITY_M_S2,
         float(unit_errors["accel_bias_walk_m_s2_per_sqrt_s"])),
    ):
        floor = math.sqrt(2.0 * math.sqrt(n * n / 2.0 * k * k / 3.0)) if k > 0 else 0.0
        out[sensor] = {"noise density": n, "random walk": k,
                       "bias instability": floor / FLICKER_FACTOR}
    return out


def print_allan(result, label: str, stream: CapturedStream, out: TextIO) -> None:
    from app.core.allan import figure_support

    support = figure_support(result)
    keys = {"noise density": "noise_density", "bias instability": "bias_instability",
            "random walk": "random_walk"}
    print(f"{label}: {result.duration_s / 60:.1f} min at rest, {result.samples} samples at "
          f"{result.rate_hz:.4g} Hz", file=out)
    span = result.temperature_span_degc
    if math.isfinite(span):
        what = "regressed out" if result.temperature_removed else "kept"
        print(f"temperature moved {span:.2f} degC ({what})", file=out)
    truth = None
    if stream.unit_errors:
        truth = allan_truth(stream.unit_errors, stream.settings.accel_fs_g)
    head = f"  {'':<6}{'figure':<18}{'unit':<10}{'x':>11}{'y':>11}{'z':>11}"
    print(head + ("  truth (simulator)" if truth else ""), file=out)
    for sensor, figure, unit, values, factor in _allan_rows(result):
        shown = support.supported(sensor, keys[figure])
        cells = "".join(f"{v * factor:11.4g}" if ok else f"{'-':>11}"
                        for v, ok in zip(values, shown, strict=True))
        extra = f"  {truth[sensor][figure] * factor:11.4g}" if truth else ""
        print(f"  {sensor:<6}{figure:<18}{unit:<10}{cells}{extra}", file=out)
    if result.method == "likelihood":
        spread = [f"{sensor} " + "/".join(f"{100 * v:.0f}" if math.isfinite(v) else "?"
                                          for v in figures.random_walk_log_sd)
                  for sensor, figures in (("gyro", result.gyro), ("accel", result.accel))]
        print(f"random walk uncertainty (1 sigma, x/y/z, %): {', '.join(spread)}; noise "
              "density and random walk by likelihood (white noise + random walk)", file=out)
    for note in support.notes:
        print(f"note: {note}", file=out)


def allan_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``allan`` sub-command: refuses a record that is too short or not at rest."""
    from app.core.allan import analyse_static, figure_support, static_record_problem
    from app.core.sample_checks import implausible_message, implausible_rows

    out = sys.stdout if out is None else out
    try:
        if args.json not in (None, "-"):
            check_output_folder(args.json, "--json")
            try:
                check_output(args.json, inputs=_input_paths(args), overwrite=args.overwrite,
                             option="--json")
            except OutputRefused as exc:
                raise _Usage(str(exc)) from None
        if args.json == "-":
            out = sys.stderr
        stream, label = load_stream(args, out)
        block = stream.block
        message = implausible_message(
            block.t_s, implausible_rows(block.gyro_rad_s, block.accel_m_s2),
            "the gyroscope or accelerometer")
        if message is not None:
            raise _Usage(f"{label}: {message}")
        problem = static_record_problem(block.gyro_rad_s, block.accel_m_s2,
                                        stream.settings.odr_hz)
        if problem:
            raise _Failed(f"{label}: {problem}")
        try:
            result = analyse_static(block.gyro_rad_s, block.accel_m_s2, stream.settings.odr_hz,
                                    block.temp_degc,
                                    remove_temperature=not args.keep_temperature,
                                    method=args.method)
        except ValueError as exc:
            raise _Failed(f"{label}: {exc}") from None
    except _Usage as exc:
        print(f"inclinometer allan: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except _Failed as exc:
        print(f"inclinometer allan: {exc}", file=sys.stderr)
        return EXIT_FAILED
    print_allan(result, label, stream, out)
    if args.json is not None:
        document = {**result.to_json(), "source": label,
                    "device_unique_id": stream.unique_id,
                    "supported": figure_support(result).to_json()}
        # A figure the data cannot give (NaN: e.g. too short for the bias instability) is
        # written as null: JSON has no NaN (docs/calibration-lab.md).
        text = json.dumps(json_nulls(document), indent=1, allow_nan=False) + "\n"
        if args.json == "-":
            sys.stdout.write(text)
            sys.stdout.flush()
        else:
            try:
                write_output(args.json, text, inputs=_input_paths(args),
                             overwrite=args.overwrite, option="--json")
            except OSError as exc:
                print(f"inclinometer allan: {write_error_message(exc, args.json, '--json')}",
                      file=sys.stderr)
                return EXIT_FAILED
            print(f"wrote {args.json}", file=out)
    out.flush()
    return 0


def json_nulls(value: Any) -> Any:
    """``value`` with every NaN or infinite float (numpy's too) replaced by None."""
    if isinstance(value, dict):
        return {key: json_nulls(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [json_nulls(item) for item in value]
    if isinstance(value, float | np.floating) and not math.isfinite(float(value)):
        return None
    return value


# -- calibrate-temperature -------------------------------------------------------------------------
MDPS_PER_RAD_S = 180.0 / math.pi * 1e3


def _read_base(path: str):
    """(calibration, its temperature or None) from a calibration JSON file."""
    from app.core.bounded_input import load_json
    from app.core.recording.format import calibration_from_json

    file = Path(path)
    try:
        document = load_json(file, max_bytes=1 << 20)
    except FileNotFoundError:
        raise _Usage(f"--base {path}: no such file") from None
    except RecursionError:
        raise _Usage(f"--base {path}: not a calibration JSON file (nested too deeply)") from None
    except (OSError, ValueError) as exc:  # a FIFO, a device, JSON out of bounds, huge integers
        raise _Usage(f"--base {path}: not a calibration JSON file ({one_line(exc)})") from None
    try:
        calibration = calibration_from_json(document)
    except ValueError as exc:
        raise _Usage(f"--base {path}: {exc}") from None
    temp = document.get("temperature_degc")
    temp = float(temp) if isinstance(temp, int | float) and math.isfinite(temp) else None
    return calibration, temp


def _bias_errors(fit, calibration) -> dict[str, tuple[float, float]]:
    """Worst bias error over the fitted bins, (uncompensated, compensated), per sensor in
    mdps and mg. The gyro's is absolute (it reads zero at rest); the accelerometer's is the
    change from the first pose's reading at T0 (gravity is in the reading)."""
    from app.core.samples import STANDARD_GRAVITY_M_S2

    temps = fit.bin_temp_degc
    accel_b, gyro_b = calibration.biases_at(temps)
    gyro_flat = np.broadcast_to(calibration.gyro_bias_rad_s, gyro_b.shape)
    first = fit.bin_pose == 0
    accel_meas = fit.bin_accel_m_s2[first]
    t0_reading = accel_meas - (accel_b[first] - calibration.accel_bias_m_s2)  # at T0
    reference = np.median(t0_reading, axis=0)
    accel_before = np.abs(accel_meas - reference).max()
    accel_after = np.abs(t0_reading - reference).max()
    mg = 1e3 / STANDARD_GRAVITY_M_S2
    return {
        "gyro": (float(np.abs(fit.bin_gyro_rad_s - gyro_flat).max() * MDPS_PER_RAD_S),
                 float(np.abs(fit.bin_gyro_rad_s - gyro_b).max() * MDPS_PER_RAD_S)),
        "accel": (float(accel_before * mg), float(accel_after * mg)),
    }


def print_temperature(fit, calibration, how: str, label: str, stream: CapturedStream,
                      out: TextIO) -> list[str]:
    """The summary of a temperature fit; returns its key lines for the report."""
    from app.core.calibration_procedures.temperature import QUADRATIC, truth_of
    from app.core.samples import STANDARD_GRAVITY_M_S2

    mg = 1e3 / STANDARD_GRAVITY_M_S2
    s = fit.settings
    print(f"{label}: {fit.duration_s:.1f} s, {fit.samples} samples at {s.odr_hz:.4g} Hz, "
          f"{fit.still_s:.1f} s still in {fit.segments} segment(s), {fit.poses} pose(s)",
          file=out)
    if stream.unique_id:
        print(f"device {printable(stream.unique_id)}", file=out)
    print(f"temperature {fit.temp_min_degc:.2f} to {fit.temp_max_degc:.2f} degC (span "
          f"{fit.span_degc:.2f}), {len(fit.bin_temp_degc)} bins; T0 = "
          f"{calibration.temperature.reference_temp_degc:.2f} degC", file=out)
    model = calibration.temperature
    lines = []
    for name, sensor, k1, k2, scale, unit in (
        ("gyro", fit.gyro, model.gyro_k1, model.gyro_k2, MDPS_PER_RAD_S, "mdps"),
        ("accel", fit.accel, model.accel_k1, model.accel_k2, mg, "mg"),
    ):
        chosen = "quadratic" if sensor.degree == QUADRATIC else "linear"
        aicc = sensor.aicc
        gain = aicc[1] - aicc[2] if math.isfinite(aicc.get(2, math.nan)) else math.nan
        why = (f"AICc gain of the quadratic {gain:.1f}" if math.isfinite(gain)
               else "span too narrow for a quadratic")
        print(f"{name}: {chosen} ({why}); residual RMS {_vec(sensor.rms * scale, '.4f', 8)} "
              f"{unit}", file=out)
        print(f"  k1 ({unit}/degC)   {_vec(k1 * scale, '+.5f', 11)}   +- "
              f"{_vec(sensor.k1_std * scale, '.5f', 8)}", file=out)
        if sensor.degree == QUADRATIC:
            print(f"  k2 ({unit}/degC2)  {_vec(k2 * scale, '+.6f', 11)}   +- "
                  f"{_vec(sensor.k2_std * scale, '.6f', 10)}", file=out)
        lines.append(f"{name}: {chosen}, k1 = [{', '.join(f'{v:+.4g}' for v in k1 * scale)}]"
                     f" {unit}/degC")
    print(f"b0 at T0: gyro (dps) {_vec(np.degrees(calibration.gyro_bias_rad_s), '+.4f')}, "
          f"accel (mg) {_vec(calibration.accel_bias_m_s2 * mg, '+.3f')}", file=out)
    print(f"calibration: {how}", file=out)
    errors = _bias_errors(fit, calibration)
    for name, unit in (("gyro", "mdps"), ("accel", "mg")):
        before, after = errors[name]
        line = (f"worst {name} bias error over the data: {before:.3f} {unit} uncompensated, "
                f"{after:.3f} {unit} compensated")
        print(line, file=out)
        lines.append(line)
    for note in fit.notes:
        print(f"note: {note}", file=out)
    if stream.unit_errors:
        truth = truth_of(fit, stream.unit_errors)
        print("against the simulator's truth (fitted / truth):", file=out)
        print(f"  gyro k1 (mdps/degC)      {_vec(model.gyro_k1 * MDPS_PER_RAD_S, '+.4f')}",
              file=out)
        print(f"    truth                  {_vec(truth.gyro_k1 * MDPS_PER_RAD_S, '+.4f')}",
              file=out)
        print(f"  accel k1 (mg/degC)       {_vec(model.accel_k1 * mg, '+.4f')}", file=out)
        print(f"    truth in this pose     {_vec(truth.accel_k1 * mg, '+.4f')}", file=out)
        print(f"    bias coefficient alone {_vec(truth.accel_bias_k1 * mg, '+.4f')}", file=out)
    return lines


def temperature_json(fit, calibration, how: str, device_unique_id: str, source: str,
                     created_utc: str) -> dict[str, Any]:
    """The binding calibration keys, the temperature terms and descriptive extras."""
    from app.core.calibration import temperature_to_json
    from app.core.calibration_procedures.offline import JSON_FORMAT, JSON_VERSION

    return {
        "accel_bias_m_s2": np.asarray(calibration.accel_bias_m_s2, float).tolist(),
        "accel_matrix": np.asarray(calibration.accel_matrix, float).tolist(),
        "gyro_bias_rad_s": np.asarray(calibration.gyro_bias_rad_s, float).tolist(),
        "gyro_matrix": np.asarray(calibration.gyro_matrix, float).tolist(),
        **temperature_to_json(calibration.temperature),
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


def temperature_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``calibrate-temperature`` sub-command."""
    from dataclasses import replace

    from app.core.calibration_procedures.profiles import (
        ProfileError,
        ProfileStore,
        make_profile,
        utc_now_iso,
    )
    from app.core.calibration_procedures.temperature import (
        TemperatureFitError,
        fit_temperature,
        merge_temperature,
    )

    out = sys.stdout if out is None else out
    try:
        _check_outputs(args)
        finite(args.min_span, "--min-span", positive=True, maximum=1000.0)
        if args.reference_temp is not None:
            finite(args.reference_temp, "--reference-temp", minimum=-273.15, maximum=1000.0)
        base = base_temp = None
        base_label = ""
        if args.base is not None:
            base, base_temp = _read_base(args.base)
            base_label = args.base
        stream, label = load_stream(args, out)
        _check_save(args, stream, label)
        store = ProfileStore(args.profile_dir)
        existing = None
        if stream.unique_id and not args.no_merge:
            try:
                existing = store.load_for_device(stream.unique_id)
            except ProfileError as exc:
                raise _Usage(f"the device's profile cannot be read ({exc}); use --no-merge "
                             "or --base FILE.json") from None
        if base is None and existing is not None:
            base, base_temp = existing.calibration, existing.temperature_degc
            base_label = f"the profile of device {stream.unique_id}"
        try:
            fit = fit_temperature(stream.block, stream.settings,
                                  reference_temp_degc=args.reference_temp,
                                  min_span_degc=args.min_span)
        except TemperatureFitError as exc:
            raise _Failed(f"{label}: cannot fit the temperature dependence: {exc}") from None
    except _Usage as exc:
        print(f"inclinometer calibrate-temperature: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except _Failed as exc:
        print(f"inclinometer calibrate-temperature: {exc}", file=sys.stderr)
        return EXIT_FAILED
    name = None if base is None or base.is_identity else f"{base.name} + temperature"
    calibration, how = merge_temperature(fit, base, base_temp, name=name)
    if base_label and base is not None and not base.is_identity:
        how += f" (from {base_label})"
    lines = print_temperature(fit, calibration, how, label, stream, out)
    created = utc_now_iso()
    document = temperature_json(fit, calibration, how, stream.unique_id, label, created)
    residuals = {"temperature_fit": fit.summary()}
    if existing is not None and calibration.name == name:
        profile = replace(existing, calibration=calibration, created_utc=created,
                          method=f"{existing.method} + temperature".strip(" +"),
                          residuals={**existing.residuals, **residuals},
                          notes=f"{existing.notes}; inclinometer calibrate-temperature {label}")
    else:
        profile = make_profile(
            stream.unique_id or "unknown", calibration, fit.settings, method="temperature",
            temperature_degc=calibration.temperature.reference_temp_degc,
            residuals=residuals, created_utc=created,
            notes=f"inclinometer calibrate-temperature {label}")
    status = _write_outputs(
        args, out, document,
        lambda path: write_temperature_report(fit, calibration, profile, stream, label, lines,
                                              path))
    if status:
        return status
    if args.save:
        path = store.save(profile)
        print(f"saved as the profile of device {printable(stream.unique_id)}: {path}",
              file=out)
    out.flush()
    return 0


def write_temperature_report(fit, calibration, profile, stream, label: str, lines,
                             path: Path) -> None:
    import os

    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtGui import QGuiApplication

    from app.gui.calibration_report import report_from_temperature, write_report

    _app = QGuiApplication.instance() or QGuiApplication(["inclinometer"])
    report = report_from_temperature(fit, calibration, profile, stream.device, label,
                                     stream.unit_errors, lines)
    write_report(report, path)
