"""GUI load: whole-app CPU and the frames actually drawn, with the simulator streaming into the
main window; with ``--minutes``, resident memory over a long run.

Measure in a real X window (the figures of issue 17 are for Xvfb at 1920x1080)::

    xvfb-run -a -s "-screen 0 1920x1080x24" .venv/bin/python benchmarks/gui_load.py
    xvfb-run -a -s "-screen 0 1920x1080x24" .venv/bin/python benchmarks/gui_load.py \\
        --device "sim://wobble?odr=104&seed=7"
    xvfb-run -a -s "-screen 0 1920x1080x24" .venv/bin/python benchmarks/gui_load.py \\
        --device "sim://static?odr=104&seed=7"          # idle: at rest, noise only
    xvfb-run -a -s "-screen 0 1920x1080x24" .venv/bin/python benchmarks/gui_load.py \\
        --device "sim://wobble?odr=104&seed=7" --hide-plots   # the instrument view
    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/gui_load.py --minutes 10

CPU is the process's CPU time (user + system, all threads: the worker with the simulator and
the pipeline, and the GUI) over wall time, in % of one core, so other processes on a shared
machine change it far less than a throughput figure; each of ``--repeat`` intervals is
reported and their spread, with the load average. Frames are paint events of the plots' view
and of the bubble level (what reached the window), and the presenter's own count of frames
that drew something; rebuilds are the plots' traces handed over anew, appends the new samples
drawn onto the screen between rebuilds. The window is 1280 x 860 with all plots on a 10 s
window unless told.
"""

from __future__ import annotations

import argparse
import itertools
import os
import resource
import statistics
import sys
import tempfile
import time

from PySide6.QtCore import QEvent, QObject, QSettings, QTimer
from PySide6.QtWidgets import QApplication

from app.gui import theme
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession


class PaintCounter(QObject):
    """Counts paint events of a widget (frames actually drawn)."""

    def __init__(self) -> None:
        super().__init__()
        self.paints = 0

    def eventFilter(self, watched, event) -> bool:
        if event.type() == QEvent.Type.Paint:
            self.paints += 1
        return False


def rss_mib() -> float:
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def thread_cpu_s() -> dict[str, float]:
    """CPU seconds per thread name (Linux /proc; empty elsewhere)."""
    result: dict[str, float] = {}
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return result
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                stat = f.read()
            with open(f"/proc/self/task/{tid}/comm") as f:
                name = f.read().strip()
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2:].split()
        name = "GUI" if tid == str(os.getpid()) else name
        result[name] = result.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return result


