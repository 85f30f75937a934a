"""The protocol v1 serial driver against an emulated NUCLEO, through real pseudo-terminals.

No sleeps: reads wait on the port with timeouts, and loops stop on a condition or a deadline.
"""

from __future__ import annotations

import errno
import io
import os
import pty
import signal
import subprocess
import sys
import threading
import time
import tty
import types
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import ClassVar

import numpy as np
import pytest
import serial

from app.core.samples import RawBlock, convert_raw_block
from drivers import lsm6dsox
from drivers.base import Device, DeviceInfo, DeviceMessage
from drivers.emulated_nucleo import EmulatedNucleo, NucleoFaults, odr_fits_link
from drivers.errors import DeviceError, DeviceIOError, DeviceOpenError, DeviceUrlError
from drivers.link import protocol as p
from drivers.link.framing import frame_bytes
from drivers.link.ports import (
    SerialPortInfo,
    open_error,
    permission_denied_message,
    port_busy_message,
)
from drivers.registry import available_devices, create_device
from drivers.serial_link import (
    PortDevice,
    SerialLinkDevice,
    parse_link_url,
    reconnect_url,
    url_with_port,
)

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals")


@pytest.fixture
def boards() -> Iterator[Callable[..., EmulatedNucleo]]:
    made: list[EmulatedNucleo] = []

    def make(scenario: str = "wobble", **options) -> EmulatedNucleo:
        board = EmulatedNucleo(scenario, **options)
        made.append(board)
        return board

    yield make
    for board in made:
        board.close()


@pytest.fixture
def devices() -> Iterator[Callable[[str], Device]]:
    made: list[Device] = []

    def open_url(url: str, **kwargs) -> Device:
        device = create_device(url) if not kwargs else SerialLinkDevice(url, **kwargs)
        made.append(device)
        device.open()
        return device

    yield open_url
    for device in made:
        device.close()


def read_samples(device: Device, count: int, deadline_s: float = 5.0) -> list[RawBlock]:
    """Blocks until at least ``count`` samples arrived (or fail at the deadline)."""
    blocks: list[RawBlock] = []
    end = time.monotonic() + deadline_s
    while sum(len(b) for b in blocks) < count:
        assert time.monotonic() < end, "samples did not arrive"
        block = device.read(0.2)
        if block is not None:
            blocks.append(block)
    return blocks


def joined(blocks: list[RawBlock], name: str) -> np.ndarray:
    return np.concatenate([getattr(b, name) for b in blocks])


@contextmanager
def talking_pty(chunks: list[bytes]) -> Iterator[str]:
    """A pseudo-terminal whose far end keeps sending ``chunks`` in turn (every 10 ms)."""
    master, slave = pty.openpty()
    tty.setraw(slave)
    stop = threading.Event()

    def talk() -> None:
        index = 0
        while chunks and not stop.wait(0.01):  # pacing the far end, not synchronising
            try:
                os.write(master, chunks[index % len(chunks)])
            except OSError:
                return
            index += 1

    thread = threading.Thread(target=talk, daemon=True)
    thread.start()
    try:
        yield os.ttyname(slave)
    finally:
        stop.set()
        thread.join()
        os.close(master)
        os.close(slave)


# -- URLs ----------------------------------------------------------------------------------------
def test_url_forms():
    opts = parse_link_url("serial:///dev/ttyACM0?baud=115200&odr=100&accel_fs=8&gyro_fs=500")
    assert (opts.port, opts.baud, opts.odr_hz, opts.accel_fs_g, opts.gyro_fs_dps) == (
        "/dev/ttyACM0", 115200, 104.0, 8, 500)
    assert parse_link_url("serial://COM3").port == "COM3"
    assert parse_link_url("/dev/pts/4?timeout=0.5").hello_timeout_s == 0.5
    assert parse_link_url("serial://spy:///dev/pts/4?file=t.txt&odr=208").port == (
        "spy:///dev/pts/4?file=t.txt")
    assert parse_link_url("COM7?columns=ax,ay,az", allow_other=True).other_options == (
        ("columns", "ax,ay,az"),)
    for bad, problem in [("serial://", "no port"), ("serial:///dev/x?accel_fs=3", "accel_fs"),
                         ("serial:///dev/x?odr=-1", "positive"), ("/dev/x?nope=1", "unknown")]:
        with pytest.raises(DeviceUrlError, match=problem):
            parse_link_url(bad)
    assert url_with_port("serial:///dev/ttyACM0?odr=208", "/dev/ttyACM3") == (
        "serial:///dev/ttyACM3?odr=208")
    assert url_with_port("/dev/ttyACM0", "/dev/ttyACM1") == "/dev/ttyACM1"
    assert isinstance(create_device("/dev/ttyACM0"), PortDevice)
    assert isinstance(create_device("COM3"), PortDevice)
    assert type(create_device("serial:///dev/ttyACM0")) is SerialLinkDevice


