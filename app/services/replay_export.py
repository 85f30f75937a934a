"""Replay a recording's filters into an angles file (``inclinometer replay``), one summary.

Online filters run in one streamed pass (memory does not grow with the file); a run with an
offline smoother, or ``all`` filters, reads the whole recording. Both paths end in the same
:class:`ReplaySummary`: the rows, the calibration applied, which rows were scored and, per
filter, the final angles and (with a reference orientation) the inclination error; with a
magnetometer too, the heading and total errors (meaningful only for a filter that took its
heading from the magnetometer: :attr:`FilterLine.magnetic`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.core.evaluation import magnetic_heading, recording_score_mask
from app.core.faults import FaultEvent
from app.core.filters import FILTERS, default_filter_for
from app.core.recording.errors import RecordingError
from app.core.recording.export import (
    recorded_filter_parameters,
    replay_streamed,
    resolve_calibration,
    run_filters,
    write_angles_csv,
)
from app.core.recording.format import MAG_COLUMNS, recorded_calibration_problem
from app.core.recording.reader import Recording, read_recording
from app.core.recording.stream import RecordingStream
from app.core.safe_output import OutputRefused, check_output, write_error_message
from app.core.scoring import DEFAULT_SKIP_S, error_statistics, scoring_rows

MAX_BLOCK = 1_000_000
"""The largest ``block`` (a block is held in memory whole)."""
WHOLE_FILE_OFFLINE_BYTES = 64 << 20
"""From this size on, ``all`` filters leave the offline smoothers out (memory)."""


class ReplayRefused(ValueError):
    """Input the replay cannot use (a bad recording, filter, parameter or target)."""


class ReplayFailed(RuntimeError):
    """The replay ran but its file could not be written, or the recording broke off."""


@dataclass(frozen=True, slots=True)
class FilterLine:
    """One filter's result: final angles (degrees); errors: ``rmse_deg``, ``max_deg`` (and
    ``heading_rmse_deg``, ``total_rmse_deg``: NaN without a magnetometer) when the recording
    has a reference orientation, else None. ``magnetic``: the filter took its heading from the
    magnetometer (its quaternion's earth frame is ENU, y toward magnetic north)."""

    name: str
    final_roll_deg: float
    final_pitch_deg: float
    errors: dict[str, Any] | None
    magnetic: bool = False


@dataclass(slots=True)
class ReplaySummary:
    """What a replay wrote and found, whichever path it took."""

    target: Path
    rows: int
    duration_s: float
    calibration_name: str | None
    """The calibration applied (None: the raw samples)."""
    masked: bool
    """The scored rows are those the recording's ``movement`` column marks."""
    scored_rows: int | None
    """Rows with a reference that were scored; None without a reference."""
    filters: list[FilterLine] = field(default_factory=list)
    streamed: bool = False
    fault_events: list[FaultEvent] = field(default_factory=list)
    """The fault detector's events over the recording, as ``diagnose`` finds them."""


@dataclass(frozen=True, slots=True)
class ReplayRequest:
    """A replay: the recording, the filters (None: the recorded one; ``all``), the target."""

    source: Path
    target: Path
    filters: list[str] | None = None
    parameters: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Per filter, values that change the recorded (else default) parameters."""
    raw: bool = False
    block: int | None = None
    overwrite: bool = False


Say = Callable[[str], None]


def _quiet(_: str) -> None:
    """Drop a line (the default for ``warn`` and ``note``)."""


def replay_recording(request: ReplayRequest, warn: Say = _quiet, note: Say = _quiet
                     ) -> ReplaySummary:
    """Run the filters over the recording and write the angles file.

    ``warn`` gets each warning the recording raises (a damaged row skipped...), ``note`` a line
    for the user (filters ``all`` leaves out). Raises :class:`ReplayRefused` for input it
    cannot use and :class:`ReplayFailed` when the file could not be written.
    """
    summary = _replay(request, warn, note)
    summary.fault_events = replay_fault_events(request.source)
    return summary


def replay_fault_events(source: Path) -> list[FaultEvent]:
    """The fault detector over the recording, streamed (memory does not grow with the file),
    as live and ``diagnose`` run it (issue 33: a replay warns of the same faults)."""
    try:
        return _fault_events(source)
    except RecordingError:  # a row the replay skipped with a warning: no verdict past it
        return []


def _fault_events(source: Path) -> list[FaultEvent]:
    from app.core.faults import FaultDetector, SensorSpec
    from app.core.faults.recording import recorded_field_calibration
    from app.core.recording.format import KEY_MAGNETOMETER
    from app.core.recording.stream import device_blocks
    from app.core.sample_checks import implausible_rows
    from app.core.samples import convert_raw_block

    events: list[FaultEvent] = []
    detector: FaultDetector | None = None
    with warnings.catch_warnings(), RecordingStream(source) as stream:
        warnings.simplefilter("ignore")  # the replay itself has told of damaged rows
        device = stream.metadata.get("device")
        device = device if isinstance(device, dict) else {}
        magnetometer = stream.metadata.get(KEY_MAGNETOMETER)
        size = None if "block_start" in stream.header else 256
        for raw in device_blocks(stream.chunks(), size):
            if detector is None:
                if len(raw) < 2 or not raw.t_s[-1] > raw.t_s[0]:
                    continue
                rate = (len(raw) - 1) / float(raw.t_s[-1] - raw.t_s[0])
                detector = FaultDetector(SensorSpec.from_device_dict(device, rate)
                                         .with_magnetometer(magnetometer
                                                            if isinstance(magnetometer, dict)
                                                            else None))
                detector.field_calibration = recorded_field_calibration(magnetometer)
            block = convert_raw_block(raw)
            if implausible_rows(block.accel_m_s2, block.gyro_rad_s).any():
                break  # NaN or absurd samples: diagnose names them; no statistics past them
            counts = np.issubdtype(np.asarray(raw.accel_raw).dtype, np.integer)
            events += detector.update(block, raw if counts else None)
    return events


def _replay(request: ReplayRequest, warn: Say, note: Say) -> ReplaySummary:
    if request.block is not None and not 1 <= request.block <= MAX_BLOCK:
        raise ReplayRefused(f"--block must be from 1 to {MAX_BLOCK}")
    try:
        with _warnings_to(warn):
            head = RecordingStream(request.source)
    except RecordingError as exc:
        raise ReplayRefused(str(exc)) from None
    with head:
        if not request.raw:
            _check_calibration(head.metadata, request.source)
        names = _chosen_filters(request, Recording(head.metadata, head.header, {}),
                                head.file_size(), note)
        if "all" not in names and all(n in FILTERS and not FILTERS[n].offline for n in names):
            return _replay_streamed(request, head, list(dict.fromkeys(names)), warn)
    return _replay_whole(request, names, warn)


def _chosen_filters(request: ReplayRequest, head: Recording, size: int, note: Say
                    ) -> list[str]:
    has_field = all(column in head.header for column in MAG_COLUMNS)
    names = request.filters or [head.filter_name or default_filter_for(has_field)]
    if "all" in names and size >= WHOLE_FILE_OFFLINE_BYTES:
        left_out = [n for n in FILTERS if FILTERS[n].offline]
        names = [n for n in dict.fromkeys([*FILTERS, *names]) if n != "all"
                 and (n not in left_out or n in names)]
        note(f"'all' leaves out {', '.join(left_out)} on a recording this long: offline "
             "smoothers hold the whole session in memory (name them with --filter to run "
             "them anyway)")
    return names


def _replay_streamed(request: ReplayRequest, stream: RecordingStream, names: list[str],
                     warn: Say) -> ReplaySummary:
    """Online filters in one streamed pass: memory does not grow with the file."""
    head = Recording(stream.metadata, stream.header, {})
    parameters = _parameters(request, head, names)
    _check_target(request)
    try:
        with _warnings_to(warn, always=True):
            summary = replay_streamed(stream, names, request.target,
                                      calibration=None if request.raw else "recorded",
                                      parameters=parameters, block=request.block,
                                      overwrite=request.overwrite, option="--out")
    except (RecordingError, ValueError) as exc:
        raise ReplayFailed(str(exc)) from None
    except OSError as exc:  # a full disk: the temporary file is gone, the target untouched
        raise ReplayFailed(write_error_message(exc, request.target, "--out")) from None
    calibration = None if request.raw else head.calibration
    has_field = all(column in stream.header for column in MAG_COLUMNS)
    lines = [FilterLine(f.name, f.final_roll_deg, f.final_pitch_deg,
                        f.errors.result() if summary.reference else None,
                        magnetic_heading(FILTERS[f.name], f.parameters, has_field))
             for f in summary.filters]
    return ReplaySummary(request.target, summary.rows, summary.duration_s,
                         None if calibration is None else calibration.name, summary.masked,
                         summary.scored_rows if summary.reference else None, lines,
                         streamed=True)


def _replay_whole(request: ReplayRequest, names: list[str], warn: Say) -> ReplaySummary:
    """The whole recording in memory: offline smoothers, or ``all`` filters."""
    try:
        with _warnings_to(warn):
            recording = read_recording(request.source)
    except RecordingError as exc:
        raise ReplayRefused(str(exc)) from None
    if "all" in names:
        names = list(FILTERS)
    unknown = [n for n in names if n not in FILTERS]
    if unknown:
        raise ReplayRefused(f"no filter {unknown[0]!r}; choose from {', '.join(FILTERS)} "
                            "(or 'all')")
    names = list(dict.fromkeys(names))
    parameters = _parameters(request, recording, names)
    try:
        score_mask = recording_score_mask(recording)
    except ValueError as exc:
        raise ReplayRefused(str(exc)) from None
    _check_target(request)
    calibration = None if request.raw else resolve_calibration(recording, "recorded")
    outputs = run_filters(recording, names, calibration=calibration, parameters=parameters,
                          block=request.block)
    try:
        write_angles_csv(request.target, recording, outputs, calibration=calibration,
                         overwrite=request.overwrite, option="--out")
    except OSError as exc:  # OutputRefused (a file that came meanwhile), a full disk
        raise ReplayFailed(write_error_message(exc, request.target, "--out")) from None
    reference = recording.reference_quat
    has_field = recording.mag_ut is not None
    lines = [FilterLine(output.name, output.roll_deg[-1], output.pitch_deg[-1],
                        None if reference is None else error_statistics(
                            output.quat, reference, recording.t_s, DEFAULT_SKIP_S, score_mask,
                            heading=has_field),
                        magnetic_heading(FILTERS[output.name], output.parameters, has_field))
             for output in outputs]
    scored = None if reference is None else int(
        scoring_rows(reference, recording.t_s, DEFAULT_SKIP_S, score_mask).sum())
    return ReplaySummary(request.target, len(recording), recording.duration_s,
                         None if calibration is None else calibration.name,
                         score_mask is not None, scored, lines)


def _check_calibration(metadata: dict[str, Any], path: Path) -> None:
    problem = recorded_calibration_problem(metadata)
    if problem is not None:
        raise ReplayRefused(f"{path}: the recorded calibration is invalid ({problem}); give "
                            "--raw to use the samples uncalibrated")


def _parameters(request: ReplayRequest, recording: Recording, names: list[str]
                ) -> dict[str, dict[str, Any]]:
    """Each filter's parameters: the recorded (else default) ones, changed by the request's;
    ReplayRefused when the request names a filter that is not run."""
    for name in request.parameters:
        if name not in names:
            raise ReplayRefused(f"--param {name}.NAME=...: the filter {name!r} is not among "
                                f"those run ({', '.join(names)}); add it with --filter")
    recorded = recorded_filter_parameters(recording)
    return {name: {**recorded.get(name, {}), **request.parameters.get(name, {})}
            for name in names}


def _check_target(request: ReplayRequest) -> None:
    """ReplayRefused when the target would overwrite the recording itself (the same file, a
    hard link too) or, without ``overwrite``, any existing file."""
    try:
        check_output(request.target, inputs=[request.source], overwrite=request.overwrite,
                     option="--out", input_name="recording")
    except OutputRefused as exc:
        raise ReplayRefused(str(exc)) from None


@contextmanager
def _warnings_to(warn: Say, always: bool = False) -> Iterator[None]:
    """Pass every warning raised inside to ``warn``, in order, after the block: when it
    raised too, only if ``always`` (a file that cannot be read gets its one error line)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        failed = True
        try:
            yield
            failed = False
        finally:
            if always or not failed:
                for warning in caught:
                    warn(str(warning.message))
