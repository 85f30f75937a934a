"""The ``record`` and ``replay`` sub-commands of ``inclinometer`` (docs/recording-format.md).

``inclinometer record --device URL [--duration S] OUT.csv``
    read a device headless, run the pipeline, write a recording; Ctrl-C (or SIGTERM) ends it
    cleanly and keeps the file. An unplugged board is awaited (``--reconnect-timeout``) and
    recorded on into the same file, the outage marked as a gap.
``inclinometer replay IN.csv [--filter NAME...] [--param FILTER.NAME=VALUE...] --out ANGLES.csv``
    run filters over a recording as fast as possible, exactly as live, and export their angles.

:func:`add_param_argument` and :func:`parse_filter_parameters` give ``replay`` and
``evaluate`` the same ``--param FILTER.NAME=VALUE`` option.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import shutil
import signal
import sys
import threading
import warnings
from pathlib import Path
from typing import Any, TextIO

from app.core.safe_output import OutputRefused, check_output, write_error_message

EXIT_USAGE = 2
DEFAULT_RECONNECT_TIMEOUT_S = 300.0
"""As :data:`app.services.recorder.DEFAULT_RECONNECT_TIMEOUT_S` (a test keeps them equal)."""
EXIT_FAILED = 1
TRUE_WORDS = ("true", "1", "yes", "on")
FALSE_WORDS = ("false", "0", "no", "off")


def add_param_argument(parser: argparse.ArgumentParser) -> None:
    """Add the repeatable ``--param FILTER.NAME=VALUE`` option (``dest="params"``)."""
    parser.add_argument(
        "--param", dest="params", metavar="FILTER.NAME=VALUE", action="append", default=[],
        help="set a filter parameter, e.g. --param ekf.gyro_noise=2.5 (repeatable; checked "
             "against the filter's range; booleans take true/false/1/0)",
    )


def parse_filter_parameters(items: list[str] | None) -> dict[str, dict[str, Any]]:
    """``["ekf.gyro_noise=2.5", ...]`` -> ``{"ekf": {"gyro_noise": 2.5}}``, validated.

    Each value goes through the parameter's :class:`~app.core.filters.ParameterSpec` (type and
    range). Raises ValueError with a message for the user: bad form, unknown filter or
    parameter, a value out of range or not a number, a boolean that is not true/false/1/0.
    """
    from app.core.filters import FILTERS

    found: dict[str, dict[str, Any]] = {}
    for item in items or []:
        target, equals, text = item.partition("=")
        filter_name, dot, name = target.strip().partition(".")
        text = text.strip()
        if not equals or not dot or not filter_name or not name or not text:
            raise ValueError(f"--param {item!r}: write FILTER.NAME=VALUE, e.g. "
                             "ekf.gyro_noise=2.5")
        cls = FILTERS.get(filter_name)
        if cls is None:
            raise ValueError(f"--param {item!r}: no filter {filter_name!r}; choose from "
                             f"{', '.join(FILTERS)}")
        try:
            spec = cls.parameter_spec(name)
        except KeyError:
            known = ", ".join(s.name for s in cls.parameters) or "none"
            raise ValueError(f"--param {item!r}: {filter_name} has no parameter {name!r} "
                             f"(it has: {known})") from None
        if spec.kind == "bool":
            word = text.lower()
            if word not in TRUE_WORDS + FALSE_WORDS:
                raise ValueError(f"--param {item!r}: {name} is true or false (or 1 or 0)")
            value: Any = word in TRUE_WORDS
        else:
            try:
                value = spec.validate(text)
            except ValueError as exc:
                raise ValueError(f"--param {item!r}: {exc}") from None
        found.setdefault(filter_name, {})[name] = value
    return found


def check_parameters_for(parameters: dict[str, dict[str, Any]], filters: list[str]) -> None:
    """Raise ValueError when ``--param`` names a filter that is not being run."""
    for name in parameters:
        if name not in filters:
            raise ValueError(f"--param {name}.NAME=...: the filter {name!r} is not among "
                             f"those run ({', '.join(filters)}); add it with --filter")


def add_recording_parsers(commands: argparse._SubParsersAction) -> None:
    """Add ``record`` and ``replay`` to the command's sub-parsers."""
    record = commands.add_parser(
        "record",
        help="record a device to a CSV file, without the GUI",
        description=(
            "Open a device, run the pipeline (calibration and filter) and write every raw "
            "sample to a recording (format: docs/recording-format.md). Ctrl-C stops it "
            "cleanly; the file keeps every row. Progress goes to stderr."
        ),
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
             "pitch, level (out of level: tilt beyond a tolerance). Raised once beyond the "
             "limit for the delay; cleared once back inside by the hysteresis for the delay. "
             "E.g. --alarm 'tilt>2.0,hyst=0.2,delay=0.5' --alarm '|roll|>1'")

    replay = commands.add_parser(
        "replay",
        help="run filters over a recording and export their angles to CSV",
        description=(
            "Run orientation filters over a recording as fast as possible, through the same "
            "stages as live (the recorded calibration, the recorded device blocks, the "
            "recorded filter parameters), and write t, then per filter roll, pitch, tilt, "
            "direction (degrees) and the quaternion; with reference columns also the "
            "reference angles and each filter's inclination error."
        ),
    )
    replay.add_argument("source", metavar="IN.csv", help="a recording (or replay://PATH)")
    replay.add_argument("--filter", dest="filters", metavar="NAME", nargs="+", action="extend",
                        help="filter(s) to run, or 'all' (default: the recorded filter)")
    replay.add_argument("--out", required=True, metavar="ANGLES.csv", help="the file to write")
    replay.add_argument("--overwrite", action="store_true",
                        help="replace ANGLES.csv if it exists (never the recording itself)")
    replay.add_argument("--raw", action="store_true",
                        help="do not apply the calibration recorded in the file")
    replay.add_argument("--block", type=int, metavar="N",
                        help="process blocks of N samples instead of the recorded device "
                             "blocks: faster, but VQF then differs from live in the last bits")
    add_param_argument(replay)


