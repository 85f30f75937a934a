"""``--jobs N`` / ``--scheduler tcp://HOST:PORT``: where ``tune`` and ``evaluate`` run their
work (:mod:`app.services.tuning.runner`): worker processes on this machine or an existing
Dask cluster."""

from __future__ import annotations

import argparse
from typing import Any

from app.cli.errors import CommandError
from app.core.evaluation import SourceResult
from app.core.recording.errors import RecordingError
from app.services.tuning.runner import RunnerError, local_cores, make_runner
from app.services.tuning.trials import SourceSpec, evaluate_recording

MAX_JOBS = 1024


def add_parallel_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    """``--jobs`` and ``--scheduler`` (one or the other); ``default`` says what --jobs is
    when neither is given."""
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=int, metavar="N",
                       help=f"worker processes (default: {default}; {local_cores()} cores "
                       "here; 1: in this process)")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="run on an existing Dask cluster (pip install "
                       "'inclinometer[cluster]'); its workers read the recordings from the "
                       "paths given, which they must see")


def check_jobs(args: argparse.Namespace) -> None:
    """CommandError for a --jobs out of range."""
    if args.jobs is not None and not 1 <= args.jobs <= MAX_JOBS:
        raise CommandError(f"--jobs must be from 1 to {MAX_JOBS}")


def evaluate_recordings(args: argparse.Namespace, pending: list[Any], filters: list[str],
                        parameters: dict[str, dict], skip: float
                        ) -> list[SourceResult | None] | None:
    """``evaluate --jobs N`` (N > 1) or ``--scheduler``: every recording among ``pending``
    scored by the workers, in the order given (None for a simulated source, scored here);
    None when neither option asks for workers."""
    check_jobs(args)
    if not args.scheduler and (args.jobs is None or args.jobs <= 1):
        return None
    if getattr(args, "turn", None) is not None:  # the workers score sources as they are
        raise CommandError("--turn is applied in this process only: leave out --jobs and "
                           "--scheduler")
    recordings = [(i, item) for i, item in enumerate(pending) if item.path is not None]
    calls = [(SourceSpec(str(item.path.resolve()), item.label, not args.raw), filters, skip,
              args.repeats, parameters) for _, item in recordings]
    try:
        with make_runner(args.jobs, args.scheduler, filters) as runner:
            results = runner.run(evaluate_recording, calls)
    except RunnerError as exc:
        raise CommandError(str(exc)) from None
    except (RecordingError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    found: list[SourceResult | None] = [None] * len(pending)
    for (i, _), result in zip(recordings, results, strict=True):
        found[i] = result
    return found
