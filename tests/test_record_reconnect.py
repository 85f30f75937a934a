"""Headless ``inclinometer record`` survives an unplug: an emulated NUCLEO on a pseudo-terminal
is pulled mid-recording and plugged back in (a new port, the same USB serial and unique id).

The command runs in the main thread as from a shell; a helper thread plays the user, acting on
what the command prints (no sleeps).
"""

from __future__ import annotations

import io
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from app import cli_recording
from app.cli import main
from app.core.recording import read_recording
from app.services import recorder
from drivers.emulated_nucleo import EmulatedNucleo
from drivers.sim.error_model import unique_id_for_seed

ODR_HZ = 208.0
WAIT_S = 10.0
MIN_ROWS = 25
LOST = re.compile(r"inclinometer: device lost at (\d+\.\d) s: (.*was disconnected.*); "
                  r"waiting for it \(Ctrl-C stops\)\n")
BACK = re.compile(r"inclinometer: device back after (\d+\.\d) s, (\d+) samples lost, "
                  r"marked as a gap\n")


class Tap(io.TextIOBase):
    """stderr that another thread can wait on."""

    def __init__(self) -> None:
        self.text = ""
        self._changed = threading.Condition()

    def write(self, text: str) -> int:
        with self._changed:
            self.text += text
            self._changed.notify_all()
        return len(text)

    def wait_for(self, pattern: re.Pattern[str]) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: pattern.search(self.text), WAIT_S)


@pytest.fixture
def board():
    nucleo = EmulatedNucleo("static", odr_hz=ODR_HZ, seed=23)
    yield nucleo
    nucleo.close()


def tap_stderr(monkeypatch) -> Tap:
    """Put a :class:`Tap` in place of stderr (in the test: capsys replaces it at the call)."""
    stream = Tap()
    monkeypatch.setattr(sys, "stderr", stream)
    return stream


def rows_in(path: Path) -> int:
    """Data rows the OS has of a recording being written (the header row counted off)."""
    try:
        lines = path.read_bytes().split(b"\n")[:-1]
    except FileNotFoundError:
        return 0
    return max(0, sum(1 for line in lines if not line.startswith(b"#")) - 1)


def wait_for_rows(path: Path, count: int) -> bool:
    """Poll the file (every 10 ms, as qtbot.waitUntil) until it has ``count`` rows. The
    progress lines are no use here: they come after an fsync, which a busy disk holds up."""
    stop_at = time.monotonic() + WAIT_S
    while rows_in(path) < count and time.monotonic() < stop_at:
        time.sleep(0.01)
    return rows_in(path) >= count


def play(tap: Tap, board: EmulatedNucleo, out: Path,
         when_lost: Callable[[], object] | None) -> threading.Thread:
    """Pull the cable once rows are in the file; once the loss is reported, ``when_lost()``."""
    def user() -> None:
        if wait_for_rows(out, MIN_ROWS):
            board.close()
            if when_lost is not None and tap.wait_for(LOST):
                when_lost()

    thread = threading.Thread(target=user, name="user", daemon=True)
    thread.start()
    return thread