MAX_BLOCK = 1_000_000
"""The largest ``replay --block`` (a block is held in memory whole)."""
WHOLE_FILE_OFFLINE_BYTES = 64 << 20
"""From this size on, ``replay --filter all`` leaves the offline smoothers out (memory)."""


def _error(message: str) -> None:
    print(f"inclinometer: {message}", file=sys.stderr)


def record_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``record`` sub-command."""
    from app.cli_errors import one_line
    from app.core.alarms import AlarmMonitor, alarms_from_specs
    from app.core.calibration_procedures.profiles import ProfileError, read_profile_file
    from app.core.filters import FILTERS
    from app.core.recording.errors import RecordingWriteError
    from app.services.recorder import parse_duration, record_device, warm_up_filters
    from drivers.errors import DeviceError
    from drivers.registry import create_device

    out = sys.stdout if out is None else out
    names = [args.record_filter] if args.record_filter else []
    comparisons = [n.strip() for item in args.record_comparisons or [] for n in item.split(",")
                   if n.strip()]
    unknown = [n for n in [*names, *comparisons] if n not in FILTERS]
    if unknown:
        _error(f"no filter {unknown[0]!r}; choose from {', '.join(FILTERS)}")
        return EXIT_USAGE
    offline = [n for n in [*names, *comparisons] if FILTERS[n].offline]
    if offline:
        _error(f"{offline[0]!r} is an offline filter (it needs the whole recording) and cannot "
               f"run while recording; record with a live filter, then run it with "
               f"'inclinometer replay OUT.csv --filter {offline[0]} --out ANGLES.csv'")
        return EXIT_USAGE
    try:
        alarm_config = alarms_from_specs(getattr(args, "alarms", None) or [])
    except ValueError as exc:
        _error(f"--alarm: {exc}")
        return EXIT_USAGE
    try:
        duration = None if args.duration is None else parse_duration(args.duration)
    except ValueError:
        _error(f"--duration {args.duration!r}: give seconds (30), or 30s, 2m, 1h")
        return EXIT_USAGE
    reconnect_timeout: float | None = DEFAULT_RECONNECT_TIMEOUT_S
    if args.reconnect_timeout is not None:
        if args.no_reconnect:
            _error("--reconnect-timeout and --no-reconnect contradict each other: give one")
            return EXIT_USAGE
        try:
            reconnect_timeout = parse_duration(args.reconnect_timeout)
        except ValueError:
            _error(f"--reconnect-timeout {args.reconnect_timeout!r}: give seconds (60), or "
                   "60s, 5m, 1h")
            return EXIT_USAGE
    if args.no_reconnect:
        reconnect_timeout = None
    calibration = None
    if args.calibration:
        try:
            calibration = read_profile_file(Path(args.calibration)).calibration
        except ProfileError as exc:
            _error(str(exc))
            return EXIT_USAGE
        except RecursionError:
            _error(f"{args.calibration}: not a valid calibration profile: its JSON is nested "
                   "too deeply to read")
            return EXIT_USAGE
        except ValueError as exc:  # an integer of thousands of digits
            _error(f"{args.calibration}: not a valid calibration profile ({one_line(exc)})")
            return EXIT_USAGE
    target = Path(args.out)
    if args.compress and target.suffix.lower() != ".gz":
        target = target.with_name(target.name + ".gz")
    try:
        check_output(target, inputs=_record_inputs(args), overwrite=args.overwrite,
                     input_name="recording being replayed")
    except OutputRefused as exc:
        _error(str(exc))
        return EXIT_FAILED
    warm_up_filters(args.record_filter, comparisons)  # before the device streams
    try:
        device = create_device(args.record_device)
        info = device.open()
    except DeviceError as exc:
        _error(str(exc))
        return EXIT_USAGE
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
            device, target, duration_s=duration, note=args.note,
            filter_name=args.record_filter, comparisons=comparisons,
            calibration=calibration, overwrite=args.overwrite, stop=stop, on_flush=progress,
            alarms=AlarmMonitor(alarm_config) if alarm_config.limits else None,
            on_alarms=lambda events: print_crossings(events, out),
            reconnect_timeout_s=reconnect_timeout, on_outage=print_outage,
            on_faults=lambda events: print_faults(events, out),
            on_message=print_warning,
        )
    except (DeviceError, RecordingWriteError) as exc:
        _error(str(exc))
        return EXIT_FAILED
    except KeyboardInterrupt:  # before the first sample: nothing was recorded
        _error("interrupted before recording started")
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    status = outcome.status
    endings = {
        "duration": "duration reached", "stopped": "stopped", "interrupted": "stopped by Ctrl-C",
        "end": "the source ended", "device": "the device failed", "write": "writing failed",
        "lost": "the device did not come back",
    }
    print(f"{status.path}: {status.rows_written} rows, {status.duration_s:.1f} s of device "
          f"time ({endings.get(outcome.reason, outcome.reason)})", file=out)
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
    from drivers.errors import DeviceError

    paths = [Path(args.calibration)] if args.calibration else []
    if args.record_device.lower().startswith("replay://"):
        with contextlib.suppress(DeviceError, ValueError):  # a bad URL: opening it says why
            paths.append(_recording_path(args.record_device))
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
    from app.services.health import fault_line

    for event in events:
        print(fault_line(event), file=out, flush=True)


def _data_rate(target: Path, odr_hz: float, reference: bool) -> str:
    """The estimated data rate and how long the target's disk lasts (for the user)."""
    from app.core.recording.sizing import data_rate

    try:
        free = float(shutil.disk_usage(target.resolve().parent).free)
    except OSError:
        free = None
    compressed = target.suffix.lower() == ".gz"
    kind = "compressed CSV" if compressed else "CSV"
    return f"{kind}, " + data_rate(odr_hz, reference=reference, compressed=compressed,
                                   free_bytes=free).text()


