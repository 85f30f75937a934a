"""Recording format v1: writer thread, reader, crash safety, full disks and bad files."""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from app.core.calibration import SensorCalibration
from app.core.filters import create_filter
from app.core.recording import (
    MissingColumnsError,
    NotARecordingError,
    RecordingCorruptError,
    RecordingVersionError,
    RecordingWarning,
    RecordingWriteError,
    RecordingWriter,
    read_recording,
    recording_metadata,
    sample_recordings,
    save_bookmarks,
    simulator_metadata,
)
from app.core.recording.format import FIRST_LINE, to_json_value
from app.core.recording.reader import Bookmark, parse_recording
from app.core.samples import RawBlock, ScaleFactors, convert_raw_block
from drivers.base import DeviceInfo
from drivers.sim.device import SimulatedDevice

ROOT = Path(__file__).resolve().parent.parent


def sim_blocks(url: str = "sim://wobble?odr=416&seed=4", count: int = 40, block: int = 37):
    """Raw blocks of the simulator, as fast as it makes them."""
    device = SimulatedDevice(url, realtime=False, block=block)
    device.open()
    try:
        return [device.read(0.0) for _ in range(count)], device
    finally:
        device.close()


def joined(blocks: list[RawBlock], name: str) -> np.ndarray:
    return np.concatenate([getattr(convert_raw_block(b), name) for b in blocks])


def record(path: Path, blocks: list[RawBlock], metadata: dict | None = None, **options):
    writer = RecordingWriter(path, metadata or recording_metadata(), **options).start()
    for block in blocks:
        assert writer.write(block)
    return writer.close()


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(
        np.ascontiguousarray(a).view(np.int64), np.ascontiguousarray(b).view(np.int64))


# -- round trips ---------------------------------------------------------------------------------
def test_the_writer_thread_round_trip_is_identical_to_the_last_bit(tmp_path):
    blocks, _ = sim_blocks()
    path = tmp_path / "run.csv"
    status = record(path, blocks)
    n = sum(len(b) for b in blocks)
    assert status.state == "stopped" and status.error is None
    assert status.rows_written == status.rows_synced == n
    assert status.bytes_written == path.stat().st_size

    rec = read_recording(path)
    assert len(rec) == n
    assert same_bits(rec.t_s, joined(blocks, "t_s"))
    assert same_bits(rec.accel_m_s2, joined(blocks, "accel_m_s2"))
    assert same_bits(rec.gyro_rad_s, joined(blocks, "gyro_rad_s"))
    assert same_bits(rec.temp_degc, joined(blocks, "temp_degc"))
    assert same_bits(rec.reference_quat, joined(blocks, "reference_quat"))
    assert np.array_equal(rec.gap, joined(blocks, "gap"))
    starts = np.cumsum([0] + [len(b) for b in blocks[:-1]])
    assert np.array_equal(np.flatnonzero(rec.block_start), starts)
    assert not rec.warnings and not rec.dropped_partial_row
    # Replayed through scale factors of 1.0, the pipeline's conversion gives the same bits.
    again = convert_raw_block(rec.raw_block())
    assert same_bits(again.accel_m_s2, joined(blocks, "accel_m_s2"))
    assert same_bits(again.temp_degc, joined(blocks, "temp_degc"))


def test_blocks_without_reference_or_temperature_and_with_gaps(tmp_path):
    unit = ScaleFactors(0.001, 0.0001, 1.0, 0.0)
    t = np.arange(10) * 0.01
    gap = np.zeros(10, bool)
    gap[[0, 6]] = True
    raw = RawBlock(t, np.arange(30).reshape(10, 3), -np.arange(30).reshape(10, 3),
                   np.full(10, np.nan), unit, gap)
    path = tmp_path / "plain.csv"
    record(path, [raw])
    header = next(line for line in path.read_text().splitlines() if line.startswith("t,"))
    assert "qw" not in header.split(",")  # decided by the first block: it has no reference
    rec = read_recording(path)
    assert rec.reference_quat is None and not rec.has_reference
    assert np.isnan(rec.temp_degc).all()
    assert np.flatnonzero(rec.gap).tolist() == [0, 6]
    assert same_bits(rec.accel_m_s2, np.arange(30).reshape(10, 3) * 0.001)


