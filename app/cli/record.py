"""``inclinometer record --device URL [--duration S] OUT.csv`` (docs/recording-format.md).

Read a device headless, run the pipeline, write a recording; Ctrl-C (or SIGTERM) ends it
cleanly and keeps the file. An unplugged board is awaited (``--reconnect-timeout``) and
recorded on into the same file, the outage marked as a gap.
"""

from __future__ import annotations

import argparse
import contextlib
import shutil
import signal
import sys
import threading
from dataclasses import dataclass
from datetime import date
from pathlib import Path
from typing import Any, TextIO

from app.cli.errors import one_line
from app.core.alarms import AlarmMonitor, alarms_from_specs
from app.core.calibration_procedures.profiles import ProfileError, read_profile_file
from app.core.filters import FILTERS
from app.core.heading import (
    KEY_HEADING,
    heading_metadata,
    parse_place,
    typed_declination,
    wmm_declination,
)
from app.core.recording.errors import RecordingWriteError
from app.core.recording.sizing import data_rate
from app.core.safe_output import OutputRefused, check_output
from app.services.health import fault_line
from app.services.lsl_outlet import LslUnavailable
from app.services.recorder import parse_duration, record_device, warm_up_kernels
from drivers.errors import DeviceError
from drivers.registry import create_device, driver_for
from drivers.replay import recording_path

EXIT_USAGE = 2
DEFAULT_RECONNECT_TIMEOUT_S = 300.0
"""As :data:`app.services.recorder.DEFAULT_RECONNECT_TIMEOUT_S` (a test keeps them equal)."""
EXIT_FAILED = 1


def add_arguments(record: argparse.ArgumentParser) -> None:
    """The options of ``record``; it runs :func:`record_command`."""
    record.set_defaults(handler=record_command)
    record.description = (
        "Open a device, run the pipeline (calibration and filter) and write every raw "
        "sample to a recording (format: docs/recording-format.md). Ctrl-C stops it "
        "cleanly; the file keeps every row. Progress goes to stderr."
    )
    record.add_argument("out", metavar="OUT.csv", help="the recording to create")
    record.add_argument("--device", dest="record_device", metavar="URL", required=True,
                        help="the device, e.g. 'sim://wobble?odr=104' or "
                             "'sim://tour?realtime=0' (as fast as possible)")
    record.add_argument("--duration", metavar="S",
                        help="device time to record: 30, 30s, 2m, 1h (default: until Ctrl-C)")
    record.add_argument("--note", default="", help="free text stored in the recording")
    record.add_argument("--filter", dest="record_filter", metavar="NAME",
                        help="orientation filter to run (default: the app's default)")
    record.add_argument("--compare", dest="record_comparisons", metavar="NAME[,NAME]",
                        action="append", help="filters run side by side (noted in the file); "
                        "repeat the option or separate names with commas")
    record.add_argument("--calibration", metavar="PROFILE.json",
                        help="a calibration profile file to apply (default: none)")
    record.add_argument("--overwrite", action="store_true", help="replace OUT.csv if it exists")
    record.add_argument("--compress", action="store_true",
                        help="write format v1 inside gzip (OUT.csv.gz, about 40 %% of the size; "
                             "a crash still leaves a file readable up to its last write); "
                             "also chosen by a name ending in .gz")
    record.add_argument("--quiet", action="store_true", help="no progress lines")
    record.add_argument("--lsl", action="store_true",
                        help="also stream live over Lab Streaming Layer: the calibrated samples "
                             "(stream type IMU) and the filtered orientation (type "
                             "Orientation), source id inclinometer:UNIQUE_ID:imu/orientation, "
                             "stamped on the device's clock aligned to LSL's")
    record.add_argument(
        "--reconnect-timeout", metavar="S", default=None,
        help="how long to wait for an unplugged board (one with a USB serial number, found "
             "again on any port) before the recording ends; it records on into the same file "
             f"and marks the outage as a gap (default: {DEFAULT_RECONNECT_TIMEOUT_S:g} s)")
    record.add_argument("--no-reconnect", action="store_true",
                        help="end the recording when the device is lost (exit 1)")
    record.add_argument(
        "--alarm", dest="alarms", metavar="SPEC", action="append", default=[],
        help="watch a limit on the filtered angles (degrees) and print each crossing as it "
             "happens (also stored in the file); repeatable. SPEC: QUANTITY>LIMIT, "
             "QUANTITY<LIMIT or |QUANTITY|>LIMIT, both limits as 'roll>2,roll<-1', then "
             "options hyst=DEG (default 0.1) and delay=S (default 0.5). Quantities: tilt, roll, "
             "pitch, level (out of level: tilt beyond a tolerance); the magnetic heading "
             "with a 9-axis filter: 'heading:350..10' (outside a sector, clockwise), "
             "'|heading-45|>5' or 'heading-45>5' (off a set heading). Raised once beyond the "
             "limit for the delay; cleared once back inside by the hysteresis for the delay. "
             "E.g. --alarm 'tilt>2.0,hyst=0.2,delay=0.5' --alarm '|roll|>1'")
    north = record.add_mutually_exclusive_group()
    north.add_argument(
        "--declination", metavar="DEG", default=None,
        help="the magnetic declination (degrees, east positive) for true north, stored in the "
             "file's 'heading' metadata key (docs/recording-format.md)")
    north.add_argument(
        "--place", metavar="LAT,LON[,ALT]", default=None,
        help="take the declination from the World Magnetic Model at this place (degrees, "
             "metres) today, stored in the file's 'heading' metadata key (a southern latitude: "
             "--place=-33.9,151.2)")