def load_average() -> str:
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "?"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=15.0, help="length of one interval")
    parser.add_argument("--repeat", type=int, default=3, help="measured intervals")
    parser.add_argument("--minutes", type=float, default=0.0, help="memory run length")
    parser.add_argument("--device", default="sim://wobble?odr=6667&seed=7")
    parser.add_argument("--window", type=float, default=10.0, help="plot window in seconds")
    parser.add_argument("--hide-plots", action="store_true",
                        help="close the plots dock (the instrument view: bubble and readouts)")
    args = parser.parse_args()
    if args.minutes:
        args.seconds, args.repeat = args.minutes * 60.0, 1
    warm_up = 5.0

    app = QApplication(sys.argv)
    theme.apply_theme(app)
    settings_dir = tempfile.mkdtemp(prefix="inclinometer-bench-")
    settings = QSettings(os.path.join(settings_dir, "bench.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, args.device)
    window.resize(1280, 860)
    window.window_combo.setCurrentIndex(window.window_combo.findData(int(args.window)))
    window.show()
    if args.hide_plots:
        window.docks["plots"].close()
    plot_paints, bubble_paints = PaintCounter(), PaintCounter()
    window.plots.graphics.viewport().installEventFilter(plot_paints)
    window.level.installEventFilter(bubble_paints)

    marks: list[dict] = []
    memory: list[tuple[float, float]] = []
    started = time.monotonic()

    def mark() -> None:
        marks.append({
            "wall": time.monotonic(), "cpu": time.process_time(), "threads": thread_cpu_s(),
            "frames": window.presenter.frames,
            "updates": getattr(window.presenter, "plot_updates", 0),
            "appends": getattr(window.presenter, "plot_appends", 0),
            "plot": plot_paints.paints, "bubble": bubble_paints.paints,
            "samples": session.pipeline.counters.samples, "load": load_average(),
        })

    def sample_memory() -> None:
        memory.append((time.monotonic() - started, rss_mib()))

    for index in range(args.repeat + 1):
        QTimer.singleShot(int((warm_up + index * args.seconds) * 1000), mark)
    QTimer.singleShot(int((warm_up + args.repeat * args.seconds) * 1000) + 50, window.close)
    memory_timer = QTimer()
    memory_timer.timeout.connect(sample_memory)
    memory_timer.start(10_000 if args.minutes else 1000)
    app.exec()
    memory_timer.stop()

    screen = window.screen()
    clock = getattr(window.presenter, "clock", None)  # None: the fixed 30 fps timer before it
    pacing = f"frame clock {clock.interval_ms} ms" if clock is not None else "fixed timer"
    print(f"platform: {app.platformName()}, screen {screen.size().width()}x"
          f"{screen.size().height()} at {screen.refreshRate():.0f} Hz ({pacing}), window "
          f"{window.width()}x{window.height()}")
    print(f"device {args.device}, plot window {args.window:g} s"
          + (", plots dock closed" if args.hide_plots else ", all plots shown"))
    print(f"{args.repeat} x {args.seconds:g} s after {warm_up:g} s warm-up")
    rows = []
    for before, after in itertools.pairwise(marks):
        wall = after["wall"] - before["wall"]

        def rate(key: str, a: dict = after, b: dict = before, w: float = wall) -> float:
            return (a[key] - b[key]) / w

        threads = {name: 100 * (after["threads"].get(name, 0.0) - before["threads"].get(name, 0.0))
                   / wall for name in after["threads"]}
        rows.append({
            "cpu": 100 * (after["cpu"] - before["cpu"]) / wall, "gui": threads.get("GUI", 0.0),
            "worker": threads.get("device-worker", 0.0), "samples": rate("samples"),
            "frames": rate("frames"), "updates": rate("updates"), "appends": rate("appends"),
            "plot": rate("plot"),
            "bubble": rate("bubble"), "load": after["load"],
        })
    print("  whole-app CPU  (GUI thread, worker)  | plot repaints  bubble repaints  presenter"
          " frames  plot rebuilds / appends | samples/s | load average")
    for row in rows:
        print(f"  {row['cpu']:5.1f} % ({row['gui']:5.1f} %, {row['worker']:5.1f} %)   | "
              f"{row['plot']:6.1f} fps      {row['bubble']:6.1f} fps      {row['frames']:6.1f} fps"
              f"        {row['updates']:5.1f} / {row['appends']:5.1f} /s  "
              f"| {row['samples']:8,.0f}  | {row['load']}")
    cpu = [row["cpu"] for row in rows]
    spread = f"{min(cpu):.1f}..{max(cpu):.1f}" if len(cpu) > 1 else f"{cpu[0]:.1f}"
    print(f"whole-app CPU: median {statistics.median(cpu):.1f} % of one core (spread {spread} %)")
    plot = [row["plot"] for row in rows]
    bubble = [row["bubble"] for row in rows]
    print(f"frames drawn:  plots median {statistics.median(plot):.1f} fps, bubble median "
          f"{statistics.median(bubble):.1f} fps")
    if memory:
        values = [m for _, m in memory]
        print(f"resident memory:  start {values[0]:.0f} MiB, peak {max(values):.0f} MiB, "
              f"end {values[-1]:.0f} MiB over {memory[-1][0] / 60:.1f} min")
        if args.minutes:
            for seconds, mib in memory[:: max(1, len(memory) // 12)]:
                print(f"  t = {seconds / 60:5.1f} min   {mib:7.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
