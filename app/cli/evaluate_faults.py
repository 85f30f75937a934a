"""``inclinometer evaluate-faults [SOURCE ...]``: the fault detector measured as in the thesis.

Gaussian noise of sigma = multiples of each channel's own noise is injected into one channel at
a time of clean simulator scenarios and recordings; printed are NDR(sigma) (fraction of samples
flagged, on the injected channel and on the clean ones, and the whole matrix), FDI(sigma, theta)
(samples until the cumulative count of flagged samples reaches theta) and the false-alarm rate
on the clean sources (events per hour). ``--json OUT`` writes the same, ``--png DIR`` the
curves (docs/fault-detection.md#evaluation).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import numpy as np

from app.cli.errors import EXIT_FAILED, CommandError, finite
from app.core.faults.evaluation import (
    DEADLINES_S,
    NOISE_MULTIPLES,
    THETAS,
    motion_table,
    to_user_units,
    unit_of,
)
from app.core.faults.events import CHANNELS
from app.core.faults.motion import TUNING_TRIALS
from app.core.recording.errors import RecordingError
from app.core.safe_output import check_output, write_error_message, write_output
from app.services.fault_evaluation import (
    FaultEvaluationSettings,
    MotionSource,
    resolve_fault_sources,
    run_fault_evaluation,
    run_motion_evaluation,
)
from drivers.errors import DeviceError

if TYPE_CHECKING:
    from app.core.faults.evaluation import GroupSummary, SourceSweep
    from app.services.fault_evaluation import FaultEvaluation


def _numbers(kind: type, name: str):
    def parse(text: str) -> list:
        try:
            values = [kind(part) for part in text.split(",") if part.strip()]
        except ValueError:
            what = "whole numbers" if kind is int else "numbers"
            raise argparse.ArgumentTypeError(
                f"{name}: {text!r} is not a comma-separated list of {what}") from None
        if not values:
            raise argparse.ArgumentTypeError(f"{name}: give at least one value")
        return values
    return parse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``evaluate-faults``; it runs :func:`evaluate_faults_command`."""
    parser.set_defaults(handler=evaluate_faults_command)
    parser.description = (
            "Inject Gaussian noise of growing sigma (multiples of each channel's own noise per "
            "sample: the datasheet's for a known sensor, else estimated at rest) into one "
            "channel at a time of clean sources, from --onset to the end, and print NDR(sigma) "
            "(the fraction of samples the detector flags, on the injected channel and on the "
            "other five), FDI(sigma, theta) (samples until the cumulative count of samples "
            "flagged on the injected channel reaches theta; the median over the sources) and "
            "the false alarms on the clean sources (detector events per hour). Sources are "
            "grouped: 'simulator' and each recording folder. Exit status 2 when a source "
            "cannot be read.")
    parser.add_argument(
        "sources", metavar="SOURCE", nargs="*", default=["scenarios"],
        help="'scenarios' (every simulator scenario but the interactive one; the default), "
             "sim:// URLs, recordings or globs of them (e.g. '../shared/datasets/broad/*.csv')")
    parser.add_argument("--seconds", type=float, default=60.0, metavar="S",
                        help="simulator stream the noise is injected into (default %(default)g; "
                             "recordings: whole)")
    parser.add_argument("--onset", type=float, default=None, metavar="S",
                        help="noise from S seconds after the start (the detector learns the "
                             "clean noise first; default 10, with --in-motion 60: inside "
                             "BROAD's movement phase)")
    parser.add_argument("--in-motion", action="store_true",
                        help="instead of the sigma sweep: inject each fault of the goal of "
                             "issue 33 alone at --onset (noise of 1 and 2.9 dps on each gyro "
                             "axis, 0.2 and 0.5 m/s^2 on each accelerometer axis, a 2 dps gyro "
                             "bias step) and print per fault NDR (found within its deadline: "
                             "2 s for noise, 10 s for a bias), FDI (found on the injected "
                             "channel), the delays, and the false alarms on the clean sources")
    parser.add_argument("--clean-seconds", type=float, default=600.0, metavar="S",
                        help="clean simulator stream for the false alarms (default %(default)g; "
                             "3600 for the hour of the goal)")
    parser.add_argument("--sigma", type=_numbers(float, "--sigma"),
                        default=list(NOISE_MULTIPLES), metavar="M,M,...",
                        help="sigma as multiples of the channel's own noise (default "
                             f"{','.join(f'{m:g}' for m in NOISE_MULTIPLES)})")
    parser.add_argument("--theta", type=_numbers(int, "--theta"), default=list(THETAS),
                        metavar="N,N,...",
                        help="FDI thresholds on the cumulative flagged count (default "
                             f"{','.join(map(str, THETAS))})")
    parser.add_argument("--channels", type=lambda text: [c.strip().lower() for c in
                                                        text.split(",") if c.strip()],
                        default=None, metavar="CH,CH,...",
                        help="channels to inject into (default all: ax,ay,az,gx,gy,gz)")
    parser.add_argument("--seed", type=int, default=0, help="picks the injected noise")
    parser.add_argument("--json", metavar="OUT",
                        help="write every figure as JSON to OUT ('-': stdout, the tables then "
                             "go to stderr)")
    parser.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    parser.add_argument("--png", metavar="DIR",
                        help="save the NDR and FDI curves as ndr_GROUP.png and fdi_GROUP.png")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.add_argument("--inject", action="append", metavar="KIND:CHANNEL[:SIZE]@START[-END]",
                        help="with --write: the fault(s) to inject (repeatable; START seconds "
                             "from the first sample; SIZE in g or dps as for sim://...?fault=)")
    parser.add_argument("--write", metavar="OUT",
                        help="instead of an evaluation: copy the one recording SOURCE to OUT "
                             "with the --inject faults (to replay it, e.g. in the window)")


