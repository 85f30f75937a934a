"""Replay controls (play, pause, step, seek, ...) and what a replay restores (no Qt).

A replay is a device of scheme ``replay`` (:class:`drivers.replay.ReplayDevice`); these
functions do nothing to other devices.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import PurePath
from typing import NamedTuple

from app.core.alarms import recorded_alarm_events
from app.core.devices import DeviceInfo
from app.core.filters import known_parameters
from app.core.filters.base import OrientationFilter
from app.core.pipeline import Pipeline
from app.core.recording.index import Overview
from drivers.base import Device

COMMANDS = ("play", "pause", "step", "speed", "loop", "seek", "next_gap", "next_bookmark",
            "add_bookmark")
SEEK_LEAD_IN_S = 10.0
"""A jump (seek, next gap, next bookmark) replays this much before the new position at once:
the filter converges on it, a paused replay shows the attitude there, and the plots (10 s
wide by default) are filled up to it."""


class ReplayCommandError(ValueError):
    """A replay command that cannot be carried out (no further gap, an unknown command...)."""


class ReplayNotice(ReplayCommandError):
    """A command with nothing to do (no further gap or bookmark): information, not an error."""


class ReplayState(NamedTuple):
    """Where a replay is, for the transport bar (sent with each stream status)."""

    position_s: float
    duration_s: float
    playing: bool
    """Playing and not at the end."""
    ended: bool = False
    """Every sample was delivered and the replay does not loop: Play starts it again."""
    bookmarks_s: tuple[float, ...] = ()
    """The bookmarks' positions, s from the start."""


def is_replay(device: Device | None) -> bool:
    """True for a recording played back as a device (its declared capability)."""
    return device is not None and device.replayable


def replay_position(device: Device | None) -> ReplayState | None:
    """Position, duration, playing, ended and bookmarks of a replay; None for any other
    device."""
    if not is_replay(device):
        return None
    replay = device  # a drivers.replay.ReplayDevice
    ended = bool(replay.at_end)  # type: ignore[union-attr]
    bookmarks = tuple(replay.bookmark_position_s(b)  # type: ignore[union-attr]
                      for b in replay.bookmarks)  # type: ignore[union-attr]
    return ReplayState(float(replay.position_s), float(replay.duration_s),  # type: ignore[union-attr]
                       bool(replay.playing) and not ended,  # type: ignore[union-attr]
                       ended, bookmarks)


def replay_caption(info: DeviceInfo) -> str:
    """"Replay of FILE" for a replayed recording's device info; "" for any other device."""
    replay = info.extra.get("replay") if isinstance(info.extra, dict) else None
    if not isinstance(replay, dict) or not replay.get("path"):
        return ""
    return f"Replay of {PurePath(str(replay['path'])).name}"


def replay_command(device: Device | None, pipeline: Pipeline, name: str, value: object) -> None:
    """Carry out one of :data:`COMMANDS` on a replay (ignored for other devices).

    ``speed`` 0 means as fast as possible; ``seek`` is in seconds from the start. A jump
    (seek, next gap, next bookmark) starts the views afresh, since time would run backwards,
    with :data:`SEEK_LEAD_IN_S` before the new position (delivered at once, also while
    paused: the views show the attitude there). ``play`` at the end starts from the beginning.
    Raises :class:`ReplayCommandError` (:class:`ReplayNotice` when there is nothing to do)
    and the driver's DeviceError or ValueError.
    """
    if not is_replay(device):
        return
    assert device is not None
    replay = device  # a drivers.replay.ReplayDevice
    if name == "play":
        if replay.at_end:  # type: ignore[attr-defined]
            pipeline.configure(replay.info.odr_hz)
            replay.seek(0.0)  # type: ignore[attr-defined]
        replay.play()
    elif name == "pause":
        replay.pause()
    elif name == "step":
        replay.step()
    elif name == "speed":
        replay.set_speed(value if value else "max")
    elif name == "loop":
        replay.loop = bool(value)
    elif name == "add_bookmark":
        replay.add_bookmark()
    elif name in ("seek", "next_gap", "next_bookmark"):
        target = _jump_target(replay, name, value)
        pipeline.configure(replay.info.odr_hz)
        replay.seek(target, SEEK_LEAD_IN_S)
    else:
        raise ReplayCommandError(f"unknown replay command {name!r} (known: "
                                 f"{', '.join(COMMANDS)})")


