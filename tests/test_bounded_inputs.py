"""Bounded work on any input (issue 36): FIFOs and devices are refused without blocking,
decompressed bytes count toward the limits (a real gzip bomb, made here), JSON is read with its
depth, size and integers capped, and a recording shortened while it is read is a message."""

from __future__ import annotations

import json
import os
import time
import tracemalloc
import zlib
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.core.arm.layout import ArmLayout, ArmLayoutError
from app.core.bounded_input import (
    InputTooLargeError,
    JsonInputError,
    NotRegularFileError,
    load_json,
    loads_json,
    read_bounded,
)
from app.core.calibration_procedures.profiles import ProfileError, read_profile_file
from app.core.evaluation import recording_source
from app.core.measurement_log import MeasurementLog
from app.core.recording.errors import RecordingError, RecordingTooLargeError
from app.core.recording.reader import read_metadata, read_recording
from app.core.recording.session import SessionManifestError, load_session
from app.core.recording.stream import RecordingStream
from drivers import replay as replay_module
from drivers.errors import DeviceOpenError
from drivers.replay import ReplayDevice, replay_url
from drivers.replay_rows import StreamedRows

BOUND_S = 30
"""pytest-timeout: a hang on a FIFO fails the test instead of blocking the suite."""
HEADER = (b"# inclinometer-recording 1\n# device: {\"odr_hz\": 100.0}\n"
          b"t,ax,ay,az,gx,gy,gz,qw,qx,qy,qz\n")


def rows_text(n: int) -> bytes:
    """``n`` rows at 100 Hz with a reference: compressible, as a still sensor's are."""
    t = np.arange(n) / 100.0
    return b"".join(b"%.2f,0.1,0.2,9.8,0.01,0,0,1,0,0,0\n" % v for v in t.tolist())


def gzip_of(parts, level: int = 9) -> bytes:
    packer = zlib.compressobj(level, zlib.DEFLATED, 31)
    return b"".join(packer.compress(p) for p in parts) + packer.flush()


# -- JSON --------------------------------------------------------------------------------------
def test_bounded_json_reads_json_and_refuses_what_is_out_of_bounds():
    assert loads_json('{"a": [1, -2.5e3, "x]\\"[", null, true]}') == {
        "a": [1, -2500.0, 'x]"[', None, True]}
    assert loads_json("[" * 64 + "]" * 64) is not None
    for text, words in [
        ("[" * 65 + "]" * 65, "nested more than 64 deep"),
        ("[" * 200_000, "nested more than 64 deep"),  # before Python's decoder recurses
        ("9" * 41, "integer of 41 digits"),
        ("-" + "9" * 5000, "integer of 5000 digits"),
        ("[NaN]", "NaN"),
        ('{"a": -Infinity}', "-Infinity"),
        ("1e400", "out of range"),
        ("{", "not valid JSON"),
        (b"\xff\xfe{}", "not UTF-8"),
    ]:
        with pytest.raises(JsonInputError, match=words):
            loads_json(text)
    with pytest.raises(JsonInputError, match="more than the 100 accepted"):
        loads_json(" " * 101 + "1", max_bytes=100)


def test_read_bounded_never_reads_past_its_limit(tmp_path):
    path = tmp_path / "big.json"
    path.write_bytes(b" " * 2000 + b"{}")
    assert load_json(path) == {}
    with pytest.raises(InputTooLargeError, match="larger than 1000 bytes"):
        read_bounded(path, 1000)
    with pytest.raises(InputTooLargeError):  # st_size 0, endless bytes: still refused
        read_bounded(path, 10)


# -- FIFOs and devices -------------------------------------------------------------------------
@pytest.fixture
def fifo(tmp_path) -> Path:
    path = tmp_path / "pipe.csv"
    os.mkfifo(path)
    return path


@pytest.mark.timeout(BOUND_S)
def test_a_fifo_is_refused_at_once_by_every_reader(fifo, tmp_path):
    """No writer ever opens the FIFO: a reader that opened it the ordinary way would block."""
    start = time.perf_counter()
    with pytest.raises(NotRegularFileError, match="FIFO"):
        load_json(fifo)
    for read in (read_recording, read_metadata, RecordingStream):
        with pytest.raises((RecordingError, OSError), match="FIFO"):
            read(fifo)
    with pytest.raises(ProfileError, match="FIFO"):
        read_profile_file(fifo)
    with pytest.raises(SessionManifestError, match="FIFO"):
        load_session(fifo)
    with pytest.raises(OSError, match="FIFO"):
        ArmLayout.load(fifo)
    with pytest.raises(DeviceOpenError, match="FIFO"):
        ReplayDevice(replay_url(fifo)).open()
    log, message = MeasurementLog.load(fifo)  # the log is kept aside, as a damaged one
    assert "FIFO" in message and len(log) == 0 and not fifo.exists()
    assert len(list(tmp_path.glob("pipe.csv.corrupt-*"))) == 1
    assert time.perf_counter() - start < BOUND_S / 2


