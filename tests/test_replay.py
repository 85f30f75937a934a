"""replay:// : pacing on an injected clock, transport controls, and exact reproduction."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from app.core.evaluation import calibration_from_unit_errors
from app.core.filters import ONLINE_FILTERS
from app.core.pipeline import Pipeline
from app.core.recording import (
    UNIT_SCALE,
    Bookmark,
    RecordingWriter,
    read_recording,
    recording_metadata,
)
from app.core.samples import RawBlock
from app.services.recorder import record_device
from drivers.base import DeviceInfo
from drivers.errors import DeviceOpenError, DeviceUrlError
from drivers.registry import create_device, scheme_of
from drivers.replay import HOLE_LIMIT_S, ReplayDevice, replay_url
from drivers.sim.device import SimulatedDevice

RATE_HZ = 100.0
BLOCK = 4
HOLE_AT = 200


class FakeClock:
    """A wall clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 500.0

    def __call__(self) -> float:
        return self.now


def make_recording(path, n: int = 400, hole_s: float = 0.2, bookmarks=()) -> np.ndarray:
    """``n`` samples at 100 Hz in blocks of 4, lost data (a hole, a gap) before sample 200
    when there are that many.

    ``ax`` holds the sample index, so each delivered sample says which one it is.
    """
    t = np.arange(n) / RATE_HZ
    gap = np.zeros(n, bool)
    if n > HOLE_AT:
        t[HOLE_AT:] += hole_s
        gap[HOLE_AT] = True
    accel = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.full(n, 9.80665)])
    reference = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    info = DeviceInfo("sim://static", "Bench unit", "UID-42", "LSM6DSOX", RATE_HZ, 104.0, 4, 250)
    metadata = recording_metadata(device=info, bookmarks=bookmarks, reference_source="test")
    writer = RecordingWriter(path, metadata).start()
    for start in range(0, n, BLOCK):
        rows = slice(start, start + BLOCK)
        writer.write(RawBlock(t[rows], accel[rows], np.zeros((len(t[rows]), 3)),
                              np.full(len(t[rows]), 25.0), UNIT_SCALE, gap[rows],
                              reference_quat=reference[rows]))
    assert writer.close().state == "stopped"
    return t


def open_replay(path, clock: FakeClock, **options) -> ReplayDevice:
    device = ReplayDevice(replay_url(path, **options), clock=clock)
    device.open()
    return device


def indices(block: RawBlock) -> list[int]:
    return block.accel_raw[:, 0].astype(int).tolist()


def drain(device: ReplayDevice, clock: FakeClock, tick: float, limit: int = 100_000):
    """Advance the clock by ``tick`` before each read; (elapsed wall, block) per block."""
    start = clock.now
    got = []
    for _ in range(limit):
        if device.at_end:
            break
        clock.now += tick
        block = device.read(0.0)
        if block is not None:
            got.append((clock.now - start, block))
    return got


# -- pacing ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("speed", [1.0, 2.0, 0.5])
def test_blocks_come_at_the_recorded_pace_times_the_speed(tmp_path, speed):
    path = tmp_path / "r.csv"
    t = make_recording(path)
    clock = FakeClock()
    device = open_replay(path, clock, speed=speed)
    tick = 0.005
    delivered = drain(device, clock, tick)
    assert [i for _, b in delivered for i in indices(b)] == list(range(len(t)))
    assert all(len(b) == BLOCK for _, b in delivered)  # the recorded device blocks
    for elapsed, block in delivered:
        data_time = (block.t_s[-1] - t[0]) / speed
        # Never early, and at the first read after the block's last sample was due.
        assert data_time - 1e-9 <= elapsed <= data_time + tick + 1e-9
    assert delivered[-1][0] == pytest.approx((t[-1] - t[0]) / speed, abs=tick + 1e-9)
    assert device.position_s == pytest.approx(device.duration_s)
    assert device.read(0.0) is None


def test_as_fast_as_possible_needs_no_clock(tmp_path):
    path = tmp_path / "r.csv"
    t = make_recording(path)
    clock = FakeClock()
    device = open_replay(path, clock, speed="max")
    blocks = []
    while (block := device.read(0.0)) is not None:
        blocks.append(block)
    assert clock.now == 500.0  # the clock never moved
    assert np.array_equal(np.concatenate([b.t_s for b in blocks]), t)
    assert np.flatnonzero(np.concatenate([b.gap for b in blocks])).tolist() == [HOLE_AT]
    assert device.at_end and device.speed == math.inf


