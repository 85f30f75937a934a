"""The firmware streaming from the emulated LSM6DSOX, decoded by the app's own link decoder.

Virtual time: the firmware's clock is the emulated chip's, advanced in the firmware's poll loop,
so seconds of streaming take milliseconds and nothing sleeps. Expected samples come from the
chip's truth (what it wrote into its FIFO), never typed in.
"""

from __future__ import annotations

import logging
import sys
import time

import numpy as np
import pytest
from fwcore import LED_ERROR, LED_STREAMING, FirmwareCore, PtyBoard
from test_firmware_commands import RecordingBus

from app.core.samples import RawBlock
from drivers import lsm6dsox
from drivers.link import protocol as p
from drivers.link.decoder import LinkDecoder
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.registry import create_device
from drivers.sim.options import SimOptions


def make(firmware_lib, scenario: str = "wobble", seed: int = 6, **core_options):
    chip = EmulatedLsm6dsox(SimOptions(scenario, seed=seed), clock=VirtualClock(50.0),
                            record_truth=True)
    bus = RecordingBus(chip)
    return FirmwareCore(firmware_lib, bus, **core_options), bus, chip


class Host:
    """The app's side: the link decoder fed with everything the firmware sent."""

    def __init__(self) -> None:
        self.decoder = LinkDecoder()
        self.packets: list[p.Packet] = []
        self.blocks: list[RawBlock] = []

    def take(self, core: FirmwareCore) -> None:
        self.packets += self.decoder.feed(core.take_output())
        self.blocks += self.decoder.take_blocks()

    def joined(self, name: str) -> np.ndarray:
        return np.concatenate([getattr(block, name) for block in self.blocks])


def start(core: FirmwareCore, host: Host, odr_code: int) -> None:
    core.send(p.Hello(), p.Configure(odr_code, 4, 500))
    host.take(core)
    assert [pk.status for pk in host.packets if isinstance(pk, p.Ack)] == [p.ACK_OK]
    host.decoder.arm_start(new_origin=True)
    core.send(p.Start())
    host.take(core)


def samples_of(packets: list[p.Packet]) -> list[p.Samples]:
    return [packet for packet in packets if isinstance(packet, p.Samples)]


@pytest.mark.parametrize("odr_hz", [12.5, 104.0, 833.0, 1667.0])
def test_every_sample_arrives_in_order_with_its_time(firmware_lib, odr_hz) -> None:
    core, _, chip = make(firmware_lib)
    seconds = 3.0 if odr_hz >= 100 else 8.0
    core.send(p.Hello(), p.Configure(lsm6dsox.odr_code_for(odr_hz), 4, 500), p.Start())
    core.run(seconds)
    core.send(p.Stop())
    packets = core.packets()
    samples = samples_of(packets)
    assert isinstance(packets[-1], p.Ack) and packets[-1].command == p.STOP
    # Every sample the chip batched after its turn-on transient, in order, none twice (the last
    # few may still be in the FIFO); the settling samples (wrong, by the chip's model) never go.
    skip = lsm6dsox.turn_on_discard(odr_hz)
    assert core.counters()["settling"] == skip
    truth = chip.truth()
    data = np.concatenate([s.data for s in samples])
    truth_rows = np.hstack([truth["gyro_raw"], truth["accel_raw"]])[skip:]
    assert len(truth_rows) - 2 * odr_hz * 0.002 - 2 <= len(data) <= len(truth_rows)
    np.testing.assert_array_equal(data, truth_rows[:len(data)])
    assert truth["index"][skip] == skip + 1  # the first sample kept: the (skip+1)th produced
    # Sequence numbers count packets; packets are small (sent ~5 ms after their first sample).
    assert [s.seq for s in samples] == list(range(len(samples)))
    counts = np.array([s.count for s in samples])
    assert counts.max() <= max(1, np.ceil(odr_hz * 0.0075))
    # t0 advances by count x the chip's ticks per sample (one oscillator drives both).
    ticks_per_sample = 1.0 / (lsm6dsox.real_odr_hz(odr_hz) * 25e-6)
    t0 = np.array([s.t0 for s in samples], dtype=np.int64)
    # Each t0 is within a tick of the truth (the chip's ticks are floored, the firmware rounds its
    # extrapolation from the nearest anchor), so a difference of two is within two ticks.
    np.testing.assert_allclose(np.diff(t0), counts[:-1] * ticks_per_sample, atol=2.0)
    # The temperature field follows the chip's temperature (raw / 256 + 25 degC).
    temp_degc = np.array([s.temperature_raw for s in samples]) / 256 + 25
    assert np.all(np.abs(temp_degc - np.mean(truth["temp_degc"])) < 1.0)
    counters = core.counters()
    assert counters["dropped_packets"] == counters["overruns"] == 0
    assert counters["incomplete_slots"] == counters["lost_slots"] == 0
    core.close()


