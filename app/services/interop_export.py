"""``inclinometer export`` and File > Export: a recording as MCAP (ROS 2) or EuRoC/Kalibr CSV.

The recording runs through the replay's streamed pass (:func:`app.core.recording.export.
filtered_blocks`: the recorded calibration, then the recorded filter with its recorded
parameters, block by block as the device delivered them): the exported samples are the
calibrated ones the pipeline saw, the orientation the one its filter gave. Every export states
its axis convention (:mod:`app.core.interop.frames`), frame id, time axis and origin: MCAP in a
metadata record, EuRoC in a sidecar file (:func:`app.core.interop.euroc.readme_path`).
Outputs go through :mod:`app.core.safe_output`: nothing is overwritten without ``overwrite``,
and a failed write (a full disk) leaves no file behind.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.core.filters import DEFAULT_FILTER, FILTERS
from app.core.interop import euroc, frames
from app.core.interop.mcap_ros2 import McapImuWriter
from app.core.recording.errors import RecordingError
from app.core.recording.export import filtered_blocks
from app.core.recording.format import recorded_calibration_problem
from app.core.recording.stream import RecordingStream
from app.core.safe_output import (
    OutputRefused,
    check_output,
    output_file,
    write_error_message,
    write_output,
)
from app.core.version import __version__

FORMATS = ("mcap", "euroc")
DEFAULT_FRAME_ID = "imu_link"
IMU_TOPIC = "/imu/data"
MAG_TOPIC = "/imu/mag"
OPTION = "OUT"
"""How messages name the output (the command's positional argument)."""


class ExportRefused(ValueError):
    """Input the export cannot use (a bad recording, format, frame or target); one line."""


class ExportFailed(RuntimeError):
    """The export ran but its file could not be written, or the recording broke off."""


@dataclass(frozen=True, slots=True)
class ExportRequest:
    """An export: the recording, the format, the target and the conventions."""

    source: Path
    target: Path
    format: str
    frame: str = "enu"
    frame_id: str = DEFAULT_FRAME_ID
    filter: str | None = None
    """None: the recording's filter (else the default one)."""
    orientation: bool = True
    """MCAP: write the filter's orientation (False: none given, covariance[0] = -1)."""
    raw: bool = False
    """The samples as measured, without the recorded calibration."""
    overwrite: bool = False


@dataclass(slots=True)
class ExportSummary:
    """What an export wrote."""

    target: Path
    format: str
    frame: str
    rows: int = 0
    mag_rows: int = 0
    first_t_s: float = math.nan
    last_t_s: float = math.nan
    filter_name: str | None = None
    calibration_name: str | None = None
    files: list[Path] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return self.last_t_s - self.first_t_s if self.rows > 1 else 0.0


Say = Callable[[str], None]


def _quiet(_: str) -> None:
    """Drop a line (the default for ``warn``)."""


def export_recording(request: ExportRequest, warn: Say = _quiet) -> ExportSummary:
    """Write the export; :class:`ExportRefused` for input it cannot use, :class:`ExportFailed`
    when the file could not be written (then nothing is left at the target)."""
    if request.format not in FORMATS:
        raise ExportRefused(f"--format {request.format!r}: one of {', '.join(FORMATS)}")
    try:
        frame = frames.check_frame(request.frame)
    except ValueError as exc:
        raise ExportRefused(f"--frame: {exc}") from None
    if not request.frame_id.strip() or any(c.isspace() for c in request.frame_id):
        raise ExportRefused(f"--frame-id {request.frame_id!r}: a name without spaces")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            stream = RecordingStream(request.source)
        except RecordingError as exc:
            raise ExportRefused(str(exc)) from None
    for warning in caught:
        warn(str(warning.message))
    with stream:
        metadata = stream.metadata
        if not request.raw:
            problem = recorded_calibration_problem(metadata)
            if problem is not None:
                raise ExportRefused(f"{request.source}: the recorded calibration is invalid "
                                    f"({problem}); give --raw to export the samples "
                                    "uncalibrated")
        name = _filter_name(request, metadata)
        targets = [request.target]
        if request.format == "euroc":
            targets.append(euroc.readme_path(request.target))
        for target in targets:
            try:
                check_output(target, inputs=[request.source], overwrite=request.overwrite,
                             option=OPTION, input_name="recording")
            except OutputRefused as exc:
                raise ExportRefused(str(exc)) from None
        summary = ExportSummary(request.target, request.format, frame, filter_name=name,
                                calibration_name=_calibration_name(metadata, request.raw))
        write = _write_mcap if request.format == "mcap" else _write_euroc
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                write(request, stream, summary)
        except (RecordingError, ValueError) as exc:
            raise ExportFailed(f"{request.source}: {exc}; nothing was written") from None
        except OSError as exc:  # a full disk: the temporary file is gone, the target untouched
            raise ExportFailed(write_error_message(exc, request.target, OPTION)) from None
        finally:
            for warning in caught:
                warn(str(warning.message))
    return summary


def _filter_name(request: ExportRequest, metadata: dict[str, Any]) -> str:
    recorded = metadata.get("filter")
    name = request.filter or (recorded.get("name") if isinstance(recorded, dict) else None)
    name = name if isinstance(name, str) else DEFAULT_FILTER
    if name not in FILTERS:
        raise ExportRefused(f"no filter {name!r}; choose from {', '.join(FILTERS)} (--filter)")
    if FILTERS[name].offline:
        online = ", ".join(n for n in FILTERS if not FILTERS[n].offline)
        raise ExportRefused(f"{name} is an offline smoother: the export runs its filter in one "
                            f"streamed pass; choose one of {online} with --filter")
    return name


def _calibration_name(metadata: dict[str, Any], raw: bool) -> str | None:
    value = metadata.get("calibration")
    if raw or not isinstance(value, dict):
        return None
    return str(value.get("name") or "recorded")


def _conventions(request: ExportRequest, summary: ExportSummary) -> dict[str, Any]:
    """What every export states: frame, frame id, time axis, units, origin."""
    heading = ("from the magnetometer (earth y = magnetic north)"
               if FILTERS[summary.filter_name or DEFAULT_FILTER].uses_magnetometer
               else "from the gyroscope alone: relative to an arbitrary start unless the "
                    "filter used a magnetometer")
    return {
        "frame": summary.frame.upper(),
        "frame_convention": frames.DESCRIPTIONS[summary.frame],
        "frame_id": request.frame_id,
        "time_axis": "the recording's t column (the device clock) in integer nanoseconds; "
                     "its start_time metadata gives the wall-clock start",
        "units": "angular velocity rad/s, linear acceleration m/s^2 (specific force, gravity "
                 "included), magnetic field tesla",
        "source": Path(request.source).name,
        "samples": "as measured (--raw)" if request.raw else (
            f"calibrated with the recorded calibration ({summary.calibration_name})"
            if summary.calibration_name else "as recorded (the recording has no calibration)"),
        "orientation": (f"the {summary.filter_name} filter over the recording, heading "
                        f"{heading}") if request.orientation else "not given",
        "exporter": f"inclinometer {__version__}",
    }


def _blocks(request: ExportRequest, stream: RecordingStream, summary: ExportSummary
            ) -> Any:
    """(t_ns, gyro, accel, quat, mag) per device block, in the export's frame."""
    name = summary.filter_name or DEFAULT_FILTER
    for samples, outputs in filtered_blocks(stream, [name],
                                            calibration=None if request.raw else "recorded"):
        if summary.rows == 0:
            summary.first_t_s = float(samples.t_s[0])
        summary.last_t_s = float(samples.t_s[-1])
        summary.rows += len(samples)
        t_ns = euroc.timestamps_ns(samples.t_s)
        mag = None if samples.mag_ut is None else frames.body_vectors(summary.frame,
                                                                       samples.mag_ut)
        yield (t_ns, frames.body_vectors(summary.frame, samples.gyro_rad_s),
               frames.body_vectors(summary.frame, samples.accel_m_s2),
               frames.orientation(summary.frame, outputs[0].quat), mag)


def _write_mcap(request: ExportRequest, stream: RecordingStream, summary: ExportSummary
                ) -> None:
    with output_file(request.target, inputs=[request.source], overwrite=request.overwrite,
                     option=OPTION) as handle:
        writer = McapImuWriter(handle, frame_id=request.frame_id, imu_topic=IMU_TOPIC,
                               mag_topic=MAG_TOPIC, orientation=request.orientation)
        writer.add_metadata("inclinometer.export", {
            **_conventions(request, summary), "imu_topic": IMU_TOPIC, "mag_topic": MAG_TOPIC,
            "covariance": "all zeros = unknown (sensor_msgs/Imu); orientation_covariance[0] "
                          "= -1 when no orientation is given"})
        writer.add_metadata("inclinometer.recording", stream.metadata)
        for t_ns, gyro, accel, quat, mag in _blocks(request, stream, summary):
            writer.write_imu(t_ns, gyro, accel, quat)
            if mag is not None:
                writer.write_mag(t_ns, mag)
        summary.mag_rows = writer.mag_messages
        writer.finish()
    summary.files.append(request.target)


def _write_euroc(request: ExportRequest, stream: RecordingStream, summary: ExportSummary
                 ) -> None:
    with output_file(request.target, inputs=[request.source], overwrite=request.overwrite,
                     option=OPTION) as handle:
        handle.write((euroc.EUROC_HEADER + "\n").encode("ascii"))
        for t_ns, gyro, accel, _, _ in _blocks(request, stream, summary):
            handle.write(euroc.euroc_rows(t_ns, gyro, accel))
    summary.files.append(request.target)
    conventions = {**_conventions(request, summary), "orientation": "not in this format"}
    readme = euroc.readme_path(request.target)
    write_output(readme, euroc.euroc_readme(
        request.target.name, [f"{key}: {value}" for key, value in conventions.items()]),
        inputs=[request.source], overwrite=request.overwrite, option=OPTION)
    summary.files.append(readme)
