"""Recording the live stream: start, write every raw block, stop (no Qt).

The raw stream is recorded before calibration, in format v1 (docs/recording-format.md), with
the metadata of the device, the calibration and the filters running at the start.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from app.core.calibration import SensorCalibration
from app.core.pipeline import Pipeline
from app.core.recording import RecordingWriter, WriterStatus, recording_metadata
from app.core.recording.format import simulator_metadata
from app.core.recording.sizing import data_rate
from app.core.safe_output import OutputLock
from app.core.samples import RawBlock
from drivers.base import Device


class RecordingControl:
    """At most one recording at a time.

    ``on_error`` gets the writer's error messages (from its thread), ``on_status`` its
    :class:`WriterStatus` after every flush.
    """

    def __init__(self, on_error: Callable[[str], None],
                 on_status: Callable[[WriterStatus], None]) -> None:
        self._on_error = on_error
        self._on_status = on_status
        self._writer: RecordingWriter | None = None

    @property
    def active(self) -> bool:
        return self._writer is not None

    def start(self, device: Device | None, pipeline: Pipeline | None, path: str,
              note: str, extra: dict | None = None, *, overwrite: bool = False,
              lock: OutputLock | None = None,
              on_flush: Callable[[WriterStatus], None] | None = None,
              calibration: SensorCalibration | None = None) -> WriterStatus:
        """Stop any recording, then record ``device``'s stream to ``path`` (``extra``: more
        metadata entries, such as the board's counters at the start or the alarms in force;
        a simulator's truth is added). ``calibration`` is noted when there is no pipeline.

        Raises ValueError when no device is connected and
        :class:`~app.core.recording.errors.RecordingError` when the file cannot be started.
        """
        if device is None or device.info is None:
            raise ValueError("Connect a device before recording.")
        self.stop()
        filters: dict[str, Any] = {} if pipeline is None else {
            "calibration": pipeline.calibration, "orientation_filter": pipeline.filter,
            "comparison_filters": list(pipeline.comparisons.values())}
        if pipeline is None and calibration is not None:
            filters["calibration"] = calibration
        metadata = recording_metadata(
            device=device.info, note=note, reference_source=device.reference_source,
            extra={**simulator_metadata(device), **(extra or {})}, **filters,
        )
        writer = RecordingWriter(path, metadata, overwrite=overwrite, on_error=self._on_error,
                                 on_flush=on_flush or self._on_status, lock=lock)
        writer.start()
        self._writer = writer
        return writer.status

    def write(self, raw: RawBlock) -> bool:
        """Queue a block for the file (nothing when not recording); False when the recording
        failed (a full disk: the writer said why through ``on_error``)."""
        if self._writer is None:
            return True
        return self._writer.write(raw) or self._writer.status.state != "failed"

    @property
    def error(self) -> str:
        """Why the recording under way failed ("" while it is fine)."""
        return "" if self._writer is None else self._writer.status.error or ""

    def stop(self) -> WriterStatus | None:
        """Finish the recording (everything queued is written and synced); None if none."""
        writer, self._writer = self._writer, None
        return None if writer is None else writer.close()


def recording_cost(folder: str | Path, odr_hz: float, *, reference: bool) -> str:
    """What recording at ``odr_hz`` into ``folder`` costs, plain and compressed, for the user:
    ``CSV about 5.5 MB/min, compressed about 2.5 MB/min; the 71 GB free last about 9 days``."""
    try:
        free: float | None = float(shutil.disk_usage(Path(folder)).free)
    except OSError:
        free = None
    plain = data_rate(odr_hz, reference=reference, free_bytes=free)
    packed = data_rate(odr_hz, reference=reference, compressed=True, free_bytes=free)
    text = (f"CSV about {plain.mb_per_minute:.3g} MB/min, compressed about "
            f"{packed.mb_per_minute:.3g} MB/min")
    if free is not None:
        text += (f"; the {free / 1e9:.3g} GB free last {plain.text().split(' last ')[-1]} "
                 f"(compressed: {packed.text().split(' last ')[-1]})")
    return text
