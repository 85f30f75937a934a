"""Hostile inputs for every command of ``inclinometer`` (issue 36), built on demand.

:func:`build_corpus` writes small files into a folder and returns the :class:`Case` list: one
hostile input run through one command. Every case must end in exit status 2 and a one-line
message on stderr, never a traceback. tests/test_hostile_commands.py runs them in-process;
benchmarks/hostile_inputs.py runs them through the real ``inclinometer`` command and prints
the message, the time and the peak memory of each.

Nothing here is large: the files are generated (a few kilobytes each), never kept in git.
"""

from __future__ import annotations

import json
import math
import os
import stat
from dataclasses import dataclass
from pathlib import Path

MAGIC = "# inclinometer-recording 1\n"
HEADER = "t,ax,ay,az,gx,gy,gz,temp,qw,qx,qy,qz"
RATE_HZ = 100.0
ROWS = 600
G = 9.80665


@dataclass(frozen=True)
class Case:
    """One hostile input through one command."""

    input: str
    """What is hostile, in words (the table's first column)."""
    command: str
    argv: tuple[str, ...]
    """The arguments after ``inclinometer``."""


def _metadata(calibration: object | None = None) -> str:
    device = {"url": "sim://static", "name": "hostile corpus", "unique_id": "HOSTILE-1",
              "sensor": "LSM6DSOX", "odr_hz": RATE_HZ, "accel_fs_g": 4, "gyro_fs_dps": 250}
    lines = [f"# device: {json.dumps(device)}\n"]
    if calibration is not None:
        lines.append(f"# calibration: {json.dumps(calibration)}\n")
    return "".join(lines)


def _rows(rows: int = ROWS, *, t_equal: bool = False, poison: str | None = None) -> str:
    """A board lying still and level, with its true orientation; ``poison`` replaces ``gx``
    and ``az`` in a tenth of the rows."""
    out = []
    for k in range(rows):
        t = 1.0 if t_equal else k / RATE_HZ
        gx = f"{1e-3 * math.sin(k * 0.7):.6f}"
        az = f"{G + 1e-3 * math.cos(k * 1.3):.6f}"
        if poison is not None and k % 10 == 5:
            gx = az = poison
        out.append(f"{t!r},0.01,-0.02,{az},{gx},0.0005,-0.0003,25.0,1,0,0,0\n")
    return "".join(out)


def recording_text(rows: int = ROWS, *, t_equal: bool = False, poison: str | None = None,
                   calibration: object | None = None) -> str:
    return MAGIC + _metadata(calibration) + HEADER + "\n" + _rows(rows, t_equal=t_equal,
                                                                  poison=poison)


def _deep_json(depth: int = 100_000) -> str:
    return "[" * depth + "]" * depth


def _huge_int_json(key: str) -> str:
    return '{"' + key + '": ' + "9" * 5000 + "}"


def _manifest(first: str, second: str, clock: str = "1.0") -> str:
    return ('{"format": "inclinometer-session", "version": 1, "sensors": ['
            f'{{"file": "{first}", "clock": {{"scale": {clock}}}}}, '
            f'{{"file": "{second}"}}], "joints": []}}')


def build_corpus(root: Path) -> list[Case]:
    """Write the hostile files into ``root`` (an empty folder) and return the cases."""
    root = Path(root)
    write_files(root)
    return corpus_cases(root)


