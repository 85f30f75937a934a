"""Screenshots of the real window in a given state, theme and screen size (issue #29's
"Must show").

Each shot starts the real application (``run_gui``'s steps, the real device session and
simulator or replay) under its own X server (``xvfb-run``) with an isolated settings file
(``INCLINOMETER_SETTINGS``) and temporary ``HOME``/``XDG_*`` folders, so nothing of the
user's settings is read or written. The window is driven in-process by timed steps that
call its own actions and methods; the replay state also clicks the slider's groove with
``xdotool`` (a real X click, as a user makes it). The whole screen is saved with
``import -window root``.

States:
  main     the default simulator (``sim://interactive``)
  alarm    ``--alarm "tilt>100"`` on ``sim://static?roll=178.33&pitch=0``
  wizard   the calibration wizard rejecting a face captured 3.3 degrees off its axis
           (still blocks of the simulator, ``sim://static``, fed to the poses page as the
           wizard's own timer feeds it, as tests/test_guarded_measurements.py does)
  replay   a replay paused after a seek, with two bookmarks
  stale    the device lost: readouts greyed with the "NOT LIVE" badge (and HOLD)

Usage (all states, both sizes, every theme into one folder)::

    python benchmarks/screenshots.py --out /work/shots/final
    python benchmarks/screenshots.py --states alarm --sizes 1366x768 --themes light --out DIR

Files are named ``STATE-WxH-THEME.png``. It lives in benchmarks/ beside the other scripts
that run the real application for a figure or a picture (gui_load.py); it is not shipped.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STATES = ("main", "alarm", "wizard", "replay", "stale")
SIZES = ("1366x768", "1920x1080")
THEMES = ("dark", "light", "high-contrast")
RECORDING = Path("/work/shared/datasets/broad/01_undisturbed_slow_rotation_A.csv")
FACE_ROLL_PITCH = {"+z": (0.0, 0.0), "-z": (180.0, 0.0), "+x": (0.0, 90.0),
                   "-x": (0.0, -90.0), "+y": (90.0, 0.0), "-y": (-90.0, 0.0)}
OFF_AXIS_FACE, OFF_AXIS_DEG = "+y", 3.3


def _device_for(state: str, recording: Path) -> tuple[str | None, list[str]]:
    """The device URL and alarm specs a state starts with."""
    if state == "alarm":
        return "sim://static?roll=178.33&pitch=0", ["tilt>100"]
    if state == "replay":
        return str(recording), []
    if state == "stale":
        return "sim://static?roll=12.5&pitch=-3.25", []
    return None, []  # the default: sim://interactive


def _shoot(out: Path) -> None:
    """The whole screen as the X server shows it."""
    subprocess.run(["import", "-window", "root", str(out)], check=True, timeout=60)


def _click(x: int, y: int) -> None:
    """A real left click at screen pixel (x, y)."""
    subprocess.run(["xdotool", "mousemove", str(x), str(y), "click", "1"], check=True,
                   timeout=30)


class _Steps:
    """Runs ``(wait_ms, step)`` pairs one after the other on the event loop; a step that
    returns False is retried every 200 ms until ``timeout_s`` (then the run fails)."""

    def __init__(self, steps: list[tuple[int, Callable[[], object]]], timeout_s: float = 60):
        from PySide6.QtCore import QTimer

        self._steps = list(steps)
        self._timer = QTimer()
        self._timer.setSingleShot(True)
        self._timer.timeout.connect(self._run)
        self._deadline = 0.0
        self._timeout_s = timeout_s
        self.error: str | None = None
        self._next()

    def _next(self) -> None:
        from PySide6.QtWidgets import QApplication

        if not self._steps:
            QApplication.quit()
            return
        self._deadline = time.monotonic() + self._timeout_s
        self._timer.start(self._steps[0][0])

    def _run(self) -> None:
        from PySide6.QtWidgets import QApplication

        step = self._steps[0][1]
        try:
            done = step()
        except Exception as exc:  # reported, and the run ends
            self.error = f"{getattr(step, '__name__', step)}: {exc!r}"
            QApplication.exit(1)
            return
        if done is False:
            if time.monotonic() > self._deadline:
                self.error = f"{getattr(step, '__name__', step)}: timed out"
                QApplication.exit(1)
                return
            self._timer.start(200)
            return
        self._steps.pop(0)
        self._next()


def _still_block(roll: float, pitch: float, t0: float):
    """5 s of the simulated raw unit lying still at (roll, pitch), starting at ``t0``."""
    import dataclasses

    from app.core.samples import convert_raw_block
    from drivers.registry import create_device

    device = create_device(f"sim://static?roll={roll}&pitch={pitch}&odr=104&realtime=0"
                           "&block=520&seed=3")
    device.open()
    try:
        block = convert_raw_block(device.read(1.0))
    finally:
        device.close()
    return dataclasses.replace(block, t_s=block.t_s + t0)


def run_one(state: str, theme_name: str, out: Path, recording: Path) -> int:
    """Inside the X server: start the window, drive it into ``state``, save the screen."""
    from PySide6.QtCore import QPoint
    from PySide6.QtWidgets import QApplication

    from app import __version__
    from app.core.alarms import alarms_from_specs
    from app.gui import theme
    from app.gui.main_window import MainWindow
    from app.gui.user_settings import APPLICATION, ORGANIZATION, create_settings
    from app.services.session import DeviceSession

    url, alarm_specs = _device_for(state, recording)
    app = QApplication(sys.argv[:1])
    app.setOrganizationName(ORGANIZATION)
    app.setApplicationName(APPLICATION)
    app.setApplicationVersion(__version__)
    theme.apply_theme(app)
    session = DeviceSession()
    alarms = alarms_from_specs(alarm_specs) if alarm_specs else None
    window = MainWindow(session, create_settings(), url, None, alarms)
    window.show()
    readouts = window.readouts
    report: list[str] = []

    def live() -> bool:
        return readouts.isValid() and window.isVisible()

    def settle() -> None:
        app.processEvents()

    steps: list[tuple[int, Callable[[], object]]] = [(500, live)]
    if state == "alarm":
        steps.append((1500, lambda: bool(readouts.alarmQuantities())))
    elif state == "stale":
        def lose() -> None:
            readouts.setHold(True)
            readouts.setStale(time.time())
        steps.append((1500, lose))
    elif state == "wizard":
        holder: dict[str, object] = {}

        def open_wizard() -> bool:
            wizard = window.open_calibration_wizard()
            holder["wizard"] = wizard
            return wizard is not None

        def to_poses() -> bool:
            wizard = holder["wizard"]
            wizard.timer.stop()  # the faces below come from the still blocks only
            wizard.next()  # the gyro page
            wizard.next()  # the six faces
            return wizard.currentPage() is wizard.poses_page

        def capture_faces() -> bool:
            page = holder["wizard"].poses_page
            for index, face in enumerate(("+z", "-z", "+x", "-x", "+y")):
                roll, pitch = FACE_ROLL_PITCH[face]
                tilt = OFF_AXIS_DEG if face == OFF_AXIS_FACE else 0.0
                page.feed(_still_block(roll + tilt, pitch, 10.0 * index))
                if page.capture is not None:
                    page.capture.request_capture()
            report.append(f"rejection: {page.rejection.text()}")
            return not page.rejection.isHidden()

        def place_wizard() -> None:
            wizard = holder["wizard"]
            screen = wizard.screen().availableGeometry()
            wizard.move(screen.center() - wizard.rect().center())
            wizard.raise_()
            wizard.activateWindow()

        steps += [(500, open_wizard), (800, to_poses), (300, capture_faces),
                  (300, place_wizard)]
    elif state == "replay":
        bar = window.replay_bar

        def has_duration() -> bool:
            return bar._duration_s > 1.0 and readouts.isValid()

        def pause() -> None:
            bar.play_button.setChecked(False)

        def seek_to(fraction: float) -> Callable[[], None]:
            def seek() -> None:
                bar.control.emit("seek", fraction * bar._duration_s)
            return seek

        def mark() -> None:
            bar.control.emit("add_bookmark", None)

        def marks_drawn() -> bool:
            return len(bar.slider.marks()) >= 2

        clicked: list[float] = []

        def click_groove() -> None:
            slider = bar.slider
            point = slider.mapToGlobal(QPoint(round(slider.x_of(0.62)), slider.height() // 2))
            report.append(f"xdotool click at {point.x()},{point.y()} (62 % of the groove)")
            clicked.append(time.monotonic())
            _click(point.x(), point.y())

        def arrived() -> bool:
            position = bar.slider.value() / max(bar.slider.maximum(), 1)
            ok = abs(position - 0.62) < 0.02 and readouts.isValid()
            if ok:
                report.append(f"after the click: {bar.position_label.text().strip()}, "
                              f"play button {bar.play_button.text()!r}")
            elif len(clicked) < 3 and time.monotonic() - clicked[-1] > 5.0:
                report.append("the click did not arrive within 5 s: clicking again")
                click_groove()  # a click once got lost under Xvfb (seen 1 in 12 runs)
            return ok

        steps += [(300, has_duration), (1500, pause), (300, seek_to(0.2)), (1200, mark),
                  (300, seek_to(0.45)), (1200, mark), (500, marks_drawn),
                  (300, click_groove), (300, arrived)]

    def shoot() -> None:
        settle()
        for name in ("roll", "pitch", "tilt", "direction"):
            report.append(f"{name}: {readouts.readoutText(name)!r}")
        corner = readouts.mapToGlobal(QPoint(0, 0))
        report.append(f"readouts at {corner.x()},{corner.y()} "
                      f"{readouts.width()}x{readouts.height()}")  # to crop them for OCR
        _shoot(out)

    steps.append((4000 if state in ("main", "alarm") else 1500, shoot))  # plots fill
    runner = _Steps(steps)
    code = app.exec()
    for line in report:
        print(f"  {line}")
    session.shutdown()
    if runner.error:
        print(f"screenshots: {state} {theme_name}: {runner.error}", file=sys.stderr)
        return 1
    return code


def _isolated_env(home: Path, theme_name: str) -> dict[str, str]:
    """Environment of one run: its own HOME, XDG folders and settings file (the theme)."""
    env = dict(os.environ)
    for name in ("config", "data", "cache", "state", "runtime"):
        folder = home / name
        folder.mkdir(mode=0o700, exist_ok=True)
    env.update({
        "HOME": str(home),
        "XDG_CONFIG_HOME": str(home / "config"),
        "XDG_DATA_HOME": str(home / "data"),
        "XDG_CACHE_HOME": str(home / "cache"),
        "XDG_STATE_HOME": str(home / "state"),
        "XDG_RUNTIME_DIR": str(home / "runtime"),
        "INCLINOMETER_SETTINGS": str(home / "inclinometer.ini"),
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH", "")])),
    })
    env.pop("QT_QPA_PLATFORM", None)  # the X server, not offscreen
    (home / "inclinometer.ini").write_text(f"[General]\ntheme={theme_name}\n")
    return env


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", nargs="+", choices=STATES, default=list(STATES[:4]))
    parser.add_argument("--sizes", nargs="+", default=list(SIZES), metavar="WxH")
    parser.add_argument("--themes", nargs="+", choices=THEMES, default=list(THEMES))
    parser.add_argument("--out", type=Path, required=True, help="folder for the PNG files")
    parser.add_argument("--recording", type=Path, default=RECORDING,
                        help="the recording the replay state plays")
    parser.add_argument("--one", nargs=2, metavar=("STATE", "THEME"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        return run_one(args.one[0], args.one[1], args.out, args.recording)
    for tool in ("xvfb-run", "import", "xdotool"):
        if shutil.which(tool) is None:
            print(f"screenshots: {tool} is needed (apt install xvfb imagemagick xdotool)",
                  file=sys.stderr)
            return 2
    args.out.mkdir(parents=True, exist_ok=True)
    failures = 0
    for size in args.sizes:
        width, height = (int(v) for v in size.lower().split("x"))
        for state in args.states:
            for theme_name in args.themes:
                target = args.out / f"{state}-{width}x{height}-{theme_name}.png"
                with tempfile.TemporaryDirectory(prefix="inclinometer-shot-") as home:
                    env = _isolated_env(Path(home), theme_name)
                    command = ["xvfb-run", "-a", "-s", f"-screen 0 {width}x{height}x24",
                               sys.executable, str(Path(__file__).resolve()),
                               "--one", state, theme_name, "--out", str(target),
                               "--recording", str(args.recording)]
                    print(target.name, flush=True)
                    done = subprocess.run(command, env=env, timeout=300)
                failures += done.returncode != 0 or not target.exists()
    print(f"{failures} failed" if failures else "all saved")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
