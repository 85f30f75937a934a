"""Protocol v1 decode throughput: bytes of SAMPLES frames -> RawBlocks, in samples/s.

The stream is what a NUCLEO sends: CONFIG, then SAMPLES packets of noisy int16 data with
consecutive seq and t0 (one in 500 packets missing, so the gap path runs too). It is fed to
:class:`drivers.link.decoder.LinkDecoder` in chunks the size a serial read returns; only
decoding is timed (best of 3).

    .venv/bin/python benchmarks/link_decode.py [--samples 2000000]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from drivers.link import protocol as p
from drivers.link.decoder import LinkDecoder
from drivers.link.framing import encode_packet

CONFIG = p.Config(6_667_000, 4, 250, 25_000)


def make_stream(samples: int, per_packet: int, seed: int = 1) -> tuple[bytes, int]:
    """Encoded frames holding about ``samples`` samples; returns (stream, samples sent)."""
    rng = np.random.default_rng(seed)
    ticks_per_sample = 1e12 / (CONFIG.odr_mhz * CONFIG.tick_ns)
    frames = [encode_packet(CONFIG)]
    packets = samples // per_packet
    values = rng.normal(0, 400, size=(packets, per_packet, 6)).astype(np.int16)
    values[:, :, 5] += 8192  # gravity on z at +-4 g
    sent = 0
    for seq in range(packets):
        t0 = round(seq * per_packet * ticks_per_sample)
        if seq % 500 == 499:
            continue  # a lost packet
        frames.append(encode_packet(p.Samples(seq & 0xFFFF, t0 & 0xFFFFFFFF, 300, values[seq])))
        sent += per_packet
    return b"".join(frames), sent


def decode_rate(stream: bytes, expected: int, chunk: int, repeats: int = 3) -> float:
    best = 0.0
    for _ in range(repeats):
        decoder = LinkDecoder()
        delivered = 0
        start = time.perf_counter()
        for i in range(0, len(stream), chunk):
            decoder.feed(stream[i:i + chunk])
            for block in decoder.take_blocks():
                delivered += len(block)
        elapsed = time.perf_counter() - start
        assert delivered == expected, (delivered, expected)
        best = max(best, delivered / elapsed)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=2_000_000)
    args = parser.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    print(f"{'samples/packet':>15}{'read chunk':>12}{'samples/s':>14}{'MB/s':>8}{'x 6667 Hz':>11}")
    for per_packet in (32, 8, 1):
        stream, sent = make_stream(args.samples // (32 // per_packet), per_packet)
        for chunk in (512, 4096, 65536):
            rate = decode_rate(stream, sent, chunk)
            megabytes = rate * len(stream) / sent / 1e6
            print(f"{per_packet:>15}{chunk:>12}{rate:>14,.0f}{megabytes:>8.1f}{rate / 6667:>11.0f}")
    print("goal (issue 4): >= 1,000,000 samples/s")


if __name__ == "__main__":
    main()
