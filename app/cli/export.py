"""``inclinometer export REC --format mcap|euroc OUT [--frame enu|ned] [--overwrite]``: a
recording as MCAP (sensor_msgs/Imu with the filter's orientation, sensor_msgs/MagneticField) or as
EuRoC/Kalibr ``imu0.csv``. The work is :mod:`app.services.interop_export`'s.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TextIO

from app.cli.errors import EXIT_FAILED, CommandError, check_output_folder, check_regular_file
from app.core.interop.frames import FRAMES
from app.services.interop_export import (
    DEFAULT_FRAME_ID,
    FORMATS,
    ExportFailed,
    ExportRefused,
    ExportRequest,
    ExportSummary,
    export_recording,
)
from drivers.replay import recording_path


def add_arguments(export: argparse.ArgumentParser) -> None:
    """The options of ``export``; it runs :func:`run`."""
    export.set_defaults(handler=run)
    export.description = (
        "Export a recording for other tools. mcap: sensor_msgs/Imu (angular velocity, "
        "specific force and the orientation of the recording's filter, run over it as the "
        "replay does) and sensor_msgs/MagneticField (tesla) when the recording has a "
        "magnetometer, stamped with the recording's t in nanoseconds, with the recording's "
        "metadata; for Foxglove and ROS 2. euroc: Kalibr's imu0.csv (integer nanoseconds, "
        "rad/s, m/s^2) and a sidecar README stating the conventions. The samples are the "
        "calibrated ones (--raw: as measured). Every export states its axis convention.")
    export.add_argument("source", metavar="REC", help="a recording (or replay://PATH)")
    export.add_argument("out", metavar="OUT", help="the file to write (EuRoC: e.g. imu0.csv)")
    export.add_argument("--format", required=True, choices=FORMATS)
    export.add_argument("--frame", choices=FRAMES, default="enu",
                        help="axis convention (default %(default)s: ROS REP 103; ned: "
                             "north-east-down, body forward-right-down)")
    export.add_argument("--frame-id", default=DEFAULT_FRAME_ID, metavar="NAME",
                        help="the messages' header.frame_id (default %(default)s)")
    export.add_argument("--filter", metavar="NAME",
                        help="the filter for the orientation (default: the recorded one)")
    export.add_argument("--no-orientation", action="store_true",
                        help="mcap: give no orientation (orientation_covariance[0] = -1)")
    export.add_argument("--raw", action="store_true",
                        help="do not apply the calibration recorded in the file")
    export.add_argument("--overwrite", "--force", dest="overwrite", action="store_true",
                        help="replace OUT (and its sidecar) if it exists, never the recording")


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``export`` sub-command."""
    out = sys.stdout if out is None else out
    check_output_folder(args.out, "OUT")
    source = recording_path(args.source)
    check_regular_file(source)
    target = Path(args.out)
    request = ExportRequest(source, target, args.format, frame=args.frame,
                            frame_id=args.frame_id, filter=args.filter,
                            orientation=not args.no_orientation, raw=args.raw,
                            overwrite=args.overwrite)
    try:
        summary = export_recording(
            request, warn=lambda text: print(f"inclinometer: warning: {text}", file=sys.stderr))
    except ExportRefused as exc:
        raise CommandError(str(exc)) from None
    except ExportFailed as exc:
        raise CommandError(str(exc), EXIT_FAILED) from None
    print_summary(summary, out)
    if args.format == "euroc" and not (target.name.startswith("imu")
                                       and target.suffix == ".csv"):
        print("note: Kalibr's bag creator reads only files named imu*.csv", file=out)
    return 0


def print_summary(summary: ExportSummary, out: TextIO) -> None:
    """What was written: files, rows, time span, frame, filter and calibration."""
    applied = ("no calibration" if summary.calibration_name is None
               else f"calibration {summary.calibration_name!r}")
    what = f"{summary.rows} IMU samples"
    if summary.format == "mcap":
        what = f"{summary.rows} Imu and {summary.mag_rows} MagneticField messages"
    print(f"{summary.target}: {what}, t {summary.first_t_s:.3f}-{summary.last_t_s:.3f} s "
          f"({summary.duration_s:.1f} s), {summary.frame.upper()}, {applied}"
          + (f", orientation by {summary.filter_name}" if summary.format == "mcap" else ""),
          file=out)
    for extra in summary.files[1:]:
        print(f"{extra}: the conventions (frame, units, time axis, origin)", file=out)
