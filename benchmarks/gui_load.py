"""GUI load: frame rate and whole-app CPU with the simulator at 6667 Hz and all plots on a 10 s
window; with ``--minutes``, resident memory over a long run.

    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/gui_load.py --seconds 30
    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/gui_load.py --minutes 10

Under Xvfb (``xvfb-run -a .venv/bin/python benchmarks/gui_load.py``) the window is painted
to a real X server. CPU is the process's user+system time over wall time, in % of one core,
so it includes the worker thread, the simulator and the GUI.
"""

from __future__ import annotations

import argparse
import os
import resource
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="measured time (frame rate)")
    parser.add_argument("--minutes", type=float, default=0.0, help="memory run length")
    parser.add_argument("--device", default="sim://wobble?odr=6667&seed=7")
    parser.add_argument("--window", type=float, default=10.0, help="plot window in seconds")
    args = parser.parse_args()
    duration = args.minutes * 60.0 if args.minutes else args.seconds
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
    counter = PaintCounter()
    window.plots.graphics.viewport().installEventFilter(counter)

    marks: dict[str, tuple[float, float, int, int, int]] = {}
    memory: list[tuple[float, float]] = []
    started = time.monotonic()

    def mark(name: str) -> None:
        marks[name] = (
            time.monotonic(), time.process_time(), window.presenter.frames, counter.paints,
            session.pipeline.counters.samples,
        )

    def sample_memory() -> None:
        memory.append((time.monotonic() - started, rss_mib()))

    QTimer.singleShot(int(warm_up * 1000), lambda: mark("start"))
    QTimer.singleShot(int((warm_up + duration) * 1000), lambda: (mark("end"), window.close()))
    memory_timer = QTimer()
    memory_timer.timeout.connect(sample_memory)
    memory_timer.start(10_000 if args.minutes else 1000)
    app.exec()
    memory_timer.stop()

    (t0, c0, f0, p0, s0), (t1, c1, f1, p1, s1) = marks["start"], marks["end"]
    wall = t1 - t0
    print(f"platform: {app.platformName()}, device {args.device}, plot window {args.window:g} s")
    print(f"measured over {wall:.1f} s after {warm_up:g} s warm-up")
    print(f"samples streamed: {(s1 - s0) / wall:,.0f} /s")
    print(f"presenter frames: {(f1 - f0) / wall:.1f} fps")
    print(f"plot repaints:    {(p1 - p0) / wall:.1f} fps")
    print(f"whole-app CPU:    {100 * (c1 - c0) / wall:.1f} % of one core")
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