def test_a_long_hole_in_time_is_waited_for_only_a_second(tmp_path):
    path = tmp_path / "hole.csv"
    t = make_recording(path, hole_s=30.0)
    clock = FakeClock()
    device = open_replay(path, clock)
    delivered = drain(device, clock, 0.01)
    after_hole = next(e for e, b in delivered if indices(b)[0] == HOLE_AT)
    before_hole = next(e for e, b in delivered if indices(b)[-1] == HOLE_AT - 1)
    waited = after_hole - before_hole
    last_block_span = t[HOLE_AT + BLOCK - 1] - t[HOLE_AT]
    assert waited == pytest.approx(HOLE_LIMIT_S + last_block_span, abs=0.011)
    assert delivered[-1][0] < 10.0  # not 30 s and more
    gap_block = next(b for _, b in delivered if indices(b)[0] == HOLE_AT)
    assert gap_block.gap[0] and gap_block.lost_samples == round(30.0 * RATE_HZ)


def test_without_recorded_blocks_whatever_is_due_comes_in_20_ms_pieces(tmp_path):
    path = tmp_path / "r.csv"
    t = make_recording(path)
    clock = FakeClock()
    device = open_replay(path, clock, exact=0)
    assert not device.exact_blocks
    delivered = drain(device, clock, 0.001)
    assert [i for _, b in delivered for i in indices(b)] == list(range(len(t)))
    assert {len(b) for _, b in delivered[:-1]} == {2}  # 20 ms at 100 Hz
    for elapsed, block in delivered:
        assert elapsed >= block.t_s[-1] - t[0] - 1e-9


# -- transport controls ----------------------------------------------------------------------------
def test_pause_holds_and_play_resumes_without_a_burst(tmp_path):
    path = tmp_path / "r.csv"
    make_recording(path)
    clock = FakeClock()
    device = open_replay(path, clock)
    clock.now += 0.2
    first = device.read(0.0)
    assert indices(first) == [0, 1, 2, 3]
    device.pause()
    assert not device.playing
    clock.now += 10.0
    assert device.read(0.0) is None
    device.play()
    assert device.read(0.0) is None  # the next block needs its own 30 ms again
    clock.now += 0.03
    assert indices(device.read(0.0)) == [4, 5, 6, 7]


def test_single_step_one_block_or_n_samples(tmp_path):
    path = tmp_path / "r.csv"
    make_recording(path)
    clock = FakeClock()
    device = open_replay(path, clock, paused=1)
    assert not device.playing and device.read(0.0) is None
    device.step()
    assert indices(device.read(0.0)) == [0, 1, 2, 3]
    assert device.read(0.0) is None
    device.step(7)
    assert indices(device.read(0.0)) == list(range(4, 11))
    device.step()  # the rest of the recorded block 8..11
    assert indices(device.read(0.0)) == [11]
    device.play()
    device.step()  # stepping while playing pauses
    assert not device.playing
    assert indices(device.read(0.0)) == [12, 13, 14, 15]


def test_a_seek_marks_the_jump_as_a_gap_and_counts_a_generation(tmp_path):
    path = tmp_path / "r.csv"
    t = make_recording(path)
    clock = FakeClock()
    device = open_replay(path, clock, speed="max")
    for _ in range(30):
        device.read(0.0)
    assert device.last_block_generation == device.generation == 0
    assert device.seek(0.5) == pytest.approx(0.5)  # backwards, into a recorded block
    assert device.generation == 1
    block = device.read(0.0)
    assert indices(block) == [50, 51]  # to the end of the recorded block 48..51
    assert block.gap.tolist() == [True, False] and block.t_s[0] == t[50]
    assert device.last_block_generation == 1
    assert not device.read(0.0).gap.any()
    device.seek(3.0)  # forwards: the skipped samples are lost to the filters too
    block = device.read(0.0)
    assert block.gap[0] and block.t_s[0] >= t[0] + 3.0
    position = device.position_s
    device.seek(position)  # no move: no gap
    assert not device.read(0.0).gap[0] and device.generation == 2
    device.seek(1e9)
    assert device.position_s == pytest.approx(t[-1] - t[0])  # clamped to the last sample
    with pytest.raises(ValueError, match="cannot seek"):
        device.seek(math.nan)


