"""The board's health (STATUS) and the reasons for lost data, on the host.

The decoder names each sequence gap's cause (corrupt frames on the link, or the board); the
services turn a rise of the board's counters into a message with its reason; recordings store
the counters; ``check-board`` prints them. Real parts: the emulated NUCLEO on a pseudo-terminal
and the serial driver; expected counts come from what the emulated board did (its callback and
stats), never typed in.
"""

from __future__ import annotations

import io
import sys
import threading
import time

import numpy as np
import pytest
from test_services import DEADLINE_S, parts, stream

from app.cli.check_board import check_board
from app.core.devices import BoardStatus
from app.core.recording import read_recording
from app.services.board_health import (
    KEY_STATUS_END,
    KEY_STATUS_START,
    BoardHealth,
    describe_rise,
)
from app.services.health import HealthMonitor
from drivers.emulated_nucleo import EmulatedNucleo, NucleoFaults
from drivers.link import protocol as p
from drivers.link.decoder import LinkDecoder
from drivers.link.framing import encode_packet
from drivers.serial_link import SerialLinkDevice

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals")


def board_status(**changes) -> BoardStatus:
    values = dict(reset_cause="power-on", uptime_s=10.0, streaming=True, sensor_ok=True,
                  clock_fallback=False, uart_tx_dropped_bytes=0, uart_rx_errors=0,
                  i2c_errors=1, i2c_recoveries=0, i2c_retries=0, fifo_overruns=0,
                  samples_read=1000, samples_sent=1000, watchdog_resets=0)
    values.update(changes)
    return BoardStatus(**values)


def samples(seq: int, t0: int, count: int = 4) -> p.Samples:
    return p.Samples(seq, t0, 0, np.zeros((count, 6), dtype=np.int16))


# -- the decoder: which gap is whose ------------------------------------------------------------
def test_a_gap_after_corrupt_frames_is_the_links_and_one_without_is_the_boards():
    decoder = LinkDecoder(p.Config(100_000, 4, 250, 25_000))  # 100 Hz: 400 ticks a sample
    good = [encode_packet(samples(seq, seq * 1600)) for seq in range(12)]
    cut = [frame[:5] + frame[15:] for frame in good[3:6]]  # bytes lost inside three frames
    stream_bytes = b"".join(good[:3] + cut + good[6:9] + good[10:])  # 9: dropped whole
    for start in range(0, len(stream_bytes), 7):  # any chunking
        decoder.feed(stream_bytes[start:start + 7])
    link, board = decoder.take_gap_reports()
    assert (link.cause, link.corrupt_frames, link.lost_samples) == ("link", 3, 12)
    assert link.message == "link: 3 corrupt frames, ~12 samples lost"
    assert (board.cause, board.corrupt_frames, board.lost_samples) == ("board", 0, 4)
    counters = decoder.counters()
    assert counters.crc_errors + counters.undecodable == 3
    assert (counters.seq_gaps, counters.lost_samples) == (2, 16)
    assert (counters.link_gaps, counters.link_lost_samples) == (1, 12)
    gaps = np.concatenate([block.gap for block in decoder.take_blocks()])
    assert gaps.sum() == 2  # both marked
    assert decoder.take_gap_reports() == []


def test_status_is_a_typed_record_and_its_extension_bytes_are_kept():
    status = p.Status(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13)
    assert p.parse_packet(p.STATUS, status.payload()) == status
    later = p.parse_packet(p.STATUS, bytes([2]) + status.payload()[1:] + b"\x01\x02")
    assert later.version == 2 and later.extra == b"\x01\x02" and later.samples_sent == 12
    with pytest.raises(p.PacketError, match="at least 43"):
        p.parse_packet(p.STATUS, status.payload()[:-1])
    with pytest.raises(p.PacketError, match="status_version 0"):
        p.parse_packet(p.STATUS, bytes([0]) + status.payload()[1:])
    assert status.reset_cause_text == "reset pin" and status.streaming and status.sensor_ok


# -- the messages ---------------------------------------------------------------------------------
def test_each_rise_becomes_a_message_with_its_reason():
    before = board_status(host_gap_samples=5)
    after = board_status(uptime_s=11.0, fifo_overruns=1, i2c_retries=3, i2c_errors=4,
                         host_gap_samples=17)
    texts = [m.text for m in describe_rise(before, after)]
    assert texts[0] == "board: sensor FIFO overrun, 12 samples lost"
    assert texts[1].startswith("board: I2C retried 3 times")
    assert len(texts) == 2  # the errors were the retried ones
    dropped = board_status(uptime_s=11.0, uart_tx_dropped_bytes=512, host_gap_samples=41)
    (message,) = describe_rise(before, dropped)
    assert message.level == 2
    assert message.text.startswith("board: UART dropped 512 bytes") and "36 samples" in message.text
    wrapped = board_status(uptime_s=11.0, samples_read=3, samples_sent=3)
    assert describe_rise(board_status(samples_read=2**32 - 2), wrapped) == []
    health = BoardHealth()
    health.update(board_status())
    (restart, watchdog) = health.update(board_status(uptime_s=1.0, reset_cause="independent "
                                                     "watchdog", watchdog_resets=1))
    assert "restarted (independent watchdog)" in restart.text
    assert "1 watchdog resets since power-on" in watchdog.text


