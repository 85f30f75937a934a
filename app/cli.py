"""The ``inclinometer`` command: the GUI by default, plus headless sub-commands.

``inclinometer``                    the GUI on the simulated device
``inclinometer --device URL``       the GUI on another device
``inclinometer --alarm SPEC ...``   the GUI with these alarms (as ``record --alarm``)
``inclinometer devices``            list what can be connected
``inclinometer evaluate SOURCE...`` score the orientation filters against a known truth
``inclinometer record ... OUT.csv`` record a device headless (see app/cli_recording.py)
``inclinometer replay IN.csv ...``  run filters over a recording, export their angles
``inclinometer simulate --pty``     an emulated NUCLEO board on a pseudo-terminal
``inclinometer check-board PORT``   put a NUCLEO board through its paces (app/cli_check.py)
``inclinometer calibrate|allan|calibrate-temperature ...``
                                    the calibration lab, headless (app/cli_calibration.py)
``inclinometer joint A.csv B.csv --out J.csv``
                                    a hinge's angle between two sensors (app/cli_joint.py)
``inclinometer record-arm URL DIR`` a simulated measuring arm, one recording per sensor
``inclinometer --version``

Bad input ends in one line ``inclinometer: MESSAGE`` and exit status 2 (app/cli_errors.py);
``inclinometer --debug COMMAND ...`` or ``INCLINOMETER_DEBUG=1`` shows Python's tracebacks.
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TextIO

from app import __version__
from app.cli_calibration import CALIBRATION_COMMANDS, add_calibration_parsers, calibration_command
from app.cli_check import add_check_parser, check_command
from app.cli_diagnose import add_diagnose_parser, diagnose_command
from app.cli_errors import DEBUG_ENV, EXIT_USAGE, CommandError, check_output_folder, finite
from app.cli_faults import add_evaluate_faults_parser, evaluate_faults_command
from app.cli_joint import add_joint_parser, joint_command, record_arm_command
from app.cli_magnetometer import add_parser as add_magnetometer_parser
from app.cli_magnetometer import run as magnetometer_command
from app.cli_recording import (
    add_param_argument,
    add_recording_parsers,
    check_recorded_calibration,
    record_command,
    replay_command,
)
from app.cli_simulate import add_simulate_parser, simulate_command
from app.core.safe_output import (
    OutputRefused,
    check_output,
    write_error_message,
    write_output,
)

if TYPE_CHECKING:
    from app.core.evaluation import FilterScore, SourceResult, StreamSource


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
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    commands.add_parser("devices", help="list the devices that can be connected")
    add_evaluate_parser(commands)
    add_recording_parsers(commands)
    add_simulate_parser(commands)
    add_check_parser(commands)
    add_diagnose_parser(commands)
    add_evaluate_faults_parser(commands)
    add_calibration_parsers(commands)
    add_joint_parser(commands)
    add_magnetometer_parser(commands)
    return parser


EVALUATE_DEFAULT_SECONDS = 60.0
MAX_SECONDS = 86400.0
"""The longest simulator stream ``evaluate --seconds`` makes (and the longest --skip)."""
MAX_REPEATS = 1000
GLOB_CHARACTERS = "*?["


def add_evaluate_parser(commands: argparse._SubParsersAction) -> None:
    evaluate = commands.add_parser(
        "evaluate",
        help="score the orientation filters on sources with a known true orientation",
        description=(
            "Run orientation filters over streams whose true orientation is known and print, "
            "per filter, the inclination error (RMSE and maximum), the batch throughput and a "
            "flag (ok, NaN, diverged or error). Scored are the rows after the first seconds "
            "of convergence (--skip) or, in a recording with a 'movement' column, exactly "
            "the rows with movement == 1; rows without a reference never count. With several "
            "sources, a table of RMSE per source and filter follows, with each filter's mean "
            "over the sources. The simulator's static sensor errors are compensated with "
            "their true values unless --raw is given."
        ),
    )
    evaluate.add_argument(
        "sources", metavar="SOURCE", nargs="+",
        help="one or more of: a simulator URL such as 'sim://translation?odr=208' (never "
        "paced in real time); a recording with reference columns (IN.csv or replay://IN.csv; "
        "its recorded calibration is applied again unless --raw; always the whole "
        "recording), or a glob of them ('DIR/*.csv', quoted or not); 'scenarios': every "
        "simulator scenario with motion plus the hard cases (an hour at rest, 90 degrees of "
        "pitch, upside down, a stream with a gap)",
    )
    evaluate.add_argument(
        "--filter", dest="filters", metavar="NAME", action="extend", nargs="+",
        help="filter(s) to evaluate (repeatable; default: all)",
    )
    add_param_argument(evaluate)
    evaluate.add_argument(
        "--seconds", type=float, default=EVALUATE_DEFAULT_SECONDS, metavar="S",
        help="length of each simulator stream (default %(default)g; the hour at rest is "
        "always an hour)",
    )
    evaluate.add_argument(
        "--skip", type=float, default=None, metavar="S",
        help="seconds at the start not scored while filters converge (default 2; not used "
        "for a recording with a 'movement' column)",
    )
    evaluate.add_argument(
        "--raw", action="store_true",
        help="leave the sensor's static errors (bias, scale, cross-axis) uncompensated",
    )
    evaluate.add_argument(
        "--repeats", type=int, default=None, metavar="N",
        help="runs per filter and source, the throughput being the fastest's (default: 3, "
        "1 for a million samples or more); the errors never depend on it",
    )
    evaluate.add_argument(
        "--json", metavar="FILE",
        help="also write every figure as JSON to FILE ('-': to stdout, the tables then go "
        "to stderr)",
    )
    evaluate.add_argument("--overwrite", action="store_true",
                          help="replace the --json FILE if it exists")
    evaluate.add_argument(
        "--per-source", action=argparse.BooleanOptionalAction, default=None,
        help="print each source's full table (RMSE, maximum, throughput, flag); default: "
        "when a single SOURCE that is not a glob is given",
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
    rate = _number(score.samples_per_s, ",.0f")
    flag = score.flag if not score.message else f"{score.flag}: {score.message}"
    return (f"  {score.name:<{width}}  {_number(score.rmse_deg, '.3f'):>9}  "
            f"{_number(score.max_deg, '.3f'):>9}  {rate:>14}  {flag}")


def _number(value: float, spec: str) -> str:
    return format(value, spec) if math.isfinite(value) else "-"


class _Usage(CommandError):
    """A source or option the command cannot use: message for the user, exit 2."""


@dataclass
class _Pending:
    """A source named on the command line, checked but not read yet (recordings are read one
    at a time, just before they are evaluated)."""

    label: str
    short: str
    treatment: str
    """How the samples are prepared, in words (calibration)."""
    load: Callable[[], StreamSource]
    path: Path | None = None
    """The recording's file (None for a simulated source)."""


