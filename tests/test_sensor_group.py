"""Several sensors at once (real worker threads): one time base, the live joint angle."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.joint.estimator import hinge_angle
from app.services.joint_stream import JointStream
from app.services.sensor_group import SensorGroup
from drivers.sim.device import SimulatedDevice

ARM = "sim://arm?seed=3&odr=104&speed=10"
FAST_ARM = "sim://arm?seed=3&odr=104&speed=20"


def joint_error_deg(estimate_deg: np.ndarray, truth_deg: np.ndarray) -> float:
    """RMS difference up to a sign and a constant offset (the angle's zero is arbitrary)."""
    best = math.inf
    for sign in (1.0, -1.0):
        d = np.radians(estimate_deg - sign * truth_deg)
        offset = math.atan2(np.sin(d).mean(), np.cos(d).mean())
        residual = np.degrees(np.angle(np.exp(1j * (d - offset))))
        best = min(best, float(np.sqrt(np.mean(residual ** 2))))
    return best


@pytest.fixture
def group(qtbot):
    group = SensorGroup()
    yield group
    group.shutdown()


def test_two_arm_sensors_share_a_clock_and_give_the_true_joint_angle(qtbot, group) -> None:
    group.add(FAST_ARM)
    group.add(FAST_ARM + "&sensor=1")
    qtbot.waitUntil(lambda: group.connected_count() == 2, timeout=15000)
    assert group.members[0].aligner is group.members[1].aligner  # one board, one clock
    stream = JointStream(group, 0, 1)
    # 40 s of the arm at twenty times real time.
    qtbot.waitUntil(lambda: stream.step() >= 0 and len(stream.angles) and
                    stream.angles.latest(1)["device_t"][0] > 40.0, timeout=20000)
    alignment = group.alignment()
    assert all(a is not None and a.shared_clock for a in alignment)
    rows = stream.angles.latest(len(stream.angles))
    late = rows["device_t"] > 20.0
    t = rows["device_t"][late]
    truth_source = SimulatedDevice(FAST_ARM + "&sensor=1")
    t_true = t * truth_source.odr_hz / truth_source.true_odr_hz
    truth = truth_source.scenario.joint_angles_deg(t_true)[:, 0]
    assert np.all(np.isfinite(rows["angle"][late]))
    assert joint_error_deg(rows["angle"][late], truth) < 4.0
    assert stream.axis_quality.source == "estimated"


def test_a_sensor_with_its_own_clock_is_mapped_onto_the_first(qtbot, group) -> None:
    group.add(ARM)
    group.add(ARM + "&sensor=1&clock_offset=7.5&clock_ppm=2000")
    qtbot.waitUntil(lambda: group.connected_count() == 2, timeout=15000)
    assert group.members[0].aligner is not group.members[1].aligner
    qtbot.waitUntil(lambda: all(len(m.aligner) > 60 for m in group.members), timeout=10000)
    d0 = np.array([1.0, 5.0])
    d1 = group.to_member_clock(0, 1, d0)
    # Same arm, same instants: sensor 1's clock reads 7.5 s ahead, 2000 ppm fast. Receive
    # latency on a loaded machine limits this to a few ms of the 10x-speed device time.
    assert d1 is not None
    assert np.allclose(d1, d0 * (1 + 2000e-6) + 7.5, atol=0.05)
    a0, a1 = group.alignment()
    assert a0 is not None and a1 is not None and not a1.shared_clock
    assert a1.spread_ms >= 0.0


def test_the_joint_stream_pairs_samples_of_one_instant(qtbot, group) -> None:
    group.add(ARM + "&errors=0")
    group.add(ARM + "&errors=0&sensor=1")
    qtbot.waitUntil(lambda: group.connected_count() == 2, timeout=15000)
    scenario = SimulatedDevice(ARM + "&sensor=1").scenario
    j1, j2 = scenario.axis_in_sensor(1, 0), scenario.axis_in_sensor(1, 1)
    stream = JointStream(group, 0, 1, axes=(j1, j2))
    qtbot.waitUntil(lambda: stream.step() >= 0 and len(stream.angles) > 300, timeout=10000)
    assert stream.axis_quality.source == "entered"
    # The true orientations of both sensors at the same device times give the true angle.
    s0 = group.members[0].pipeline.samples.latest(400, ["t", "ref_quat"])
    s1 = group.members[1].pipeline.samples.latest(400, ["t", "ref_quat"])
    common, i0, i1 = np.intersect1d(s0["t"], s1["t"], return_indices=True)
    assert len(common) > 50  # shared clock: identical time stamps
    truth = np.degrees(hinge_angle(s0["ref_quat"][i0], s1["ref_quat"][i1], j1, j2))
    expected = scenario.joint_angles_deg(common * SimulatedDevice(ARM).odr_hz
                                         / SimulatedDevice(ARM).true_odr_hz)[:, 0]
    # One sample apart (9.6 ms) would be about a degree off while the joint moves.
    assert joint_error_deg(truth, expected) < 0.1