MAX_SECONDS = 86400.0
"""The longest stream ``--seconds`` and ``--clean-seconds`` ask for (a day)."""


def evaluate_faults_command(args: argparse.Namespace) -> int:
    """Run ``evaluate-faults``; returns the exit status."""
    if args.write is not None or args.inject:
        return _write_injected(args)
    if args.onset is None:
        args.onset = 60.0 if args.in_motion else 10.0
    if args.in_motion:
        return _in_motion(args)
    for option, value in (("--seconds", args.seconds), ("--onset", args.onset),
                          ("--clean-seconds", args.clean_seconds)):
        finite(value, option, minimum=0.0, maximum=MAX_SECONDS)
    for value in args.sigma:
        finite(value, "--sigma", positive=True, maximum=1e6)
    settings = FaultEvaluationSettings(
        seconds=args.seconds, onset_s=args.onset, clean_seconds=args.clean_seconds,
        multiples=tuple(args.sigma), channels=tuple(args.channels or CHANNELS),
        thetas=tuple(args.theta), seed=args.seed)
    out: TextIO = sys.stderr if args.json == "-" else sys.stdout
    try:
        settings.check()
        if args.json not in (None, "-"):
            check_output(args.json, inputs=_file_sources(args), overwrite=args.overwrite,
                         option="--json")
        sources = resolve_fault_sources(args.sources)
        if not sources:
            raise ValueError("no sources")

        def progress(line: str) -> None:
            if not args.quiet:
                print(line, file=sys.stderr, flush=True)

        result = run_fault_evaluation(sources, settings, progress)
    except (ValueError, RecordingError, DeviceError, OSError) as exc:
        raise CommandError(str(exc), command="evaluate-faults") from None
    print_evaluation(result, out)
    document = result.as_json()
    if args.json is not None:
        text = json.dumps(document, indent=1) + "\n"
        if args.json == "-":
            sys.stdout.write(text)
            sys.stdout.flush()
        else:
            try:
                write_output(args.json, text, inputs=_file_sources(args),
                             overwrite=args.overwrite, option="--json")
            except OSError as exc:
                raise CommandError(write_error_message(exc, args.json, "--json"), EXIT_FAILED,
                                   command="evaluate-faults") from None
    if args.png is not None:
        for path in save_curves(document, Path(args.png)):
            print(f"wrote {path}", file=out)
    return 0


