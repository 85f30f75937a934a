"""Lab Streaming Layer throughput: a pylsl inlet receives a live simulated stream at its full rate.

The simulator runs in real time (``sim://wobble?odr=6667&mag=lis3mdl`` by default: the
LSM6DSOX's highest rate, with a magnetometer) through the acquisition session with its
pipeline; the LSL outlet (``app/services/lsl_outlet.py``) is its subscriber, as in ``record
--lsl`` and the window. An inlet in a thread of the same process pulls both streams (IMU and
orientation) for ``--seconds``. It prints samples sent, received and lost per stream, whether
every received sample equals the one sent (the IMU stream is double64: bit for bit), whether
the timestamps increase, the device's own losses (gaps in its time axis: samples the session
never saw), and the latency from a sample's timestamp to its arrival in the inlet.

liblsl is confined to this machine (a configuration with ``ResolveScope = machine`` and
``KnownPeers = {127.0.0.1}``, IPv6 off) unless ``--lsl-config`` names another.

    .venv/bin/python benchmarks/lsl_throughput.py [--seconds 60] [--device URL]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

LOOPBACK_CONFIG = """[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
[lab]
KnownPeers = {127.0.0.1}
"""


POLL_S = 0.002
"""How often the inlet looks for new samples."""


class Puller(threading.Thread):
    """Pulls one inlet until stopped and the stream is drained."""

    def __init__(self, inlet: object, name: str) -> None:
        super().__init__(name=f"inlet-{name}", daemon=True)
        self.inlet = inlet
        self.data: list[np.ndarray] = []
        self.stamps: list[np.ndarray] = []
        self.latency: list[np.ndarray] = []
        self.stop = threading.Event()

    def run(self) -> None:
        import pylsl

        idle = 0
        while not self.stop.is_set() or idle < 100:
            # timeout 0: what has arrived, at once (a longer timeout waits to fill the chunk,
            # which would count as latency here)
            chunk, times = self.inlet.pull_chunk(timeout=0.0, max_samples=200_000)
            now = pylsl.local_clock()
            if times:
                idle = 0
                self.data.append(np.asarray(chunk))
                self.stamps.append(np.asarray(times))
                self.latency.append(now - np.asarray(times))
            else:
                idle += self.stop.is_set()
                time.sleep(POLL_S)

    def received(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not self.stamps:
            return np.empty((0, 0)), np.empty(0), np.empty(0)
        return (np.vstack(self.data), np.concatenate(self.stamps),
                np.concatenate(self.latency))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="how long to stream")
    parser.add_argument("--device", default="sim://wobble?odr=6667&mag=lis3mdl&seed=2",
                        help="the live source (default: the simulator at 6667 Hz)")
    parser.add_argument("--lsl-config", help="liblsl's configuration (default: loopback only)")
    args = parser.parse_args()
    if args.lsl_config:
        os.environ["LSLAPICFG"] = args.lsl_config
    else:
        config = Path(tempfile.mkdtemp(prefix="lsl-bench-")) / "lsl_api.cfg"
        config.write_text(LOOPBACK_CONFIG)
        os.environ["LSLAPICFG"] = str(config)

    import pylsl

    from app.core.pipeline import Pipeline
    from app.services.acquisition import Acquisition, Block, Subscriber, Until
    from app.services.connection import Connection
    from app.services.lsl_outlet import LslOutlet, source_id
    from app.services.recorder import warm_up_kernels

    class Keep(Subscriber):
        def __init__(self) -> None:
            self.imu: list[np.ndarray] = []
            self.gaps = 0

        def on_block(self, block: Block) -> None:
            s = block.samples
            columns = [s.accel_m_s2, s.gyro_rad_s] + ([] if s.mag_ut is None else [s.mag_ut])
            self.imu.append(np.hstack(columns))
            self.gaps += int(np.count_nonzero(s.gap))

    warm_up_kernels(None)
    session = Acquisition(Connection(), Pipeline(), detect_faults=False)
    info = session.open(args.device)
    outlet = LslOutlet(lambda: session.connection.device.info, session.pipeline)
    pullers = {}
    for kind in ("imu", "orientation"):
        found = pylsl.resolve_byprop("source_id", source_id(info, kind), 1, 10.0)
        if not found:
            print(f"no LSL stream {source_id(info, kind)} found", file=sys.stderr)
            return 1
        inlet = pylsl.StreamInlet(found[0], max_buflen=60)
        inlet.open_stream(10.0)
        pullers[kind] = Puller(inlet, kind)
        pullers[kind].start()
    # The device ran on while the inlets connected: start afresh with them listening.
    session.close()
    session.open(args.device)
    keep = session.subscribe(Keep())
    session.subscribe(outlet)
    started = time.monotonic()
    end = session.run(Until(duration_s=args.seconds))
    wall = time.monotonic() - started
    for puller in pullers.values():
        puller.stop.set()
    for puller in pullers.values():
        puller.join(30.0)
    outlet.close()
    session.close()

    sent_imu = np.vstack(keep.imu)
    print(f"device {args.device}: {info.odr_hz:.2f} Hz, {end.samples} samples in {wall:.1f} s "
          f"wall ({end.reason}); gaps in the device's own stream: {keep.gaps}")
    counts = {"imu": outlet.counts.imu_samples, "orientation": outlet.counts.orientation_samples}
    for kind, puller in pullers.items():
        data, stamps, latency = puller.received()
        sent = counts[kind]
        same = ""
        if kind == "imu" and len(data) == len(sent_imu):
            equal = np.array_equal(data, sent_imu, equal_nan=True)
            same = f", values {'identical' if equal else 'DIFFER'}"
        increasing = bool(np.all(np.diff(stamps) > 0)) if len(stamps) > 1 else True
        print(f"{kind:<12} sent {sent:>8}  received {len(stamps):>8}  lost {sent - len(stamps):>6}"
              f"  ({len(stamps) / max(wall, 1e-9):8.1f} samples/s{same}, timestamps "
              f"{'increasing' if increasing else 'NOT increasing'}; latency median "
              f"{np.median(latency) * 1e3:.1f} ms, 99 % {np.quantile(latency, 0.99) * 1e3:.1f} "
              f"ms)" if len(stamps) else f"{kind:<12} sent {sent:>8}  received 0")
    fit = outlet.aligner.fit()
    if fit is not None:
        print(f"clock fit: drift {fit.drift_ppm:+.1f} ppm, spread {fit.spread_ms:.2f} ms over "
              f"{fit.points} blocks")
    return 0


if __name__ == "__main__":
    sys.exit(main())
