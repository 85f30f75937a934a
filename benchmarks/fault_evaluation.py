"""The fault detector measured as in the founding thesis (issue 15, item 5): the full sweep.

Gaussian noise of 0.5, 1, 2, 5, 10 and 20 times each channel's own noise per sample, injected
into one channel at a time from 10 s on, of every simulator scenario (60 s each) and of the
12 shared BROAD trials (whole); NDR(sigma) on every channel, FDI(sigma, theta) for theta = 1,
10, 100, and the false alarms on an hour of every clean scenario and on the clean trials.
Prints the tables (what ``inclinometer evaluate-faults`` prints) and writes them, with the
NDR and FDI curves, to ``docs/fault-evaluation/`` (about 6 minutes on 2 cores):

    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/fault_evaluation.py \\
        [--out docs/fault-evaluation] [--clean-seconds 3600] [--seconds 60] [--json FILE]
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
from pathlib import Path

from app.cli.evaluate_faults import print_evaluation, save_curves
from app.services.fault_evaluation import (
    FaultEvaluationSettings,
    resolve_fault_sources,
    run_fault_evaluation,
)

ROOT = Path(__file__).resolve().parents[1]
BROAD_DIR = ROOT.parent / "shared" / "datasets" / "broad"


class _Tee(io.TextIOBase):
    def __init__(self, *streams) -> None:
        self.streams = streams

    def write(self, text: str) -> int:
        for stream in self.streams:
            stream.write(text)
        return len(text)

    def flush(self) -> None:
        for stream in self.streams:
            stream.flush()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "fault-evaluation",
                        help="folder for the PNGs and evaluation.txt (default %(default)s)")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--clean-seconds", type=float, default=3600.0)
    parser.add_argument("--json", type=Path, help="also write the whole evaluation as JSON")
    args = parser.parse_args()
    items = ["scenarios"]
    if BROAD_DIR.is_dir():
        items.append(str(BROAD_DIR / "*.csv"))
    else:
        print(f"(no BROAD trials at {BROAD_DIR}: simulator only)", file=sys.stderr)
    settings = FaultEvaluationSettings(seconds=args.seconds, onset_s=10.0,
                                       clean_seconds=args.clean_seconds)
    started = time.perf_counter()
    result = run_fault_evaluation(resolve_fault_sources(items), settings,
                                  lambda line: print(line, file=sys.stderr, flush=True))
    args.out.mkdir(parents=True, exist_ok=True)
    table = io.StringIO()
    print_evaluation(result, _Tee(sys.stdout, table))
    command = ("QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/fault_evaluation.py"
               + (f" --seconds {args.seconds:g}" if args.seconds != 60 else "")
               + (f" --clean-seconds {args.clean_seconds:g}" if args.clean_seconds != 3600
                  else ""))
    (args.out / "evaluation.txt").write_text(f"$ {command}\n{table.getvalue()}",
                                             encoding="utf-8")
    document = result.as_json()
    if args.json is not None:
        args.json.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    for path in save_curves(document, args.out):
        print(f"wrote {path}")
    print(f"wrote {args.out / 'evaluation.txt'}; {time.perf_counter() - started:.0f} s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