def test_metadata_round_trips_with_every_bit_of_the_calibration(tmp_path):
    rng = np.random.default_rng(5)
    calibration = SensorCalibration(rng.normal(size=3), np.eye(3) + rng.normal(0, 0.01, (3, 3)),
                                    rng.normal(size=3) * 1e-3, np.eye(3) * 1.0001, "bench unit 7")
    info = DeviceInfo("sim://tour?seed=3", "Simulated LSM6DSOX (tour)", "SIM-ABC", "LSM6DSOX",
                      102.44, 104.0, 4, 250, "simulator 0.1.0",
                      {"scenario": "tour", "params": np.array([1.5, 2.0]), "ok": np.True_})
    main_filter = create_filter("madgwick", beta=0.07)
    _, device = sim_blocks(count=1)
    metadata = recording_metadata(
        device=info, calibration=calibration, orientation_filter=main_filter,
        comparison_filters=[create_filter("ekf")], note='a "note", with\nnewline and ° ✓',
        reference_source="simulator", bookmarks=[{"t": 1.25, "label": "tilt"}],
        extra=simulator_metadata(device),
    )
    path = tmp_path / "meta.csv"
    record(path, sim_blocks(count=2)[0], metadata)
    text = path.read_text(encoding="utf-8")
    assert text.startswith(FIRST_LINE + "\n")
    rec = read_recording(path)
    assert rec.metadata == json.loads(json.dumps(to_json_value(metadata)))
    assert list(rec.metadata) == list(metadata)
    for name in ("accel_bias_m_s2", "accel_matrix", "gyro_bias_rad_s", "gyro_matrix"):
        assert same_bits(getattr(rec.calibration, name), getattr(calibration, name))
    assert rec.calibration.name == "bench unit 7"
    assert rec.filter_name == "madgwick" and rec.filter_parameters["beta"] == 0.07
    assert rec.device["unique_id"] == "SIM-ABC" and rec.device["extra"]["params"] == [1.5, 2.0]
    assert rec.note == metadata["note"]
    assert rec.bookmarks == [Bookmark(1.25, "tilt")]
    errors = rec.metadata["simulator"]["unit_errors"]
    assert same_bits(np.array(errors["accel_bias_m_s2"]), device.unit_errors.accel_bias_m_s2)


def test_unknown_columns_are_kept_and_ignored_in_any_order():
    text = (
        "# inclinometer-recording 1\n"
        "# future_key: {\"anything\": [1, 2]}\n"
        "# a plain comment line\n"
        "gz,label,t,ax,ay,az,gx,gy,pressure\n"
        "0.3,start,0.0,1,2,3,0.1,0.2,1013.25\n"
        "\n"
        "0.6 , x y ,0.01,4,5,6,0.4,0.5,\r\n"
    )
    rec = parse_recording(text.encode())
    assert rec.metadata["future_key"] == {"anything": [1, 2]}
    assert rec.comments == ["# a plain comment line"]
    assert rec.accel_m_s2.tolist() == [[1, 2, 3], [4, 5, 6]]
    assert rec.gyro_rad_s.tolist() == [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]
    assert set(rec.unknown_columns) == {"label", "pressure"}
    assert rec.columns["label"].tolist() == ["start", "x y"]
    assert rec.columns["pressure"][0] == 1013.25 and np.isnan(rec.columns["pressure"][1])
    assert not rec.gap.any() and rec.block_start is None and rec.reference_quat is None
    # The same with a quoted text field holding a comma (the csv-module path).
    quoted = text.replace(",start,", ',"start, here",')
    rec2 = parse_recording(quoted.encode())
    assert rec2.columns["label"].tolist() == ["start, here", "x y"]
    assert same_bits(rec2.accel_m_s2, rec.accel_m_s2)


def test_the_documented_examples_load():
    text = (ROOT / "docs" / "recording-format.md").read_text(encoding="utf-8")
    examples = re.findall(r"```\n(# inclinometer-recording 1\n.*?)```", text, re.S)
    assert len(examples) == 2
    assert [len(parse_recording(e.encode())) for e in examples] == [3, 2]


