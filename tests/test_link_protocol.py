"""NUCLEO link protocol v1: test vectors, packet round trips, framing and the decoder's counters.

The vectors in ``tests/vectors/link_v1.json`` are checked three ways: against the codec, against
an independent reference COBS encoder written from the paper here, and against the copy in
``docs/protocol.md``.
"""

from __future__ import annotations

import binascii
import json
import os
import select
import tty
from pathlib import Path

import numpy as np
import pytest

from drivers import lsm6dsox
from drivers.link import protocol as p
from drivers.link.decoder import LinkDecoder
from drivers.link.framing import (
    MAX_FRAME_BYTES,
    FrameError,
    FrameSplitter,
    crc16,
    encode_packet,
    frame_bytes,
    unframe,
)

ROOT = Path(__file__).resolve().parent.parent
VECTORS = json.loads((ROOT / "tests" / "vectors" / "link_v1.json").read_text())["vectors"]
CONFIG_104 = p.Config(104_000, 4, 250, 25_000)
TICKS_104 = 1e12 / (104_000 * 25_000)  # ticks per sample at 104 Hz


def reference_cobs_encode(data: bytes) -> bytes:
    """COBS as in Cheshire & Baker (1999), written independently of the codec under test."""
    out = bytearray()
    block = bytearray()
    for byte in data:
        if byte == 0:
            out += bytes((len(block) + 1,)) + block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out += b"\xff" + block
                block.clear()
    out += bytes((len(block) + 1,)) + block
    return bytes(out)


