"""Long sessions: record, replay, evaluate and open hour-long recordings; time, rows/s, peak RSS.

For each length (default 1, 10 and 60 minutes) at 6667 Hz, plain CSV and compressed
(``.csv.gz``), it records the simulator (``sim://wobble?odr=6667&realtime=0&block=4096``) with
``inclinometer record``, then runs, each in its own process so that peak RSS is the command's
own:

- ``replay IN --out ANGLES.csv`` (the recorded filter, one pass, streamed);
- ``replay IN --filter all --out ANGLES.csv`` (offline smoothers need the whole session);
- ``evaluate IN --filter ekf`` (one filter);
- opening IN in the replay window, offscreen: the time until the first samples are in the
  views, until the overview is complete, and the worst of ten seeks to random places (until
  the replay stands at the new place; at speed 1 its next block then follows at its pace).

Each line gives the wall time, rows/s and the peak RSS (``/usr/bin/time``-style, from
``resource.getrusage`` of the child). Recordings go to a temporary folder (about 1 GB per 10
minutes of plain CSV, 0.4 GB compressed) and are removed afterwards unless ``--keep DIR``.

    .venv/bin/python benchmarks/long_sessions.py [--minutes 1 10 60] [--keep DIR]
        [--skip-all]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DEVICE = "sim://wobble?odr=6667&realtime=0&block=4096"
ROOT = Path(__file__).resolve().parents[1]
INCLINOMETER = [sys.executable, "-m", "app"]

GUI_SCRIPT = r"""
import os, random, sys, time
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
from PySide6.QtCore import QEventLoop, QTimer
from PySide6.QtWidgets import QApplication
app = QApplication([])
from app.gui.application import create_settings
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession
from app.services.devices import replay_url
session = DeviceSession()
window = MainWindow(session, create_settings(), None, None)
window.resize(1400, 900)
window.show()
def wait_for(predicate, limit_s):
    end = time.perf_counter() + limit_s
    while not predicate() and time.perf_counter() < end:
        loop = QEventLoop(); QTimer.singleShot(5, loop.quit); loop.exec()
    return predicate()
path = sys.argv[1]
overviews = []
def keep(status):
    if status.overview is not None:
        overviews.append(status.overview)
session.status.connect(keep)
start = time.perf_counter()
window.connect_device(replay_url(path))
wait_for(lambda: session.pipeline.counters.samples > 0, 120)
first = time.perf_counter() - start
wait_for(lambda: overviews and overviews[-1].complete, 1200)
indexed = time.perf_counter() - start
duration = session.worker.connection.device.duration_s
worst = 0.0
random.seed(1)
for _ in range(10):
    target = random.uniform(0, duration)
    device = session.worker.connection.device
    generation = device.generation
    t0 = time.perf_counter()
    session.requestReplayControl.emit("seek", target)
    wait_for(lambda: device.generation > generation, 60)  # the replay stands there
    worst = max(worst, time.perf_counter() - t0)
if len(sys.argv) > 2:
    window.grab().save(sys.argv[2])
session.shutdown()
print(f"first samples {first:.2f} s, overview complete {indexed:.1f} s, worst seek {worst:.3f} s")
"""


def run(command: list[str], label: str, rows: int | None = None) -> str:
    """Run ``command`` in a child; print wall time, rows/s and the child's own peak RSS
    (GNU time's %M when /usr/bin/time exists, else the largest child's so far)."""
    timer = ["/usr/bin/time", "-f", "peak-rss-kb %M"] if Path("/usr/bin/time").exists() else []
    start = time.perf_counter()
    result = subprocess.run([*timer, *command], cwd=ROOT, capture_output=True, text=True,
                            env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    wall = time.perf_counter() - start
    marks = [line for line in result.stderr.splitlines() if line.startswith("peak-rss-kb ")]
    peak_kb = (int(marks[-1].split()[1]) if marks
               else resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
    peak = f"{peak_kb / 1024:6.0f} MB"
    rate = f"{rows / wall / 1000:7.0f} k rows/s" if rows else " " * 16
    tail = (result.stdout.strip().splitlines() or [""])[-1]
    errors = [line for line in result.stderr.splitlines() if not line.startswith("peak-rss")]
    status = "" if result.returncode == 0 else f"  FAILED ({result.returncode}): " \
        f"{errors[-1] if errors else ''}"
    print(f"  {label:<28} {wall:8.1f} s {rate} peak {peak}{status}", flush=True)
    return tail


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1, 10, 60])
    parser.add_argument("--keep", type=Path, help="keep the recordings in this folder")
    parser.add_argument("--skip-all", action="store_true", help="leave out replay --filter all")
    parser.add_argument("--screenshot", type=Path, help="save the replay window of the last file")
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}; device {DEVICE}")
    print("each step runs in a fresh process; peak RSS is that process's own")
    folder = tempfile.TemporaryDirectory()
    base = args.keep or Path(folder.name)
    base.mkdir(parents=True, exist_ok=True)
    for minutes in args.minutes:
        for compressed in (False, True):
            name = f"wobble-{minutes:g}min.csv" + (".gz" if compressed else "")
            path = base / name
            print(f"{name}:", flush=True)
            if not path.exists():
                run([*INCLINOMETER, "record", "--device", DEVICE, "--duration",
                     f"{minutes * 60:g}", "--quiet", str(path)], "record")
            rows = round(minutes * 60 * 6867.01)  # the simulated unit's trimmed clock
            size = path.stat().st_size
            print(f"  {size / 1e6:.0f} MB on disk, about {rows:,} rows", flush=True)
            angles = base / "angles.csv"
            run([*INCLINOMETER, "replay", str(path), "--out", str(angles)], "replay (ekf)", rows)
            if not args.skip_all:
                run([*INCLINOMETER, "replay", str(path), "--filter", "all", "--out",
                     str(angles)], "replay --filter all", rows)
            run([*INCLINOMETER, "evaluate", str(path), "--filter", "ekf", "--repeats", "1"],
                "evaluate --filter ekf", rows)
            shot = [str(args.screenshot)] if args.screenshot and minutes == args.minutes[-1] \
                else []
            line = run([sys.executable, "-c", GUI_SCRIPT, str(path), *shot],
                       "replay window (offscreen)")
            print(f"    {line}", flush=True)
            angles.unlink(missing_ok=True)
    folder.cleanup()


if __name__ == "__main__":
    main()
