"""The magnetometer on the NUCLEO link (docs/protocol.md, "A magnetometer beside the sensor",
a v1 extension): MAGNETOMETER and MAG_SAMPLES, STATUS version 2, the decoder placing field
samples on accelerometer rows, the emulated board's LIS3MDL and LIS2MDL through the real serial
driver, and a host from before the extension (its decoder taken from git) reading the new
stream unchanged.
"""

from __future__ import annotations

import os
import select
import time
from pathlib import Path

import numpy as np
import pytest
from old_link_reader import load_old_decoder
from test_two_sensors import read_samples

from app.core.devices import BoardStatus
from app.core.earth_field import DEFAULT_PLACE, earth_field
from app.services.board_health import describe_rise
from drivers import magnetometers
from drivers.emulated_nucleo import MAG_FIELD_DATE, EmulatedNucleo, mag_fits
from drivers.link import protocol as p
from drivers.link.client import board_status_of
from drivers.link.decoder import LinkDecoder
from drivers.link.framing import FrameSplitter, encode_packet, unframe
from drivers.registry import create_device
from drivers.sim.device import SimulatedDevice

PRE_MAG_COMMIT = "8b3bdf3"
"""The last commit before the magnetometer extension: its decoder knows SAMPLES, STATUS,
SAMPLES_INDEXED and SENSOR, as every host built before it does."""


def load_pre_mag_reader(tmp_path: Path):
    """The decoder before the magnetometer extension (``premag``)."""
    decoder = load_old_decoder(tmp_path, PRE_MAG_COMMIT, "premag")
    assert not hasattr(decoder.p, "MAG_SAMPLES")  # really the reader before the extension
    return decoder


CONFIG = p.Config(104_167, 4, 250, 25_000)
TICKS_PER_SAMPLE = 1e12 / (CONFIG.odr_mhz * CONFIG.tick_ns)  # 384 ticks at 104.17 Hz
LIS3MDL_PACKET = p.Magnetometer(magnetometers.CHIP_LIS3MDL, 0x1C, 0x3D, 80_000, 400, 14_616,
                                magnetometers.MODE_ULTRA_HIGH_PERFORMANCE)


def samples(seq: int, t0: int, count: int, first_value: int = 0) -> p.Samples:
    rows = (np.arange(count * 6, dtype=np.int64).reshape(count, 6) + first_value) % 30000
    return p.Samples(seq, t0, 256, rows.astype(np.int16))


# -- the packets ----------------------------------------------------------------------------------
def test_mag_packets_round_trip_and_refuse_what_does_not_fit() -> None:
    mag = p.MagSamples(65535, np.array([4294967295, 7], dtype=np.uint32),
                       np.array([[1, -2, 3], [-32768, 32767, 0]], dtype=np.int16))
    body = mag.payload()
    assert len(body) == 3 + 2 * 10
    assert p.parse_packet(p.MAG_SAMPLES, body) == mag
    assert p.parse_packet(p.MAGNETOMETER, LIS3MDL_PACKET.payload()) == LIS3MDL_PACKET
    assert len(LIS3MDL_PACKET.payload()) == 15  # 16 bytes with the type byte
    with pytest.raises(p.PacketError, match="count 0"):
        p.MagSamples.from_payload(bytes([1, 0, 0]))
    with pytest.raises(p.PacketError, match="expected"):
        p.MagSamples.from_payload(body[:-1])
    with pytest.raises(p.PacketError, match="odr_mhz"):
        p.Magnetometer.from_payload(LIS3MDL_PACKET.payload()[:3] + bytes(4)
                                    + LIS3MDL_PACKET.payload()[7:])


def test_status_version_2_carries_the_magnetometers_i2c_errors_and_v1_reads_none() -> None:
    v1 = p.Status(1, 1, 3, 1000, 0, 0, 4, 0, 0, 0, 100, 100, 0)
    v2 = p.Status(2, 1, 3, 2000, 0, 0, 9, 0, 0, 0, 300, 300, 0, extra=p.Status.mag_extra(5, 160, 2))
    assert v1.mag_i2c_errors is None and v1.mag_samples_read is None
    parsed = p.parse_packet(p.STATUS, v2.payload())
    assert (parsed.mag_i2c_errors, parsed.mag_samples_read, parsed.mag_overruns) == (5, 160, 2)
    before, after = board_status_of(v1), board_status_of(parsed)
    assert (before.mag_i2c_errors, after.mag_i2c_errors) == (0, 5)
    assert "mag_i2c_errors" in BoardStatus.COUNTERS
    texts = [m.text for m in describe_rise(before, after)]
    assert "board: 5 failed I2C transfers to the magnetometer (field samples lost)" in texts