def _file_sources(args: argparse.Namespace) -> list[Path]:
    """The sources that are files (no output may be one of them)."""
    return [Path(source) for source in args.sources if "://" not in source]


def save_curves(document: dict, directory: Path) -> list[Path]:
    """The curves through Qt's painting (:mod:`app.documents.fault_plots`; a QGuiApplication
    is made when none runs, offscreen without a screen). Qt is loaded only for ``--png``."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")  # no screen needed
    from app.documents.fault_plots import save_fault_curves

    return save_fault_curves(document, directory)


# -- tables ----------------------------------------------------------------------------------------
def print_evaluation(result: FaultEvaluation, out: TextIO) -> None:
    """Every group's NDR, full matrix, FDI and false-alarm tables."""
    s = result.settings
    print(f"Fault detector evaluation (thesis measures): Gaussian noise injected into one "
          f"channel at a time from {s.onset_s:g} s to the end; sigma in multiples of the "
          f"channel's own noise per sample", file=out)
    for group in result.groups:
        members = [w for w in result.sweeps if w.group == group.name]
        print_group(group, members, out)


def print_group(group: GroupSummary, sweeps: Sequence[SourceSweep], out: TextIO) -> None:
    rates = "/".join(f"{r:.4g}" for r in sorted(set(group.rates_hz)))
    swept = sum(w.duration_s for w in sweeps)
    print(f"\n== {group.name}: {len(sweeps)} source(s), {swept / 60:.1f} min swept at "
          f"{rates} Hz ==", file=out)
    basis = sorted({w.noise_basis for w in sweeps})
    own = []
    for c, name in enumerate(CHANNELS):
        values = [to_user_units(c, float(w.noise_si[c])) for w in sweeps]
        scale, unit = (1e3, "mg") if unit_of(c) == "g" else (1.0, "dps")
        own.append(f"{name} {_mean(values) * scale:.3g} {unit}")
    print(f"own noise per sample ({', '.join(basis)}; mean over sources): {', '.join(own)}",
          file=out)
    header = "".join(f"{_mult(m):>8}" for m in group.multiples)
    print("\nNDR on the injected channel (fraction of samples flagged from the onset)", file=out)
    print(f"  {'noise on':<9}{header}{'clean':>9}", file=out)
    for c in group.channels:
        cells = "".join(f"{v:8.3f}" for v in group.ndr_injected(c))
        print(f"  {CHANNELS[c]:<9}{cells}{group.clean_ndr[c]:9.4f}", file=out)
    print("\nNDR on the other five channels, largest (should stay near 0)", file=out)
    print(f"  {'noise on':<9}{header}", file=out)
    for c in group.channels:
        cells = "".join(f"{v:8.3f}" for v in group.ndr_others_max(c))
        print(f"  {CHANNELS[c]:<9}{cells}", file=out)
    print("\nNDR on the injected channel per source (mean over the channels)", file=out)
    width = max(8, *(len(w.label) for w in sweeps))
    print(f"  {'source':<{width}}{header}", file=out)
    for w in sweeps:
        cells = []
        for m in group.multiples:
            values = [r.ndr[r.channel] for r in w.runs if r.multiple == m]
            cells.append(f"{_mean(values):8.3f}")
        print(f"  {w.label:<{width}}{''.join(cells)}", file=out)
    print("\nNDR matrix: noise on (rows) x flagged channel (columns), per sigma", file=out)
    for k, m in enumerate(group.multiples):
        print(f"  sigma = {_mult(m)}  " + "".join(f"{name:>7}" for name in CHANNELS),
              file=out)
        for c in group.channels:
            row = group.ndr[c][k]
            print(f"    {CHANNELS[c]:<11}" + "".join(f"{v:7.3f}" for v in row), file=out)
    print(f"\nFDI: samples from the onset until the count of samples flagged on the injected "
          f"channel reaches theta (median over the sources where reached; [n]: reached in n "
          f"of the {len(sweeps)} when not all; '-': in none)", file=out)
    wide = "".join(f"{_mult(m):>10}" for m in group.multiples)
    for th in group.thetas:
        print(f"  theta = {th:<4}{wide}", file=out)
        for c in group.channels:
            cells = []
            for value, hits in zip(group.fdi[th][c], group.detected[th][c], strict=True):
                text = "-" if value is None else f"{value:g}"
                if 0 < hits < len(sweeps):
                    text += f"[{hits}]"
                cells.append(f"{text:>10}")
            print(f"    {CHANNELS[c]:<9}{''.join(cells)}", file=out)
    hours = group.clean_seconds / 3600.0
    rate = group.false_alarms_per_hour
    per = f" = {rate:.2f} per hour" if math.isfinite(rate) else ""
    print(f"\nFalse alarms on the clean sources: {group.false_alarms} event(s) in {hours:.2f} h"
          f"{per}", file=out)
    for w in sweeps:
        kinds = ", ".join(sorted({f"{e.channel} {e.kind}" for e in w.clean_events
                                  if e.channel != "link"}))
        print(f"  {w.label:<{width}} {w.clean_seconds / 60:7.1f} min {w.false_alarms:4d}"
              + (f"  ({kinds})" if kinds else ""), file=out)
    out.flush()


