"""``inclinometer tune SOURCES... --param F.NAME=V1,V2,... --json OUT``: a parameter study of
one filter over recordings with a reference, cross-validated by trial, on every local core
or an existing Dask cluster. The work is in :mod:`app.services.tuning`; this module checks
the options, draws the progress bar and writes the results.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from app.cli.errors import EXIT_FAILED, CommandError, check_output_folder
from app.cli.evaluate import resolve_sources
from app.cli.filter_params import parse_filter_parameters
from app.cli.parallel import add_parallel_arguments, check_jobs
from app.core.filters import FILTERS
from app.core.recording.errors import RecordingError
from app.core.safe_output import OutputRefused, check_output, write_error_message, write_output
from app.core.version import __version__
from app.documents.tuning_plot import plot_png
from app.services.tuning import grid, report
from app.services.tuning.grid import Axis
from app.services.tuning.runner import RunnerError, make_runner
from app.services.tuning.study import StudyRequest, run_study
from app.services.tuning.trials import SourceSpec

RECORDING_PATTERNS = ("*.csv", "*.csv.gz")


def add_arguments(tune: argparse.ArgumentParser) -> None:
    """The options of ``tune``; it runs :func:`run`."""
    tune.set_defaults(handler=run)
    tune.description = (
        "A parameter study of one filter: run it with every point of a grid (or a random "
        "search) over recordings with a reference, score each run as 'evaluate' does "
        "(inclination RMSE over the movement rows), and cross-validate by trial: for each "
        "fold the parameters are chosen on the other trials and scored on the held-out "
        "ones. Prints the best points, the folds, the cross-validated RMSE and the "
        "sensitivity around the optimum (x0.5 and x2; integers and booleans: the "
        "neighbouring values); --json writes every figure, --png plots the error against "
        "each parameter. Runs on every local core unless told otherwise; results are the "
        "same to the bit however they are run."
    )
    tune.add_argument(
        "sources", metavar="SOURCE", nargs="+",
        help="recordings with reference columns: files, globs ('DIR/*.csv') or directories "
        "(every *.csv and *.csv.gz in them)",
    )
    tune.add_argument(
        "--param", dest="axes", metavar="FILTER.NAME=V1,V2,...", action="append", default=[],
        help="a parameter and the values to try (repeatable; one filter per study; each "
        "value checked against the filter's range), e.g. --param ekf.lp_tau=1,2,4; with "
        "--random also a range LOW..HIGH (drawn log-uniformly for a log-scale parameter)",
    )
    tune.add_argument("--filter", metavar="NAME",
                      help="the filter studied (default: the one --param names; without "
                      "--param its defaults are cross-validated as one point)")
    tune.add_argument("--random", type=int, metavar="N",
                      help="a random search of N points instead of the whole grid")
    tune.add_argument("--seed", type=int, default=0, metavar="S",
                      help="seed of the random search (default %(default)s)")
    split = tune.add_mutually_exclusive_group()
    split.add_argument("--folds", type=int, metavar="K",
                       help="k-fold cross-validation by trial (trial i in fold i mod K; "
                       "default: leave one trial out)")
    split.add_argument("--groups", action="store_true",
                       help="leave one group out: BROAD's groups from the file names "
                       "(rotation, translation, disturbed, combined)")
    add_parallel_arguments(tune, "every core")
    tune.add_argument("--scatter", action="store_true",
                      help="with --scheduler: read each recording here and send it to every "
                      "worker once (for workers without the shared path)")
    tune.add_argument("--raw", action="store_true",
                      help="do not apply the recordings' recorded calibration again")
    tune.add_argument("--json", metavar="FILE", required=True,
                      help="write the study (results per point and trial, folds, "
                      "sensitivity) as JSON to FILE")
    tune.add_argument("--png", metavar="FILE", help="plot the error against each parameter")
    tune.add_argument("--overwrite", action="store_true",
                      help="replace the --json / --png files if they exist")
    tune.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                      help="a progress line with the time left on stderr (default: when "
                      "stderr is a terminal)")


def parse_axis(text: str, ranges: bool) -> Axis:
    """``ekf.lp_tau=1,2,4`` (or ``ekf.lp_tau=0.5..8`` when ``ranges``) -> an :class:`Axis`,
    each value checked by the filter's ParameterSpec (CommandError naming the problem)."""
    target, equals, values = text.partition("=")
    target = target.strip()
    if not equals or not values.strip():
        raise CommandError(f"--param {text!r}: write FILTER.NAME=V1,V2,... e.g. "
                           "ekf.lp_tau=1,2,4")

    def one(value: str) -> Any:
        try:
            parsed = parse_filter_parameters([f"{target}={value.strip()}"])
        except ValueError as exc:
            raise CommandError(str(exc)) from None
        return next(iter(next(iter(parsed.values())).values()))

    if ".." in values:
        low_text, _, high_text = values.partition("..")
        low, high = one(low_text), one(high_text)
        filter_name, _, name = target.partition(".")
        spec = FILTERS[filter_name].parameter_spec(name)
        if spec.kind == "bool":
            raise CommandError(f"--param {text!r}: {name} is true or false: list the values")
        if not ranges:
            raise CommandError(f"--param {text!r}: a range LOW..HIGH needs --random N (a "
                               "grid takes listed values)")
        if not low < high:
            raise CommandError(f"--param {text!r}: the range must go from low to high")
        return Axis(filter_name, spec, low=float(low), high=float(high))
    items = [v for v in values.split(",")]
    if any(not v.strip() for v in items):
        raise CommandError(f"--param {text!r}: an empty value in the list")
    parsed = [one(v) for v in items]
    filter_name, _, name = target.partition(".")
    unique = list(dict.fromkeys(parsed))
    return Axis(filter_name, FILTERS[filter_name].parameter_spec(name), values=tuple(unique))