# -- the decoder ----------------------------------------------------------------------------------
def test_field_samples_land_on_the_first_row_at_or_after_their_time() -> None:
    decoder = LinkDecoder()
    decoder.arm_start(new_origin=True)
    t0 = 1000
    # Field samples at rows 0, 2.5 (-> row 3), 31 exactly; 40.2 waits for the next packet.
    ticks = np.array([t0, t0 + 2.5 * TICKS_PER_SAMPLE, t0 + 31 * TICKS_PER_SAMPLE,
                      t0 + 40.2 * TICKS_PER_SAMPLE]).round().astype(np.uint32)
    xyz = np.array([[100, 200, 300], [-1, -2, -3], [7, 8, 9], [40, 41, 42]], dtype=np.int16)
    stream = b"".join(encode_packet(pk) for pk in (
        CONFIG, LIS3MDL_PACKET, p.Ack(p.START, p.ACK_OK), p.MagSamples(0, ticks, xyz),
        samples(0, t0, 32)))
    decoder.feed(stream)
    (block,) = decoder.take_blocks()
    assert block.scale.mag_ut_per_lsb == pytest.approx(0.014616)
    assert block.mag_raw.shape == (32, 3)
    placed = np.flatnonzero(~np.isnan(block.mag_raw[:, 0]))
    assert placed.tolist() == [0, 3, 31]
    np.testing.assert_array_equal(block.mag_raw[placed], xyz[:3])
    # The next packet brings row 40; a field sample older than the rows already delivered
    # (row 20, arriving late) is dropped and counted, never put on a later row.
    late = np.array([t0 + 20 * TICKS_PER_SAMPLE], dtype=np.uint32)
    decoder.feed(encode_packet(p.MagSamples(1, late, xyz[:1]))
                 + encode_packet(samples(1, t0 + round(32 * TICKS_PER_SAMPLE), 32)))
    (block,) = decoder.take_blocks()
    placed = np.flatnonzero(~np.isnan(block.mag_raw[:, 0]))
    assert placed.tolist() == [41 - 32]  # 40.2 -> row 41
    np.testing.assert_array_equal(block.mag_raw[placed], xyz[3:])
    counters = decoder.counters()
    assert (counters.mag_samples, counters.mag_late, counters.mag_seq_gaps) == (4, 1, 0)
    assert counters.undecodable == 0


def test_a_paused_magnetometer_gives_no_field_column() -> None:
    decoder = LinkDecoder()
    paused = p.Magnetometer(*[getattr(LIS3MDL_PACKET, f) for f in (
        "chip", "i2c_address", "who_am_i", "odr_mhz", "range_ut", "pt_per_lsb", "mode")],
        flags=p.MAG_FLAG_ANSWERING | p.MAG_FLAG_PAUSED)
    decoder.feed(b"".join(encode_packet(pk) for pk in (CONFIG, paused, samples(0, 0, 4))))
    (block,) = decoder.take_blocks()
    assert decoder.magnetometer == paused and block.mag_raw is None


# -- a host built before the extension ----------------------------------------------------------
def capture_emulated_stream(board: EmulatedNucleo, seconds: float) -> bytes:
    """What the emulated board sends after HELLO and START, read straight off its port."""
    fd = os.open(board.port, os.O_RDWR | os.O_NOCTTY)
    try:
        import tty

        tty.setraw(fd)
        os.write(fd, b"\x00" + encode_packet(p.Hello()) + encode_packet(p.Start()))
        data = bytearray()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ready, _, _ = select.select([fd], [], [], 0.05)
            if ready:
                data += os.read(fd, 65536)
        os.write(fd, encode_packet(p.Stop()))
        return bytes(data)
    finally:
        os.close(fd)


@pytest.mark.parametrize("chip", ["lis3mdl", "lis2mdl"])
def test_a_host_from_before_the_extension_reads_the_new_stream_unchanged(chip, tmp_path) -> None:
    with EmulatedNucleo("wobble", odr_hz=208, seed=4, mag=chip) as board:
        stream = capture_emulated_stream(board, 0.6)
    old = load_pre_mag_reader(tmp_path).LinkDecoder()
    new = LinkDecoder()
    for decoder in (old, new):
        decoder.arm_start(new_origin=True)
        for start in range(0, len(stream), 97):  # chunks cut anywhere
            decoder.feed(stream[start:start + 97])
    old_blocks, new_blocks = old.take_blocks(), new.take_blocks()
    old_counts, new_counts = old.counters(), new.counters()
    assert new_counts.mag_samples > 0 and new_counts.samples > 50
    # The old host: the same samples, times and counters; the new packets only as unknown.
    for name in ("t_s", "accel_raw", "gyro_raw", "temp_raw"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, name) for b in old_blocks]),
                                      np.concatenate([getattr(b, name) for b in new_blocks]))
    assert old_counts.undecodable == old_counts.crc_errors == 0
    assert old_counts.seq_gaps == 0 and old_counts.samples == new_counts.samples
    mag_packets = stream.count(b"\x00") - new_counts.packets  # every frame ends with 0x00
    assert old_counts.unknown_packets >= new_counts.mag_samples // 32
    assert old_counts.unknown_packets + old_counts.packets == new_counts.packets + mag_packets
    assert all(block.mag_raw is None for block in old_blocks)


