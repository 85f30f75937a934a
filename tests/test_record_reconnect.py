"""Headless ``inclinometer record`` survives an unplug: an emulated NUCLEO on a pseudo-terminal
is pulled mid-recording and plugged back in (a new pseudo-terminal, the same USB serial and
unique id). Also the time axis a reconnection continues (the window's and record's).

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

from app.cli import main
from app.cli import record as cli_recording
from app.core.devices import DeviceInfo
from app.core.recording import read_recording
from app.core.samples import RawBlock, ScaleFactors
from app.services import recorder
from app.services.connection import Connection
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


@pytest.mark.parametrize("power_cycle", [False, True], ids=["clock-runs-on", "board-reset"])
def test_record_reconnects_by_usb_serial_and_marks_the_outage(tmp_path, board, monkeypatch,
                                                              capsys, power_cycle):
    tap = tap_stderr(monkeypatch)
    out = tmp_path / "unplugged.csv"
    def replug_then_stop() -> None:
        board.replug(power_cycle=power_cycle)  # a reset board's clock starts at 0 again
        if tap.wait_for(BACK) and wait_for_rows(out, rows_in(out) + MIN_ROWS):
            os.kill(os.getpid(), signal.SIGTERM)  # the recording's own stop

    user = play(tap, board, out, replug_then_stop)
    try:
        code = main(["record", "--device", board.port, "--duration", "30", str(out)])
    finally:
        user.join(WAIT_S)
    assert code == 0, tap.text
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
    assert span > 1.5 * period  # a hole in t spans the outage
    assert int(back.group(2)) >= 1
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
    assert re.search(r"inclinometer: the device lost at \d+\.\d s did not come back within "
                     rf"0\.3 s; the file keeps the {len(recording)} rows \(", tap.text)
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


class _Board:
    """A closed-or-open stand-in for a serial board: its info and its clock origin."""

    url = "/dev/ttyACM0"

    def __init__(self, origin_s: float) -> None:
        self.device_clock_origin_s = origin_s
        self.info = DeviceInfo(url=self.url, name="NUCLEO", unique_id="ABC", sensor="LSM6DSOX",
                               odr_hz=100.0, odr_nominal_hz=104.0, accel_fs_g=4,
                               gyro_fs_dps=250, extra={"usb_serial": "0670FF"})

    def open(self) -> DeviceInfo:
        return self.info

    def close(self) -> None:
        pass


def _block(t0: float) -> RawBlock:
    n = 5
    return RawBlock(t_s=t0 + np.arange(n) / 100.0, accel_raw=np.zeros((n, 3)),
                    gyro_raw=np.zeros((n, 3)), temp_raw=np.zeros(n),
                    scale=ScaleFactors(1e-3, 1e-4))


@pytest.mark.parametrize(("new_origin_s", "first_t_s"), [
    (2.1, 10.0 + 5.0),  # reset, and streaming as late after power-on as before: host clock
    (0.5, 10.0 + 5.0),  # reset, streaming sooner: host clock
    (2.0 + 10.0 + 7.0, 10.0 + 7.0),  # the clock ran on: the board's clock spans the outage
])
def test_a_reconnected_board_continues_the_time_axis(new_origin_s, first_t_s):
    now = [100.0]
    boards = iter([_Board(2.0), _Board(new_origin_s)])
    connection = Connection(factory=lambda url: next(boards),
                            find_board=lambda url, serial: url, clock=lambda: now[0])
    connection.open("/dev/ttyACM0")
    connection.continue_time_axis(_block(0.0))
    assert connection.await_board("unplugged", last_t_s=10.0) is not None
    assert connection.try_reconnect() is not None
    now[0] += 5.0  # host time from the loss to the first block after it
    raw = _block(0.0)
    connection.continue_time_axis(raw)
    assert raw.t_s[0] == pytest.approx(first_t_s)
    assert raw.gap is not None and raw.gap[0] and not raw.gap[1:].any()