def hex_bytes(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def packet_from_fields(vector: dict) -> p.Packet:
    fields = dict(vector["fields"])
    cls = p.PACKET_CLASSES[vector["type"]]
    if cls is p.Info:
        return p.Info(fields["protocol_version"], tuple(fields["firmware"]), fields["who_am_i"],
                      bytes.fromhex(fields["unique_id_hex"]), fields["name"])
    if cls is p.Samples:
        return p.Samples(fields["seq"], fields["t0"], fields["temperature_raw"],
                         np.array(fields["samples"], dtype=np.int16))
    if cls is p.SelfTestResult:
        return p.SelfTestResult(bool(fields["accel_pass"]), bool(fields["gyro_pass"]),
                                tuple(fields["accel_delta_mg"]), tuple(fields["gyro_delta_dps"]))
    if cls is p.SamplesIndexed:
        return p.SamplesIndexed(fields["sensor_index"], p.Samples(
            fields["seq"], fields["t0"], fields["temperature_raw"],
            np.array(fields["samples"], dtype=np.int16)))
    return cls(**fields)


def samples_packet(seq: int, t0: int, count: int = 4, temperature: int = 0,
                   first_value: int = 0) -> p.Samples:
    values = np.arange(first_value, first_value + 6 * count).reshape(count, 6)
    return p.Samples(seq, t0, temperature, values.astype(np.int16))


# -- vectors ------------------------------------------------------------------------------------
def test_crc_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1
    assert binascii.crc_hqx(b"123456789", 0xFFFF) == 0x29B1


def test_vectors_cover_every_packet_type():
    assert {v["type"] for v in VECTORS} == set(p.PACKET_CLASSES)


@pytest.mark.parametrize("vector", VECTORS, ids=[v["name"] for v in VECTORS])
def test_vector_byte_for_byte(vector):
    packet = packet_from_fields(vector)
    body = hex_bytes(vector["packet_hex"])
    frame = hex_bytes(vector["frame_hex"])
    crc = int(vector["crc_hex"], 16)
    # Building: the codec produces exactly the frame.
    assert bytes((packet.TYPE,)) + packet.payload() == body
    assert crc16(body) == crc
    assert encode_packet(packet) == frame
    # An independent COBS encoder agrees.
    assert reference_cobs_encode(body + crc.to_bytes(2, "little")) + b"\x00" == frame
    # Parsing: the frame gives back the packet.
    assert frame[-1] == 0 and 0 not in frame[:-1]
    assert unframe(frame[:-1]) == body
    assert p.parse_packet(body[0], body[1:]) == packet


def test_protocol_page_quotes_the_vectors():
    page = " ".join((ROOT / "docs" / "protocol.md").read_text().split())
    for vector in VECTORS:
        assert f"frame: {vector['frame_hex']}" in page, vector["name"]
        assert f"packet: {vector['packet_hex']}" in page, vector["name"]


def test_long_vector_exercises_the_254_byte_cobs_run():
    frame = hex_bytes(next(v for v in VECTORS if "32 samples" in v["name"])["frame_hex"])
    assert frame[0] == 0xFF


# -- packets ------------------------------------------------------------------------------------
ROUND_TRIP = [
    p.Info(1, (2, 5, 11), 0x6C, bytes(range(12)), "NUCLEO-F746ZG µ"),
    p.Info(1, (0, 0, 0), 0x6A, b"\x00" * 12, ""),
    p.Config(6_667_000, 16, 2000, 24_888),
    samples_packet(65535, 2**32 - 1, count=32, temperature=-32768),
    samples_packet(0, 0, count=1, temperature=32767, first_value=-32768),
    p.Ack(p.CONFIGURE, p.ACK_BUSY, "streaming; send STOP first"),
    p.SelfTestResult(False, True, (-1, 0, 32767), (-32768, 5, 6)),
    p.Log(3, "sensor error ✓"),
    p.Pong(0), p.Pong(2**32 - 1),
    p.Hello(), p.Configure(10, 16, 2000), p.Start(), p.Stop(), p.SelfTest(), p.Ping(12345),
    p.Status(1, 0, 0, *([0] * 10)), p.Status(3, 7, 7, *([2**32 - 1] * 10), extra=b"\x00\x01"),
    p.GetStatus(),
]


@pytest.mark.parametrize("packet", ROUND_TRIP, ids=lambda pkt: type(pkt).__name__)
def test_every_packet_type_round_trips(packet):
    body = unframe(encode_packet(packet)[:-1])
    assert body[0] == packet.TYPE
    assert p.parse_packet(body[0], body[1:]) == packet


@pytest.mark.parametrize(
    ("packet_type", "payload", "problem"),
    [
        (p.CONFIG, b"\x00" * 10, "11"),
        (p.CONFIG, p.Config(104_000, 3, 250, 25_000).payload(), "accel_fs_g=3"),
        (p.CONFIG, p.Config(104_000, 4, 300, 25_000).payload(), "gyro_fs_dps=300"),
        (p.CONFIG, p.Config(0, 4, 250, 25_000).payload(), "odr_mhz=0"),
        (p.SAMPLES, samples_packet(1, 2).payload()[:-1], "expected"),
        (p.SAMPLES, b"\x01\x00\x00\x00\x00\x00\x00\x00\x00", "count is 0"),
        (p.SAMPLES, b"\x01\x00\x00\x00\x00\x00\x21\x00\x00" + bytes(396), "count is 33"),
        (p.INFO, b"\x01" * 16, "at least 17"),
        (p.ACK, b"\x83", "at least 2"),
        (p.SELFTEST, b"\x00" * 13, "14"),
        (p.LOG, b"", "empty"),
        (p.PONG, b"\x00" * 5, "4"),
        (p.HELLO, b"\x00", "expected 0"),
        (p.CONFIGURE, b"\x04\x04", "expected 4"),
    ],
)
def test_malformed_payloads_are_refused(packet_type, payload, problem):
    with pytest.raises(p.PacketError, match=problem):
        p.parse_packet(packet_type, payload)


def test_unknown_type_is_its_own_error():
    with pytest.raises(p.UnknownPacketType):
        p.parse_packet(0x42, b"")


def test_samples_accessors_and_limits():
    packet = samples_packet(7, 100, count=3)
    assert packet.count == 3
    assert packet.gyro_raw.tolist() == [[0, 1, 2], [6, 7, 8], [12, 13, 14]]
    assert packet.accel_raw[0].tolist() == [3, 4, 5]
    with pytest.raises(p.PacketError):
        samples_packet(0, 0, count=33).payload()
    with pytest.raises(ValueError):
        frame_bytes(p.LOG, bytes(510))


# -- framing ------------------------------------------------------------------------------------
def test_unframe_sorts_bad_frames_into_crc_and_undecodable():
    frame = encode_packet(p.Pong(7))[:-1]
    broken = bytearray(frame)
    broken[2] ^= 0x01
    with pytest.raises(FrameError) as crc:
        unframe(bytes(broken))
    assert crc.value.kind == "crc"
    for bad in (b"\x05\x01\x02", b"\x01", b"\x02\x03", bytes([1]) * (MAX_FRAME_BYTES + 1)):
        with pytest.raises(FrameError) as undecodable:
            unframe(bad)
        assert undecodable.value.kind == "undecodable"


def test_splitter_handles_any_chunking_and_overlong_runs():
    stream = b"".join(encode_packet(p.Pong(i)) for i in range(50))
    for chunk in (1, 2, 3, 7, 64, len(stream)):
        splitter = FrameSplitter()
        frames = [frame for i in range(0, len(stream), chunk)
                  for frame in splitter.feed(stream[i:i + chunk])]
        assert [unframe(f) for f in frames] == [bytes((p.PONG,)) + p.Pong(i).payload()
                                                for i in range(50)]
    splitter = FrameSplitter()
    junk = b"\x01" * 2000
    assert splitter.feed(junk[:700]) == [] and splitter.feed(junk[700:]) == []
    frames = splitter.feed(b"\x00\x00" + encode_packet(p.Pong(1)))
    assert frames == [encode_packet(p.Pong(1))[:-1]]
    assert splitter.oversized == 1


# -- decoder ------------------------------------------------------------------------------------
def feed_all(decoder: LinkDecoder, *packets: p.Packet, chunk: int = 0) -> list:
    stream = b"".join(encode_packet(packet) for packet in packets)
    chunk = chunk or len(stream)
    others = []
    for i in range(0, len(stream), chunk):
        others += decoder.feed(stream[i:i + chunk])
    return others


def take_all(decoder: LinkDecoder):
    from app.core.samples import RawBlock

    blocks = decoder.take_blocks()
    assert blocks, "no block"
    scale = blocks[0].scale
    return RawBlock(
        t_s=np.concatenate([b.t_s for b in blocks]),
        accel_raw=np.concatenate([b.accel_raw for b in blocks]),
        gyro_raw=np.concatenate([b.gyro_raw for b in blocks]),
        temp_raw=np.concatenate([b.temp_raw for b in blocks]),
        scale=scale, gap=np.concatenate([b.gap for b in blocks]),
        lost_samples=sum(b.lost_samples for b in blocks),
    )


def test_decoder_builds_raw_blocks_with_units_time_and_temperature():
    decoder = LinkDecoder()
    others = feed_all(decoder, CONFIG_104, samples_packet(10, 1000, count=3, temperature=512),
                      samples_packet(11, 1000 + round(3 * TICKS_104), count=2, temperature=-256),
                      chunk=5)
    assert others == [CONFIG_104]
    block = take_all(decoder)
    assert len(block) == 5
    assert block.gyro_raw.dtype == np.int16 and block.gyro_raw.shape == (5, 3)
    assert block.gyro_raw[0].tolist() == [0, 1, 2] and block.accel_raw[0].tolist() == [3, 4, 5]
    assert block.accel_raw[4].tolist() == [9, 10, 11]  # second packet, second sample
    np.testing.assert_allclose(block.t_s, np.arange(5) / 104.0, atol=25e-6)
    assert block.temp_raw.tolist() == [512, 512, 512, -256, -256]
    assert block.scale.accel_m_s2_per_lsb == pytest.approx(0.122e-3 * 9.80665)
    assert block.scale.gyro_rad_s_per_lsb == pytest.approx(np.radians(8.75e-3))
    assert 512 * block.scale.temp_degc_per_lsb + block.scale.temp_offset_degc == 27.0
    assert not block.gap.any() and block.lost_samples == 0
    counters = decoder.counters()
    assert (counters.packets, counters.samples) == (3, 5)
    assert decoder.clock_origin_s == pytest.approx(1000 * 25e-6)


def test_decoder_times_and_gap_estimates_use_the_real_rate_the_board_reports():
    """The firmware reports "12.5 Hz" as its real 13.021 Hz (docs/protocol.md section 5)."""
    config = p.Config(lsm6dsox.odr_mhz(1), 4, 250, 25_000)
    ticks = 1e12 / (config.odr_mhz * config.tick_ns)  # 3072 ticks a sample, not 3200
    decoder = LinkDecoder()
    feed_all(decoder, config, samples_packet(0, 0, count=3),
             samples_packet(2, round(13 * ticks), count=2))  # seq 1 (10 samples) was lost
    block = take_all(decoder)
    np.testing.assert_allclose(block.t_s[:3], np.arange(3) / 13.021, rtol=1e-9)
    assert block.t_s[3] == pytest.approx(13 / 13.0208, rel=1e-4)
    assert block.gap[3] and block.lost_samples == 10  # 13 - 3 samples, at the real rate


def test_every_counter():
    decoder = LinkDecoder()
    good = encode_packet(samples_packet(0, 0, count=4))
    bad_crc = bytearray(encode_packet(samples_packet(1, round(4 * TICKS_104), count=4)))
    bad_crc[20] ^= 0x10
    stream = b"".join([
        encode_packet(samples_packet(99, 0, count=2)),  # before any CONFIG: dropped
        encode_packet(CONFIG_104), good,
        bytes(bad_crc),  # seq 1 fails the CRC
        encode_packet(samples_packet(2, round(8 * TICKS_104), count=4)),  # gap: seq 1 missing
        encode_packet(samples_packet(2, round(8 * TICKS_104), count=4)),  # duplicate
        b"\x05\x01\x02\x00",  # bad COBS
        frame_bytes(p.SAMPLES, samples_packet(3, 0).payload()[:-2]),  # wrong length
        frame_bytes(0x42, b"new type"),  # unknown
        b"\x01" * 600 + b"\x00",  # overlong run
        encode_packet(p.Log(1, "hi")),
    ])
    others = decoder.feed(stream)
    assert others == [CONFIG_104, p.Log(1, "hi")]
    counters = decoder.counters()
    assert counters.bytes_received == len(stream)
    assert counters.packets == 6  # sample before config, config, 2 good + 1 duplicate, log
    assert counters.samples == 8
    assert counters.crc_errors == 1
    assert counters.undecodable == 3
    assert counters.unknown_packets == 1
    assert counters.seq_gaps == 1
    assert counters.lost_samples == 4  # from the timestamps: the missing packet held 4
    assert counters.dropped_samples == 2 + 4
    block = take_all(decoder)
    assert block.gap.tolist() == [False] * 4 + [True] + [False] * 3
    assert block.lost_samples == 4
    np.testing.assert_allclose(block.t_s[4], 8 / 104.0, atol=25e-6)


def test_gap_estimate_never_below_the_missing_packets():
    decoder = LinkDecoder(CONFIG_104)
    # Three packets missing, but timestamps claim no time passed: still 3 lost (>= 1 each).
    feed_all(decoder, samples_packet(0, 0, count=1), samples_packet(4, round(TICKS_104), count=1))
    assert decoder.counters().lost_samples == 3


def test_timestamp_and_sequence_wrap_without_gaps():
    decoder = LinkDecoder(CONFIG_104)
    t0 = 2**32 - 3 * round(8 * TICKS_104)
    packets = []
    for i in range(8):
        packets.append(samples_packet((65533 + i) & 0xFFFF, (t0 + round(8 * i * TICKS_104))
                                      & 0xFFFFFFFF, count=8))
    feed_all(decoder, *packets, chunk=13)
    block = take_all(decoder)
    assert decoder.counters().seq_gaps == 0 and not block.gap.any()
    np.testing.assert_allclose(np.diff(block.t_s), 1 / 104.0, atol=30e-6)


def test_clock_restart_keeps_time_increasing():
    decoder = LinkDecoder(CONFIG_104)
    feed_all(decoder, samples_packet(10, 1_000_000, count=4), samples_packet(11, 500, count=4),
             samples_packet(12, 500 + round(4 * TICKS_104), count=4))
    block = take_all(decoder)
    assert np.all(np.diff(block.t_s) > 0)
    assert block.gap.tolist() == [False] * 4 + [True] + [False] * 7
    assert decoder.counters().seq_gaps == 1 and decoder.counters().lost_samples == 0


def test_config_change_splits_blocks_with_their_own_scale():
    decoder = LinkDecoder(CONFIG_104)
    other = p.Config(208_000, 16, 2000, 25_000)
    feed_all(decoder, samples_packet(0, 0, count=2), other,
             samples_packet(1, round(2 * TICKS_104), count=2))
    first, second = decoder.take_blocks()
    assert first.scale.accel_m_s2_per_lsb == pytest.approx(lsm6dsox.accel_m_s2_per_lsb(4))
    assert second.scale.accel_m_s2_per_lsb == pytest.approx(lsm6dsox.accel_m_s2_per_lsb(16))
    np.testing.assert_allclose(second.t_s, [2 / 104, 2 / 104 + 1 / 208], atol=30e-6)
    # Another tick length is another time base: time goes on, with a gap.
    feed_all(decoder, p.Config(208_000, 16, 2000, 20_000), samples_packet(2, 123, count=1))
    (third,) = decoder.take_blocks()
    assert third.gap[0] and third.t_s[0] > second.t_s[-1]


def test_samples_before_the_start_ack_are_dropped():
    decoder = LinkDecoder(CONFIG_104)
    feed_all(decoder, samples_packet(0, 0))
    decoder.take_blocks()
    decoder.arm_start(new_origin=True)
    feed_all(decoder, samples_packet(1, 10_000), p.Ack(p.START, p.ACK_OK),
             samples_packet(50, 20_000, count=2))
    (block,) = decoder.take_blocks()
    assert len(block) == 2 and block.t_s[0] == 0.0 and not block.gap.any()
    assert decoder.counters().dropped_samples == 4
    # A pause (self-test): time goes on and the restart is marked.
    decoder.arm_start(new_origin=False, mark_gap=True)
    feed_all(decoder, p.Ack(p.START, p.ACK_OK), samples_packet(70, 30_000, count=1))
    (block,) = decoder.take_blocks()
    assert block.gap[0] and block.t_s[0] == pytest.approx(10_000 * 25e-6)


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="pseudo-terminals")
def test_every_packet_type_round_trips_through_a_pty():
    """All packets, both directions' types, through a real pseudo-terminal pair."""
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        config = p.Config(6_667_000, 16, 2000, 24_888)
        packets = [config, *ROUND_TRIP]
        stream = b"".join(encode_packet(packet) for packet in packets)
        os.write(master, stream)
        received = b""
        while len(received) < len(stream):
            ready, _, _ = select.select([slave], [], [], 5.0)
            assert ready, "the pseudo-terminal delivered nothing"
            received += os.read(slave, 4096)
    finally:
        os.close(master)
        os.close(slave)
    assert received == stream
    decoder = LinkDecoder()
    others = decoder.feed(received)
    assert others == [packet for packet in packets if not isinstance(packet, p.Samples)]
    samples = [packet for packet in packets if isinstance(packet, p.Samples)]
    rows = np.concatenate([np.hstack([b.gyro_raw, b.accel_raw]) for b in decoder.take_blocks()])
    assert np.array_equal(rows, np.concatenate([packet.data for packet in samples]))
    counters = decoder.counters()
    assert counters.packets == len(packets) and counters.crc_errors == counters.undecodable == 0
