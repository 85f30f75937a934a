"""The command line: version, device listing and argument checks."""

from __future__ import annotations

import io
import subprocess
import sys

from app import __version__
from app.cli.devices import list_devices
from app.launcher import main


def test_version_flag_prints_the_version():
    result = subprocess.run(
        [sys.executable, "-m", "app", "--version"], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == f"inclinometer {__version__}"


def test_devices_lists_the_simulator_scenarios():
    out = io.StringIO()
    assert list_devices(out) == 0
    listing = out.getvalue()
    for scenario in ("interactive", "static", "wobble", "vibration", "translation", "tour"):
        assert f"sim://{scenario}" in listing


def test_devices_subcommand_runs_headless():
    result = subprocess.run(
        [sys.executable, "-m", "app", "devices"], capture_output=True, text=True, check=True
    )
    assert "sim://interactive" in result.stdout


def test_bad_device_url_and_filter_are_refused_before_the_gui(capsys):
    assert main(["--device", "nosuch://x"]) == 2
    assert "no driver for nosuch://" in capsys.readouterr().err
    assert main(["--filter", "nonsense"]) == 2
    assert "no filter" in capsys.readouterr().err