def _axes(args: argparse.Namespace) -> tuple[str, list[Axis]]:
    axes = [parse_axis(text, ranges=args.random is not None) for text in args.axes]
    filters = list(dict.fromkeys([a.filter for a in axes] +
                                 ([args.filter] if args.filter else [])))
    if args.filter and args.filter not in FILTERS:
        raise CommandError(f"--filter {args.filter!r}: no such filter; choose from "
                           f"{', '.join(FILTERS)}")
    if not filters:
        raise CommandError("give --param FILTER.NAME=V1,V2,... (or --filter NAME to "
                           "cross-validate a filter's defaults)")
    if len(filters) > 1:
        raise CommandError(f"one filter per study: --param/--filter name {', '.join(filters)}")
    names = [a.name for a in axes]
    repeated = next((n for n in names if names.count(n) > 1), None)
    if repeated:
        raise CommandError(f"--param {filters[0]}.{repeated} is given twice: list all its "
                           "values in one --param")
    if FILTERS[filters[0]].offline:
        raise CommandError(f"{filters[0]} is an offline smoother; tune studies online filters")
    return filters[0], axes


def _expand(items: list[str]) -> list[str]:
    """Directories become globs of the recordings in them."""
    expanded = []
    for item in items:
        path = Path(item).expanduser()
        if path.is_dir():
            found = sorted({str(p) for pattern in RECORDING_PATTERNS for p in path.glob(pattern)})
            if not found:
                raise CommandError(f"{item}: no recording (*.csv, *.csv.gz) in the directory")
            expanded.extend(found)
        else:
            expanded.append(item)
    return expanded


def _sources(args: argparse.Namespace) -> list[SourceSpec]:
    pending = resolve_sources(_expand(args.sources), 1.0, compensate=not args.raw)
    specs = []
    for item in pending:
        if item.path is None:
            raise CommandError(f"{item.label}: tune takes recordings with a reference (a "
                               "simulator stream cannot be sent to the workers)")
        specs.append(SourceSpec(str(item.path.resolve()), item.short, not args.raw))
    labels = [s.label for s in specs]
    twice = next((label for label in labels if labels.count(label) > 1), None)
    if twice:
        raise CommandError(f"two recordings are named {twice!r}: their results would mix "
                           "(rename one)")
    if len(specs) < 2:
        raise CommandError("tune needs two recordings or more: it holds trials out to "
                           "cross-validate")
    return specs


