"""The ``inclinometer`` command: the GUI by default, plus headless sub-commands.

``inclinometer``                    the GUI on the simulated device
``inclinometer --device URL``       the GUI on another device
``inclinometer devices``            list what can be connected
``inclinometer --version``
"""

from __future__ import annotations

import argparse
import sys

from app import __version__


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="inclinometer",
        description="LSM6DSOX tilt meter and IMU workbench. With no command, start the GUI.",
    )
    parser.add_argument("--version", action="version", version=f"inclinometer {__version__}")
    parser.add_argument(
        "--device", metavar="URL",
        help="device to connect at start (default: the last one used, or sim://interactive)",
    )
    parser.add_argument("--filter", metavar="NAME", help="orientation filter to start with")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    commands.add_parser("devices", help="list the devices that can be connected")
    return parser


def list_devices(out=sys.stdout) -> int:
    from drivers.registry import available_devices

    devices = available_devices()
    if not devices:
        print("No devices found.", file=out)
        return 1
    width = max(len(d.url) for d in devices)
    for descriptor in devices:
        line = f"{descriptor.url:<{width}}  {descriptor.kind:<10}  {descriptor.description}"
        print(line, file=out)
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "devices":
        return list_devices()
    if args.filter is not None:
        from app.core.filters import FILTERS

        if args.filter not in FILTERS:
            print(f"inclinometer: no filter {args.filter!r}; choose from {', '.join(FILTERS)}",
                  file=sys.stderr)
            return 2
    if args.device is not None:
        from drivers.errors import DeviceUrlError
        from drivers.registry import create_device

        try:
            create_device(args.device)
        except DeviceUrlError as exc:
            print(f"inclinometer: {exc}", file=sys.stderr)
            return 2
    from app.gui.application import run_gui

    return run_gui(args.device, args.filter)


if __name__ == "__main__":
    sys.exit(main())
