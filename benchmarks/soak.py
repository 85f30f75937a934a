"""Soak test: stream for an hour while recording; RSS over time and every lost sample accounted for.

Two sources, each recorded through :func:`app.services.recorder.record_device` (what
``inclinometer record`` runs: device -> writer thread -> pipeline):

- ``--mode sim``: the simulator in real time, ``sim://wobble?odr=6667``;
- ``--mode board``: an emulated NUCLEO board at 1667 Hz, ``inclinometer simulate --pty`` in its
  own process, read through the real serial driver from the pseudo-terminal it prints.

``--load`` runs as many busy-loop processes as there are cores (normal priority) meanwhile.

What it reports (printed; ``--json FILE`` writes every figure):

- the process's RSS every ``--rss-every`` seconds (and the emulated board's), with its CPU
  share and the counts so far;
- the rates: the datasheet label, the rate the device reports (its timestamps and the holes
  between them are read at this rate), and the simulator's true rate (it knows its own clock
  error; the samples come at this rate on the host's clock);
- samples expected = host time from the first to the last sample x the true rate + 1, against
  samples received by the recorder, rows the recorder wrote and rows the file reads back with;
- the gaps: every sample after a hole in the device timestamps or flagged ``gap``, how long the
  holes are, how many samples they hold, and why (the simulator's FIFO overrun, a sequence
  gap on the link with the CRC errors before it, the board's own drop count);
- silent loss = expected - received - samples in marked gaps, and the exact check behind it:
  holes in the device timestamps that carry no gap flag. The host time of the first and last
  sample is its arrival less its latency (arrival minus due time, against the least latency
  within ``LATENCY_WINDOW_S`` of it), so the balance is exact to about a sample.

    .venv/bin/python benchmarks/soak.py --mode sim [--minutes 60] [--load] [--json OUT.json]
        [--dir DIR] [--keep] [--compress] [--rss-every 30]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.core.recording.stream import RecordingStream
from app.core.samples import RawBlock
from app.services.recorder import record_device
from drivers.registry import create_device
from drivers.sim.device import SimulatedDevice

ROOT = Path(__file__).resolve().parents[1]

MODES = {"sim": 6667.0, "board": 1667.0}
SCENARIO = "wobble"
SEED = 1
LATENCY_WINDOW_S = 30.0
"""The least arrival latency within this much of the first (last) sample is taken as zero."""
HOLE_PERIODS = 1.5
"""A step in the device timestamps longer than this many sample periods is a hole."""
MAX_LISTED_GAPS = 200
FIFO_OVERRUN = "sensor FIFO overrun (simulator: the host read more than 1 s late)"
SEQUENCE_GAP = "link: sequence gap"
UNKNOWN_REASON = "flagged by the device (no reason given)"
UNMARKED = "UNMARKED hole (silent)"
BOARD_STOPPED = re.compile(
    r"Stopped: (\d+) SAMPLES packets, (\d+) samples sent, (\d+) packets dropped")


def rss_mb(pid: int | str = "self") -> float | None:
    """Resident set size of a process in MB (Linux /proc), None when unknown."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


