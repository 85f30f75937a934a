"""Two LSM6DSOX on one board (docs/protocol.md, "Several sensors on one board", a v1 extension).

The firmware's own core streams two emulated chips on one I2C bus (0x6A and 0x6B) in virtual
time; the app's decoder follows each sensor; a v1 reader that predates the extension (the
decoder as it was before it, taken from git) still gets sensor 0 intact from the same bytes.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fwcore import FirmwareCore, SharedBus

from drivers import lsm6dsox
from drivers.link import protocol as p
from drivers.link.decoder import LinkDecoder
from drivers.link.framing import FrameSplitter, encode_packet, unframe
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.sim.options import SimOptions

ROOT = Path(__file__).resolve().parent.parent
V1_READER_COMMIT = "af5deac"
"""The last commit before the multi-sensor extension: its decoder knows SAMPLES and STATUS
only, as every host in the field does."""


# -- the packets ----------------------------------------------------------------------------------
def test_samples_indexed_refuses_sensor_0_and_wrong_lengths() -> None:
    inner = p.Samples(1, 2, 3, np.zeros((2, 6), dtype=np.int16))
    good = p.SamplesIndexed(1, inner).payload()
    assert p.parse_packet(p.SAMPLES_INDEXED, good) == p.SamplesIndexed(1, inner)
    with pytest.raises(p.PacketError, match="sensor_index"):
        p.parse_packet(p.SAMPLES_INDEXED, b"\x00" + good[1:])
    with pytest.raises(p.PacketError, match="expected"):
        p.parse_packet(p.SAMPLES_INDEXED, good[:-1])
    with pytest.raises(p.PacketError):
        p.SamplesIndexed(0, inner).payload()


def test_sensor_packet_checks_index_and_settings() -> None:
    sensor = p.Sensor(1, 2, 0x6B, 0x6C, 104_323, 4, 250, 24_963)
    assert p.parse_packet(p.SENSOR, sensor.payload()) == sensor
    assert sensor.config == p.Config(104_323, 4, 250, 24_963) and sensor.answering
    with pytest.raises(p.PacketError, match="index 2 of 2"):
        p.parse_packet(p.SENSOR, p.Sensor(2, 2, 0x6B, 0x6C, 1, 4, 250, 1).payload())
    with pytest.raises(p.PacketError, match="accel_fs_g"):
        p.parse_packet(p.SENSOR, p.Sensor(0, 1, 0x6A, 0x6C, 1, 3, 250, 1).payload())


def test_decoder_follows_its_sensor_with_its_own_sequence_and_clock() -> None:
    rows = np.arange(24, dtype=np.int16).reshape(4, 6)
    stream = b"".join(encode_packet(pk) for pk in (
        p.Config(104_167, 4, 250, 25_000),
        p.Sensor(0, 2, 0x6A, 0x6C, 104_167, 4, 250, 25_000),
        p.Sensor(1, 2, 0x6B, 0x6C, 104_323, 4, 250, 24_963),
        p.Samples(0, 1000, 0, rows),
        p.SamplesIndexed(1, p.Samples(7, 50, 0, rows + 100)),
        p.Samples(1, 1000 + 4 * 384, 0, rows),
        p.SamplesIndexed(1, p.Samples(9, 50 + 8 * 384, 0, rows + 100)),  # seq 8 lost
    ))
    zero, one = LinkDecoder(), LinkDecoder(sensor=1)
    zero.feed(stream)
    one.feed(stream)
    a0 = np.concatenate([b.gyro_raw for b in zero.take_blocks()])
    blocks1 = one.take_blocks()
    a1 = np.concatenate([b.gyro_raw for b in blocks1])
    assert np.array_equal(a0, np.vstack([rows, rows])[:, 0:3])
    assert np.array_equal(a1, np.vstack([rows, rows])[:, 0:3] + 100)
    assert one.config == p.Config(104_323, 4, 250, 24_963)
    assert zero.counters().seq_gaps == 0 and zero.counters().other_sensor_packets == 2
    assert one.counters().seq_gaps == 1 and one.counters().lost_samples == 4
    assert np.concatenate([b.gap for b in blocks1]).tolist() == [False] * 4 + [True] + [False] * 3


# -- the firmware core with two chips ----------------------------------------------------------
def two_chip_core(firmware_lib):
    clock = VirtualClock(50.0)
    chips = [EmulatedLsm6dsox(SimOptions("wobble", seed=seed), address=address, clock=clock,
                              record_truth=True)
             for seed, address in ((6, 0x6A), (7, 0x6B))]
    return FirmwareCore(firmware_lib, SharedBus(*chips)), chips


def packets_of(data: bytes) -> list[p.Packet]:
    return [p.parse_packet(body[0], body[1:])
            for body in map(unframe, FrameSplitter().feed(data))]


def load_v1_reader(tmp_path: Path):
    """The decoder before the extension, from git, as a package of its own (``v1link``)."""
    package = tmp_path / "v1link"
    package.mkdir()
    (package / "__init__.py").write_text("")
    for name in ("decoder", "protocol", "framing"):
        source = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{V1_READER_COMMIT}:drivers/link/{name}.py"],
            capture_output=True, text=True, check=True).stdout
        source = source.replace("from drivers.link import protocol", "from v1link import protocol")
        source = source.replace("from drivers.link.", "from v1link.")
        (package / f"{name}.py").write_text(source)
    sys.path.insert(0, str(tmp_path))
    try:
        decoder = importlib.import_module("v1link.decoder")
    finally:
        sys.path.remove(str(tmp_path))
    assert not hasattr(decoder.p, "SAMPLES_INDEXED")  # really the reader before the extension
    return decoder


def test_the_firmware_streams_both_sensors_and_a_v1_reader_still_gets_sensor_0(
        firmware_lib, tmp_path) -> None:
    core, chips = two_chip_core(firmware_lib)
    assert core.sensor_count == 2
    wire = bytearray()
    core.send(p.Hello())
    hello = packets_of(core.take_output())
    sensors = [pk for pk in hello if isinstance(pk, p.Sensor)]
    assert [type(pk) for pk in hello] == [p.Info, p.Config, p.Sensor, p.Sensor]
    assert [(s.sensor_index, s.sensor_count, s.i2c_address) for s in sensors] == [
        (0, 2, 0x6A), (1, 2, 0x6B)]
    # Each SENSOR reports its own chip's trimmed clock; sensor 0's equals CONFIG.
    assert sensors[0].config == hello[1]
    assert sensors[1].odr_mhz == lsm6dsox.odr_mhz(4, chips[1].unit.freq_fine)
    # 1667 Hz does not fit two sensors on I2C at 400 kHz: refused with the reason.
    core.send(p.Configure(8, 4, 500))
    refused = packets_of(core.take_output())
    assert refused[0] == p.Ack(p.CONFIGURE, p.ACK_BAD_ARGUMENT, refused[0].message)
    assert "for 2 sensors" in refused[0].message and "highest ODR 833 Hz" in refused[0].message
    core.send(p.Configure(7, 4, 500))
    wire += core.take_output()
    core.send(p.Start())
    core.run(2.0)
    core.send(p.Stop())
    wire += core.take_output()
    packets = packets_of(bytes(wire))
    indexed = [pk for pk in packets if isinstance(pk, p.SamplesIndexed)]
    plain = [pk for pk in packets if isinstance(pk, p.Samples)]
    assert {pk.sensor_index for pk in indexed} == {1}
    # Sequence numbers per sensor, each from 0 without a hole.
    assert [pk.samples.seq for pk in indexed] == list(range(len(indexed)))
    assert [pk.seq for pk in plain] == list(range(len(plain)))

    decoders = [LinkDecoder(sensor=0), LinkDecoder(sensor=1)]
    for index, (decoder, chip) in enumerate(zip(decoders, chips, strict=True)):
        decoder.feed(bytes(wire))
        blocks = decoder.take_blocks()
        data = np.hstack([np.concatenate([b.gyro_raw for b in blocks]),
                          np.concatenate([b.accel_raw for b in blocks])])
        truth = chip.truth()
        truth_rows = np.hstack([truth["gyro_raw"], truth["accel_raw"]])
        skip = lsm6dsox.turn_on_discard(833)  # settling dropped (less what passed before START)
        starts = [k for k in range(skip + 1)
                  if np.array_equal(truth_rows[k:k + len(data)], data)]
        assert starts, f"sensor {index}: not its chip's samples, in order"
        assert len(data) > 0.9 * 2.0 * 833
        counters = decoder.counters()
        assert counters.seq_gaps == counters.crc_errors == counters.undecodable == 0
        # Device time at that chip's own trimmed rate.
        t_s = np.concatenate([b.t_s for b in blocks])
        np.testing.assert_allclose(np.diff(t_s), 1000.0 / decoder.config.odr_mhz, atol=30e-6)
    assert decoders[0].config.odr_mhz != decoders[1].config.odr_mhz  # two trims, two clocks

    # A reader of plain v1 skips the new types (rule 7) and sees sensor 0 exactly as the new one.
    v1 = load_v1_reader(tmp_path).LinkDecoder()
    v1.feed(bytes(wire))
    old_blocks = v1.take_blocks()
    new = LinkDecoder()
    new.feed(bytes(wire))
    new_blocks = new.take_blocks()
    for name in ("t_s", "accel_raw", "gyro_raw", "gap"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, name) for b in old_blocks]),
                                      np.concatenate([getattr(b, name) for b in new_blocks]))
    old = v1.counters()
    assert old.unknown_packets == len(indexed) + 2  # SAMPLES_INDEXED and the two SENSOR
    assert old.crc_errors == old.undecodable == old.seq_gaps == 0
    core.close()


def test_one_chip_board_sends_plain_v1(firmware_lib) -> None:
    clock = VirtualClock(50.0)
    chip = EmulatedLsm6dsox(SimOptions("static", seed=3), address=0x6B, clock=clock)
    core = FirmwareCore(firmware_lib, SharedBus(chip))
    assert core.sensor_count == 1
    core.send(p.Hello(), p.Configure(8, 4, 500), p.Ping(5))  # 1667 Hz fits one sensor
    packets = packets_of(core.take_output())
    # No SENSOR: the answers are those of plain v1, and PONG comes right after them.
    assert [type(pk) for pk in packets] == [p.Info, p.Config, p.Ack, p.Config, p.Pong]
    assert packets[2] == p.Ack(p.CONFIGURE, p.ACK_OK)
    core.close()
