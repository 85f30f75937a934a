"""``inclinometer check-board PORT``: put a NUCLEO board (link protocol v1) through its paces.

For someone who has just flashed the firmware: one command that says whether the board, the
sensor and the link work, rate by rate. It reports what the board says about itself, the
PING round trip, and for every output data rate the board accepts a few seconds of streaming:
samples against the expected count, lost samples, sequence gaps, CRC errors, the regularity
of the device time axis, the sample rate measured on the chip's own clock against the rate an
LSM6DSOX really runs at (6666.67 Hz / ODR_Coeff, trimmed: "104 Hz" is 104.17 Hz) and against
the rate the board reports, and the board clock against the computer's; then |a| at rest (0.5 g
or 2 g is a look-alike part answering WHO_AM_I 0x6C, such as an LSM6DSO32: a warning); then the
sensor's self-test (it must lie still). Rates the board refuses (its link or sensor bus cannot carry
them) are listed with its reason; they are not failures. On a board with two sensors a rate
that fits sensor 0 alone is checked as usual, with the board's note that sensor 1 is paused
there. Last, the board's own health counters
(STATUS) and how they rose during the check: a FIFO overrun, dropped or damaged bytes, a stuck
I2C bus or a watchdog reset fail it; I2C retries are reported. Exit status 0 when everything
passed.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, TextIO

import numpy as np

from app.cli.errors import finite, printable
from app.core.lookalike import GIVE_UP_SECONDS
from app.services.board_check import at_rest_verdict, timed_blocks
from drivers import lsm6dsox
from drivers.errors import DeviceError, SettingRefusedError
from drivers.serial_link import SerialLinkDevice

if TYPE_CHECKING:
    from app.core.devices import BoardStatus
    from drivers.base import Device

CHECK_SECONDS = 3.0
MIN_SAMPLES = 40
"""Each rate streams at least this many samples (12.5 Hz takes longer than the seconds asked)."""
PINGS = 20
AT_REST_SECONDS = 5.0
"""Longest wait for the board to lie still for the look-alike check (|a| at rest)."""
COUNT_TOLERANCE = 0.03
"""Samples may differ from rate x time by this share (startup, the last packet in flight)."""
CLOCK_TOLERANCE_PPM = 30_000
"""Device clock against the computer's: the trimmed chip clock is within a few percent."""
RATE_TOLERANCE_PPM = 1_000
"""Measured sample rate (chip timestamps) against the real rate: a datasheet label used as the
rate is 1 600 ppm off ("104 Hz" for 104.17 Hz), 40 000 at "12.5 Hz"."""
REPORTED_TOLERANCE_PPM = 100
"""The rate the board reports (CONFIG's odr_mhz) against the real one (rounding: 13 ppm)."""
HEALTH_PROBLEMS = ("uart_tx_dropped_bytes", "uart_rx_errors", "i2c_recoveries",
                   "fifo_overruns", "watchdog_resets")
"""Board counters whose rise during the check fails it."""


def add_arguments(check: argparse.ArgumentParser) -> None:
    """The options of ``check-board``; it runs :func:`check_command`."""
    check.set_defaults(handler=check_command)
    check.description = __doc__.splitlines()[0].split(": ", 1)[1]
    check.add_argument("port", metavar="PORT", help="its serial port (/dev/ttyACM0, COM5)")
    check.add_argument("--seconds", type=float, default=CHECK_SECONDS, metavar="S",
                       help="streaming time per rate (default %(default)g)")
    check.add_argument("--rates", metavar="HZ,...",
                       help="output data rates to try (default: all ten)")
    check.add_argument("--no-self-test", action="store_true",
                       help="skip the self-test (it needs the sensor lying still)")


