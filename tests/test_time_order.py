"""Time order (issue 36): ``t`` that decreases, repeats, is shuffled or NaN is refused with its
line named; a jump of more than a few sample periods is a gap, in the reader (whole and in
chunks) and in the text-line driver on the host's clock."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from app.cli import main
from app.core.recording import reader
from app.core.recording.errors import RecordingCorruptError, RecordingWarning
from app.core.recording.reader import GAP_PERIODS, read_recording
from app.core.recording.stream import RecordingStream, device_blocks, read_stream
from drivers.text_lines import Layout, _Timeline

HEADER = b"# inclinometer-recording 1\n# device: {\"odr_hz\": 100.0}\nt,ax,ay,az,gx,gy,gz,gap\n"
FIRST_ROW_LINE = 4


def recording_bytes(times: list[float] | np.ndarray, gaps: dict[int, int] | None = None) -> bytes:
    gaps = gaps or {}
    return HEADER + b"".join(b"%r,0.1,0.2,9.8,0.01,0.0,0.0,%d\n" % (float(t), gaps.get(i, 0))
                             for i, t in enumerate(times))


def times(n: int) -> np.ndarray:
    return np.arange(n) * 0.01


def out_of_order_cases() -> dict[str, tuple[np.ndarray, int, str]]:
    """name -> (times, index of the first refused row, words of the message)."""
    back = times(40)
    back[25] = back[24] - 0.005
    repeat = times(40)
    repeat[17] = repeat[16]
    nan = times(40)
    nan[30] = math.nan
    shuffled = times(40)
    order = np.random.default_rng(3).permutation(40)
    shuffled = shuffled[order]
    first = int(np.flatnonzero(np.diff(shuffled) <= 0)[0]) + 1
    equal = np.full(40, 5.0)
    return {
        "decreases": (back, 25, "is before the previous row's"),
        "repeats": (repeat, 17, "repeats the previous row's time"),
        "NaN": (nan, 30, "t is nan"),
        "shuffled": (shuffled, first, "is before the previous row's"),
        "all equal": (equal, 1, "repeats the previous row's time"),
    }


@pytest.mark.filterwarnings("ignore:.*t jumps by")  # a shuffled file jumps too
@pytest.mark.parametrize("case", list(out_of_order_cases()))
def test_time_out_of_order_is_refused_with_its_line(tmp_path, case):
    t, bad, words = out_of_order_cases()[case]
    path = tmp_path / "r.csv"
    path.write_bytes(recording_bytes(t))
    with pytest.raises(RecordingCorruptError, match=words) as caught:
        read_recording(path)
    assert caught.value.line == FIRST_ROW_LINE + bad
    assert f"line {FIRST_ROW_LINE + bad}:" in str(caught.value)
    assert np.array_equal(caught.value.partial.t_s, t[:bad])  # the rows before it
    with pytest.warns(RecordingWarning, match="reading stopped there"):
        kept = read_recording(path, on_corrupt="truncate")
    assert kept.corrupt_line == FIRST_ROW_LINE + bad and len(kept) == bad
    with RecordingStream(path) as stream, pytest.raises(RecordingCorruptError) as streamed:
        list(stream.chunks())
    assert streamed.value.line == FIRST_ROW_LINE + bad


def test_time_order_is_checked_across_chunks(tmp_path, monkeypatch):
    """A step back in the first row of a later chunk (the previous chunk's last time carried
    over), in a file read in chunks, by the stream and by read_recording's chunked path."""
    n = 40_000  # about 1.9 MB: more than the head's first read, so several chunks of 64 kB
    t = times(n)
    path = tmp_path / "long.csv"
    path.write_bytes(recording_bytes(t))
    with RecordingStream(path, chunk_bytes=64 << 10) as stream:
        chunks = list(stream.chunks())
    assert len(chunks) > 5
    seam = chunks[3].first_row
    t[seam] = t[seam - 1]
    path.write_bytes(recording_bytes(t))
    with RecordingStream(path, chunk_bytes=64 << 10) as stream, \
            pytest.raises(RecordingCorruptError) as caught:
        for _ in stream.chunks():
            pass
    assert caught.value.line == FIRST_ROW_LINE + seam
    monkeypatch.setattr(reader, "CHUNKED_MIN_BYTES", 0)
    with pytest.raises(RecordingCorruptError) as whole:
        read_recording(path)
    assert whole.value.line == FIRST_ROW_LINE + seam and len(whole.value.partial) == seam