@pytest.mark.timeout(BOUND_S)
@pytest.mark.parametrize("argv", [
    ["joint", "{fifo}", "{fifo}", "--out", "{tmp}/out.csv"],
    ["diagnose", "{fifo}"],
    ["replay", "{fifo}", "--out", "{tmp}/angles.csv"],
    ["joint", "/dev/zero", "/dev/zero", "--out", "{tmp}/out.csv"],
    ["record", "--calibration", "/dev/zero", "--device", "sim://static?realtime=0",
     "--duration", "0.1", "{tmp}/out.csv"],
    ["record", "--calibration", "{fifo}", "--device", "sim://static?realtime=0",
     "--duration", "0.1", "{tmp}/out.csv"],
])
def test_commands_refuse_fifos_and_devices_with_a_message(fifo, tmp_path, capsys, argv):
    args = [a.format(fifo=fifo, tmp=tmp_path) for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "not a regular file" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out.csv").exists()


def test_dev_zero_is_refused_as_a_recording_and_as_a_profile():
    with pytest.raises(RecordingError, match="character device"):
        read_recording("/dev/zero")
    with pytest.raises(ProfileError, match="character device"):
        read_profile_file(Path("/dev/zero"))


def test_arm_layouts_are_bounded_json(tmp_path):
    path = tmp_path / "arm.json"
    path.write_text("[" * 10_000 + "]" * 10_000)
    with pytest.raises(ArmLayoutError, match="nested more than"):
        ArmLayout.load(path)


# -- decompressed bytes ------------------------------------------------------------------------
@pytest.fixture
def blank_bomb(tmp_path) -> Path:
    """A recording whose 128 MB of blank lines pack into 600 kB: one read of the file (1 MB)
    held all of it, which the decompressor turned into 128 MB at once."""
    path = tmp_path / "bomb.csv.gz"
    path.write_bytes(gzip_of([HEADER + rows_text(10)] + [b"\n" * (1 << 20)] * 128, level=1))
    assert path.stat().st_size < 1 << 20
    return path


@pytest.mark.timeout(BOUND_S)
def test_a_gzip_bomb_stops_at_the_decompressed_limit_in_bounded_memory(blank_bomb, tmp_path):
    warm = tmp_path / "warm.csv"  # the parser's compiled kernels load before memory is traced
    warm.write_bytes(HEADER + rows_text(10) + b"\n\n")
    assert len(read_recording(warm)) == 10
    tracemalloc.start()
    try:
        start = time.perf_counter()
        with pytest.raises(RecordingTooLargeError, match="larger than 16777216 bytes when "
                                                           "decompressed"):
            # (max_values small: the table reserved for it is traced as if it were used)
            read_recording(blank_bomb, max_bytes=16 << 20, max_values=1 << 20)
        stopped_s = time.perf_counter() - start
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 100 << 20  # the 128 MB are never in memory at once
    assert stopped_s < 5.0


def test_a_small_gzip_that_expands_past_the_replay_threshold_is_streamed(tmp_path,
                                                                         monkeypatch):
    """The replay and evaluate thresholds look at decompressed bytes, not the file's size."""
    text = rows_text(150_000)  # about 5 MB of text
    path = tmp_path / "expands.csv.gz"
    path.write_bytes(gzip_of([HEADER, text]))
    threshold = 2 << 20
    assert path.stat().st_size < threshold < len(text)
    monkeypatch.setattr(replay_module, "STREAMED_MIN_BYTES", threshold)
    device = ReplayDevice(replay_url(path, speed="max"))
    device.open()
    try:
        assert isinstance(device._rows, StreamedRows)
    finally:
        device.close()
    from app.core import evaluation

    monkeypatch.setattr(evaluation, "STREAM_MIN_BYTES", threshold)
    source = recording_source(path)
    assert source.pieces is not None  # scored in pieces
    assert sum(len(block.t_s) for block, _ in source.pieces()) == 150_000
    with pytest.raises(RecordingTooLargeError, match="more than 1000000 numbers"):
        read_recording(path, max_values=1_000_000)


def test_a_line_of_zeros_is_refused_at_the_line_limit(tmp_path, monkeypatch):
    from app.core.recording import stream

    monkeypatch.setattr(stream, "MAX_LINE_BYTES", 4 << 20)
    path = tmp_path / "zeros.csv.gz"
    path.write_bytes(gzip_of([HEADER + rows_text(3)] + [b"\0" * (1 << 20)] * 64))
    with pytest.raises(RecordingError, match="line 7 is longer than 4 MB"):
        read_recording(path)


# -- a file shortened while it is read -----------------------------------------------------
def test_a_recording_shortened_while_it_is_read_is_a_message(tmp_path):
    """Large files were memory-mapped: shortening one while it was read was a bus error
    (SIGBUS, exit 135). Now the reader sees fewer bytes and says so."""
    path = tmp_path / "long.csv"
    path.write_bytes(HEADER + rows_text(60_000))  # about 2 MB: more than the first read
    with RecordingStream(path, chunk_bytes=256 << 10) as stream:
        chunks = stream.chunks()
        first = next(chunks)
        assert len(first) > 0
        with open(path, "r+b") as handle:  # as `record --overwrite` would
            handle.truncate(path.stat().st_size // 2)
        with pytest.raises(RecordingError, match="became shorter while it was read"):
            for _ in chunks:
                pass


def test_json_files_the_program_reads_are_bounded(tmp_path):
    deep = "[" * 100_000 + "]" * 100_000
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps({"format": 1})[:-1] + ', "x": ' + deep + "}")
    with pytest.raises(ProfileError, match="nested more than"):
        read_profile_file(profile)
    big_int = tmp_path / "int.json"
    big_int.write_text('{"format": ' + "7" * 400 + "}")
    with pytest.raises(ProfileError, match="integer of 400 digits"):
        read_profile_file(big_int)
    manifest = tmp_path / "m.session.json"
    manifest.write_text(deep)
    with pytest.raises(SessionManifestError, match="nested more than"):
        load_session(manifest)
