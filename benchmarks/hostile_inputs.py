"""Every hostile input of issue 36 through the real ``inclinometer`` command: the table.

Runs the corpus of tests/hostile_corpus.py (the same cases tests/test_hostile_commands.py runs
in-process) each in its own process, plus three that need a shell or a second user:

- ``replay <(cat a.csv)``: a pipe from bash's process substitution;
- ``replay a.csv --out b.csv`` where b.csv is a hard link of a.csv (the recording must survive);
- ``simulate --pty`` with ``dev_pts_N.json -> victim`` links planted in the emulated-ports
  folder of the temporary directory by another user (uid 65534 when run as root; the victim
  must be unchanged).

Printed per run: the input, the command, the exit status, the wall time, the peak resident
memory of the process (``os.wait4``'s ``ru_maxrss``), whether the run kept its promise (exit 2
and one line on stderr, no traceback; for the two attacks: refused and the victim unchanged)
and the message. Run it from the repository:

    .venv/bin/python benchmarks/hostile_inputs.py [--only TEXT] [--timeout S]

Exit status 0 when every run kept its promise, 1 otherwise.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from hostile_corpus import build_corpus, recording_text  # noqa: E402

MESSAGE_CHARS = 160
OTHER_UID = 65534


@dataclass
class Run:
    input: str
    command: str
    code: int | None
    seconds: float
    peak_mb: float
    message: str
    kept: bool


def command_prefix() -> list[str]:
    """The installed ``inclinometer`` script beside this interpreter, else ``python -m app``
    (both import ``app`` from this repository: PYTHONPATH is set to it)."""
    script = Path(sys.executable).with_name("inclinometer")
    return [str(script)] if script.exists() else [sys.executable, "-m", "app"]


def environment(tmp: Path) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(REPO), "QT_QPA_PLATFORM": "offscreen",
           "TMPDIR": str(tmp)}
    env.pop("INCLINOMETER_DEBUG", None)
    return env


def run_process(argv: list[str], env: dict[str, str], timeout: float,
                stop_after_first_line: bool = False) -> tuple[int | None, float, float, str]:
    """(exit status or None on a timeout, seconds, peak MB, stderr) of one process."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        process = subprocess.Popen(argv, stdout=out, stderr=err, env=env, cwd=REPO,
                                   start_new_session=True)
        deadline = start + timeout
        status = None
        while time.perf_counter() < deadline:
            pid, status, usage = os.wait4(process.pid, os.WNOHANG)
            if pid:
                break
            if stop_after_first_line and out.tell() > 0:
                os.killpg(process.pid, signal.SIGTERM)  # served: stop it as `kill` would
                stop_after_first_line = False
                deadline = time.perf_counter() + 10.0
            time.sleep(0.02)
        else:
            os.killpg(process.pid, signal.SIGKILL)
            _, status, usage = os.wait4(process.pid, 0)
            status = None
        elapsed = time.perf_counter() - start
        process.returncode = 0  # reaped by wait4: keep Popen from waiting again
        err.seek(0)
        text = err.read().decode("utf-8", "replace")
    code = None if status is None else os.waitstatus_to_exitcode(status)
    return code, elapsed, usage.ru_maxrss / 1024.0, text


def kept_promise(code: int | None, stderr: str) -> bool:
    lines = [line for line in stderr.splitlines() if line.strip()]
    return code == 2 and len(lines) == 1 and "Traceback" not in stderr


def corpus_runs(root: Path, env: dict[str, str], timeout: float, only: str) -> list[Run]:
    runs = []
    for case in build_corpus(root):
        if only and only not in f"{case.input} {case.command}":
            continue
        code, seconds, peak, err = run_process([*command_prefix(), *case.argv], env, timeout)
        runs.append(Run(case.input, case.command, code, seconds, peak, err.strip(),
                        kept_promise(code, err)))
    return runs


