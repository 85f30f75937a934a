"""``inclinometer calibrate-mag RECORDING --json OUT [--save] [--place LAT,LON] [--date D]``.

Fits the magnetometer of a recorded tour (hard iron, the full soft-iron matrix and the chip's
turn against the accelerometer, :mod:`app.core.magnetometer.fit`), prints a summary and the
verdict, writes the binding JSON ``{"magnetometer": {...}}`` and, with ``--save``, stores the
result in the device's calibration profile (a "redo" verdict only with ``--force``).

Exit status: 0 done, 1 the tour does not calibrate or a "redo" was not saved (the message
says why), 2 bad usage or a file that cannot be read.
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import date
from pathlib import Path
from typing import TextIO

import numpy as np

from app.cli_errors import CommandError, check_output_folder
from app.core.devices import printable
from app.core.safe_output import OutputRefused, check_output, write_error_message, write_output

COMMAND = "calibrate-mag"
EXIT_FAILED = 1
EXIT_USAGE = 2


class _Usage(CommandError):
    """Bad arguments or an unreadable input: exit 2."""


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``calibrate-mag``."""
    parser = commands.add_parser(
        COMMAND, help="calibrate the magnetometer from a recorded tour (hard iron, soft "
                      "iron and its turn against the accelerometer)",
        description="Fit the magnetometer of RECORDING (a tour through every direction, with "
                    "mx,my,mz and the accelerometer): hard iron, the full soft-iron matrix and "
                    "the turn between the magnetometer's axes and the accelerometer's, from "
                    "the field's constant strength and its constant dip to gravity. Prints the "
                    "result and a verdict (good / redo, with the reasons), writes the JSON "
                    "{\"magnetometer\": {...}}. The model: m = soft_iron (raw - hard_iron), in "
                    "the accelerometer's frame.",
    )
    parser.add_argument("recording", metavar="RECORDING", help="the recorded tour (CSV)")
    parser.add_argument("--json", metavar="OUT", help="write the calibration JSON to OUT")
    parser.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    parser.add_argument("--save", action="store_true",
                        help="store the result in the device's calibration profile (a 'redo' "
                             "verdict is refused unless --force)")
    parser.add_argument("--force", action="store_true",
                        help="with --save: store it even when the verdict is 'redo'")
    parser.add_argument("--place", metavar="LAT,LON",
                        help="where the tour was made (degrees), to judge the field and dip "
                             "against the World Magnetic Model")
    parser.add_argument("--date", metavar="YYYY-MM-DD",
                        help="the day of the tour for the WMM (default: the recording's)")
    parser.add_argument("--profile-dir", metavar="DIR", help=argparse.SUPPRESS)


def _place(text: str | None):
    from app.core.earth_field import Place

    if text is None:
        return None
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        latitude, longitude = (float(part) for part in parts)
    except ValueError:
        raise _Usage(f"--place {text!r}: give LAT,LON in degrees, e.g. 52.51,13.33") from None
    try:
        return Place(latitude, longitude)
    except ValueError as exc:
        raise _Usage(f"--place {text!r}: {exc}") from None


def _date(text: str | None) -> date | None:
    if text is None:
        return None
    try:
        return date.fromisoformat(text)
    except ValueError:
        raise _Usage(f"--date {text!r}: give YYYY-MM-DD") from None


def _fmt(values: np.ndarray, spec: str = "8.3f") -> str:
    return " ".join(format(float(v), spec) for v in values)