def test_the_app_decoder_sees_a_clean_stream_at_device_time(firmware_lib) -> None:
    core, _, chip = make(firmware_lib)
    host = Host()
    start(core, host, odr_code=7)
    for _ in range(40):
        core.run(0.05)
        host.take(core)
    counters = host.decoder.counters()
    assert counters.crc_errors == counters.undecodable == counters.seq_gaps == 0
    assert counters.lost_samples == counters.dropped_samples == 0
    t_s = host.joined("t_s")
    config = host.decoder.config
    # The real rate ("833 Hz" is 833.33 Hz), trimmed, rounded as the Python driver computes it.
    assert config is not None and config.odr_mhz == lsm6dsox.odr_mhz(7, chip.unit.freq_fine)
    assert config.odr_mhz == pytest.approx(833_333 * chip.trim, abs=1)
    # Device time: the chip's trimmed clock, steady to within a tick.
    np.testing.assert_allclose(np.diff(t_s), 1000.0 / config.odr_mhz, atol=30e-6)
    assert not host.joined("gap").any()
    skip = core.counters()["settling"]  # the turn-on transient, dropped in the firmware
    assert 0 < skip <= lsm6dsox.turn_on_discard(833)
    truth = chip.truth()
    np.testing.assert_array_equal(host.joined("accel_raw"),
                                  truth["accel_raw"][skip:skip + len(t_s)])
    core.close()


def test_a_fifo_overrun_is_a_gap_the_host_measures(firmware_lib) -> None:
    core, bus, chip = make(firmware_lib)
    host = Host()
    start(core, host, odr_code=7)  # 833 Hz: the FIFO holds ~0.29 s
    core.run(0.5)
    host.take(core)
    bus.delay(1.0)  # the firmware is held up (say, by a debugger) for a second
    core.run(0.5)
    host.take(core)
    logs = [pk for pk in host.packets if isinstance(pk, p.Log) and pk.level == 2]
    assert logs and logs[0].text.startswith("FIFO overrun")
    t_s, gap = host.joined("t_s"), host.joined("gap")
    odr = host.decoder.config.odr_mhz / 1000.0
    index = np.rint(t_s * odr).astype(np.int64)
    steps = np.diff(index)
    assert np.all(steps >= 1)
    jumps = np.flatnonzero(steps > 1)
    assert len(jumps) == 1 and gap[jumps[0] + 1] and gap.sum() == 1
    lost = host.decoder.counters().lost_samples
    fifo_samples = 512 / 2.125  # 512 words, 2 per sample + a timestamp every 8th
    assert lost == steps[jumps[0]] - 1 > odr - fifo_samples - 50
    # The samples after the gap are the chip's samples at those indices.
    truth = chip.truth()
    rows = {int(i): k for k, i in enumerate(truth["index"])}
    first = jumps[0] + 1
    skip = core.counters()["settling"]
    np.testing.assert_array_equal(host.joined("accel_raw")[first],
                                  truth["accel_raw"][rows[int(truth["index"][skip] + index[first]
                                                              - index[0])]])
    assert core.counters()["overruns"] >= 1
    core.close()


