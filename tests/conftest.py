"""Test set-up: offscreen Qt, and no QThread or QTimer may outlive a test (as napari does)."""

from __future__ import annotations

import gc
import os
import signal
import subprocess
import sys
import tempfile
import traceback
from weakref import WeakKeyDictionary

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# Never read or write the user's real settings, profiles or recordings from a test.
_USER_DIRS = tempfile.mkdtemp(prefix="inclinometer-tests-")
for _variable in ("XDG_DATA_HOME", "XDG_CONFIG_HOME", "XDG_CACHE_HOME", "XDG_STATE_HOME"):
    os.environ[_variable] = os.path.join(_USER_DIRS, _variable.lower())

# A shell without job control (a script's `make test &`, nohup) starts the suite with SIGINT
# ignored, and every process it starts inherits that: the tests of what Ctrl-C does to
# `record` and `simulate` then waited out their timeouts (one for 300 s). A test process
# answers Ctrl-C as a terminal's foreground job does, and so do the commands it starts.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

ARTIFACTS = os.path.join(os.path.dirname(os.path.dirname(__file__)), "test-artifacts")
# The firmware's host harness (firmware/host/fwcore.py) lives beside the firmware sources.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(__file__)), "firmware", "host"))


COMPILE_SHARES = (("ekf", "gyro"), (), ("faults",))
"""The live filters' kernels in two shares of about equal compile time (the EKF alone is
half; ``()`` is every other filter), and the fault detector's, which every session loads
before its device opens (about 9 s to compile)."""
_COMPILE_SCRIPT = (
    "import sys\n"
    "if sys.argv[1:] == ['faults']:\n"
    "    from app.core.faults.warm_up import warm_up_detector\n"
    "    warm_up_detector()\n"
    "    sys.exit()\n"
    "from app.core.filters import ONLINE_FILTERS, create_filter\n"
    "share = sys.argv[1:] or [n for n in ONLINE_FILTERS if n not in {shared}]\n"
    "for name in share:\n"
    "    create_filter(name).warm_up()\n"
)


LONG_TESTS_FIRST = (
    "test_link_fuzz.py::test_decoder_survives_100000_mutated_streams",
    "test_soak_benchmark.py::test_soak_script_accounts_for_every_sample",
    "test_recording.py::test_sigkill_of_a_recording_process_leaves_a_file_with_every_flushed_row",
    "test_look_and_settings.py::test_screenshots_of_every_theme_and_mode",
    "test_window_fit.py::test_no_text_is_clipped_in_any_dock_or_dialog_at_either_size_in_any_theme",
    "test_packaging.py::test_smoke_test_passes_from_source_and_saves_a_screenshot",
)
"""The suite's longest tests (10-45 s each; 0.4 s is the median). They run first: xdist's
work stealing balances the workers with the short ones, but a long test that starts late
keeps one worker busy after the other has run out of tests."""


def pytest_collection_modifyitems(config, items):
    """:data:`LONG_TESTS_FIRST` at the front, the rest in their order (the same in every
    worker: xdist requires it)."""
    first = [item for name in LONG_TESTS_FIRST for item in items if item.nodeid.endswith(name)]
    chosen = set(map(id, first))
    items[:] = first + [item for item in items if id(item) not in chosen]


