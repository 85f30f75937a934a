"""Run filters over a recording exactly as the live pipeline did, and export their angles.

:func:`run_filters` applies the same stages as :meth:`app.core.pipeline.Pipeline.process`
(``convert_raw_block``, then the calibration, then ``filter.process`` per block), on the blocks
the device delivered while recording (the ``block_start`` column), with the recorded filter
parameters: the same filter then gives the same angles, bit for bit, as it gave live.
An offline filter (``offline``: a smoother, which needs the whole recording) gets every sample
in a single ``process`` call instead.

:func:`write_angles_csv` writes them: ``t``, then per filter ``NAME.roll``, ``NAME.pitch``,
``NAME.tilt``, ``NAME.direction`` (degrees) and ``NAME.qw`` ... ``NAME.qz``; with a reference,
``reference.roll`` ... ``reference.direction`` and ``NAME.inclination_error`` (degrees); with
a reference and a magnetometer also ``NAME.heading_error`` and ``NAME.total_error`` (degrees,
BROAD's split: :mod:`app.core.heading_metrics`). It starts with ``# inclinometer-angles 1``
and ``# key: <JSON>`` lines like a recording.

The quaternions are sensor-to-earth. A 9-axis filter's (one that took heading from the
magnetometer: ``earth_frame`` in its entry of the ``filters`` metadata) earth frame is ENU, y
toward magnetic north, the frame of a recording's reference ``qw..qz``; a 6-axis filter's is
z up with an arbitrary heading.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from app.core.calibration import SensorCalibration
from app.core.filters import FILTERS, create_filter, known_parameters
from app.core.heading_metrics import heading_error_deg, total_error_deg
from app.core.orientation import angles_from_quaternion, inclination_error_deg
from app.core.recording.format import (
    KEY_COMPARISONS,
    KEY_FILTER,
    MAG_COLUMNS,
    REFERENCE_COLUMNS,
    calibration_to_json,
    metadata_line,
    utc_timestamp,
)
from app.core.recording.reader import Recording
from app.core.recording.stream import RecordingStream, device_blocks, prefetched
from app.core.recording.writer import format_table_bytes
from app.core.safe_output import output_file
from app.core.samples import SampleBlock, convert_raw_block
from app.core.scoring import DEFAULT_SKIP_S, SCORE_COLUMN, ErrorAccumulator

ANGLES_MAGIC = "# inclinometer-angles 1"
ANGLE_NAMES = ("roll", "pitch", "tilt", "direction")
QUATERNION_NAMES = ("qw", "qx", "qy", "qz")
EXPORT_ROWS = 65536
"""Rows formatted and written at a time."""
EXPORT_CELLS = 500_000
"""A streamed replay writes when this many numbers wait (about 10 MB of text)."""

CalibrationChoice = SensorCalibration | None | Literal["recorded"]


@dataclass(slots=True)
class FilterOutput:
    """One filter's orientation over a recording (angles in degrees)."""

    name: str
    title: str
    parameters: dict[str, Any]
    quat: np.ndarray
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    tilt_deg: np.ndarray
    direction_deg: np.ndarray


def recorded_filter_parameters(recording: Recording) -> dict[str, dict[str, Any]]:
    """Filter name -> parameter values, for the main and the comparison filters recorded."""
    found: dict[str, dict[str, Any]] = {}
    entries = [recording.metadata.get(KEY_FILTER), *(recording.metadata.get(KEY_COMPARISONS)
                                                      or [])]
    for entry in reversed(entries):  # the main filter wins
        if isinstance(entry, dict) and isinstance(entry.get("name"), str):
            params = entry.get("parameters")
            params = dict(params) if isinstance(params, dict) else {}
            if entry["name"] in FILTERS:  # parameters an older version had are left out
                params = known_parameters(entry["name"], params)[0]
            found[entry["name"]] = params
    return found


def resolve_calibration(recording: Recording, choice: CalibrationChoice) -> SensorCalibration:
    """``"recorded"``: the recording's calibration (identity when it has none)."""
    if choice == "recorded":
        return recording.calibration or SensorCalibration()
    return choice or SensorCalibration()


