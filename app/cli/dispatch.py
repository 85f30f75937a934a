"""The ``inclinometer`` command's parser and dispatcher.

The top-level parser knows each sub-command by name and one line of help only (:data:`COMMANDS`);
a sub-command's module (``app/cli/<module>.py``) is imported when that sub-command is parsed:
its ``add_arguments(parser)`` adds the options and ``parser.set_defaults(handler=run)`` names the
function that runs it. ``inclinometer --help`` and the GUI's start import no command.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from importlib import import_module
from typing import Any, NoReturn

from app.cli.errors import DEBUG_ENV, EXIT_USAGE, install_warning_format, run_guarded
from app.core.version import __version__

COMMANDS: tuple[tuple[str, str, str], ...] = (
    ("devices", "devices", "list the devices that can be connected"),
    ("evaluate", "evaluate",
     "score the orientation filters on sources with a known true orientation"),
    ("tune", "tune",
     "a parameter study of a filter over recordings, cross-validated by trial, on every "
     "core or a Dask cluster"),
    ("record", "record", "record a device to a CSV file, without the GUI"),
    ("replay", "replay", "run filters over a recording and export their angles to CSV"),
    ("export", "export",
     "export a recording to MCAP (ROS 2, Foxglove) or EuRoC/Kalibr CSV, ENU or NED"),
    ("simulate", "simulate",
     "serve an emulated NUCLEO board (link protocol v1) on a pseudo-terminal"),
    ("check-board", "check_board",
     "check a NUCLEO board running the Inclinometer firmware, rate by rate"),
    ("diagnose", "diagnose",
     "detect sensor faults (stuck, dead, spikes, noise, bias, ...) in a recording or a "
     "device's stream"),
    ("evaluate-faults", "evaluate_faults",
     "measure the fault detector as in the thesis: NDR and FDI with noise injected into one "
     "channel at a time, false alarms on clean data"),
    ("calibrate", "calibrate",
     "calibrate from a recorded six-face tour or free poses (headless wizard)"),
    ("allan", "allan",
     "Allan deviation of a static recording: noise density, bias instability, random walk"),
    ("calibrate-temperature", "calibrate_temperature",
     "fit gyro and accelerometer bias against temperature (a warm-up recording)"),
    ("calibrate-mag", "calibrate_mag",
     "calibrate the magnetometer from a recorded tour (hard iron, soft iron and its turn "
     "against the accelerometer)"),
    ("calibrate-gyro-scale", "calibrate_gyro_scale",
     "gyroscope scale and misalignment from whole turns (the accelerometer as the reference)"),
    ("joint", "joint", "the angle of a hinge between two sensors' recordings"),
    ("record-arm", "record_arm",
     "record a simulated measuring arm: one v1 file per sensor, with the truth"),
    ("import", "import_data",
     "import x-IMU3 CSV, EuRoC/Kalibr imu0.csv or any CSV (--map) as a recording"),
)
"""(sub-command, its module in app.cli, the line ``inclinometer --help`` shows for it)."""


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line (``inclinometer COMMAND: MESSAGE (see --help)``), exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: {message} (see {self.prog} --help)\n")


class _CommandParser(_Parser):
    """A sub-command's parser: its module adds the options when the sub-command is parsed."""

    def __init__(self, *args: Any, module: str = "", **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._module = module

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        if self._module:
            module, self._module = self._module, ""
            import_module(f"app.cli.{module}").add_arguments(self)
        return super().parse_known_args(args, namespace)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="inclinometer",
        description="LSM6DSOX tilt meter and IMU workbench. With no command, start the GUI.",
    )
    parser.add_argument("--version", action="version", version=f"inclinometer {__version__}")
    parser.add_argument(
        "--debug", action="store_true",
        help=f"show the Python traceback of an error (also {DEBUG_ENV}=1); without it an "
        "unexpected error prints one line and keeps the traceback in the crash log",
    )
    parser.add_argument(
        "--device", metavar="URL",
        help="device to connect at start (default: the last one used, or sim://interactive)",
    )
    parser.add_argument("--filter", metavar="NAME", help="orientation filter to start with")
    parser.add_argument(
        "--alarm", dest="gui_alarms", metavar="SPEC", action="append", default=[],
        help="start the window with this alarm (repeatable; it replaces the remembered "
             "alarms). SPEC as for 'record --alarm', e.g. --alarm 'tilt>2.0,hyst=0.2,delay=0.5' "
             "--alarm '|roll|>1'",
    )
    parser.add_argument(
        "--smoke-test", nargs="?", const="", metavar="PNG",
        help="check the GUI end to end (simulator, views, a sample replay, the compiled "
        "filters; offscreen without a screen), print one line and exit 0, or 1 with the "
        "reason; PNG: also save a screenshot",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND",
                                     parser_class=_CommandParser)
    for name, module, summary in COMMANDS:
        commands.add_parser(name, help=summary, module=module)
    return parser


def main(argv: list[str] | None = None,
         start_gui: Callable[[argparse.Namespace], int] | None = None) -> int:
    """Run the sub-command ``argv`` names through the one error path of
    :mod:`app.cli.errors` (bad input: one line and exit status 2). Without a sub-command (or
    with ``--smoke-test``) ``start_gui(args)`` runs: :func:`app.launcher.main` passes the
    window's; this package never imports the GUI."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    handler = getattr(args, "handler", None)
    if handler is None or args.smoke_test is not None:
        if start_gui is None:
            # Only an entry point installed before app.launcher existed calls this for the window.
            parser.error("give a COMMAND (the window starts from app.launcher:main; an install "
                         "made before it needs 'pip install -e .' again)")
        return start_gui(args)
    install_warning_format()
    return run_guarded(lambda: handler(args), argv, debug=args.debug)
