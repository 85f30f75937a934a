"""Write ``link_v1.json``: the test vectors of NUCLEO link protocol v1.

The vectors are frozen: ``tests/test_link_protocol.py`` checks the Python codec against the
file byte for byte, the firmware's host tests read the same file, and ``docs/protocol.md``
quotes it. Run this only to add vectors (never to change existing ones):

    python tests/vectors/make_link_v1_vectors.py > tests/vectors/link_v1.json
"""

from __future__ import annotations

import json
import sys

import numpy as np

from drivers.link import protocol as p
from drivers.link.framing import crc16, encode_packet

UNIQUE_ID = bytes.fromhex("1A0036000851393235363300")  # holds 0x00 bytes, as real UIDs do


def _samples(rows: list[list[int]]) -> np.ndarray:
    return np.array(rows, dtype=np.int16)


VECTORS: list[tuple[str, p.Packet, dict]] = [
    ("HELLO", p.Hello(), {}),
    ("CONFIGURE 104 Hz, 4 g, 250 dps", p.Configure(4, 4, 250),
     {"odr_code": 4, "accel_fs_g": 4, "gyro_fs_dps": 250}),
    ("START", p.Start(), {}),
    ("STOP", p.Stop(), {}),
    ("SELF_TEST", p.SelfTest(), {}),
    ("PING", p.Ping(0xDEADBEEF), {"token": 0xDEADBEEF}),
    ("INFO", p.Info(1, (1, 2, 3), 0x6C, UNIQUE_ID, "NUCLEO-F746ZG"),
     {"protocol_version": 1, "firmware": [1, 2, 3], "who_am_i": 0x6C,
      "unique_id_hex": UNIQUE_ID.hex().upper(), "name": "NUCLEO-F746ZG"}),
    ("CONFIG 104 Hz, 4 g, 250 dps, 25 us ticks", p.Config(104000, 4, 250, 25000),
     {"odr_mhz": 104000, "accel_fs_g": 4, "gyro_fs_dps": 250, "tick_ns": 25000}),
    ("SAMPLES with 2 samples",
     p.Samples(0x1234, 0x00012345, 256,
               _samples([[10, -20, 30, 0, 0, 8192], [-1, 2, -3, 100, -100, 8190]])),
     {"seq": 0x1234, "t0": 0x00012345, "temperature_raw": 256,
      "samples": [[10, -20, 30, 0, 0, 8192], [-1, 2, -3, 100, -100, 8190]]}),
    ("SAMPLES with 32 samples and no zero byte (a COBS run of 254)",
     p.Samples(65535, 0xFFFFFFF0, -511,
               _samples([[0x0101 + 6 * i + j for j in range(6)] for i in range(32)])),
     {"seq": 65535, "t0": 0xFFFFFFF0, "temperature_raw": -511,
      "samples": [[0x0101 + 6 * i + j for j in range(6)] for i in range(32)]}),
    ("ACK START ok", p.Ack(p.START, 0, ""), {"command": p.START, "status": 0, "message": ""}),
    ("ACK CONFIGURE bad argument", p.Ack(p.CONFIGURE, 1, "odr"),
     {"command": p.CONFIGURE, "status": 1, "message": "odr"}),
    ("SELFTEST", p.SelfTestResult(True, True, (410, -380, 520), (55, -60, 48)),
     {"accel_pass": 1, "gyro_pass": 1, "accel_delta_mg": [410, -380, 520],
      "gyro_delta_dps": [55, -60, 48]}),
    ("LOG", p.Log(2, "FIFO overrun"), {"level": 2, "text": "FIFO overrun"}),
    ("PONG", p.Pong(0xDEADBEEF), {"token": 0xDEADBEEF}),
    # v1 extensions: appended, the vectors above are unchanged.
    ("GET_STATUS", p.GetStatus(), {}),
    ("STATUS after a watchdog reset, streaming",
     p.Status(1, 5, 0x03, 3_723_000, 512, 2, 4, 1, 3, 1, 387_000, 386_688, 1),
     {"version": 1, "reset_cause": 5, "flags": 3, "uptime_ms": 3_723_000,
      "uart_tx_dropped_bytes": 512, "uart_rx_errors": 2, "i2c_errors": 4, "i2c_recoveries": 1,
      "i2c_retries": 3, "fifo_overruns": 1, "samples_read": 387_000, "samples_sent": 386_688,
      "watchdog_resets": 1}),
]


def main() -> None:
    vectors = []
    for name, packet, fields in VECTORS:
        body = bytes((packet.TYPE,)) + packet.payload()
        vectors.append({
            "name": name,
            "type": packet.TYPE,
            "type_name": p.PACKET_NAMES[packet.TYPE],
            "fields": fields,
            "packet_hex": body.hex(" ").upper(),
            "crc_hex": f"{crc16(body):04X}",
            "frame_hex": encode_packet(packet).hex(" ").upper(),
        })
    document = {
        "protocol": "NUCLEO link protocol v1 (docs/protocol.md)",
        "notes": [
            "packet_hex: type byte + payload; crc_hex: CRC-16/CCITT-FALSE of packet_hex as a "
            "number (sent little-endian after the packet); frame_hex: the bytes on the wire, "
            "COBS(packet + CRC) followed by 0x00.",
            "All integers little-endian. Samples rows are gx, gy, gz, ax, ay, az in LSB.",
        ],
        "vectors": vectors,
    }
    json.dump(document, sys.stdout, indent=1)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