@dataclass(frozen=True, slots=True)
class RateResult:
    """One rate's streaming check."""

    odr_nominal_hz: float
    refused: str = ""
    samples: int = 0
    expected: float = 0.0
    lost: int = 0
    seq_gaps: int = 0
    crc_errors: int = 0
    worst_step_error: float = 0.0
    """Largest |dt - 1/ODR| of the device time axis, in sample periods."""
    clock_ppm: float = 0.0
    """Device time against the computer's, over the run (ppm)."""
    measured_hz: float = 0.0
    """Samples per second of the chip's own clock (its timestamps)."""
    real_hz: float = 0.0
    """The rate an LSM6DSOX runs at for this setting: 6666.67 Hz / ODR_Coeff x the trim the
    board's tick reports."""
    reported_hz: float = 0.0
    """The rate the board reports (CONFIG)."""
    paused: str = ""
    """The board's LOG when it paused another sensor at this rate (it fits sensor 0 alone)."""

    @property
    def rate_ppm(self) -> float:
        return (self.measured_hz / self.real_hz - 1.0) * 1e6 if self.real_hz else 0.0

    @property
    def reported_ppm(self) -> float:
        return (self.reported_hz / self.real_hz - 1.0) * 1e6 if self.real_hz else 0.0

    @property
    def rate_ok(self) -> bool:
        return (abs(self.rate_ppm) < RATE_TOLERANCE_PPM
                and abs(self.reported_ppm) < REPORTED_TOLERANCE_PPM)

    @property
    def passed(self) -> bool:
        return bool(self.refused) or (
            abs(self.samples - self.expected) <= COUNT_TOLERANCE * self.expected + 2
            and self.lost == self.seq_gaps == self.crc_errors == 0
            and self.worst_step_error < 0.5
            and abs(self.clock_ppm) < CLOCK_TOLERANCE_PPM
            and self.rate_ok
        )

    def rate_problem(self) -> str:
        """Why the rate is wrong, for the report; empty when it is right."""
        if self.refused or self.rate_ok:
            return ""
        return (f"the chip should run at {self.real_hz:.3f} Hz (\"{self.odr_nominal_hz:g} Hz\" "
                f"is 6666.67 Hz / ODR_Coeff, trimmed); measured {self.measured_hz:.3f} Hz "
                f"({self.rate_ppm:+.0f} ppm), the board reports {self.reported_hz:.3f} Hz "
                f"({self.reported_ppm:+.0f} ppm)")


def clock_ppm_of(arrivals: list[tuple[float, float]]) -> float:
    """Device clock against the computer's (ppm) from each block's last sample time and arrival.

    A block arrives after its last sample, so each pair places one instant on both clocks; the
    slope of a straight-line fit through all of them averages out each read's latency. (The
    first and last reads alone, against the first and last sample *kept*, mixed a block's worth
    of samples, up to 100 ms, into a 1.5 s span: -3 % on a loaded machine.)
    0 when the arrivals span a second or less: too short to say.
    """
    if len(arrivals) < 3:
        return 0.0
    device_t, wall = np.asarray(arrivals, dtype=float).T
    if wall[-1] - wall[0] <= 1.0 or device_t[-1] - device_t[0] <= 0.0:
        return 0.0
    wall_per_device = float(np.polyfit(device_t - device_t[0], wall - wall[0], 1)[0])
    return (1.0 / wall_per_device - 1.0) * 1e6


