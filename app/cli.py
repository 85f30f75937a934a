"""The ``inclinometer`` command: the GUI by default, plus headless sub-commands.

``inclinometer``                    the GUI on the simulated device
``inclinometer --device URL``       the GUI on another device
``inclinometer devices``            list what can be connected
``inclinometer evaluate SOURCE``    score the orientation filters against a known truth
``inclinometer record ... OUT.csv`` record a device headless (see app/cli_recording.py)
``inclinometer replay IN.csv ...``  run filters over a recording, export their angles
``inclinometer simulate --pty``     an emulated NUCLEO board on a pseudo-terminal
``inclinometer check-board PORT``   put a NUCLEO board through its paces (app/cli_check.py)
``inclinometer --version``
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING, TextIO

from app import __version__
from app.cli_check import add_check_parser, check_command
from app.cli_recording import add_recording_parsers, record_command, replay_command
from app.cli_simulate import add_simulate_parser, simulate_command

if TYPE_CHECKING:
    from app.core.evaluation import FilterScore


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
    add_evaluate_parser(commands)
    add_recording_parsers(commands)
    add_simulate_parser(commands)
    add_check_parser(commands)
    return parser


EVALUATE_DEFAULT_SECONDS = 60.0


def add_evaluate_parser(commands: argparse._SubParsersAction) -> None:
    evaluate = commands.add_parser(
        "evaluate",
        help="score the orientation filters on a source with a known true orientation",
        description=(
            "Run orientation filters over a stream whose true orientation is known and print, "
            "per filter, the inclination error (RMSE and maximum, after the first seconds of "
            "convergence), the batch throughput and a flag (ok, NaN, diverged or error). "
            "The simulator's static sensor errors are compensated with their true values "
            "unless --raw is given."
        ),
    )
    evaluate.add_argument(
        "source", metavar="SOURCE",
        help="a simulator URL such as 'sim://translation?odr=208' (never paced in real time), "
        "a recording with reference columns (IN.csv; its recorded calibration is applied "
        "again unless --raw; always the whole recording), or 'scenarios': every simulator "
        "scenario with motion plus the hard cases (an hour at "
        "rest, 90 degrees of pitch, upside down, a stream with a gap)",
    )
    evaluate.add_argument(
        "--filter", dest="filters", metavar="NAME", action="extend", nargs="+",
        help="filter(s) to evaluate (repeatable; default: all)",
    )
    evaluate.add_argument(
        "--seconds", type=float, default=EVALUATE_DEFAULT_SECONDS, metavar="S",
        help="length of each stream (default %(default)g; the hour at rest is always an hour)",
    )
    evaluate.add_argument(
        "--skip", type=float, default=None, metavar="S",
        help="seconds at the start not scored while filters converge (default 2)",
    )
    evaluate.add_argument(
        "--raw", action="store_true",
        help="leave the sensor's static errors (bias, scale, cross-axis) uncompensated",
    )


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


def _format_score(score: FilterScore, width: int) -> str:
    def number(value: float, spec: str) -> str:
        return format(value, spec) if math.isfinite(value) else "-"

    rate = number(score.samples_per_s, ",.0f")
    flag = score.flag if not score.message else f"{score.flag}: {score.message}"
    return (f"  {score.name:<{width}}  {number(score.rmse_deg, '.3f'):>9}  "
            f"{number(score.max_deg, '.3f'):>9}  {rate:>14}  {flag}")


def evaluate_sources(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``evaluate`` sub-command: one table per source."""
    from app.core import evaluation
    from app.core.filters import FILTERS
    from drivers.errors import DeviceError
    from drivers.registry import scheme_of

    out = sys.stdout if out is None else out

    filters = args.filters or list(FILTERS)
    unknown = [name for name in filters if name not in FILTERS]
    if unknown:
        print(f"inclinometer: no filter {unknown[0]!r}; choose from {', '.join(FILTERS)}",
              file=sys.stderr)
        return 2
    if args.seconds <= 0:
        print("inclinometer: --seconds must be positive", file=sys.stderr)
        return 2
    skip = evaluation.DEFAULT_SKIP_S if args.skip is None else args.skip
    compensate = not args.raw
    errors = "static errors uncompensated" if args.raw else "static errors compensated"
    if args.source == "scenarios":
        sources = evaluation.standard_sources(args.seconds, compensate=compensate)
    elif scheme_of_recording(args.source):
        from app.core.recording.errors import RecordingError
        from drivers.replay import recording_path

        try:
            sources = [evaluation.recording_source(str(recording_path(args.source)),
                                                   recalibrate=compensate)]
        except (RecordingError, ValueError) as exc:
            print(f"inclinometer: {exc}", file=sys.stderr)
            return 2
        errors = "raw samples (--raw)" if args.raw else "recorded calibration"
    else:
        try:
            if scheme_of(args.source) != "sim":
                print(f"inclinometer: {args.source}: only sources that know their true "
                      "orientation can be evaluated (sim:// URLs)", file=sys.stderr)
                return 2
            sources = [evaluation.simulator_source(args.source, args.seconds,
                                                   compensate=compensate)]
        except DeviceError as exc:
            print(f"inclinometer: {exc}", file=sys.stderr)
            return 2
    width = max(6, *(len(name) for name in filters))
    for source in sources:
        stream = evaluation.concatenate_blocks(source.blocks())
        info = evaluation.stream_summary(stream)
        about = f" ({source.description})" if source.description else ""
        print(f"{source.label}{about}", file=out)
        print(f"  {info['duration_s']:.0f} s, {info['samples']} samples at "
              f"{info['rate_hz']:.4g} Hz, {info['gaps']} gap(s), {errors}, "
              f"first {skip:g} s not scored", file=out)
        print(f"  {'filter':<{width}}  {'RMSE deg':>9}  {'max deg':>9}  {'samples/s':>14}  flag",
              file=out)
        # A long stream (an hour-long recording) times well in one run; short ones need three.
        repeats = 1 if info["samples"] >= 1_000_000 else evaluation.DEFAULT_REPEATS
        for score in evaluation.evaluate(stream, filters, skip_s=skip, repeats=repeats):
            print(_format_score(score, width), file=out)
        print(file=out)
        out.flush()
    return 0


def scheme_of_recording(source: str) -> bool:
    """True when ``source`` names a recording (``replay://PATH`` or a path ending in .csv)."""
    from drivers.errors import DeviceUrlError
    from drivers.registry import scheme_of

    try:
        return scheme_of(source) == "replay"
    except DeviceUrlError:
        return False


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "devices":
        return list_devices()
    if args.command == "evaluate":
        return evaluate_sources(args)
    if args.command == "record":
        return record_command(args)
    if args.command == "replay":
        return replay_command(args)
    if args.command == "simulate":
        return simulate_command(args)
    if args.command == "check-board":
        return check_command(args)
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