def _error(message: str) -> None:
    print(f"inclinometer: {message}", file=sys.stderr)


class _Refused(Exception):
    """Arguments ``record`` cannot use: one line on stderr and an exit status."""

    def __init__(self, message: str, code: int = EXIT_USAGE) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class _Settings:
    """What ``record``'s arguments ask for, checked."""

    comparisons: list[str]
    alarms: Any
    heading: dict[str, Any] | None
    duration_s: float | None
    reconnect_timeout_s: float | None
    calibration: Any
    target: Path


def record_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``record`` sub-command."""
    out = sys.stdout if out is None else out
    try:
        settings = _settings(args)
    except _Refused as exc:
        _error(str(exc))
        return exc.code
    warm_up_kernels(args.record_filter, settings.comparisons)  # before the device streams
    try:
        device = create_device(args.record_device)
        info = device.open()
    except DeviceError as exc:
        _error(str(exc))
        return EXIT_USAGE
    target = settings.target
    if not args.quiet:
        print(f"recording {target.name} at {info.odr_hz:g} Hz: "
              f"{_data_rate(target, info.odr_hz, device.reference_source is not None)}",
              file=sys.stderr, flush=True)
    stop = threading.Event()

    def progress(status: Any) -> None:
        if not args.quiet:
            print(f"recording {status.path.name}: {status.duration_s:7.1f} s, "
                  f"{status.rows_synced} rows on disk", file=sys.stderr, flush=True)

    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        outcome = record_device(
            device, target, duration_s=settings.duration_s, note=args.note,
            filter_name=args.record_filter, comparisons=settings.comparisons,
            calibration=settings.calibration, overwrite=args.overwrite, stop=stop,
            on_flush=progress,
            alarms=AlarmMonitor(settings.alarms) if settings.alarms.limits else None,
            on_alarms=lambda events: print_crossings(events, out),
            reconnect_timeout_s=settings.reconnect_timeout_s, on_outage=print_outage,
            on_faults=lambda events: print_faults(events, out),
            on_message=print_warning, lsl=args.lsl,
            extra_metadata=None if settings.heading is None else {KEY_HEADING: settings.heading},
        )
    except (DeviceError, RecordingWriteError, LslUnavailable) as exc:
        _error(str(exc))
        return EXIT_FAILED
    except KeyboardInterrupt:  # before the first sample: nothing was recorded
        _error("interrupted before recording started")
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return _report(outcome, out)


def _settings(args: argparse.Namespace) -> _Settings:
    """``record``'s arguments checked (raises :class:`_Refused` with the reason)."""
    return _Settings(
        comparisons=_filters(args), alarms=_alarms(args), heading=_heading(args),
        duration_s=_duration(args.duration, "--duration", "30"),
        reconnect_timeout_s=_reconnect_timeout(args), calibration=_calibration(args),
        target=_target(args),
    )


def _filters(args: argparse.Namespace) -> list[str]:
    """The comparison filters (the main one is checked too): live filters that exist."""
    names = [args.record_filter] if args.record_filter else []
    comparisons = [n.strip() for item in args.record_comparisons or [] for n in item.split(",")
                   if n.strip()]
    unknown = [n for n in [*names, *comparisons] if n not in FILTERS]
    if unknown:
        raise _Refused(f"no filter {unknown[0]!r}; choose from {', '.join(FILTERS)}")
    offline = [n for n in [*names, *comparisons] if FILTERS[n].offline]
    if offline:
        raise _Refused(
            f"{offline[0]!r} is an offline filter (it needs the whole recording) and cannot "
            f"run while recording; record with a live filter, then run it with "
            f"'inclinometer replay OUT.csv --filter {offline[0]} --out ANGLES.csv'")
    return comparisons


def _heading(args: argparse.Namespace) -> dict[str, Any] | None:
    """The ``heading`` metadata of ``--declination`` or ``--place`` (None: neither given)."""
    try:
        if getattr(args, "declination", None) is not None:
            try:
                degrees = float(args.declination)
            except ValueError:
                raise ValueError(f"{args.declination!r} is not a number of degrees") from None
            return heading_metadata(typed_declination(degrees))
        if getattr(args, "place", None) is not None:
            return heading_metadata(wmm_declination(parse_place(args.place), date.today()))
    except ValueError as exc:
        option = "--declination" if getattr(args, "declination", None) is not None else "--place"
        raise _Refused(f"{option}: {exc}") from None
    return None


def _alarms(args: argparse.Namespace) -> Any:
    try:
        return alarms_from_specs(getattr(args, "alarms", None) or [])
    except ValueError as exc:
        raise _Refused(f"--alarm: {exc}") from None


