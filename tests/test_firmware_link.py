"""The firmware's C codec against the Python one: the shared vectors, both ways, and random data.

Device packets: the C encoder must produce each vector's frame byte for byte, and the Python
decoder must read back the vector's fields. Host commands: the Python encoder's frames must come
out of the C receiver as the vector's packet. Random packets and byte streams check the same
beyond the vectors.
"""

from __future__ import annotations

import binascii
import json
import random
from pathlib import Path

import numpy as np
import pytest
from cobs import cobs
from fwcore import CReceiver, c_encode

from drivers.link import protocol as p
from drivers.link.framing import FrameSplitter, encode_packet, unframe

VECTORS = json.loads((Path(__file__).parent / "vectors" / "link_v1.json").read_text())["vectors"]
DEVICE_VECTORS = [v for v in VECTORS if v["type"] in p.DEVICE_PACKET_TYPES]
HOST_VECTORS = [v for v in VECTORS if v["type"] in p.HOST_PACKET_TYPES]


def packet_from_fields(vector: dict) -> p.Packet:
    """The Python packet object a vector describes (from its fields, not its bytes)."""
    fields = vector["fields"]
    kind = vector["type"]
    if kind == p.INFO:
        return p.Info(fields["protocol_version"], tuple(fields["firmware"]), fields["who_am_i"],
                      bytes.fromhex(fields["unique_id_hex"]), fields["name"])
    if kind == p.CONFIG:
        return p.Config(fields["odr_mhz"], fields["accel_fs_g"], fields["gyro_fs_dps"],
                        fields["tick_ns"])
    if kind == p.SAMPLES:
        return p.Samples(fields["seq"], fields["t0"], fields["temperature_raw"],
                         np.array(fields["samples"], dtype=np.int16))
    if kind == p.ACK:
        return p.Ack(fields["command"], fields["status"], fields["message"])
    if kind == p.SELFTEST:
        return p.SelfTestResult(bool(fields["accel_pass"]), bool(fields["gyro_pass"]),
                                tuple(fields["accel_delta_mg"]), tuple(fields["gyro_delta_dps"]))
    if kind == p.LOG:
        return p.Log(fields["level"], fields["text"])
    if kind == p.PONG:
        return p.Pong(fields["token"])
    if kind == p.STATUS:
        return p.Status(**fields)
    if kind == p.SAMPLES_INDEXED:
        return p.SamplesIndexed(fields["sensor_index"], p.Samples(
            fields["seq"], fields["t0"], fields["temperature_raw"],
            np.array(fields["samples"], dtype=np.int16)))
    if kind == p.SENSOR:
        return p.Sensor(**fields)
    if kind == p.MAGNETOMETER:
        return p.Magnetometer(**fields)
    if kind == p.MAG_SAMPLES:
        return p.MagSamples(fields["seq"], fields["t"], fields["xyz"])
    raise AssertionError(f"no device packet type {kind}")


def parse_frame(frame: bytes) -> p.Packet:
    """Python's decoding of one wire frame (with its 0x00)."""
    assert frame.endswith(b"\x00") and frame.count(0) == 1
    packet = unframe(frame[:-1])
    return p.parse_packet(packet[0], packet[1:])


def test_vectors_cover_every_packet_type() -> None:
    assert {v["type"] for v in VECTORS} == p.DEVICE_PACKET_TYPES | p.HOST_PACKET_TYPES


@pytest.mark.parametrize("vector", DEVICE_VECTORS, ids=lambda v: v["name"])
def test_c_encoder_makes_the_vector_frame_and_python_decodes_it(firmware_lib, vector) -> None:
    frame = c_encode(firmware_lib, packet_from_fields(vector))
    assert frame.hex(" ").upper() == vector["frame_hex"].upper()
    decoded = parse_frame(frame)
    assert decoded == packet_from_fields(vector)


@pytest.mark.parametrize("vector", HOST_VECTORS, ids=lambda v: v["name"])
def test_python_commands_come_out_of_the_c_receiver(firmware_lib, vector) -> None:
    fields = vector["fields"]
    command = {
        p.HELLO: p.Hello, p.START: p.Start, p.STOP: p.Stop, p.SELF_TEST: p.SelfTest,
        p.GET_STATUS: p.GetStatus,
    }.get(vector["type"])
    if vector["type"] == p.CONFIGURE:
        packet = p.Configure(fields["odr_code"], fields["accel_fs_g"], fields["gyro_fs_dps"])
    elif vector["type"] == p.PING:
        packet = p.Ping(fields["token"])
    else:
        packet = command()
    frame = encode_packet(packet)
    assert frame.hex(" ").upper() == vector["frame_hex"].upper()
    receiver = CReceiver(firmware_lib)
    try:
        assert receiver.feed(frame) == [bytes.fromhex(vector["packet_hex"])]
        assert receiver.bad_frames == 0
    finally:
        receiver.close()


