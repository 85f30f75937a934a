"""Temperature compensation on the simulator's drift: bias and tilt error over a warm-up.

1. A six-position calibration of the simulated unit from a recorded tour (cold, as a lab
   would do it first): biases and matrices at the tour's temperature.
2. A level warm-up (``sim://static?warmup=RISE:TAU``) gives the temperature fit
   (``inclinometer calibrate-temperature``'s code), merged onto that calibration.
3. A second warm-up of the same unit, tilted and at twice the rate (so that its bias random
   walk is not the one the fit saw), runs through the pipeline (EKF) with the
   six-position calibration alone and with the temperature terms added; per stretch of the
   warm-up the table shows the gyro and accelerometer bias error (calibrated mean at rest
   against the truth) and the tilt error (EKF and accelerometer-only, against the true
   orientation).
4. The fitted coefficients against the simulator's truth.

Usage: ``.venv/bin/python benchmarks/temperature_compensation.py [--seed 3] [--rise 20]
[--tau 300] [--minutes 25]``
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.core.calibration_procedures import SensorSettings
from app.core.calibration_procedures.offline import calibrate_stream
from app.core.calibration_procedures.temperature import (
    QUADRATIC,
    fit_temperature,
    merge_temperature,
    truth_of,
)
from app.core.evaluation import concatenate_blocks
from app.core.orientation import up_in_sensor_frame
from app.core.pipeline import Pipeline
from app.core.samples import STANDARD_GRAVITY_M_S2, convert_raw_block
from drivers.sim.device import SimulatedDevice

MDPS = 180.0 / math.pi * 1e3
MG = 1e3 / STANDARD_GRAVITY_M_S2


def capture(url: str, seconds: float):
    device = SimulatedDevice(url, realtime=False, block=4096)
    info = device.open()
    blocks, n = [], 0
    while n < seconds * info.odr_hz:
        block = convert_raw_block(device.read(1.0))
        blocks.append(block)
        n += len(block)
    device.close()
    block = concatenate_blocks(blocks)
    keep = block.t_s < block.t_s[0] + seconds
    from dataclasses import replace

    block = replace(block, t_s=block.t_s[keep], accel_m_s2=block.accel_m_s2[keep],
                    gyro_rad_s=block.gyro_rad_s[keep], temp_degc=block.temp_degc[keep],
                    gap=block.gap[keep], reference_quat=block.reference_quat[keep])
    return block, SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps), device


def run(url: str, seconds: float, calibration):
    """Calibrated samples, EKF inclination error and temperature of ``url`` in the pipeline."""
    device = SimulatedDevice(url, realtime=False, block=1024)
    device.open()
    pipeline = Pipeline(device.odr_hz, "ekf")
    pipeline.set_calibration(calibration)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("t", "accel", "gyro", "temp", "ref",
                                                          "incl")}
    total = 0
    while total < seconds * device.odr_hz:
        block = pipeline.process(device.read(1.0))
        n = len(block)
        total += n
        parts["t"].append(block.t_s)
        parts["accel"].append(block.accel_m_s2)
        parts["gyro"].append(block.gyro_rad_s)
        parts["temp"].append(block.temp_degc)
        parts["ref"].append(block.reference_quat)
        parts["incl"].append(pipeline.orientation.latest(n)["incl_error"])
    device.close()
    return {k: np.concatenate(v) for k, v in parts.items()}


def accel_tilt_error_deg(accel_mean: np.ndarray, up: np.ndarray) -> float:
    cos = float(accel_mean @ up / np.linalg.norm(accel_mean) / np.linalg.norm(up))
    return math.degrees(math.acos(min(1.0, cos)))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--rise", type=float, default=20.0, help="warm-up, degC")
    parser.add_argument("--tau", type=float, default=300.0, help="warm-up time constant, s")
    parser.add_argument("--minutes", type=float, default=25.0, help="each warm-up's length")
    parser.add_argument("--odr", type=float, default=26.0)
    args = parser.parse_args()
    started = time.perf_counter()
    seconds = args.minutes * 60.0
    warm = f"warmup={args.rise:g}:{args.tau:g}&odr={args.odr:g}&seed={args.seed}&realtime=0"

    # 1. the six-position calibration, cold
    tour, tour_settings, device = capture(f"sim://tour?odr=52&seed={args.seed}&realtime=0", 50)
    six = calibrate_stream(tour, tour_settings)
    unit = device.unit_errors
    print(f"unit seed {args.seed} ({device.unique_id}): ambient {unit.ambient_degc:.2f} degC")
    print(f"1. six-position calibration on a 50 s tour at {six.temperature_degc:.2f} degC: "
          f"{len(six.poses)} poses, residual {six.fit.residual_norm_rms_mg:.3f} mg")

    # 2. the temperature fit on a level warm-up
    block, settings, _ = capture(f"sim://static?{warm}", seconds)
    fit = fit_temperature(block, settings)
    calibration, how = merge_temperature(fit, six.calibration, six.temperature_degc,
                                         name="six-position + temperature")
    print(f"2. temperature fit on a level warm-up of {args.minutes:g} min "
          f"(sim://static?{warm}): {fit.temp_min_degc:.2f} to {fit.temp_max_degc:.2f} degC, "
          f"{len(fit.bin_temp_degc)} bins; gyro "
          f"{'quadratic' if fit.gyro.degree == QUADRATIC else 'linear'}, accel "
          f"{'quadratic' if fit.accel.degree == QUADRATIC else 'linear'}")
    print(f"   {how}")

    # 3. another warm-up, tilted, through the pipeline
    # At twice the rate: the same unit (seed) draws the same random-walk steps per sample, so
    # a different rate gives this run a bias walk of its own (the fit never saw it).
    url = (f"sim://static?roll=15&pitch=-10&warmup={args.rise:g}:{args.tau:g}"
           f"&odr={2 * args.odr:g}&seed={args.seed}&realtime=0")
    runs = {"without": run(url, seconds, six.calibration), "with": run(url, seconds, calibration)}
    t = runs["with"]["t"] - runs["with"]["t"][0]
    up = up_in_sensor_frame(runs["with"]["ref"][0])
    true_force = up * STANDARD_GRAVITY_M_S2
    edges = [0, 30, 60, 120, 240, 480, 900, seconds - 60, seconds]
    print(f"3. a second warm-up, tilted (roll 15, pitch -10), through the pipeline (EKF); "
          f"errors without / with temperature compensation ({url}):")
    header = (f"   {'t (s)':>11} {'T (degC)':>8} | {'gyro bias err (mdps)':>21} | "
              f"{'accel bias err (mg)':>19} | {'EKF tilt err (deg)':>19} | "
              f"{'accel tilt err (deg)':>20}")
    print(header)
    print("   " + "-" * (len(header) - 3))
    worst = {k: np.zeros(4) for k in runs}
    for a, b in itertools.pairwise(edges):
        rows = (t >= a) & (t < b)
        temp = float(runs["with"]["temp"][rows].mean())
        cells = {}
        for key, data in runs.items():
            gyro = np.linalg.norm(data["gyro"][rows].mean(axis=0)) * MDPS
            accel_mean = data["accel"][rows].mean(axis=0)
            accel = np.linalg.norm(accel_mean - true_force) * MG
            ekf = float(np.nanmean(data["incl"][rows]))
            tilt = accel_tilt_error_deg(accel_mean, up)
            cells[key] = (gyro, accel, ekf, tilt)
            worst[key] = np.maximum(worst[key], cells[key])
        w, c = cells["without"], cells["with"]
        print(f"   {a:5.0f}-{b:5.0f} {temp:8.2f} | {w[0]:9.2f} / {c[0]:9.2f} | "
              f"{w[1]:8.3f} / {c[1]:8.3f} | {w[2]:8.4f} / {c[2]:8.4f} | "
              f"{w[3]:9.4f} / {c[3]:8.4f}")
    w, c = worst["without"], worst["with"]
    print(f"   {'worst':>11} {'':>8} | {w[0]:9.2f} / {c[0]:9.2f} | {w[1]:8.3f} / {c[1]:8.3f} "
          f"| {w[2]:8.4f} / {c[2]:8.4f} | {w[3]:9.4f} / {c[3]:8.4f}")

    # 4. fitted against true
    truth = truth_of(fit, unit.as_dict())
    model = calibration.temperature
    print("4. fitted coefficients against the simulator's truth (x, y, z):")
    rows = [
        ("gyro k1 (mdps/degC)", model.gyro_k1 * MDPS, truth.gyro_k1 * MDPS),
        ("gyro k2 (mdps/degC^2)", model.gyro_k2 * MDPS, np.zeros(3)),
        ("accel k1 (mg/degC), level pose", model.accel_k1 * MG, truth.accel_k1 * MG),
        ("accel k2 (mg/degC^2)", model.accel_k2 * MG, np.zeros(3)),
    ]
    for name, fitted, true in rows:
        print(f"   {name:<32} fitted {' '.join(f'{v:+9.5f}' for v in fitted)}")
        print(f"   {'':<32} truth  {' '.join(f'{v:+9.5f}' for v in true)}")
    print(f"   (accel bias coefficient alone: "
          f"{' '.join(f'{v:+.5f}' for v in truth.accel_bias_k1 * MG)} mg/degC; the level "
          "pose adds the z sensitivity drift x 1 g)")
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
