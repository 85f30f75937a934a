"""The runtime folder of ``simulate --pty`` (issue 36): private, owner-checked, written
atomically without following links; announcements naming a process or a port that is not
ours are ignored."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import pytest

from app.cli import build_parser
from app.cli.simulate import simulate_command
from drivers.link import ports
from drivers.link.ports import SerialPortInfo

VICTIM_TEXT = b"export PATH=$HOME/bin:$PATH  # the user's own file\n"


@pytest.fixture
def temp_root(tmp_path, monkeypatch) -> Path:
    """A private stand-in for /tmp, without XDG_RUNTIME_DIR."""
    root = tmp_path / "tmp"
    root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(root))
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    return root


def _simulate() -> tuple[int, str, str]:
    """``inclinometer simulate --pty``, stopped at once: (exit code, stdout, port)."""
    args = build_parser().parse_args(["simulate", "--pty"])
    out = io.StringIO()
    stop = threading.Event()
    stop.set()
    code = simulate_command(args, out=out, stop=stop)
    text = out.getvalue()
    return code, text, text.splitlines()[0] if text else ""


def _plant_links(folder: Path, victim: Path) -> None:
    for n in range(100):
        (folder / f"dev_pts_{n}.json").symlink_to(victim)


def test_planted_links_in_the_old_predictable_folder_never_reach_the_victim(
        temp_root, tmp_path, capsys):
    victim = tmp_path / "bashrc"
    victim.write_bytes(VICTIM_TEXT)
    planted = temp_root / f"inclinometer-{os.getuid()}" / "emulated-ports"
    planted.mkdir(parents=True)  # open for anyone to plant files in
    os.chmod(planted.parent, 0o777)
    _plant_links(planted, victim)
    code, out, _ = _simulate()
    assert code == 2 and out == ""
    err = capsys.readouterr().err
    assert "refusing to use the runtime folder" in err and "open to others (mode 777" in err
    assert victim.read_bytes() == VICTIM_TEXT
    # Ours and closed to others' writes (755, as an older version left it): made 700 and
    # used; the links in it are replaced, never followed: the victim stays, byte for byte.
    os.chmod(planted.parent, 0o755)
    code, out, port = _simulate()
    assert (planted.parent.stat().st_mode & 0o777) == 0o700
    assert code == 0 and port.startswith("/dev/")
    assert victim.read_bytes() == VICTIM_TEXT
    assert victim.stat().st_nlink == 1


def test_a_runtime_folder_that_is_a_link_or_another_users_is_refused(temp_root, tmp_path,
                                                                      monkeypatch, capsys):
    elsewhere = tmp_path / "attacker"
    elsewhere.mkdir(mode=0o700)
    link = temp_root / f"inclinometer-{os.getuid()}"
    link.symlink_to(elsewhere)
    assert _simulate()[0] == 2
    assert "is a symbolic link" in capsys.readouterr().err
    assert list(elsewhere.iterdir()) == []
    link.unlink()
    folder = ports.runtime_folder()
    assert folder == link and (folder.stat().st_mode & 0o777) == 0o700
    monkeypatch.setattr(ports, "_uid", lambda: os.getuid() + 1)  # as if another user made it
    with pytest.raises(ports.RuntimeFolderError, match="belongs to another user"):
        ports.runtime_folder()


def test_xdg_runtime_dir_is_used_only_when_private(temp_root, tmp_path, monkeypatch):
    xdg = tmp_path / "run-user"
    xdg.mkdir(mode=0o700)
    os.chmod(xdg, 0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(xdg))
    assert ports.shared_ports_folder() == xdg / "inclinometer" / "emulated-ports"
    assert (xdg / "inclinometer").stat().st_mode & 0o777 == 0o700
    os.chmod(xdg, 0o755)
    assert ports.shared_ports_folder() == (temp_root / f"inclinometer-{os.getuid()}"
                                           / "emulated-ports")


def test_announcements_naming_a_process_or_port_not_ours_are_ignored(temp_root):
    folder = ports.shared_ports_folder()
    child = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"],
                             stdin=subprocess.PIPE)
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    master, slave = os.openpty()
    try:
        pty_name = os.ttyname(slave)

        def announce(device: str, serial: str, pid: int) -> None:
            info = SerialPortInfo(device=device, serial_number=serial, vid=0x0483, pid=0x374B,
                                  emulated=True)
            name = device.strip("/").replace("/", "_") + ".json"
            (folder / name).write_text(json.dumps({"port": dataclasses.asdict(info),
                                                   "process": pid}))

        announce(pty_name, "GOOD", child.pid)
        announce("/etc/passwd", "NOTAPTY", child.pid)  # a live process of ours, not a pty
        announce("/dev/pts/999999", "NOPORT", child.pid)
        (folder / "dev_pts_999998.json").write_text(json.dumps(
            {"port": {"device": pty_name, "serial_number": "WRONGNAME"}, "process": child.pid}))
        announce(pty_name.replace("/dev/pts/", "/dev/pts/1"), "DEAD", gone.pid)
        shared = ports._shared_ports()
        assert [info.serial_number for info in shared] == ["GOOD"]
        assert ports.find_port_by_serial("NOTAPTY") is None
        assert ports.find_port_by_serial("GOOD") == pty_name
        # The dead process's entry was stale: removed; the others stay ignored.
        assert not any("DEAD" in p.read_text() for p in folder.iterdir())
    finally:
        os.close(master)
        os.close(slave)
        child.stdin.close()
        child.wait()
