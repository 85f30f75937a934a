"""How the EKF's heading on real, turned motion depends on its magnetometer settings.

BROAD's trials (Laidig, Caruso, Cereatti, Seel 2021, Data 6(7):72, CC BY 4.0) with each
trial's sensor frame turned by a fixed rotation (accelerometer, gyroscope, magnetometer and
reference alike: ``a' = R a``, ``q_ref' = q_ref R^-1``), so that only the magnetometer can find
north. Metric (BROAD's ``calculateRMSE``): ``e = q_est q_ref^-1``; heading error
``2 atan(|e_z / e_w|)``, inclination error ``2 acos(sqrt(e_w^2 + e_z^2))``; RMSE over the
movement rows with a reference, then the mean over the trials.

Prints the per-trial heading and inclination with and without disturbance rejection (and the
6-axis EKF's inclination), the means on a tuning half and a held-out half, and the mean heading
with each disturbance setting halved and doubled.

    .venv/bin/python benchmarks/heading_sensitivity.py [TRIAL.csv ...] [--turn 20,-30,110]
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import math
import sys
import time
from pathlib import Path

import numpy as np

from app.core import quaternion as quat
from app.core.filters.ekf import QuaternionEKF
from app.core.recording.reader import read_recording
from app.core.samples import SampleBlock, slice_block

DEFAULT_GLOB = str(Path(__file__).resolve().parents[2] / "shared" / "datasets" / "broad" / "*.csv")
DEFAULT_TURN_DEG = (20.0, -30.0, 110.0)
VQF_9D_HEADING = {  # online VQF 9D (vqf 2.1.2, defaults) on the turned trials, for the bar
    "01": 1.89, "04": 0.73, "06": 3.95, "08": 2.84, "10": 1.78, "14": 0.61, "15": 2.26,
    "24": 1.42, "26": 1.66, "28": 3.86, "30": 2.25, "32": 7.65,
}
EXTRA_SETTINGS = ("new_first_time_s", "min_undisturbed_s", "ref_tau_s", "rejection_factor",
                  "current_tau_s", "new_min_gyro_dps")
"""Detector settings that are not filter parameters (DisturbanceSettings' fields)."""


@dataclasses.dataclass
class Trial:
    name: str
    samples: SampleBlock
    mask: np.ndarray


def turn_block(samples: SampleBlock, rotvec_rad: np.ndarray) -> SampleBlock:
    """The block with its sensor frame turned by ``rotvec_rad`` (see the module docstring)."""
    turn = quat.from_rotation_vector(np.asarray(rotvec_rad, dtype=float)[None])[0]
    matrix = quat.rotate(np.tile(turn, (3, 1)), np.eye(3)).T  # columns: the turned axes
    ref = samples.reference_quat
    if ref is not None:
        inverse = np.array([turn[0], -turn[1], -turn[2], -turn[3]])
        ref = quat.multiply(ref, np.tile(inverse, (len(ref), 1)))
    mag = None if samples.mag_ut is None else samples.mag_ut @ matrix.T
    return SampleBlock(samples.t_s, samples.accel_m_s2 @ matrix.T,
                       samples.gyro_rad_s @ matrix.T, samples.temp_degc, samples.gap, ref, mag)


def load(paths: list[str], rotvec_rad: np.ndarray) -> list[Trial]:
    trials = []
    for path in paths:
        recording = read_recording(path)
        samples = turn_block(recording.sample_block(recording.calibration), rotvec_rad)
        columns = recording.unknown_columns
        movement = (np.asarray(columns["movement"]) > 0.5 if "movement" in columns
                    else np.ones(len(samples), bool))
        mask = movement & np.all(np.isfinite(samples.reference_quat), axis=1)
        trials.append(Trial(Path(path).stem, samples, mask))
    return trials


def _errors_deg(estimate: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """Heading and inclination RMSE (degrees) of ``estimate`` against ``reference``."""
    inverse = reference * np.array([1.0, -1.0, -1.0, -1.0])
    e = quat.multiply(estimate, inverse)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    heading = np.degrees(2.0 * np.arctan(np.abs(e[:, 3] / e[:, 0])))
    inclination = np.degrees(2.0 * np.arccos(np.clip(np.sqrt(e[:, 0] ** 2 + e[:, 3] ** 2),
                                                     0.0, 1.0)))
    return float(np.sqrt(np.mean(heading**2))), float(np.sqrt(np.mean(inclination**2)))


def make_filter(values: dict, settings: dict | None = None) -> QuaternionEKF:
    ekf = QuaternionEKF(**values)
    if settings:
        base = ekf.disturbance_settings

        def patched() -> object:
            return dataclasses.replace(base(), **settings)

        ekf.disturbance_settings = patched  # type: ignore[method-assign]
    return ekf


def score(trials: list[Trial], values: dict, settings: dict | None = None
          ) -> np.ndarray:
    """(trials, 2): heading and inclination RMSE per trial."""
    out = np.empty((len(trials), 2))
    for i, trial in enumerate(trials):
        estimate = make_filter(values, settings).process(trial.samples).quat
        out[i] = _errors_deg(estimate[trial.mask], trial.samples.reference_quat[trial.mask])
    return out


def speed(trials: list[Trial], block_size: int = 65536, repeats: int = 3) -> int:
    """Batch throughput of the EKF on the trials (a field on every row), best of
    ``repeats``, with the field and without it. Timed in process CPU time, so that other
    programs on a shared machine weigh less."""
    total = sum(len(t.samples) for t in trials)
    for label, values, keep_field in (("field on every row", {}, 1),
                                      ("field on every 3rd row", {}, 3),
                                      ("rejection off, every row", {"mag_rejection": False}, 1),
                                      ("no field (6-axis)", {}, 0)):
        best = math.inf
        for _ in range(repeats):
            elapsed = 0.0
            for trial in trials:
                ekf = QuaternionEKF(**values)
                samples = dataclasses.replace(trial.samples, mag_ut=None)
                if keep_field:
                    mag = np.full_like(trial.samples.mag_ut, np.nan)
                    mag[::keep_field] = trial.samples.mag_ut[::keep_field]
                    samples = dataclasses.replace(trial.samples, mag_ut=mag)
                for start in range(0, len(samples), block_size):
                    piece = slice_block(samples, start, start + block_size)
                    began = time.process_time()
                    ekf.process(piece)
                    elapsed += time.process_time() - began
            best = min(best, elapsed)
        print(f"ekf, {label:<26} {total / best / 1e6:6.2f} M samples/s ({total} samples)")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="*", help=f"recordings (default {DEFAULT_GLOB})")
    parser.add_argument("--turn", default=",".join(f"{v:g}" for v in DEFAULT_TURN_DEG),
                        help="rotation vector of the turn, degrees (default %(default)s)")
    parser.add_argument("--no-table", action="store_true", help="skip the sensitivity table")
    parser.add_argument("--speed", action="store_true",
                        help="only time the EKF with and without the field (samples/s)")
    args = parser.parse_args()
    paths = args.trials or sorted(glob.glob(DEFAULT_GLOB))
    if not paths:
        print(f"no trials at {DEFAULT_GLOB}", file=sys.stderr)
        return 2
    rotvec = np.radians([float(v) for v in args.turn.split(",")])
    trials = load(paths, rotvec)
    if args.speed:
        return speed(trials)
    on = score(trials, {})
    off = score(trials, {"mag_rejection": False})
    six = score(trials, {"magnetometer": False})
    print(f"{len(trials)} trials turned by {args.turn} deg; RMSE over movement, degrees")
    print(f"{'trial':<44} {'heading':>8} {'no rej.':>8} {'VQF 9D':>7} "
          f"{'incl.':>6} {'no rej.':>8} {'6-axis':>7} {'6-axis heading':>15}")
    for i, trial in enumerate(trials):
        bar = VQF_9D_HEADING.get(trial.name[:2], math.nan)
        print(f"{trial.name:<44} {on[i, 0]:8.2f} {off[i, 0]:8.2f} {bar:7.2f} "
              f"{on[i, 1]:6.2f} {off[i, 1]:8.2f} {six[i, 1]:7.2f} {six[i, 0]:15.2f}")
    halves = {"tuning (even rows)": slice(0, None, 2), "held out (odd rows)": slice(1, None, 2),
              "all": slice(None)}
    for label, part in halves.items():
        bars = [VQF_9D_HEADING.get(t.name[:2], math.nan) for t in trials[part]]
        print(f"mean, {label:<20} heading {on[part, 0].mean():.3f} (no rejection "
              f"{off[part, 0].mean():.3f}, VQF 9D {np.mean(bars):.2f}); inclination "
              f"{on[part, 1].mean():.3f} (6-axis {six[part, 1].mean():.3f})")
    if args.no_table:
        return 0
    base = on[:, 0].mean()
    print()
    print(f"{'setting':<22} {'default':>9}   {'x0.5':>15}   {'x2':>15}")
    cells_for = []
    for spec in QuaternionEKF.parameters:
        if spec.name.startswith("mag_") and spec.kind != "bool":
            cells_for.append((spec.name, spec.default, spec, None))
    defaults = dataclasses.asdict(QuaternionEKF().disturbance_settings())
    for name in EXTRA_SETTINGS:
        cells_for.append((name, defaults[name], None, name))
    for name, default, spec, setting in cells_for:
        cells = []
        for factor in (0.5, 2.0):
            value = default * factor
            if spec is not None:
                value = min(max(value, spec.minimum), spec.maximum)
                result = score(trials, {name: value})
            else:
                result = score(trials, {}, {setting: value})
            mean = result[:, 0].mean()
            cells.append(f"{mean:.3f} ({mean - base:+.3f})")
        print(f"{name:<22} {default:>9g}   {cells[0]:>15}   {cells[1]:>15}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
