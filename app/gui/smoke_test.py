"""``inclinometer --smoke-test``: the whole application checked end to end in a few seconds.

Made for the standalone bundle (``dist/inclinometer/inclinometer --smoke-test`` in CI), where
a missing Qt plugin, resource file, numba source or compiled extension only shows when the
program runs. It drives the real main window (offscreen when there is no screen):

1. the theme loads its stylesheet and icons through :mod:`importlib.resources`;
2. the simulator (``sim://wobble``) streams, samples go through the default filter into the
   ring buffers, and the bubble level, the readouts and the plots show them;
3. frames are drawn: the presenter's frame counter advances and a screenshot of the window
   is not blank (saved as PNG if asked);
4. a bundled sample recording replays through the same pipeline;
5. every online filter's kernel (numba-compiled, or VQF's C++) runs on a known tilt and
   finds it; in a frozen app numba's cache must land in ``NUMBA_CACHE_DIR``.

It exits 0 with a one-line summary on stdout, or 1 with the reason on stderr. Nothing is
written to the user's settings: the window gets a throw-away settings file.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

SIMULATOR_URL = "sim://wobble?odr=208&seed=3"
STEP_TIMEOUT_S = 60.0
"""Generous: the first run of a fresh bundle compiles every kernel (about 10-20 s)."""
LIVE_SAMPLES = 400
REPLAY_SAMPLES = 300
KERNEL_TILT_TOLERANCE_DEG = 0.5


class SmokeTestFailure(Exception):
    """One step did not do what it should; the message says which and why."""


def _wait_until(app, predicate: Callable[[], bool], what: str,
                timeout_s: float = STEP_TIMEOUT_S) -> float:
    """Run the event loop until ``predicate()`` holds; return the seconds it took."""
    from PySide6.QtCore import QEventLoop

    start = time.monotonic()
    while not predicate():
        if time.monotonic() - start > timeout_s:
            raise SmokeTestFailure(f"timed out after {timeout_s:g} s waiting for {what}")
        app.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 50)
        time.sleep(0.01)
    return time.monotonic() - start


def _curve_points(curve) -> int:
    return 0 if curve.xData is None else len(curve.xData)


def _distinct_colours(image) -> int:
    """Distinct colours on a coarse grid of the image (a blank window has one or two)."""
    colours = set()
    step_x, step_y = max(1, image.width() // 64), max(1, image.height() // 64)
    for y in range(0, image.height(), step_y):
        for x in range(0, image.width(), step_x):
            colours.add(image.pixel(x, y))
    return len(colours)


def _tilted_block(tilt_deg: float, seconds: float = 10.0, odr_hz: float = 104.0):
    """A sensor at rest with roll ``tilt_deg`` (about x): the kernels' known answer."""
    from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

    n = round(seconds * odr_hz)
    roll = math.radians(tilt_deg)
    gravity = STANDARD_GRAVITY_M_S2 * np.array([0.0, math.sin(roll), math.cos(roll)])
    return SampleBlock(
        np.arange(n) / odr_hz, np.tile(gravity, (n, 1)), np.zeros((n, 3)), np.full(n, 25.0),
        np.zeros(n, dtype=bool),
    )


def _numba_dispatchers() -> list:
    """The numba-compiled functions of the filter modules that have been compiled."""
    from numba.core.registry import CPUDispatcher

    found = []
    for name, module in sorted(sys.modules.items()):
        if not name.startswith("app.core.") or module is None:
            continue
        for value in vars(module).values():
            if isinstance(value, CPUDispatcher) and value.signatures and value not in found:
                found.append(value)
    return found