# -- the emulated board through the serial driver -------------------------------------------------


@pytest.mark.parametrize(("chip", "rate_hz", "ut_per_lsb"), [
    ("lis3mdl", 80.0, 100 / 6842), ("lis2mdl", 100.0, 0.15)])
def test_the_emulated_board_streams_its_magnetometer_to_the_app(chip, rate_hz, ut_per_lsb
                                                                ) -> None:
    # An ideal unit (no hard or soft iron, no noise): the field is the WMM's, quantised.
    with EmulatedNucleo("wobble", odr_hz=208, seed=5, mag=chip, errors=False,
                        noise=False) as board:
        device = create_device(board.port)
        info = device.open()
        try:
            blocks = read_samples(device, 150)
            status = device.request_status()
        finally:
            device.close()
    mag = info.magnetometer
    assert mag is not None and mag.chip == chip.upper() and mag.path == "bus"
    assert mag.odr_hz == rate_hz and mag.ut_per_lsb == pytest.approx(ut_per_lsb, rel=1e-4)
    field = np.concatenate([b.mag_raw for b in blocks])
    rows = ~np.isnan(field[:, 0])
    # One field sample per 208/rate rows, each on an accelerometer row.
    assert abs(rows.sum() - len(field) * rate_hz / 208.33) <= 3
    wmm = earth_field(DEFAULT_PLACE, MAG_FIELD_DATE).total_ut
    magnitude = np.linalg.norm(field[rows] * blocks[0].scale.mag_ut_per_lsb, axis=1)
    assert np.all(np.abs(magnitude - wmm) < 2 * ut_per_lsb)  # quantisation only
    assert status is not None and status.mag_i2c_errors == 0


def test_the_magnetometer_pauses_where_the_link_cannot_carry_it() -> None:
    # 833 Hz fits a 115200-baud UART alone (10.4 of 11.5 kB/s) but not with 80 field
    # samples a second beside it: the board pauses the magnetometer, the accelerometer keeps
    # its rate.
    assert not mag_fits(833.33, 80.0, 115_200, 400_000)
    assert mag_fits(416.67, 80.0, 115_200, 400_000)
    with EmulatedNucleo("wobble", odr_hz=833, seed=6, mag="lis3mdl", baud=115_200) as board:
        assert board.mag_paused
        device = create_device(f"serial://{board.port}?baud=115200")
        info = device.open()
        try:
            blocks = read_samples(device, 100)
            logs = [entry.text for entry in device.recent_logs()]
        finally:
            device.close()
    assert info.magnetometer is None and info.odr_nominal_hz == 833
    assert all(block.mag_raw is None for block in blocks)
    assert any("magnetometer (LIS3MDL) paused: 833 Hz" in text for text in logs)


def test_the_emulated_board_sends_the_simulators_field_at_the_rate_it_announces() -> None:
    # At 208 Hz the LIS2MDL runs at its own 100 Hz: the board sends the simulator's samples
    # (its unit's hard and soft iron and noise included), every one, in order.
    with EmulatedNucleo("wobble", odr_hz=208, seed=4, mag="lis2mdl") as board:
        packets = [p.parse_packet(body[0], body[1:]) for body in map(
            unframe, FrameSplitter().feed(capture_emulated_stream(board, 0.5)))]
    sent = np.concatenate([pk.xyz for pk in packets if isinstance(pk, p.MagSamples)])
    sim = SimulatedDevice("sim://wobble?odr=208&accel_fs=4&gyro_fs=250&seed=4&realtime=0"
                          "&block=256&settling=1&mag=lis2mdl&date=2026-07-02")
    sim.open()
    field = sim.read(1.0).mag_raw
    sim.close()
    own = field[~np.isnan(field[:, 0])].astype(np.int16)
    assert len(sent) >= 30
    assert any(np.array_equal(own[k:k + len(sent)], sent) for k in range(len(own) - len(sent)))
    # At 52 Hz the LIS3MDL is set to 40 Hz, and the board sends 40 a second.
    with EmulatedNucleo("wobble", odr_hz=52, seed=4, mag="lis3mdl") as board:
        packets = [p.parse_packet(body[0], body[1:]) for body in map(
            unframe, FrameSplitter().feed(capture_emulated_stream(board, 1.0)))]
    (described,) = [pk for pk in packets if isinstance(pk, p.Magnetometer)]
    samples_52 = [pk for pk in packets if isinstance(pk, p.Samples)]
    rows = sum(pk.count for pk in samples_52)
    field_rows = sum(len(pk.t) for pk in packets if isinstance(pk, p.MagSamples))
    assert described.odr_mhz == 40_000
    assert abs(field_rows - rows * 40 / 52.08) <= 2
