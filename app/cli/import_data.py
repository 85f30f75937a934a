"""``inclinometer import FILE OUT.csv``: another tool's IMU data as a format v1 recording.

Reads x-IMU3's data logger CSV (with x-io's ``ximu3csv``), a EuRoC/Kalibr ``imu0.csv``, or any
CSV through ``--map``; the format is detected from the content. The recording's header says
where it came from (``imported_from``: format, file, sha256, tool). Nothing is half-written:
the file appears complete or not at all, and an existing OUT is kept unless ``--overwrite``.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from typing import TextIO

from app.cli.errors import CommandError
from app.core.interop.imported import ImportInputError, write_recording
from app.core.interop.importing import FORMATS, read_any
from app.core.safe_output import OutputRefused, write_error_message


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``import``; it runs :func:`import_command`."""
    parser.set_defaults(handler=import_command)
    parser.description = (
        "Import IMU data from another tool as an inclinometer recording (format v1), to replay "
        "and compare filters on it: x-IMU3's logged CSV (a data logger folder, a device folder "
        "or its Inertial.csv), a EuRoC/Kalibr imu0.csv, or any CSV through --map. Units are "
        "converted to the format's (m/s^2, rad/s, uT, s).")
    parser.add_argument("file", metavar="FILE", help="the file or x-IMU3 folder to import")
    parser.add_argument("out", metavar="OUT.csv", help="the recording to write (.gz: gzip)")
    parser.add_argument("--format", dest="import_format", choices=FORMATS,
                        help="the input's format (default: detected from its content; "
                             "--map alone means csv)")
    parser.add_argument("--map", dest="mapping", default="", metavar="SPEC",
                        help="a generic CSV's columns: TARGET=COLUMN:UNIT,... e.g. "
                             "t=time:s,ax=acc_x:g,ay=acc_y:g,az=acc_z:g,gx=gyro_x:dps,"
                             "gy=gyro_y:dps,gz=-gyro_z:dps (COLUMN a header name or #N; a "
                             "leading - flips the sign; optional mx,my,mz in uT/nT/mT/G, temp "
                             "in degC/K)")
    parser.add_argument("--delimiter", default=",", help="a generic CSV's separator "
                                                          "(default ,)")
    parser.add_argument("--device", dest="import_device", default="", metavar="NAME",
                        help="x-IMU3: which device of a data logger folder (part of its "
                             "folder's name, e.g. its serial number)")
    parser.add_argument("--mag-au-ut", type=float, default=None, metavar="UT",
                        help="x-IMU3: the field in uT that its magnetometer's 1 a.u. stands "
                             "for (the field where it was calibrated, about 50); without it an "
                             "a.u. magnetometer is left out")
    parser.add_argument("--note", default="", help="free text stored in the recording")
    parser.add_argument("--overwrite", "--force", dest="overwrite", action="store_true",
                        help="replace OUT.csv if it exists")


def import_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Read, convert and write; one line for what was written."""
    out = out or sys.stdout
    if args.mag_au_ut is not None and not 0 < args.mag_au_ut < 1e4:
        raise CommandError(f"--mag-au-ut {args.mag_au_ut}: give the field in uT (about 50)")
    if args.mapping and args.import_format not in (None, "csv"):
        raise CommandError("--map is for --format csv")
    try:
        data = read_any(args.file, args.import_format, mapping=args.mapping,
                        delimiter=args.delimiter, device=args.import_device,
                        mag_au_ut=args.mag_au_ut)
    except ImportInputError as exc:
        raise CommandError(str(exc)) from None
    for text in data.warnings:
        warnings.warn(text, stacklevel=1)
    try:
        write_recording(data, args.out, inputs=[args.file], overwrite=args.overwrite,
                        note=args.note, option="OUT")
    except OutputRefused as exc:
        raise CommandError(str(exc)) from None
    except OSError as exc:
        raise CommandError(write_error_message(exc, args.out), code=1) from None
    extras = [name for name, present in (("magnetometer", data.mag_ut is not None),
                                         ("temperature", data.temp_degc is not None)) if present]
    print(f"imported {len(data)} samples ({data.duration_s:.3f} s at {data.rate_hz:.2f} Hz"
          f"{', with ' + ' and '.join(extras) if extras else ''}) from "
          f"{data.origin['format']} {args.file} into {args.out}", file=out)
    return 0
