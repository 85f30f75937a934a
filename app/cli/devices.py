"""``inclinometer devices [--options SCHEME] [--json]``: list what can be connected, or a
driver's URL options."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TextIO

from app.cli.errors import EXIT_USAGE
from drivers.registry import available_devices


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``devices``; it runs :func:`run`."""
    parser.add_argument("--options", metavar="SCHEME",
                        help="list a driver's URL options instead: sim, serial, port, text, "
                             "lsm6dsox, replay, or a URL (sim://static: with its scenario's)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    if args.options:
        return list_device_options(args.options, as_json=args.json)
    return list_devices(as_json=args.json)


def list_devices(out: TextIO | None = None, *, as_json: bool = False) -> int:
    """One line per device (URL, kind, description); 1 when there is none."""
    out = sys.stdout if out is None else out
    devices = available_devices()
    if as_json:
        rows = [{"url": d.url, "kind": d.kind, "description": d.description} for d in devices]
        print(json.dumps(rows, indent=2), file=out)
        return 0 if devices else 1
    if not devices:
        print("No devices found.", file=out)
        return 1
    width = max(len(d.url) for d in devices)
    for descriptor in devices:
        line = f"{descriptor.url:<{width}}  {descriptor.kind:<10}  {descriptor.description}"
        print(line, file=out)
    return 0


def list_device_options(name: str, *, as_json: bool = False, out: TextIO | None = None) -> int:
    """A driver's URL options as a table (or JSON); 2 for an unknown scheme."""
    from app.services.devices import device_options, device_options_table
    from drivers.errors import DeviceError

    try:
        text = (json.dumps(device_options(name), indent=2) + "\n" if as_json
                else device_options_table(name))
    except DeviceError as exc:
        print(f"inclinometer: devices --options: {exc}", file=sys.stderr)
        return EXIT_USAGE
    (out or sys.stdout).write(text)
    return 0
