"""``inclinometer devices``: list what can be connected."""

from __future__ import annotations

import argparse
import sys
from typing import TextIO

from drivers.registry import available_devices


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``devices`` has no options; it runs :func:`run`."""
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return list_devices()


def list_devices(out: TextIO | None = None) -> int:
    """One line per device (URL, kind, description); 1 when there is none."""
    out = sys.stdout if out is None else out
    devices = available_devices()
    if not devices:
        print("No devices found.", file=out)
        return 1
    width = max(len(d.url) for d in devices)
    for descriptor in devices:
        line = f"{descriptor.url:<{width}}  {descriptor.kind:<10}  {descriptor.description}"
        print(line, file=out)
    return 0