def test_loop_starts_again_with_a_gap(tmp_path):
    path = tmp_path / "r.csv"
    t = make_recording(path, n=40)
    clock = FakeClock()
    device = open_replay(path, clock, speed="max", loop=1)
    seen = [device.read(0.0) for _ in range(12)]
    assert indices(seen[10]) == [0, 1, 2, 3] and seen[10].gap[0]
    assert device.last_block_generation == 1 and not device.at_end
    device.loop = False
    while device.read(0.0) is not None:
        pass
    assert device.at_end and device.position_s == pytest.approx(t[-1] - t[0])
    device.play()  # at the end, play starts again from the beginning
    block = device.read(0.0)
    assert indices(block) == [0, 1, 2, 3] and block.gap[0] and device.generation == 2


def test_jump_to_gaps(tmp_path):
    path = tmp_path / "r.csv"
    t = make_recording(path)
    clock = FakeClock()
    device = open_replay(path, clock, speed="max")
    assert device.gap_positions_s == [pytest.approx(t[HOLE_AT] - t[0])]
    assert device.previous_gap() is None
    assert device.next_gap() == pytest.approx(t[HOLE_AT] - t[0])
    assert device.next_gap() is None  # no later gap: no move
    block = device.read(0.0)
    assert indices(block)[0] == HOLE_AT and block.gap[0]
    device.read(0.0)
    assert device.previous_gap() == pytest.approx(t[HOLE_AT] - t[0])
    assert indices(device.read(0.0))[0] == HOLE_AT


def test_bookmarks_from_the_file_and_added(tmp_path):
    path = tmp_path / "r.csv"
    t = make_recording(path, bookmarks=[{"t": 1.0, "label": "one"}, {"t": 3.0, "label": ""}])
    clock = FakeClock()
    device = open_replay(path, clock, speed="max")
    assert device.bookmarks == [Bookmark(1.0, "one"), Bookmark(3.0, "")]
    mark = device.add_bookmark(2.0, "two")
    assert device.bookmark_position_s(mark) == 2.0
    assert device.next_bookmark() == Bookmark(1.0, "one")
    assert indices(device.read(0.0))[0] == 100
    assert device.next_bookmark().label == "two"
    assert device.previous_bookmark().label == "one"
    assert device.bookmarks_metadata() == {"bookmarks": [
        {"t": 1.0, "label": "one"}, {"t": 2.0, "label": "two"}, {"t": 3.0, "label": ""}]}
    device.seek(t[-1])
    assert device.next_bookmark() is None


def test_speed_limits(tmp_path):
    path = tmp_path / "r.csv"
    make_recording(path, n=8)
    device = open_replay(path, FakeClock())
    assert device.set_speed(0.1) == 0.1
    assert device.set_speed("max") == math.inf and device.set_speed(0) == math.inf
    assert device.set_speed("4x") == 4.0
    for bad in (0.05, 101, "fast", -1):
        with pytest.raises(ValueError):
            device.set_speed(bad)
    with pytest.raises(DeviceUrlError, match="speed"):
        ReplayDevice(replay_url(path, speed=500))


def test_close_wakes_a_reader_waiting_in_another_thread(tmp_path):
    path = tmp_path / "r.csv"
    make_recording(path, n=8)
    device = open_replay(path, FakeClock(), paused=1)
    results = []
    reader = threading.Thread(target=lambda: results.append(device.read(30.0)))
    reader.start()
    device.close()
    reader.join(10.0)
    assert not reader.is_alive() and results == [None]


# -- URLs, registry and device info ----------------------------------------------------------
def test_urls_bare_paths_and_the_device_description(tmp_path):
    folder = tmp_path / "my runs"
    folder.mkdir()
    path = folder / "bench 1.csv"
    make_recording(path, n=8)
    assert scheme_of(str(path)) == "replay"
    assert scheme_of("replay:///x/y.csv") == "replay"
    for url in (str(path), f"replay://{path}", replay_url(path),
                "replay://" + str(path).replace(" ", "%20")):
        device = create_device(url)
        assert isinstance(device, ReplayDevice) and device.path == path
    info = create_device(str(path)).open()
    assert info.unique_id == "UID-42" and info.name == "Bench unit"
    assert info.odr_hz == RATE_HZ and info.accel_fs_g == 4
    assert info.extra["replay"]["path"] == str(path)
    assert info.extra["replay"]["samples"] == 8
    with pytest.raises(DeviceUrlError, match="unknown option 'sped'"):
        ReplayDevice(f"replay://{path}?sped=2")
    with pytest.raises(DeviceUrlError, match="loop"):
        ReplayDevice(f"replay://{path}?loop=maybe")
    foreign = tmp_path / "foreign.csv"
    foreign.write_text("a,b\n1,2\n")
    with pytest.raises(DeviceOpenError, match="not an inclinometer recording"):
        create_device(str(foreign)).open()