# -- damaged files -------------------------------------------------------------------------------
def test_an_incomplete_last_row_is_dropped_with_a_warning(tmp_path):
    blocks, _ = sim_blocks(count=3)
    path = tmp_path / "cut.csv"
    record(path, blocks)
    data = path.read_bytes()
    last_row_start = data.rstrip(b"\n").rfind(b"\n") + 1
    path.write_bytes(data[: last_row_start + 25])  # the writer died inside the last row
    lines = data[: last_row_start].count(b"\n") + 1
    with pytest.warns(RecordingWarning, match=f"line {lines}: the last row is incomplete"):
        rec = read_recording(path)
    n = sum(len(b) for b in blocks)
    assert rec.dropped_partial_row and len(rec) == n - 1
    assert same_bits(rec.accel_m_s2, joined(blocks, "accel_m_s2")[:-1])
    # Cut exactly after a row: nothing is dropped, nothing is said.
    path.write_bytes(data[:last_row_start])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)
        rec = read_recording(path)
    assert len(rec) == n - 1 and not rec.dropped_partial_row


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda row: b",".join([row.split(b",")[0], b"abc", *row.split(b",")[2:]]),
         "column 'ax' holds 'abc', which is not a number"),
        (lambda row: row.rsplit(b",", 3)[0], "the row has 11 field(s), the header has 14"),
        (lambda row: row + b",7", "more fields than the header's 14"),
        (lambda row: b"," + row.split(b",", 1)[1], "the required column 't' is empty"),
    ],
)
def test_a_corrupt_row_in_the_middle_names_its_line_and_keeps_the_rows_before(
    tmp_path, damage, message
):
    blocks, _ = sim_blocks(count=4)
    path = tmp_path / "bad.csv"
    record(path, blocks)
    lines = path.read_bytes().split(b"\n")
    header = next(i for i, line in enumerate(lines) if line.startswith(b"t,"))
    bad = header + 51  # the 51st sample
    lines[bad] = damage(lines[bad])
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(RecordingCorruptError) as caught:
        read_recording(path)
    error = caught.value
    assert error.line == bad + 1
    assert f"line {bad + 1}: " in str(error) and message in str(error)
    assert "the 50 row(s) before it are valid" in str(error)
    assert len(error.partial) == 50
    assert same_bits(error.partial.t_s, joined(blocks, "t_s")[:50])
    with pytest.warns(RecordingWarning, match=f"line {bad + 1}"):
        rec = read_recording(path, on_corrupt="truncate")
    assert len(rec) == 50 and rec.corrupt_line == bad + 1


def test_large_file_paths_parallel_and_memory_mapped_read_the_same(tmp_path, monkeypatch):
    from app.core.recording import reader, text_parse

    blocks, _ = sim_blocks(count=60, block=211)
    path = tmp_path / "big.csv"
    record(path, blocks)
    lines = path.read_bytes().split(b"\n")
    for k in (3000, 7001, 7002, 11500):  # blank lines leave holes inside the pieces
        lines.insert(k, b" \r")
    path.write_bytes(b"\n".join(lines))
    simple = read_recording(path)
    monkeypatch.setattr(text_parse, "PARALLEL_MIN_BYTES", 1)
    monkeypatch.setattr(reader, "CHUNKED_MIN_BYTES", 0)
    monkeypatch.setattr(os, "cpu_count", lambda: 5)
    assert len(text_parse.row_chunks(path.read_bytes(), 0, path.stat().st_size)) == 5
    mapped = read_recording(path)
    assert len(mapped) == len(simple) == sum(len(b) for b in blocks)
    for name, column in simple.columns.items():
        assert same_bits(mapped.columns[name], column), name
    assert same_bits(mapped.gyro_rad_s, joined(blocks, "gyro_rad_s"))
    # A bad row in a later piece: the same line number and the same rows before it.
    bad = 9876
    lines[bad] = lines[bad].replace(b",", b",,", 1)
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(RecordingCorruptError) as caught:
        read_recording(path)
    assert caught.value.line == bad + 1
    monkeypatch.setattr(text_parse, "PARALLEL_MIN_BYTES", 1 << 40)
    with pytest.raises(RecordingCorruptError) as again:
        read_recording(path)
    assert again.value.line == bad + 1
    assert same_bits(caught.value.partial.t_s, again.value.partial.t_s)


def test_foreign_files_other_versions_and_missing_columns_are_refused(tmp_path):
    def attempt(data: bytes):
        path = tmp_path / "x.csv"
        path.write_bytes(data)
        return read_recording(path)

    with pytest.raises(NotARecordingError, match="first line is a CSV line of 10 characters"):
        attempt(b"time,x,y,z\n1,2,3,4\n")
    with pytest.raises(NotARecordingError, match="the file is empty"):
        attempt(b"")
    with pytest.raises(RecordingVersionError, match=r"version 2 .*newer") as caught:
        attempt(b"# inclinometer-recording 2\nt,ax\n")
    assert caught.value.version == "2"
    with pytest.raises(MissingColumnsError, match=r"lacks the required column.*gx, gy, gz") as c2:
        attempt(b"# inclinometer-recording 1\nt,ax,ay,az,temp\n0,1,2,3,4\n")
    assert c2.value.missing == ["gx", "gy", "gz"]
    with pytest.raises(RecordingCorruptError, match="names ax more than once"):
        attempt(b"# inclinometer-recording 1\nt,ax,ax,ay,az,gx,gy,gz\n")
    with pytest.raises(RecordingCorruptError, match="ends before its header row"):
        attempt(b"# inclinometer-recording 1\n# note: \"killed early\"\nt,ax,a")
    # A byte-order mark (a spreadsheet saved it) and an empty body are fine.
    rec = attempt(b"\xef\xbb\xbf# inclinometer-recording 1\nt,ax,ay,az,gx,gy,gz\n")
    assert len(rec) == 0


