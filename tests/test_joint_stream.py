"""JointStream's pairing of two sensors' samples (Qt-free, hand-made blocks)."""

from __future__ import annotations

import numpy as np

from app.core.pipeline import Pipeline
from app.core.recording.reader import UNIT_SCALE
from app.core.samples import RawBlock
from app.services.joint_stream import MAX_PENDING, JointStream

RATE = 100.0
OFFSET_S = 7.5


class TwoClocks:
    """Two pipelines; the second device's clock reads OFFSET_S more than the first's."""

    def __init__(self) -> None:
        self.pipelines = [Pipeline(RATE), Pipeline(RATE)]

    def pipeline(self, index: int) -> Pipeline:
        return self.pipelines[index]

    def to_member_clock(self, source: int, target: int, t: np.ndarray) -> np.ndarray:
        shift = {(1, 0): -OFFSET_S, (0, 1): OFFSET_S}.get((source, target), 0.0)
        return np.asarray(t) + shift

    def to_common(self, index: int, t: np.ndarray) -> np.ndarray:
        return self.to_member_clock(index, 0, t)


def raw(t: np.ndarray, rate_x: np.ndarray, angle: np.ndarray | None = None) -> RawBlock:
    """A sensor turning about its (horizontal) x axis at ``rate_x``, at ``angle`` (rad)."""
    n = len(t)
    gyro = np.zeros((n, 3))
    gyro[:, 0] = rate_x
    angle = np.zeros(n) if angle is None else angle
    accel = 9.81 * np.column_stack([np.zeros(n), np.sin(angle), np.cos(angle)])
    return RawBlock(t_s=t, accel_raw=accel, gyro_raw=gyro, temp_raw=np.full(n, 25.0),
                    scale=UNIT_SCALE, gap=np.zeros(n, bool))


def test_the_second_sensor_is_put_on_the_first_ones_clock_and_paired_causally() -> None:
    source = TwoClocks()
    stream = JointStream(source, 0, 1, axes=(np.array([1.0, 0, 0]), np.array([1.0, 0, 0])))
    t = np.arange(0, 400) / RATE
    # Link 1 turns at 0.5 rad/s about the hinge (x, horizontal), link 0 stands still.
    source.pipelines[0].process(raw(t[:300], np.zeros(300)))
    # The second device's samples lie half a period later on its own clock.
    t_b = t + OFFSET_S + 0.5 / RATE
    turned = 0.5 * (t + 0.5 / RATE)
    source.pipelines[1].process(raw(t_b[:200], np.full(200, 0.5), turned[:200]))
    produced = stream.step()
    # Only A's rows within B's span (on A's clock) are paired: row 0 lies before B's first
    # sample, rows 200 on after its newest and wait.
    rows = stream.angles.latest(len(stream.angles))
    assert produced == len(rows["t"]) == 199
    assert rows["device_t"][-1] <= t_b[199] - OFFSET_S
    source.pipelines[1].process(raw(t_b[200:], np.full(200, 0.5), turned[200:]))
    assert stream.step() == 100  # A's rows 200..299 lie inside B's span now
    rows = stream.angles.latest(len(stream.angles))
    np.testing.assert_allclose(rows["device_t"], t[1:300])
    # The readout averages over the first sensor's own clock: 0.1 s is 11 rows at 100 Hz.
    np.testing.assert_array_equal(stream.recent_angles(0.1), rows["angle"][-11:])
    np.testing.assert_array_equal(stream.recent_angles(0.0), rows["angle"][-1:])
    # The angle grows at link 1's rate about the hinge (0.5 rad/s) once the fusion settled.
    angle = np.unwrap(np.radians(rows["angle"]))
    rate = np.diff(angle[-100:]).mean() * RATE
    assert abs(abs(rate) - 0.5) < 0.05


def test_a_stalled_link_does_not_grow_the_buffers_without_bound() -> None:
    source = TwoClocks()
    stream = JointStream(source, 0, 1)
    t = np.arange(0, MAX_PENDING + 5000) / RATE
    for part in np.array_split(t, 10):  # less than the pipeline's ring each time
        source.pipelines[0].process(raw(part, np.zeros(len(part))))
        assert stream.step() == 0  # nothing from the second sensor: nothing to pair
    assert stream._pending_a is not None and len(stream._pending_a["t"]) == MAX_PENDING
    np.testing.assert_array_equal(stream._pending_a["t"], t[-MAX_PENDING:])
