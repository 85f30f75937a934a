"""Alarm crossings in a recording: the ``alarm_events`` and ``alarms`` metadata keys
(docs/recording-format.md), written when the file is closed as fault events are."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from typing import Any

from app.core.alarms.limits import AlarmConfig
from app.core.alarms.monitor import AlarmEvent

KEY_ALARM_EVENTS = "alarm_events"
KEY_ALARMS = "alarms"


def alarm_events_metadata(events: Iterable[AlarmEvent],
                          config: AlarmConfig | None = None) -> dict[str, Any]:
    """The metadata entries that store a recording's crossings (and the alarms in force)."""
    entries: dict[str, Any] = {
        KEY_ALARM_EVENTS: [e.as_dict() for e in sorted(events, key=lambda e: e.t)]
    }
    if config is not None:
        entries[KEY_ALARMS] = [limit.spec() for limit in config.enabled]
    return entries


def save_alarm_events(path: str | os.PathLike[str], events: Iterable[AlarmEvent],
                      config: AlarmConfig | None = None) -> None:
    """Store the crossings into a finished recording (as fault events are stored)."""
    from app.core.recording.edit import rewrite_metadata

    rewrite_metadata(path, alarm_events_metadata(events, config))


def recorded_alarm_events(metadata: Mapping[str, Any]) -> list[AlarmEvent]:
    """The crossings a recording's metadata holds (none when absent; malformed ones skipped)."""
    from app.core.recording.format import metadata_entries

    return metadata_entries(metadata, KEY_ALARM_EVENTS, AlarmEvent.from_dict)
