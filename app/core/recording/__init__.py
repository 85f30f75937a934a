"""Recordings: the v1 CSV format (docs/recording-format.md), its writer, reader and exports.

- :class:`RecordingWriter`: a thread that writes blocks crash-safely (``write(raw_block)``).
- :func:`read_recording` -> :class:`Recording`: metadata, columns, blocks for a replay.
- :func:`recording_metadata`: the metadata a recording starts with.
- :func:`run_filters` / :func:`write_angles_csv`: filters over a recording, angles to CSV.
- :func:`sample_recordings`: the recordings shipped in ``resources/recordings``.

No Qt and no devices here. Recording a device headless is :mod:`app.services.recorder`
(``inclinometer record``); replaying a recording as a device is :mod:`drivers.replay`
(``replay://PATH``).
"""

from app.core.recording.edit import rewrite_metadata, save_bookmarks
from app.core.recording.errors import (
    MissingColumnsError,
    NotARecordingError,
    RecordingCorruptError,
    RecordingError,
    RecordingVersionError,
    RecordingWarning,
    RecordingWriteError,
)
from app.core.recording.export import FilterOutput, run_filters, write_angles_csv
from app.core.recording.format import (
    FORMAT_VERSION,
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    recording_metadata,
    simulator_metadata,
)
from app.core.recording.reader import (
    UNIT_SCALE,
    Bookmark,
    Recording,
    parse_recording,
    read_metadata,
    read_recording,
)
from app.core.recording.samples import sample_recording, sample_recordings
from app.core.recording.stream import RecordingStream
from app.core.recording.writer import RecordingWriter, WriterStatus, format_rows

__all__ = [
    "FORMAT_VERSION", "OPTIONAL_COLUMNS", "REQUIRED_COLUMNS", "UNIT_SCALE", "Bookmark",
    "FilterOutput", "MissingColumnsError", "NotARecordingError", "Recording",
    "RecordingCorruptError", "RecordingError", "RecordingStream", "RecordingVersionError",
    "RecordingWarning",
    "RecordingWriteError", "RecordingWriter", "WriterStatus", "format_rows", "parse_recording",
    "read_metadata", "read_recording", "recording_metadata", "rewrite_metadata",
    "run_filters", "sample_recording", "sample_recordings", "save_bookmarks",
    "simulator_metadata", "write_angles_csv",
]
