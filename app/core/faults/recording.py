"""Fault events in a recording: the ``fault_events`` metadata key (docs/recording-format.md).

The worker collects the detector's events while recording and calls :func:`save_fault_events`
once the file is closed (as bookmarks are saved); a replay reads them back with
:func:`recorded_fault_events`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from typing import Any

from app.core.calibration import MagnetometerCalibration
from app.core.faults.events import FaultEvent

KEY_FAULT_EVENTS = "fault_events"


def save_fault_events(path: str | os.PathLike[str], events: Iterable[FaultEvent],
                      extra: Mapping[str, Any] | None = None) -> None:
    """Store ``events`` as the finished recording's ``fault_events`` (replacing earlier ones;
    none: the key is left as it is), and the ``extra`` keys, in one rewrite of the file."""
    from app.core.recording.edit import rewrite_metadata

    entries = [e.as_dict() for e in sorted(events, key=lambda e: e.t)]
    changes = dict(extra or {})
    if entries:
        changes[KEY_FAULT_EVENTS] = entries
    rewrite_metadata(path, changes)


def recorded_fault_events(metadata: Mapping[str, Any]) -> list[FaultEvent]:
    """The events a recording's metadata holds (none when the key is absent or malformed)."""
    from app.core.recording.format import metadata_entries

    return metadata_entries(metadata, KEY_FAULT_EVENTS, FaultEvent.from_dict)


def recorded_field_calibration(magnetometer: Any) -> MagnetometerCalibration | None:
    """The magnetometer calibration a recording's ``magnetometer`` metadata holds (applied
    while it was recorded), for the fault detector's gyro bias test; None when there is none
    or it is malformed (the test then uses gravity alone)."""
    value = magnetometer.get("calibration") if isinstance(magnetometer, Mapping) else None
    if value is None:
        return None
    try:
        return MagnetometerCalibration.from_json(value)
    except (TypeError, ValueError, KeyError):
        return None