def check_recorded_calibration(metadata: dict[str, Any], path: Path) -> None:
    """CommandError when the recording's ``calibration`` is there but cannot be used: the
    samples would silently go uncalibrated (``--raw`` says so on purpose)."""
    from app.cli_errors import CommandError
    from app.core.recording.format import KEY_CALIBRATION, calibration_from_json

    value = metadata.get(KEY_CALIBRATION)
    if value is None:
        return
    try:
        calibration_from_json(value)
    except (ValueError, TypeError, KeyError) as exc:
        raise CommandError(f"{path}: the recorded calibration is invalid ({exc}); give --raw "
                           "to use the samples uncalibrated") from None


def _recording_path(source: str) -> Path:
    from drivers.replay import recording_path

    return recording_path(source)


def load_recording_for_cli(source: str) -> Any:
    """Read a recording for a command; warnings go to stderr. Raises RecordingError."""
    from app.core.recording.reader import read_recording

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = read_recording(_recording_path(source))
    for warning in caught:
        _error(f"warning: {warning.message}")
    return recording


def replay_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """The ``replay`` sub-command."""
    from app.cli_errors import check_output_folder, check_regular_file
    from app.core.evaluation import (
        DEFAULT_SKIP_S,
        error_statistics,
        recording_score_mask,
        scoring_rows,
    )
    from app.core.filters import DEFAULT_FILTER, FILTERS
    from app.core.recording.errors import RecordingError
    from app.core.recording.export import (
        resolve_calibration,
        run_filters,
        write_angles_csv,
    )
    from app.core.recording.reader import Recording
    from app.core.recording.stream import RecordingStream
    from drivers.errors import DeviceUrlError

    out = sys.stdout if out is None else out
    if args.block is not None and not 1 <= args.block <= MAX_BLOCK:
        _error(f"--block must be from 1 to {MAX_BLOCK}")
        return EXIT_USAGE
    check_output_folder(args.out, "--out")
    try:
        cli_parameters = parse_filter_parameters(getattr(args, "params", None))
    except ValueError as exc:
        _error(str(exc))
        return EXIT_USAGE
    try:
        source_path = _recording_path(args.source)
        check_regular_file(source_path)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            head = RecordingStream(source_path)
    except (RecordingError, DeviceUrlError) as exc:
        _error(str(exc))
        return EXIT_USAGE
    for warning in caught:
        _error(f"warning: {warning.message}")
    with head:
        if not args.raw:
            check_recorded_calibration(head.metadata, source_path)
        recorded_name = Recording(head.metadata, head.header, {}).filter_name
        names = args.filters or [recorded_name or DEFAULT_FILTER]
        if "all" in names and head.file_size() >= WHOLE_FILE_OFFLINE_BYTES:
            left_out = [n for n in FILTERS if FILTERS[n].offline]
            names = [n for n in dict.fromkeys([*FILTERS, *names]) if n != "all"
                     and (n not in left_out or n in names)]
            print(f"'all' leaves out {', '.join(left_out)} on a recording this long: offline "
                  "smoothers hold the whole session in memory (name them with --filter to run "
                  "them anyway)", file=out)
        if "all" not in names and all(n in FILTERS and not FILTERS[n].offline for n in names):
            return _replay_streamed(args, head, list(dict.fromkeys(names)), cli_parameters,
                                    source_path, out)
    try:
        recording = load_recording_for_cli(args.source)
    except (RecordingError, DeviceUrlError) as exc:
        _error(str(exc))
        return EXIT_USAGE
    if "all" in names:
        names = list(FILTERS)
    unknown = [n for n in names if n not in FILTERS]
    if unknown:
        _error(f"no filter {unknown[0]!r}; choose from {', '.join(FILTERS)} (or 'all')")
        return EXIT_USAGE
    names = list(dict.fromkeys(names))
    try:
        check_parameters_for(cli_parameters, names)
        score_mask = recording_score_mask(recording)
    except ValueError as exc:
        _error(str(exc))
        return EXIT_USAGE
    target = _replay_target(args, source_path)
    if target is None:
        return EXIT_USAGE
    calibration = None if args.raw else resolve_calibration(recording, "recorded")
    parameters = _replay_parameters(recording, cli_parameters, names)
    outputs = run_filters(recording, names, calibration=calibration, parameters=parameters,
                          block=args.block)
    try:
        write_angles_csv(target, recording, outputs, calibration=calibration,
                         overwrite=args.overwrite, option="--out")
    except OSError as exc:  # OutputRefused (a file that came meanwhile), a full disk
        _error(write_error_message(exc, target, "--out"))
        return EXIT_FAILED
    reference = recording.reference_quat
    scored = None
    table = []
    for output in outputs:
        stats = None
        if reference is not None:
            stats = error_statistics(output.quat, reference, recording.t_s, DEFAULT_SKIP_S,
                                     score_mask)
        table.append((output.name, output.roll_deg[-1], output.pitch_deg[-1], stats))
    if reference is not None:
        scored = int(scoring_rows(reference, recording.t_s, DEFAULT_SKIP_S, score_mask).sum())
    _print_replay(out, target, len(recording), recording.duration_s, calibration,
                  score_mask is not None, scored, table)
    return 0