def test_evaluate_refuses_a_recording_whose_times_are_all_equal(tmp_path, capsys):
    path = tmp_path / "equal.csv"
    rows = b"".join(b"5.0,0.1,0.2,9.8,0.01,0,0,0,1,0,0,0\n" for _ in range(300))
    path.write_bytes(b"# inclinometer-recording 1\nt,ax,ay,az,gx,gy,gz,gap,qw,qx,qy,qz\n" + rows)
    assert main(["evaluate", str(path), "--filter", "ekf"]) == 2
    err = capsys.readouterr().err
    assert "line 4" in err and "repeats the previous row's time" in err
    assert "Traceback" not in err and "Hz" not in err


def test_a_two_hour_jump_is_a_gap_named_by_its_line(tmp_path):
    t = times(50)
    t[20:] += 7200.0
    path = tmp_path / "jump.csv"
    path.write_bytes(recording_bytes(t))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = read_recording(path)
    assert np.flatnonzero(recording.gap).tolist() == [20]
    messages = [str(w.message) for w in caught if issubclass(w.category, RecordingWarning)]
    assert any(f"line {FIRST_ROW_LINE + 20}: t jumps by 7200" in m for m in messages)
    assert any("marked as a gap" in m for m in recording.warnings)
    # In chunks: the same row marked, in the blocks a replay hands the filters.
    with RecordingStream(path) as stream, pytest.warns(RecordingWarning, match="t jumps"):
        blocks = list(device_blocks(stream.chunks(), 8))
    gap = np.concatenate([b.gap for b in blocks])
    assert np.flatnonzero(gap).tolist() == [20]
    with pytest.warns(RecordingWarning, match="t jumps"):  # read_stream: parsed ahead
        assert np.flatnonzero(read_stream(path).gap).tolist() == [20]


def test_a_jump_the_file_marks_is_not_warned_and_small_jitter_is_no_gap(tmp_path):
    t = times(50)
    t[20:] += 30.0
    t[35:] += (GAP_PERIODS - 1.5) * 0.01  # under the threshold: not a gap
    path = tmp_path / "marked.csv"
    path.write_bytes(recording_bytes(t, gaps={20: 1}))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)
        recording = read_recording(path)
    assert np.flatnonzero(recording.gap).tolist() == [20] and not recording.warnings


def test_without_a_rate_the_median_step_sets_the_period(tmp_path):
    t = np.arange(60) * 0.004
    t[40:] += 0.5
    body = recording_bytes(t).replace(b"# device: {\"odr_hz\": 100.0}\n", b"")
    path = tmp_path / "no-rate.csv"
    path.write_bytes(body)
    with pytest.warns(RecordingWarning, match="126 sample periods"):
        recording = read_recording(path)
    assert np.flatnonzero(recording.gap).tolist() == [40]


def test_a_silence_on_the_host_clock_is_a_gap_in_the_text_line_driver():
    """Lines without a time column get the host's arrival times: 5 s without a line is a gap
    (it was gap=0, so filters integrated across it), a burst of lines is not."""
    timeline = _Timeline()
    timeline.start(Layout(kind="columns", time_unit="host"), 0.01)

    def batch(arrivals: list[float]) -> tuple[np.ndarray, np.ndarray]:
        n = len(arrivals)
        records = {"lost": np.zeros(n, np.int64), "arrival": np.array(arrivals, float),
                   "t_raw": np.full(n, np.nan)}
        t, _lost, gap = timeline.times(records, timeline.layout)
        return t, gap

    _, gap = batch([100.0 + 0.01 * k for k in range(50)])
    assert not gap.any()
    burst, gap = batch([100.6] * 6 + [100.61, 100.62])  # lines that came together
    assert not gap.any() and np.all(np.diff(burst) > 0)
    after, gap = batch([105.62 + 0.01 * k for k in range(10)])  # 5 s of silence
    assert gap.tolist() == [True] + [False] * 9
    assert after[0] - burst[-1] == pytest.approx(5.0, abs=0.02)