def _mult(m: float) -> str:
    return f"{m:g}x"


def _mean(values: Sequence[float]) -> float:
    return sum(values) / len(values) if values else math.nan


# -- faults while moving (issue 33) ------------------------------------------------------------
def _in_motion(args: argparse.Namespace) -> int:
    finite(args.onset, "--onset", minimum=0.0, maximum=MAX_SECONDS)
    finite(args.clean_seconds, "--clean-seconds", minimum=1.0, maximum=MAX_SECONDS)
    out: TextIO = sys.stderr if args.json == "-" else sys.stdout
    try:
        if args.json not in (None, "-"):
            check_output(args.json, inputs=_file_sources(args), overwrite=args.overwrite,
                         option="--json")
        sources = resolve_fault_sources(args.sources)
        if not sources:
            raise ValueError("no sources")
        results = run_motion_evaluation(
            sources, args.onset, seed=args.seed, clean_seconds=args.clean_seconds,
            progress=None if args.quiet else lambda line: print(line, file=sys.stderr,
                                                                flush=True))
    except (ValueError, RecordingError, DeviceError, OSError) as exc:
        raise CommandError(str(exc), command="evaluate-faults") from None
    print_motion(results, out)
    if args.json is not None:
        text = json.dumps(motion_json(results), indent=1) + "\n"
        if args.json == "-":
            sys.stdout.write(text)
        else:
            try:
                write_output(args.json, text, inputs=_file_sources(args),
                             overwrite=args.overwrite, option="--json")
            except OSError as exc:
                raise CommandError(write_error_message(exc, args.json, "--json"), EXIT_FAILED,
                                   command="evaluate-faults") from None
    return 0


def motion_json(results: Sequence[MotionSource]) -> dict:
    """``--in-motion --json``: every run, the pooled rows per group and the false alarms."""
    groups: dict[str, list[MotionSource]] = {}
    for source in results:
        groups.setdefault(source.group, []).append(source)
    return {
        "measure": {"ndr": "share of the injections found (any channel) within the deadline",
                    "fdi": "share found within the deadline on the injected channel",
                    "deadline_s": DEADLINES_S},
        "groups": {name: {
            "rows": [row.as_dict() for row in motion_table([r for s in members
                                                            for r in s.runs])],
            "clean_seconds": sum(s.clean_seconds for s in members),
            "false_alarms": [dict(e.as_dict(), source=s.label) for s in members
                             for e in s.clean_events]} for name, members in groups.items()},
        "runs": [r.as_dict() for s in results for r in s.runs],
    }


