"""Hostile files are read in time linear in their size, or refused at once, with short messages.

Each case is bounded by pytest-timeout: the bound catches a hang (a quadratic loop over a
million columns), it is not a speed assertion.
"""

from __future__ import annotations

import json
import warnings

import pytest

from app.core.calibration_procedures.profiles import ProfileCorruptError, read_profile_file
from app.core.recording import (
    MissingColumnsError,
    RecordingCorruptError,
    RecordingError,
    read_metadata,
    read_recording,
)
from app.core.recording.stream import RecordingStream

MAGIC = b"# inclinometer-recording 1\n"
HEADER = b"t,ax,ay,az,gx,gy,gz\n"
ROW = b"0.0,0.1,0.2,9.8,0.0,0.0,0.0\n"
BOUND_S = 30


def read_all_ways(path):
    """read_recording, read_metadata and a streamed read: each either works or raises a
    RecordingError; warnings are collected, never raised."""
    outcomes = []
    for reader in (read_recording, read_metadata,
                   lambda p: list(RecordingStream(p).chunks())):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                reader(path)
                outcomes.append("ok")
            except RecordingError as exc:
                assert len(str(exc)) < 2000, "a message must stay short"
                outcomes.append(exc)
    return outcomes


@pytest.mark.timeout(BOUND_S)
def test_a_header_of_a_million_columns_is_refused_with_a_short_message(tmp_path):
    path = tmp_path / "wide.csv"
    names = ",".join(f"c{i}" for i in range(200_000)).encode()
    path.write_bytes(MAGIC + names + b",c5\n" + ROW)
    outcomes = read_all_ways(path)
    for outcome in outcomes[:1]:
        assert isinstance(outcome, RecordingCorruptError)
        assert "c5" in str(outcome)
    with pytest.raises(MissingColumnsError, match=r"\.\.\. and \d+ more"):
        read_recording(_write(tmp_path / "wide2.csv", MAGIC + names + b"\n" + ROW))


def _write(path, data: bytes):
    path.write_bytes(data)
    return path


@pytest.mark.timeout(BOUND_S)
def test_a_fifty_megabyte_line_is_read_or_refused_in_linear_time(tmp_path):
    huge = b"0.0," + b"1" * (50 << 20) + b",0.2,9.8,0.0,0.0,0.0\n"
    path = _write(tmp_path / "long-line.csv", MAGIC + HEADER + ROW + huge + ROW)
    for outcome in read_all_ways(path):
        assert outcome == "ok" or isinstance(outcome, RecordingError)
    many = b"0.0" + b",1" * (10 << 20) + b"\n"
    path = _write(tmp_path / "many-fields.csv", MAGIC + HEADER + ROW + many)
    with pytest.raises(RecordingCorruptError, match="more fields than the header"):
        read_recording(path)


@pytest.mark.timeout(BOUND_S)
def test_many_metadata_lines_and_their_warnings_are_bounded(tmp_path):
    lines = b"".join(b"# key%d: not json\n" % i for i in range(300_000))
    path = _write(tmp_path / "meta.csv", MAGIC + lines + HEADER + ROW)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = read_recording(path)
    assert len(recording) == 1
    assert len(recording.warnings) <= 21 and "more such problems" in recording.warnings[-1]
    assert len(caught) <= 22


@pytest.mark.timeout(BOUND_S)
def test_deeply_nested_metadata_is_kept_as_text(tmp_path):
    deep = b"[" * 1_000_000 + b"]" * 1_000_000
    path = _write(tmp_path / "deep.csv", MAGIC + b"# note: " + deep + b"\n" + HEADER + ROW)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = read_recording(path)
    assert isinstance(recording.metadata["note"], str)
    assert any("nested too deeply" in str(w.message) for w in caught)


@pytest.mark.timeout(BOUND_S)
def test_non_utf8_bytes_and_a_header_that_never_comes(tmp_path):
    path = _write(tmp_path / "latin.csv", MAGIC + b"# note: \xff\xfe\n" + HEADER + ROW)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert len(read_recording(path)) == 1
    path = _write(tmp_path / "badhead.csv", MAGIC + b"t,ax,\xff\n" + ROW)
    assert all(isinstance(o, RecordingCorruptError) for o in read_all_ways(path))
    endless = _write(tmp_path / "endless.csv", MAGIC + b"# x: 1\n" * 3_000_000)
    with pytest.raises(RecordingError):
        read_metadata(endless)
    with pytest.raises(RecordingError):
        RecordingStream(endless)


@pytest.mark.timeout(BOUND_S)
def test_hostile_calibration_profiles_are_refused(tmp_path):
    deep = _write(tmp_path / "deep.json", b"[" * 1_000_000 + b"]" * 1_000_000)
    with pytest.raises(ProfileCorruptError):
        read_profile_file(deep)
    huge = _write(tmp_path / "huge.json", json.dumps({"x": "y" * (80 << 20)}).encode())
    with pytest.raises(ProfileCorruptError, match="too large"):
        read_profile_file(huge)
