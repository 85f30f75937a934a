"""``inclinometer record-arm "sim://arm?..." --duration S DIR``: a simulated measuring arm,
one recording per sensor, with the truth (:mod:`app.services.arm_recordings`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TextIO

from app.cli.errors import EXIT_FAILED, CommandError, finite
from app.services.arm_recordings import record_arm
from drivers.errors import DeviceError


def add_arguments(arm: argparse.ArgumentParser) -> None:
    """The options of ``record-arm``; it runs :func:`record_arm_command`."""
    arm.set_defaults(handler=record_arm_command)
    arm.description = (
        "Run every sensor of one sim://arm (same seed: one arm) as fast as possible and "
        "write DIR/sensor0.csv, sensor1.csv, ...: raw samples, the true orientation and, "
        "from sensor 1 on, joint_ref_deg, the true angle of the hinge between sensor K-1 "
        "and K; the true axes are in the 'arm' metadata key."
    )
    arm.add_argument("url", metavar="URL", help="a sim://arm URL, e.g. "
                     "'sim://arm?links=3&seed=4&odr=208' (sensor= is set for each file)")
    arm.add_argument("directory", metavar="DIR", help="where to write the files")
    arm.add_argument("--duration", type=float, default=180.0, metavar="S",
                     help="seconds of device time (default %(default)g)")
    arm.add_argument("--overwrite", "--force", dest="force", action="store_true",
                     help="replace existing files")


def record_arm_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``record-arm`` sub-command."""
    out = sys.stdout if out is None else out
    finite(args.duration, "--duration", positive=True, maximum=86400.0)
    try:
        written = record_arm(args.url, args.duration, Path(args.directory),
                             overwrite=args.force)
    except (ValueError, DeviceError) as exc:
        raise CommandError(str(exc), command="record-arm") from None
    except OSError as exc:
        raise CommandError(exc.strerror or str(exc), EXIT_FAILED, command="record-arm") from None
    for item in written:
        print(f"{item.path}: sensor {item.sensor}, {item.samples} samples", file=out)
    return 0