def pipe_run(root: Path, env: dict[str, str], timeout: float) -> Run:
    good = root / "good.csv"
    line = " ".join(f'"{part}"' for part in command_prefix())
    argv = ["bash", "-c", f'{line} replay <(cat "{good}") --out "{root / "pipe-angles.csv"}"']
    code, seconds, peak, err = run_process(argv, env, timeout)
    return Run("a pipe: replay <(cat a.csv)", "replay", code, seconds, peak, err.strip(),
               kept_promise(code, err) and not (root / "pipe-angles.csv").exists())


def hard_link_run(root: Path, env: dict[str, str], timeout: float) -> Run:
    source = root / "linked.csv"
    source.write_text(recording_text(), encoding="utf-8")
    before = source.read_bytes()
    target = root / "linked-out.csv"
    os.link(source, target)
    code, seconds, peak, err = run_process(
        [*command_prefix(), "replay", str(source), "--out", str(target)], env, timeout)
    unchanged = source.read_bytes() == before
    message = err.strip() + f" [recording {'unchanged' if unchanged else 'OVERWRITTEN'}]"
    return Run("--out a hard link of the input", "replay", code, seconds, peak, message,
               code not in (None, 0) and unchanged)


def symlink_run(tmp: Path, env: dict[str, str], timeout: float) -> Run:
    """Links planted where ``simulate --pty`` announces its port, by another user."""
    victim = tmp / "victim.txt"
    victim.write_text("the victim's file\n", encoding="utf-8")
    folder = tmp / f"inclinometer-{os.getuid()}" / "emulated-ports"
    folder.mkdir(parents=True)
    for n in range(1000):
        (folder / f"dev_pts_{n}.json").symlink_to(victim)
    if os.geteuid() == 0:  # planted by someone else, as on a shared machine
        for path in (folder.parent, folder, *folder.iterdir()):
            os.lchown(path, OTHER_UID, OTHER_UID)
    code, seconds, peak, err = run_process(
        [*command_prefix(), "simulate", "--pty"], env, timeout, stop_after_first_line=True)
    unchanged = victim.read_text(encoding="utf-8") == "the victim's file\n"
    message = " ".join(err.split())[:MESSAGE_CHARS] or "(no message)"
    message += f" [victim {'unchanged' if unchanged else 'OVERWRITTEN'}]"
    return Run("planted dev_pts_N.json links in /tmp", "simulate", code, seconds, peak,
               message, unchanged)


def print_table(runs: list[Run]) -> None:
    width_in = max(len(r.input) for r in runs)
    width_cmd = max(len(r.command) for r in runs)
    print(f"{'input':<{width_in}}  {'command':<{width_cmd}}  exit  {'time s':>6}  "
          f"{'peak MB':>7}  ok   message")
    for r in runs:
        message = " ".join(r.message.split())
        if len(message) > MESSAGE_CHARS:
            message = message[:MESSAGE_CHARS] + "..."
        code = "T/O" if r.code is None else str(r.code)
        print(f"{r.input:<{width_in}}  {r.command:<{width_cmd}}  {code:>4}  {r.seconds:6.2f}  "
              f"{r.peak_mb:7.1f}  {'yes' if r.kept else 'NO ':<3}  {message}")
    kept = sum(r.kept for r in runs)
    print(f"\n{kept} of {len(runs)} runs kept their promise; slowest "
          f"{max(r.seconds for r in runs):.2f} s, most memory "
          f"{max(r.peak_mb for r in runs):.0f} MB")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="", help="only the cases whose input or command "
                        "contains this text")
    parser.add_argument("--timeout", type=float, default=60.0,
                        help="seconds before a run counts as hung and is killed")
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="hostile-"))
    try:
        root = tmp / "corpus"
        root.mkdir()
        env = environment(tmp)
        runs = corpus_runs(root, env, args.timeout, args.only)
        if not args.only:
            runs += [pipe_run(root, env, args.timeout), hard_link_run(root, env, args.timeout),
                     symlink_run(tmp, env, args.timeout)]
        print_table(runs)
        return 0 if all(r.kept for r in runs) else 1
    finally:
        with contextlib.suppress(OSError):
            (root / "readonly").chmod(0o700)
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