def _replay_streamed(args: argparse.Namespace, stream: Any, names: list[str],
                     cli_parameters: dict[str, dict[str, Any]], source_path: Path,
                     out: TextIO) -> int:
    """``replay`` of online filters in one streamed pass: memory does not grow with the file."""
    from app.core.recording.errors import RecordingError
    from app.core.recording.export import replay_streamed
    from app.core.recording.reader import Recording

    try:
        check_parameters_for(cli_parameters, names)
    except ValueError as exc:
        _error(str(exc))
        return EXIT_USAGE
    target = _replay_target(args, source_path)
    if target is None:
        return EXIT_USAGE
    parameters = _replay_parameters(Recording(stream.metadata, stream.header, {}),
                                    cli_parameters, names)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            summary = replay_streamed(stream, names, target,
                                      calibration=None if args.raw else "recorded",
                                      parameters=parameters, block=args.block,
                                      overwrite=args.overwrite, option="--out")
        except (RecordingError, ValueError) as exc:
            failure = str(exc)
        except OSError as exc:  # a full disk: the temporary file is gone, the target untouched
            failure = write_error_message(exc, target, "--out")
        else:
            failure = ""
    for warning in caught:
        _error(f"warning: {warning.message}")
    if failure:
        _error(failure)
        return EXIT_FAILED
    calibration = None if args.raw else Recording(stream.metadata, stream.header, {}).calibration
    table = [(f.name, f.final_roll_deg, f.final_pitch_deg,
              f.errors.result() if summary.reference else None) for f in summary.filters]
    _print_replay(out, target, summary.rows, summary.duration_s, calibration, summary.masked,
                  summary.scored_rows if summary.reference else None, table)
    return 0


