"""``inclinometer replay IN.csv [--filter NAME...] [--param FILTER.NAME=VALUE...] --out
ANGLES.csv``: run filters over a recording as fast as possible, exactly as live, and export
their angles. The work is :mod:`app.services.replay_export`'s; this prints its summary.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TextIO

from app.cli.errors import EXIT_FAILED, CommandError, check_output_folder, check_regular_file
from app.cli.evaluate import HEADING_NOTE, heading_cell
from app.cli.filter_params import add_param_argument, parse_filter_parameters
from app.core.scoring import DEFAULT_SKIP_S, SCORE_COLUMN
from app.services.replay_export import (
    MAX_BLOCK,
    ReplayFailed,
    ReplayRefused,
    ReplayRequest,
    ReplaySummary,
    replay_recording,
)
from drivers.replay import recording_path


def add_arguments(replay: argparse.ArgumentParser) -> None:
    """The options of ``replay``; it runs :func:`run`."""
    replay.set_defaults(handler=run)
    replay.description = (
        "Run orientation filters over a recording as fast as possible, through the same "
        "stages as live (the recorded calibration, the recorded device blocks, the "
        "recorded filter parameters), and write t, then per filter roll, pitch, tilt, "
        "direction (degrees) and the quaternion (sensor-to-earth; a 9-axis filter's is ENU "
        "with y toward magnetic north); with reference columns also the reference angles "
        "and each filter's inclination error, and with a magnetometer its heading and total "
        "error."
    )
    replay.add_argument("source", metavar="IN.csv", help="a recording (or replay://PATH)")
    replay.add_argument("--filter", dest="filters", metavar="NAME", nargs="+", action="extend",
                        help="filter(s) to run, or 'all' (default: the recorded filter)")
    replay.add_argument("--out", required=True, metavar="ANGLES.csv", help="the file to write")
    replay.add_argument("--overwrite", action="store_true",
                        help="replace ANGLES.csv if it exists (never the recording itself)")
    replay.add_argument("--raw", action="store_true",
                        help="do not apply the calibration recorded in the file")
    replay.add_argument("--block", type=int, metavar="N",
                        help="process blocks of N samples instead of the recorded device "
                             "blocks: faster, but VQF then differs from live in the last bits")
    add_param_argument(replay)


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``replay`` sub-command."""
    out = sys.stdout if out is None else out
    if args.block is not None and not 1 <= args.block <= MAX_BLOCK:
        raise CommandError(f"--block must be from 1 to {MAX_BLOCK}")
    check_output_folder(args.out, "--out")
    try:
        parameters = parse_filter_parameters(getattr(args, "params", None))
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    source = recording_path(args.source)
    check_regular_file(source)
    request = ReplayRequest(source, target=Path(args.out), filters=args.filters,
                            parameters=parameters, raw=args.raw, block=args.block,
                            overwrite=args.overwrite)
    try:
        summary = replay_recording(
            request, warn=lambda text: print(f"inclinometer: warning: {text}", file=sys.stderr),
            note=lambda text: print(text, file=out))
    except ReplayRefused as exc:
        raise CommandError(str(exc)) from None
    except ReplayFailed as exc:
        raise CommandError(str(exc), EXIT_FAILED) from None
    print_summary(summary, out)
    print_fault_events(summary, out)
    return 0


def print_fault_events(summary: ReplaySummary, out: TextIO) -> None:
    """The fault detector's verdict on the recording (``diagnose`` prints every event)."""
    events = [e for e in summary.fault_events if e.channel != "link"]
    if not events:
        print("  fault detector: no sensor fault", file=out)
        return
    print(f"  fault detector: {len(events)} event(s) (inclinometer diagnose lists them)",
          file=out)
    for event in events[:5]:
        print(f"    t = {event.t:.2f} s  {event.channel} {event.kind}: {event.message}", file=out)


def print_summary(summary: ReplaySummary, out: TextIO) -> None:
    """The file, which rows were scored, a line per filter (final angles, and RMSE and
    maximum when the recording has a reference)."""
    applied = ("no calibration" if summary.calibration_name is None
               else f"calibration {summary.calibration_name!r}")
    rows = summary.rows
    print(f"{summary.target}: {rows} rows, {summary.duration_s:.1f} s, {applied}", file=out)
    scored = summary.scored_rows
    if scored is not None:
        rule = (f"rows with {SCORE_COLUMN} == 1" if summary.masked
                else f"after the first {DEFAULT_SKIP_S:g} s")
        print(f"  inclination error scored {rule} with a reference: {scored} of {rows} rows",
              file=out)
    width = max(6, *(len(line.name) for line in summary.filters))
    header = f"  {'filter':<{width}}  {'final roll':>10}  {'final pitch':>11}"
    split = any(line.errors is not None and "heading_rmse_deg" in line.errors
                and math.isfinite(line.errors["heading_rmse_deg"]) for line in summary.filters)
    if scored is not None:
        header += f"  {'RMSE deg':>9}  {'max deg':>9}"
        if split:
            header += f"  {'heading deg':>11}  {'total deg':>11}"
    print(header, file=out)
    for line in summary.filters:
        text = f"  {line.name:<{width}}  {line.final_roll_deg:10.3f}  {line.final_pitch_deg:11.3f}"
        if line.errors is not None:
            rmse, worst = line.errors["rmse_deg"], line.errors["max_deg"]
            text += (f"  {rmse:9.3f}  {worst:9.3f}" if math.isfinite(rmse)
                     else f"  {'-':>9}  {'-':>9}")
            if split:
                text += "".join(f"  {heading_cell(line.errors[key], line.magnetic):>11}"
                                for key in ("heading_rmse_deg", "total_rmse_deg"))
        print(text, file=out)
    if split:
        print("  RMSE of inclination, heading and total error (earth frame ENU, y toward "
              "magnetic north)", file=out)
        if any(not line.magnetic for line in summary.filters):
            print(f"  {HEADING_NOTE}", file=out)