def _check_outputs(args: argparse.Namespace, sources: list[SourceSpec]) -> None:
    inputs = [Path(s.path) for s in sources]
    for option, path in (("--json", args.json), ("--png", args.png)):
        if path is None:
            continue
        check_output_folder(path, option)
        try:
            check_output(path, inputs=inputs, overwrite=args.overwrite, option=option)
        except OutputRefused as exc:
            raise CommandError(str(exc)) from None
    if args.png is not None and Path(args.png).resolve() == Path(args.json).resolve():
        raise CommandError("--png and --json name the same file")


def _request(args: argparse.Namespace) -> StudyRequest:
    check_jobs(args)
    if args.scatter and not args.scheduler:
        raise CommandError("--scatter goes with --scheduler")
    filter_name, axes = _axes(args)
    try:
        if not axes:
            points: list[dict[str, Any]] = [{}]
        elif args.random is not None:
            points = grid.random_points(axes, args.random, args.seed)
        else:
            points = grid.grid_points(axes)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    sources = _sources(args)
    _check_outputs(args, sources)
    return StudyRequest(
        filter_name, axes, points, sources, folds=args.folds, groups=args.groups,
        search="random" if args.random is not None else "grid",
        seed=args.seed if args.random is not None else None,
        settings={"sources": list(args.sources), "compensated": not args.raw,
                  "app_version": __version__},
    )


class TerminalProgress:
    """``tune: 340/1200 runs (28 %), 0:41 so far, about 1:45 left`` on one line of stderr."""

    INTERVAL_S = 0.25

    def __init__(self, out: TextIO) -> None:
        self.out = out
        self.total = self.done = 0
        self.start = time.monotonic()
        self.shown = -math.inf

    def extend(self, runs: int) -> None:
        self.total += runs
        self._show()

    def advance(self, runs: int) -> None:
        self.done += runs
        self._show(force=self.done == self.total)

    def _show(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self.shown < self.INTERVAL_S:
            return
        self.shown = now
        spent = now - self.start
        left = (f"about {_clock(spent / self.done * (self.total - self.done))} left"
                if self.done else "starting")
        share = 100.0 * self.done / self.total if self.total else 0.0
        self.out.write(f"\rtune: {self.done}/{self.total} runs ({share:.0f} %), "
                       f"{_clock(spent)} so far, {left}   ")
        self.out.flush()

    def close(self) -> None:
        self.out.write("\n")
        self.out.flush()


def _clock(seconds: float) -> str:
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``tune`` sub-command."""
    out = sys.stdout if out is None else out
    request = _request(args)
    show = args.progress if args.progress is not None else sys.stderr.isatty()
    progress = TerminalProgress(sys.stderr) if show else None
    start = time.perf_counter()
    try:
        with make_runner(args.jobs, args.scheduler, [request.filter],
                         scatter=args.scatter) as runner:
            print(f"tune: {len(request.points)} points x {len(request.sources)} recordings on "
                  f"{runner.description}", file=out)
            out.flush()
            document = run_study(request, runner, progress)
    except RunnerError as exc:
        raise CommandError(str(exc)) from None
    except (RecordingError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    finally:
        if progress is not None:
            progress.close()
    wall = time.perf_counter() - start
    document["run"] = {"runner": runner.description, "workers": runner.workers,
                       "wall_s": round(wall, 3)}
    for line in report.summary_lines(document):
        print(line, file=out)
    print(f"{document['runs']} runs in {wall:.1f} s on {runner.description}", file=out)
    inputs = [Path(s.path) for s in request.sources]
    _write(args.json, (json.dumps(document, indent=2) + "\n").encode(), args, inputs, "--json")
    if args.png is not None and request.axes:
        _write(args.png, plot_png(document), args, inputs, "--png")
    elif args.png is not None:
        print("--png: no plot: the study has no parameter (give --param)", file=out)
    return 0


def _write(path: str, data: bytes, args: argparse.Namespace, inputs: list[Path],
           option: str) -> None:
    try:
        write_output(path, data, inputs=inputs, overwrite=args.overwrite, option=option)
    except OSError as exc:
        raise CommandError(write_error_message(exc, path, option), EXIT_FAILED) from None