def _recording_pending(path: Path, label: str, compensate: bool) -> _Pending:
    """Check a recording's head now (format, columns, reference); read it later."""
    from app.core import evaluation
    from app.core.recording.errors import RecordingError
    from app.core.recording.format import REFERENCE_COLUMNS
    from app.core.recording.reader import read_metadata, read_recording

    if not path.is_file():
        raise _Usage(f"{label}: no such file" if not path.exists() else f"{label}: not a file")
    try:
        metadata, header = read_metadata(path)
    except RecordingError as exc:
        raise _Usage(str(exc)) from None
    except OSError as exc:
        raise _Usage(f"{label}: cannot read the recording: {exc.strerror or exc}") from None
    if compensate:
        check_recorded_calibration(metadata, path)
    if not all(column in header for column in REFERENCE_COLUMNS):
        try:  # a broken row says more than the missing columns: read the file for it
            read_recording(path)
        except RecordingError as exc:
            raise _Usage(str(exc)) from None
        raise _Usage(f"{path}: the recording has no reference orientation (columns qw, qx, "
                     "qy, qz) to compare the filters with")
    treatment = "recorded calibration" if compensate else "raw samples (--raw)"
    short = path.stem if path.suffix.lower() == ".csv" else path.name

    def load() -> StreamSource:
        return evaluation.recording_source(str(path), recalibrate=compensate, label=label)

    return _Pending(label, short, treatment, load, path)