def check_rate(port: str, odr_hz: float, seconds: float) -> RateResult:
    """Stream ``odr_hz`` for ``seconds`` (at least :data:`MIN_SAMPLES` samples)."""
    device = SerialLinkDevice(f"serial://{port}?odr={odr_hz:g}")
    try:
        try:
            info = device.open()
        except SettingRefusedError as exc:
            return RateResult(odr_hz, refused=exc.reason)
        duration = max(seconds, MIN_SAMPLES / info.odr_hz)
        # (device time of a block's last sample, computer time it arrived), one pair a block.
        seen = timed_blocks(device, duration * info.odr_hz, wall_s=duration + 5.0)
        times, arrivals = seen.times, seen.arrivals
        # Reads return whole blocks (up to 100 ms of samples): the count stops at what was asked.
        t = np.concatenate(times)[: math.ceil(duration * info.odr_hz)] if times else np.zeros(0)
        counters = device.counters
        period = 1.0 / info.odr_hz
        steps = np.diff(t)
        worst = float(np.max(np.abs(steps - period)) / period) if len(steps) else 1.0
        device_span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
        clock_ppm = clock_ppm_of(arrivals)
        # The rate on the chip's own clock (its timestamps place the packets), against the rate
        # the chip really runs at: the ODR code's 6666.67 Hz / ODR_Coeff times the trim that
        # the board's tick length carries (tick_ns = 25 000 / trim).
        tick_ns = float(info.extra.get("tick_ns") or 25_000)
        real_hz = lsm6dsox.real_odr_hz(odr_hz) * 25_000.0 / tick_ns
        measured_hz = (len(t) - 1) / device_span if device_span > 0 else 0.0
        paused = next((entry.text for entry in device.recent_logs()
                       if entry.text.startswith("sensor ") and " paused: " in entry.text), "")
        return RateResult(
            odr_hz, samples=len(t), expected=duration * info.odr_hz,
            lost=counters.lost_samples, seq_gaps=counters.seq_gaps,
            crc_errors=counters.crc_errors + counters.undecodable, worst_step_error=worst,
            clock_ppm=clock_ppm, measured_hz=measured_hz, real_hz=real_hz,
            reported_hz=info.odr_hz, paused=paused,
        )
    finally:
        device.close()


def at_rest_line(device: Device) -> str:
    """|a| while the board lies still: near 0.5 g or 2 g is a look-alike part (WHO_AM_I 0x6C
    answers for the LSM6DSO32 too, whose ranges are double)."""
    verdict = at_rest_verdict(device, min(GIVE_UP_SECONDS, AT_REST_SECONDS))
    if verdict.warning:
        return f"WARN  sensor: {verdict.warning}"
    if verdict.accel_g is None:
        return "at rest   no verdict on |a|: the board moved (it must lie still)"
    return f"at rest   |a| = {verdict.accel_g:.3f} g (an LSM6DSOX reads 1 g)"


def request_board_status(port: str) -> BoardStatus | None:
    """The board's STATUS now (None: its firmware predates STATUS). Raises DeviceError."""
    device = SerialLinkDevice(f"serial://{port}")
    try:
        device.open()
        return device.request_status()
    finally:
        device.close()


def health_report(start: BoardStatus | None, end: BoardStatus | None,
                  out: TextIO) -> bool:
    """Print the board's counters at the end and their rise since ``start``; False when a
    rise means trouble (see :data:`HEALTH_PROBLEMS`) or the board restarted."""
    if end is None:
        print("health    no STATUS: the firmware predates the STATUS extension of protocol v1",
              file=out)
        return True
    restarted = start is not None and end.restarted_since(start)
    print(f"health    started by {end.reset_cause}, up {end.uptime_s:.1f} s"
          + (", on its internal oscillator" if end.clock_fallback else "")
          + (" - RESTARTED during the check" if restarted else ""), file=out)
    ok = not restarted
    for name in end.COUNTERS:
        value = getattr(end, name)
        rise = 0 if start is None or restarted else end.rise(start, name)
        bad = name in HEALTH_PROBLEMS and rise > 0
        ok &= not bad
        print(f"  {end.TITLES[name]:<22} {value:>12,}  (+{rise:,} during the check)"
              + ("  FAIL" if bad else ""), file=out)
    return ok


