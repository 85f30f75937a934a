"""Latency from a SAMPLES packet written to the pseudo-terminal to its samples in the ring buffer.

An emulated NUCLEO (``drivers.emulated_nucleo``) streams on a pseudo-terminal from its own
process (as a board would: it does not compete for this process's interpreter lock) and notes
the time right after each SAMPLES packet's bytes were written. A reader thread runs what the
app's worker runs: the real serial driver (``device.read``) and
``app.core.pipeline.Pipeline.process`` (units, calibration, the default filter, ring buffers),
and notes the time after each block is in the ring buffer (the pipeline's first-call costs are
paid before the measurement). A packet's latency is the time from
its write to the first ring write that holds its last sample. Both processes read
``time.perf_counter()``, the system's monotonic clock on Linux, so their times compare.

    .venv/bin/python benchmarks/link_latency.py [--seconds 10] [--odr 833 6667]
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import threading
import time

import numpy as np

from app.core.pipeline import Pipeline
from app.core.samples import RawBlock
from drivers.emulated_nucleo import EmulatedNucleo
from drivers.link.decoder import scale_factors
from drivers.link.protocol import Config
from drivers.registry import create_device


def serve(odr_hz: float) -> None:
    """The board's process: print the port, serve until stdin closes, print the write log."""
    written: list[tuple[int, float]] = []  # (end sample index, time written)

    def on_sent(_seq: int, first: int, count: int, t_write: float) -> None:
        written.append((first + count, t_write))

    board = EmulatedNucleo("wobble", odr_hz=odr_hz, seed=3, on_packet_sent=on_sent)
    print(board.port, flush=True)
    sys.stdin.read()
    board.close()
    for end_index, t_write in written:
        print(end_index, repr(t_write))


def warm_pipeline(odr_hz: float) -> Pipeline:
    """A pipeline whose first-call costs (compilation, caches) are paid: steady state only."""
    pipeline = Pipeline(odr_hz)
    n = 64
    pipeline.process(RawBlock(
        t_s=np.arange(n) / odr_hz, accel_raw=np.tile(np.int16([0, 0, 8192]), (n, 1)),
        gyro_raw=np.zeros((n, 3), np.int16), temp_raw=np.zeros(n, np.int16),
        scale=scale_factors(Config(round(odr_hz * 1000), 4, 250, 25_000)),
    ))
    pipeline.configure(odr_hz)
    return pipeline


def measure(odr_hz: float, seconds: float) -> np.ndarray:
    """Latencies in seconds, one per SAMPLES packet."""
    board = subprocess.Popen([sys.executable, __file__, "--serve", str(odr_hz)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    port = board.stdout.readline().strip()
    device = create_device(port)
    pipeline = warm_pipeline(odr_hz)  # before START: the board streams from then on
    info = device.open()
    pipeline.configure(info.odr_hz)
    in_ring: list[tuple[int, float]] = []  # (samples in the ring so far, time)
    stop = threading.Event()

    def reader() -> None:
        while not stop.is_set():
            block = device.read(0.05)
            if block is not None:
                pipeline.process(block)
                in_ring.append((pipeline.samples.total_written, time.perf_counter()))

    thread = threading.Thread(target=reader, name="reader")
    thread.start()
    stop.wait(seconds)  # the measurement runs this long
    stop.set()
    thread.join()
    device.close()
    log, _ = board.communicate("")
    written = [(int(end), float(t)) for end, t in (line.split() for line in log.splitlines())]
    totals = np.array([total for total, _ in in_ring])
    ring_times = np.array([t for _, t in in_ring])
    latencies = []
    for end_index, t_write in written:
        k = int(np.searchsorted(totals, end_index))
        if k < len(totals):
            latencies.append(ring_times[k] - t_write)
    return np.array(latencies)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--odr", type=float, nargs="+", default=[104.0, 833.0, 6667.0])
    parser.add_argument("--serve", type=float, metavar="ODR", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        serve(args.serve)
        return
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    print(f"{'ODR Hz':>8}{'packets':>9}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}")
    for odr in args.odr:
        latency_ms = measure(odr, args.seconds) * 1e3
        p50, p99 = np.percentile(latency_ms, [50, 99])
        print(f"{odr:>8g}{len(latency_ms):>9}{p50:>9.2f}{p99:>9.2f}{latency_ms.max():>9.2f}")
    print("goal (issue 4): p99 < 10 ms")


if __name__ == "__main__":
    main()