def resolve_sources(items: list[str], seconds: float, compensate: bool) -> list[_Pending]:
    """The sources named by ``items`` (scenarios, sim:// URLs, recordings, globs), in order.

    Raises :class:`_Usage` for a URL that cannot be evaluated, a file that is not a recording
    with a reference, or a glob that matches nothing. A file named twice is evaluated once.
    """
    from app.services import simulation
    from drivers.errors import DeviceError, DeviceUrlError
    from drivers.registry import scheme_of
    from drivers.replay import recording_path

    errors = "static errors uncompensated" if not compensate else "static errors compensated"
    pending: list[_Pending] = []
    seen: set[Path] = set()

    def add_recording(path: Path, label: str) -> None:
        key = path.resolve()
        if key not in seen:
            seen.add(key)
            pending.append(_recording_pending(path, label, compensate))

    for item in items:
        if item == "scenarios":
            for source in simulation.standard_sources(seconds, compensate=compensate):
                pending.append(_Pending(source.label, source.label, errors,
                                        lambda source=source: source))
            continue
        if "://" in item:
            try:
                scheme = scheme_of(item)
            except DeviceUrlError as exc:
                raise _Usage(str(exc)) from None
            if scheme == "replay":
                add_recording(recording_path(item), item)
                continue
            if scheme != "sim":
                raise _Usage(f"{item}: only sources that know their true orientation can be "
                             "evaluated (sim:// URLs and recordings with reference columns)")
            try:
                source = simulation.simulator_source(item, seconds, compensate=compensate)
            except DeviceError as exc:
                raise _Usage(str(exc)) from None
            pending.append(_Pending(item, item, errors, lambda source=source: source))
            continue
        if any(c in item for c in GLOB_CHARACTERS) and not Path(item).exists():
            matches = sorted(glob.glob(os.path.expanduser(item)))
            if not matches:
                raise _Usage(f"{item}: no file matches")
            for match in matches:
                add_recording(Path(match), match)
            continue
        if item.strip().lower().endswith(".csv") or Path(item).exists():
            add_recording(Path(item), item)
            continue
        try:
            scheme_of(item)  # a bare serial port, or not a URL at all
        except DeviceUrlError:
            raise _Usage(f"{item}: no such file, and not a device URL (give a recording, a "
                         "glob of recordings, a sim:// URL or 'scenarios')") from None
        raise _Usage(f"{item}: only sources that know their true orientation can be "
                     "evaluated (sim:// URLs and recordings with reference columns)")
    return pending


def _print_details(
    result: SourceResult, treatment: str, skip: float, width: int, out: TextIO
) -> None:
    about = f" ({result.description})" if result.description else ""
    print(f"{result.label}{about}", file=out)
    if result.masked:
        scored = f"scored: {result.scoring} ({result.scored_samples} samples)"
    else:
        scored = f"first {skip:g} s not scored"
    print(f"  {result.duration_s:.0f} s, {result.samples} samples at {result.rate_hz:.4g} Hz, "
          f"{result.gaps} gap(s), {treatment}, {scored}", file=out)
    print(f"  {'filter':<{width}}  {'RMSE deg':>9}  {'max deg':>9}  {'samples/s':>14}  flag",
          file=out)
    for score in result.scores:
        print(_format_score(score, width), file=out)
    print(file=out)