def pytest_sessionstart(session):
    """Every live filter's numba kernels compiled (or loaded from the cache) once per test
    process, before any test (a hook, so no test's timeout counts it). From a cold cache (a
    fresh clone) the EKF alone takes about 15 s to compile, and numba holds the GIL meanwhile:
    a window test that happened to be a process's first EKF user timed out waiting for its
    device, and the GUI thread of others stalled mid-test.

    Under xdist the controller, before it starts the workers (xdist's hook runs last), has
    the kernels compiled into numba's cache by three processes, a share each: each worker
    then loads them, where before every worker compiled all of them at once on a cold cache.
    The fault detector's too: every session loads them before its device opens."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None and session.config.getoption(
            "numprocesses", default=None):
        _compile_kernels_in_parallel()
        return
    from app.core.faults.warm_up import warm_up_detector
    from app.core.filters import ONLINE_FILTERS, create_filter

    for name in ONLINE_FILTERS:
        create_filter(name).warm_up()
    warm_up_detector()


def _compile_kernels_in_parallel() -> None:

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    script = _COMPILE_SCRIPT.format(shared=sorted(COMPILE_SHARES[0]))
    processes = [subprocess.Popen([sys.executable, "-c", script, *share], cwd=root)
                 for share in COMPILE_SHARES]
    for process in processes:  # a failure shows again, with its test, in the workers
        process.wait()


@pytest.fixture(scope="session", autouse=True)
def _qapplication_first(qapp):
    """The process's QApplication exists before its first test: a command that draws a
    document (``lab`` reports, the fault plots) makes a bare QGuiApplication when there is
    none, and every widget test after it in that process then failed ("no attribute
    'style'"), in whichever process xdist had given such a command first."""
    return qapp


@pytest.fixture(autouse=True)
def _environment_left_as_found():
    """Fail a test that leaves the process's environment changed: every later test in its
    process, and every subprocess they start, would run with it (a leaked NUMBA_CACHE_DIR
    made each later subprocess compile every kernel again, 20-40 s a test)."""
    before = dict(os.environ)
    yield
    after = dict(os.environ)
    for name in ("PYTEST_CURRENT_TEST",):  # pytest's own, set for each phase
        before.pop(name, None)
        after.pop(name, None)
    if after != before:
        changed = sorted(name for name in {*before, *after} if before.get(name) != after.get(name))
        pytest.fail(f"the test left the environment changed: {', '.join(changed)}",
                    pytrace=False)


@pytest.fixture(scope="session")
def firmware_lib(tmp_path_factory):
    """The firmware's portable core built for this machine (``make -C firmware host``), once
    per run: under xdist the first worker to need it builds it into the run's shared
    temporary folder while the others wait on a lock, then each loads it (a build with the
    sanitizers takes about 5 s of a core)."""
    import fcntl
    from pathlib import Path

    from fwcore import build_library

    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        return build_library(tmp_path_factory.mktemp("firmware-build"))
    shared: Path = tmp_path_factory.getbasetemp().parent / "firmware-build"
    shared.mkdir(exist_ok=True)
    with open(shared / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        return build_library(shared)  # make: nothing to do once a worker has built it


@pytest.fixture
def artifacts_dir() -> str:
    """Folder for screenshots and other files a person may look at after the run."""
    os.makedirs(ARTIFACTS, exist_ok=True)
    return ARTIFACTS


@pytest.fixture(autouse=True)
def _no_dangling_qthreads_or_timers(request, monkeypatch):
    """Fail a test that leaves a started QThread running or a QTimer active."""
    if "qtbot" not in request.fixturenames and "qapp" not in request.fixturenames:
        yield
        return
    from PySide6.QtCore import QThread, QTimer

    threads: WeakKeyDictionary = WeakKeyDictionary()
    timers: WeakKeyDictionary = WeakKeyDictionary()
    thread_start = QThread.start
    timer_start = QTimer.start

    def tracked_thread_start(self, *args):
        threads[self] = "".join(traceback.format_stack(limit=6)[:-1])
        return thread_start(self, *args)

    def tracked_timer_start(self, *args):
        timers[self] = "".join(traceback.format_stack(limit=6)[:-1])
        return timer_start(self, *args)

    monkeypatch.setattr(QThread, "start", tracked_thread_start)
    monkeypatch.setattr(QTimer, "start", tracked_timer_start)
    yield
    problems = []
    for thread, where in list(threads.items()):
        try:
            if thread.isRunning():
                problems.append(f"QThread still running, started at:\n{where}")
        except RuntimeError:  # the C++ object is gone: fine
            pass
    for timer, where in list(timers.items()):
        try:
            if timer.isActive():
                problems.append(f"QTimer still active, started at:\n{where}")
        except RuntimeError:
            pass
    if problems:
        pytest.fail("\n".join(problems))


@pytest.hookimpl(trylast=True)
def pytest_runtest_teardown(item, nextitem):
    """Delete the widgets the test closed, after every fixture is torn down.

    pytest-qt closes a test's widgets and calls ``deleteLater``, but only a return to the event
    loop deletes them, and ``processEvents`` does not. Without this a main window, its menus,
    docks and dialogs (about 120 top-level widgets) outlived every test that made one: 3 000
    after four GUI test files, and each application-wide stylesheet change then re-polished all
    of them (12-19 s per teardown in test_widgets).
    """
    _collect_garbage()
    if "PySide6.QtWidgets" not in sys.modules:
        return
    from PySide6.QtCore import QCoreApplication, QEvent

    app = QCoreApplication.instance()
    if app is None:
        return
    QCoreApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete)
    # pyqtgraph gives every plot's and view box's context menus no parent, so Qt does not
    # delete them with their plot; they live as long as a Python reference to the plot does.
    from PySide6.QtWidgets import QApplication, QMenu

    if not isinstance(app, QApplication):  # a Qt-core or Qt-GUI application has no widgets
        return
    for widget in app.topLevelWidgets():
        if isinstance(widget, QMenu) and widget.parent() is None and not widget.isVisible():
            widget.deleteLater()
    QCoreApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete)