def test_pyserial_urls_work_and_loopback_is_not_a_board():
    # loop:// echoes the host's own commands: they decode, but nothing answers HELLO.
    device = SerialLinkDevice("serial://loop://?timeout=0.3")
    with pytest.raises(DeviceOpenError, match="no INFO/CONFIG"):
        device.open()


# -- streaming -----------------------------------------------------------------------------------
def test_open_reads_info_config_and_streams(boards, devices):
    board = boards("static", odr_hz=208, seed=5, scenario_params={"roll": 30.0})
    device = devices(board.port)
    info = device.info
    assert isinstance(device, PortDevice)
    assert info.unique_id == board.unique_id.hex().upper()
    assert info.name.startswith("NUCLEO-F746ZG emulated") and info.firmware == "1.2.0"
    assert info.odr_nominal_hz == 208.0 and info.odr_hz == pytest.approx(board.config.odr_hz)
    assert (info.accel_fs_g, info.gyro_fs_dps) == (4, 250)
    assert info.extra["usb_serial"] == board.usb_serial
    assert info.extra["usb_vid_pid"] == "0483:374B"
    blocks = read_samples(device, 120)
    t = joined(blocks, "t_s")
    assert t[0] == 0.0
    np.testing.assert_allclose(np.diff(t), 1 / info.odr_hz, atol=30e-6)
    assert not joined(blocks, "gap").any()
    si = convert_raw_block(blocks[-1])
    gravity = np.linalg.norm(si.accel_m_s2, axis=1)
    assert np.all(np.abs(gravity - 9.81) < 0.5)
    roll = np.degrees(np.arctan2(si.accel_m_s2[:, 1], si.accel_m_s2[:, 2]))
    assert np.all(np.abs(roll - 30.0) < 3.0)
    assert np.all(np.abs(si.temp_degc - 30) < 15)
    counters = device.counters
    assert counters.samples >= len(t) and counters.packets > 0
    assert counters.crc_errors == counters.undecodable == counters.seq_gaps == 0


def test_configure_from_the_url(boards, devices):
    board = boards(odr_hz=104)
    device = devices(f"serial://{board.port}?odr=833&accel_fs=8&gyro_fs=1000")
    assert device.info.odr_nominal_hz == 833.0
    assert (device.info.accel_fs_g, device.info.gyro_fs_dps) == (8, 1000)
    block = read_samples(device, 50)[0]
    assert block.scale.accel_m_s2_per_lsb == pytest.approx(lsm6dsox.accel_m_s2_per_lsb(8))
    assert board.config.odr_code == 7


def test_rates_the_link_cannot_carry_are_refused(boards, devices):
    assert odr_fits_link(833, 115200) and not odr_fits_link(1667, 115200)
    assert odr_fits_link(6667, 921600) and odr_fits_link(6667, None)
    board = boards(baud=115200)
    with pytest.raises(DeviceOpenError, match=r"bad argument.*1667 Hz needs"):
        devices(f"{board.port}?odr=1667")
    # The board keeps its settings and still works.
    assert devices(board.port).info.odr_nominal_hz == 104.0