class _Matrix:
    """The table of RMSE per source (rows) and filter (columns), printed row by row."""

    def __init__(self, labels: list[str], filters: list[str], out: TextIO) -> None:
        self.filters = filters
        self.out = out
        self.label_width = max(6, *(len(label) for label in labels))
        self.widths = [max(7, len(name)) for name in filters]
        self.flagged: list[str] = []

    def header(self) -> None:
        print("Inclination error RMSE (degrees) per source and filter", file=self.out)
        cells = "".join(f" {name:>{w}} " for name, w in zip(self.filters, self.widths,
                                                               strict=True))
        print(f"{'source':<{self.label_width}}  {'scored':>7}{cells}".rstrip(), file=self.out)

    def row(self, label: str, result: SourceResult) -> None:
        cells = []
        for name, width in zip(self.filters, self.widths, strict=True):
            score = result.score(name)
            value = math.nan if score is None else score.rmse_deg
            mark = " "
            if score is not None and score.flag != "ok":
                mark = "!"
                why = score.flag if not score.message else f"{score.flag}: {score.message}"
                self.flagged.append(f"{name} on {label}: {why}")
            cells.append(f" {_number(value, '.3f'):>{width}}{mark}")
        print(f"{label:<{self.label_width}}  {result.scored_samples:>7}{''.join(cells)}"
              .rstrip(), file=self.out)
        self.out.flush()

    def footer(self, summary: dict[str, dict[str, float | int]], sources: int) -> None:
        for key, title in (("mean_rmse_deg", f"mean of {sources}"),
                           ("worst_rmse_deg", "worst")):
            cells = "".join(
                f" {_number(float(summary[name][key]), '.3f'):>{w}} "
                for name, w in zip(self.filters, self.widths, strict=True))
            print(f"{title:<{self.label_width}}  {'':>7}{cells}".rstrip(), file=self.out)
        for line in self.flagged:
            print(f"  ! {line}", file=self.out)