def check_board(port: str, rates: list[float], seconds: float, self_test: bool,
                out: TextIO) -> bool:
    """Run the checks, print a report to ``out``; True when everything passed."""
    ok = True
    device = SerialLinkDevice(f"serial://{port}")
    try:
        info = device.open()
    except DeviceError as exc:
        print(f"FAIL  open: {exc}", file=out)
        return False
    try:
        extra = info.extra
        print(f"board     {printable(info.name)}, firmware {printable(info.firmware)}, "
              f"unique id {printable(info.unique_id)}",
              file=out)
        print(f"sensor    {info.sensor} (WHO_AM_I 0x{extra.get('who_am_i', 0):02X}), "
              f"{info.odr_hz:g} Hz (label {info.odr_nominal_hz:g}), tick "
              f"{extra.get('tick_ns')} ns, +-{info.accel_fs_g} g, +-{info.gyro_fs_dps} dps",
              file=out)
        if extra.get("usb_vid_pid"):
            print(f"usb       {extra['usb_vid_pid']}, serial {extra.get('usb_serial')}", file=out)
        trips = [device.ping() * 1e3 for _ in range(PINGS)]
        print(f"ping      {len(trips)} round trips: median {statistics.median(trips):.1f} ms, "
              f"max {max(trips):.1f} ms", file=out)
        status_at_start = device.request_status()
    except DeviceError as exc:
        print(f"FAIL  {exc}", file=out)
        return False
    finally:
        device.close()

    print(f"{'rate':>7}  {'samples':>14}  lost  gaps  crc  step  {'measured':>9}  {'rate ppm':>8}  "
          f"clock ppm  result", file=out)
    for odr in rates:
        try:
            result = check_rate(port, odr, seconds)
        except DeviceError as exc:
            print(f"{odr:>7g}  FAIL  {exc}", file=out)
            ok = False
            continue
        if result.refused:
            print(f"{odr:>7g}  refused by the board: {result.refused}", file=out)
            continue
        ok &= result.passed
        counts = f"{result.samples}/{result.expected:.0f}"
        print(f"{odr:>7g}  {counts:>14}  {result.lost:>4}  "
              f"{result.seq_gaps:>4}  {result.crc_errors:>3}  {result.worst_step_error:>4.2f}  "
              f"{result.measured_hz:>9.3f}  {result.rate_ppm:>+8.0f}  "
              f"{result.clock_ppm:>+9.0f}  {'ok' if result.passed else 'FAIL'}", file=out)
        if result.rate_problem():
            print(f"         rate: {result.rate_problem()}", file=out)
        if result.paused:
            print(f"         note: {result.paused}", file=out)

    device = SerialLinkDevice(f"serial://{port}")
    try:
        device.open()
        print(at_rest_line(device), file=out)
    except DeviceError as exc:
        print(f"FAIL  at rest: {exc}", file=out)
        ok = False
    finally:
        device.close()

    if self_test:
        device = SerialLinkDevice(f"serial://{port}")
        try:
            device.open()
            st = device.self_test()
            accel = "/".join(str(v) for v in st.accel_delta_mg)
            gyro = "/".join(str(v) for v in st.gyro_delta_dps)
            print(f"self-test accelerometer {'pass' if st.accel_pass else 'FAIL'} ({accel} mg), "
                  f"gyroscope {'pass' if st.gyro_pass else 'FAIL'} ({gyro} dps)", file=out)
            ok &= st.accel_pass and st.gyro_pass
        except DeviceError as exc:
            print(f"FAIL  self-test: {exc}", file=out)
            ok = False
        finally:
            device.close()
    try:
        ok &= health_report(status_at_start, request_board_status(port), out)
    except DeviceError as exc:
        print(f"FAIL  board status: {exc}", file=out)
        ok = False
    print("PASS: the board works." if ok else "FAIL: see the lines marked FAIL.", file=out)
    return ok


def check_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Run the ``check-board`` sub-command."""
    out = sys.stdout if out is None else out
    finite(args.seconds, "--seconds", positive=True, maximum=3600.0)
    rates = list(lsm6dsox.ODR_LABELS_HZ.values())
    if args.rates:
        try:
            rates = [float(text) for text in args.rates.split(",") if text.strip()]
        except ValueError:
            print(f"inclinometer: --rates wants numbers like 104,833: {args.rates!r}",
                  file=sys.stderr)
            return 2
    unknown = [r for r in rates if r not in lsm6dsox.ODR_LABELS_HZ.values()]
    if unknown:
        choices = ", ".join(f"{hz:g}" for hz in lsm6dsox.ODR_LABELS_HZ.values())
        print(f"inclinometer: {unknown[0]:g} Hz is not an LSM6DSOX rate; use {choices}",
              file=sys.stderr)
        return 2
    return 0 if check_board(args.port, rates, args.seconds, not args.no_self_test, out) else 1
