"""How a 9-axis filter's heading on real disturbed data depends on its disturbance thresholds.

BROAD's heading-error RMSE (movement phase, reference known) on the twelve shared BROAD trials
(Laidig, Caruso, Cereatti, Seel 2021, Data 6(7):72, CC BY 4.0), each turned by the project's
fixed rotation (:data:`app.core.heading_metrics.PROJECT_TURN_DEG`, as ``evaluate --turn``) so that
only the magnetometer can find north. Printed: the mean over the twelve, over the five disturbed
trials (tapping, vibration, magnets), and per disturbed trial, for the filter with its defaults,
with the rejection off, and with each threshold halved and doubled; inclination beside.

    .venv/bin/python benchmarks/vqf_heading_sensitivity.py [TRIAL.csv ...] [--filter vqf]
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import numpy as np

from app.core.filters import FILTERS
from app.core.heading_metrics import (
    PROJECT_TURN_DEG,
    heading_error_deg,
    turn_block,
    turn_quaternion,
)
from app.core.orientation import inclination_error_deg
from app.core.recording.reader import read_recording

DEFAULT_GLOB = str(Path(__file__).resolve().parents[2] / "shared" / "datasets" / "broad" / "*.csv")
THRESHOLDS = {"vqf": (("mag_norm_threshold", 0.1), ("mag_dip_threshold_deg", 10.0))}


def load(paths: list[str]) -> list[tuple[str, object, np.ndarray]]:
    turn = turn_quaternion(PROJECT_TURN_DEG)
    trials = []
    for path in paths:
        recording = read_recording(path)
        samples = turn_block(recording.sample_block(recording.calibration), turn)
        movement = np.asarray(recording.unknown_columns["movement"]) > 0.5
        mask = movement & np.all(np.isfinite(samples.reference_quat), axis=1)
        trials.append((Path(path).stem, samples, mask))
    return trials


def scores(name: str, trials, **values) -> tuple[list[float], list[float]]:
    """Per trial: heading RMSE and inclination RMSE (degrees)."""
    heading, inclination = [], []
    for _, samples, mask in trials:
        quat = FILTERS[name](**values).process(samples).quat
        ref = samples.reference_quat[mask]
        heading.append(float(np.sqrt(np.mean(heading_error_deg(quat[mask], ref) ** 2))))
        inclination.append(float(np.sqrt(np.mean(inclination_error_deg(quat[mask], ref) ** 2))))
    return heading, inclination


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="*", help=f"recordings (default {DEFAULT_GLOB})")
    parser.add_argument("--filter", default="vqf", choices=sorted(THRESHOLDS))
    args = parser.parse_args()
    paths = args.trials or sorted(glob.glob(DEFAULT_GLOB))
    if not paths:
        print(f"no trials at {DEFAULT_GLOB}", file=sys.stderr)
        return 2
    trials = load(paths)
    disturbed = [k for k, (stem, _, _) in enumerate(trials) if "disturbed_" in stem
                 and "undisturbed" not in stem]
    runs: list[tuple[str, dict]] = [("defaults", {}),
                                    ("rejection off", {"mag_disturbance_rejection": False})]
    for key, default in THRESHOLDS[args.filter]:
        runs += [(f"{key} {default * factor:g}", {key: default * factor})
                 for factor in (0.5, 2.0)]
    labels = [" ".join(trials[k][0].split("_")[0:3:2])[:12] for k in disturbed]  # "28 stationary"
    print(f"{args.filter} on {len(trials)} BROAD trials turned by {PROJECT_TURN_DEG} deg; "
          "heading RMSE (deg), mean of all, of the disturbed, and per disturbed trial")
    print(f"{'setting':<32} {'all':>6} {'disturbed':>9} " + " ".join(f"{x:>12}" for x in labels)
          + f" {'incl. all':>9}")
    for title, values in runs:
        heading, inclination = scores(args.filter, trials, **values)
        cells = " ".join(f"{heading[k]:>12.2f}" for k in disturbed)
        mean_disturbed = np.mean([heading[k] for k in disturbed])
        print(f"{title:<32} {np.mean(heading):>6.2f} {mean_disturbed:>9.2f} {cells} "
              f"{np.mean(inclination):>9.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