@dataclass
class GapTally:
    """Holes and gap flags in a stream of device timestamps, block by block."""

    rate_hz: float
    samples: int = 0
    flagged: int = 0
    marked_samples: int = 0
    """Samples the holes at flagged samples hold (from the timestamps)."""
    unmarked: int = 0
    unmarked_samples: int = 0
    backwards: int = 0
    hole_s: float = 0.0
    by_reason: dict[str, list[float]] = field(default_factory=dict)
    """reason -> [gaps, samples, seconds]."""
    listed: list[dict[str, Any]] = field(default_factory=list)
    first_t: float | None = None
    last_t: float | None = None

    def add(self, t: np.ndarray, gap: np.ndarray | None,
            reasons: list[str] | None = None) -> None:
        """Count the block's samples, flags and holes; ``reasons`` name its flagged gaps in
        order (missing ones get :data:`UNKNOWN_REASON`)."""
        if not len(t):
            return
        period = 1.0 / self.rate_hz
        before = self.last_t if self.last_t is not None else t[0] - period
        steps = np.diff(t, prepend=before)
        flags = np.zeros(len(t), bool) if gap is None else np.asarray(gap, bool)
        if self.first_t is None:
            self.first_t = float(t[0])
            flags = flags.copy()
            flags[0] = False  # nothing before the first sample
        holes = steps > HOLE_PERIODS * period
        self.backwards += int(np.count_nonzero(steps <= 0))
        reasons = list(reasons or [])
        for index in np.flatnonzero(holes | flags):
            step = float(steps[index])
            lost = max(0, round(step * self.rate_hz) - 1) if holes[index] else 0
            seconds = max(0.0, step - period) if holes[index] else 0.0
            if flags[index]:
                reason = reasons.pop(0) if reasons else UNKNOWN_REASON
                self.flagged += 1
                self.marked_samples += lost
            else:
                reason = UNMARKED
                self.unmarked += 1
                self.unmarked_samples += lost
            self.hole_s += seconds
            entry = self.by_reason.setdefault(reason, [0, 0, 0.0])
            entry[0] += 1
            entry[1] += lost
            entry[2] += seconds
            if len(self.listed) < MAX_LISTED_GAPS:
                self.listed.append({"t_s": round(float(t[index]), 6), "samples": lost,
                                    "seconds": round(seconds, 6), "reason": reason})
        self.samples += len(t)
        self.last_t = float(t[-1])

    def summary(self) -> dict[str, Any]:
        return {
            "samples": self.samples, "gaps_flagged": self.flagged,
            "samples_in_flagged_gaps": self.marked_samples,
            "holes_unmarked": self.unmarked, "samples_in_unmarked_holes": self.unmarked_samples,
            "steps_backwards": self.backwards, "gap_seconds": round(self.hole_s, 6),
            "by_reason": {k: {"gaps": int(v[0]), "samples": int(v[1]), "seconds": round(v[2], 6)}
                          for k, v in self.by_reason.items()},
            "first_t_s": self.first_t, "last_t_s": self.last_t,
            "gaps": self.listed,
        }


