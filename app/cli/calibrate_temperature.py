"""``inclinometer calibrate-temperature RECORDING [--out FILE.json] [--save] [--report FILE]``:
gyroscope and accelerometer bias against die temperature, fitted on a recording of the board
resting while it warms up (linear, or quadratic when the span and the AICc say so); merged with
the device's profile (or ``--base FILE.json``) when there is one.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import TextIO

import numpy as np

from app.cli import lab
from app.cli.errors import finite, one_line
from app.core.bounded_input import load_json
from app.core.calibration_procedures.profiles import (
    ProfileError,
    ProfileStore,
    make_profile,
    utc_now_iso,
)
from app.core.calibration_procedures.temperature import (
    QUADRATIC,
    TemperatureFitError,
    fit_temperature,
    merge_temperature,
    temperature_calibration_json,
    truth_of,
)
from app.core.devices import printable
from app.core.recording.format import calibration_from_json
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.services.calibration_runs import CapturedStream


def add_arguments(temperature: argparse.ArgumentParser) -> None:
    """The options of ``calibrate-temperature``; it runs :func:`temperature_command`."""
    temperature.set_defaults(handler=temperature_command)
    temperature.description = (
        "Fit the gyroscope and accelerometer biases against the die temperature, "
        "b(T) = b0 + k1 (T - T0) + k2 (T - T0)^2, on a recording of the board resting "
        "while its temperature moves (from power-up, in a chamber, or still poses at "
        "several temperatures; still stretches are found by the wizard's stillness "
        "detection). The quadratic term is used only with a span of 10 degC or more and "
        "a clear AICc gain. The terms are added to the device's profile (or to --base "
        "FILE.json from 'inclinometer calibrate --out'), whose biases stay as b0 at its "
        "own temperature; without one, the gyro bias comes from the fit."
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


MDPS_PER_RAD_S = 180.0 / math.pi * 1e3


def _read_base(args: argparse.Namespace):
    """(calibration, its temperature or None) from the calibration JSON file ``--base``."""
    path = args.base
    file = Path(path)
    try:
        document = load_json(file, max_bytes=1 << 20)
    except FileNotFoundError:
        raise lab.usage(args, f"--base {path}: no such file") from None
    except RecursionError:
        raise lab.usage(args, f"--base {path}: not a calibration JSON file (nested too "
                              "deeply)") from None
    except (OSError, ValueError) as exc:  # a FIFO, a device, JSON out of bounds, huge integers
        raise lab.usage(args, f"--base {path}: not a calibration JSON file "
                              f"({one_line(exc)})") from None
    try:
        calibration = calibration_from_json(document)
    except ValueError as exc:
        raise lab.usage(args, f"--base {path}: {exc}") from None
    temp = document.get("temperature_degc")
    temp = float(temp) if isinstance(temp, int | float) and math.isfinite(temp) else None
    return calibration, temp


def _bias_errors(fit, calibration) -> dict[str, tuple[float, float]]:
    """Worst bias error over the fitted bins, (uncompensated, compensated), per sensor in
    mdps and mg. The gyro's is absolute (it reads zero at rest); the accelerometer's is the
    change from the first pose's reading at T0 (gravity is in the reading)."""
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
        print(f"{name}: {chosen} ({why}); residual RMS {lab.vec(sensor.rms * scale, '.4f', 8)} "
              f"{unit}", file=out)
        print(f"  k1 ({unit}/degC)   {lab.vec(k1 * scale, '+.5f', 11)}   +- "
              f"{lab.vec(sensor.k1_std * scale, '.5f', 8)}", file=out)
        if sensor.degree == QUADRATIC:
            print(f"  k2 ({unit}/degC2)  {lab.vec(k2 * scale, '+.6f', 11)}   +- "
                  f"{lab.vec(sensor.k2_std * scale, '.6f', 10)}", file=out)
        lines.append(f"{name}: {chosen}, k1 = [{', '.join(f'{v:+.4g}' for v in k1 * scale)}]"
                     f" {unit}/degC")
    print(f"b0 at T0: gyro (dps) {lab.vec(np.degrees(calibration.gyro_bias_rad_s), '+.4f')}, "
          f"accel (mg) {lab.vec(calibration.accel_bias_m_s2 * mg, '+.3f')}", file=out)
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
        print(f"  gyro k1 (mdps/degC)      {lab.vec(model.gyro_k1 * MDPS_PER_RAD_S, '+.4f')}",
              file=out)
        print(f"    truth                  {lab.vec(truth.gyro_k1 * MDPS_PER_RAD_S, '+.4f')}",
              file=out)
        print(f"  accel k1 (mg/degC)       {lab.vec(model.accel_k1 * mg, '+.4f')}", file=out)
        print(f"    truth in this pose     {lab.vec(truth.accel_k1 * mg, '+.4f')}", file=out)
        print(f"    bias coefficient alone {lab.vec(truth.accel_bias_k1 * mg, '+.4f')}", file=out)
    return lines


def temperature_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``calibrate-temperature`` sub-command."""
    out = sys.stdout if out is None else out
    lab.check_outputs(args)
    finite(args.min_span, "--min-span", positive=True, maximum=1000.0)
    if args.reference_temp is not None:
        finite(args.reference_temp, "--reference-temp", minimum=-273.15, maximum=1000.0)
    base = base_temp = None
    if args.base is not None:
        base, base_temp = _read_base(args)
    stream, label = lab.load_stream(args, out)
    lab.check_save(args, stream, label)
    store = ProfileStore(args.profile_dir)
    existing = _existing_profile(args, store, stream)
    base_label = args.base or ""
    if base is None and existing is not None:
        base, base_temp = existing.calibration, existing.temperature_degc
        base_label = f"the profile of device {stream.unique_id}"
    try:
        fit = fit_temperature(stream.block, stream.settings,
                              reference_temp_degc=args.reference_temp,
                              min_span_degc=args.min_span)
    except TemperatureFitError as exc:
        raise lab.failed(args, f"{label}: cannot fit the temperature dependence: {exc}") from None
    name = None if base is None or base.is_identity else f"{base.name} + temperature"
    calibration, how = merge_temperature(fit, base, base_temp, name=name)
    if base_label and base is not None and not base.is_identity:
        how += f" (from {base_label})"
    lines = print_temperature(fit, calibration, how, label, stream, out)
    created = utc_now_iso()
    document = temperature_calibration_json(fit, calibration, how, stream.unique_id, label,
                                            created)
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
    lab.write_outputs(
        args, out, document,
        lambda path: write_temperature_report(fit, calibration, profile, stream, label, lines,
                                              path))
    if args.save:
        path = store.save(profile)
        print(f"saved as the profile of device {printable(stream.unique_id)}: {path}",
              file=out)
    out.flush()
    return 0


def _existing_profile(args: argparse.Namespace, store: ProfileStore, stream: CapturedStream):
    """The device's stored profile to merge with (None: none, or --no-merge)."""
    if not stream.unique_id or args.no_merge:
        return None
    try:
        return store.load_for_device(stream.unique_id)
    except ProfileError as exc:
        raise lab.usage(args, f"the device's profile cannot be read ({exc}); use --no-merge "
                        "or --base FILE.json") from None


def write_temperature_report(fit, calibration, profile, stream, label: str, lines,
                             path: Path) -> None:
    """The report (:mod:`app.documents.calibration_report`; Qt is loaded only now)."""
    _app = lab.qt_for_documents()
    from app.documents.calibration_report import report_from_temperature, write_report

    report = report_from_temperature(fit, calibration, profile, stream.device, label,
                                     stream.unit_errors, lines)
    write_report(report, path)