def test_crc_agrees_with_python_on_random_data(firmware_lib) -> None:
    rng = random.Random(1)
    assert firmware_lib.crc16(b"123456789", 9) == 0x29B1
    for _ in range(500):
        data = rng.randbytes(rng.randrange(0, 600))
        assert firmware_lib.crc16(data, len(data)) == binascii.crc_hqx(data, 0xFFFF)


def test_cobs_agrees_with_the_python_library(firmware_lib) -> None:
    import ctypes

    rng = random.Random(2)
    out = (ctypes.c_uint8 * 1024)()
    for trial in range(800):
        length = rng.randrange(0, 700)
        zeros = (0.0, 0.01, 0.3, 1.0)[trial % 4]
        data = bytes(0 if rng.random() < zeros else rng.randrange(1, 256) for _ in range(length))
        n = firmware_lib.cobs_encode(data, len(data), out)
        encoded = bytes(out[:n])
        assert cobs.decode(encoded) == data
        if len(data) % 254 or b"\x00" in data or not data:
            # The forms differ only after a run of exactly k x 254 bytes (both are valid).
            assert encoded == cobs.encode(data)
        python_encoded = cobs.encode(data)
        m = firmware_lib.cobs_decode(python_encoded, len(python_encoded), out, len(out))
        assert bytes(out[:m]) == data


def test_random_device_packets_round_trip_through_both_codecs(firmware_lib) -> None:
    rng = np.random.default_rng(3)
    status_rng = np.random.default_rng(4)
    for _ in range(300):
        count = int(rng.integers(1, 33))
        samples = p.Samples(int(rng.integers(0, 65536)), int(rng.integers(0, 2**32)),
                            int(rng.integers(-32768, 32768)),
                            rng.integers(-32768, 32768, (count, 6)).astype(np.int16))
        text = "".join(chr(c) for c in rng.integers(32, 127, int(rng.integers(0, 120))))
        status = p.Status(1, int(status_rng.integers(0, 8)), int(status_rng.integers(0, 8)),
                          *(int(v) for v in status_rng.integers(0, 2**32, 10)))
        for packet in (samples, p.Log(int(rng.integers(0, 4)), text),
                       p.Ack(int(rng.integers(0x81, 0x87)), int(rng.integers(0, 5)), text),
                       p.Pong(int(rng.integers(0, 2**32))), status):
            frame = c_encode(firmware_lib, packet)
            assert frame == encode_packet(packet)
            assert parse_frame(frame) == packet


def test_c_receiver_resynchronises_like_the_python_one(firmware_lib) -> None:
    """Garbage, over-long runs and corrupted frames between good ones, cut at random places."""
    rng = random.Random(4)
    stream = bytearray()
    sent: list[bytes] = []
    for _ in range(400):
        roll = rng.random()
        if roll < 0.6:
            packet = p.Ping(rng.randrange(2**32)) if rng.random() < 0.5 else p.Configure(
                rng.randrange(1, 11), rng.choice((2, 4, 8, 16)), rng.choice((125, 250, 2000)))
            frame = encode_packet(packet)
            stream += frame
            sent.append(unframe(frame[:-1]))
        elif roll < 0.75:
            stream += rng.randbytes(rng.randrange(1, 40)) + b"\x00"
        elif roll < 0.85:
            stream += bytes(rng.randrange(1, 256) for _ in range(600)) + b"\x00"
        else:
            frame = bytearray(encode_packet(p.Ping(rng.randrange(2**32))))
            frame[rng.randrange(1, len(frame) - 1)] ^= 1 << rng.randrange(8)
            stream += frame
    receiver = CReceiver(firmware_lib)
    got: list[bytes] = []
    position = 0
    while position < len(stream):
        step = rng.randrange(1, 300)
        got += receiver.feed(bytes(stream[position:position + step]))
        position += step
    receiver.close()
    # What Python's splitter accepts (a flipped bit may, rarely, still pass both checks).
    expected = []
    for frame in FrameSplitter().feed(bytes(stream)):
        try:
            expected.append(unframe(frame))
        except ValueError:
            continue
    assert got == expected
    assert all(packet in got for packet in sent)
