"""Joint angle of a hinge between two IMUs: `inclinometer joint` against qmt's pipeline.

Recordings: `sim://arm` (drivers/sim/scenarios.py `Arm`: a hand-held base, a hinge moving
through 10-130 degrees, random sensor mountings so the axis is unknown in both frames, lever
arms, gyro turn-on biases within +-0.5 dps, LSM6DSOX noise and quantisation, bias drift and
temperature; 208 Hz nominal, 180 s) written by `app.services.arm_recordings.record_arm`, one v1
file per sensor with the true joint angle (`joint_ref_deg`) and true axes (metadata `arm`).
The main set varies the seed (unit, mounting, motion), the hand's speed (`level`) and the
joint's speed (`joint_band`), and has three-link arms whose two hinges are scored apart.

Per recording and method: the RMSE of the joint angle against the truth over the rows from
10 s on, up to a sign and a constant offset (the angle's zero and direction are conventions),
the axis error (largest angle between an estimated axis and the true one, either sign), and
the time taken (orientation estimation included, file reading not).

- `joint`: what `inclinometer joint` runs (`app.core.joint.offline.joint_angle_offline`: the
  axis fitted on the whole recording, then the causal estimator).
- `live`: the causal estimator alone (`JointEstimator` with the axis estimated as the data
  arrive, refitted every 10 s), as a live session would show it; its RMSE counts from 10 s
  too, so it includes the axis settling.
- `qmt`: qmt 0.2.4 (`pip install ".[bench-joint]"`): `qmt.oriEstVQF` per link,
  `qmt.jointAxisEstHingeOlsson`, sensor 2's orientation turned so the axis has sensor 1's
  coordinates (qmt's heading correction takes one axis for both segments),
  `qmt.headingCorrection` (defaults: 8 s backward windows, `dataRate` 5 Hz rounded so that it
  divides the sample rate, since qmt requires it; the time axis is the samples' index times
  the median period, since qmt requires an exactly constant step), then the same hinge angle
  as `joint` computes. Olsson's method does not fix the axes' relative sign; both methods get
  the same rule (`app.core.joint.axis.consistent_sign`: the axis' inclination seen from both
  links must agree).

Then the sensitivity to gyro bias, noise, uncalibrated units and the richness of the motion
(each on the first four seeds).

Usage: ``.venv/bin/python benchmarks/joint_angle.py [--trials 12] [--seconds 180]
[--no-sensitivity] [--keep DIR]``
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.core.joint.axis import consistent_sign
from app.core.joint.estimator import JointEstimator, hinge_angle
from app.core.joint.offline import joint_angle_offline
from app.core.recording.reader import read_recording
from app.services.arm_recordings import JOINT_REFERENCE_COLUMN, record_arm

SKIP_S = 10.0
LEVELS = (0.2, 0.5, 0.8)
JOINT_BANDS = (0.3, 0.5, 0.8)


@dataclass
class Trial:
    label: str
    url: str
    joint: int = 1


def rmse_up_to_sign_and_offset(estimate_deg: np.ndarray, truth_deg: np.ndarray) -> float:
    """RMSE (deg) after the best sign and constant offset (circular mean of the difference)."""
    ok = np.isfinite(estimate_deg) & np.isfinite(truth_deg)
    best = math.inf
    for sign in (1.0, -1.0):
        d = np.radians(sign * estimate_deg[ok] - truth_deg[ok])
        offset = np.angle(np.mean(np.exp(1j * d)))
        e = np.angle(np.exp(1j * (d - offset)))
        best = min(best, math.degrees(math.sqrt(float(np.mean(e * e)))))
    return best


def axis_error_deg(pairs: list[tuple[np.ndarray, np.ndarray]]) -> float:
    return max(math.degrees(math.acos(min(1.0, abs(float(a @ b) / np.linalg.norm(a)))))
               for a, b in pairs)


def qmt_pipeline(b1, b2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import qmt

    ts = float(np.median(np.diff(b1.t_s)))
    q1 = qmt.oriEstVQF(b1.gyro_rad_s, b1.accel_m_s2, params={"Ts": ts})
    q2 = qmt.oriEstVQF(b2.gyro_rad_s, b2.accel_m_s2, params={"Ts": ts})
    j1, j2 = qmt.jointAxisEstHingeOlsson(b1.accel_m_s2, b2.accel_m_s2, b1.gyro_rad_s,
                                         b2.gyro_rad_s)
    j1, j2 = np.ravel(j1), np.ravel(j2)
    j2 = consistent_sign(j1, j2, q1, q2)
    turn = np.cross(j1, j2)
    q_align = qmt.quatFromAngleAxis(math.acos(float(np.clip(j1 @ j2, -1.0, 1.0))), turn)
    q2_segment = qmt.qmult(q2, q_align)
    rate = 1.0 / ts
    t = np.arange(len(b1.t_s)) * ts
    q2_corrected = qmt.headingCorrection(
        b1.gyro_rad_s, b2.gyro_rad_s, q1, q2_segment, t, j1, None,
        estSettings={"dataRate": rate / round(rate / 5.0)},
    )[0]
    angle = np.degrees(hinge_angle(np.asarray(q1), np.asarray(q2_corrected), j1, j1))
    return angle, j1, j2


def run_trial(trial: Trial, seconds: float, root: Path, with_qmt: bool) -> dict[str, float]:
    folder = root / f"{trial.label}"
    if not (folder / "sensor0.csv").exists():
        record_arm(trial.url, seconds, folder, overwrite=True)
    k = trial.joint
    a = read_recording(folder / f"sensor{k - 1}.csv")
    b = read_recording(folder / f"sensor{k}.csv")
    truth = b.unknown_columns[JOINT_REFERENCE_COLUMN]
    axes = b.metadata["arm"]["true_axes"]
    true1 = np.array(a.metadata["arm"]["true_axes"][f"joint_{k}_in_sensor_{k - 1}"])
    true2 = np.array(axes[f"joint_{k}_in_sensor_{k}"])
    b1, b2 = a.sample_block(), b.sample_block()
    scored = a.t_s >= a.t_s[0] + SKIP_S
    row: dict[str, float] = {}

    start = time.perf_counter()
    result = joint_angle_offline(b1, b2)
    row["joint_s"] = time.perf_counter() - start
    row["joint"] = rmse_up_to_sign_and_offset(result.angles.angle_deg[scored], truth[scored])
    row["joint_axis"] = axis_error_deg([(result.j1, true1), (result.j2, true2)])
    row["spread"] = result.axis_spread_deg

    start = time.perf_counter()
    live = JointEstimator()
    angle = np.concatenate([live.update(_part(b1, s), _part(b2, s)).angle_deg
                            for s in _blocks(len(b1.t_s), 52)])
    row["live_s"] = time.perf_counter() - start
    row["live"] = rmse_up_to_sign_and_offset(angle[scored], truth[scored])
    assert live.axes is not None
    row["live_axis"] = axis_error_deg([(live.axes[0], true1), (live.axes[1], true2)])

    if with_qmt:
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            angle, j1, j2 = _quiet(qmt_pipeline, b1, b2)
        row["qmt_s"] = time.perf_counter() - start
        row["qmt"] = rmse_up_to_sign_and_offset(angle[scored], truth[scored])
        row["qmt_axis"] = axis_error_deg([(j1, true1), (j2, true2)])
    # What a perfect orientation would give with the estimated axes (a check of the metric).
    ideal = np.degrees(hinge_angle(a.reference_quat, b.reference_quat, result.j1, result.j2))
    row["ideal"] = rmse_up_to_sign_and_offset(ideal[scored], truth[scored])
    return row


def _quiet(function, *args):
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        return function(*args)


def _blocks(n: int, size: int) -> list[slice]:
    return [slice(s, min(n, s + size)) for s in range(0, n, size)]


def _part(block, rows: slice):
    from app.core.samples import SampleBlock

    return SampleBlock(block.t_s[rows], block.accel_m_s2[rows], block.gyro_rad_s[rows],
                       block.temp_degc[rows], block.gap[rows])


def main_trials(count: int) -> list[Trial]:
    trials = []
    for i in range(count - 2):
        seed = i + 1
        level = LEVELS[i % 3]
        band = JOINT_BANDS[(i // 3) % 3]
        trials.append(Trial(f"s{seed}-level{level}-band{band}",
                            f"sim://arm?odr=208&seed={seed}&level={level}&joint_band={band}"))
    url = "sim://arm?odr=208&seed=100&links=3"
    trials += [Trial("3links-s100", url, joint) for joint in (1, 2)]
    return trials


SENSITIVITY = (
    ("as the main set (bias 0.5 dps, level 0.5)", "bias=0.5"),
    ("gyro bias within +-0 dps", "bias=0"),
    ("gyro bias within +-1 dps", "bias=1"),
    ("gyro bias within +-2 dps", "bias=2"),
    ("no white noise (quantisation stays)", "noise=0"),
    ("raw units: 1 % scale and cross-axis errors, 20 mg", "calibrated=0"),
    ("slow hand (level 0)", "level=0"),
    ("fast hand (level 1)", "level=1"),
    ("base rotation x0.3", "base=0.3"),
    ("base rotation x0.1 (axis poorly excited)", "base=0.1"),
    ("slow joint (up to 0.1 Hz)", "joint_band=0.1"),
)


def print_table(title: str, rows: list[tuple[str, dict[str, float]]], with_qmt: bool) -> None:
    print(f"\n{title}")
    head = (f"{'recording':<34} {'joint':>7} {'live':>7}" + (f" {'qmt':>7}" if with_qmt else "")
            + f" {'axis j':>7} {'axis lv':>7}" + (f" {'axis q':>7}" if with_qmt else "")
            + f" {'spread':>7} {'t joint':>8} {'t live':>7}" + (f" {'t qmt':>7}" if with_qmt
                                                                 else ""))
    print(head)
    for label, r in rows:
        line = f"{label:<34} {r['joint']:7.3f} {r['live']:7.3f}"
        if with_qmt:
            line += f" {r['qmt']:7.3f}"
        line += f" {r['joint_axis']:7.3f} {r['live_axis']:7.3f}"
        if with_qmt:
            line += f" {r['qmt_axis']:7.3f}"
        line += f" {r['spread']:7.3f} {r['joint_s']:7.2f}s {r['live_s']:6.2f}s"
        if with_qmt:
            line += f" {r['qmt_s']:6.2f}s"
        print(line, flush=True)
    keys = ["joint", "live"] + (["qmt"] if with_qmt else [])
    for name, fn in (("mean", np.mean), ("worst", np.max)):
        cells = " ".join(f"{fn([r[k] for _, r in rows]):7.3f}" for k in keys)
        print(f"{name:<34} {cells}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=12, help="main recordings (>= 3)")
    parser.add_argument("--seconds", type=float, default=180.0)
    parser.add_argument("--no-sensitivity", action="store_true")
    parser.add_argument("--no-qmt", action="store_true", help="leave qmt out")
    parser.add_argument("--keep", metavar="DIR", help="keep (and reuse) the recordings here")
    args = parser.parse_args()
    with_qmt = not args.no_qmt
    if with_qmt:
        try:
            import qmt  # noqa: F401
        except ImportError:
            print("qmt is missing: pip install '.[bench-joint]' (or run with --no-qmt)")
            return 1
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(args.keep) if args.keep else Path(scratch)
        print("RMSE (deg) of the joint angle from 10 s on, up to sign and offset; axis error "
              "(deg); spread: the axis over the recording's quarters (deg); times in s")
        rows = []
        for trial in main_trials(args.trials):
            label = trial.label + (f" j{trial.joint}" if trial.joint != 1 else "")
            rows.append((label, run_trial(trial, args.seconds, root, with_qmt)))
            r = rows[-1][1]
            print(f"  {label}: joint {r['joint']:.3f}, live {r['live']:.3f}"
                  + (f", qmt {r['qmt']:.3f}" if with_qmt else "")
                  + f", perfect orientations {r['ideal']:.3f}", flush=True)
        print_table(f"Main set ({len(rows)} hinges, {args.seconds:g} s at 208 Hz)", rows,
                    with_qmt)
        if not args.no_sensitivity:
            srows = []
            for title, option in SENSITIVITY:
                scores = []
                for seed in (1, 2, 3, 4):
                    url = f"sim://arm?odr=208&seed={seed}&{option}"
                    trial = Trial(f"sens-{option.replace('=', '')}-s{seed}", url)
                    scores.append(run_trial(trial, args.seconds, root, with_qmt))
                mean = {k: float(np.mean([s[k] for s in scores])) for k in scores[0]}
                srows.append((title, mean))
                print(f"  {title}: joint {mean['joint']:.3f}"
                      + (f", qmt {mean['qmt']:.3f}" if with_qmt else ""), flush=True)
            print_table("Sensitivity (mean over seeds 1-4; level 0.5, band 0.5 unless "
                        "varied)", srows, with_qmt)
    return 0


if __name__ == "__main__":
    sys.exit(main())
