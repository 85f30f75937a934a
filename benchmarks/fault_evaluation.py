"""The fault detector measured as in the founding thesis (issue 15, item 5): the full sweep.

Gaussian noise of 0.5, 1, 2, 5, 10 and 20 times each channel's own noise per sample, injected
into one channel at a time from 10 s on, of every simulator scenario (60 s each) and of the
12 shared BROAD trials (whole); NDR(sigma) on every channel, FDI(sigma, theta) for theta = 1,
10, 100, and the false alarms on an hour of every clean scenario and on the clean trials.
Prints the tables (what ``inclinometer evaluate-faults`` prints) and writes them, with the
NDR and FDI curves, to ``docs/fault-evaluation/`` (about 6 minutes on 2 cores):

    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/fault_evaluation.py \\
        [--out docs/fault-evaluation] [--clean-seconds 3600] [--seconds 60] [--json FILE]

``--in-motion`` (issue 33) instead injects each fault of the goal alone at 60 s, inside
BROAD's movement phase (noise of 1 and 2.9 dps on each gyro axis, 0.2 and 0.5 m/s^2 on each
accelerometer axis, a 2 dps gyro bias step) into the 12 trials and into every scenario, and
counts the false alarms on the clean trials and on ``--clean-seconds`` (an hour) of every
scenario; the table goes to ``in-motion.txt`` (about an hour on 2 free cores).
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
from pathlib import Path

from app.cli.evaluate_faults import motion_json, print_evaluation, print_motion, save_curves
from app.services.fault_evaluation import (
    FaultEvaluationSettings,
    resolve_fault_sources,
    run_fault_evaluation,
    run_motion_evaluation,
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
    parser.add_argument("--in-motion", action="store_true",
                        help="faults of issue 33 injected in the movement phase (see above)")
    args = parser.parse_args()
    if args.in_motion:
        return in_motion(args)
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


def in_motion(args: argparse.Namespace) -> int:
    """The in-motion table of issue 33 (``evaluate-faults --in-motion``) with an hour of clean
    scenarios."""
    items = [str(BROAD_DIR / "*.csv")] if BROAD_DIR.is_dir() else []
    items.append("scenarios")
    started = time.perf_counter()
    results = run_motion_evaluation(resolve_fault_sources(items), 60.0,
                                    clean_seconds=args.clean_seconds,
                                    progress=lambda line: print(line, file=sys.stderr,
                                                                flush=True))
    args.out.mkdir(parents=True, exist_ok=True)
    table = io.StringIO()
    print_motion(results, _Tee(sys.stdout, table))
    command = ("QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/fault_evaluation.py "
               f"--in-motion --clean-seconds {args.clean_seconds:g}")
    (args.out / "in-motion.txt").write_text(f"$ {command}\n{table.getvalue()}",
                                            encoding="utf-8")
    if args.json is not None:
        args.json.write_text(json.dumps(motion_json(results), indent=1) + "\n",
                             encoding="utf-8")
    print(f"wrote {args.out / 'in-motion.txt'}; {time.perf_counter() - started:.0f} s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
