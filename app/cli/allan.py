"""``inclinometer allan RECORDING [--json OUT] [--kalibr IMU_YAML]``: Allan deviation of a
static recording: noise density (in both conventions: the datasheet's one-sided and the
Allan/Kalibr one), bias instability and random walk per axis of the gyroscope and the
accelerometer; ``--kalibr`` also writes Kalibr's IMU noise file (:mod:`app.core.interop.kalibr`).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from typing import Any, TextIO

import numpy as np

from app.cli import lab
from app.cli.errors import check_output_folder
from app.core import allan as noise_model  # looked up when run (a test swaps the analysis)
from app.core.allan import (
    FLICKER_FACTOR,
    ONE_SIDED_PER_ALLAN,
    figure_support,
    static_record_problem,
)
from app.core.calibration_procedures.stillness import (
    ACCEL_NOISE_G_PER_SQRT_HZ_16G,
    ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS,
    GYRO_NOISE_DPS_PER_SQRT_HZ,
)
from app.core.interop.kalibr import DEFAULT_ROSTOPIC, KalibrRefused, kalibr_yaml
from app.core.safe_output import (
    OutputRefused,
    check_output,
    write_error_message,
    write_output,
)
from app.core.sample_checks import implausible_message, implausible_rows
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.services.calibration_runs import CapturedStream


def add_arguments(allan: argparse.ArgumentParser) -> None:
    """The options of ``allan``; it runs :func:`allan_command`."""
    allan.set_defaults(handler=allan_command)
    allan.description = (
        "Allan deviation (allantools) of every gyroscope and accelerometer axis of a "
        "recording of the sensor at rest, and the noise model fitted to it: noise density "
        "(dps/sqrt(Hz), ug/sqrt(Hz)), bias instability (deg/h, ug) and bias random walk "
        "(deg/h/sqrt(h), ug/sqrt(h)). A temperature that moves is regressed out first "
        "(--keep-temperature keeps it). Noise density and random walk come from the "
        "time series' likelihood (white noise + bias random walk, the walk as the posterior "
        "median, its relative 1-sigma uncertainty printed); --method allan-fit reads them "
        "off the Allan curve instead. Record at least 30 minutes; the gyroscope's random "
        "walk needs an hour or more (30 minutes leave it uncertain by about 50 %)."
    )
    allan.add_argument("recording", nargs="?", metavar="RECORDING",
                       help="a recording (format v1) of the sensor lying still")
    allan.add_argument("--json", metavar="OUT", help="write the figures as JSON ('-': stdout)")
    allan.add_argument("--kalibr", metavar="IMU_YAML",
                       help="also write Kalibr's IMU noise file (its continuous-time "
                            "convention: the Allan densities and the random walks, measured, "
                            "not inflated); needs 30 min or more at rest")
    allan.add_argument("--rostopic", default=DEFAULT_ROSTOPIC, metavar="TOPIC",
                       help="with --kalibr: the IMU topic it names (default %(default)s)")
    allan.add_argument("--overwrite", action="store_true",
                       help="replace OUT or IMU_YAML if it exists")
    allan.add_argument("--device", metavar="URL", help="read a live device instead")
    allan.add_argument("--seconds", type=float, metavar="N", help="with --device: how long")
    allan.add_argument("--keep-temperature", action="store_true",
                       help="do not regress the temperature out before the analysis")
    allan.add_argument("--method", choices=("likelihood", "allan-fit"), default="likelihood",
                       help="estimator of noise density and random walk (default %(default)s)")


TOPIC = re.compile(r"/[A-Za-z0-9_/]+")
"""A ROS topic name as --rostopic takes it."""
ONE_SIDED = "noise density (1-sided)"
"""The datasheet's one-sided density: one sample at rate fs scatters by N sqrt(fs/2)."""
ALLAN = "noise density (Allan)"
"""The Allan/Kalibr/IEEE 952 density, adev at tau = 1 s: a sample scatters by N sqrt(fs)."""
CONVENTION_NOTE = (
    "noise density (1-sided): the datasheet's convention, one sample at rate fs scatters by "
    "N*sqrt(fs/2) (JSON noise_density, noise_density_one_sided); noise density (Allan): "
    "Allan/Kalibr/IEEE 952, the Allan deviation at tau = 1 s, one sample scatters by "
    "N*sqrt(fs), = 1-sided / sqrt(2) (JSON noise_density_allan)")


def _allan_rows(result) -> list[tuple[str, str, str, np.ndarray, float]]:
    """(sensor, figure, unit, values (3,), SI-to-unit factor) in the familiar units."""
    deg = 180.0 / math.pi
    ug = 1e6 / STANDARD_GRAVITY_M_S2
    g, a = result.gyro, result.accel
    return [
        ("gyro", ONE_SIDED, "dps/rtHz", g.noise_density_one_sided, deg),
        ("gyro", ALLAN, "dps/rtHz", g.noise_density_allan, deg),
        ("gyro", "bias instability", "deg/h", g.bias_instability, deg * 3600.0),
        ("gyro", "random walk", "deg/h/rth", g.random_walk, deg * 3600.0 * 60.0),
        ("accel", ONE_SIDED, "ug/rtHz", a.noise_density_one_sided, ug),
        ("accel", ALLAN, "ug/rtHz", a.noise_density_allan, ug),
        ("accel", "bias instability", "ug", a.bias_instability, ug),
        ("accel", "random walk", "ug/rth", a.random_walk, ug * 60.0),
    ]