# -- the display: views in a shown window, a presenter over a pipeline fed by hand -------------
LIVE_ODR_HZ = 104.0
"""The pipeline's rate in ``live`` (test_display_refresh.raw_block makes blocks at it)."""


@pytest.fixture
def host(qtbot):
    """A shown window holding the views, and a sentinel label to flush paints with."""
    from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget

    window = QWidget()
    layout = QVBoxLayout(window)
    window.sentinel = QLabel("sentinel")
    layout.addWidget(window.sentinel)
    qtbot.addWidget(window)
    window.resize(900, 900)
    return window


@pytest.fixture
def live(qtbot, host):
    """A presenter over a real pipeline (fed by hand) and real views in a shown window;
    ``handed`` lists the rows of every rebuild of the plots."""
    from types import SimpleNamespace

    from PySide6.QtWidgets import QLabel

    from app.core.pipeline import Pipeline
    from app.gui.bubble_level import BubbleLevel
    from app.gui.filter_panel import FilterPanel
    from app.gui.plots import LivePlots
    from app.gui.presenter import LivePresenter
    from app.gui.readouts import TiltReadouts

    pipeline = Pipeline(odr_hz=LIVE_ODR_HZ)
    session = SimpleNamespace(pipeline=pipeline, device_info=None)
    level, readouts, plots = BubbleLevel(), TiltReadouts(), LivePlots()
    truth, panel = QLabel(), FilterPanel()
    for widget in (level, readouts, plots, truth, panel):
        host.layout().addWidget(widget)
    plots.setMinimumHeight(300)
    presenter = LivePresenter(session, level, readouts, plots, truth, panel, parent=host)
    # Each refresh takes what is new at once (coalescing has its own test).
    presenter.level_interval_s = presenter.plot_data_interval_s = 0.0
    host.show()
    qtbot.waitExposed(host)
    handed = []
    original = plots.set_data

    def spy(*args, **kwargs):
        handed.append(len(args[0]))
        return original(*args, **kwargs)

    plots.set_data = spy
    return SimpleNamespace(
        pipeline=pipeline, presenter=presenter, plots=plots, level=level, handed=handed
    )


# -- garbage: collected in the main thread only ----------------------------------------------
# Python's cycle collector runs in whichever thread allocates. In a device worker or a
# simulator's thread it freed Qt objects of the main thread mid-timer: a segmentation fault
# in a later test (reproduced with test_window_fit's value-labels test before a window test).
# The app collects on a GUI-thread timer (pyqtgraph's GarbageCollector); the tests collect at
# each test's end, as the automatic collector would, by generation thresholds.
_THRESHOLDS = gc.get_threshold()
gc.disable()


def _collect_garbage() -> None:
    young, middle, old = gc.get_count()
    if young > _THRESHOLDS[0]:
        gc.collect(0)
        if middle > _THRESHOLDS[1]:
            gc.collect(1)
            if old > _THRESHOLDS[2]:
                gc.collect(2)