def run_filters(
    recording: Recording,
    filters: Sequence[str],
    *,
    calibration: CalibrationChoice = "recorded",
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
    block: int | None = None,
) -> list[FilterOutput]:
    """Each filter's orientation over the whole recording.

    Parameters
    ----------
    filters : registry names (:data:`app.core.filters.FILTERS`).
    calibration : ``"recorded"`` (default), a calibration, or None for none.
    parameters : name -> parameter values; default: those recorded for that filter, else the
        filter's defaults.
    block : None: the recorded device blocks (exact replay); else blocks of this many samples
        (faster for tiny recorded blocks; partition-sensitive filters such as VQF then differ
        from the live run in the last bits). Offline filters (``offline`` True) ignore it:
        they get the whole recording in one ``process`` call.
    """
    cal = resolve_calibration(recording, calibration)
    recorded = recorded_filter_parameters(recording)
    chosen = dict(parameters or {})
    objects = [create_filter(name, **dict(chosen.get(name, recorded.get(name, {}))))
               for name in filters]
    n = len(recording)
    quats = [np.empty((n, 4)) for _ in objects]
    angles = [{key: np.empty(n) for key in ANGLE_NAMES} for _ in objects]
    offline = [k for k, f in enumerate(objects) if type(f).offline]
    online = [k for k in range(len(objects)) if k not in offline]

    def keep(k: int, row: int, output: Any) -> None:
        stop = row + len(output.quat)
        quats[k][row:stop] = output.quat
        angles[k]["roll"][row:stop] = output.angles.roll_deg
        angles[k]["pitch"][row:stop] = output.angles.pitch_deg
        angles[k]["tilt"][row:stop] = output.angles.tilt_deg
        angles[k]["direction"][row:stop] = output.angles.direction_deg

    row = 0
    if online:
        for raw in recording.raw_blocks(block):
            samples = cal.apply(convert_raw_block(raw))
            for k in online:
                keep(k, row, objects[k].process(samples))
            row += len(samples)
    if offline and n:
        whole = cal.apply(convert_raw_block(recording.raw_block()))
        for k in offline:
            keep(k, 0, objects[k].process(whole))
    return [
        FilterOutput(f.name, f.title or f.name, f.parameter_values(), quats[k],
                     angles[k]["roll"], angles[k]["pitch"], angles[k]["tilt"],
                     angles[k]["direction"])
        for k, f in enumerate(objects)
    ]


def write_angles_csv(
    path: str | os.PathLike[str],
    recording: Recording,
    outputs: Sequence[FilterOutput],
    *,
    calibration: SensorCalibration | None = None,
    overwrite: bool = True,
    option: str = "",
) -> int:
    """Write the filters' angles (see the module docstring); returns the rows written.

    Written through :func:`~app.core.safe_output.output_file`: atomically, never over the
    recording itself, over an existing file only with ``overwrite`` (OutputRefused).
    """
    path = Path(path)
    reference = recording.reference_quat
    names: list[str] = ["t"]
    columns: list[np.ndarray] = [recording.t_s]
    for output in outputs:
        names += [f"{output.name}.{a}" for a in ANGLE_NAMES]
        names += [f"{output.name}.{q}" for q in QUATERNION_NAMES]
        columns += [output.roll_deg, output.pitch_deg, output.tilt_deg, output.direction_deg]
        columns += [output.quat[:, k] for k in range(4)]
    if reference is not None:
        ref_angles = angles_from_quaternion(reference)
        names += [f"reference.{a}" for a in ANGLE_NAMES]
        columns += [ref_angles.roll_deg, ref_angles.pitch_deg, ref_angles.tilt_deg,
                    ref_angles.direction_deg]
        for output in outputs:
            names.append(f"{output.name}.inclination_error")
            columns.append(inclination_error_deg(output.quat, reference))
        if recording.mag_ut is not None:
            for output in outputs:
                names += [f"{output.name}.heading_error", f"{output.name}.total_error"]
                columns += [heading_error_deg(output.quat, reference),
                            total_error_deg(output.quat, reference)]
    metadata = _angles_metadata(recording, outputs, calibration)
    head = [ANGLES_MAGIC, *(metadata_line(k, v) for k, v in metadata.items()), ",".join(names)]
    n = len(recording)
    with output_file(path, inputs=[recording.path], overwrite=overwrite, option=option) as out:
        out.write(("\n".join(head) + "\n").encode("utf-8"))
        for start in range(0, n, EXPORT_ROWS):
            out.write(format_table_bytes([c[start:start + EXPORT_ROWS] for c in columns]))
    return n


@dataclass(slots=True)
class StreamedFilter:
    """One filter's result over a streamed replay: its last angles and its error figures."""

    name: str
    title: str
    parameters: dict[str, Any]
    final_roll_deg: float = math.nan
    final_pitch_deg: float = math.nan
    errors: ErrorAccumulator = field(default_factory=ErrorAccumulator)