def write_files(root: Path) -> None:
    """The corpus's files (a few hundred kilobytes in all)."""
    (root / "good.csv").write_text(recording_text(), encoding="utf-8")
    files = {
        "nan": recording_text(poison="nan"),
        "inf": recording_text(poison="inf"),
        "1e308": recording_text(poison="1e308"),
        "t-equal": recording_text(t_equal=True),
        "bad-calibration": recording_text(calibration={"name": "broken",
                                                       "accel_matrix": [[0, 0, 0]] * 3}),
    }
    for name, text in files.items():
        (root / f"{name}.csv").write_text(text, encoding="utf-8")
    (root / "deep.json").write_text(_deep_json(), encoding="utf-8")
    (root / "deep.session.json").write_text(
        '{"format": "inclinometer-session", "version": 1, "sensors": ' + _deep_json() + "}",
        encoding="utf-8")
    (root / "bigint.json").write_text(_huge_int_json("accel_bias_m_s2"), encoding="utf-8")
    (root / "bigint.session.json").write_text(_manifest("good.csv", "good.csv",
                                                        clock="9" * 5000), encoding="utf-8")
    readonly = root / "readonly"
    readonly.mkdir()
    readonly.chmod(stat.S_IRUSR | stat.S_IXUSR)


def read_only_folder(root: Path) -> Path:
    """A folder no file can be created in."""
    readonly = root / "readonly"
    if os.geteuid() == 0:  # root writes into any folder of its own: take sysfs instead
        readonly = Path("/sys")
    return readonly