def test_every_counter_through_the_pty(boards, devices):
    sent: dict[int, tuple[int, int]] = {}

    def record(seq: int, first: int, count: int, _t_write: float) -> None:
        sent.setdefault(seq, (first, count))

    faults = NucleoFaults(drop_seqs=frozenset({5, 6}), corrupt_seqs=frozenset({10}))
    board = boards(odr_hz=833, faults=faults, on_packet_sent=record)
    device = devices(board.port)
    read_samples(device, 200)
    board.inject(b"\x05\x01\x02\x00")  # bad COBS
    board.inject(frame_bytes(0x42, b"a later packet type"))
    board.inject(frame_bytes(p.CONFIG, b"\x01\x02"))  # wrong length
    read_samples(device, 100)
    ack = device.send_command(p.Stop())
    assert ack.ok
    # After the ACK of STOP nothing more comes: what was sent has been decoded.
    end = time.monotonic() + 5
    while device.read(0.05) is not None:
        assert time.monotonic() < end
    counters = device.counters
    last = max(sent)
    corrupted_count = sent[10][1]
    dropped = sent[7][0] - sent[4][0] - sent[4][1]
    assert counters.crc_errors == 1
    assert counters.undecodable == 2
    assert counters.unknown_packets == 1
    assert counters.seq_gaps == 2  # 5-6 dropped, 10 corrupted
    assert counters.lost_samples == dropped + corrupted_count
    assert counters.samples == sum(c for s, (_, c) in sent.items() if s != 10)
    assert counters.samples + counters.lost_samples == sent[last][0] + sent[last][1]
    assert board.stats.packets_dropped == 2 and board.stats.packets_corrupted == 1


def test_gap_is_marked_where_packets_were_lost(boards, devices):
    board = boards(odr_hz=416, faults=NucleoFaults(drop_seqs=frozenset({3})))
    device = devices(board.port)
    blocks = read_samples(device, 150)
    t, gap = joined(blocks, "t_s"), joined(blocks, "gap")
    (where,) = np.flatnonzero(gap)
    step = t[where] - t[where - 1]
    assert step > 1.5 / device.info.odr_hz  # the time axis keeps the hole
    lost = sum(b.lost_samples for b in blocks)
    assert lost == round(step * device.info.odr_hz) - 1


def test_self_test_ping_and_logs(boards, devices):
    board = boards(odr_hz=208)
    device = devices(board.port)
    before = read_samples(device, 30)
    assert device.ping() < 1.0
    result = device.self_test()
    assert result.passed and all(50 <= a <= 1700 for a in result.accel_delta_mg)
    after = read_samples(device, 30)
    # The pause is marked once. Samples queued before the self-test may still come first, in
    # the same block (the link joins queued packets), so the mark need not be the first sample.
    t_after, gaps = joined(after, "t_s"), joined(after, "gap")
    assert t_after[0] > before[-1].t_s[-1] and np.all(np.diff(t_after) > 0)
    assert np.count_nonzero(gaps) == 1
    board.log(3, "sensor hiccup")
    end = time.monotonic() + 5
    while not any(entry.text == "sensor hiccup" for entry in device.recent_logs()):
        assert time.monotonic() < end
        device.read(0.1)
    levels = {entry.text: entry.level for entry in device.recent_logs()}
    assert levels["sensor hiccup"] == 3
    assert any(text.startswith("streaming at") for text in levels)
    # The same messages, once each, for the app to show the user.
    messages = device.take_messages()
    assert DeviceMessage(3, "sensor hiccup") in messages
    assert device.take_messages() == []


def test_self_test_from_another_thread_while_streaming(boards, devices):
    board = boards(odr_hz=833, faults=NucleoFaults(self_test_fails=True))
    device = devices(board.port)
    results: list[p.SelfTestResult] = []
    worker = threading.Thread(target=lambda: results.append(device.self_test()))
    worker.start()
    while worker.is_alive():  # the reading thread hands the answers over
        device.read(0.05)
    worker.join()
    assert results and not results[0].gyro_pass and results[0].accel_pass
    assert read_samples(device, 20)


def test_timestamps_unwrap_across_the_32_bit_wrap(boards, devices):
    board = boards(odr_hz=833, initial_ticks=2**32 - 12_000)  # wraps 0.3 s in
    device = devices(board.port)
    t = joined(read_samples(device, 600), "t_s")
    assert t[-1] > 0.6
    np.testing.assert_allclose(np.diff(t), 1 / device.info.odr_hz, atol=30e-6)
    assert device.counters.seq_gaps == 0


# -- unplug, replug ------------------------------------------------------------------------------
def test_unplug_then_replug_by_usb_serial(boards, devices):
    board = boards(odr_hz=208, seed=9)
    first = devices(board.port)
    old_port, usb_serial = board.port, first.info.extra["usb_serial"]
    blocks_1 = read_samples(first, 60)
    board.close()  # the cable is pulled
    with pytest.raises(DeviceIOError, match=f"{old_port} was disconnected"):
        end = time.monotonic() + 5
        while time.monotonic() < end:
            if (block := first.read(0.1)) is not None:
                blocks_1.append(block)
    origin_1 = first.device_clock_origin_s
    unique_id = first.info.unique_id
    first.close()
    assert reconnect_url(old_port, usb_serial) is None  # still unplugged
    board.replug()
    url = reconnect_url(old_port, usb_serial)
    assert url == board.port
    second = devices(url)
    assert second.info.unique_id == unique_id == board.unique_id.hex().upper()
    blocks_2 = read_samples(second, 60)
    # The board's clock ran on: on its time axis no sample comes twice.
    t_1 = joined(blocks_1, "t_s") + origin_1
    t_2 = joined(blocks_2, "t_s") + second.device_clock_origin_s
    both = np.concatenate([t_1, t_2])
    assert np.all(np.diff(both) > 0)
    assert t_2[0] > t_1[-1]


