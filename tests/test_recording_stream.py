"""Recordings read in chunks and written compressed: the same rows as a whole-file read."""

from __future__ import annotations

import gzip
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

from app.core.recording import (
    Bookmark,
    RecordingCorruptError,
    RecordingWarning,
    RecordingWriter,
    read_metadata,
    read_recording,
    recording_metadata,
    save_bookmarks,
)
from app.core.recording.sizing import data_rate, duration_text
from app.core.recording.stream import RecordingStream, device_blocks, read_stream
from drivers.sim.device import SimulatedDevice

URL = "sim://wobble?odr=833&realtime=0&block=700&seed=8"


def record(path, url: str = URL, blocks: int = 40, **options) -> int:
    """Record ``blocks`` device blocks of ``url`` into ``path``; returns the rows."""
    device = SimulatedDevice(url)
    info = device.open()
    writer = RecordingWriter(path, recording_metadata(device=info), **options).start()
    for _ in range(blocks):
        writer.write(device.read(1.0))
    status = writer.close()
    device.close()
    assert status.error is None
    return status.rows_written


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    path = tmp_path_factory.mktemp("stream") / "wobble.csv"
    record(path)
    return path


def same_columns(first, second) -> bool:
    return first.header == second.header and all(
        np.array_equal(first.columns[k], second.columns[k], equal_nan=True)
        for k in first.header)


@pytest.mark.parametrize("chunk_bytes", [4096, 100_000, 8 << 20])
def test_chunks_hold_every_row_once_and_device_blocks_match_the_whole_file(plain, chunk_bytes):
    whole = read_recording(plain)
    with RecordingStream(plain, chunk_bytes=chunk_bytes) as stream:
        chunks = list(stream.chunks())
        assert [c.first_row for c in chunks] == list(
            np.cumsum([0, *[len(c) for c in chunks[:-1]]]))
        joined = np.concatenate([c.rows.t_s for c in chunks])
        np.testing.assert_array_equal(joined, whole.t_s)
        for size in (None, 333):
            streamed = list(device_blocks(stream.chunks(), size))
            expected = list(whole.raw_blocks(size))
            assert len(streamed) == len(expected)
            for got, want in zip(streamed, expected, strict=True):
                np.testing.assert_array_equal(got.t_s, want.t_s)
                np.testing.assert_array_equal(got.accel_raw, want.accel_raw)
                np.testing.assert_array_equal(got.gyro_raw, want.gyro_raw)
                np.testing.assert_array_equal(got.gap, want.gap)
                np.testing.assert_array_equal(got.reference_quat, want.reference_quat)


def test_a_chunk_can_be_read_again_from_its_offset(plain):
    with RecordingStream(plain, chunk_bytes=50_000) as stream:
        chunks = list(stream.chunks())
        target = chunks[len(chunks) // 2]
        again = next(stream.chunks(target.offset, target.first_row, target.line))
        assert again.first_row == target.first_row and again.line == target.line
        np.testing.assert_array_equal(again.rows.t_s, target.rows.t_s)


def test_compressed_recording_reads_as_the_plain_one_and_zcat_agrees(tmp_path):
    plain, packed = tmp_path / "a.csv", tmp_path / "a.csv.gz"
    assert record(plain) == record(packed)
    assert os.path.getsize(packed) < 0.6 * os.path.getsize(plain)
    a, b = read_recording(plain), read_recording(packed)
    assert len(a) == len(b) > 0
    for name in ("t", "ax", "gz", "qw", "gap", "block_start"):
        np.testing.assert_array_equal(a.columns[name], b.columns[name])
    assert same_columns(b, read_stream(packed))
    with gzip.open(packed, "rb") as handle:  # any gzip reader sees one v1 file
        assert handle.read().startswith(b"# inclinometer-recording 1\n")
    with RecordingStream(packed) as stream:
        list(stream.chunks())
        assert len(stream.members) > 2  # one gzip member per durable write


def test_a_killed_compressed_recording_reads_up_to_its_last_write(tmp_path):
    """SIGKILL mid-recording, as for plain CSV: the file keeps what was written."""
    target = tmp_path / "killed.csv.gz"
    script = (
        "import signal\n"
        "from app.core.recording import RecordingWriter, recording_metadata\n"
        "from drivers.sim.device import SimulatedDevice\n"
        f"d = SimulatedDevice({URL!r}); info = d.open()\n"
        f"w = RecordingWriter({str(target)!r}, recording_metadata(device=info),"
        " flush_interval_s=0.05).start()\n"
        "for i in range(10**6):\n"
        "    w.write(d.read(1.0))\n"
        "    if w.status.rows_synced > 20000:\n"
        "        print('synced', flush=True); signal.pause()  # until killed\n"
    )
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                               text=True)
    try:
        assert process.stdout.readline().strip() == "synced"
    finally:
        process.kill()
        process.wait()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)
        recording = read_recording(target)
    assert len(recording) > 20000
    assert np.all(np.diff(recording.t_s) > 0)