def _jump_target(replay: object, name: str, value: object) -> float:
    if name == "seek":
        return float(value)  # type: ignore[arg-type]
    position = replay.position_s  # type: ignore[attr-defined]
    if name == "next_bookmark":
        later = [replay.bookmark_position_s(b) for b in replay.bookmarks  # type: ignore[attr-defined]
                 if replay.bookmark_position_s(b) > position + 1e-9]  # type: ignore[attr-defined]
        if not later:
            raise ReplayNotice("No further bookmark in this recording.")
        return min(later)
    later = [p for p in replay.gap_positions_s if p > position + 1e-9]  # type: ignore[attr-defined]
    if not later:
        raise ReplayNotice("No further gap in this recording.")
    return later[0]


@dataclass(frozen=True, slots=True)
class RestoredFilter:
    """What :func:`restore_recorded_filter` did: the filter now running and what to tell."""

    orientation_filter: OrientationFilter | None
    """The recorded filter, now the pipeline's; None when nothing was restored."""
    warning: str = ""
    """Parameters from an older version that were ignored."""
    error: str = ""
    """Why the recorded filter could not be restored (the current one keeps running)."""


def restore_recorded_filter(device: Device | None, pipeline: Pipeline) -> RestoredFilter:
    """A replay runs the filter (and parameters) it was recorded with, to reproduce it."""
    recording = None if device is None else device.recording
    name = None if recording is None else recording.filter_name
    if not name or recording is None:
        return RestoredFilter(None)
    try:
        values, dropped = known_parameters(name, recording.filter_parameters)
        new_filter = pipeline.set_source_filter(name, **values)  # the source's, not a choice
    except (KeyError, ValueError) as exc:
        return RestoredFilter(None, error=f"The recording's filter cannot be restored ({exc}); "
                                          f"replaying with {pipeline.filter.title}")
    warning = (f"The recording's {name} parameters {', '.join(dropped)} are from an older "
               "version and are ignored") if dropped else ""
    return RestoredFilter(new_filter, warning=warning)


class OverviewTracker:
    """Hands out a replay's overview when it changed (the index grew or finished), else None."""

    def __init__(self) -> None:
        self._seen: tuple[int, int, bool] | None = None

    def reset(self) -> None:
        self._seen = None

    def changed(self, device: Device | None) -> tuple[Overview, tuple[float, ...]] | None:
        """(overview, gap positions in s) when new since the last call; None otherwise."""
        if not is_replay(device):
            return None
        overview = device.overview()  # type: ignore[union-attr]
        if overview is None:
            return None
        key = (id(device), overview.rows, overview.complete)
        if key == self._seen:
            return None
        self._seen = key
        return overview, tuple(device.gap_positions_s)  # type: ignore[union-attr]


def recorded_alarm_marks(device: Device | None) -> tuple[float, ...]:
    """Where the replayed recording's alarms were raised, s from its start (for the overview)."""
    if device is None or not is_replay(device):
        return ()
    metadata = {} if device.recording is None else device.recording.metadata
    start = device.start_t_s  # type: ignore[attr-defined]
    return tuple(e.t - start for e in recorded_alarm_events(metadata) if e.raised)


def recorded_alarms_note(metadata: dict) -> str:
    """A replay's note on the alarm crossings its recording holds ("" when none)."""
    events = recorded_alarm_events(metadata)
    if not events:
        return ""
    shown = "; ".join(e.message() for e in events[:8])
    more = f"; and {len(events) - 8} more" if len(events) > 8 else ""
    return (f"This recording holds {len(events)} alarm crossing(s) (marked on the replay "
            f"bar): {shown}{more}")