def check_kernels() -> str:
    """Run every online filter on a known 10 degree tilt; check numba compiled and cached."""
    from numba import config as numba_config

    from app.core.filters import ONLINE_FILTERS, create_filter
    from app.core.orientation import angles_from_quaternion

    block = _tilted_block(10.0)
    for name in ONLINE_FILTERS:
        if name == "gyro":  # integrates rates only: it keeps whatever it started from
            create_filter(name).process(block)
            continue
        result = create_filter(name).process(block)
        if not np.all(np.isfinite(result.quat)):
            raise SmokeTestFailure(f"filter {name!r} produced non-finite quaternions")
        roll = float(angles_from_quaternion(result.quat[-1:]).roll_deg[0])
        if abs(roll - 10.0) > KERNEL_TILT_TOLERANCE_DEG:
            raise SmokeTestFailure(f"filter {name!r} finds roll {roll:.3f} deg for a true 10 deg")
    dispatchers = _numba_dispatchers()
    if not dispatchers:
        raise SmokeTestFailure("no numba kernel was compiled")
    cache_dir = numba_config.CACHE_DIR
    if getattr(sys, "frozen", False):
        if not cache_dir:
            raise SmokeTestFailure("NUMBA_CACHE_DIR is not set in the frozen app")
        outside = sorted({
            f"{d.py_func.__qualname__} ({d.stats.cache_path})" for d in dispatchers
            if not str(d.stats.cache_path or "").startswith(cache_dir)
        })
        if outside:
            raise SmokeTestFailure(
                f"numba caches {', '.join(outside)} outside NUMBA_CACHE_DIR {cache_dir} (are "
                "the kernels' sources in the bundle?)"
            )
    loaded = sum(sum(d.stats.cache_hits.values()) for d in dispatchers)
    compiled = sum(sum(d.stats.cache_misses.values()) for d in dispatchers)
    where = cache_dir or "beside the sources"
    return (f"{len(ONLINE_FILTERS)} filters found a 10° tilt; numba: {compiled} compiled, "
            f"{loaded} loaded from the cache ({where})")


def _quiet_offscreen_warnings(_mode, _context, message: str) -> None:
    """Qt's messages to stderr, less the offscreen plugin's harmless notice about window
    size hints (printed for every dock), so that the smoke test's output stays one line."""
    if "propagateSizeHints" not in message:
        print(message, file=sys.stderr)


def _use_offscreen_without_a_screen() -> None:
    if os.environ.get("QT_QPA_PLATFORM"):
        return
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        os.environ["QT_QPA_PLATFORM"] = "offscreen"


def run_smoke_test(screenshot: str | None = None) -> int:
    """Run every check; print one line and return the exit code (0: all passed)."""
    started = time.monotonic()
    try:
        summary = _run_checks(screenshot)
    except SmokeTestFailure as exc:
        print(f"inclinometer smoke test FAILED: {exc}", file=sys.stderr, flush=True)
        return 1
    except Exception as exc:  # the reason, not a traceback, is what CI shows
        print(f"inclinometer smoke test FAILED: {type(exc).__name__}: {exc}",
              file=sys.stderr, flush=True)
        return 1
    print(f"inclinometer smoke test passed in {time.monotonic() - started:.1f} s: {summary}",
          flush=True)
    return 0