def test_the_start_option_opens_at_a_time_without_a_gap(tmp_path):
    path = tmp_path / "r.csv"
    make_recording(path)
    device = open_replay(path, FakeClock(), speed="max", start=1.0)
    block = device.read(0.0)
    assert indices(block) == [100, 101, 102, 103] and not block.gap.any()


# -- the whole pipeline ----------------------------------------------------------------------------
def test_a_replay_reproduces_the_live_pipeline_bit_for_bit(tmp_path):
    """A week later: same samples, same calibration, same filters: exactly the same angles."""
    sim = SimulatedDevice("sim://wobble?odr=208&seed=5", realtime=False, block=5)
    calibration = calibration_from_unit_errors(sim.unit_errors)
    others = [name for name in ONLINE_FILTERS if name != "vqf"]
    path = tmp_path / "live.csv"
    outcome = record_device(sim, path, duration_s=8.0, filter_name="vqf",
                            filter_parameters={"tau_acc_s": 2.5}, comparisons=others,
                            calibration=calibration)
    live = outcome.pipeline
    assert outcome.reason == "duration"

    recording = read_recording(path)
    n = len(recording)
    for url_options in ({"speed": "max"}, {"speed": 1}):
        clock = FakeClock()
        device = ReplayDevice(replay_url(path, **url_options), clock=clock)
        info = device.open()
        replayed = Pipeline(info.odr_hz, recording.filter_name)
        for key, value in recording.filter_parameters.items():
            replayed.set_filter_parameter(key, value)
        replayed.set_comparisons(others)
        replayed.set_calibration(device.recorded_calibration)
        while not device.at_end:
            clock.now += 0.01
            raw = device.read(0.0)
            if raw is not None:
                replayed.process(raw)
        assert replayed.counters.samples == n == live.counters.samples
        assert replayed.filter.get_parameter("tau_acc_s") == 2.5
        want, got = live.orientation.latest(n), replayed.orientation.latest(n)
        for column in want:
            assert np.array_equal(want[column], got[column], equal_nan=True), column
        for name in others:
            want = live.comparison_buffers[name].latest(n)
            got = replayed.comparison_buffers[name].latest(n)
            for column in want:
                assert np.array_equal(want[column], got[column], equal_nan=True), (name, column)
        assert np.array_equal(live.samples.latest(n)["accel"], replayed.samples.latest(n)["accel"])


def test_a_replay_of_a_recording_with_a_field_is_a_9_axis_source(tmp_path):
    """Its magnetometer as recorded, or (no ``magnetometer`` metadata: an import, a BROAD
    trial) a field sampled with the rows; the live pipeline then takes the 9-axis default."""
    from app.core.filters import DEFAULT_FILTER_9AXIS

    path = tmp_path / "mag.csv"
    device = SimulatedDevice("sim://static?odr=104&mag=lis3mdl&realtime=0&seed=4")
    record_device(device, path, duration_s=2.0)
    replay = create_device(replay_url(path) + "?speed=max")
    info = replay.open()
    replay.close()
    assert info.magnetometer is not None and info.magnetometer.chip == "LIS3MDL"
    pipeline = Pipeline(info.odr_hz)
    assert pipeline.adopt_source(info.magnetometer is not None)
    assert pipeline.filter.name == DEFAULT_FILTER_9AXIS
    bare = tmp_path / "bare.csv"
    bare.write_text("".join(line for line in path.read_text().splitlines(keepends=True)
                            if not line.startswith("# magnetometer:")))
    replay = create_device(replay_url(bare) + "?speed=max")
    info = replay.open()
    replay.close()
    assert info.magnetometer is not None and info.magnetometer.chip == "recorded"
    assert info.magnetometer.odr_hz == pytest.approx(info.odr_hz)
    six = tmp_path / "six.csv"
    record_device(SimulatedDevice("sim://static?odr=104&realtime=0&seed=4"), six,
                  duration_s=1.0)
    replay = create_device(replay_url(six) + "?speed=max")
    assert replay.open().magnetometer is None
    replay.close()
