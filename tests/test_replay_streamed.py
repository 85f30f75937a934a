"""A long recording replays a chunk at a time exactly as a short one replays from memory."""

from __future__ import annotations

import numpy as np
import pytest

import app.core.recording.stream as stream_module
import drivers.replay as replay_module
from app.core.recording import RecordingWriter, read_recording, recording_metadata
from drivers.replay import ReplayDevice, replay_url
from drivers.replay_rows import StreamedRows
from drivers.sim.device import SimulatedDevice

CHUNK_BYTES = 60_000  # about 280 rows: every block and seek crosses chunk ends


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """20 000 rows with device blocks of 90, a lost stretch, and a reference."""
    path = tmp_path_factory.mktemp("streamed") / "long.csv"
    device = SimulatedDevice("sim://wobble?odr=833&realtime=0&block=90&seed=6&fail_after=60")
    info = device.open()
    writer = RecordingWriter(path, recording_metadata(device=info)).start()
    for k in range(222):
        raw = device.read(1.0)
        if k == 100:  # drop a block: the next one starts after a gap
            continue
        if k == 101:
            raw.gap = np.zeros(len(raw), dtype=bool)
            raw.gap[0] = True
        writer.write(raw)
    assert writer.close().error is None
    return path


def open_device(path, streamed: bool, monkeypatch, **options) -> ReplayDevice:
    monkeypatch.setattr(replay_module, "STREAMED_MIN_BYTES", 0 if streamed else 1 << 40)
    monkeypatch.setattr(stream_module, "CHUNK_BYTES", CHUNK_BYTES)
    device = ReplayDevice(replay_url(path, speed="max", **options))
    device.open()
    assert device.streamed is streamed
    return device


def drain(device: ReplayDevice, limit: int = 10_000) -> list:
    blocks = []
    for _ in range(limit):
        block = device.read(1.0)
        if block is None:
            break
        blocks.append(block)
    return blocks


def same_blocks(first: list, second: list) -> None:
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=True):
        assert (a is None) == (b is None)
        if a is None:
            continue
        np.testing.assert_array_equal(a.t_s, b.t_s)
        np.testing.assert_array_equal(a.accel_raw, b.accel_raw)
        np.testing.assert_array_equal(a.gyro_raw, b.gyro_raw)
        np.testing.assert_array_equal(a.gap, b.gap)
        np.testing.assert_array_equal(a.reference_quat, b.reference_quat)
        assert a.lost_samples == b.lost_samples


def test_streamed_replay_delivers_the_blocks_of_the_memory_replay(recording, monkeypatch):
    memory = open_device(recording, False, monkeypatch)
    streamed = open_device(recording, True, monkeypatch)
    try:
        same_blocks(drain(streamed), drain(memory))
        assert streamed.at_end and memory.at_end
        assert streamed.sample_count == memory.sample_count == len(read_recording(recording))
        assert streamed.duration_s == pytest.approx(memory.duration_s)
        rows = streamed._rows
        assert isinstance(rows, StreamedRows)
        held = len(rows._cur[1]) + (len(rows._prev[1]) if rows._prev else 0)
        assert held < 3 * CHUNK_BYTES / 150  # a few chunks, not the recording
    finally:
        memory.close()
        streamed.close()


def test_seeks_gaps_and_bookmarks_land_where_the_memory_replay_lands(recording, monkeypatch):
    memory = open_device(recording, False, monkeypatch, exact=0, block=64)
    streamed = open_device(recording, True, monkeypatch, exact=0, block=64)
    try:
        for device in (memory, streamed):
            device.add_bookmark(5.5, "five and a half")
        for position in (12.34, 0.0, 23.9, 7.0, 1e6):
            landed = [device.seek(position) for device in (memory, streamed)]
            assert landed[0] == pytest.approx(landed[1])
            same_blocks([streamed.read(0.0) for _ in range(5)],
                        [memory.read(0.0) for _ in range(5)])
        memory.seek(0.0)
        streamed.seek(0.0)
        assert streamed.next_gap() == pytest.approx(memory.next_gap())  # waits for the index
        same_blocks([streamed.read(1.0)], [memory.read(1.0)])
        assert streamed.gap_positions_s == pytest.approx(memory.gap_positions_s)
        assert len(memory.gap_positions_s) == 1
        memory.seek(0.0)
        streamed.seek(0.0)
        assert streamed.next_bookmark() == memory.next_bookmark()
        assert streamed.position_s == pytest.approx(memory.position_s)
        assert streamed.indexed
    finally:
        memory.close()
        streamed.close()


def test_loop_starts_again_from_the_first_chunk(recording, monkeypatch):
    streamed = open_device(recording, True, monkeypatch, loop=1, exact=0, block=5000)
    try:
        first = streamed.read(1.0)
        t = [first.t_s[0]]
        for _ in range(6):
            t.append(streamed.read(1.0).t_s[0])
        assert t.count(first.t_s[0]) == 2  # 20 000 rows in blocks of 5000: back at the start
        assert streamed.generation == 1
    finally:
        streamed.close()


def test_the_overview_covers_the_whole_session(recording, monkeypatch):
    streamed = open_device(recording, True, monkeypatch)
    try:
        streamed.seek(1e6)  # waits for the index to reach the end
        overview = streamed.overview()
        assert overview is not None and overview.complete
        whole = read_recording(recording)
        assert overview.rows == len(whole)
        assert overview.low[:, 0].min() == whole.columns["ax"].min()
        assert overview.high[:, 5].max() == whole.columns["gz"].max()
        assert 100 <= len(overview.t_s) <= 4000
        assert np.all(np.diff(overview.t_s) > 0)
    finally:
        streamed.close()


def test_a_compressed_long_recording_seeks_from_the_nearest_gzip_member(recording, tmp_path,
                                                                        monkeypatch):
    import gzip

    from app.core.recording.compressed import gzip_member

    packed = tmp_path / "long.csv.gz"
    data = recording.read_bytes()
    lines = data.splitlines(keepends=True)
    body = next(k for k, line in enumerate(lines) if not line.startswith(b"#")) + 1
    members = [gzip_member(b"".join(lines[:body]))]
    members += [gzip_member(b"".join(lines[k:k + 500])) for k in range(body, len(lines), 500)]
    packed.write_bytes(b"".join(members))
    assert gzip.decompress(packed.read_bytes()) == data
    memory = open_device(recording, False, monkeypatch, exact=0, block=64)
    streamed = open_device(packed, True, monkeypatch, exact=0, block=64)
    try:
        streamed.seek(1e6)  # waits for the index: every member start is known then
        rows = streamed._rows
        assert isinstance(rows, StreamedRows)
        assert len(rows._stream.members) >= len(members) - 1
        for position in (20.0, 3.3, 17.7):
            assert streamed.seek(position) == pytest.approx(memory.seek(position))
            same_blocks([streamed.read(0.0) for _ in range(3)],
                        [memory.read(0.0) for _ in range(3)])
    finally:
        memory.close()
        streamed.close()