def test_a_metadata_value_that_is_not_json_is_kept_as_text():
    data = b'# inclinometer-recording 1\n# note: hello there\nt,ax,ay,az,gx,gy,gz\n'
    with pytest.warns(RecordingWarning, match="'note' is not JSON"):
        rec = parse_recording(data)
    assert rec.note == "hello there"


# -- durability ----------------------------------------------------------------------------------
def test_rows_reach_the_disk_within_a_second_while_recording(tmp_path):
    flushed = threading.Event()
    seen = []

    def on_flush(status):
        seen.append((time.monotonic(), status))
        flushed.set()

    blocks, _ = sim_blocks(count=2)
    path = tmp_path / "live.csv"
    writer = RecordingWriter(path, recording_metadata(), on_flush=on_flush).start()
    try:
        written_at = time.monotonic()
        writer.write(blocks[0])
        assert flushed.wait(5.0)
        flush_time, status = seen[0]
        assert flush_time - written_at < 1.0
        assert status.rows_synced == len(blocks[0])
        # Another program can load the rows while the recording goes on.
        assert len(read_recording(path)) == len(blocks[0])
    finally:
        writer.close()


class DiskWithLittleSpace:
    """An unbuffered file on a disk with ``free`` bytes left: a write takes what fits, the
    next one fails with ENOSPC, as write(2) does on a full disk."""

    def __init__(self, path: Path, mode: str, free: int) -> None:
        self.raw = open(path, mode, buffering=0)  # noqa: SIM115 - closed by the writer
        self.free = free

    def write(self, data) -> int:
        if self.free <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        count = self.raw.write(bytes(data[: self.free]))
        self.free -= count
        return count

    def fileno(self) -> int:
        return self.raw.fileno()

    def truncate(self, size: int) -> int:
        return self.raw.truncate(size)

    def close(self) -> None:
        self.raw.close()


