"""The closing metadata of a recording (issue 36, item 8): Ctrl-C or a full disk during the
final rewrite loses no rows and no alarm crossings, and the message and the exit code say
what was kept and where."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import signal
import threading
import types
from pathlib import Path

from app.cli import main
from app.core.alarms import recorded_alarm_events
from app.core.recording import closing, edit, read_recording

# Roll swings +-10° with a 4 s period: "roll>5" is raised and cleared twice in 6 s.
SWING = "sim://slow-tilt?odr=104&realtime=0&amplitude=10&roll_period=4&pitch_period=1000&seed=2"


def _record(out: Path) -> int:
    return main(["record", "--device", SWING, "--duration", "6", "--quiet",
                 "--alarm", "roll>5,hyst=0.5,delay=0.2", str(out)])


class _Proxy(types.SimpleNamespace):
    """A module seen through one replaced function (the rest is the real module's)."""

    def __init__(self, module: types.ModuleType, **replaced: object) -> None:
        super().__init__(**replaced)
        self._module = module

    def __getattr__(self, name: str) -> object:
        return getattr(self._module, name)


class _FullDisk:
    """The rewrite's temporary file on a disk with ``free`` bytes left (a real file)."""

    def __init__(self, handle, free: int) -> None:
        self._handle, self._free = handle, free

    def write(self, data) -> int:
        if len(data) > self._free:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self._free -= len(data)
        return self._handle.write(data)

    def __getattr__(self, name: str):
        return getattr(self._handle, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self._handle.close()


def _printed_rows(stdout: str, out: Path) -> int:
    return int(re.search(rf"^{re.escape(str(out))}: (\d+) rows", stdout, re.M).group(1))


def test_ctrl_c_during_the_final_rewrite_is_held_until_the_crossings_are_stored(
        tmp_path, capsys, monkeypatch):
    out = tmp_path / "swing.csv"
    interrupted = []

    def copy_after_ctrl_c(source, target, length=0):
        interrupted.append(True)
        os.kill(os.getpid(), signal.SIGINT)  # a real Ctrl-C, in the middle of the rewrite
        return shutil.copyfileobj(source, target, length)

    monkeypatch.setattr(edit, "shutil", _Proxy(shutil, copyfileobj=copy_after_ctrl_c))
    assert _record(out) == 0
    captured = capsys.readouterr()
    assert interrupted
    rows = _printed_rows(captured.out, out)
    assert f"{out}: {rows} rows, 6.0 s of device time (stopped by Ctrl-C)" in captured.out
    assert "interrupted before recording started" not in captured.err
    assert "the signal came while the file was being closed: it was finished first" in (
        captured.err)
    recording = read_recording(out)
    assert len(recording) == rows > 600
    assert [e.state for e in recorded_alarm_events(recording.metadata)] == [
        "raised", "cleared", "raised", "cleared"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["swing.csv"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # given back


def test_a_full_disk_during_the_final_rewrite_keeps_the_crossings_beside_the_file(
        tmp_path, capsys, monkeypatch):
    out = tmp_path / "swing.csv"
    real_fdopen = os.fdopen
    monkeypatch.setattr(edit, "os", _Proxy(
        os, fdopen=lambda fd, *a, **k: _FullDisk(real_fdopen(fd, *a, **k), 4096)))
    assert _record(out) == 1
    captured = capsys.readouterr()
    rows = _printed_rows(captured.out, out)
    aside = tmp_path / "swing.csv.closing.json"
    assert (f"{out}: the {rows} rows (6.0 s) were kept, but the 4 alarm crossings could not be "
            f"added to it (No space left on device); they were written to {aside}"
            ) in captured.err
    recording = read_recording(out)  # the rows, untouched by the failed rewrite
    assert len(recording) == rows and "alarm_events" not in recording.metadata
    kept = json.loads(aside.read_text())
    assert kept["recording"] == "swing.csv"
    assert [e["state"] for e in kept["metadata"]["alarm_events"]] == [
        "raised", "cleared", "raised", "cleared"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["swing.csv", "swing.csv.closing.json"]


def test_with_no_room_beside_it_either_the_crossings_are_in_the_message(tmp_path, capsys,
                                                                        monkeypatch):
    out = tmp_path / "swing.csv"

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(edit, "rewrite_metadata", no_space)
    monkeypatch.setattr(closing, "write_output", no_space)
    assert _record(out) == 1
    err = capsys.readouterr().err
    line = next(line for line in err.splitlines() if "could not be added" in line)
    assert "nor written beside it; here they are: " in line
    document = json.loads(line.split("here they are: ", 1)[1])
    assert len(document["metadata"]["alarm_events"]) == 4
    assert len(read_recording(out)) > 600


def test_the_windows_closing_rewrite_keeps_its_entries_beside_a_file_on_a_full_disk(
        tmp_path, monkeypatch):
    from app.services.health import HealthMonitor
    from app.services.recorder import record_device
    from drivers.sim.device import SimulatedDevice

    path = tmp_path / "live.csv"
    record_device(SimulatedDevice("sim://static?odr=104", realtime=False), path, duration_s=2)
    before = path.read_bytes()
    real_fdopen = os.fdopen
    monkeypatch.setattr(edit, "os", _Proxy(
        os, fdopen=lambda fd, *a, **k: _FullDisk(real_fdopen(fd, *a, **k), 1000)))
    entries = {"alarm_events": [{"t": 1.5, "quantity": "tilt", "state": "raised"}]}
    health = HealthMonitor()
    health.begin_recording()
    messages: list[str] = []
    health.end_recording(path, messages.append, also=entries)
    for thread in threading.enumerate():
        if thread.name == "save-fault-events":
            thread.join(10)
    aside = tmp_path / "live.csv.closing.json"
    assert messages == [f"{path}: its rows were kept, but the closing metadata could not be "
                        f"added to it (No space left on device); they were written to {aside}"]
    assert path.read_bytes() == before
    assert json.loads(aside.read_text()) == {"recording": "live.csv", "metadata": entries}
