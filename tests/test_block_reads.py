"""Streaming reads gather about ten samples (20 to 100 ms) into one block.

A board sends a SAMPLES packet per FIFO poll (every 2 ms: one or two samples at a tilt meter's
rate) and the host's cost is mostly per block, so the serial link joins what has queued up and
the simulator waits for as much; nothing is lost or reordered on the way, and a loss between
two joined packets stays marked.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.core.samples import RawBlock, ScaleFactors, merge_raw_blocks
from drivers.base import read_block_s
from drivers.emulated_nucleo import EmulatedNucleo
from drivers.serial_link import SerialLinkDevice
from drivers.sim.device import SimulatedDevice

SCALE = ScaleFactors(1e-3, 1e-4, 1 / 256, 25.0)


def block(start: int, count: int, lost: int = 0, scale: ScaleFactors = SCALE) -> RawBlock:
    gap = np.zeros(count, bool)
    gap[0] = lost > 0
    return RawBlock(t_s=(start + np.arange(count)) / 104.0,
                    accel_raw=np.full((count, 3), start, np.int16),
                    gyro_raw=np.zeros((count, 3), np.int16),
                    temp_raw=np.zeros(count, np.int16), scale=scale,
                    gap=gap, lost_samples=lost)


def test_joined_blocks_keep_every_sample_and_every_loss():
    joined = merge_raw_blocks([block(0, 2), block(2, 1), block(5, 2, lost=2), block(7, 1)])
    assert len(joined) == 1
    one = joined[0]
    np.testing.assert_array_equal(one.t_s * 104.0, [0, 1, 2, 5, 6, 7])
    assert one.lost_samples == 2
    np.testing.assert_array_equal(one.gap, [False, False, False, True, False, False])
    assert one.accel_raw[3, 0] == 5


def test_a_change_of_scale_starts_a_new_block():
    other = ScaleFactors(2e-3, 1e-4, 1 / 256, 25.0)
    joined = merge_raw_blocks([block(0, 2), block(2, 2), block(4, 2, scale=other)])
    assert [len(b) for b in joined] == [4, 2]
    assert joined[1].scale == other


@pytest.mark.parametrize(("odr_hz", "seconds"), [
    (12.5, 0.1), (104.0, 10 / 104.0), (208.0, 10 / 208.0), (833.0, 0.02), (6667.0, 0.02),
])
def test_a_read_waits_for_ten_samples_within_20_to_100_ms(odr_hz, seconds):
    assert read_block_s(odr_hz) == pytest.approx(seconds)


def test_the_serial_link_joins_the_packets_of_a_slow_stream():
    board = EmulatedNucleo("static", odr_hz=104.0, seed=3)
    try:
        device = SerialLinkDevice(f"serial://{board.port}")
        info = device.open()
        blocks = []
        while sum(len(b) for b in blocks) < 60:
            raw = device.read(0.5)
            if raw is not None:
                blocks.append(raw)
        device.close()
    finally:
        board.close()
    # The board sends a packet every 2 ms (a sample or none at 104 Hz): the reads join them.
    assert np.median([len(b) for b in blocks[1:]]) >= 8
    t = np.concatenate([b.t_s for b in blocks])
    steps = np.diff(t) * info.odr_hz
    np.testing.assert_allclose(steps, 1.0, atol=0.05)  # every sample, in order
    assert not any(b.gap is not None and b.gap.any() for b in blocks[1:])


def test_the_simulator_gathers_as_much_in_real_time():
    device = SimulatedDevice("sim://static?odr=104&seed=2")
    device.open()
    try:
        sizes = [len(device.read(0.5)) for _ in range(4)]
    finally:
        device.close()
    assert min(sizes[1:]) >= 9  # ~96 ms of samples each
