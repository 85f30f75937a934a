"""Distribution: the --smoke-test flag, the frozen-app set-up, and the packaging files agree.

The bundle itself (``make bundle``) and the wheel in a fresh venv (``packaging/check_wheel.sh``)
take a minute each and are checked by .ci/run after this suite.
"""

from __future__ import annotations

import ast
import fnmatch
import os
import re
import shutil
import struct
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from app import __version__

ROOT = Path(__file__).resolve().parent.parent
LINUX = ROOT / "packaging" / "linux"
APP_ID = "org.inclinometer.Inclinometer"


def test_smoke_test_passes_from_source_and_saves_a_screenshot(artifacts_dir):
    screenshot = Path(artifacts_dir) / "smoke_test.png"
    screenshot.unlink(missing_ok=True)
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    result = subprocess.run(
        [sys.executable, "-m", "app", "--smoke-test", str(screenshot)],
        capture_output=True, text=True, timeout=240, env=env, cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("inclinometer smoke test passed"), lines
    from app.core.filters import DEFAULT_FILTER

    for fact in (f"through {DEFAULT_FILTER}", "frames drawn", "replayed", "found a 10° tilt",
                 "numba:"):
        assert fact in lines[0]
    assert screenshot.stat().st_size > 20_000


def test_smoke_test_fails_with_the_reason(qapp, monkeypatch, capsys):
    import app.core.recording
    from app.gui.smoke_test import run_smoke_test

    monkeypatch.setattr(app.core.recording, "sample_recordings", lambda: [])
    assert run_smoke_test() == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.strip() == (
        "inclinometer smoke test FAILED: no sample recordings in resources/recordings"
    )


def test_frozen_environment_points_numba_at_the_user_cache(monkeypatch):
    from app import frozen

    monkeypatch.setattr(sys, "frozen", True, raising=False)
    # Recorded as unset first: delenv of an unset variable records nothing, and the cache
    # directory set below then stayed in this process's environment for every later test,
    # whose subprocesses (record, tune's workers, the soak) compiled every kernel again.
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setattr(sys, "stdout", None)
    monkeypatch.setattr(sys, "dont_write_bytecode", False)
    frozen.prepare_frozen_environment()
    cache = os.environ["NUMBA_CACHE_DIR"]
    assert cache.startswith(os.environ["XDG_CACHE_HOME"])  # the platformdirs user cache
    assert Path(cache).parts[-2:] == ("Inclinometer", "numba")
    assert sys.stdout is not None and sys.dont_write_bytecode
    sys.stdout.close()


def test_frozen_environment_does_nothing_from_source(monkeypatch):
    from app import frozen

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    frozen.prepare_frozen_environment()
    assert "NUMBA_CACHE_DIR" not in os.environ


def test_the_version_comes_from_one_place():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert "version" in pyproject["project"]["dynamic"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {
        "attr": "app.core.version.__version__"
    }
    spec = (ROOT / "packaging" / "inclinometer.spec").read_text(encoding="utf-8")
    assert "from app.core.version import __version__" in spec
    metainfo = ET.parse(LINUX / f"{APP_ID}.metainfo.xml").getroot()
    newest = metainfo.find("releases/release")
    assert newest is not None and newest.get("version") == __version__, (
        "add a <release> for the new version to the metainfo file"
    )


def test_every_resource_file_is_package_data_in_the_wheel_and_the_bundle():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = pyproject["tool"]["setuptools"]["package-data"]["resources"]
    spec = (ROOT / "packaging" / "inclinometer.spec").read_text(encoding="utf-8")
    spec_patterns = re.search(r'collect_data_files\(\s*"resources", includes=(\[.*?\])', spec, re.S)
    assert spec_patterns is not None
    assert sorted(ast.literal_eval(spec_patterns.group(1))) == sorted(patterns)  # same lists
    folder = ROOT / "resources"
    files = [
        path.relative_to(folder).as_posix() for path in folder.rglob("*")
        if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".py"
    ]
    assert files
    missing = [
        name for name in files
        if not any(fnmatch.fnmatch(name, p) or fnmatch.fnmatch(name, p.removeprefix("**/"))
                   for p in patterns)
    ]
    assert not missing, f"add patterns for {missing} to [tool.setuptools.package-data]"


def png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n", path
    return struct.unpack(">II", header[16:24])


def test_desktop_entry_icons_and_udev_rules():
    desktop = (LINUX / f"{APP_ID}.desktop").read_text(encoding="utf-8")
    assert f"Icon={APP_ID}\n" in desktop and "Exec=inclinometer\n" in desktop
    for size in (16, 22, 24, 32, 48, 64, 128, 256, 512):
        icon = LINUX / "icons" / "hicolor" / f"{size}x{size}" / "apps" / f"{APP_ID}.png"
        assert png_size(icon) == (size, size)
    assert (LINUX / "icons/hicolor/scalable/apps" / f"{APP_ID}.svg").read_bytes() == (
        ROOT / "resources/icons/inclinometer.svg"
    ).read_bytes(), "run packaging/linux/render_icons.py after changing the icon"
    rules = (LINUX / "60-inclinometer.rules").read_text(encoding="utf-8")
    active = [line for line in rules.splitlines() if line and not line.startswith("#")]
    for vendor, product in (("0483", "374b"), ("04d8", "00dd")):
        mine = [line for line in active if f'"{vendor}"' in line and f'"{product}"' in line]
        assert mine and all('TAG+="uaccess"' in line for line in mine)
    assert int(LINUX.joinpath("60-inclinometer.rules").name[:2]) < 73  # before 73-seat-late


@pytest.mark.skipif(shutil.which("desktop-file-validate") is None,
                    reason="desktop-file-validate not installed (apt: desktop-file-utils)")
def test_desktop_entry_validates():
    result = subprocess.run(["desktop-file-validate", str(LINUX / f"{APP_ID}.desktop")],
                            capture_output=True, text=True)
    assert result.returncode == 0 and not result.stdout.strip(), result.stdout


@pytest.mark.skipif(shutil.which("appstreamcli") is None,
                    reason="appstreamcli not installed (apt: appstream)")
def test_appstream_metainfo_validates():
    result = subprocess.run(
        ["appstreamcli", "validate", "--no-net", str(LINUX / f"{APP_ID}.metainfo.xml")],
        capture_output=True, text=True,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_install_desktop_for_the_current_user(tmp_path):
    command = tmp_path / "bin dir" / "inclinometer"
    command.parent.mkdir()
    command.write_text("#!/bin/sh\n")
    command.chmod(0o755)
    data = tmp_path / "share"
    env = dict(os.environ, XDG_DATA_HOME=str(data))
    script = str(LINUX / "install-desktop.sh")
    subprocess.run([script, str(command)], check=True, env=env, capture_output=True)
    installed = (data / "applications" / f"{APP_ID}.desktop").read_text(encoding="utf-8")
    assert f'Exec="{command}"\n' in installed and f"TryExec={command}\n" in installed
    assert (data / "icons/hicolor/48x48/apps" / f"{APP_ID}.png").is_file()
    assert (data / "metainfo" / f"{APP_ID}.metainfo.xml").is_file()
    subprocess.run([script, "--uninstall"], check=True, env=env, capture_output=True)
    assert not (data / "applications" / f"{APP_ID}.desktop").exists()
    assert not list(data.rglob(f"{APP_ID}.*"))
