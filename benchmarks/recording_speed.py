"""Recording speed: write and read an hour at 1 kHz, then evaluate every filter over it.

The stream is the simulator's ``wobble`` with reference orientation, as a recording of it
holds. It is generated first (not timed), then

- written through :class:`app.core.recording.RecordingWriter` (its thread: conversion,
  formatting, writing, fsync): rows/s and MB;
- read back with :func:`app.core.recording.read_recording` (rows/s; the first read of a
  session includes loading the compiled parser from numba's cache);
- evaluated: every registered filter over the whole recording, as ``inclinometer evaluate
  IN.csv`` does (the recorded calibration applied again, one run per filter).

Goals (issue "Record and replay"): 3.6 M rows load in < 5 s; ``evaluate`` of every filter
over them in < 30 s.

    .venv/bin/python benchmarks/recording_speed.py [--rows 3600000] [--keep FILE]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

from app.core.evaluation import evaluate, recording_source
from app.core.filters import FILTERS
from app.core.recording import RecordingWriter, read_recording, recording_metadata
from drivers.sim.device import SimulatedDevice

URL = "sim://wobble?odr=833&seed=21"
READ_GOAL_S = 5.0
EVALUATE_GOAL_S = 30.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=3_600_000, help="samples to record")
    parser.add_argument("--keep", type=Path, help="write here and keep the file")
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}")

    device = SimulatedDevice(URL, realtime=False, block=20)  # 20 ms blocks at 1 kHz, as live
    info = device.open()
    start = time.perf_counter()
    blocks = []
    total = 0
    while total < args.rows:
        block = device.read(0.0)
        blocks.append(block)
        total += len(block)
    device.close()
    print(f"generated {total:,} samples of {URL} in {time.perf_counter() - start:.1f} s "
          "(not timed below)")

    folder = tempfile.TemporaryDirectory()
    path = args.keep or Path(folder.name) / "hour.csv"
    metadata = recording_metadata(device=info, reference_source="the simulator's true "
                                  "orientation", note="benchmark")
    start = time.perf_counter()
    writer = RecordingWriter(path, metadata, overwrite=True).start()
    for block in blocks:
        writer.write(block)
    status = writer.close()
    elapsed = time.perf_counter() - start
    size_mb = path.stat().st_size / 1e6
    print(f"write: {status.rows_written:,} rows, {size_mb:.0f} MB in {elapsed:.1f} s = "
          f"{status.rows_written / elapsed:,.0f} rows/s ({size_mb / elapsed:.1f} MB/s), "
          f"one writer thread")
    del blocks

    for attempt in ("first", "second"):
        start = time.perf_counter()
        recording = read_recording(path)
        elapsed = time.perf_counter() - start
        verdict = "ok" if elapsed < READ_GOAL_S else f"SLOWER than the {READ_GOAL_S:g} s goal"
        print(f"read ({attempt}): {len(recording):,} rows in {elapsed:.2f} s = "
              f"{len(recording) / elapsed:,.0f} rows/s ({size_mb / elapsed:.0f} MB/s) {verdict}")
    del recording

    start = time.perf_counter()
    source = recording_source(str(path))
    stream = next(iter(source.blocks()))
    loaded = time.perf_counter() - start
    scores = evaluate(stream, list(FILTERS), repeats=1)
    elapsed = time.perf_counter() - start
    verdict = "ok" if elapsed < EVALUATE_GOAL_S else f"SLOWER than the {EVALUATE_GOAL_S:g} s goal"
    print(f"evaluate every filter: {elapsed:.1f} s including {loaded:.1f} s to load ({verdict})")
    for score in scores:
        print(f"  {score.name:<14} RMSE {score.rmse_deg:6.3f} deg  max {score.max_deg:6.3f} deg"
              f"  {score.samples_per_s:13,.0f} samples/s  {score.flag}")
    folder.cleanup()


if __name__ == "__main__":
    main()
