"""Cost of the fault detector at the LSM6DSOX's top rate (issue 33: under 3 % of one core).

Streams simulated ``sim://wobble`` at 6667 Hz through :class:`FaultDetector` in blocks of a
typical live size and prints the CPU time per second of data, as a share of one core.

    .venv/bin/python benchmarks/fault_detector_cost.py [--seconds 60] [--mag lis3mdl]

``--mag CHIP`` gives the simulated sensor a magnetometer (``lis3mdl``: 1000 Hz at the top
accelerometer rates; ``lis2mdl``: 100 Hz): its checks and the field part of the gyro bias test
run too (the field taken as calibrated, as for a calibrated sensor).
"""

from __future__ import annotations

import argparse
import time

from app.core.faults import FaultDetector, SensorSpec
from app.core.samples import convert_raw_block
from drivers.sim.device import SimulatedDevice


def measure(odr: float, block: int, seconds: float, mag: str = "") -> tuple[float, int]:
    """CPU seconds per second of data and the number of events, for one block size."""
    field = f"&mag={mag}&errors=0" if mag else ""
    device = SimulatedDevice(f"sim://wobble?odr={odr:g}&realtime=0&block={block}{field}")
    info = device.open()
    blocks = []
    count = 0
    while count < seconds * info.odr_hz:
        raw = device.read(0.1)
        blocks.append((convert_raw_block(raw), raw))
        count += len(raw)
    detector = FaultDetector(SensorSpec.from_device_info(info, device.scale))
    detector.field_calibrated = bool(mag)  # an ideal chip (errors=0): nothing to calibrate
    detector.update(*blocks[0])  # compile outside the timing
    detector.reset()
    start = time.process_time()
    for sample_block, raw in blocks:
        detector.update(sample_block, raw)
    used = time.process_time() - start
    return used / (count / info.odr_hz), len(detector.events)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--mag", default="", help="a magnetometer beside it: lis3mdl, lis2mdl")
    args = parser.parse_args()
    print(f"{'ODR Hz':>7} {'block':>6} {'blocks/s':>9} {'% of a core':>12} {'events':>7}")
    for odr, block in [(6667, 67), (6667, 134), (6667, 667), (6667, 6667), (104, 3), (104, 26)]:
        share, events = measure(odr, block, args.seconds, args.mag)
        print(f"{odr:7g} {block:6d} {odr / block:9.1f} {100 * share:11.2f}% {events:7d}")


if __name__ == "__main__":
    main()
