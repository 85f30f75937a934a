"""Run filters over a recording exactly as the live pipeline did, and export their angles.

:func:`run_filters` applies the same stages as :meth:`app.core.pipeline.Pipeline.process`
(``convert_raw_block``, then the calibration, then ``filter.process`` per block), on the blocks
the device delivered while recording (the ``block_start`` column), with the recorded filter
parameters: the same filter then gives the same angles, bit for bit, as it gave live.
An offline filter (``offline``: a smoother, which needs the whole recording) gets every sample
in a single ``process`` call instead.

:func:`write_angles_csv` writes them: ``t``, then per filter ``NAME.roll``, ``NAME.pitch``,
``NAME.tilt``, ``NAME.direction`` (degrees) and ``NAME.qw`` ... ``NAME.qz``; with a reference,
``reference.roll`` ... ``reference.direction`` and ``NAME.inclination_error`` (degrees). It
starts with ``# inclinometer-angles 1`` and ``# key: <JSON>`` lines like a recording.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from app.core.calibration import SensorCalibration
from app.core.filters import FILTERS, create_filter, known_parameters
from app.core.orientation import angles_from_quaternion, inclination_error_deg
from app.core.recording.format import (
    KEY_COMPARISONS,
    KEY_FILTER,
    calibration_to_json,
    metadata_line,
    utc_timestamp,
)
from app.core.recording.reader import Recording
from app.core.recording.writer import format_table
from app.core.samples import convert_raw_block

ANGLES_MAGIC = "# inclinometer-angles 1"
ANGLE_NAMES = ("roll", "pitch", "tilt", "direction")
QUATERNION_NAMES = ("qw", "qx", "qy", "qz")
EXPORT_ROWS = 65536
"""Rows formatted and written at a time."""

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
) -> int:
    """Write the filters' angles (see the module docstring); returns the rows written."""
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
    metadata = {
        "source": str(recording.path) if recording.path is not None else None,
        "source_start_time": recording.metadata.get("start_time"),
        "exported": utc_timestamp(),
        "filters": [{"name": o.name, "title": o.title, "parameters": o.parameters}
                    for o in outputs],
        "calibration": calibration_to_json(calibration) if calibration is not None else None,
        "units": {"t": "s", "angles": "deg", "quaternions": "1 (w, x, y, z), sensor-to-earth"},
    }
    head = [ANGLES_MAGIC, *(metadata_line(k, v) for k, v in metadata.items()), ",".join(names)]
    n = len(recording)
    with open(path, "w" if overwrite else "x", encoding="utf-8", newline="") as out:
        out.write("\n".join(head) + "\n")
        for start in range(0, n, EXPORT_ROWS):
            out.write(format_table([c[start:start + EXPORT_ROWS] for c in columns]))
    return n
