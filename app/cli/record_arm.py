"""``inclinometer record-arm "sim://arm?..." --duration S DIR``: a simulated measuring arm,
one recording per sensor, with the truth (:mod:`app.services.arm_recordings`); with
``--placements N`` (a ``column=1`` arm with magnetometers) the end point of each placement in
R, theta and Z, measured against the truth, and the repeatability."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, TextIO

from app.cli.errors import EXIT_FAILED, CommandError, check_output_folder, finite
from app.core.arm import COLUMN_AZIMUTH, CYLINDRICAL
from app.core.safe_output import OutputRefused, check_output, write_error_message, write_output
from app.services.arm_recordings import CAPTURE_S, ArmPlacements, record_arm_placements
from drivers.errors import DeviceError

MAX_PLACEMENTS = 1000
LABELS = {"R": "R", "azimuth_deg": "theta", "Z": "Z", COLUMN_AZIMUTH: "azimuth"}


def add_arguments(arm: argparse.ArgumentParser) -> None:
    """The options of ``record-arm``; it runs :func:`record_arm_command`."""
    arm.set_defaults(handler=record_arm_command)
    arm.description = (
        "Run every sensor of one sim://arm (same seed: one arm) as fast as possible and "
        "write DIR/sensor0.csv, sensor1.csv, ...: raw samples (and mx,my,mz with mag=), the "
        "true orientation and, from sensor 1 on, joint_ref_deg, the true angle of the hinge "
        "between sensor K-1 and K (column=1: theta_ref_deg too, the column's true angle); the "
        "true axes are in the 'arm' metadata key. --placements N (column=1 with a "
        "magnetometer) captures the first N placements as the Arm panel does and prints the "
        "end point in R, theta and Z, measured and true, and their repeatability."
    )
    arm.add_argument("url", metavar="URL", help="a sim://arm URL, e.g. "
                     "'sim://arm?links=3&seed=4&odr=208' or "
                     "'sim://arm?column=1&mag=lis3mdl&spots=1' (sensor= is set for each file)")
    arm.add_argument("directory", metavar="DIR", help="where to write the files")
    arm.add_argument("--duration", type=float, default=180.0, metavar="S",
                     help="seconds of device time (default %(default)g; with --placements at "
                          "least until the last one)")
    arm.add_argument("--placements", type=int, default=0, metavar="N",
                     help="measure the first N placements of a column=1 arm (theta from the "
                          "magnetometers, its zero at the first accepted placement)")
    arm.add_argument("--capture", type=float, default=CAPTURE_S, metavar="S",
                     help="seconds each placement averages, the middle of its hold "
                          "(default %(default)g)")
    arm.add_argument("--json", metavar="OUT",
                     help="write the placements and their repeatability as JSON ('-': stdout)")
    arm.add_argument("--overwrite", "--force", dest="force", action="store_true",
                     help="replace existing files")


def record_arm_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``record-arm`` sub-command."""
    out = sys.stdout if out is None else out
    finite(args.duration, "--duration", positive=True, maximum=86400.0)
    finite(args.capture, "--capture", positive=True, maximum=3600.0)
    if not 0 <= args.placements <= MAX_PLACEMENTS:
        raise CommandError(f"--placements must be 0 to {MAX_PLACEMENTS}, not {args.placements}",
                           command="record-arm")
    if args.json is not None and not args.placements:
        raise CommandError("--json writes the placements: give --placements N",
                           command="record-arm")
    if args.json not in (None, "-"):
        check_output_folder(args.json, "--json")
        try:
            check_output(args.json, overwrite=args.force, option="--json")
        except OutputRefused as exc:
            raise CommandError(str(exc), command="record-arm") from None
    if args.json == "-":
        out = sys.stderr
    try:
        written, measured = record_arm_placements(
            args.url, args.duration, Path(args.directory), overwrite=args.force,
            placements=args.placements, capture_s=args.capture)
    except (ValueError, DeviceError) as exc:
        raise CommandError(str(exc), command="record-arm") from None
    except OSError as exc:
        raise CommandError(exc.strerror or str(exc), EXIT_FAILED, command="record-arm") from None
    for item in written:
        print(f"{item.path}: sensor {item.sensor}, {item.samples} samples", file=out)
    if measured is None:
        return 0
    print_placements(measured, out)
    if args.json is not None:
        text = json.dumps(_json_nulls(measured.to_dict()), indent=1, allow_nan=False) + "\n"
        if args.json == "-":
            sys.stdout.write(text)
            sys.stdout.flush()
        else:
            try:
                write_output(args.json, text, overwrite=args.force, option="--json")
            except OSError as exc:
                raise CommandError(write_error_message(exc, args.json, "--json"), EXIT_FAILED,
                                   command="record-arm") from None
            print(f"wrote {args.json}", file=out)
    return 0


def _number(value: float | None, digits: int) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def print_placements(measured: ArmPlacements, out: TextIO) -> None:
    """Each placement measured and true, then the repeatability of R, theta, Z."""
    unit = measured.layout.unit
    print(f"placements (theta's zero: {measured.zero.source}; field corrected with "
          f"{measured.calibration}):", file=out)
    print(f"{'#':>3} {'R ' + unit:>9} {'theta °':>9} {'Z ' + unit:>9} {'azimuth °':>10} │ "
          f"{'true R':>9} {'theta':>9} {'Z':>9} {'azimuth':>10}", file=out)
    for row in measured.rows:
        truth = "".join(f"{_number(row.truth[name], 2):>10}" for name in
                        ("R", "azimuth_deg", "Z", COLUMN_AZIMUTH))
        if row.measured is None:
            print(f"{row.index + 1:>3} refused: {row.refused}", file=out)
            print(f"{'':>3} {'':>41}│{truth}", file=out)
            continue
        values = " ".join(f"{_number(row.measured[name], 2):>9}" for name in
                          ("R", "azimuth_deg", "Z"))
        print(f"{row.index + 1:>3} {values} {_number(row.measured[COLUMN_AZIMUTH], 2):>10} │"
              f"{truth}", file=out)
    stats = measured.placements.statistics()
    accepted = len(measured.placements)
    print(f"repeatability over {accepted} accepted placement{'s' if accepted != 1 else ''} "
          f"of {len(measured.rows)} (SD n-1):", file=out)
    print(f"{'':>8}" + "".join(f"{LABELS[name]:>10}" for name in CYLINDRICAL), file=out)
    for what in ("mean", "sd", "min", "max", "range"):
        cells = "".join(f"{_number(getattr(stats[name], what), 3):>10}" if stats else
                        f"{'—':>10}" for name in CYLINDRICAL)
        print(f"{what:>8}{cells}", file=out)


def _json_nulls(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _json_nulls(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_json_nulls(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
