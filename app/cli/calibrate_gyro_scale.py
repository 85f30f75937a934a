"""``inclinometer calibrate-gyro-scale RECORDING --json OUT [--overwrite]``.

Finds the whole turns in RECORDING (the sensor rolled one or more whole turns about each of
its axes, lying horizontal, from rest to rest: :mod:`app.core.calibration_procedures.gyro_scale`),
prints each turn's verdict, the scale errors and misalignments, and writes the calibration
JSON's gyroscope keys (``gyro_bias_rad_s`` from the rests, ``gyro_matrix``; the accelerometer's
left as the identity) for a calibration profile.

Exit status: 0 done, 1 the turns do not give a calibration (the message says why), 2 bad usage
or a file that cannot be read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TextIO

import numpy as np

from app.cli.errors import CommandError, check_output_folder
from app.core.safe_output import OutputRefused, check_output, write_error_message, write_output

EXIT_FAILED = 1
EXIT_USAGE = 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``calibrate-gyro-scale``; it runs :func:`run`."""
    parser.set_defaults(handler=run)
    parser.description = (
        "Gyroscope scale factors and axis misalignment from whole turns (Ferraris): roll the "
        "sensor one or more whole turns about each of its three axes, the axis lying "
        "horizontal, holding it still for a second before and after each turn; record it; "
        "give the recording here. The accelerometer is the reference angle (gravity turns "
        "once per turn across the axis), so no turntable is needed.")
    parser.add_argument("recording", metavar="RECORDING", help="the recorded turns (CSV)")
    parser.add_argument("--json", metavar="OUT", required=True,
                        help="write the calibration JSON (gyro_bias_rad_s, gyro_matrix) to OUT")
    parser.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Run ``calibrate-gyro-scale``; returns the exit status."""
    from app.core.calibration import SensorCalibration, calibration_json_text, calibration_to_json
    from app.core.calibration_procedures.gyro_scale import GyroScaleError, fit_gyro_scale
    from app.core.recording.errors import RecordingError
    from app.core.recording.reader import read_recording

    out = sys.stdout if out is None else out
    path = Path(args.recording)
    try:
        check_output_folder(args.json, "--json")
        check_output(args.json, inputs=[path], overwrite=args.overwrite, option="--json")
    except (OutputRefused, CommandError) as exc:
        print(f"calibrate-gyro-scale: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        recording = read_recording(path)
    except (RecordingError, OSError) as exc:
        print(f"calibrate-gyro-scale: {path}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        result = fit_gyro_scale(recording.t_s, recording.accel_m_s2, recording.gyro_rad_s)
    except GyroScaleError as exc:
        print(f"calibrate-gyro-scale: {path}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    for turn in result.turns:
        axis = "xyz"[turn.axis] if turn.axis >= 0 else "?"
        verdict = "used" if turn.used else f"refused: {turn.refused}"
        print(f"  {turn.start_s:7.1f}-{turn.end_s:7.1f} s  about {axis}  {turn.turns:+d} turns  "
              f"gyro {np.linalg.norm(turn.gyro_angle_deg):8.2f} deg  accelerometer "
              f"{turn.accel_angle_deg:8.2f} deg  {verdict}", file=out)
    scale = " ".join(f"{v:+.3f}" for v in result.scale_error_pct)
    print(f"scale error (x y z)   {scale} %", file=out)
    off = result.misalignment_deg
    print("misalignment          " + " ".join(
        f"{'xyz'[i]}{'xyz'[j]} {off[i, j]:+.3f}" for i in range(3) for j in range(3) if i != j)
        + " deg", file=out)
    print("bias (dps)            " + " ".join(f"{v:+.4f}" for v in np.degrees(result.bias_rad_s)),
          file=out)
    calibration = SensorCalibration(gyro_bias_rad_s=result.bias_rad_s, gyro_matrix=result.matrix,
                                    name="gyro scale")
    document = {**calibration_to_json(calibration), "gyro_scale": {
        "method": "whole turns, accelerometer as the reference angle (Ferraris)",
        "recording": str(path),
        "scale_error_pct": result.scale_error_pct.tolist(),
        "turns_used": sum(turn.used for turn in result.turns),
    }}
    try:
        write_output(args.json, calibration_json_text(document), inputs=[path],
                     overwrite=args.overwrite, option="--json")
    except OSError as exc:
        print(f"calibrate-gyro-scale: {write_error_message(exc, args.json, '--json')}",
              file=sys.stderr)
        return EXIT_USAGE
    print(f"wrote {args.json}", file=out)
    return 0