def test_a_full_disk_stops_the_recording_cleanly_and_keeps_every_complete_row(tmp_path):
    blocks, _ = sim_blocks(count=40)
    path = tmp_path / "full.csv"
    messages = []
    free = 40_000  # falls inside a row, somewhere in the second hundred rows
    writer = RecordingWriter(
        path, recording_metadata(note="disk test"), on_error=messages.append,
        opener=lambda p, mode: DiskWithLittleSpace(p, mode, free), flush_interval_s=0.0,
    ).start()
    for block in blocks:
        writer.write(block)
    status = writer.close()
    assert status.state == "failed"
    assert len(messages) == 1 and messages[0] == status.error
    assert "the disk is full" in status.error and str(path) in status.error
    assert f"The {status.rows_written} rows recorded until then" in status.error
    assert not writer.write(blocks[0])  # refused afterwards
    assert status.rows_written < sum(len(b) for b in blocks)
    # The file was cut back to its last complete row: it loads without any warning.
    data = path.read_bytes()
    assert len(data) == status.bytes_written < free and data.endswith(b"\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)
        rec = read_recording(path)
    assert 100 < len(rec) == status.rows_written
    assert same_bits(rec.accel_m_s2, joined(blocks, "accel_m_s2")[: len(rec)])
    assert rec.t_s[-1] == status.last_t_s
    assert rec.note == "disk test"


def test_a_disk_too_full_for_the_metadata_refuses_to_start(tmp_path):
    path = tmp_path / "none.csv"
    writer = RecordingWriter(path, recording_metadata(),
                             opener=lambda p, mode: DiskWithLittleSpace(p, mode, 100))
    with pytest.raises(RecordingWriteError, match=r"cannot write .*No space left"):
        writer.start()
    assert not path.exists()


def test_an_existing_file_is_never_overwritten_unless_asked(tmp_path):
    path = tmp_path / "keep.csv"
    path.write_text("precious")
    with pytest.raises(RecordingWriteError, match="exists"):
        RecordingWriter(path, recording_metadata()).start()
    assert path.read_text() == "precious"
    record(path, sim_blocks(count=1)[0], overwrite=True)
    assert path.read_text().startswith(FIRST_LINE)


def _subprocess_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _wait_for_rows(process: subprocess.Popen, minimum: int) -> int:
    """Read the recorder's progress lines until ``minimum`` rows are on disk."""
    assert process.stderr is not None
    for line in process.stderr:
        found = re.search(r"(\d+) rows on disk", line)
        if found and int(found.group(1)) >= minimum:
            return int(found.group(1))
    raise AssertionError(f"the recorder ended early: {process.wait()}")


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigkill_of_a_recording_process_leaves_a_file_with_every_flushed_row(tmp_path):
    path = tmp_path / "killed.csv"
    process = subprocess.Popen(
        [sys.executable, "-m", "app", "record", "--device", "sim://wobble?odr=833&seed=2",
         "--duration", "120", str(path)],
        cwd=ROOT, env=_subprocess_env(), stderr=subprocess.PIPE, stdout=subprocess.PIPE,
        text=True,
    )
    try:
        on_disk = _wait_for_rows(process, 400)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
        process.stderr.close()
        process.stdout.close()
    assert process.returncode == -signal.SIGKILL
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = read_recording(path)
    assert len(rec) >= on_disk
    assert rec.dropped_partial_row == any("incomplete" in str(w.message) for w in caught)
    steps = np.diff(rec.t_s)
    assert np.all(steps > 0)
    assert np.allclose(np.linalg.norm(rec.accel_m_s2, axis=1), 9.81, atol=1.5)
    assert rec.device["url"] == "sim://wobble?odr=833&seed=2"


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs RLIMIT_FSIZE")
def test_a_real_file_size_limit_stops_the_recording_and_keeps_the_rows(tmp_path):
    path = tmp_path / "limited.csv"
    limit = 300_000
    script = (
        "import resource, signal, sys\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n"
        "from app.cli import main\n"
        "sys.exit(main(['record', '--quiet', '--device', "
        "'sim://wobble?odr=1667&realtime=0', '--duration', '60', sys.argv[1]]))\n"
    )
    result = subprocess.run([sys.executable, "-c", script, str(path)], cwd=ROOT,
                            env=_subprocess_env(), capture_output=True, text=True, timeout=120)
    assert result.returncode == 1, result.stderr
    assert "the file reached the largest size this system allows" in result.stderr
    assert "writing failed" in result.stdout
    data = path.read_bytes()
    assert len(data) <= limit and data.endswith(b"\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)
        rec = read_recording(path)
    kept = int(re.search(r"(\d+) rows", result.stdout).group(1))
    assert len(rec) == kept > 500


# -- files -----------------------------------------------------------------------------------------
def test_bookmarks_are_saved_without_touching_a_row(tmp_path):
    path = tmp_path / "marks.csv"
    record(path, sim_blocks(count=3)[0], recording_metadata(note="n"))
    before = path.read_bytes()
    body = before[before.index(b"\nt,") + 1:]
    save_bookmarks(path, [Bookmark(0.2, "late"), Bookmark(0.05, "early")])
    after = path.read_bytes()
    assert after.endswith(body)
    rec = read_recording(path)
    assert rec.bookmarks == [Bookmark(0.05, "early"), Bookmark(0.2, "late")]
    assert rec.note == "n"


def test_the_sample_recordings_are_ready_to_replay():
    paths = sample_recordings()
    assert {p.stem for p in paths} == {"wobble-104hz", "translation-208hz", "tour-104hz"}
    assert sum(p.stat().st_size for p in paths) < 5_000_000
    for path in paths:
        rec = read_recording(path)
        assert rec.has_reference and rec.block_start is not None
        assert rec.calibration is not None and not rec.calibration.is_identity
        assert rec.device["unique_id"].startswith("SIM-")
        nominal = rec.device["odr_nominal_hz"]
        assert rec.duration_s == pytest.approx(60.0 if "tour" in path.stem else 30.0, abs=0.1)
        assert f"{nominal:g}hz" in path.stem
    tour = read_recording(next(p for p in paths if "tour" in p.stem))
    assert np.count_nonzero(tour.gap) == 1
    assert [b.label for b in tour.bookmarks[:3]] == ["+z up", "-z up", "+x up"]


def test_a_failing_progress_callback_does_not_stop_the_recording(tmp_path, caplog):
    def broken(_status):
        raise BrokenPipeError(32, "Broken pipe")  # an OSError, like a closed console

    blocks, _ = sim_blocks(count=3)
    path = tmp_path / "cb.csv"
    status = record(path, blocks, on_flush=broken, flush_interval_s=0.0)
    assert status.state == "stopped" and status.rows_written == sum(len(b) for b in blocks)
    assert len(read_recording(path)) == status.rows_written
    assert "callback" in caplog.text