def _run_checks(screenshot: str | None) -> str:
    _use_offscreen_without_a_screen()
    from PySide6.QtCore import QSettings, qInstallMessageHandler
    from PySide6.QtWidgets import QApplication

    from app import __version__
    from app.core.filters import DEFAULT_FILTER
    from app.core.recording import sample_recordings
    from app.gui import theme
    from app.gui.application import APPLICATION, ORGANIZATION
    from app.gui.main_window import MainWindow
    from app.services.devices import replay_url
    from app.services.session import DeviceSession

    qInstallMessageHandler(_quiet_offscreen_warnings)
    app = QApplication.instance() or QApplication([sys.argv[0]])
    app.setOrganizationName(ORGANIZATION)
    app.setApplicationName(APPLICATION)
    theme.apply_theme(app)
    if not app.styleSheet():
        raise SmokeTestFailure("the stylesheet resources/styles/instrument.qss did not load")
    if theme.app_icon().isNull():
        raise SmokeTestFailure("the application icon resources/icons/inclinometer.svg is null")
    recordings = sample_recordings()
    if not recordings:
        raise SmokeTestFailure("no sample recordings in resources/recordings")

    with tempfile.TemporaryDirectory(prefix="inclinometer-smoke-") as folder:
        settings = QSettings(str(Path(folder) / "settings.ini"), QSettings.Format.IniFormat)
        session = DeviceSession()
        errors: list[str] = []
        session.error.connect(errors.append)
        try:
            window = MainWindow(session, settings, SIMULATOR_URL, DEFAULT_FILTER)
        except BaseException:
            session.shutdown()  # its worker thread must not outlive the failed window
            raise
        try:
            window.resize(1280, 860)
            window.show()
            # 2. Live samples through the filter into the views.
            pipeline = session.pipeline
            _wait_until(app, lambda: session.device_info is not None or bool(errors),
                        f"the simulator to connect ({SIMULATOR_URL})")
            if errors:
                raise SmokeTestFailure(f"connecting {SIMULATOR_URL}: {errors[0]}")
            frames_before = window.presenter.frames
            _wait_until(app, lambda: pipeline.counters.samples >= LIVE_SAMPLES,
                        f"{LIVE_SAMPLES} samples from the simulator")
            _wait_until(app, lambda: pipeline.orientation.total_written >= LIVE_SAMPLES,
                        "the filter's output in the ring buffer")
            _wait_until(app, window.level.isValid, "the bubble level to show an attitude")
            _wait_until(app, lambda: _curve_points(window.plots.accel_curves[2]) > 100,
                        "the acceleration plot to fill")
            if pipeline.filter.name != DEFAULT_FILTER:
                raise SmokeTestFailure(f"the filter is {pipeline.filter.name!r}, "
                                       f"not {DEFAULT_FILTER!r}")
            latest = pipeline.orientation.latest(50)
            error = np.hypot(latest["roll"] - latest["ref_roll"],
                             latest["pitch"] - latest["ref_pitch"])
            if not np.all(np.isfinite(error)) or float(np.max(error)) > 5.0:
                raise SmokeTestFailure(f"the filter is {np.max(error):.2f}° off the simulator's "
                                       "true attitude")
            # 3. Frames drawn.
            _wait_until(app, lambda: window.presenter.frames >= frames_before + 10,
                        "10 frames from the presenter")
            live_frames = window.presenter.frames - frames_before
            image = window.grab().toImage()
            colours = _distinct_colours(image)
            if image.isNull() or colours < 20:
                raise SmokeTestFailure(f"the window renders blank ({colours} colours)")
            if screenshot and not image.save(screenshot):
                raise SmokeTestFailure(f"could not save the screenshot to {screenshot}")
            live_samples = pipeline.counters.samples
            odr = session.device_info.odr_hz
            # 4. A bundled sample recording replays through the same pipeline.
            recording = recordings[0]
            url = replay_url(str(recording))
            window.open_recording(str(recording))
            _wait_until(app, lambda: (session.device_info is not None
                                      and session.device_info.url == url) or bool(errors),
                        f"the replay of {recording.name}")
            if errors:
                raise SmokeTestFailure(f"replaying {recording.name}: {errors[0]}")
            _wait_until(app, lambda: pipeline.orientation.total_written >= REPLAY_SAMPLES,
                        f"{REPLAY_SAMPLES} replayed samples through the filter")
            if not window.replay_bar.isVisible():
                raise SmokeTestFailure("the replay bar is hidden during a replay")
            replayed = pipeline.orientation.total_written
        finally:
            window.close()
            app.processEvents()
        # 5. The kernels, directly.
        kernels = check_kernels()
    frozen = ("frozen bundle" if getattr(sys, "frozen", False)
              else f"Python {sys.version_info.major}.{sys.version_info.minor}")
    return (f"inclinometer {__version__} ({frozen}, Qt platform {app.platformName()}); "
            f"{live_samples} samples at {odr:g} Hz through {DEFAULT_FILTER}, {live_frames} "
            f"frames drawn; replayed {replayed} samples of {recording.name}; {kernels}")