def print_summary(run, out: TextIO) -> None:
    """The human summary: hard iron, matrix, alignment, field, dip, residual, coverage,
    verdict and reasons."""
    result = run.result
    cal = result.calibration
    alignment = cal.extra.get("alignment_deg")
    print(f"{run.source}: {result.samples_used} field samples used "
          f"({result.outliers} left out), {result.still_samples} at rest with gravity", file=out)
    print(f"  method       {cal.extra.get('method')}", file=out)
    print(f"  hard iron    {_fmt(cal.hard_iron_ut)}  uT", file=out)
    for i, row in enumerate(cal.soft_iron):
        print(f"  {'soft iron' if i == 0 else '':12s} {_fmt(row, '8.5f')}", file=out)
    print("  alignment    " + ("not estimated" if alignment is None
                               else f"{alignment:.2f} deg (magnetometer against accelerometer)"),
          file=out)
    reference = run.expected
    field = f"{cal.field_ut:.2f} uT"
    dip = "n/a" if not np.isfinite(cal.dip_deg) else f"{cal.dip_deg:.2f} deg"
    if reference is not None:
        field += f"  (WMM {reference.total_ut:.2f} uT)"
        dip += f"  (WMM {reference.dip_deg:.2f} deg)"
    print(f"  field        {field}", file=out)
    print(f"  dip          {dip}", file=out)
    print(f"  residual     {cal.fitness_ut:.3f} uT RMS", file=out)
    print(f"  coverage     {cal.coverage:.0%} of 80 sections", file=out)
    print(f"  verdict      {result.verdict}", file=out)
    for reason in result.reasons:
        print(f"    - {reason}", file=out)
    for note in (*result.notes, *run.notes):
        print(f"  note: {note}", file=out)


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Run ``calibrate-mag``; returns the exit status."""
    from app.core.calibration_procedures.profiles import ProfileError, ProfileStore
    from app.core.recording.errors import RecordingError
    from app.services.mag_calibration import calibrate_recording, save_to_profile

    out = sys.stdout if out is None else out
    inputs = [Path(args.recording)]
    try:
        if args.json is None and not args.save:
            raise _Usage("say what to do with the result: --json OUT and/or --save")
        if args.force and not args.save:
            raise _Usage("--force goes with --save")
        place, when = _place(args.place), _date(args.date)
        if args.json is not None:
            check_output_folder(args.json, "--json")
            try:
                check_output(args.json, inputs=inputs, overwrite=args.overwrite,
                             option="--json")
            except OutputRefused as exc:
                raise _Usage(str(exc)) from None
        path = Path(args.recording)
        if not path.is_file():
            raise _Usage(f"{path}: no such file" if not path.exists() else f"{path}: not a file")
        try:
            result = calibrate_recording(path, place, when)
        except RecordingError as exc:
            raise _Usage(str(exc)) from None
        except OSError as exc:
            raise _Usage(f"{path}: cannot read the recording: {exc.strerror or exc}") from None
        except ValueError as exc:
            print(f"inclinometer {COMMAND}: {path}: cannot calibrate: {exc}", file=sys.stderr)
            return EXIT_FAILED
    except CommandError as exc:
        print(f"inclinometer {COMMAND}: {exc}", file=sys.stderr)
        return exc.code
    print_summary(result, out)
    if args.json is not None:
        text = json.dumps(result.document(), indent=2, allow_nan=False) + "\n"
        try:
            write_output(args.json, text, inputs=inputs, overwrite=args.overwrite,
                         option="--json")
        except OSError as exc:
            print(f"inclinometer {COMMAND}: {write_error_message(exc, args.json, '--json')}",
                  file=sys.stderr)
            return EXIT_FAILED
        print(f"wrote {args.json}", file=out)
    if args.save:
        if not result.result.good and not args.force:
            out.flush()
            print(f"inclinometer {COMMAND}: not saved: the verdict is 'redo' "
                  f"({'; '.join(result.result.reasons)}). Redo the tour, or --force to save "
                  "it all the same", file=sys.stderr)
            return EXIT_FAILED
        try:
            saved, _ = save_to_profile(result, ProfileStore(args.profile_dir))
        except (ValueError, ProfileError) as exc:
            print(f"inclinometer {COMMAND}: not saved: {exc}", file=sys.stderr)
            return EXIT_USAGE
        except OSError as exc:
            print(f"inclinometer {COMMAND}: not saved: {exc.strerror or exc}", file=sys.stderr)
            return EXIT_FAILED
        print(f"saved in the profile of device {printable(result.unique_id)}: {saved}",
              file=out)
    out.flush()
    return 0
