"""Allan-variance noise figures of the simulated LSM6DSOX against the simulator's truth.

For each seed (simulated unit) a static stream of ``--minutes`` is read from the simulator as
fast as it computes, from power-up (the board warms by 1.5-4 degC in the first minutes; the
analysis regresses the temperature out) or after ``--warmup`` minutes. The Allan analysis of
``inclinometer allan`` (app/core/allan.py) runs on it; printed per unit and axis: the relative
error of the noise density (truth: the datasheet density the simulator adds) and of the bias
random walk (truth: the unit's walk), and at the end how many axes meet the goals of issue 16
(noise density within 10 %, random walk within 35 %).

    .venv/bin/python benchmarks/allan_truth.py --minutes 30 60 --seeds 8 --synthetic 20

``--method`` picks the estimator of N and K (default ``likelihood``, the time-domain fit;
``allan-fit`` the older fit of the Allan curve). After each summary, ``bound`` is the Cramer-Rao
limit for the units' walks (the least scatter of ln K any unbiased estimator reaches from that
much data, with N unknown too) and the share of axes within 35 % that such an estimator would
get: what the data allow, whatever the method.

A walk shows only where it rises above the white noise: from tau ~ 1.2 N / K, 25-100 s for
the simulated accelerometer but 200-500 s for the gyroscope, so 30 or 60 minutes hold only a
few independent clusters of gyro walk. ``--synthetic`` repeats the check on numpy white noise
plus a random walk with the same figures: the estimators' own scatter (the likelihood's
posterior median, its maximum, and the Allan fit), with no simulator.

Both density conventions are printed against the truth: the datasheet's one-sided density
(a sample scatters by N sqrt(fs/2), what the simulator adds) and the Allan/Kalibr one
(N / sqrt(2): a sample scatters by N sqrt(fs)), and the figures of ``allan --kalibr``'s file
(the mean of the axes) against the truth in Kalibr's convention. ``--kalibr-synthetic HOURS``
generates white noise and a bias walk exactly as Kalibr's discrete model does
(``sigma / sqrt(dt)`` per sample, walk steps ``sigma_b sqrt(dt)``) and reads both back.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.core.allan import (
    METHODS,
    ONE_SIDED_PER_ALLAN,
    analyse_static,
    axis_noise,
    fit_white_and_walk,
    random_walk_bound,
)
from app.core.interop.kalibr import kalibr_figures
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.services.calibration_runs import capture_device

GYRO_DENSITY = math.radians(3.8e-3)
ACCEL_DENSITY = 70e-6 * STANDARD_GRAVITY_M_S2
NOISE_GOAL = 0.10
WALK_GOAL = 0.35


def within_goal_share(log_sd: float, goal: float = WALK_GOAL) -> float:
    """P(|K_hat / K - 1| <= goal) for ln K_hat ~ normal(ln K, log_sd)."""
    def phi(v: float) -> float:
        return 0.5 * (1.0 + math.erf(v / math.sqrt(2.0)))

    return phi(math.log1p(goal) / log_sd) - phi(math.log1p(-goal) / log_sd)


def run(minutes: float, seeds: int, odr: float, warmup: float, method: str
        ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    errors: dict[str, list[float]] = {"gyro N": [], "accel N": [], "gyro N_allan": [],
                                      "accel N_allan": [], "gyro K": [], "accel K": []}
    kalibr: list[dict[str, float]] = []
    bounds: dict[str, list[float]] = {"gyro K": [], "accel K": []}
    print(f"\n{minutes:g} min static at {odr:g} Hz, after {warmup:g} min of warm-up "
          f"(method: {method})")
    print(f"{'seed':>4}  {'dT degC':>7}  {'gyro N err %':>20}  {'accel N err %':>20}  "
          f"{'gyro K err %':>22}  {'accel K err %':>22}")
    for seed in range(1, seeds + 1):
        stream = capture_device(f"sim://static?odr={odr:g}&seed={seed}&realtime=0&block=65536",
                                (minutes + warmup) * 60.0)
        unit = stream.unit_errors or {}
        block = stream.block
        start = round(warmup * 60.0 * stream.settings.odr_hz)
        result = analyse_static(block.gyro_rad_s[start:], block.accel_m_s2[start:],
                                stream.settings.odr_hz, block.temp_degc[start:],
                                method=method)
        rows = {
            "gyro N": result.gyro.noise_density / GYRO_DENSITY - 1.0,
            "accel N": result.accel.noise_density / ACCEL_DENSITY - 1.0,
            "gyro N_allan": result.gyro.noise_density_allan
            / (GYRO_DENSITY / ONE_SIDED_PER_ALLAN) - 1.0,
            "accel N_allan": result.accel.noise_density_allan
            / (ACCEL_DENSITY / ONE_SIDED_PER_ALLAN) - 1.0,
            "gyro K": result.gyro.random_walk / unit["gyro_bias_walk_rad_s_per_sqrt_s"] - 1.0,
            "accel K": result.accel.random_walk / unit["accel_bias_walk_m_s2_per_sqrt_s"] - 1.0,
        }
        for key, value in rows.items():
            errors[key].extend(value.tolist())
        if result.duration_s >= 1800.0:
            truth = kalibr_truth(unit)
            kalibr.append({k: v / truth[k] - 1.0 for k, v in kalibr_figures(result).items()})
        for key, density, walk in (
                ("gyro K", GYRO_DENSITY, unit["gyro_bias_walk_rad_s_per_sqrt_s"]),
                ("accel K", ACCEL_DENSITY, unit["accel_bias_walk_m_s2_per_sqrt_s"])):
            bounds[key].extend([random_walk_bound(density, walk, stream.settings.odr_hz,
                                                  minutes * 60.0)] * 3)

        def cells(values: np.ndarray, width: int) -> str:
            return f"{' '.join(f'{100 * v:+6.1f}' for v in values):>{width}}"

        print(f"{seed:>4}  {result.temperature_span_degc:7.2f}  {cells(rows['gyro N'], 20)}  "
              f"{cells(rows['accel N'], 20)}  {cells(rows['gyro K'], 22)}  "
              f"{cells(rows['accel K'], 22)}")
    if kalibr:
        print("  allan --kalibr's figures (mean of the axes) against the truth in Kalibr's "
              "convention, error %:")
        for key in kalibr[0]:
            values = np.array([row[key] for row in kalibr])
            print(f"    {key:<28} " + " ".join(f"{100 * v:+6.1f}" for v in values)
                  + f"   median {100 * np.median(values):+.1f}")
    return ({key: np.array(values) for key, values in errors.items()},
            {key: np.array(values) for key, values in bounds.items()})


def kalibr_truth(unit: dict) -> dict[str, float]:
    """A simulated unit's figures in Kalibr's convention (the simulator adds the datasheet's
    one-sided densities; Kalibr's is that over sqrt(2); the walks are the same)."""
    return {
        "accelerometer_noise_density": ACCEL_DENSITY / ONE_SIDED_PER_ALLAN,
        "accelerometer_random_walk": float(np.mean(unit["accel_bias_walk_m_s2_per_sqrt_s"])),
        "gyroscope_noise_density": GYRO_DENSITY / ONE_SIDED_PER_ALLAN,
        "gyroscope_random_walk": float(np.mean(unit["gyro_bias_walk_rad_s_per_sqrt_s"])),
    }


def kalibr_synthetic(hours: float, odr: float, seed: int = 7) -> None:
    """White noise and bias walks generated as Kalibr's discrete model does, read back."""
    rng = np.random.default_rng(seed)
    n = round(hours * 3600.0 * odr)
    dt = 1.0 / odr
    truth = {"gyroscope_noise_density": 1.6e-4, "gyroscope_random_walk": 2.0e-6,
             "accelerometer_noise_density": 1.2e-3, "accelerometer_random_walk": 6.0e-5}

    def axis(density: float, walk: float) -> np.ndarray:
        return (rng.standard_normal(n) * density / math.sqrt(dt)
                + np.cumsum(rng.standard_normal(n)) * walk * math.sqrt(dt))

    gyro = np.column_stack([axis(truth["gyroscope_noise_density"],
                                 truth["gyroscope_random_walk"]) for _ in range(3)])
    accel = np.column_stack([axis(truth["accelerometer_noise_density"],
                                  truth["accelerometer_random_walk"]) for _ in range(3)])
    result = analyse_static(gyro, accel + np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2]), odr)
    measured = kalibr_figures(result)
    print(f"\nKalibr-convention synthetic data, {hours:g} h at {odr:g} Hz (3 axes each):")
    print(f"  {'figure':<28} {'truth (Kalibr)':>14} {'allan --kalibr':>14} {'error':>8}   "
          "datasheet 1-sided: measured vs truth*sqrt(2)")
    for key, value in truth.items():
        one_sided = ""
        if key.endswith("noise_density"):
            sensor = result.gyro if key.startswith("gyro") else result.accel
            measured_one_sided = float(np.mean(sensor.noise_density_one_sided))
            one_sided = (f"{measured_one_sided:.4g} vs {value * ONE_SIDED_PER_ALLAN:.4g} "
                         f"({100 * (measured_one_sided / (value * ONE_SIDED_PER_ALLAN) - 1):+.1f}"
                         " %)")
        print(f"  {key:<28} {value:14.4g} {measured[key]:14.4g} "
              f"{100 * (measured[key] / value - 1):+7.1f}%   {one_sided}")