def print_motion(results: Sequence[MotionSource], out: TextIO) -> None:
    """Per group (and, for the BROAD trials, per half: the thresholds' and the held-out one)
    the NDR / FDI / delay table and the false alarms."""
    groups: dict[str, list[MotionSource]] = {}
    for source in results:
        groups.setdefault(source.group, []).append(source)
    print("Faults injected one at a time while the sensor moves: NDR = found within the "
          "deadline (noise 2 s, bias 10 s), FDI = found on the injected channel", file=out)
    for name, members in groups.items():
        moving = [s.moving_at_onset for s in members if s.moving_at_onset is not None]
        where = f", moving at the onset in {sum(moving)} of {len(moving)}" if moving else ""
        print(f"\n== {name}: {len(members)} source(s), faults at {members[0].onset_s:g} s"
              f"{where} ==", file=out)
        _motion_rows(members, out)
        tuning = [s for s in members if s.label.startswith(TUNING_TRIALS)]
        held = [s for s in members if not s.label.startswith(TUNING_TRIALS)]
        if tuning and held:
            for title, half in (("thresholds set on", tuning), ("held out", held)):
                print(f"\n  {title}: {', '.join(_short(s.label) for s in half)}", file=out)
                _motion_rows(half, out)
        seconds = sum(s.clean_seconds for s in members)
        alarms = [(s.label, e) for s in members for e in s.clean_events]
        print(f"\nFalse alarms on the clean sources: {len(alarms)} in {seconds / 3600:.2f} h",
              file=out)
        for label, event in alarms:
            print(f"  {label}: t = {event.t:.1f} s {event.channel} {event.kind}", file=out)
    out.flush()


def _motion_rows(members: Sequence[MotionSource], out: TextIO) -> None:
    print(f"  {'fault':<22}{'n':>4}{'NDR':>7}{'FDI':>7}{'delay med':>11}{'max':>7}  "
          "missed / on another channel", file=out)
    for row in motion_table([r for s in members for r in s.runs]):
        delays = row.delays()
        med = f"{float(np.median(delays)):.1f}" if delays else "-"
        top = f"{delays[-1]:.1f}" if delays else "-"
        notes = [f"{_short(r.source)} missed" for r in row.runs if not r.detected]
        notes += [f"{_short(r.source)} {r.first_channel}" for r in row.runs
                  if r.detected and not r.isolated]
        print(f"  {row.label:<22}{len(row.runs):>4}{row.ndr:7.2f}{row.fdi:7.2f}{med:>11}"
              f"{top:>7}  {', '.join(notes)}", file=out)


def _write_injected(args: argparse.Namespace) -> int:
    """``--write OUT --inject SPEC ... SOURCE``: a copy of one recording with faults in it."""
    from app.core.faults.injection import FAULT_CHANNELS, inject_recording, parse_fault_spec

    if args.write is None or not args.inject:
        raise CommandError("--inject and --write go together", command="evaluate-faults")
    if len(args.sources) != 1 or "://" in args.sources[0]:
        raise CommandError("--write takes exactly one recording as SOURCE",
                           command="evaluate-faults")
    try:
        specs = [parse_fault_spec(text, FAULT_CHANNELS) for text in args.inject]
        check_output(args.write, inputs=_file_sources(args), overwrite=args.overwrite,
                     option="--write")
        rows = inject_recording(args.sources[0], args.write, specs, args.seed)
    except (ValueError, OSError) as exc:
        raise CommandError(str(exc), command="evaluate-faults") from None
    print(f"wrote {args.write}: {rows} rows with {', '.join(s.text() for s in specs)}")
    return 0


def _short(label: str) -> str:
    """``01`` for a BROAD trial, ``static`` for ``static?seed=1``."""
    return label.split("_")[0].split("?")[0]
