"""Outputs never destroy data (issue 36): no existing file without --overwrite, never an
input (device and inode: hard links too), atomic replacement, one writer per file."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from app.cli import main
from app.core.recording import read_recording
from app.core.safe_output import (
    OutputLock,
    OutputRefused,
    check_output,
    output_file,
    output_path,
    write_output,
)
from app.services.recorder import record_device
from drivers.sim.device import SimulatedDevice

PRECIOUS = b"precious data, byte for byte\n"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """A small recording with a reference (1.5 s of the simulator at 104 Hz)."""
    path = tmp_path_factory.mktemp("source") / "wobble.csv"
    device = SimulatedDevice("sim://wobble?odr=104&seed=4", realtime=False)
    record_device(device, path, duration_s=1.5)
    return path


def _source_copy(recording: Path, folder: Path) -> Path:
    copy = folder / "in.csv"
    copy.write_bytes(recording.read_bytes())
    return copy


def test_replay_refuses_a_hard_link_of_its_recording_even_with_overwrite(recording, tmp_path,
                                                                         capsys):
    source = _source_copy(recording, tmp_path)
    before = source.read_bytes()
    link = tmp_path / "angles.csv"
    os.link(source, link)  # another name, the same file
    symlink = tmp_path / "also.csv"
    symlink.symlink_to(source)
    for target in (link, symlink):
        for extra in ([], ["--overwrite"]):
            assert main(["replay", str(source), "--out", str(target), *extra]) == 2
            err = capsys.readouterr().err
            assert "would overwrite the recording itself" in err and err[-1] == "\n"
            assert err.count("\n") == 1
    assert source.read_bytes() == before and link.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["also.csv", "angles.csv", "in.csv"]


@pytest.mark.parametrize("command", [
    ["replay", "{src}", "--out", "{out}"],
    ["evaluate", "{src}", "--json", "{out}"],
    ["allan", "{src}", "--json", "{out}"],
    ["calibrate", "{src}", "--out", "{out}"],
    ["calibrate", "{src}", "--report", "{out}.html"],
    ["calibrate-temperature", "{src}", "--out", "{out}"],
    ["joint", "{src}", "{src}", "--out", "{out}"],
    ["record", "--device", "sim://static?realtime=0", "--duration", "1", "--quiet", "{out}"],
    ["allan", "{src}", "--kalibr", "{out}"],
    ["export", "{src}", "--format", "mcap", "{out}"],
    ["export", "{src}", "--format", "euroc", "{out}"],
])
def test_every_writing_command_refuses_an_existing_file(recording, tmp_path, capsys, command):
    existing = tmp_path / "existing.out"
    args = [a.format(src=recording, out=existing) for a in command]
    target = Path(next(a for a in args if a.startswith(str(existing))))
    target.write_bytes(PRECIOUS)
    assert main(args) in (1, 2)
    err = capsys.readouterr().err
    assert "exists" in err and str(target) in err
    assert target.read_bytes() == PRECIOUS
    assert [p.name for p in tmp_path.iterdir()] == [target.name]  # no temporary, no lock


def test_overwrite_replaces_with_a_complete_file_and_keeps_the_old_inode(recording, tmp_path,
                                                                       capsys):
    target = tmp_path / "angles.csv"
    target.write_bytes(PRECIOUS)
    os.chmod(target, 0o640)
    reader = open(target, "rb")  # noqa: SIM115 (someone reading the old file meanwhile)
    try:
        assert main(["replay", str(recording), "--out", str(target), "--overwrite"]) == 0
        assert reader.read() == PRECIOUS  # replaced by a rename, not truncated
    finally:
        reader.close()
    assert target.read_text().startswith("# inclinometer-angles 1")
    assert (target.stat().st_mode & 0o777) == 0o640
    assert capsys.readouterr().err == ""
    # evaluate --json replaces too, with --overwrite
    target.write_bytes(PRECIOUS)
    assert main(["evaluate", str(recording), "--filter", "complementary", "--repeats", "1",
                 "--json", str(target), "--overwrite"]) == 0
    assert target.read_text().lstrip().startswith("{")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["angles.csv"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.json"
    target.write_bytes(PRECIOUS)
    with pytest.raises(RuntimeError), output_file(target, overwrite=True) as handle:
        handle.write(b"half a fi")
        raise RuntimeError("the computation failed half way")
    assert target.read_bytes() == PRECIOUS
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_a_file_that_appears_while_writing_is_not_replaced(tmp_path):
    target = tmp_path / "new.json"
    with pytest.raises(OutputRefused, match="appeared while it was written"), \
            output_path(target) as temporary:
        temporary.write_bytes(b"ours")
        target.write_bytes(PRECIOUS)  # someone else's file, created meanwhile
    assert target.read_bytes() == PRECIOUS
    assert [p.name for p in tmp_path.iterdir()] == ["new.json"]


def test_only_regular_files_in_existing_folders_are_written(tmp_path):
    with pytest.raises(OutputRefused, match="not a regular file"):
        check_output(os.devnull, overwrite=True)
    with pytest.raises(OutputRefused, match="not a regular file"):
        check_output(tmp_path, overwrite=True)
    with pytest.raises(OutputRefused, match="no such directory"):
        write_output(tmp_path / "none" / "x.json", "{}")
    assert write_output(tmp_path / "x.json", "{}").read_text() == "{}"


def test_a_second_writer_to_one_file_is_refused(tmp_path):
    target = tmp_path / "busy.json"
    with OutputLock(target):
        with pytest.raises(OutputRefused, match="being written by another inclinometer"):
            write_output(target, "second")
        assert not target.exists()
    write_output(target, "after")  # the lock is released, and its file removed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["busy.json"]


def test_two_record_overwrite_to_one_file_the_second_is_refused(tmp_path, capsys):
    path = tmp_path / "rec.csv"
    path.write_bytes(PRECIOUS)
    started, stop = threading.Event(), threading.Event()
    outcome = []

    def first() -> None:
        device = SimulatedDevice("sim://static?odr=104&seed=1", realtime=True)
        outcome.append(record_device(device, path, overwrite=True, stop=stop,
                                     on_flush=lambda status: started.set()))

    thread = threading.Thread(target=first)
    thread.start()
    try:
        assert started.wait(10)
        assert main(["record", "--device", "sim://static?realtime=0", "--duration", "1",
                     "--overwrite", "--quiet", str(path)]) == 1
        assert "being written by another inclinometer command" in capsys.readouterr().err
    finally:
        stop.set()
        thread.join(10)
    recording = read_recording(path)  # the first recording, whole and valid
    assert len(recording) == outcome[0].status.rows_written > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.csv"]


def test_record_never_writes_over_the_recording_it_replays(recording, tmp_path, capsys):
    source = _source_copy(recording, tmp_path)
    before = source.read_bytes()
    link = tmp_path / "link.csv"
    os.link(source, link)
    assert main(["record", "--device", f"replay://{source}?speed=max", "--overwrite",
                 "--quiet", str(link)]) == 1
    assert "would overwrite the recording being replayed itself" in capsys.readouterr().err
    assert source.read_bytes() == before


@pytest.mark.parametrize("command", [
    ["evaluate", "{src}", "--json", "{out}"],
    ["allan", "{src}", "--json", "{out}"],
    ["calibrate", "{src}", "--out", "{out}"],
    ["calibrate", "{src}", "--report", "{out}"],
    ["calibrate-temperature", "{src}", "--out", "{out}"],
    ["joint", "{src}", "{src}", "--out", "{out}"],
])
def test_no_command_writes_over_its_input_even_with_overwrite(recording, tmp_path, capsys,
                                                             command):
    source = _source_copy(recording, tmp_path)
    before = source.read_bytes()
    link = tmp_path / ("link.html" if "--report" in command else "link.csv")
    os.link(source, link)
    args = [a.format(src=source, out=link) for a in command]
    assert main([*args, "--overwrite"]) == 2
    assert "would overwrite the input itself" in capsys.readouterr().err
    assert source.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["in.csv", link.name])