def test_a_full_transmit_buffer_drops_packets_with_their_sequence_numbers(firmware_lib) -> None:
    core, _, _ = make(firmware_lib)
    host = Host()
    start(core, host, odr_code=6)
    core.run(0.3)
    host.take(core)
    core.set_tx_free(0)  # the host stops reading; the firmware must not block
    core.run(0.2)
    dropped = core.counters()["tx_dropped_packets"]
    assert dropped > 10
    core.set_tx_free(64 * 1024)
    core.run(0.3)
    host.take(core)
    counters = host.decoder.counters()
    assert counters.seq_gaps == 1
    t_s = host.joined("t_s")
    odr = host.decoder.config.odr_mhz / 1000.0
    steps = np.diff(np.rint(t_s * odr).astype(np.int64))
    assert counters.lost_samples == steps.max() - 1 > 0.15 * odr
    logs = [pk.text for pk in host.packets if isinstance(pk, p.Log)]
    assert f"{dropped} SAMPLES packets dropped: the host did not read the port fast enough" in logs
    core.close()


def test_the_sensor_unplugged_and_back_resumes_the_stream(firmware_lib) -> None:
    core, bus, _ = make(firmware_lib)
    host = Host()
    start(core, host, odr_code=5)
    core.run(0.5)
    host.take(core)
    before = len(host.joined("t_s"))
    bus.present = False
    core.run(1.0)
    host.take(core)
    assert core.led_mode == LED_ERROR and not core.streaming
    errors = [pk.text for pk in host.packets if isinstance(pk, p.Log) and pk.level == 3]
    assert errors == ["the LSM6DSOX at 0x6A stopped answering on I2C1; looking for it every 0.5 s"]
    bus.present = True
    core.run(1.0)
    host.take(core)
    assert core.streaming and core.led_mode == LED_STREAMING
    assert p.Log(1, "the LSM6DSOX answers again") in host.packets
    t_s, gap = host.joined("t_s"), host.joined("gap")
    assert len(t_s) > before + 150  # about 0.5 s at 208 Hz after the sensor came back
    assert np.all(np.diff(t_s) > 0) and gap[before:].sum() == 1
    core.close()


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals")
def test_the_app_connects_to_the_firmware_on_a_pty(firmware_lib, caplog) -> None:
    """The first connection, as a user makes it: the app's port driver opens the firmware."""
    def core() -> FirmwareCore:
        chip = EmulatedLsm6dsox(SimOptions("static", seed=8, scenario_params={"roll": 20.0}))
        return FirmwareCore(firmware_lib, chip, unique_id=bytes(range(12)))

    board = PtyBoard(core)
    device = create_device(f"{board.port}?odr=208")
    try:
        caplog.set_level(logging.INFO)
        device.open()
        info = device.info
        assert info.name == "NUCLEO-F746ZG" and info.firmware == "1.2.0"
        assert info.unique_id == bytes(range(12)).hex().upper()
        assert info.odr_nominal_hz == 208.0
        blocks: list[RawBlock] = []
        deadline = time.monotonic() + 10.0
        while sum(len(b) for b in blocks) < 200:
            assert time.monotonic() < deadline, "no samples from the firmware"
            block = device.read(0.2)
            if block is not None:
                blocks.append(block)
        accel = np.concatenate([b.accel_raw for b in blocks]).astype(float)
        roll = np.degrees(np.arctan2(accel[:, 1], accel[:, 2]))
        assert abs(np.median(roll) - 20.0) < 2.0
        assert device.counters.seq_gaps == device.counters.crc_errors == 0
        result = device.self_test()
        assert result.accel_pass and result.gyro_pass
    finally:
        device.close()
        board.close()


@pytest.mark.parametrize("idle_s", [0.0, 0.05, 1.0])
def test_the_transient_is_dropped_only_while_the_sensor_is_still_settling(firmware_lib,
                                                                          idle_s) -> None:
    core, _, chip = make(firmware_lib)
    core.send(p.Hello(), p.Configure(4, 4, 500))
    core.run(idle_s)  # the chip runs (and settles) from CONFIGURE on, streamed or not
    core.send(p.Start())
    core.run(0.5)
    settling = core.counters()["settling"]
    produced = idle_s * lsm6dsox.odr_mhz(4, chip.unit.freq_fine) / 1000.0
    needed = lsm6dsox.turn_on_discard(104)  # 14 samples at "104 Hz"
    # What was produced before START counts, 2 % short (an MCU clock running fast).
    assert needed - produced <= settling <= max(0.0, needed - 0.98 * produced) + 1
    samples = samples_of(core.packets())
    assert samples and samples[0].seq == 0  # dropping is not a loss: no sequence skipped
    core.close()
