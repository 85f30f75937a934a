"""``inclinometer evaluate SOURCE...``: score the orientation filters against a known truth.

Per source a table (RMSE and maximum of the inclination error, throughput, a flag; with a
magnetometer also the heading and total error RMSE), and with several sources a table of RMSE
per source and filter with each filter's mean (and the same for heading and total error when
the sources have a magnetometer); ``--turn`` turns every source's sensor frame first;
``--json`` writes every figure.
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
from typing import Any, TextIO

from app.cli.errors import EXIT_FAILED, CommandError, check_output_folder, finite
from app.cli.filter_params import (
    add_param_argument,
    check_parameters_for,
    parse_filter_parameters,
)
from app.cli.parallel import add_parallel_arguments, evaluate_recordings
from app.cli.recordings import check_recorded_calibration
from app.core import evaluation
from app.core.evaluation import FilterScore, SourceResult, StreamSource
from app.core.filters import FILTERS
from app.core.heading_metrics import PROJECT_TURN_DEG, turn_quaternion
from app.core.recording.errors import RecordingError
from app.core.recording.format import REFERENCE_COLUMNS
from app.core.recording.reader import read_metadata, read_recording
from app.core.safe_output import (
    OutputRefused,
    check_output,
    write_error_message,
    write_output,
)
from app.core.version import __version__
from app.services import simulation
from drivers.errors import DeviceError, DeviceUrlError
from drivers.registry import driver_for, scheme_of
from drivers.replay import recording_path

EVALUATE_DEFAULT_SECONDS = 60.0
MAX_SECONDS = 86400.0
"""The longest simulator stream ``evaluate --seconds`` makes (and the longest --skip)."""
MAX_REPEATS = 1000
GLOB_CHARACTERS = "*?["


def add_arguments(evaluate: argparse.ArgumentParser) -> None:
    """The options of ``evaluate``; it runs :func:`run`."""
    evaluate.set_defaults(handler=run)
    evaluate.description = (
        "Run orientation filters over streams whose true orientation is known and print, "
        "per filter, the inclination error (RMSE and maximum), the batch throughput and a "
        "flag (ok, NaN, diverged or error). Scored are the rows after the first seconds "
        "of convergence (--skip) or, in a recording with a 'movement' column, exactly "
        "the rows with movement == 1; rows without a reference never count. With several "
        "sources, a table of RMSE per source and filter follows, with each filter's mean "
        "over the sources. The simulator's static sensor errors are compensated with "
        "their true values unless --raw is given."
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
        "--turn", nargs="?", const=",".join(f"{a:g}" for a in PROJECT_TURN_DEG),
        metavar="RX,RY,RZ",
        help="turn each source's sensor frame by a fixed rotation (a rotation vector in "
        "degrees; without a value the project's %(const)s) before scoring: accelerometer, "
        "gyroscope, magnetometer and reference alike. A recording whose sensor starts "
        "pointing north gives a 6-axis heading right by luck; turned, only the magnetometer "
        "can find north. Inclination does not change",
    )
    evaluate.add_argument(
        "--per-source", action=argparse.BooleanOptionalAction, default=None,
        help="print each source's full table (RMSE, maximum, throughput, flag); default: "
        "when a single SOURCE that is not a glob is given",
    )
    add_parallel_arguments(evaluate, "1; with more, recordings are scored side by side and "
                           "the throughput is measured under that load")


def _format_score(score: FilterScore, width: int, heading: bool = False) -> str:
    rate = _number(score.samples_per_s, ",.0f")
    flag = score.flag if not score.message else f"{score.flag}: {score.message}"
    split = ""
    if heading:
        split = (f"  {heading_cell(score.heading_rmse_deg, score.magnetic):>11}"
                 f"  {heading_cell(score.total_rmse_deg, score.magnetic):>11}")
    return (f"  {score.name:<{width}}  {_number(score.rmse_deg, '.3f'):>9}  "
            f"{_number(score.max_deg, '.3f'):>9}{split}  {rate:>14}  {flag}")


def heading_cell(value: float, magnetic: bool) -> str:
    """A heading or total error; in parentheses for a filter whose heading is not the
    magnetometer's (a 6-axis heading is the gyroscope's from an arbitrary start)."""
    text = _number(value, ".3f")
    return text if magnetic or text == "-" else f"({text})"


HEADING_NOTE = ("heading and total error in parentheses: the filter does not take heading from "
                "the magnetometer, so its heading is the gyroscope's from an arbitrary start "
                "and means nothing")


def _number(value: float, spec: str) -> str:
    return format(value, spec) if math.isfinite(value) else "-"


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
    if not path.is_file():
        raise CommandError(f"{label}: no such file" if not path.exists()
                           else f"{label}: not a file")
    try:
        metadata, header = read_metadata(path)
    except RecordingError as exc:
        raise CommandError(str(exc)) from None
    except OSError as exc:
        raise CommandError(f"{label}: cannot read the recording: {exc.strerror or exc}") from None
    if compensate:
        check_recorded_calibration(metadata, path)
    if not all(column in header for column in REFERENCE_COLUMNS):
        try:  # a broken row says more than the missing columns: read the file for it
            read_recording(path)
        except RecordingError as exc:
            raise CommandError(str(exc)) from None
        raise CommandError(f"{path}: the recording has no reference orientation (columns qw, "
                           "qx, qy, qz) to compare the filters with")
    treatment = "recorded calibration" if compensate else "raw samples (--raw)"
    short = path.stem if path.suffix.lower() == ".csv" else path.name

    def load() -> StreamSource:
        return evaluation.recording_source(str(path), recalibrate=compensate, label=label)

    return _Pending(label, short, treatment, load, path)


NOT_EVALUABLE = ("only sources that know their true orientation can be evaluated (sim:// "
                 "URLs and recordings with reference columns)")


def resolve_sources(items: list[str], seconds: float, compensate: bool) -> list[_Pending]:
    """The sources named by ``items`` (scenarios, sim:// URLs, recordings, globs), in order.

    Raises :class:`CommandError` for a URL that cannot be evaluated, a file that is not a
    recording with a reference, or a glob that matches nothing. A file named twice is
    evaluated once.
    """
    errors = "static errors uncompensated" if not compensate else "static errors compensated"
    pending: list[_Pending] = []
    seen: set[Path] = set()
    for item in items:
        if item == "scenarios":
            pending.extend(_Pending(source.label, source.label, errors,
                                    lambda source=source: source)
                           for source in simulation.standard_sources(seconds,
                                                                     compensate=compensate))
            continue
        for path, label in _recordings_named(item):
            if path is None:  # a simulator URL
                source = _simulator(item, seconds, compensate)
                pending.append(_Pending(item, item, errors, lambda source=source: source))
            elif path.resolve() not in seen:
                seen.add(path.resolve())
                pending.append(_recording_pending(path, label, compensate))
    return pending


def _recordings_named(item: str) -> list[tuple[Path | None, str]]:
    """(file, label) of each recording ``item`` names, or ``[(None, item)]`` for a sim:// URL."""
    if "://" in item:
        try:
            scheme_of(item)
        except DeviceUrlError as exc:
            raise CommandError(str(exc)) from None
        try:
            driver = driver_for(item)
        except DeviceError:  # no such driver: it knows nothing
            driver = None
        if driver is not None and driver.replayable:
            return [(recording_path(item), item)]
        if driver is None or not driver.knows_truth:
            raise CommandError(f"{item}: {NOT_EVALUABLE}")
        return [(None, item)]
    if any(c in item for c in GLOB_CHARACTERS) and not Path(item).exists():
        matches = sorted(glob.glob(os.path.expanduser(item)))
        if not matches:
            raise CommandError(f"{item}: no file matches")
        return [(Path(match), match) for match in matches]
    if item.strip().lower().endswith(".csv") or Path(item).exists():
        return [(Path(item), item)]
    try:
        scheme_of(item)  # a bare serial port, or not a URL at all
    except DeviceUrlError:
        raise CommandError(f"{item}: no such file, and not a device URL (give a recording, a "
                           "glob of recordings, a sim:// URL or 'scenarios')") from None
    raise CommandError(f"{item}: {NOT_EVALUABLE}")


def _simulator(url: str, seconds: float, compensate: bool) -> StreamSource:
    try:
        return simulation.simulator_source(url, seconds, compensate=compensate)
    except DeviceError as exc:
        raise CommandError(str(exc)) from None


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
    split = f"  {'heading deg':>11}  {'total deg':>11}" if result.has_field else ""
    print(f"  {'filter':<{width}}  {'RMSE deg':>9}  {'max deg':>9}{split}  {'samples/s':>14}  "
          "flag", file=out)
    for score in result.scores:
        print(_format_score(score, width, result.has_field), file=out)
    if result.has_field:
        note = (f"; {HEADING_NOTE}" if any(not s.magnetic for s in result.scores) else "")
        print(f"  RMSE of inclination, heading and total error{note}", file=out)
    print(file=out)


class _Matrix:
    """The table of RMSE per source (rows) and filter (columns), printed row by row."""

    def __init__(self, labels: list[str], filters: list[str], out: TextIO,
                 what: str = "Inclination", key: str = "rmse_deg") -> None:
        self.filters = filters
        self.out = out
        self.what = what
        self.key = key
        self.label_width = max(6, *(len(label) for label in labels))
        self.widths = [max(7, len(name)) for name in filters]
        self.flagged: list[str] = []
        self.starred = False

    def header(self) -> None:
        print(f"{self.what} error RMSE (degrees) per source and filter", file=self.out)
        cells = "".join(f" {name:>{w}} " for name, w in zip(self.filters, self.widths,
                                                               strict=True))
        print(f"{'source':<{self.label_width}}  {'scored':>7}{cells}".rstrip(), file=self.out)

    def row(self, label: str, result: SourceResult) -> None:
        cells = []
        for name, width in zip(self.filters, self.widths, strict=True):
            score = result.score(name)
            value = math.nan if score is None else getattr(score, self.key)
            mark = " "
            if self.key != "rmse_deg" and score is not None and not score.magnetic:
                mark = "*"
                self.starred = True
            elif score is not None and score.flag != "ok":
                mark = "!"
                why = score.flag if not score.message else f"{score.flag}: {score.message}"
                self.flagged.append(f"{name} on {label}: {why}")
            cells.append(f" {_number(value, '.3f'):>{width}}{mark}")
        print(f"{label:<{self.label_width}}  {result.scored_samples:>7}{''.join(cells)}"
              .rstrip(), file=self.out)
        self.out.flush()

    def footer(self, summary: dict[str, dict[str, float | int]], sources: int) -> None:
        rows = ((("mean_rmse_deg", f"mean of {sources}"), ("worst_rmse_deg", "worst"))
                if self.key == "rmse_deg" else
                ((f"mean_{self.key}", f"mean of {sources}"),))
        for key, title in rows:
            cells = "".join(
                f" {_number(float(summary[name][key]), '.3f'):>{w}} "
                for name, w in zip(self.filters, self.widths, strict=True))
            print(f"{title:<{self.label_width}}  {'':>7}{cells}".rstrip(), file=self.out)
        for line in self.flagged:
            print(f"  ! {line}", file=self.out)
        if self.starred:
            print(f"  * {HEADING_NOTE.replace('in parentheses', 'marked *')}", file=self.out)


def _check_options(args: argparse.Namespace, filters: list[str]) -> dict[str, dict]:
    """The filter parameters; CommandError for an option out of range or unknown."""
    unknown = [name for name in filters if name not in FILTERS]
    if unknown:
        raise CommandError(f"no filter {unknown[0]!r}; choose from {', '.join(FILTERS)}")
    try:
        parameters = parse_filter_parameters(args.params)
        check_parameters_for(parameters, filters)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    finite(args.seconds, "--seconds", positive=True, maximum=MAX_SECONDS)
    if args.skip is not None:
        finite(args.skip, "--skip", minimum=0.0, maximum=MAX_SECONDS)
    if args.repeats is not None and not 1 <= args.repeats <= MAX_REPEATS:
        raise CommandError(f"--repeats must be from 1 to {MAX_REPEATS}")
    if args.json not in (None, "-"):
        check_output_folder(args.json, "--json")
    if args.turn is not None:
        args.turn_quat = parse_turn(args.turn)
    return parameters


def parse_turn(text: str) -> Any:
    """``RX,RY,RZ`` (degrees) as a unit quaternion; CommandError when it is not three finite
    numbers."""
    parts = text.split(",")
    try:
        angles = [float(part) for part in parts]
        if len(angles) != 3:
            raise ValueError
        return turn_quaternion(angles)
    except ValueError:
        raise CommandError(f"--turn {text!r}: give a rotation vector as three angles in "
                           "degrees, RX,RY,RZ (such as 20,-30,110)") from None


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``evaluate`` sub-command: per source a table, and with several a summary table."""
    out = sys.stdout if out is None else out
    filters = list(dict.fromkeys(args.filters or list(FILTERS)))
    parameters = _check_options(args, filters)
    pending = resolve_sources(args.sources, args.seconds, compensate=not args.raw)
    inputs = [item.path for item in pending]
    if args.json not in (None, "-"):
        try:
            check_output(args.json, inputs=inputs, overwrite=args.overwrite, option="--json")
        except OutputRefused as exc:
            raise CommandError(str(exc)) from None
    skip = evaluation.DEFAULT_SKIP_S if args.skip is None else args.skip
    if args.json == "-":
        out = sys.stderr  # stdout carries the JSON alone
    if parameters:
        chosen = ", ".join(f"{f}.{k}={v}" for f, values in parameters.items()
                           for k, v in values.items())
        print(f"parameters: {chosen}", file=out)
    if args.turn is not None:
        print(f"sensor frame turned by the rotation vector ({args.turn}) degrees", file=out)
    results = _evaluate_all(args, pending, filters, parameters, skip, out)
    for name in filters:
        if FILTERS[name].reference_only:
            print(f"{name}: {FILTERS[name].title}, kept as a reference implementation, not "
                  "for measurement", file=out)
    out.flush()
    if args.json is not None:
        settings = {
            "sources": list(args.sources), "skip_s": skip, "seconds": args.seconds,
            "compensated": not args.raw, "repeats": args.repeats, "app_version": __version__,
            "turn_deg": (None if args.turn is None
                         else [float(a) for a in args.turn.split(",")]),
        }
        document = evaluation.results_json(results, settings=settings, filters=filters,
                                           parameters=parameters)
        _write_json(args, json.dumps(document, indent=2) + "\n", inputs)
    return 0


def _evaluate_all(args: argparse.Namespace, pending: list[_Pending], filters: list[str],
                  parameters: dict[str, dict], skip: float, out: TextIO) -> list[SourceResult]:
    """Evaluate each source in turn, printing its table (or its row of the matrix) at once;
    then the matrix's footer when there are several sources."""
    single = len(args.sources) == 1 and not any(c in args.sources[0] for c in GLOB_CHARACTERS)
    details = args.per_source if args.per_source is not None else (single or len(pending) == 1)
    matrix = _Matrix([p.short for p in pending], filters, out) if len(pending) > 1 else None
    if matrix is not None and not details:
        matrix.header()
    width = max(6, *(len(name) for name in filters))
    results: list[SourceResult] = []
    computed = evaluate_recordings(args, pending, filters, parameters, skip)
    for index, item in enumerate(pending):
        try:
            if computed is not None and computed[index] is not None:
                result = computed[index]  # scored by a worker (--jobs, --scheduler)
            else:
                source = item.load()
                if getattr(args, "turn", None) is not None:
                    source = evaluation.turned_source(source, args.turn_quat)
                result = evaluation.evaluate_source(source, filters, skip_s=skip,
                                                    repeats=args.repeats, parameters=parameters)
        except (RecordingError, ValueError) as exc:
            raise CommandError(str(exc)) from None
        results.append(result)
        if details:
            _print_details(result, item.treatment, skip, width, out)
        elif matrix is not None:
            matrix.row(item.short, result)
        out.flush()
    if matrix is not None:
        if details:
            matrix.header()
            for item, result in zip(pending, results, strict=True):
                matrix.row(item.short, result)
        summary = evaluation.summarize(results)
        matrix.footer(summary, len(results))
        if all(r.has_field for r in results):
            for what, key in (("Heading", "heading_rmse_deg"), ("Total", "total_rmse_deg")):
                split = _Matrix([p.short for p in pending], filters, out, what, key)
                print(file=out)
                split.header()
                for item, result in zip(pending, results, strict=True):
                    split.row(item.short, result)
                split.footer(summary, len(results))
        rules = sorted({r.scoring for r in results})
        print(f"scored: {'; '.join(rules)}; rows without a reference never count", file=out)
    return results


def _write_json(args: argparse.Namespace, text: str, inputs: list[Path | None]) -> None:
    """``--json``: to stdout ('-') or safely to the file (CommandError, exit 1, when it
    cannot be written: the old file is intact)."""
    if args.json == "-":
        sys.stdout.write(text)
        sys.stdout.flush()
        return
    try:
        write_output(args.json, text, inputs=inputs, overwrite=args.overwrite, option="--json")
    except OSError as exc:  # OutputRefused, or a full disk
        raise CommandError(write_error_message(exc, args.json, "--json"),
                           EXIT_FAILED) from None