# -- on a pseudo-terminal -------------------------------------------------------------------------
def test_a_fifo_overrun_on_the_board_arrives_as_a_message_with_the_samples_lost():
    board = EmulatedNucleo("static", odr_hz=833.0, seed=5,
                           faults=NucleoFaults(overrun_seqs=frozenset({40})))
    try:
        connection, _pipeline, _rec, acquisition, messages = parts(board.port)
        device = connection.device
        deadline = time.monotonic() + DEADLINE_S
        while device.counters.seq_gaps == 0:
            assert time.monotonic() < deadline, "no gap"
            acquisition.step()
        device.request_status()  # the board's counters now, after the gap
        stream(acquisition, 1)
        lost = board.stats.samples_dropped
        assert lost > 0 and board.stats.fifo_overruns == 1
        assert (2, f"board: sensor FIFO overrun, {lost} samples lost") in messages
        latest = acquisition.board.latest
        assert latest is not None and latest.fifo_overruns == 1
        assert latest.samples_read == latest.samples_sent
        assert latest.reset_cause == "power-on" and latest.uart_tx_dropped_bytes == 0
        connection.close()
    finally:
        board.close()


def test_bytes_lost_inside_frames_are_a_marked_gap_with_the_links_reason():
    sent: dict[int, int] = {}
    board = EmulatedNucleo(
        "static", odr_hz=833.0, seed=6, faults=NucleoFaults(cut_seqs=frozenset({30, 31, 32})),
        on_packet_sent=lambda seq, _first, count, _t: sent.__setitem__(seq, count))
    try:
        connection, pipeline, _rec, acquisition, messages = parts(board.port)
        device = connection.device
        deadline = time.monotonic() + DEADLINE_S
        while not any(text.startswith("link:") for _, text in messages):
            assert time.monotonic() < deadline, f"no link message in {messages}"
            acquisition.step()
        lost = sent[30] + sent[31] + sent[32]
        assert (2, f"link: 3 corrupt frames, ~{lost} samples lost (bytes lost between the "
                   "board and this computer)") in messages
        counters = device.counters
        assert counters.link_gaps == counters.seq_gaps == 1
        assert counters.link_lost_samples == counters.lost_samples == lost
        rows = pipeline.samples.latest(pipeline.counters.samples, ["gap"])
        assert rows["gap"].sum() == 1
        # The board saw nothing wrong: its STATUS gives no reason, and no board message.
        status = device.request_status()
        assert status.uart_tx_dropped_bytes == status.fifo_overruns == 0
        assert status.host_gap_samples == 0
        assert not any(text.startswith("board:") for _, text in messages)
        connection.close()
    finally:
        board.close()


def test_a_firmware_without_status_is_still_checked_and_says_so():
    board = EmulatedNucleo("static", odr_hz=104.0, seed=7, sends_status=False)
    try:
        device = SerialLinkDevice(f"serial://{board.port}")
        device.open()
        assert device.request_status() is None  # ACK status 2: unknown command
        device.close()
        out = io.StringIO()
        assert check_board(board.port, [104.0], 0.5, False, out)
        assert "health    no STATUS: the firmware predates" in out.getvalue()
    finally:
        board.close()


def test_recordings_keep_the_counters_at_start_and_end(tmp_path):
    board = EmulatedNucleo("static", odr_hz=208.0, seed=8)
    try:
        connection, pipeline, recording, acquisition, _messages = parts(board.port)
        stream(acquisition, 10)
        assert acquisition.board.latest is not None  # sent right after START
        path = tmp_path / "board.csv"
        recording.start(connection.device, pipeline, str(path), "",
                        extra=acquisition.board.start_metadata())
        first = acquisition.board.latest
        deadline = time.monotonic() + DEADLINE_S
        while acquisition.board.latest is first:  # the next periodic STATUS
            assert time.monotonic() < deadline
            acquisition.step()
        status = recording.stop()
        errors: list[str] = []
        health = HealthMonitor()
        health.begin_recording()
        health.end_recording(status.path, errors.append, also=acquisition.board.end_metadata())
        end = acquisition.board.latest
        for thread in threading.enumerate():  # the closing metadata is stored in a thread
            if thread.name == "save-fault-events":
                thread.join(DEADLINE_S)
        assert not errors, errors
        metadata = read_recording(path).metadata
        assert metadata[KEY_STATUS_START] == first.as_dict()
        assert metadata[KEY_STATUS_END] == end.as_dict()
        assert metadata[KEY_STATUS_END]["samples_sent"] > metadata[KEY_STATUS_START]["samples_sent"]
        assert metadata[KEY_STATUS_END]["uptime_s"] > metadata[KEY_STATUS_START]["uptime_s"]
        connection.close()
    finally:
        board.close()