def test_record_reconnects_by_usb_serial_and_marks_the_outage(tmp_path, board, monkeypatch, capsys):
    tap = tap_stderr(monkeypatch)
    out = tmp_path / "unplugged.csv"
    first_port = board.port
    squatter: list[int] = []

    def replug_then_stop() -> None:
        squatter.extend(os.openpty())  # hold the freed pty: the board comes back elsewhere
        board.replug()
        if tap.wait_for(BACK) and wait_for_rows(out, rows_in(out) + MIN_ROWS):
            os.kill(os.getpid(), signal.SIGTERM)  # the recording's own stop

    user = play(tap, board, out, replug_then_stop)
    try:
        code = main(["record", "--device", first_port, "--duration", "30", str(out)])
    finally:
        user.join(WAIT_S)
        for fd in squatter:
            os.close(fd)
    assert code == 0, tap.text
    assert board.port != first_port, tap.text
    lost, back = LOST.search(tap.text), BACK.search(tap.text)
    assert lost and back, tap.text
    assert lost.start() < back.start()

    recording = read_recording(out)
    t, gap = recording.t_s, recording.gap.astype(bool)
    assert recording.device["unique_id"] == unique_id_for_seed(board.seed).removeprefix("SIM-")
    assert np.all(np.diff(t) > 0)  # time runs on across the outage, nothing repeated
    marked = np.flatnonzero(gap[1:]) + 1
    assert len(marked) == 1, marked  # the outage, and nothing else, is a gap
    k = int(marked[0])
    period = 1.0 / recording.device["odr_hz"]
    assert k >= MIN_ROWS and len(t) - k >= MIN_ROWS  # rows before and after it
    span = t[k] - t[k - 1]
    assert span > 5 * period  # the hole in t spans the outage
    assert float(lost.group(1)) == pytest.approx(t[k - 1] - t[0], abs=0.051)
    assert float(back.group(1)) == pytest.approx(span, abs=0.051)
    assert int(back.group(2)) == round(span / period) - 1
    summary = capsys.readouterr().out
    assert f"{out}: {len(recording)} rows, {t[-1] - t[0]:.1f} s of device time (stopped)" in (
        summary)


def test_record_gives_up_after_the_reconnect_timeout(tmp_path, board, monkeypatch, capsys):
    tap = tap_stderr(monkeypatch)
    out = tmp_path / "gone.csv"
    user = play(tap, board, out, lambda: None)
    try:
        code = main(["record", "--device", board.port, "--duration", "20",
                     "--reconnect-timeout", "0.3", str(out)])
    finally:
        user.join(WAIT_S)
    assert code == 1
    recording = read_recording(out)  # closed validly
    assert len(recording) >= MIN_ROWS and not recording.gap[1:].any()
    assert LOST.search(tap.text) and not BACK.search(tap.text)
    assert re.search(r"inclinometer: the device was lost at \d+\.\d s \(.*\) and did not come "
                     rf"back within 0\.3 s; the file keeps the {len(recording)} rows", tap.text)
    assert "(the device did not come back)" in capsys.readouterr().out


def test_ctrl_c_while_waiting_closes_the_file(tmp_path, board, monkeypatch, capsys):
    tap = tap_stderr(monkeypatch)
    out = tmp_path / "stopped.csv"
    user = play(tap, board, out, lambda: os.kill(os.getpid(), signal.SIGINT))
    try:
        code = main(["record", "--device", board.port, "--duration", "20", str(out)])
    finally:
        user.join(WAIT_S)
    assert code == 0  # stopped by the user, as a Ctrl-C while recording
    recording = read_recording(out)
    assert len(recording) >= MIN_ROWS
    assert "stopped while waiting for the device" in tap.text
    assert f"{len(recording)} rows" in capsys.readouterr().out


def test_no_reconnect_ends_at_the_unplug(tmp_path, board, monkeypatch, capsys):
    tap = tap_stderr(monkeypatch)
    out = tmp_path / "old.csv"
    user = play(tap, board, out, None)
    try:
        code = main(["record", "--device", board.port, "--duration", "20", "--no-reconnect",
                     str(out)])
    finally:
        user.join(WAIT_S)
    assert code == 1
    assert not LOST.search(tap.text)
    assert "was disconnected" in tap.text
    assert len(read_recording(out)) >= MIN_ROWS
    assert "(the device failed)" in capsys.readouterr().out


def test_reconnect_options_are_checked(tmp_path, monkeypatch):
    tap = tap_stderr(monkeypatch)
    out = tmp_path / "x.csv"
    assert main(["record", "--device", "sim://static", "--reconnect-timeout", "soon",
                 str(out)]) == 2
    assert main(["record", "--device", "sim://static", "--reconnect-timeout", "5",
                 "--no-reconnect", str(out)]) == 2
    assert not out.exists()
    assert "--reconnect-timeout 'soon': give seconds" in tap.text
    assert "--reconnect-timeout and --no-reconnect contradict each other" in tap.text
    assert cli_recording.DEFAULT_RECONNECT_TIMEOUT_S == recorder.DEFAULT_RECONNECT_TIMEOUT_S
