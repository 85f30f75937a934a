"""How the EKF's accuracy on real motion depends on each of its parameters.

BROAD's inclination-error RMSE (movement phase, reference known), mean over the trials, for the
EKF with its defaults and with one parameter at a time halved and doubled (switches: off). The
trials are the shared BROAD recordings (Laidig, Caruso, Cereatti, Seel 2021, Data 6(7):72,
CC BY 4.0); VQF's mean is printed beside as the bar.

    .venv/bin/python benchmarks/ekf_sensitivity.py [TRIAL.csv ...] [--filter ekf-smoother]
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import numpy as np

from app.core.filters import FILTERS
from app.core.orientation import inclination_error_deg
from app.core.recording.reader import read_recording

DEFAULT_GLOB = str(Path(__file__).resolve().parents[2] / "shared" / "datasets" / "broad" / "*.csv")


def load(paths: list[str]) -> list[tuple[str, object, np.ndarray]]:
    trials = []
    for path in paths:
        recording = read_recording(path)
        samples = recording.sample_block(recording.calibration)
        columns = recording.unknown_columns
        movement = (np.asarray(columns["movement"]) > 0.5 if "movement" in columns
                    else np.ones(len(samples), bool))
        mask = movement & np.all(np.isfinite(samples.reference_quat), axis=1)
        trials.append((Path(path).stem, samples, mask))
    return trials


def mean_rmse(name: str, trials, **values) -> tuple[float, list[float]]:
    scores = []
    for _, samples, mask in trials:
        quat = FILTERS[name](**values).process(samples).quat
        errors = inclination_error_deg(quat[mask], samples.reference_quat[mask])
        scores.append(float(np.sqrt(np.mean(errors**2))))
    return float(np.mean(scores)), scores


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="*", help=f"recordings (default {DEFAULT_GLOB})")
    parser.add_argument("--filter", default="ekf", help="ekf (default) or ekf-smoother")
    args = parser.parse_args()
    paths = args.trials or sorted(glob.glob(DEFAULT_GLOB))
    if not paths:
        print(f"no trials at {DEFAULT_GLOB}", file=sys.stderr)
        return 2
    trials = load(paths)
    vqf_mean, vqf_scores = mean_rmse("vqf", trials)
    base_mean, base_scores = mean_rmse(args.filter, trials)
    print(f"{len(trials)} trials; mean inclination RMSE, degrees")
    print(f"vqf (the bar)            {vqf_mean:.3f}")
    worst = max(o / v for o, v in zip(base_scores, vqf_scores, strict=True))
    print(f"{args.filter} defaults{' ' * (15 - len(args.filter))}{base_mean:.3f}"
          f"   (worst trial {worst:.2f}x VQF)")
    print()
    print(f"{'parameter':<18} {'default':>9}   {'x0.5':>13}   {'x2':>13}")
    cls = FILTERS[args.filter]
    for spec in cls.parameters:
        default = spec.default
        if spec.kind == "bool":
            low, _ = mean_rmse(args.filter, trials, **{spec.name: not default})
            print(f"{spec.name:<18} {default!s:>9}   off: {low:.3f} ({low - base_mean:+.3f})")
            continue
        if default == 0:
            continue
        cells = []
        for factor in (0.5, 2.0):
            value = min(max(default * factor, spec.minimum), spec.maximum)
            mean, _ = mean_rmse(args.filter, trials, **{spec.name: value})
            cells.append(f"{mean:.3f} ({mean - base_mean:+.3f})")
        print(f"{spec.name:<18} {default:>9g}   {cells[0]:>13}   {cells[1]:>13}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