@dataclass(slots=True)
class StreamedReplay:
    """What :func:`replay_streamed` did: rows, span, which rows were scored, each filter."""

    rows: int
    first_t_s: float
    last_t_s: float
    reference: bool
    """The recording has reference columns (the angles file then has reference columns)."""
    masked: bool
    """A ``movement`` column chose the scored rows (else: after the first ``skip_s``)."""
    scored_rows: int
    filters: list[StreamedFilter]

    @property
    def duration_s(self) -> float:
        return self.last_t_s - self.first_t_s if self.rows > 1 else 0.0


def replay_streamed(
    stream: RecordingStream,
    filters: Sequence[str],
    out_path: str | os.PathLike[str],
    *,
    calibration: CalibrationChoice = "recorded",
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
    block: int | None = None,
    skip_s: float = DEFAULT_SKIP_S,
    overwrite: bool = True,
    option: str = "",
) -> StreamedReplay:
    """:func:`run_filters` and :func:`write_angles_csv` in one pass over a streamed recording.

    Memory does not grow with the recording: rows are read in chunks, run through the online
    filters block by block as the device delivered them (or in blocks of ``block``), and
    written ``EXPORT_ROWS`` at a time. The inclination error is scored as ``replay`` prints it
    (:class:`~app.core.scoring.ErrorAccumulator`). Offline filters need the whole
    recording: run them with :func:`run_filters` (ValueError here).
    """
    head = Recording(metadata=stream.metadata, header=stream.header, columns={},
                     path=stream.path)
    cal = resolve_calibration(head, calibration)
    objects = _online_filters(head, filters, parameters)
    results = [StreamedFilter(f.name, f.title or f.name, f.parameter_values()) for f in objects]
    reference = all(name in stream.header for name in REFERENCE_COLUMNS)
    split = reference and all(name in stream.header for name in MAG_COLUMNS)
    for result in results:
        result.errors.heading = split
    masked = SCORE_COLUMN in stream.header
    names = _angle_columns([r.name for r in results], reference, split)
    metadata = _angles_metadata(head, results, calibration=cal if calibration is not None
                                else None)
    summary = StreamedReplay(0, math.nan, math.nan, reference, masked, 0, results)
    pending: list[list[np.ndarray]] = []
    pending_rows = 0
    t0: float | None = None
    path = Path(out_path)
    with output_file(path, inputs=[stream.path], overwrite=overwrite, option=option) as out:
        head_lines = [ANGLES_MAGIC, *(metadata_line(k, v) for k, v in metadata.items()),
                      ",".join(names)]
        out.write(("\n".join(head_lines) + "\n").encode("utf-8"))
        for samples, outputs, extra in _filtered(stream, objects, cal, block, (SCORE_COLUMN,)):
            n = len(samples)
            if t0 is None:
                t0 = float(samples.t_s[0])
                summary.first_t_s = t0
            summary.last_t_s = float(samples.t_s[-1])
            summary.rows += n
            columns: list[np.ndarray] = [samples.t_s]
            ref = samples.reference_quat if reference else None
            if ref is not None:
                movement = extra.get(SCORE_COLUMN)
                if movement is not None and movement.dtype == object:
                    raise ValueError(f"{stream.path}: the {SCORE_COLUMN!r} column holds text; it "
                                     "must be a flag (1 = score this row, 0 or empty = do not)")
                scored = (np.asarray(movement) == 1.0 if masked and movement is not None
                          else samples.t_s >= t0 + skip_s)
                scored &= np.all(np.isfinite(ref), axis=1)
                summary.scored_rows += int(np.count_nonzero(scored))
            for result, output in zip(results, outputs, strict=True):
                angles = output.angles
                columns += [angles.roll_deg, angles.pitch_deg, angles.tilt_deg,
                            angles.direction_deg, *output.quat.T]
                result.final_roll_deg = float(angles.roll_deg[-1])
                result.final_pitch_deg = float(angles.pitch_deg[-1])
                if ref is not None:
                    result.errors.add(output.quat, ref, scored)
            if ref is not None:
                ref_angles = angles_from_quaternion(ref)
                columns += [ref_angles.roll_deg, ref_angles.pitch_deg, ref_angles.tilt_deg,
                            ref_angles.direction_deg]
                columns += [inclination_error_deg(o.quat, ref) for o in outputs]
                if split:
                    for o in outputs:
                        columns += [heading_error_deg(o.quat, ref), total_error_deg(o.quat, ref)]
            pending.append(columns)
            pending_rows += n
            if pending_rows * len(columns) >= EXPORT_CELLS:
                _write_pending(out, pending)
                pending, pending_rows = [], 0
        _write_pending(out, pending)
    return summary