class ObservedDevice:
    """A device as the recorder sees it, counting every block it hands over.

    Everything but ``open``/``read``/``close`` is the wrapped device's own, so
    :func:`record_device` records it exactly as it would the device itself.
    """

    def __init__(self, device: Any, true_rate_hz: float | None) -> None:
        self._device = device
        self.true_rate_hz = true_rate_hz
        self.lock = threading.Lock()
        self.tally: GapTally | None = None
        self.reported_lost = 0
        self.blocks = 0
        self.opened_at = 0.0
        self.messages: list[dict[str, Any]] = []
        self._link_before: dict[str, int] = {}
        self._link_pending: Counter[str] = Counter()
        self._first: tuple[float, float, int] | None = None  # arrival, t of last sample, n
        self._start_window: list[tuple[float, float]] = []
        self._end_window: deque[tuple[float, float]] = deque()
        self._last: tuple[float, float] | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._device, name)

    def open(self) -> Any:
        self.opened_at = time.monotonic()
        info = self._device.open()
        self.tally = GapTally(info.odr_hz)
        self.true_rate_hz = self.true_rate_hz or info.odr_hz
        self._link_before = self._link_counters()
        return info

    def close(self) -> None:
        self._device.close()

    def read(self, timeout_s: float) -> RawBlock | None:
        raw = self._device.read(timeout_s)
        arrival = time.monotonic()
        for message in self._device.take_messages():
            if len(self.messages) < 1000:
                self.messages.append({"at_s": round(arrival - self.opened_at, 3),
                                      "level": message.level, "text": message.text})
        if raw is None or not len(raw):
            return raw
        link = self._link_counters()
        for key, value in link.items():
            self._link_pending[key] += value - self._link_before.get(key, 0)
        self._link_before = link
        with self.lock:
            self._count(raw, arrival)
        return raw

    def _link_counters(self) -> dict[str, int]:
        counters = getattr(self._device, "counters", None)
        if counters is None or not hasattr(counters, "seq_gaps"):
            return {}
        return {"seq_gaps": counters.seq_gaps, "crc_errors": counters.crc_errors,
                "undecodable": counters.undecodable, "dropped_samples": counters.dropped_samples}

    def _reasons(self, raw: RawBlock) -> list[str]:
        flagged = 0 if raw.gap is None else int(np.count_nonzero(raw.gap))
        if not flagged:
            return []
        if self._link_before:  # the serial driver: the decoder's counters since the last gap
            pending = self._link_pending
            extra = [f"{pending[k]} {k.replace('_', ' ')}" for k in
                     ("crc_errors", "undecodable", "dropped_samples") if pending[k]]
            base = SEQUENCE_GAP if pending["seq_gaps"] else UNKNOWN_REASON
            reason = base + (f" (after {', '.join(extra)})" if extra else "")
            self._link_pending = Counter()
            return [reason] * flagged
        if raw.lost_samples and getattr(self._device, "scheme", "") == "sim":
            return [FIFO_OVERRUN] * flagged
        return [UNKNOWN_REASON] * flagged

    def _count(self, raw: RawBlock, arrival: float) -> None:
        assert self.tally is not None
        self.tally.add(np.asarray(raw.t_s), raw.gap, self._reasons(raw))
        self.reported_lost += int(raw.lost_samples)
        self.blocks += 1
        t_last = float(raw.t_s[-1])
        if self._first is None:
            self._first = (arrival, t_last, len(raw))
        due = self._due_host_s(t_last)
        point = (arrival, arrival - due)  # arrival and arrival less due time (offset)
        if arrival - self._first[0] <= LATENCY_WINDOW_S:
            self._start_window.append(point)
        self._end_window.append(point)
        while self._end_window and arrival - self._end_window[0][0] > LATENCY_WINDOW_S:
            self._end_window.popleft()
        self._last = (arrival, t_last)

    def _due_host_s(self, t: float) -> float:
        """Host seconds since the first block's last sample at which device time ``t`` was
        due: device seconds x reported rate / true rate."""
        assert self._first is not None and self.tally is not None
        return (t - self._first[1]) * self.tally.rate_hz / (self.true_rate_hz or 1.0)

    def snapshot(self) -> dict[str, int]:
        with self.lock:
            tally = self.tally
            return {"received": 0 if tally is None else tally.samples,
                    "gaps": 0 if tally is None else tally.flagged + tally.unmarked,
                    "in_gaps": 0 if tally is None else
                    tally.marked_samples + tally.unmarked_samples}

    def balance(self) -> dict[str, Any]:
        """Expected samples from host time x true rate, with the end latencies taken out."""
        assert self.tally is not None
        if self._first is None or self._last is None:
            return {}
        first_arrival, _, first_n = self._first
        last_arrival, t_last = self._last
        start_min = min(offset for _, offset in self._start_window)
        end_min = min(offset for _, offset in self._end_window)
        latency_first = self._start_window[0][1] - start_min
        latency_last = (last_arrival - self._due_host_s(t_last)) - end_min
        span_s = (last_arrival - latency_last) - (first_arrival - latency_first)
        true = self.true_rate_hz or self.tally.rate_hz
        # The first block's samples came before its last one: count them in.
        expected = round(span_s * true) + first_n
        expected_reported = round(span_s * self.tally.rate_hz) + first_n
        return {
            "host_span_s": span_s, "latency_first_ms": 1e3 * latency_first,
            "latency_last_ms": 1e3 * latency_last,
            "raw_arrival_span_s": last_arrival - first_arrival,
            "expected": expected, "expected_at_reported_rate": expected_reported,
            "drift_ms": 1e3 * (end_min - start_min), "first_block": first_n,
        }