def test_check_board_prints_the_counters_and_fails_an_injected_overrun():
    board = EmulatedNucleo("static", seed=3, faults=NucleoFaults(overrun_seqs=frozenset({60})))
    out = io.StringIO()
    try:
        passed = check_board(board.port, [833.0], 1.0, False, out)
    finally:
        board.close()
    report = out.getvalue()
    assert not passed
    assert "health    started by power-on, up " in report
    overruns = next(line for line in report.splitlines() if "Sensor FIFO overruns" in line)
    assert overruns.split()[3:] == ["1", "(+1", "during", "the", "check)", "FAIL"]
    retries = next(line for line in report.splitlines() if "I2C retries" in line)
    assert retries.split()[2] == "0" and not retries.endswith("FAIL")


def test_a_headless_recording_of_a_board_keeps_its_counters(tmp_path):
    from app.services.recorder import record_device
    from drivers.registry import create_device

    board = EmulatedNucleo("static", odr_hz=208.0, seed=9)
    try:
        path = tmp_path / "headless.csv"
        outcome = record_device(create_device(board.port), path, duration_s=1.5)
        assert outcome.reason == "duration", outcome.message
        metadata = read_recording(path).metadata
        start, end = metadata[KEY_STATUS_START], metadata[KEY_STATUS_END]
        assert start["reset_cause"] == end["reset_cause"] == "power-on"
        rows = outcome.status.rows_written
        assert end["samples_sent"] - start["samples_sent"] >= rows
        # The end STATUS is asked for when the 1.5 s are over (uptime is in whole ms, and the
        # start STATUS can come a few ms after the first sample).
        assert end["uptime_s"] - start["uptime_s"] >= 1.4
        assert end["fifo_overruns"] == end["uart_tx_dropped_bytes"] == 0
    finally:
        board.close()


def test_the_emulated_board_counts_the_bytes_it_drops_when_the_host_stops_reading():
    import re

    board = EmulatedNucleo("static", odr_hz=1667.0, seed=10)
    try:
        connection, _pipeline, _rec, acquisition, messages = parts(board.port)
        stream(acquisition, 500)
        deadline = time.monotonic() + DEADLINE_S
        # The host does not read meanwhile: the wait is the behaviour under test (the board's
        # transmit buffer fills with wall time), so it is polled, not signalled.
        while board.stats.tx_dropped_bytes == 0:
            assert time.monotonic() < deadline, "the board never had to drop"
            time.sleep(0.01)
        device = connection.device
        while device.counters.seq_gaps == 0:  # reading again: the gap arrives
            assert time.monotonic() < deadline
            acquisition.step()
        stream(acquisition, 3000)  # the backlog is drained, the board sends everything again
        status = device.request_status()
        stream(acquisition, 1)
        stats = board.stats
        assert status.uart_tx_dropped_bytes == stats.tx_dropped_bytes > 0
        assert status.samples_read - status.samples_sent == stats.samples_dropped > 0
        said = [m for _, m in messages if m.startswith("board: UART dropped")]
        assert said, messages
        told_bytes = sum(int(re.search(r"dropped (\d+) bytes", m).group(1)) for m in said)
        told_samples = sum(int(re.search(r", (\d+) samples lost", m).group(1)) for m in said)
        assert told_bytes == stats.tx_dropped_bytes
        assert told_samples == stats.samples_dropped == device.counters.lost_samples
        connection.close()
    finally:
        board.close()


def test_simulate_pty_injects_fifo_overruns_that_the_host_sees_explained(capsys):
    import threading

    from app.cli import build_parser
    from app.cli.simulate import simulate_command

    bad = build_parser().parse_args(["simulate", "--pty", "--fifo-overrun", "soon"])
    assert simulate_command(bad, io.StringIO()) == 2
    assert "--fifo-overrun wants sequence numbers" in capsys.readouterr().err
    args = build_parser().parse_args(["simulate", "--pty", "--scenario", "static",
                                      "--odr", "833", "--fifo-overrun", "20"])
    out, stop = _Written(), threading.Event()
    server = threading.Thread(target=simulate_command, args=(args, out, stop), daemon=True)
    server.start()
    try:
        assert out.written.wait(DEADLINE_S), "simulate printed no port"
        deadline = time.monotonic() + DEADLINE_S
        port = out.getvalue().splitlines()[0]
        device = SerialLinkDevice(f"serial://{port}")
        device.open()
        while device.counters.seq_gaps == 0:
            assert time.monotonic() < deadline, "no gap"
            device.read(0.1)
        status = device.request_status()
        assert status.fifo_overruns == 1 and status.host_gap_samples > 0
        device.close()
    finally:
        stop.set()
        server.join(timeout=10)
    assert "1 FIFO overruns" in out.getvalue().splitlines()[-1]


class _Written(io.StringIO):
    """A text stream that says when something was first written to it."""

    def __init__(self) -> None:
        super().__init__()
        self.written = threading.Event()

    def write(self, text: str) -> int:
        count = super().write(text)
        if "\n" in self.getvalue():  # a whole first line (the port)
            self.written.set()
        return count