def _replay_target(args: argparse.Namespace, source_path: Path) -> Path | None:
    """``--out``, or None (said why) when it would overwrite the recording itself (the same
    file, a hard link too) or, without ``--overwrite``, any existing file."""
    target = Path(args.out)
    try:
        check_output(target, inputs=[source_path], overwrite=args.overwrite, option="--out",
                     input_name="recording")
    except OutputRefused as exc:
        _error(str(exc))
        return None
    return target


def _replay_parameters(recording: Any, cli_parameters: dict[str, dict[str, Any]],
                       names: list[str]) -> dict[str, dict[str, Any]]:
    """Each filter's parameters: the recorded (else default) ones, changed by --param."""
    from app.core.recording.export import recorded_filter_parameters

    recorded = recorded_filter_parameters(recording)
    return {name: {**recorded.get(name, {}), **cli_parameters.get(name, {})} for name in names}


def _print_replay(out: TextIO, target: Path, rows: int, duration_s: float, calibration: Any,
                  masked: bool, scored: int | None,
                  table: list[tuple[str, float, float, dict[str, Any] | None]]) -> None:
    """What ``replay`` prints: the file, which rows were scored, a line per filter (final
    angles, and RMSE and maximum when the recording has a reference: ``scored`` not None)."""
    from app.core.scoring import DEFAULT_SKIP_S, SCORE_COLUMN

    applied = "no calibration" if calibration is None else f"calibration {calibration.name!r}"
    print(f"{target}: {rows} rows, {duration_s:.1f} s, {applied}", file=out)
    if scored is not None:
        rule = (f"rows with {SCORE_COLUMN} == 1" if masked
                else f"after the first {DEFAULT_SKIP_S:g} s")
        print(f"  inclination error scored {rule} with a reference: {scored} of {rows} rows",
              file=out)
    width = max(6, *(len(name) for name, *_ in table))
    header = f"  {'filter':<{width}}  {'final roll':>10}  {'final pitch':>11}"
    if scored is not None:
        header += f"  {'RMSE deg':>9}  {'max deg':>9}"
    print(header, file=out)
    for name, roll, pitch, stats in table:
        line = f"  {name:<{width}}  {roll:10.3f}  {pitch:11.3f}"
        if stats is not None:
            rmse, worst = stats["rmse_deg"], stats["max_deg"]
            line += (f"  {rmse:9.3f}  {worst:9.3f}" if math.isfinite(rmse)
                     else f"  {'-':>9}  {'-':>9}")
        print(line, file=out)
