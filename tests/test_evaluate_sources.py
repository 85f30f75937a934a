"""`inclinometer evaluate` over several sources, the `movement` score mask, --param, --json,
offline filters, and the reference-only label (issue 13, items 1 and 5)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from app.core import evaluation
from app.core.filters import FILTERS
from app.core.filters.base import OrientationFilter
from app.core.orientation import quaternion_from_roll_pitch
from app.core.recording.reader import parse_recording, read_recording
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

BROAD = Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "broad"
SMALL_TRIALS = ("32_disturbed_attached_magnet_1cm", "30_disturbed_stationary_magnet_C")
needs_broad = pytest.mark.skipif(
    not BROAD.is_dir(), reason=f"the BROAD trials are not at {BROAD} (shared datasets absent)"
)

ODR = 100.0


# -- synthetic recordings whose errors are known -------------------------------------------
def synthetic_recording(path: Path, *, seconds: float = 10.0, movement: bool = True,
                        text_flag: bool = False) -> Path:
    """A level sensor whose reference is rolled 10 degrees at rest and 2 degrees in motion.

    The accelerometer says level, so the ``accel`` filter's inclination error is exactly the
    reference's roll: 10 degrees where ``movement`` is 0 (t < 1 s and t >= 4 s), 2 degrees
    where it is 1 (1 s <= t < 4 s). The reference is unknown (empty) for 1.5 s <= t < 1.6 s.
    """
    n = round(seconds * ODR)
    t = np.arange(n) / ODR
    moving = (t >= 1.0) & (t < 4.0)
    ref = quaternion_from_roll_pitch(np.where(moving, 2.0, 10.0), 0.0)
    unknown = (t >= 1.5) & (t < 1.6)
    names = "t,ax,ay,az,gx,gy,gz,qw,qx,qy,qz" + (",movement" if movement else "")
    lines = ["# inclinometer-recording 1", names]
    for k in range(n):
        quat = ",,," if unknown[k] else ",".join(repr(float(v)) for v in ref[k])
        row = f"{float(t[k])!r},0,0,{STANDARD_GRAVITY_M_S2!r},0,0,0,{quat}"
        if movement:
            flag = ("yes" if moving[k] else "no") if text_flag else ("1" if moving[k] else "0")
            row += "," + flag
        lines.append(row)
    path.write_text("\n".join(lines) + "\n")
    return path


def expected_scored(seconds: float = 10.0) -> int:
    t = np.arange(round(seconds * ODR)) / ODR
    return int(np.count_nonzero((t >= 1.0) & (t < 4.0) & ~((t >= 1.5) & (t < 1.6))))


def test_a_score_mask_chooses_exactly_the_rows_and_replaces_the_skip():
    n = 1000
    t = np.arange(n) / ODR
    quat = quaternion_from_roll_pitch(np.where(t < 5.0, 1.0, 3.0), 0.0)
    reference = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    reference[10] = np.nan
    mask = t < 0.5  # inside the 2 s a skip would drop
    stats = evaluation.error_statistics(quat, reference, t, skip_s=2.0, score_mask=mask)
    assert stats["scored"] == 49  # 50 rows, one without a reference
    assert stats["rmse_deg"] == pytest.approx(1.0, rel=1e-9)
    unmasked = evaluation.error_statistics(quat, reference, t, skip_s=2.0)
    assert unmasked["scored"] == 800
    assert unmasked["rmse_deg"] == pytest.approx(math.sqrt((300 * 1 + 500 * 9) / 800), rel=1e-9)
    with pytest.raises(ValueError, match="shape"):
        evaluation.error_statistics(quat, reference, t, score_mask=mask[:-1])


def test_recording_score_mask_reads_the_movement_column(tmp_path):
    with_flag = read_recording(synthetic_recording(tmp_path / "a.csv"))
    assert "movement" in with_flag.unknown_columns
    mask = evaluation.recording_score_mask(with_flag)
    assert mask is not None and mask.dtype == bool
    assert np.array_equal(mask, (with_flag.t_s >= 1.0) & (with_flag.t_s < 4.0))
    without = read_recording(synthetic_recording(tmp_path / "b.csv", movement=False))
    assert evaluation.recording_score_mask(without) is None
    # An empty flag is not 1; a flag given as floats counts where it equals 1.
    odd = parse_recording(b"# inclinometer-recording 1\nt,ax,ay,az,gx,gy,gz,movement\n"
                          b"0,0,0,9.8,0,0,0,1.0\n0.01,0,0,9.8,0,0,0,\n0.02,0,0,9.8,0,0,0,2\n")
    assert evaluation.recording_score_mask(odd).tolist() == [True, False, False]
    text = read_recording(synthetic_recording(tmp_path / "c.csv", text_flag=True))
    with pytest.raises(ValueError, match="'movement' column holds text"):
        evaluation.recording_score_mask(text)


@pytest.mark.parametrize("param, message", [
    ("madgwick.beta=abc", "is not a number"),
    ("madgwick.beta=99", "is outside"),
    ("madgwick.nosuch=1", "madgwick has no parameter 'nosuch'"),
    ("nosuch.beta=1", "no filter 'nosuch'"),
    ("madgwick-beta", "write FILTER.NAME=VALUE"),
    ("ekf.estimate_bias=maybe", "true or false"),
    ("vqf.tau_acc_s=2", "'vqf' is not among those run"),
])
# -- offline filters -------------------------------------------------------------------------
class OfflineProbe(OrientationFilter):
    """An 'acausal' test filter: records the length of every ``process`` call."""

    name = "offline-probe"
    title = "Offline probe"
    offline = True
    calls: ClassVar[list[int]] = []

    def process(self, block: SampleBlock):
        type(self).calls.append(len(block))
        return super().process(block)

    def _process(self, block: SampleBlock) -> np.ndarray:
        return np.tile([1.0, 0.0, 0.0, 0.0], (len(block), 1))


class OnlineProbe(OfflineProbe):
    name = "online-probe"
    offline = False
    calls: ClassVar[list[int]] = []


def test_an_offline_filter_gets_the_whole_stream_in_one_call():
    n = 1000
    t = np.arange(n) / ODR
    stream = SampleBlock(t, np.tile([0.0, 0.0, STANDARD_GRAVITY_M_S2], (n, 1)), np.zeros((n, 3)),
                         np.zeros(n), np.zeros(n, bool), np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))
    OfflineProbe.calls.clear()
    OnlineProbe.calls.clear()
    scores = evaluation.evaluate(stream, [OfflineProbe, OnlineProbe], block=64, repeats=1)
    assert OfflineProbe.calls == [n]
    assert OnlineProbe.calls == [64] * 15 + [40]
    assert [s.flag for s in scores] == ["ok", "ok"]


def test_replay_gives_an_offline_filter_the_whole_recording(tmp_path, monkeypatch):
    from app.core.recording.export import run_filters

    monkeypatch.setitem(FILTERS, OfflineProbe.name, OfflineProbe)
    monkeypatch.setitem(FILTERS, OnlineProbe.name, OnlineProbe)
    recording = read_recording(synthetic_recording(tmp_path / "r.csv"))
    OfflineProbe.calls.clear()
    OnlineProbe.calls.clear()
    outputs = run_filters(recording, ["online-probe", "offline-probe"], block=300)
    assert OfflineProbe.calls == [1000]
    assert OnlineProbe.calls == [300, 300, 300, 100]
    assert [len(o.quat) for o in outputs] == [1000, 1000]
    assert np.array_equal(outputs[1].quat, np.tile([1.0, 0.0, 0.0, 0.0], (1000, 1)))