def summary(errors: dict[str, np.ndarray], bounds: dict[str, np.ndarray]) -> None:
    for key, values in errors.items():
        goal = WALK_GOAL if key.endswith("K") else NOISE_GOAL
        inside = np.mean(np.abs(values) <= goal)
        worst = values[np.argmax(np.abs(values))]
        print(f"  {key:<13} within {100 * goal:.0f} %: {100 * inside:5.1f} % of axes; median "
              f"error {100 * np.median(values):+.1f} %, worst {100 * worst:+.1f} %")
    for key, sd in bounds.items():
        share = np.mean([within_goal_share(v) for v in sd])
        print(f"  {key:<8} bound: sd(ln K) >= {sd.min():.2f}..{sd.max():.2f} (Cramer-Rao); an "
              f"efficient unbiased estimator gets {100 * share:.0f} % of these axes within 35 %")


def synthetic(minutes: float, repeats: int, odr: float) -> None:
    """The estimators alone: white noise + random walk with the simulator's gyro figures."""
    rng = np.random.default_rng(1)
    n = round(minutes * 60.0 * odr)
    for walk_deg_h in (2.0, 5.0):
        k = math.radians(walk_deg_h / 3600.0) / 60.0
        errors: dict[str, list[float]] = {"likelihood": [], "its maximum": [], "allan-fit": []}
        for _ in range(repeats):
            x = (rng.standard_normal(n) * GYRO_DENSITY * math.sqrt(odr / 2.0)
                 + np.cumsum(rng.standard_normal(n)) * k / math.sqrt(odr))
            fit = fit_white_and_walk(x, odr)
            errors["likelihood"].append(fit.random_walk / k - 1.0)
            errors["its maximum"].append(fit.random_walk_ml / k - 1.0)
            errors["allan-fit"].append(axis_noise(x, odr, method="allan-fit").random_walk / k
                                       - 1.0)
        bound = random_walk_bound(GYRO_DENSITY, k, odr, minutes * 60.0)
        print(f"  synthetic gyro walk {walk_deg_h:g} deg/h/sqrt(h), {minutes:g} min, {repeats} "
              f"records; bound sd(ln K) {bound:.2f}, {100 * within_goal_share(bound):.0f} % "
              "within 35 %:")
        for name, values in errors.items():
            e = np.array(values)
            print(f"    {name:<12} within 35 % in {100 * np.mean(np.abs(e) <= WALK_GOAL):3.0f} %;"
                  f" median {100 * np.median(e):+6.1f} %, zero in {np.sum(e == -1.0)}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[30.0, 60.0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--odr", type=float, default=104.0)
    parser.add_argument("--warmup", type=float, default=0.0, help="minutes skipped first")
    parser.add_argument("--synthetic", type=int, default=0, metavar="REPEATS",
                        help="also check the estimators on synthetic gyro data")
    parser.add_argument("--method", choices=METHODS, default="likelihood",
                        help="estimator of N and K (default %(default)s)")
    parser.add_argument("--kalibr-synthetic", type=float, default=0.0, metavar="HOURS",
                        help="also read back white noise + walk generated in Kalibr's model")
    args = parser.parse_args()
    if args.kalibr_synthetic:
        kalibr_synthetic(args.kalibr_synthetic, args.odr)
    for minutes in args.minutes:
        errors, bounds = run(minutes, args.seeds, args.odr, args.warmup, args.method)
        summary(errors, bounds)
        if args.synthetic:
            synthetic(minutes, args.synthetic, args.odr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