def corpus_cases(root: Path) -> list[Case]:
    """The cases over the files :func:`write_files` put in ``root`` (pure: no file is
    touched, so that the list can name tests before the files exist)."""
    root = Path(root)
    good = root / "good.csv"
    readonly = read_only_folder(root)
    missing = root / "no-such-folder"
    g = str(good)
    odr_digits = "9" * 400

    def r(name: str) -> str:
        return str(root / f"{name}.csv")

    cases: list[Case] = []

    def add(what: str, command: str, *argv: str) -> None:
        cases.append(Case(what, command, (command, *argv)))

    # Non-finite and huge values in the rows.
    for name, what in (("nan", "rows with NaN"), ("inf", "rows with Inf"),
                       ("1e308", "rows with 1e308")):
        add(what, "diagnose", r(name))
        add(what, "allan", r(name))
    add("every t equal", "evaluate", r("t-equal"))
    add("invalid recorded calibration", "replay", r("bad-calibration"),
        "--out", str(root / "angles-cal.csv"))
    add("invalid recorded calibration", "evaluate", r("bad-calibration"))
    # Paths that are not plain files.
    add("recording path with NUL (replay://a.csv%00)", "replay",
        f"replay://{g}%00", "--out", str(root / "angles-nul.csv"))
    add("recording path with NUL (replay://a.csv%00)", "evaluate", f"replay://{g}%00")
    add("recording path with NUL (replay://a.csv%00)", "diagnose", f"replay://{g}%00")
    add("a directory as the recording", "replay", str(root), "--out",
        str(root / "angles-dir.csv"))
    add("a directory as the recording", "allan", str(root))
    # Output folders that cannot be written.
    for folder, what in ((missing, "missing output folder"),
                         (readonly, "read-only output folder")):
        add(what, "replay", g, "--out", str(folder / "angles.csv"))
        add(what, "evaluate", g, "--json", str(folder / "scores.json"))
        add(what, "allan", g, "--json", str(folder / "allan.json"))
        add(what, "calibrate", g, "--out", str(folder / "calibration.json"))
    # JSON: deep nesting and huge integers in profiles and manifests.
    for name, what in (("deep.json", "deeply nested JSON profile"),
                       ("bigint.json", "profile with a 5000-digit integer")):
        add(what, "record", "--device", "sim://static?realtime=0", "--duration", "0.1",
            "--calibration", str(root / name), str(root / f"rec-{name}.csv"))
        add(what, "calibrate-temperature", g, "--base", str(root / name),
            "--out", str(root / f"temperature-{name}"))
    for name, what in (("deep.session.json", "deeply nested JSON manifest"),
                       ("bigint.session.json", "manifest with a 5000-digit integer")):
        add(what, "joint", str(root / name), "--out", str(root / f"joint-{name}.csv"))
    # Numbers on the command line.
    for value in ("nan", "inf", "-1"):
        add(f"--seconds {value}", "evaluate", "sim://static", "--seconds", value)
        add(f"--seconds {value}", "diagnose", "sim://static", "--seconds", value)
        add(f"--seconds {value}", "allan", "--device", "sim://static", "--seconds", value)
        add(f"--seconds {value}", "calibrate", "--device", "sim://static",
            "--seconds", value, "--out", str(root / "calibration-seconds.json"))
        add(f"--skip {value}", "evaluate", "sim://static", "--seconds", "1", "--skip", value)
        add(f"--odr {value}", "simulate", "--pty", "--odr", value)
        add(f"--duration {value}", "record", "--device", "sim://static?realtime=0",
            "--duration", value, str(root / f"rec-duration-{value}.csv"))
        add(f"--gyro-seconds {value}", "calibrate", g, "--gyro-seconds", value,
            "--out", str(root / "calibration-gyro.json"))
        add(f"--min-span {value}", "calibrate-temperature", g, "--min-span", value,
            "--out", str(root / "temperature-span.json"))
    for value in ("nan", "inf"):
        add(f"--seconds {value}", "check-board", "/dev/null", "--seconds", value)
        add(f"--seconds {value}", "evaluate-faults", "sim://static", "--seconds", value)
        add(f"--clean-seconds {value}", "evaluate-faults", "sim://static",
            "--clean-seconds", value)
        add(f"--duration {value}", "record-arm", "sim://arm", str(root / "arm"),
            "--duration", value)
    add("--seconds x (not a number)", "evaluate", "sim://static", "--seconds", "x")
    add("--odr x (not a number)", "simulate", "--pty", "--odr", "x")
    add("--block 10**30", "replay", g, "--block", "1" + "0" * 30, "--out",
        str(root / "angles-block.csv"))
    add("--repeats 10**30", "evaluate", "sim://static", "--seconds", "1",
        "--repeats", "1" + "0" * 30)
    # Device URL options.
    for option, what in ((f"odr={odr_digits}", "odr of 400 digits"),
                         ("odr=-5", "odr=-5"), ("odr=1e300", "odr=1e300"),
                         ("odr=nan", "odr=nan"), ("odr=1e9", "odr=1e9"),
                         ("clock_offset=1e300", "clock_offset=1e300"),
                         ("clock_offset=nan", "clock_offset=nan"),
                         ("speed=1e300", "speed=1e300"), ("seed=" + "9" * 400,
                                                          "seed of 400 digits")):
        url = f"sim://static?realtime=0&{option}"
        add(f"sim URL {what}", "record", "--device", url, "--duration", "0.1",
            str(root / f"rec-{len(cases)}.csv"))
        add(f"sim URL {what}", "diagnose", url, "--seconds", "0.5")
    for option, what in ((f"odr={odr_digits}", "odr of 400 digits"),
                         ("odr=1e300", "odr=1e300"), ("odr=-5", "odr=-5")):
        add(f"lsm6dsox URL {what}", "diagnose", f"lsm6dsox://emulated?{option}",
            "--seconds", "0.5")
    for option, what in (("odr=1e9", "odr=1e9"), ("timeout=1e300", "timeout=1e300"),
                         ("baud=nan", "baud=nan")):
        add(f"serial URL {what}", "diagnose", f"serial:///dev/null?{option}",
            "--seconds", "0.5")
    for option, what in (("start=nan", "start=nan"), ("block=" + "9" * 5000,
                                                      "block of 5000 digits"),
                         ("speed=1e300", "speed=1e300")):
        add(f"replay URL {what}", "diagnose", f"replay://{g}?{option}", "--seconds", "0.5")
    return cases


def pipe_path(data: bytes) -> tuple[str, int]:
    """A pipe holding ``data`` (already written, writer closed), as ``<(cat a.csv)`` gives:
    returns its /dev/fd path and the read end to close afterwards."""
    read_end, write_end = os.pipe()
    os.write(write_end, data)
    os.close(write_end)
    return f"/dev/fd/{read_end}", read_end
