"""What the calibration lab's commands (``calibrate``, ``allan``, ``calibrate-temperature``)
share: the samples to work on (a recording or a live device), the checks and the safe writing
of ``--out`` and ``--report``, and Qt for the reports.

Exit status: 0 done, 1 the data does not calibrate (the message says why), 2 bad usage or a
file that cannot be read.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from app.cli.errors import EXIT_FAILED, CommandError, check_output_folder, finite
from app.core.calibration import calibration_json_text
from app.core.calibration_procedures.profiles import (
    SensorSettings,
)
from app.core.recording.errors import RecordingError
from app.core.recording.reader import read_recording
from app.core.safe_output import (
    OutputRefused,
    check_output,
    output_path,
    write_error_message,
)
from app.services.calibration_runs import CapturedStream, capture_device
from drivers.errors import DeviceError
from drivers.replay import recording_path

DEFAULT_ACCEL_FS_G = 4
DEFAULT_GYRO_FS_DPS = 250
MAX_SECONDS = 7 * 86400.0
"""The longest ``--seconds`` and ``--gyro-seconds`` (a week)."""


def usage(args: argparse.Namespace, message: str) -> CommandError:
    """Bad arguments or an unreadable input: exit 2, ``inclinometer COMMAND: MESSAGE``."""
    return CommandError(message, command=getattr(args, "command", None) or "calibrate")


def failed(args: argparse.Namespace, message: str) -> CommandError:
    """The data does not give a result: exit 1, ``inclinometer COMMAND: MESSAGE``."""
    return CommandError(message, EXIT_FAILED,
                        command=getattr(args, "command", None) or "calibrate")


def qt_for_documents() -> Any:
    """The QGuiApplication to paint a report with (offscreen when there is no screen: a lab
    script); the caller holds it while it paints. Qt is loaded only when a report is asked
    for."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtGui import QGuiApplication

    return QGuiApplication.instance() or QGuiApplication(["inclinometer"])


def _settings_from_device(device: dict[str, Any], rate_hz: float, out: TextIO):
    odr = device.get("odr_hz")
    accel_fs = device.get("accel_fs_g")
    gyro_fs = device.get("gyro_fs_dps")
    if not isinstance(odr, int | float) or odr <= 0:
        odr = rate_hz
    if not isinstance(accel_fs, int) or not isinstance(gyro_fs, int):
        print(f"note: the recording does not name its full scales; assuming +-"
              f"{DEFAULT_ACCEL_FS_G} g and +-{DEFAULT_GYRO_FS_DPS} dps", file=out)
        accel_fs, gyro_fs = DEFAULT_ACCEL_FS_G, DEFAULT_GYRO_FS_DPS
    return SensorSettings(float(odr), accel_fs, gyro_fs, str(device.get("sensor") or "LSM6DSOX"))


def load_stream(args: argparse.Namespace, out: TextIO) -> tuple[CapturedStream, str]:
    """The samples to work on (a recording or a live device) and a label for them."""
    if args.device is not None:
        if args.recording is not None:
            raise usage(args, "give a RECORDING or --device URL, not both")
        if args.seconds is None:
            raise usage(args, "--device needs --seconds N (how long to read)")
        finite(args.seconds, "--seconds", positive=True, maximum=MAX_SECONDS)
        print(f"reading {args.seconds:g} s from {args.device} ...", file=out)
        out.flush()
        try:
            stream = capture_device(args.device, args.seconds)
        except (DeviceError, ValueError) as exc:
            raise usage(args, str(exc)) from None
        if stream.note:
            print(f"note: {stream.note}", file=out)
        return stream, args.device
    if args.recording is None:
        raise usage(args, "give a RECORDING (or --device URL --seconds N)")
    if args.seconds is not None:
        raise usage(args, "--seconds goes with --device")
    path = Path(args.recording)
    if not path.is_file():
        raise usage(args, f"{path}: no such file" if not path.exists() else f"{path}: not a file")
    try:
        recording = read_recording(path)
    except RecordingError as exc:
        raise usage(args, str(exc)) from None
    except OSError as exc:
        raise usage(args, f"{path}: cannot read the recording: {exc.strerror or exc}") from None
    calibration = recording.calibration
    if calibration is not None and not calibration.is_identity:
        print(f"note: the recording was made with calibration {calibration.name!r}; its raw "
              "samples are used", file=out)
    simulator = recording.metadata.get("simulator")
    unit = simulator.get("unit_errors") if isinstance(simulator, dict) else None
    stream = CapturedStream(
        block=recording.sample_block(),
        settings=_settings_from_device(recording.device, recording.rate_hz, out),
        device=recording.device,
        unit_errors=unit if isinstance(unit, dict) else None,
    )
    return stream, str(path)


def vec(values: np.ndarray, spec: str, width: int = 10) -> str:
    return "".join(f"{format(float(v), spec):>{width}}" for v in values)


def check_outputs(args: argparse.Namespace) -> None:
    """``--out``, ``--save`` and ``--report`` of ``calibrate`` and ``calibrate-temperature``:
    at least one, into folders that exist, a report named .html or .pdf (CommandError)."""
    if args.out is None and not args.save and args.report is None:
        raise usage(args, "say what to do with the result: --out FILE.json, --save and/or "
                     "--report FILE")
    for option, value in (("--out", args.out), ("--report", args.report)):
        if value is not None:
            check_output_folder(value, option)
    if args.report is not None and Path(args.report).suffix.lower() not in (
            ".html", ".htm", ".pdf"):
        raise usage(args, f"--report {args.report}: name an .html or a .pdf file")
    for option, value in (("--out", args.out), ("--report", args.report)):
        if value is not None:
            try:
                check_output(value, inputs=input_paths(args), overwrite=args.overwrite,
                             option=option)
            except OutputRefused as exc:
                raise usage(args, str(exc)) from None
    if args.out is not None and args.report is not None and (
            Path(args.out).absolute() == Path(args.report).absolute()):
        raise usage(args, "--out and --report name the same file")


def input_paths(args: argparse.Namespace) -> list[Path]:
    """The files a command reads (the recording, --base): no output may be one of them."""
    paths = []
    for value in (getattr(args, "recording", None), getattr(args, "base", None)):
        if value:
            try:
                paths.append(recording_path(value) if "://" in value else Path(value))
            except ValueError:  # not a replay URL: nothing on disk to protect
                continue
    return paths


def write_outputs(args: argparse.Namespace, out: TextIO, json_document: dict[str, Any] | None,
                   report: Callable[[Path], None]) -> None:
    """Write ``--out`` (the JSON) and ``--report`` safely; CommandError, exit 1, naming what
    was written when one cannot be."""
    written = []
    for option, value in (("--out", args.out), ("--report", args.report)):
        if value is None:
            continue
        try:
            with output_path(value, inputs=input_paths(args), overwrite=args.overwrite,
                             option=option, keep_suffix=True) as temporary:
                if option == "--out":
                    text = calibration_json_text(json_document)
                    temporary.write_bytes(text.encode("utf-8"))
                else:
                    report(temporary)
        except OSError as exc:
            done = f" ({', '.join(written)} written)" if written else ""
            raise failed(args, f"{write_error_message(exc, value, option)}{done}") from None
        written.append(value)
        print(f"wrote {value}" if option == "--out" else f"wrote the report {value}", file=out)


def check_save(args: argparse.Namespace, stream: CapturedStream, label: str) -> None:
    if args.save and not stream.unique_id:
        raise usage(args, f"{label}: the device has no unique id, so --save cannot name its "
                     "profile; use --out FILE.json")


