"""The sensor's health while streaming: the fault detector on the live samples (no Qt).

:class:`HealthMonitor` runs :class:`~app.core.faults.FaultDetector` on every block as the
device delivered it (SI, before calibration: the detector judges the sensor, not the
calibration), keeps the events a recording is collecting, and stores them into the finished
file's ``fault_events`` metadata (docs/recording-format.md) so a replay shows them.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from app.core.devices import DeviceInfo
from app.core.faults import FaultDetector, FaultEvent, SensorSpec
from app.core.faults.recording import KEY_FAULT_EVENTS, recorded_fault_events
from app.core.samples import RawBlock, SampleBlock, ScaleFactors, convert_raw_block

OK_STATE = "ok"


class HealthMonitor:
    """The detector for the connected device, and the events of the recording under way."""

    def __init__(self) -> None:
        self.detector: FaultDetector | None = None
        self._recording: list[FaultEvent] | None = None

    def start(self, info: DeviceInfo, scale: ScaleFactors | None = None) -> None:
        """A new device: a fresh detector that knows its sensor settings (and its raw
        scale factors, when known)."""
        self.detector = FaultDetector(SensorSpec.from_device_info(info, scale))

    def stop(self) -> None:
        self.detector = None

    def reset(self) -> None:
        """Forget what was learnt and every latched fault (the user's reset)."""
        if self.detector is not None:
            self.detector.reset()

    def update(self, raw: RawBlock, samples: SampleBlock | None = None) -> list[FaultEvent]:
        """The events declared in this block (``raw`` as the device delivered it; ``samples``
        the same in SI units before calibration, when already converted)."""
        if self.detector is None or not len(raw):
            return []
        counts = np.issubdtype(np.asarray(raw.accel_raw).dtype, np.integer)
        samples = convert_raw_block(raw) if samples is None else samples
        events = self.detector.update(samples, raw if counts else None)
        if self._recording is not None:
            self._recording.extend(events)
        return events

    def health(self) -> dict[str, str] | None:
        """``ok``/``warning``/``fault`` per channel (ax..gz, accel, gyro, link); None without a
        device."""
        return None if self.detector is None else self.detector.health()

    def latest_fault(self) -> FaultEvent | None:
        """The newest event of severity ``fault`` (the banner's reason)."""
        if self.detector is None:
            return None
        return next((e for e in reversed(self.detector.events) if e.severity == "fault"), None)

    # -- recording --------------------------------------------------------------------------
    def begin_recording(self) -> None:
        self._recording = []

    def take_recording(self) -> list[FaultEvent]:
        """The events since :meth:`begin_recording` (and stop collecting)."""
        events, self._recording = self._recording or [], None
        return events

    def end_recording(self, path: Path | None, on_error: Callable[[str], None],
                      also: Mapping[str, Any] | None = None) -> int:
        """Store the recording's events into ``path``, with the metadata entries ``also``
        (e.g. the alarms' crossings) in the same rewrite, in a thread: the whole file is
        rewritten, which takes a while for a long one. Returns how many fault events there are.
        """
        events = self.take_recording()
        changes = dict(also or {})
        if events:
            changes[KEY_FAULT_EVENTS] = [e.as_dict() for e in sorted(events, key=lambda e: e.t)]
        if path is None or not changes:
            return 0

        def save() -> None:
            from app.core.recording.closing import store_closing_metadata

            what = f"the {len(events)} fault events" if events else "the closing metadata"
            problem = store_closing_metadata(path, changes, what)  # else beside the file
            if problem:
                on_error(problem)

        threading.Thread(target=save, name="save-fault-events", daemon=True).start()
        return len(events)


def fault_line(event: FaultEvent) -> str:
    """One line for the user: ``sensor gz stuck (fault) at 2.01 s: ...``."""
    return (f"sensor {event.channel} {event.kind} ({event.severity}) at {event.t:.2f} s: "
            f"{event.message}")


def recorded_events_note(metadata: dict) -> str:
    """A replay's note on the fault events its recording holds ("" when none)."""
    events = recorded_fault_events(metadata)
    if not events:
        return ""
    kinds = sorted({f"{e.channel} {e.kind}" for e in events})
    shown = ", ".join(kinds[:6]) + (f" and {len(kinds) - 6} more" if len(kinds) > 6 else "")
    return (f"This recording holds {len(events)} fault event(s) found while recording "
            f"({shown}); the detector finds them again as the replay runs.")