def test_replug_after_a_power_cycle_restarts_the_board_clock(boards, devices):
    board = boards(odr_hz=104, seed=2)
    first = devices(board.port)
    read_samples(first, 10)
    origin_1 = first.device_clock_origin_s
    board.replug(power_cycle=True)
    second = devices(board.port)
    read_samples(second, 10)
    assert second.info.unique_id == board.unique_id.hex().upper()
    assert second.device_clock_origin_s < origin_1 + 0.5  # the clock started again


# -- clear errors --------------------------------------------------------------------------------
def test_who_am_i_mismatch(boards, devices):
    board = boards(who_am_i=0x6A)
    with pytest.raises(DeviceOpenError, match=r"WHO_AM_I 0x6A.*0x6C.*LSM6DSL"):
        devices(board.port)


def test_port_busy(boards, devices):
    board = boards()
    devices(board.port)
    with pytest.raises(DeviceOpenError, match=rf"{board.port} is busy.*this program"):
        devices(board.port)


def test_missing_port():
    with pytest.raises(DeviceOpenError, match="There is no serial port /dev/ttyNOPE9"):
        create_device("/dev/ttyNOPE9").open()


def test_permission_message_and_errno_mapping():
    info = SerialPortInfo("/dev/ttyACM0", vid=0x0483, pid=0x374B)
    message = permission_denied_message("/dev/ttyACM0", info, group="dialout")
    assert "Permission denied opening /dev/ttyACM0" in message
    assert "'dialout' group" in message and "usermod -aG dialout" in message
    assert 'ATTRS{idVendor}=="0483", ATTRS{idProduct}=="374b"' in message
    assert "/etc/udev/rules.d/" in message and "udevadm" in message
    assert "group 'uucp'" in permission_denied_message("/dev/ttyACM0", info, group="uucp")
    refused = serial.SerialException(errno.EACCES, "could not open port /dev/ttyACM0: "
                                     "[Errno 13] Permission denied: '/dev/ttyACM0'")
    assert "dialout" in str(open_error("/dev/ttyACM0", refused))
    busy = serial.SerialException(errno.EBUSY, "could not open port: Device or resource busy")
    assert "is busy" in str(open_error("/dev/ttyACM0", busy))
    assert "is busy" in port_busy_message("/dev/ttyACM0", ["screen (pid 42)"])
    assert "screen (pid 42)" in port_busy_message("/dev/ttyACM0", ["screen (pid 42)"])
    assert "Could not open" in str(open_error("/dev/ttyACM0", serial.SerialException("odd")))


def test_wrong_protocol_garbage(devices):
    noise = bytes(np.random.default_rng(1).integers(0, 256, 300, dtype=np.uint8))
    with talking_pty([noise]) as port, pytest.raises(DeviceOpenError) as error:
        devices(f"serial://{port}?timeout=0.3")
    message = str(error.value)
    assert "within 0.3 s" in message and "neither protocol v1 nor text" in message
    assert noise[:4].hex(" ") in message and "baud" in message


def test_wrong_protocol_text_on_the_serial_scheme(devices):
    with talking_pty([b"0.01,-0.02,0.99,0.1,0.0,-0.1\r\n"]) as port, pytest.raises(
        DeviceOpenError, match=r"text lines.*text:///dev/"
    ):
        devices(f"serial://{port}?timeout=0.3")


def test_wrong_protocol_silence_after_the_default_two_seconds(devices):
    with talking_pty([]) as port:
        start = time.monotonic()
        with pytest.raises(DeviceOpenError, match=r"within 2 s.*Nothing at all was received"):
            devices(f"serial://{port}")
        assert time.monotonic() - start >= 2.0


