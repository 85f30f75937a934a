"""The ``inclinometer`` program: the window by default, or a sub-command of :mod:`app.cli`.

``inclinometer``                    the GUI on the simulated device
``inclinometer --device URL``       the GUI on another device
``inclinometer --alarm SPEC ...``   the GUI with these alarms (as ``record --alarm``)
``inclinometer --smoke-test [PNG]`` check the GUI end to end, one line
``inclinometer COMMAND ...``        a headless sub-command (``inclinometer --help`` lists them)
``inclinometer --version``
"""

from __future__ import annotations

import argparse
import sys

from app import cli


def main(argv: list[str] | None = None) -> int:
    """The console entry point (pyproject's ``inclinometer``, ``python -m app``)."""
    return cli.main(argv, start_gui=start_gui)


def start_gui(args: argparse.Namespace) -> int:
    """Run the smoke test, or check ``--filter``, ``--device`` and ``--alarm`` and start the
    window. The GUI's modules are imported here, not at start: a sub-command never loads Qt's
    widgets."""
    if args.smoke_test is not None:
        from app.gui.smoke_test import run_smoke_test

        return run_smoke_test(args.smoke_test or None)
    if args.filter is not None:
        from app.core.filters import FILTERS, ONLINE_FILTERS

        if args.filter in FILTERS and args.filter not in ONLINE_FILTERS:
            print(f"inclinometer: {args.filter!r} is an offline filter (it needs the whole "
                  f"recording); use: inclinometer replay IN.csv --filter {args.filter} "
                  "--out ANGLES.csv", file=sys.stderr)
            return 2
        if args.filter not in FILTERS:
            print(f"inclinometer: no filter {args.filter!r}; choose from "
                  f"{', '.join(ONLINE_FILTERS)}", file=sys.stderr)
            return 2
    if args.device is not None:
        from drivers.errors import DeviceUrlError
        from drivers.registry import create_device

        try:
            create_device(args.device)
        except DeviceUrlError as exc:
            print(f"inclinometer: {exc}", file=sys.stderr)
            return 2
    alarms = None
    if args.gui_alarms:
        from app.core.alarms import alarms_from_specs

        try:
            alarms = alarms_from_specs(args.gui_alarms)
        except ValueError as exc:
            print(f"inclinometer: --alarm: {exc}", file=sys.stderr)
            return 2
    from app.gui.application import run_gui

    return run_gui(args.device, args.filter, alarms)


if __name__ == "__main__":
    sys.exit(main())
