"""Test set-up: offscreen Qt, and no QThread or QTimer may outlive a test (as napari does)."""

from __future__ import annotations

import os
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

ARTIFACTS = os.path.join(os.path.dirname(os.path.dirname(__file__)), "test-artifacts")
# The firmware's host harness (firmware/host/fwcore.py) lives beside the firmware sources.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(__file__)), "firmware", "host"))


@pytest.fixture(scope="session")
def firmware_lib(tmp_path_factory):
    """The firmware's portable core built for this machine (``make -C firmware host``)."""
    from fwcore import build_library

    return build_library(tmp_path_factory.mktemp("firmware-build"))


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
