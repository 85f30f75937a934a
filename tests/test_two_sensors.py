"""Two LSM6DSOX on one board (docs/protocol.md, "Several sensors on one board", a v1 extension).

The firmware's own core streams two emulated chips on one I2C bus (0x6A and 0x6B) in virtual
time; the app's decoder follows each sensor; a v1 reader that predates the extension (the
decoder as it was before it, taken from git) still gets sensor 0 intact from the same bytes.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from fwcore import FirmwareCore, SharedBus
from old_link_reader import load_old_decoder

from drivers import lsm6dsox
from drivers.errors import DeviceError, DeviceOpenError, SettingRefusedError
from drivers.link import protocol as p
from drivers.link.decoder import LinkDecoder
from drivers.link.framing import FrameSplitter, encode_packet, unframe
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.registry import create_device
from drivers.sim.options import SimOptions

ROOT = Path(__file__).resolve().parent.parent
V1_READER_COMMIT = "af5deac"
"""The last commit before the multi-sensor extension: its decoder knows SAMPLES and STATUS
only, as every host in the field does."""


def read_samples(device, count: int, deadline_s: float = 5.0) -> list:
    """Blocks of ``device`` until at least ``count`` samples arrived (fails at the deadline)."""
    blocks: list = []
    end = time.monotonic() + deadline_s
    while sum(len(b) for b in blocks) < count:
        assert time.monotonic() < end, "samples did not arrive"
        block = device.read(0.2)
        if block is not None:
            blocks.append(block)
    return blocks


def wait_until(condition, deadline_s: float = 3.0) -> bool:
    """Poll ``condition`` (the emulated board's thread acts on its own) until true or late."""
    end = time.monotonic() + deadline_s
    while not condition():
        if time.monotonic() > end:
            return False
        threading.Event().wait(0.01)
    return True


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


def test_other_sensors_packets_left_from_an_earlier_stream_are_not_counted() -> None:
    """A board stopped by the last user may still send a packet of each sensor after a new
    user's STOP: until START's ACK they are stale, and not this stream's other sensors'."""
    rows = np.arange(24, dtype=np.int16).reshape(4, 6)
    stale = p.SamplesIndexed(1, p.Samples(7, 50, 0, rows))
    decoder = LinkDecoder()
    decoder.feed(encode_packet(p.Config(104_167, 4, 250, 25_000)))
    decoder.arm_start(new_origin=True)
    decoder.feed(encode_packet(stale) + encode_packet(p.Samples(3, 900, 0, rows)))
    assert decoder.counters().other_sensor_packets == 0 and not decoder.take_blocks()
    decoder.feed(encode_packet(p.Ack(p.START, p.ACK_OK)) + encode_packet(stale)
                 + encode_packet(p.Samples(0, 1000, 0, rows)))
    assert decoder.counters().other_sensor_packets == 1
    assert sum(len(b.gyro_raw) for b in decoder.take_blocks()) == 4


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
    """The decoder before the two-sensor extension (``v1link``)."""
    decoder = load_old_decoder(tmp_path, V1_READER_COMMIT, "v1link")
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
    # 833 Hz fits both sensors on I2C at 400 kHz: neither is paused.
    core.send(p.Configure(7, 4, 500))
    wire += core.take_output()
    answer = packets_of(bytes(wire))
    assert answer[0] == p.Ack(p.CONFIGURE, p.ACK_OK)
    assert [pk.paused for pk in answer if isinstance(pk, p.Sensor)] == [False, False]
    assert not any(isinstance(pk, p.Log) for pk in answer)
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


PAUSED_1667 = ("sensor 1 (0x6B) paused: 1667 Hz does not fit two sensors on I2C 400 kHz "
               "(highest 833 Hz)")


def test_every_one_sensor_rate_is_accepted_and_sensor_1_pauses_above_833_hz(
        firmware_lib) -> None:
    """A v1 host keeps every rate a one-sensor board has (the IKS01A3's own LSM6DSO at 0x6B
    must not cost it 1667 Hz): sensor 0 streams alone, sensor 1 is paused and a LOG says why."""
    core, chips = two_chip_core(firmware_lib)
    for code, label in lsm6dsox.ODR_LABELS_HZ.items():
        core.send(p.Configure(code, 4, 500))
        answer = packets_of(core.take_output())
        sensors = [pk for pk in answer if isinstance(pk, p.Sensor)]
        logs = [pk.text for pk in answer if isinstance(pk, p.Log)]
        if label > 1667:  # refused as by a one-sensor board, with its message
            assert answer[0].status == p.ACK_BAD_ARGUMENT, label
            assert "highest ODR 1667 Hz" in answer[0].message
            assert "sensors" not in answer[0].message
            continue
        assert answer[0] == p.Ack(p.CONFIGURE, p.ACK_OK), label
        assert answer[1].odr_code == code  # CONFIG: sensor 0 at the rate asked
        assert [s.answering for s in sensors] == [True, True]
        assert [s.paused for s in sensors] == [False, label > 833], label
        assert logs == ([PAUSED_1667] if label > 833 else []), label
    # After the refusals the board is still at 1667 Hz: a HELLO says sensor 1 is paused, why.
    core.send(p.Configure(8, 4, 500))
    core.take_output()
    core.send(p.Hello())
    hello_bytes = core.take_output()
    hello = packets_of(hello_bytes)
    assert [type(pk) for pk in hello] == [p.Info, p.Config, p.Sensor, p.Sensor, p.Log]
    assert hello[3].paused and hello[4].text == PAUSED_1667
    # Streaming: sensor 0 alone at 1667 Hz, its chip's samples in order; nothing of sensor 1.
    core.send(p.Start())
    core.run(1.0)
    core.send(p.Stop())
    wire = core.take_output()
    packets = packets_of(wire)
    assert not any(isinstance(pk, p.SamplesIndexed) for pk in packets)
    start_log = next(pk.text for pk in packets if isinstance(pk, p.Log))
    assert "(sensor 1 at 0x6B paused: the rate does not fit two sensors)" in start_log
    decoder = LinkDecoder()
    decoder.feed(hello_bytes + wire)  # CONFIG first: the rate of the samples
    data = np.concatenate([b.accel_raw for b in decoder.take_blocks()])
    assert len(data) > 0.9 * 1667
    assert contains_run(chips[0].truth()["accel_raw"], data)
    assert decoder.counters().seq_gaps == decoder.counters().crc_errors == 0
    # Back at 833 Hz both stream again.
    core.send(p.Configure(7, 4, 500), p.Start())
    core.run(0.5)
    core.send(p.Stop())
    packets = packets_of(core.take_output())
    assert [pk.paused for pk in packets if isinstance(pk, p.Sensor)] == [False, False]
    assert sum(isinstance(pk, p.SamplesIndexed) for pk in packets) > 5
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


# -- two device objects on one pseudo-terminal --------------------------------------------------
@pytest.fixture
def two_sensor_board():
    from drivers.emulated_nucleo import EmulatedNucleo

    board = EmulatedNucleo("wobble", odr_hz=833, seed=4, sensors=2, sensor_bus_hz=400_000)
    yield board
    board.close()


def sensor1_rows(board, count: int) -> np.ndarray:
    """What sensor 1 of ``board`` produces, in order, after its turn-on transient: the same
    simulated unit, run again (the simulator is deterministic per seed)."""
    sim = board._new_sim(*board._settings, seed=board.seed + 1000)
    rows = []
    while sum(len(r) for r in rows) < count + 200:
        raw = sim.read(1.0)
        rows.append(np.hstack([raw.gyro_raw, raw.accel_raw]))
    sim.close()
    return np.concatenate(rows)[lsm6dsox.turn_on_discard(833):]


def contains_run(rows: np.ndarray, run: np.ndarray) -> bool:
    """Whether ``run`` appears in ``rows`` as consecutive rows."""
    starts = np.flatnonzero((rows == run[0]).all(axis=1))
    return any(np.array_equal(rows[k:k + len(run)], run) for k in starts)


def read_in_thread(device, count: int, out: dict, key: str) -> threading.Thread:
    def run() -> None:
        try:
            out[key] = read_samples(device, count)
        except BaseException as exc:  # reported by the test
            out[key] = exc

    thread = threading.Thread(target=run, name=f"reader {key}")
    thread.start()
    return thread


def test_two_devices_on_one_pty_get_their_own_sensor(two_sensor_board) -> None:
    board = two_sensor_board
    zero = create_device(board.port)  # a bare port: protocol v1 detected, sensor 0
    one = create_device(f"serial://{board.port}?sensor=1")
    try:
        info0 = zero.open()
        info1 = one.open()  # joins the open port and the running stream
        assert info0.unique_id == board.unique_id.hex().upper()
        assert info1.unique_id == info0.unique_id + "-S1"  # its own calibration profile
        assert info1.extra["i2c_address"] == 0x6B and info1.extra["sensor_count"] == 2
        # Each reports its own chip's trimmed rate.
        assert info0.odr_hz == pytest.approx(board.config.odr_hz)
        assert info1.odr_hz == pytest.approx(board._second.config.odr_hz)
        assert info0.odr_hz != info1.odr_hz
        got: dict = {}
        threads = [read_in_thread(zero, 300, got, "zero"), read_in_thread(one, 300, got, "one")]
        for thread in threads:
            thread.join(10.0)
        for key in ("zero", "one"):
            assert not isinstance(got[key], BaseException), got[key]
        data0 = np.hstack([np.concatenate([b.gyro_raw for b in got["zero"]]),
                           np.concatenate([b.accel_raw for b in got["zero"]])])
        data1 = np.hstack([np.concatenate([b.gyro_raw for b in got["one"]]),
                           np.concatenate([b.accel_raw for b in got["one"]])])
        # Sensor 1's device gets exactly sensor 1's samples, in order, from where it joined.
        expected = sensor1_rows(board, len(data1) + 2000)
        first = np.flatnonzero((expected[:, :6] == data1[0]).all(axis=1))
        assert len(first) and any(
            np.array_equal(expected[k:k + len(data1)], data1) for k in first)
        # Sensor 0's samples are another unit's: none of them is in sensor 1's stream.
        assert not any(np.array_equal(expected[k:k + 20], data0[:20])
                       for k in np.flatnonzero((expected == data0[0]).all(axis=1)))
        for device in (zero, one):
            counters = device.counters
            assert counters.seq_gaps == counters.crc_errors == counters.undecodable == 0
        assert zero.counters.other_sensor_packets > 0 and one.counters.other_sensor_packets > 0
        # Closing sensor 1 leaves sensor 0 streaming; the last close stops the board.
        one.close()
        assert board.streaming
        assert read_samples(zero, 50)
        zero.close()
        assert wait_until(lambda: not board.streaming)
    finally:
        one.close()
        zero.close()


def test_sharing_rules_say_what_is_wrong(two_sensor_board) -> None:
    from drivers.emulated_nucleo import EmulatedNucleo

    board = two_sensor_board
    single = EmulatedNucleo("static", seed=5)
    urls = {
        "zero": f"serial://{board.port}", "again": f"serial://{board.port}",
        "other": f"serial://{board.port}?sensor=1&odr=52",
        "one": f"serial://{board.port}?sensor=1", "lonely": f"serial://{single.port}?sensor=1",
        "fast": f"serial://{board.port}?odr=1667",
    }
    devices = {name: create_device(url) for name, url in urls.items()}
    try:
        devices["zero"].open()
        with pytest.raises(DeviceOpenError, match="is busy: this program has sensor 0"):
            devices["again"].open()
        with pytest.raises(DeviceOpenError, match="share their settings"):
            devices["other"].open()
        devices["one"].open()
        with pytest.raises(DeviceError, match="another sensor of this board is open"):
            devices["zero"].self_test()
        devices["one"].close()
        with pytest.raises(DeviceOpenError, match="no sensor 1 on this board: it has one sensor"):
            devices["lonely"].open()
        devices["zero"].close()
        # 1667 Hz fits sensor 0 alone: it opens and streams; sensor 1 is paused, and opening
        # it says so with the board's reason instead of giving an empty stream.
        devices["fast"].open()
        assert read_samples(devices["fast"], 100)
        with pytest.raises(SettingRefusedError, match="is paused at 1667 Hz") as refused:
            devices["one"].open()
        assert refused.value.reason == board.pause_message() == PAUSED_1667
        # Sensor 1 is paused: not one of its packets on the link (those in flight from the
        # stream "zero" stopped are dropped with the stale samples until START's ACK).
        assert devices["fast"].counters.other_sensor_packets == 0
    finally:
        for device in devices.values():
            device.close()
        single.close()


def test_simulate_pty_serves_two_sensors() -> None:
    import io

    from app.cli import build_parser
    from app.cli.simulate import simulate_command

    args = build_parser().parse_args(["simulate", "--pty", "--sensors", "2", "--odr", "208"])
    out, stop = io.StringIO(), threading.Event()
    server = threading.Thread(target=simulate_command, args=(args, out, stop), daemon=True)
    server.start()
    try:
        assert wait_until(lambda: "Sensor 1" in out.getvalue(), 10.0)
        port = out.getvalue().splitlines()[0]
        assert f"serial://{port}?sensor=1" in out.getvalue()
        one = create_device(f"serial://{port}?sensor=1")
        info = one.open()
        try:
            assert info.extra["sensor_index"] == 1 and info.extra["i2c_address"] == 0x6B
            assert sum(len(b) for b in read_samples(one, 100)) >= 100
            assert one.counters.other_sensor_packets > 0  # sensor 0 streams beside it
        finally:
            one.close()
    finally:
        stop.set()
        server.join(timeout=10)
    refused = build_parser().parse_args(["simulate", "--pty", "--sensors", "2", "--odr", "3333"])
    assert simulate_command(refused, io.StringIO()) == 2  # not even one sensor: 1667 Hz on I2C


@pytest.mark.parametrize(("baud", "i2c_hz", "highest_hz"), [
    (115_200, 0, 417), (230_400, 0, 833), (460_800, 0, 1667), (921_600, 0, 3333),
    (921_600, 400_000, 833)])
def test_two_sensor_limits_match_the_protocol_tables(firmware_lib, baud, i2c_hz,
                                                     highest_hz) -> None:
    """docs/protocol.md section 6 (two sensors): the firmware's rule and the emulated board's."""
    import ctypes

    from drivers.emulated_nucleo import odr_fits_link, odr_fits_sensor_bus

    why = ctypes.create_string_buffer(160)
    for code, label in lsm6dsox.ODR_LABELS_HZ.items():
        fits = bool(firmware_lib.fw_rate_fits_sensors(code, baud, i2c_hz, 2, why, len(why)))
        rate = lsm6dsox.ODR_RATES_HZ[code]
        python = odr_fits_link(rate, baud, 2) and odr_fits_sensor_bus(rate, i2c_hz or None, 2)
        assert fits == (label <= highest_hz) == python, label
    page = " ".join((ROOT / "docs" / "protocol.md").read_text().split())
    if not i2c_hz:
        assert f"| {baud} | {baud // 10} |" in page and f"| {highest_hz} Hz |" in page
    else:
        assert "| 2 | 833 Hz | 3333 Hz | 833 Hz |" in page


def test_the_app_opens_both_sensors_of_the_firmware_core_on_a_pty(firmware_lib) -> None:
    """The firmware's own core, two emulated chips behind it, served in real time on a pty
    (``serve.py --sensors 2``): two device objects, one per sensor, share the port."""
    from fwcore import PtyBoard

    def core() -> FirmwareCore:
        chips = [EmulatedLsm6dsox(SimOptions("wobble", seed=seed), address=address,
                                  record_truth=True)
                 for seed, address in ((6, 0x6A), (1006, 0x6B))]
        return FirmwareCore(firmware_lib, SharedBus(*chips))

    board = PtyBoard(core)
    zero = create_device(f"serial://{board.port}?odr=833")
    one = create_device(f"serial://{board.port}?sensor=1&odr=833")
    try:
        info0, info1 = zero.open(), one.open()
        assert info0.firmware == "1.2.0" and info1.extra["i2c_address"] == 0x6B
        assert info1.unique_id == info0.unique_id + "-S1"
        got: dict = {}
        threads = [read_in_thread(zero, 200, got, "zero"), read_in_thread(one, 200, got, "one")]
        for thread in threads:
            thread.join(10.0)
        for key, device in (("zero", zero), ("one", one)):
            assert not isinstance(got[key], BaseException), got[key]
            counters = device.counters
            assert counters.seq_gaps == counters.crc_errors == counters.undecodable == 0
        # Each device's samples are a run of its own chip's, in order, none from the other.
        chips = board.core.bus.chips
        for key, address in (("zero", 0x6A), ("one", 0x6B)):
            data = np.concatenate([b.accel_raw for b in got[key]])
            assert contains_run(chips[address].truth()["accel_raw"], data), key
            other = 0x6B if address == 0x6A else 0x6A
            assert not contains_run(chips[other].truth()["accel_raw"], data[:20]), key
    finally:
        one.close()
        zero.close()
        board.close()


def test_sensor_1_paused_while_it_streams_fails_its_reads_with_the_reason(
        two_sensor_board) -> None:
    """Another program reconfigures the board to a rate only sensor 0 fits: the device of
    sensor 1 raises the board's reason instead of waiting on an empty stream."""
    board = two_sensor_board
    zero = create_device(f"serial://{board.port}")
    one = create_device(f"serial://{board.port}?sensor=1")
    try:
        zero.open()
        one.open()
        assert read_samples(one, 50)
        for command in (p.Stop(), p.Configure(8, 4, 250), p.Start()):
            assert zero.send_command(command).ok
        with pytest.raises(DeviceError, match=r"sensor 1 .* is paused at 1667 Hz") as raised:
            read_samples(one, 10_000)
        assert PAUSED_1667 in str(raised.value)
        assert read_samples(zero, 500)  # sensor 0 goes on at 1667 Hz
    finally:
        one.close()
        zero.close()


def test_the_firmware_core_on_a_pty_refuses_a_paused_sensor_1(firmware_lib) -> None:
    """The firmware's own core (serve.py --sensors 2): at 1667 Hz the app's sensor 0 streams,
    ``?sensor=1`` is refused with the firmware's reason."""
    from fwcore import PtyBoard

    def core() -> FirmwareCore:
        chips = [EmulatedLsm6dsox(SimOptions("static", seed=seed), address=address)
                 for seed, address in ((6, 0x6A), (1006, 0x6B))]
        return FirmwareCore(firmware_lib, SharedBus(*chips))

    board = PtyBoard(core)
    zero = create_device(f"serial://{board.port}?odr=1667")
    one = create_device(f"serial://{board.port}?sensor=1&odr=1667")
    try:
        info = zero.open()
        assert info.odr_nominal_hz == 1667
        assert read_samples(zero, 300)
        zero.close()
        with pytest.raises(SettingRefusedError, match="paused") as refused:
            one.open()
        assert refused.value.reason == PAUSED_1667
    finally:
        one.close()
        zero.close()
        board.close()