def _online_filters(head: Recording, filters: Sequence[str],
                    parameters: Mapping[str, Mapping[str, Any]] | None) -> list[Any]:
    """The filters, made with the chosen (else recorded, else default) parameters;
    ValueError for an offline one (it needs the whole recording: :func:`run_filters`)."""
    offline = [name for name in filters if FILTERS[name].offline]
    if offline:
        raise ValueError(f"{offline[0]} is an offline filter: it needs the whole recording")
    recorded = recorded_filter_parameters(head)
    chosen = dict(parameters or {})
    return [create_filter(name, **dict(chosen.get(name, recorded.get(name, {}))))
            for name in filters]


def _filtered(stream: RecordingStream, objects: Sequence[Any], cal: SensorCalibration,
              block: int | None, extra: tuple[str, ...] = ()
              ) -> Iterator[tuple[SampleBlock, list[Any], dict[str, np.ndarray]]]:
    """The pipeline's stages over a streamed recording, block by block as the device delivered
    them (or ``block`` rows): the calibrated samples, each filter's output, the ``extra``
    columns."""
    chunks = prefetched(stream.chunks())  # the next chunk parses while this one runs
    for raw, columns in device_blocks(chunks, block, extra=extra):
        samples = cal.apply(convert_raw_block(raw))
        yield samples, [f.process(samples) for f in objects], columns


def filtered_blocks(
    stream: RecordingStream,
    filters: Sequence[str],
    *,
    calibration: CalibrationChoice = "recorded",
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
    block: int | None = None,
) -> Iterator[tuple[SampleBlock, list[Any]]]:
    """What :func:`replay_streamed` runs, for other writers (an export): per device block,
    the calibrated samples and each online filter's output (``quat``, ``angles``), in one
    streamed pass. ValueError for an offline filter."""
    head = Recording(metadata=stream.metadata, header=stream.header, columns={},
                     path=stream.path)
    cal = resolve_calibration(head, calibration)
    objects = _online_filters(head, filters, parameters)
    for samples, outputs, _ in _filtered(stream, objects, cal, block):
        yield samples, outputs


def _write_pending(out: Any, pending: list[list[np.ndarray]]) -> None:
    if pending:
        joined = [np.concatenate(parts) for parts in zip(*pending, strict=True)]
        out.write(format_table_bytes(joined))


def _angle_columns(filters: Sequence[str], reference: bool, split: bool = False) -> list[str]:
    names = ["t"]
    for name in filters:
        names += [f"{name}.{a}" for a in ANGLE_NAMES] + [f"{name}.{q}" for q in
                                                         QUATERNION_NAMES]
    if reference:
        names += [f"reference.{a}" for a in ANGLE_NAMES]
        names += [f"{name}.inclination_error" for name in filters]
        if split:
            for name in filters:
                names += [f"{name}.heading_error", f"{name}.total_error"]
    return names


NINE_AXIS_FRAME = "ENU, y toward magnetic north (x east, z up)"
SIX_AXIS_FRAME = "z up, heading arbitrary (no magnetometer)"


def _earth_frame(name: str, parameters: Mapping[str, Any], recording: Recording) -> str:
    """The earth frame of filter ``name``'s quaternions on this recording."""
    cls = FILTERS.get(name)
    has_field = all(c in recording.header for c in MAG_COLUMNS)
    nine = (cls is not None and cls.uses_magnetometer and has_field
            and bool(parameters.get("magnetometer", False)))
    return NINE_AXIS_FRAME if nine else SIX_AXIS_FRAME


def _angles_metadata(recording: Recording, outputs: Sequence[Any],
                     calibration: SensorCalibration | None) -> dict[str, Any]:
    return {
        "source": str(recording.path) if recording.path is not None else None,
        "source_start_time": recording.metadata.get("start_time"),
        "exported": utc_timestamp(),
        "filters": [{"name": o.name, "title": o.title, "parameters": o.parameters,
                     "earth_frame": _earth_frame(o.name, o.parameters, recording)}
                    for o in outputs],
        "calibration": calibration_to_json(calibration) if calibration is not None else None,
        "units": {"t": "s", "angles": "deg", "quaternions": "1 (w, x, y, z), sensor-to-earth"},
    }
