"""``inclinometer diagnose SOURCE [--seconds N] [--json]``: sensor fault events of a source.

SOURCE is a recording or a device URL. The table (or, with ``--json``, one JSON object per
line, printed at the moment of detection: ``{"t", "channel", "kind", "severity", "message"}``)
lists what :class:`app.core.faults.FaultDetector` declared; a clean source prints no events.
"""

from __future__ import annotations

import argparse
import sys

from app.cli.errors import CommandError, finite
from app.core.faults import FaultEvent
from app.core.recording.errors import RecordingError
from app.services.diagnosis import Diagnosis, diagnose_events
from drivers.errors import DeviceError

MAX_SECONDS = 7 * 86400.0
"""The longest ``--seconds`` (a week of device time)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``diagnose``; it runs :func:`diagnose_command`."""
    parser.set_defaults(handler=diagnose_command)
    parser.description = ("Run the sensor fault detector over SOURCE (a recording or a device "
                          "URL) and list the fault events (docs/fault-detection.md). Exit "
                          "status 0 whether or not there are faults, 2 when the source cannot "
                          "be read.")
    parser.add_argument("source", metavar="SOURCE", help="recording file or device URL")
    parser.add_argument("--seconds", type=float, default=None, metavar="N",
                        help="read at most N seconds (default: a whole recording, 10 s of a "
                             "device)")
    parser.add_argument("--json", action="store_true",
                        help="one JSON object per event and line, at detection time")


def _row(event: FaultEvent) -> str:
    return f"{event.t:10.3f}  {event.channel:7s} {event.kind:12s} {event.severity:8s} " \
           f"{event.message}"


def diagnose_command(args: argparse.Namespace) -> int:
    """Run ``diagnose``; returns the exit status."""
    if args.seconds is not None:
        finite(args.seconds, "--seconds", positive=True, maximum=MAX_SECONDS)
    result = Diagnosis()
    header_done = False
    try:
        for event in diagnose_events(args.source, args.seconds, result):
            if args.json:
                print(event.to_json(), flush=True)
                continue
            if not header_done:
                print(f"{'t (s)':>10s}  {'channel':7s} {'kind':12s} {'severity':8s} message")
                header_done = True
            print(_row(event), flush=True)
    except (RecordingError, DeviceError, OSError) as exc:
        raise CommandError(str(exc), command="diagnose") from None
    if not args.json:
        count = len(result.events)
        print(f"{args.source}: {result.samples} samples, {result.duration_s:.1f} s, "
              f"{count} fault event{'s' if count != 1 else ''}", file=sys.stderr)
    return 0