def test_a_cut_compressed_file_keeps_the_complete_members_and_says_so(tmp_path):
    packed = tmp_path / "cut.csv.gz"
    rows = record(packed)
    data = packed.read_bytes()
    packed.write_bytes(data[: len(data) * 2 // 3])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = read_recording(packed)
    assert any("ends early" in str(w.message) for w in caught)
    assert any("ends early" in text for text in recording.warnings)
    assert 0.4 * rows < len(recording) < rows


def test_damaged_compressed_data_is_a_clear_error(tmp_path):
    packed = tmp_path / "bad.csv.gz"
    record(packed)
    data = bytearray(packed.read_bytes())
    middle = len(data) // 2
    data[middle: middle + 200] = b"\xff" * 200
    packed.write_bytes(bytes(data))
    with pytest.raises(RecordingCorruptError, match="damaged near byte"):
        read_recording(packed)


def test_bookmarks_are_saved_into_a_compressed_recording(tmp_path):
    packed = tmp_path / "b.csv.gz"
    rows = record(packed)
    size = os.path.getsize(packed)
    save_bookmarks(packed, [Bookmark(1.5, "look here")])
    recording = read_recording(packed)
    assert recording.bookmarks == [Bookmark(1.5, "look here")]
    assert len(recording) == rows
    assert abs(os.path.getsize(packed) - size) < 200  # rows copied, not recompressed
    assert read_metadata(packed)[0]["bookmarks"][0]["label"] == "look here"


def test_record_compress_option_and_replay_of_the_result(tmp_path):
    from app.cli import main

    target = tmp_path / "run.csv"
    assert main(["record", "--device", "sim://static?odr=208&realtime=0", "--duration", "3",
                 "--compress", "--quiet", str(target)]) == 0
    packed = tmp_path / "run.csv.gz"
    assert packed.exists() and not target.exists()
    angles = tmp_path / "angles.csv"
    assert main(["replay", str(packed), "--out", str(angles)]) == 0
    assert angles.read_text().count("\n") > 600


def test_data_rate_estimates():
    rate = data_rate(6667.0, reference=True, free_bytes=60e9)
    assert rate.mb_per_minute == pytest.approx(6667 * 220 * 60 / 1e6)
    assert data_rate(104.0, compressed=True).mb_per_minute < data_rate(104.0).mb_per_minute
    assert "GB free last about" in rate.text()
    assert duration_text(90) == "90 s" and duration_text(3 * 3600) == "3.0 h"
    assert duration_text(10 * 86400) == "10 days"


def test_a_recording_smaller_than_the_first_read_streams_whole(tmp_path):
    small = tmp_path / "small.csv"
    rows = record(small, "sim://static?odr=104&realtime=0&block=10", blocks=12)
    with RecordingStream(small) as stream:
        chunks = list(stream.chunks())
    assert sum(len(c) for c in chunks) == rows == 120
    np.testing.assert_array_equal(np.concatenate([c.rows.t_s for c in chunks]),
                                  read_recording(small).t_s)
