"""Session manifests name files inside their folder; messages never quote a file's
contents; what a device says about itself is escaped before it reaches a terminal
(issue 36, item 9)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main
from app.core.devices import DeviceInfo, DeviceMessage, printable
from app.core.recording.session import (
    SessionManifestError,
    SessionSensor,
    load_session,
    write_session,
)
from app.services.recorder import record_device
from drivers.link.ports import SerialPortInfo
from drivers.replay import ReplayDevice
from drivers.sim.device import SimulatedDevice

SECRET = "root:$6$SECRETHASHxyz:19000:0:99999:7:::\n"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "a.csv"
    record_device(SimulatedDevice("sim://wobble?odr=104&seed=5", realtime=False), path,
                  duration_s=1.0)
    return path


def _manifest(folder: Path, files: list[str]) -> Path:
    folder.mkdir(exist_ok=True)
    return write_session(folder / "s.session.json",
                         [SessionSensor(f, f"link {k}") for k, f in enumerate(files)], [])


def test_absolute_and_parent_paths_and_links_out_are_refused(tmp_path, recorded):
    secret = tmp_path / "shadow"
    secret.write_text(SECRET)
    folder = tmp_path / "session"
    (folder / "data").mkdir(parents=True)
    (folder / "data" / "a.csv").write_bytes(recorded.read_bytes())
    (folder / "out.csv").symlink_to(secret)
    for named in (str(secret), "../shadow", "data/../../shadow", "out.csv"):
        manifest = _manifest(folder, ["data/a.csv", named])
        with pytest.raises(SessionManifestError, match="outside the manifest's folder") as caught:
            load_session(manifest)
        assert "--allow-outside-paths" in str(caught.value)
        assert "SECRET" not in str(caught.value)
    inside = _manifest(folder, ["data/a.csv", "data/a.csv"])
    assert [p.name for p in load_session(inside).paths] == ["a.csv", "a.csv"]
    outside = _manifest(folder, ["data/a.csv", str(recorded)])
    assert load_session(outside, allow_outside=True).paths[1] == recorded


def test_joint_refuses_a_manifest_reaching_out_and_never_quotes_the_file(tmp_path, recorded,
                                                                        capsys):
    secret = tmp_path / "shadow"
    secret.write_text(SECRET)
    folder = tmp_path / "session"
    manifest = _manifest(folder, [str(recorded), str(secret)])
    out = folder / "j.csv"
    assert main(["joint", str(manifest), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "outside the manifest's folder" in err and "SECRETHASH" not in err and "99999" not in err
    # Allowed by the flag, the file is read, and refused without quoting a byte of it.
    assert main(["joint", str(manifest), "--out", str(out), "--allow-outside-paths"]) == 2
    err = capsys.readouterr().err
    assert "not an inclinometer recording: its first line is a line of text of 40 characters" in err
    assert "SECRETHASH" not in err and "99999" not in err and not out.exists()


def test_replay_of_a_foreign_file_does_not_echo_it(tmp_path, capsys):
    secret = tmp_path / "environ"
    secret.write_bytes(b"TOKEN=hunter2\x00PATH=/bin\x00")
    assert main(["replay", str(secret), "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert "binary data (24 bytes)" in err and "hunter2" not in err


def test_device_supplied_text_is_escaped_before_any_terminal_sees_it(tmp_path, recorded):
    hostile = "ID\x1b]0;owned\x07\x1b[2J\r\u202eX"
    assert printable(hostile) == "ID\\x1b]0;owned\\x07\\x1b[2J\\x0d\\u202eX"
    assert printable("plain é 中 id") == "plain é 中 id"
    info = DeviceInfo("u", "name\x1b[31m", hostile, "s", 104.0, 104.0, 4, 250, "fw\x07")
    assert info.unique_id == printable(hostile) and info.name == "name\\x1b[31m"
    assert info.firmware == "fw\\x07"
    assert DeviceMessage(1, "log\x1b[2J").text == "log\\x1b[2J"
    port = SerialPortInfo("/dev/ttyACM0", description="d\x1b[2J", serial_number="S\x1b]0;x\x07",
                          vid=0x0483, pid=0x374B)
    assert "\x1b" not in port.summary() and "\x07" not in port.summary()
    # A recording's device id reaches the program through the replay driver: escaped there.
    lines = recorded.read_text().splitlines(keepends=True)
    device_line = next(k for k, line in enumerate(lines) if line.startswith("# device: "))
    device = json.loads(lines[device_line][len("# device: "):])
    device["unique_id"] = hostile
    lines[device_line] = f"# device: {json.dumps(device)}\n"
    copy = tmp_path / "hostile.csv"
    copy.write_text("".join(lines))
    replay = ReplayDevice(f"replay://{copy}")
    try:
        opened = replay.open()
    finally:
        replay.close()
    assert opened.unique_id == printable(hostile) and "\x1b" not in opened.unique_id