def evaluate_sources(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``evaluate`` sub-command: per source a table, and with several a summary table."""
    from app.cli_recording import check_parameters_for, parse_filter_parameters
    from app.core import evaluation
    from app.core.filters import FILTERS
    from app.core.recording.errors import RecordingError

    out = sys.stdout if out is None else out
    filters = list(dict.fromkeys(args.filters or list(FILTERS)))
    unknown = [name for name in filters if name not in FILTERS]
    if unknown:
        print(f"inclinometer: no filter {unknown[0]!r}; choose from {', '.join(FILTERS)}",
              file=sys.stderr)
        return 2
    try:
        parameters = parse_filter_parameters(args.params)
        check_parameters_for(parameters, filters)
        finite(args.seconds, "--seconds", positive=True, maximum=MAX_SECONDS)
        if args.skip is not None:
            finite(args.skip, "--skip", minimum=0.0, maximum=MAX_SECONDS)
        if args.repeats is not None and not 1 <= args.repeats <= MAX_REPEATS:
            raise _Usage(f"--repeats must be from 1 to {MAX_REPEATS}")
        if args.json not in (None, "-"):
            check_output_folder(args.json, "--json")
        pending = resolve_sources(args.sources, args.seconds, compensate=not args.raw)
        inputs = [item.path for item in pending]
        if args.json not in (None, "-"):
            check_output(args.json, inputs=inputs, overwrite=args.overwrite, option="--json")
    except (_Usage, ValueError, OutputRefused) as exc:
        print(f"inclinometer: {exc}", file=sys.stderr)
        return 2
    skip = evaluation.DEFAULT_SKIP_S if args.skip is None else args.skip
    if args.json == "-":
        out = sys.stderr  # stdout carries the JSON alone
    single = len(args.sources) == 1 and not any(c in args.sources[0] for c in GLOB_CHARACTERS)
    details = args.per_source if args.per_source is not None else (single or len(pending) == 1)
    matrix = _Matrix([p.short for p in pending], filters, out) if len(pending) > 1 else None
    if parameters:
        chosen = ", ".join(f"{f}.{k}={v}" for f, values in parameters.items()
                           for k, v in values.items())
        print(f"parameters: {chosen}", file=out)
    if matrix is not None and not details:
        matrix.header()
    width = max(6, *(len(name) for name in filters))
    results: list[SourceResult] = []
    for item in pending:
        try:
            source = item.load()
            result = evaluation.evaluate_source(source, filters, skip_s=skip,
                                                repeats=args.repeats, parameters=parameters)
        except (RecordingError, ValueError) as exc:
            print(f"inclinometer: {exc}", file=sys.stderr)
            return 2
        results.append(result)
        if details:
            _print_details(result, item.treatment, skip, width, out)
        elif matrix is not None:
            matrix.row(item.short, result)
        out.flush()
    summary = evaluation.summarize(results)
    if matrix is not None:
        if details:
            matrix.header()
            for item, result in zip(pending, results, strict=True):
                matrix.row(item.short, result)
        matrix.footer(summary, len(results))
        rules = sorted({r.scoring for r in results})
        print(f"scored: {'; '.join(rules)}; rows without a reference never count", file=out)
    notes = [f"{name}: {FILTERS[name].title}, kept as a reference implementation, not for "
             "measurement" for name in filters if FILTERS[name].reference_only]
    for note in notes:
        print(note, file=out)
    out.flush()
    if args.json is not None:
        settings = {
            "sources": list(args.sources), "skip_s": skip, "seconds": args.seconds,
            "compensated": not args.raw, "repeats": args.repeats, "app_version": __version__,
        }
        document = evaluation.results_json(results, settings=settings, filters=filters,
                                           parameters=parameters)
        text = json.dumps(document, indent=2) + "\n"
        if args.json == "-":
            sys.stdout.write(text)
            sys.stdout.flush()
        else:
            try:
                write_output(args.json, text, inputs=inputs, overwrite=args.overwrite,
                             option="--json")
            except OSError as exc:  # OutputRefused, or a full disk: the old file is intact
                print(f"inclinometer: {write_error_message(exc, args.json, '--json')}",
                      file=sys.stderr)
                return 1
    return 0


def scheme_of_recording(source: str) -> bool:
    """True when ``source`` names a recording (``replay://PATH`` or a path ending in .csv)."""
    from drivers.errors import DeviceUrlError
    from drivers.registry import scheme_of

    try:
        return scheme_of(source) == "replay"
    except DeviceUrlError:
        return False


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line (``inclinometer COMMAND: MESSAGE (see --help)``), exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: {message} (see {self.prog} --help)\n")


def main(argv: list[str] | None = None) -> int:
    """The ``inclinometer`` command: every sub-command runs through the one error path of
    :mod:`app.cli_errors` (bad input: one line and exit status 2)."""
    from app.cli_errors import install_warning_format, run_guarded

    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    if args.smoke_test is not None:
        from app.gui.smoke_test import run_smoke_test

        return run_smoke_test(args.smoke_test or None)
    command = _COMMANDS.get(args.command)
    if command is None and args.command in CALIBRATION_COMMANDS:
        command = calibration_command
    if command is not None:
        install_warning_format()
        return run_guarded(lambda: command(args), argv, debug=args.debug)
    return _start_gui(args)


def _start_gui(args: argparse.Namespace) -> int:
    """Check ``--filter`` and ``--device``, then start the window."""
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


_COMMANDS: dict[str | None, Callable[[argparse.Namespace], int]] = {
    "devices": lambda args: list_devices(),
    "evaluate": lambda args: evaluate_sources(args),
    "record": record_command,
    "replay": replay_command,
    "simulate": simulate_command,
    "check-board": check_command,
    "diagnose": diagnose_command,
    "evaluate-faults": evaluate_faults_command,
    "joint": joint_command,
    "record-arm": record_arm_command,
    "calibrate-mag": magnetometer_command,
}


if __name__ == "__main__":
    sys.exit(main())