def allan_truth(unit_errors: dict[str, Any], accel_fs_g: int) -> dict[str, dict[str, float]]:
    """A simulated unit's noise figures in SI units (every axis alike).

    Noise densities are the datasheet's (what the simulator adds), random walks the unit's;
    the bias instability has no term of its own in the simulator: its truth is the floor where
    white noise meets the walk, ``min sqrt(N^2 / 2 tau + K^2 tau / 3) / 0.664``.
    """
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
        out[sensor] = {ONE_SIDED: n, ALLAN: n / ONE_SIDED_PER_ALLAN, "random walk": k,
                       "bias instability": floor / FLICKER_FACTOR}
    return out


def print_allan(result, label: str, stream: CapturedStream, out: TextIO) -> None:
    support = figure_support(result)
    keys = {ONE_SIDED: "noise_density", ALLAN: "noise_density",
            "bias instability": "bias_instability", "random walk": "random_walk"}
    print(f"{label}: {result.duration_s / 60:.1f} min at rest, {result.samples} samples at "
          f"{result.rate_hz:.4g} Hz", file=out)
    span = result.temperature_span_degc
    if math.isfinite(span):
        what = "regressed out" if result.temperature_removed else "kept"
        print(f"temperature moved {span:.2f} degC ({what})", file=out)
    truth = None
    if stream.unit_errors:
        truth = allan_truth(stream.unit_errors, stream.settings.accel_fs_g)
    head = f"  {'':<6}{'figure':<24}{'unit':<10}{'x':>11}{'y':>11}{'z':>11}"
    print(head + ("  truth (simulator)" if truth else ""), file=out)
    for sensor, figure, unit, values, factor in _allan_rows(result):
        shown = support.supported(sensor, keys[figure])
        cells = "".join(f"{v * factor:11.4g}" if ok else f"{'-':>11}"
                        for v, ok in zip(values, shown, strict=True))
        extra = f"  {truth[sensor][figure] * factor:11.4g}" if truth else ""
        print(f"  {sensor:<6}{figure:<24}{unit:<10}{cells}{extra}", file=out)
    print(CONVENTION_NOTE, file=out)
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
    out = sys.stdout if out is None else out
    if args.json not in (None, "-"):
        check_output_folder(args.json, "--json")
        try:
            check_output(args.json, inputs=lab.input_paths(args), overwrite=args.overwrite,
                         option="--json")
        except OutputRefused as exc:
            raise lab.usage(args, str(exc)) from None
    if args.kalibr is not None:
        if not TOPIC.fullmatch(args.rostopic):
            raise lab.usage(args, f"--rostopic {args.rostopic!r}: a ROS topic name such as "
                                  "/imu0 (a slash, then letters, digits, _ and /)")
        check_output_folder(args.kalibr, "--kalibr")
        try:
            check_output(args.kalibr, inputs=lab.input_paths(args), overwrite=args.overwrite,
                         option="--kalibr")
        except OutputRefused as exc:
            raise lab.usage(args, str(exc)) from None
    if args.json == "-":
        out = sys.stderr
    stream, label = lab.load_stream(args, out)
    result = _analyse(args, stream, label)
    print_allan(result, label, stream, out)
    if args.kalibr is not None:
        try:
            text = kalibr_yaml(result, label, args.rostopic)
        except KalibrRefused as exc:
            raise lab.failed(args, f"{label}: {exc}") from None
        try:
            write_output(args.kalibr, text, inputs=lab.input_paths(args),
                         overwrite=args.overwrite, option="--kalibr")
        except OSError as exc:
            raise lab.failed(args, write_error_message(exc, args.kalibr, "--kalibr")) from None
        print(f"wrote {args.kalibr} (Kalibr's convention; measured values, not inflated)",
              file=out)
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
                write_output(args.json, text, inputs=lab.input_paths(args),
                             overwrite=args.overwrite, option="--json")
            except OSError as exc:
                raise lab.failed(args, write_error_message(exc, args.json, "--json")) from None
            print(f"wrote {args.json}", file=out)
    out.flush()
    return 0


def _analyse(args: argparse.Namespace, stream: CapturedStream, label: str):
    """The Allan analysis; CommandError for implausible samples (exit 2) or a record that is
    too short or not at rest (exit 1)."""
    block = stream.block
    message = implausible_message(
        block.t_s, implausible_rows(block.gyro_rad_s, block.accel_m_s2),
        "the gyroscope or accelerometer")
    if message is not None:
        raise lab.usage(args, f"{label}: {message}")
    problem = static_record_problem(block.gyro_rad_s, block.accel_m_s2, stream.settings.odr_hz)
    if problem:
        raise lab.failed(args, f"{label}: {problem}")
    try:
        return noise_model.analyse_static(
            block.gyro_rad_s, block.accel_m_s2, stream.settings.odr_hz, block.temp_degc,
            remove_temperature=not args.keep_temperature, method=args.method)
    except ValueError as exc:
        raise lab.failed(args, f"{label}: {exc}") from None


def json_nulls(value: Any) -> Any:
    """``value`` with every NaN or infinite float (numpy's too) replaced by None."""
    if isinstance(value, dict):
        return {key: json_nulls(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [json_nulls(item) for item in value]
    if isinstance(value, float | np.floating) and not math.isfinite(float(value)):
        return None
    return value


