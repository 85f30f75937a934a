"""Orientation-filter speed: batch throughput per filter, and the live cost of all together.

The stream is the simulator's 'wobble' at 6667 Hz with the unit's static errors compensated,
generated beforehand so that only the filters are timed.

- batch: every registered filter processes the whole stream (default 10 minutes) in large
  blocks, as when replaying a recording; printed as samples/s, next to ``vqf.VQF.updateBatch``
  called directly on the same blocks (the C++ core without this project's wrapper).
- 9-axis batch: each filter that takes heading from the magnetometer (``uses_magnetometer``),
  with a field on every sample and with one every ``--mag-every`` samples (NaN between, as a
  slower magnetometer gives: 8 is an 833 Hz accelerometer beside a 104 Hz magnetometer); the
  field is the earth's, ENU, turned into the sensor frame by the true orientation.
- live: all filters together process a stream in blocks of 133 samples (20 ms at 6667 Hz),
  as the live pipeline delivers them; printed as thread CPU time over stream duration, in %
  of one core, per filter and in total.

Goals (issue "Orientation filters"): each filter >= 1 000 000 samples/s in batch; all filters
together < 25 % of one core live. Issue 32: every 9-axis filter >= 1 000 000 samples/s with the
magnetometer too.

    .venv/bin/python benchmarks/filter_speed.py [--minutes 10] [--live-seconds 60]
                                                [--mag-every 8]
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import time

import numpy as np

from app.core import quaternion as quat
from app.core.evaluation import concatenate_blocks, split_block
from app.core.filters import FILTERS, OrientationFilter
from app.core.samples import SampleBlock
from app.services.simulation import simulator_blocks

ODR_HZ = 6667
URL = f"sim://wobble?odr={ODR_HZ}&seed=7"
BATCH_GOAL = 1_000_000
LIVE_GOAL_PERCENT = 25.0
EARTH_FIELD_UT = np.array([0.0, 19.0, -45.0])
"""A mid-latitude earth field, ENU with y toward magnetic north (uT)."""


def batch_rate(orientation_filter: OrientationFilter, blocks: list[SampleBlock],
               clock=time.perf_counter) -> float:
    """Samples per second of ``clock`` time (default: wall) in ``process`` over ``blocks``."""
    orientation_filter.warm_up()
    elapsed = 0.0
    for block in blocks:
        start = clock()
        orientation_filter.process(block)
        elapsed += clock() - start
    return sum(len(b) for b in blocks) / elapsed


def vqf_direct_rate(blocks: list[SampleBlock], sample_period_s: float) -> float | None:
    """Samples per second of ``vqf.VQF.updateBatch`` itself, or None without the package."""
    try:
        import vqf
    except ImportError:
        return None
    arrays = [
        (np.ascontiguousarray(b.gyro_rad_s), np.ascontiguousarray(b.accel_m_s2)) for b in blocks
    ]
    engine = vqf.VQF(sample_period_s)
    start = time.perf_counter()
    for gyro, accel in arrays:
        engine.updateBatch(gyro, accel)
    return sum(len(b) for b in blocks) / (time.perf_counter() - start)


def vqf_direct_9d_rate(blocks: list[SampleBlock], sample_period_s: float,
                       field_period_s: float) -> float | None:
    """Samples per second of ``vqf.VQF.updateBatch`` with the field (rows without a sample as
    zeros, which VQF skips), or None without the package."""
    try:
        import vqf
    except ImportError:
        return None
    arrays = [(np.ascontiguousarray(b.gyro_rad_s), np.ascontiguousarray(b.accel_m_s2),
               np.ascontiguousarray(np.where(np.isfinite(b.mag_ut), b.mag_ut, 0.0)))
              for b in blocks]
    engine = vqf.VQF(sample_period_s, sample_period_s, field_period_s)
    start = time.perf_counter()
    for gyro, accel, field in arrays:
        engine.updateBatch(gyro, accel, field)
    return sum(len(b) for b in blocks) / (time.perf_counter() - start)


def nine_axis_batch(stream: SampleBlock, every: int, block: int, sample_period: float,
                    width: int) -> None:
    """Print each 9-axis filter's batch rate with a field on every sample and every
    ``every``-th sample: per second of wall time, and per second of the thread's CPU time
    (what the filter costs, whatever else the machine runs)."""
    sparse = stream.mag_ut.copy()
    sparse[np.arange(len(sparse)) % every != 0] = np.nan
    names = [name for name, cls in FILTERS.items() if cls.uses_magnetometer]
    print(f"\n9-axis batch: blocks of {block} samples; goal >= {BATCH_GOAL:,} samples/s")
    print(f"{'':<{width}}  {'wall':>31}  {'thread CPU':>31}")
    print(f"{'filter':<{width}}  {'field every':>14}  {f'1 in {every}':>14}  "
          f"{'field every':>14}  {f'1 in {every}':>14}  goal (CPU)")
    cases = [list(split_block(stream, block)),
             list(split_block(dataclasses.replace(stream, mag_ut=sparse), block))]
    for name in names:
        try:
            rates = [batch_rate(FILTERS[name](), blocks, clock) for clock in
                     (time.perf_counter, time.thread_time) for blocks in cases]
        except Exception as exc:  # report and go on with the others
            print(f"{name:<{width}}  error: {type(exc).__name__}: {exc}")
            continue
        verdict = "ok" if min(rates[2:]) >= BATCH_GOAL else "MISSED"  # CPU: load-independent
        print(f"{name:<{width}}  " + "  ".join(f"{r:>14,.0f}" for r in rates) + f"  {verdict}")
    direct = [vqf_direct_9d_rate(blocks, sample_period, sample_period * n)
              for blocks, n in zip(cases, (1, every), strict=True)]
    label = "vqf.VQF.updateBatch 9D (direct)"
    if direct[0] is None:
        print(f"{label:<{width}}  (vqf not installed)")
    else:
        print(f"{label:<{width}}  {direct[0]:>14,.0f}  {direct[1]:>14,.0f}")


def live_cost(names: list[str], blocks: list[SampleBlock]) -> dict[str, float]:
    """Thread CPU seconds per filter, all filters taking every block in turn."""
    filters = {name: FILTERS[name]() for name in names}
    for f in filters.values():
        f.warm_up()
    cpu = dict.fromkeys(names, 0.0)
    for block in blocks:
        for name, f in filters.items():
            start = time.thread_time()
            f.process(block)
            cpu[name] += time.thread_time() - start
    return cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="batch stream length")
    parser.add_argument("--block", type=int, default=65536, help="batch block size (samples)")
    parser.add_argument("--live-seconds", type=float, default=60.0, help="live stream length")
    parser.add_argument("--live-block", type=int, default=133, help="live block size (samples)")
    parser.add_argument("--mag-every", type=int, default=8,
                        help="9-axis: a field sample every N samples (default 8)")
    args = parser.parse_args()

    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    seconds = max(args.minutes * 60.0, args.live_seconds)
    start = time.perf_counter()
    stream = concatenate_blocks(simulator_blocks(URL, seconds))
    stream.mag_ut = quat.rotate_inverse(stream.reference_quat, EARTH_FIELD_UT)
    stream.reference_quat = None  # not needed; saves memory
    steps = np.diff(stream.t_s)
    sample_period = float(np.median(steps))
    print(f"stream: {URL}, {len(stream):,} samples ({seconds / 60:g} min at "
          f"{1 / sample_period:.0f} Hz), generated in {time.perf_counter() - start:.1f} s")

    names = list(FILTERS)
    width = max(len(n) for n in [*names, "vqf.VQF.updateBatch 9D (direct)"])
    field = stream.mag_ut
    stream.mag_ut = None  # the 6-axis figures, as before
    batch_blocks = list(split_block(stream, args.block))
    print(f"\nbatch: blocks of {args.block} samples; goal >= {BATCH_GOAL:,} samples/s")
    print(f"{'filter':<{width}}  {'samples/s':>14}  {'x realtime':>10}  goal")
    for name in names:
        try:
            rate = batch_rate(FILTERS[name](), batch_blocks)
        except Exception as exc:  # report and go on with the others
            print(f"{name:<{width}}  error: {type(exc).__name__}: {exc}")
            continue
        verdict = "ok" if rate >= BATCH_GOAL else "MISSED"
        print(f"{name:<{width}}  {rate:>14,.0f}  {rate * sample_period:>10,.0f}  {verdict}")
    direct = vqf_direct_rate(batch_blocks, sample_period)
    label = "vqf.VQF.updateBatch (direct)"
    if direct is None:
        print(f"{label:<{width}}  (vqf not installed)")
    else:
        print(f"{label:<{width}}  {direct:>14,.0f}  {direct * sample_period:>10,.0f}")

    nine_axis_batch(dataclasses.replace(stream, mag_ut=field), args.mag_every, args.block,
                    sample_period, width)

    live_n = round(args.live_seconds / sample_period)
    live_stream = next(split_block(stream, live_n))
    live_blocks = list(split_block(live_stream, args.live_block))
    duration = len(live_stream) * sample_period
    block_ms = args.live_block * sample_period * 1e3
    print(f"\nlive: {len(live_blocks):,} blocks of {args.live_block} samples ({block_ms:.1f} ms), "
          f"{duration:.0f} s of stream; thread CPU / stream time")
    cpu = live_cost(names, live_blocks)
    for name in names:
        print(f"{name:<{width}}  {100 * cpu[name] / duration:>13.2f} %")
    total = 100 * sum(cpu.values()) / duration
    verdict = "ok" if total < LIVE_GOAL_PERCENT else "MISSED"
    print(f"{'all together':<{width}}  {total:>13.2f} %  (goal < {LIVE_GOAL_PERCENT:g} %: "
          f"{verdict})")


if __name__ == "__main__":
    main()