class _FakeTextDevice(Device):
    """Stands in for the text driver: the hand-over itself is what is tested."""

    scheme = "text"
    opened: ClassVar[list[str]] = []

    def _open(self) -> DeviceInfo:
        _FakeTextDevice.opened.append(self.url)
        return DeviceInfo(self.url, "text sketch", "", "text", 100.0, 100.0, 0, 0)

    def _read(self, timeout_s: float) -> RawBlock | None:
        return None

    def _close(self) -> None:
        pass


def test_bare_port_hands_text_lines_to_the_text_driver(monkeypatch, devices):
    from drivers import registry

    module = types.ModuleType("fake_text_driver")
    module.FakeTextDevice = _FakeTextDevice
    monkeypatch.setitem(sys.modules, "fake_text_driver", module)
    monkeypatch.setitem(registry._BUILTIN, "text", ("fake_text_driver", "FakeTextDevice"))
    _FakeTextDevice.opened.clear()
    with talking_pty([b"ax,ay,az\r\n", b"0.01,-0.02,0.99\r\n"]) as port:
        device = devices(f"{port}?baud=115200&columns=ax,ay,az")
        assert isinstance(device, PortDevice) and device.text_device is not None
        assert device.info.extra["detected"] == "text lines"
        assert device.read(0.01) is None
    assert _FakeTextDevice.opened == [f"text://{port}?baud=115200&columns=ax%2Cay%2Caz"]


def test_bare_port_with_the_real_text_driver(devices):
    pytest.importorskip("drivers.text_lines")
    lines = [f"{0.01 * i:.2f},-0.02,0.99,0.1,0.0,-0.1\r\n".encode() for i in range(50)]
    with talking_pty(lines) as port:
        device = devices(port)
        assert device.info.url == port and device.info.extra["detected"] == "text lines"
        block = read_samples(device, 3)[0]
        np.testing.assert_allclose(block.accel_raw[0, 1:], [-0.02, 0.99])
        assert device.counters.samples >= 3  # the text driver's counters
        with pytest.raises(DeviceError, match="no self-test"):
            device.self_test()


def test_bare_port_without_a_text_driver_says_text_was_seen(monkeypatch, devices):
    from drivers import registry

    monkeypatch.delitem(registry._BUILTIN, "text", raising=False)
    with talking_pty([b"1,2,3\n"]) as port, pytest.raises(DeviceOpenError,
                                                          match="text lines were seen"):
        devices(port)


# -- discovery and the command line --------------------------------------------------------------
def test_discovery_lists_the_emulated_board_with_its_usb_identity(boards):
    board = boards(seed=11)
    listed = {d.url: d for d in available_devices()}
    entry = listed[board.port]
    assert entry.kind == "serial"
    assert "0483:374B" in entry.description and board.usb_serial in entry.description
    assert "emulated NUCLEO" in entry.description
    from app.cli.devices import list_devices

    out = io.StringIO()
    list_devices(out)
    assert board.port in out.getvalue() and "sim://wobble" in out.getvalue()


def test_ports_are_guessed_from_usb_ids():
    assert "ST-LINK" in SerialPortInfo("/dev/ttyACM0", vid=0x0483, pid=0x374E).summary()
    assert SerialPortInfo("x", vid=0x0483, pid=0x374F).kind == "nucleo"
    assert "native USB CDC" in SerialPortInfo("x", vid=0x0483, pid=0x5740).guess
    mcp = SerialPortInfo("/dev/ttyACM1", vid=0x04D8, pid=0x00DD, serial_number="0001234")
    assert mcp.kind == "mcp2221" and "04D8:00DD" in mcp.summary() and "I2C" in mcp.summary()
    assert SerialPortInfo("x", vid=0x2341, pid=0x0043).kind == "text"
    assert SerialPortInfo("/dev/ttyS0").kind == "serial"


def test_simulate_command_serves_a_board_until_ctrl_c():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    process = subprocess.Popen(
        [sys.executable, "-m", "app", "simulate", "--pty", "--odr", "208", "--seed", "4"],
        cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        port = process.stdout.readline().strip()
        assert port.startswith("/dev/")
        listed = {d.url: d.description for d in available_devices()}
        assert "emulated NUCLEO" in listed[port]  # another process sees the board too
        device = create_device(port)
        try:
            info = device.open()
            assert info.odr_nominal_hz == 208.0
            assert read_samples(device, 20)
        finally:
            device.close()
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=30)
        assert process.returncode == 0, err
        assert "Stopped:" in out
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
