"""Pipeline throughput: samples/s through conversion, calibration, filter and ring buffer.

Blocks come from the simulator at 6667 Hz (generated beforehand, so only the pipeline is
timed). A real calibration (non-identity) is applied so that stage costs what it will.

    .venv/bin/python benchmarks/pipeline_throughput.py [--seconds 120]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from app.core.calibration import SensorCalibration
from app.core.filters import ONLINE_FILTERS
from app.core.pipeline import Pipeline
from drivers.registry import open_device


def generate_blocks(seconds: float, block: int) -> list:
    url = f"sim://wobble?odr=6667&realtime=0&block={block}&seed=7"
    device = open_device(url)
    total = int(seconds * device.info.odr_hz)
    blocks, count = [], 0
    while count < total:
        raw = device.read(1.0)
        blocks.append(raw)
        count += len(raw)
    device.close()
    return blocks


def measure(blocks: list, filter_name: str, repeats: int = 3) -> float:
    calibration = SensorCalibration(
        accel_bias_m_s2=np.array([0.1, -0.05, 0.2]), accel_matrix=np.eye(3) * 1.01,
        gyro_bias_rad_s=np.array([0.01, 0.0, -0.01]), name="benchmark",
    )
    n = sum(len(b) for b in blocks)
    best = 0.0
    for _ in range(repeats):
        pipeline = Pipeline(odr_hz=6667.0, filter_name=filter_name)
        pipeline.set_calibration(calibration)
        pipeline.filter.warm_up()
        start = time.perf_counter()
        for raw in blocks:
            pipeline.process(raw)
        best = max(best, n / (time.perf_counter() - start))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="stream length per run")
    args = parser.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    print(f"stream: simulator 'wobble' at 6667 Hz, {args.seconds:g} s per run, best of 3")
    print(f"{'filter':<16}{'block':>8}{'samples/s':>14}{'x 6667 Hz':>12}")
    for block in (64, 512, 4096):
        blocks = generate_blocks(args.seconds, block)
        for name in ONLINE_FILTERS:
            rate = measure(blocks, name)
            print(f"{name:<16}{block:>8}{rate:>14,.0f}{rate / 6667:>12.0f}")


if __name__ == "__main__":
    main()