def start_board(odr_hz: float, seed: int) -> tuple[subprocess.Popen[str], str]:
    """``inclinometer simulate --pty`` in its own process; returns it and its port."""
    board = subprocess.Popen(
        [sys.executable, "-m", "app", "simulate", "--pty", "--scenario", SCENARIO,
         "--odr", f"{odr_hz:g}", "--seed", str(seed)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1,
    )
    assert board.stdout is not None
    ready, _, _ = select.select([board.stdout], [], [], 60)
    port = board.stdout.readline().strip() if ready else ""
    if not port.startswith("/dev/"):
        board.kill()
        raise SystemExit(f"simulate --pty did not print a port (got {port!r})")
    return board, port


def stop_board(board: subprocess.Popen[str]) -> dict[str, Any]:
    """SIGTERM the board; its last line says what it sent and dropped."""
    board.send_signal(signal.SIGTERM)
    try:
        output, _ = board.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        board.kill()
        output, _ = board.communicate()
    found = BOARD_STOPPED.search(output or "")
    if not found:
        return {"output": (output or "").strip()[-500:]}
    packets, samples, dropped = (int(g) for g in found.groups())
    return {"packets_sent": packets, "samples_sent": samples, "packets_dropped": dropped}


def read_back(path: Path, rate_hz: float) -> dict[str, Any]:
    """Rows, gap flags and holes of the recorded file, a chunk at a time."""
    tally = GapTally(rate_hz)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with RecordingStream(path) as stream:
            for chunk in stream.chunks():
                rows = chunk.rows
                tally.add(rows.t_s, rows.gap)
    result = tally.summary()
    result.pop("gaps")
    result["warnings"] = [str(w.message) for w in caught]
    return result


def machine_line() -> str:
    load = os.getloadavg()
    return (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, load average {load[0]:.2f} {load[1]:.2f} "
            f"{load[2]:.2f}")


def monitor(observed: ObservedDevice, stop: threading.Event, every_s: float,
            board_pid: int | None, writer_rows: list[int], rows: list[dict[str, Any]]) -> None:
    """Sample RSS, CPU share and counts every ``every_s`` until ``stop`` is set (and once
    more then)."""
    start = time.monotonic()
    cpu_last = (start, sum(os.times()[:2]))
    stopped = False
    while True:
        now = time.monotonic()
        cpu = sum(os.times()[:2])
        counts = observed.snapshot()
        rows.append({
            "minute": round((now - start) / 60, 2), "rss_mb": rss_mb(),
            "board_rss_mb": rss_mb(board_pid) if board_pid else None,
            "cpu_pct": round(100 * (cpu - cpu_last[1]) / (now - cpu_last[0]), 1)
            if now - cpu_last[0] > 0.1 else 0.0,
            "rows_on_disk": writer_rows[0], **counts,
        })
        print_rss(rows[-1:], board_pid is not None, head=len(rows) == 1)
        cpu_last = (now, cpu)
        if stopped:
            return
        stopped = stop.wait(every_s)


def print_rss(rows: list[dict[str, Any]], board: bool, head: bool = True) -> None:
    if head:
        line = f"{'minute':>7} {'RSS MB':>7} {'CPU %':>6}"
        line += f" {'board MB':>8}" if board else ""
        print(line + f" {'received':>12} {'rows on disk':>12} {'gaps':>5} {'in gaps':>8}")
    for row in rows:
        line = f"{row['minute']:7.2f} {row['rss_mb'] or 0:7.1f} {row['cpu_pct']:6.1f}"
        line += f" {row['board_rss_mb'] or 0:8.1f}" if board else ""
        print(line + f" {row['received']:12,} {row['rows_on_disk']:12,} {row['gaps']:5} "
                     f"{row['in_gaps']:8,}", flush=True)


def run(args: argparse.Namespace) -> dict[str, Any]:
    odr = args.odr or MODES[args.mode]
    command = " ".join([Path(sys.executable).name, *sys.argv])
    print(f"soak: mode {args.mode}, {args.minutes:g} min, load {'on' if args.load else 'off'}")
    args.machine_start = machine_line()
    print(args.machine_start, flush=True)
    busy = []
    board = None
    folder = tempfile.TemporaryDirectory(prefix="soak-", dir=args.dir)
    target = Path(folder.name) / f"soak-{args.mode}.csv{'.gz' if args.compress else ''}"
    try:
        if args.load:
            busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
                    for _ in range(os.cpu_count() or 2)]
            print(f"load: {len(busy)} busy-loop processes (pids "
                  f"{', '.join(str(b.pid) for b in busy)})")
        sim_url = (f"sim://{SCENARIO}?odr={odr:g}&seed={args.seed}")
        truth = SimulatedDevice(sim_url)  # the same unit as the source: its true clock
        true_rate = truth.true_odr_hz
        if args.mode == "board":
            board, port = start_board(odr, args.seed)
            url = port
            print(f"board: inclinometer simulate --pty --odr {odr:g} --seed {args.seed} "
                  f"(pid {board.pid}) on {port}")
        else:
            url = sim_url
        observed = ObservedDevice(create_device(url), true_rate)
        stop, monitor_stop = threading.Event(), threading.Event()
        writer_rows = [0]
        rss_rows: list[dict[str, Any]] = []

        def flushed(status: Any) -> None:
            writer_rows[0] = status.rows_written

        watcher = threading.Thread(
            target=monitor, args=(observed, monitor_stop, args.rss_every,
                                  board.pid if board else None, writer_rows, rss_rows),
            daemon=True)
        timer = threading.Timer(args.minutes * 60, stop.set)
        print("RSS over time (this process: device, pipeline, writer), live:", flush=True)
        watcher.start()
        started = time.monotonic()
        timer.start()
        try:
            outcome = record_device(observed, target, stop=stop, on_flush=flushed,
                                    overwrite=True, note=f"soak {args.mode}")
        finally:
            timer.cancel()
            monitor_stop.set()
            watcher.join()
        wall_s = time.monotonic() - started
        board_stats = stop_board(board) if board else {}
        board = None
        for process in busy:
            process.terminate()
        for process in busy:
            process.wait()
        busy = []
        info_rate = observed.tally.rate_hz if observed.tally else math.nan
        back = read_back(target, info_rate) if target.exists() else {}
        size = target.stat().st_size if target.exists() else 0
        if args.keep:
            kept = Path(args.keep) / target.name
            kept.parent.mkdir(parents=True, exist_ok=True)
            os.replace(target, kept)
            target = kept
    finally:
        for process in busy:
            process.kill()
        if board is not None:
            board.kill()
        if not args.keep:
            folder.cleanup()
    return report(args, command, url, odr, true_rate, observed, outcome, wall_s, rss_rows,
                  back, board_stats, size, target)