def _duration(text: str | None, option: str, example: str) -> float | None:
    if text is None:
        return None
    try:
        return parse_duration(text)
    except ValueError:
        raise _Refused(f"{option} {text!r}: give seconds ({example}), or {example}s, "
                       f"{'2m' if option == '--duration' else '5m'}, 1h") from None


def _reconnect_timeout(args: argparse.Namespace) -> float | None:
    if args.reconnect_timeout is not None and args.no_reconnect:
        raise _Refused("--reconnect-timeout and --no-reconnect contradict each other: give one")
    if args.no_reconnect:
        return None
    if args.reconnect_timeout is None:
        return DEFAULT_RECONNECT_TIMEOUT_S
    return _duration(args.reconnect_timeout, "--reconnect-timeout", "60")


def _calibration(args: argparse.Namespace) -> Any:
    if not args.calibration:
        return None
    try:
        return read_profile_file(Path(args.calibration)).calibration
    except ProfileError as exc:
        raise _Refused(str(exc)) from None
    except RecursionError:
        raise _Refused(f"{args.calibration}: not a valid calibration profile: its JSON is "
                       "nested too deeply to read") from None
    except ValueError as exc:  # an integer of thousands of digits
        raise _Refused(f"{args.calibration}: not a valid calibration profile "
                       f"({one_line(exc)})") from None


def _target(args: argparse.Namespace) -> Path:
    """The file to write (``.gz`` added with --compress), refused if it would overwrite."""
    target = Path(args.out)
    if args.compress and target.suffix.lower() != ".gz":
        target = target.with_name(target.name + ".gz")
    try:
        check_output(target, inputs=_record_inputs(args), overwrite=args.overwrite,
                     input_name="recording being replayed")
    except OutputRefused as exc:
        raise _Refused(str(exc), EXIT_FAILED) from None
    return target


ENDINGS = {
    "duration": "duration reached", "stopped": "stopped", "interrupted": "stopped by Ctrl-C",
    "end": "the source ended", "device": "the device failed", "write": "writing failed",
    "lost": "the device did not come back",
}
"""How a recording ended, in words."""


def _report(outcome: Any, out: TextIO) -> int:
    """The closing line (stdout) and what went wrong (stderr); the exit status."""
    status = outcome.status
    print(f"{status.path}: {status.rows_written} rows, {status.duration_s:.1f} s of device "
          f"time ({ENDINGS.get(outcome.reason, outcome.reason)})", file=out)
    if outcome.lsl is not None:
        print(f"LSL: {outcome.lsl.imu_samples} samples and {outcome.lsl.orientation_samples} "
              "orientations sent", file=out)
    if outcome.held_signal:
        _error("the signal came while the file was being closed: it was finished first")
    if outcome.message:
        _error(outcome.message)
    if outcome.closing_error:
        _error(outcome.closing_error)
    if outcome.reason == "interrupted" and outcome.outages and (
            outcome.outages[-1].back_after_s is None):
        _error("stopped while waiting for the device; the rows before it was lost are kept")
    failed = outcome.reason in ("device", "lost", "write")
    return EXIT_FAILED if failed or outcome.closing_error else 0


def print_outage(outage: Any) -> None:
    """One line when the board is lost and one when it is back (stderr, even with --quiet:
    they change what the file holds)."""
    if outage.back_after_s is None:
        _error(f"device lost at {outage.lost_at_s:.1f} s: {outage.reason}; waiting for it "
               "(Ctrl-C stops)")
    else:
        _error(f"device back after {outage.back_after_s:.1f} s, {outage.samples_lost} samples "
               "lost, marked as a gap")


def _record_inputs(args: argparse.Namespace) -> list[Path]:
    """The files ``record`` reads (a replayed recording, the profile): never its output."""
    paths = [Path(args.calibration)] if args.calibration else []
    with contextlib.suppress(DeviceError, ValueError):  # a bad URL: opening it says why
        if driver_for(args.record_device).replayable:
            paths.append(recording_path(args.record_device))
    return paths


def print_crossings(events: list, out: TextIO) -> None:
    """One line per alarm crossing, as it happens (stdout: they are results, not progress)."""
    for event in events:
        print(event.message(), file=out, flush=True)


def print_warning(level: int, text: str) -> None:
    """A device's warnings and the look-alike check's verdict (stderr, even with --quiet)."""
    if level >= 2:
        _error(text)


def print_faults(events: list, out: TextIO) -> None:
    """One line per fault event, as it is declared (stdout, as the alarms' crossings)."""
    for event in events:
        print(fault_line(event), file=out, flush=True)


def _data_rate(target: Path, odr_hz: float, reference: bool) -> str:
    """The estimated data rate and how long the target's disk lasts (for the user)."""
    try:
        free = float(shutil.disk_usage(target.resolve().parent).free)
    except OSError:
        free = None
    compressed = target.suffix.lower() == ".gz"
    kind = "compressed CSV" if compressed else "CSV"
    return f"{kind}, " + data_rate(odr_hz, reference=reference, compressed=compressed,
                                   free_bytes=free).text()