def report(args: argparse.Namespace, command: str, url: str, label_hz: float, true_rate: float,
           observed: ObservedDevice, outcome: Any, wall_s: float, rss_rows: list[dict[str, Any]],
           back: dict[str, Any], board_stats: dict[str, Any], size: int,
           target: Path) -> dict[str, Any]:
    tally = observed.tally
    assert tally is not None
    received = tally.samples
    recorded = outcome.status.rows_written
    balance = observed.balance()
    expected = balance.get("expected", 0)
    marked = tally.marked_samples
    silent = expected - received - marked
    pipeline = outcome.pipeline.counters if outcome.pipeline is not None else None
    link = getattr(observed, "_link_before", {})
    counts_ok = recorded == received == back.get("samples", -1)
    flags_ok = back.get("gaps_flagged") == tally.flagged
    tolerance = 2  # samples: rounding at the two ends
    verdict = ("PASS" if counts_ok and flags_ok and tally.unmarked == 0
               and back.get("holes_unmarked", 1) == 0 and abs(silent) <= tolerance else "FAIL")
    print()
    step = max(1, math.ceil((len(rss_rows) - 1) / 24))
    shown = [row for index, row in enumerate(rss_rows)
             if index % step == 0 or index == len(rss_rows) - 1]
    print(f"RSS over time (this process: device, pipeline, writer){', every ' if step > 1 else ''}"
          f"{'' if step == 1 else str(step) + ' samples'}:")
    print_rss(shown, board=args.mode == "board")
    rss_values = [r["rss_mb"] for r in rss_rows if r["rss_mb"]]
    if len(rss_values) > 2:
        later = rss_values[len(rss_values) // 4:]
        print(f"RSS: first {rss_values[0]:.1f} MB, max {max(rss_values):.1f} MB, last "
              f"{rss_values[-1]:.1f} MB; from the first quarter on {min(later):.1f}-"
              f"{max(later):.1f} MB")
    print()
    print(f"rates: label {label_hz:g} Hz; reported by the device {tally.rate_hz:.4f} Hz (reads "
          f"the timestamps and their holes); true {true_rate:.4f} Hz (the simulated unit's "
          f"clock: expected counts use this)")
    span = balance.get("host_span_s") or 0.0
    measured = (received + marked - balance["first_block"]) / span if span else 0.0
    print(f"       measured (received + samples in gaps) / host time = {measured:.4f} Hz")
    print(f"ran {wall_s:.1f} s; host time first to last sample {balance.get('host_span_s', 0):.3f}"
          f" s (arrival span {balance.get('raw_arrival_span_s', 0):.3f} s less end latencies "
          f"{balance.get('latency_first_ms', 0):.1f} / {balance.get('latency_last_ms', 0):.1f} "
          f"ms); device time {((tally.last_t or 0) - (tally.first_t or 0)):.3f} s")
    print(f"ended: {outcome.reason}{(': ' + outcome.message) if outcome.message else ''}")
    print()
    print(f"{'expected (host time x true rate)':<44} {expected:>12,}")
    print(f"{'  (at the reported rate it would be':<44} "
          f"{balance.get('expected_at_reported_rate', 0):>12,})")
    print(f"{'received by the recorder':<44} {received:>12,}")
    print(f"{'recorded (writer rows)':<44} {recorded:>12,}")
    print(f"{'read back from the file':<44} {back.get('samples', 0):>12,}"
          f"   ({size / 1e6:.0f} MB{', kept: ' + str(target) if args.keep else ''})")
    print(f"{'gaps flagged / in the file':<44} {tally.flagged:>12,} / "
          f"{back.get('gaps_flagged', 0):,}")
    print(f"{'samples in flagged gaps (timestamps)':<44} {marked:>12,}")
    print(f"{'lost samples the source reported':<44} {observed.reported_lost:>12,}")
    print(f"{'gap time (holes in device time)':<44} {tally.hole_s:>12.3f} s")
    if pipeline is not None:
        print(f"{'app counters (pipeline): samples/lost/gaps':<44} {pipeline.samples:>12,} / "
              f"{pipeline.lost_samples:,} / {pipeline.gaps:,}")
    if link:
        print(f"{'link counters: seq gaps/CRC/undecodable/dup':<44} "
              f"{link['seq_gaps']:>12,} / {link['crc_errors']:,} / {link['undecodable']:,} / "
              f"{link['dropped_samples']:,}")
    if board_stats:
        print(f"{'board (its own count): sent / dropped pkts':<44} "
              f"{board_stats.get('samples_sent', 0):>12,} / "
              f"{board_stats.get('packets_dropped', '?')}  (TX ring full)")
        print(f"  the board sent {board_stats.get('samples_sent', 0) - received:,} samples more "
              "than were received: in flight when the host stopped reading (the session's "
              "end, not a loss)")
    print("gaps by reason:")
    for reason, (gaps, samples, seconds) in sorted(tally.by_reason.items()) or [("none", [0] * 3)]:
        print(f"  {reason:<60} {int(gaps):>5} gaps {int(samples):>10,} samples "
              f"{seconds:8.3f} s")
    if observed.messages:
        print(f"device messages ({len(observed.messages)}):")
        for message in observed.messages[:10]:
            print(f"  {message['at_s']:9.3f} s  {message['text']}")
    print()
    print("=" * 78)
    print(f"SILENT LOSS = expected - received - in flagged gaps = {expected:,} - {received:,} - "
          f"{marked:,} = {silent:+,} samples")
    print(f"  unmarked holes in the device timestamps: {tally.unmarked} "
          f"({tally.unmarked_samples:,} samples); in the file: {back.get('holes_unmarked')}")
    print(f"  received = recorded = read back: {counts_ok}; flags in the file match: {flags_ok}")
    print(f"  {verdict}")
    print("=" * 78, flush=True)
    return {
        "command": command, "mode": args.mode, "minutes": args.minutes, "load": args.load,
        "machine": args.machine_start, "machine_end": machine_line(), "url": url, "wall_s": wall_s,
        "rates": {"label_hz": label_hz, "reported_hz": tally.rate_hz, "true_hz": true_rate,
                  "measured_hz": measured},
        "rss": rss_rows,
        "counts": {"expected": expected, "received": received, "recorded": recorded,
                   "read_back": back.get("samples"), "file_bytes": size,
                   "reported_lost": observed.reported_lost, "blocks": observed.blocks},
        "balance": balance, "stream": tally.summary(), "file": back,
        "pipeline": None if pipeline is None else {
            "samples": pipeline.samples, "lost_samples": pipeline.lost_samples,
            "gaps": pipeline.gaps},
        "link": link, "board": board_stats, "messages": observed.messages,
        "outcome": {"reason": outcome.reason, "message": outcome.message},
        "silent_loss": silent, "unmarked_holes": tally.unmarked, "verdict": verdict,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=sorted(MODES), default="sim",
                        help="sim: the simulator at 6667 Hz; board: an emulated NUCLEO on a "
                             "pseudo-terminal at 1667 Hz")
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--load", action="store_true",
                        help="saturate every core with a busy-loop process meanwhile")
    parser.add_argument("--odr", type=float, help="another rate (Hz label)")
    parser.add_argument("--seed", type=int, default=SEED, help="the simulated unit")
    parser.add_argument("--rss-every", type=float, default=30.0, metavar="S")
    parser.add_argument("--compress", action="store_true", help="record .csv.gz")
    parser.add_argument("--dir", help="where the recording is written (default: temp)")
    parser.add_argument("--keep", metavar="DIR", help="keep the recording in DIR")
    parser.add_argument("--json", metavar="FILE", help="write every figure as JSON")
    args = parser.parse_args()
    result = run(args)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=1, default=float) + "\n")
    return 0 if result["verdict"] == "PASS" else 1


if __name__ == "__main__":
    sys.exit(main())
