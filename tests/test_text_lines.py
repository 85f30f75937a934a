"""The text-line driver on realistic sketch output, through real pseudo-terminals.

Most tests open the pty's far end themselves (as the bare-port detection does), write what a
sketch prints on the master side, then hand the port to the driver: every byte is seen, so the
counts are exact. Two tests let the driver open the port by name while a writer thread plays a
running sketch.
"""

from __future__ import annotations

import math
import os
import pty
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
import serial

from app.core.samples import STANDARD_GRAVITY_M_S2, RawBlock, convert_raw_block
from drivers.errors import DeviceIOError, DeviceOpenError, DeviceUrlError
from drivers.registry import create_device
from drivers.text_lines import (
    Layout,
    LineParser,
    TextLineCounters,
    TextLineDevice,
    canonical_column,
    looks_like_text_lines,
    parse_text_url,
)

G = STANDARD_GRAVITY_M_S2
DEG = math.pi / 180.0


class Pty:
    """A pseudo-terminal: the test writes on ``master``; the driver reads ``name``."""

    def __init__(self) -> None:
        self.master, self.slave = pty.openpty()
        self.name = os.ttyname(self.slave)
        self.master_open = True

    def write(self, text: str | bytes) -> None:
        data = text.encode() if isinstance(text, str) else text
        view = memoryview(data)
        while view:
            written = os.write(self.master, view)
            view = view[written:]

    def port(self) -> serial.Serial:
        """The far end, opened as a driver would (baud rates are ignored by ptys)."""
        return serial.serial_for_url(self.name, baudrate=115200, timeout=0.05)

    def unplug(self) -> None:
        if self.master_open:
            os.close(self.master)
            self.master_open = False

    def close(self) -> None:
        self.unplug()
        os.close(self.slave)


@pytest.fixture
def tty() -> Iterator[Pty]:
    terminal = Pty()
    yield terminal
    terminal.close()


def open_with(tty: Pty, text: str, query: str = "") -> TextLineDevice:
    """Write ``text`` as the sketch's output so far, then open the driver on the port."""
    port = tty.port()
    tty.write(text)
    device = TextLineDevice(f"text://{tty.name}?open_timeout=0.5{query}", port=port)
    device.open()
    return device


def read_all(device: TextLineDevice, count: int) -> RawBlock:
    """The next ``count`` samples as one block (waits for the pty to deliver them)."""
    blocks: list[RawBlock] = []
    deadline = time.monotonic() + 5.0
    while sum(len(b) for b in blocks) < count and time.monotonic() < deadline:
        block = device.read(0.2)
        if block is not None:
            blocks.append(block)
    assert sum(len(b) for b in blocks) == count, "samples missing"

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(b, name) for b in blocks])

    return RawBlock(cat("t_s"), cat("accel_raw"), cat("gyro_raw"), cat("temp_raw"),
                    blocks[0].scale, cat("gap"), sum(b.lost_samples for b in blocks),
                    mag_raw=None if blocks[0].mag_raw is None else cat("mag_raw"))


def csv_rows(n: int, sep: str = ",", *, accel_scale: float = 1.0, gyro_scale: float = 1.0,
             t_ms: int | None = None, digits: int = 3) -> tuple[str, np.ndarray, np.ndarray]:
    """Rows a still sensor tilted a little prints (accel in g x scale, gyro in dps x scale)."""
    k = np.arange(n)
    accel = np.stack([0.05 + 0.001 * k, -0.02 + 0.0 * k, 0.998 + 0.0 * k], -1) * accel_scale
    gyro = np.stack([0.5 + 0.01 * k, -0.25 + 0.0 * k, 0.125 + 0.0 * k], -1) * gyro_scale
    accel, gyro = np.round(accel, digits), np.round(gyro, digits)
    lines = []
    for i in range(n):
        values = [*(f"{v:.{digits}f}" for v in accel[i]), *(f"{v:.{digits}f}" for v in gyro[i])]
        if t_ms is not None:
            values.insert(0, str(t_ms + 10 * i))
        lines.append(sep.join(values) + "\r\n")
    return "".join(lines), accel, gyro


# -- plain CSV, headers, separators ---------------------------------------------------------
def test_plain_csv_in_g_and_dps(tty: Pty) -> None:
    text, accel, gyro = csv_rows(30)
    device = open_with(tty, "Starting...\r\n" + text)
    info = device.info
    assert info is not None and info.extra["accel_unit"] == "g"
    assert info.extra["gyro_unit"] == "dps" and info.extra["time_unit"] == "host"
    raw = read_all(device, 30)
    np.testing.assert_array_equal(raw.accel_raw, accel)
    si = convert_raw_block(raw)
    np.testing.assert_allclose(si.accel_m_s2, accel * G)
    np.testing.assert_allclose(si.gyro_rad_s, gyro * DEG)
    assert np.all(np.isnan(si.temp_degc))
    assert raw.t_s[0] == 0.0 and np.all(np.diff(raw.t_s) > 0)
    assert not raw.gap.any()
    counters = device.counters
    assert (counters.lines, counters.parsed, counters.rejected, counters.samples) == (31, 30, 1, 30)
    device.close()


def test_header_row_with_a_millisecond_time_column(tty: Pty) -> None:
    text, accel, _gyro = csv_rows(25, t_ms=123456)
    device = open_with(tty, "time_ms,accX,accY,accZ,gyroX,gyroY,gyroZ\r\n" + text)
    assert device.layout is not None and device.layout.time_unit == "ms"
    raw = read_all(device, 25)
    np.testing.assert_allclose(raw.t_s, np.arange(25) * 0.010, atol=1e-12)
    np.testing.assert_array_equal(raw.accel_raw, accel)
    assert device.info.odr_hz == pytest.approx(100.0)  # type: ignore[union-attr]
    # A dropped line (10 ms missing) is a gap holding one sample.
    tty.write("123706,0.1,0.0,1.0,0,0,0\r\n123726,0.1,0.0,1.0,0,0,0\r\n")
    more = read_all(device, 2)
    assert list(more.gap) == [False, True] and more.lost_samples == 1
    # The sketch restarts: it prints its header again, in another order, and millis() from 0.
    tty.write("ms\tgx\tgy\tgz\tax\tay\taz\r\n5\t1\t2\t3\t0.0\t0.0\t1.0\r\n15\t1\t2\t3\t0.0\t0.0\t1.0\r\n")
    restarted = read_all(device, 2)
    np.testing.assert_array_equal(restarted.gyro_raw, [[1, 2, 3], [1, 2, 3]])
    np.testing.assert_array_equal(restarted.accel_raw[:, 2], [1.0, 1.0])
    assert restarted.gap[0] and restarted.t_s[0] > more.t_s[-1]
    assert restarted.t_s[1] - restarted.t_s[0] == pytest.approx(0.010)
    device.close()


@pytest.mark.parametrize("sep", [" ", "\t", " \t ", ";"])
def test_space_tab_and_semicolon_separated_rows_in_si_units(tty: Pty, sep: str) -> None:
    text, accel, gyro = csv_rows(12, sep, accel_scale=G, gyro_scale=DEG, digits=4)
    header = sep.join(["ax", "ay", "az", "gx", "gy", "gz"]) + "\r\n"
    device = open_with(tty, header + text)
    assert device.layout is not None
    assert (device.layout.accel_unit, device.layout.gyro_unit) == ("m/s2", "rad/s")
    raw = read_all(device, 12)
    si = convert_raw_block(raw)
    np.testing.assert_allclose(si.accel_m_s2, accel)
    np.testing.assert_allclose(si.gyro_rad_s, gyro)
    device.close()


def test_units_and_columns_from_the_url_win(tty: Pty) -> None:
    # Integer mg and mdps in an unusual order, with a column to skip.
    rows = "".join(f"{7 + i},-12,{i},1003,{-40 + i},250\r\n" for i in range(10))
    device = open_with(tty, rows, "&columns=gz,_,ax,az,gx,gy&accel=mg&gyro=mdps")
    raw = read_all(device, 10)
    si = convert_raw_block(raw)
    np.testing.assert_allclose(si.accel_m_s2[:, 0], np.arange(10) * 1e-3 * G)
    np.testing.assert_allclose(si.accel_m_s2[:, 2], 1.003 * G)
    np.testing.assert_allclose(si.gyro_rad_s[:, 2], (7 + np.arange(10)) * 1e-3 * DEG)
    np.testing.assert_allclose(si.accel_m_s2[:, 1], 0.0)  # ay is not printed
    device.close()


# -- ST DataLogTerminal and Adafruit_LSM6DS output --------------------------------------------
DATALOG = (
    "\r\n------ Accelerometer, gyroscope and magnetometer ------\r\n"
    "WHO AM I address[0]: 0x6C\r\n"
    "ACC_X[0]: 12, ACC_Y[0]: -3, ACC_Z[0]: 1001\r\n"
    "GYR_X[0]: 140, GYR_Y[0]: -350, GYR_Z[0]: 70\r\n"
    "MAG_X[1]: -211, MAG_Y[1]: 93, MAG_Z[1]: 402\r\n"
    "\r\nTemp[2]: +24.52 degC\r\n"
)


def test_st_datalogterminal_lines_in_mg_and_mdps(tty: Pty) -> None:
    device = open_with(tty, DATALOG * 6)
    assert device.layout is not None and device.layout.kind == "labelled"
    assert (device.layout.accel_unit, device.layout.gyro_unit) == ("mg", "mdps")
    raw = read_all(device, 6)
    assert not raw.gap.any()
    si = convert_raw_block(raw)
    np.testing.assert_allclose(si.accel_m_s2[0], np.array([12, -3, 1001]) * 1e-3 * G)
    np.testing.assert_allclose(si.gyro_rad_s[0], np.array([140, -350, 70]) * 1e-3 * DEG)
    np.testing.assert_allclose(si.temp_degc[1:], 24.52)  # the temperature of the cycle before
    # the magnetometer's line (mgauss) follows the gyroscope's: it joins the next sample
    assert device.layout.mag_unit == "mgauss"
    assert device.info is not None and device.info.magnetometer is not None
    assert np.isnan(si.mag_ut[0]).all()
    np.testing.assert_allclose(si.mag_ut[1:], np.tile([-21.1, 9.3, 40.2], (5, 1)))
    counters = device.counters
    assert counters.samples == 6 and counters.ignored >= 6 and counters.rejected <= 6
    device.close()


ADAFRUIT_BANNER = (
    "Adafruit LSM6DSOX test!\r\nLSM6DSOX Found!\r\nAccelerometer range set to: +-4G\r\n"
    "Gyro range set to: 2000 degrees/sec\r\nAccelerometer data rate set to: 104 Hz\r\n"
    "Gyro data rate set to: 104 Hz\r\n"
)


def adafruit_sample(ax: float, ay: float, az: float, gx: float, gy: float, gz: float,
                    temp: float = 25.5) -> str:
    """One loop() of examples/adafruit_lsm6dsox_test (Serial.print of floats: 2 decimals)."""
    return (
        f"\t\tTemperature {temp:.2f} deg C\r\n"
        f"\t\tAccel X: {ax:.2f} \tY: {ay:.2f} \tZ: {az:.2f} m/s^2 \r\n"
        f"\t\tGyro X: {gx:.2f} \tY: {gy:.2f} \tZ: {gz:.2f} radians/s \r\n\r\n"
    )


def test_adafruit_lsm6ds_example_output_in_si_units(tty: Pty) -> None:
    loops = [adafruit_sample(0.12 + 0.01 * i, -0.05, 9.81, 0.01, -0.0, 0.02 * i)
             for i in range(8)]
    device = open_with(tty, ADAFRUIT_BANNER + "".join(loops))
    assert device.layout is not None
    assert (device.layout.accel_unit, device.layout.gyro_unit) == ("m/s2", "rad/s")
    raw = read_all(device, 8)
    si = convert_raw_block(raw)
    np.testing.assert_allclose(si.accel_m_s2[:, 0], 0.12 + 0.01 * np.arange(8), atol=1e-9)
    np.testing.assert_allclose(si.accel_m_s2[:, 2], 9.81)
    np.testing.assert_allclose(si.gyro_rad_s[:, 2], np.round(0.02 * np.arange(8), 2))
    np.testing.assert_allclose(si.temp_degc, 25.5)
    device.close()


def test_adafruit_serial_plotter_format_temperature_first(tty: Pty) -> None:
    rows = "".join(f"25.{50 - i % 2},0.12,-0.05,9.81,0.01,0.00,{0.01 * i:.2f}\r\n"
                   for i in range(8))
    device = open_with(tty, rows)
    assert device.layout is not None and device.layout.columns["temp"] == 0
    raw = read_all(device, 8)
    si = convert_raw_block(raw)
    np.testing.assert_allclose(si.temp_degc, [25.50, 25.49] * 4)
    np.testing.assert_allclose(si.accel_m_s2[:, 2], 9.81)  # m/s^2 guessed from |a|
    device.close()


def test_nine_numbers_are_a_9dof_boards_rows_with_the_field_in_microtesla(tty: Pty) -> None:
    text, accel, _gyro = csv_rows(12)
    field = np.array([[21.5 + 0.5 * i, -3.25, -44.0] for i in range(12)])
    rows = "".join(line.rstrip("\r\n") + "," + ",".join(f"{v:.2f}" for v in m) + "\r\n"
                   for line, m in zip(text.splitlines(True), field))
    device = open_with(tty, rows)
    assert device.layout is not None and device.layout.mag_unit == "uT"
    assert device.info is not None and device.info.magnetometer is not None
    assert "field in uT" in device.info.extra["layout"]
    si = convert_raw_block(read_all(device, 12))
    np.testing.assert_allclose(si.accel_m_s2, accel * G)
    np.testing.assert_allclose(si.mag_ut, field)
    device.close()


def test_named_field_columns_in_gauss_and_a_stream_without_them(tty: Pty) -> None:
    header = "time_ms,ax,ay,az,gx,gy,gz,mag_x,mag_y,mag_z\r\n"
    rows = "".join(f"{1000 + 10 * i},0.01,0.02,0.99,0.1,0.2,0.3,0.215,-0.0325,-0.44\r\n"
                   for i in range(10))
    device = open_with(tty, header + rows)
    assert device.layout is not None and device.layout.mag_unit == "gauss"
    si = convert_raw_block(read_all(device, 10))
    np.testing.assert_allclose(si.mag_ut, np.tile([21.5, -3.25, -44.0], (10, 1)))
    device.close()


def test_a_stream_without_a_magnetometer_delivers_no_field(tty: Pty) -> None:
    text, _accel, _gyro = csv_rows(10)
    device = open_with(tty, text)
    assert device.layout is not None and device.layout.mag_unit is None
    assert device.info is not None and device.info.magnetometer is None
    assert read_all(device, 10).mag_raw is None
    device.close()


# -- robustness ---------------------------------------------------------------------------------
def test_garbage_and_lines_split_across_reads(tty: Pty) -> None:
    text, _accel, _gyro = csv_rows(10)
    device = open_with(tty, text)
    assert len(read_all(device, 10)) == 10
    tty.write("0.01,0.02,0.9")  # half a line: nothing yet
    assert device.read(0.05) is None
    tty.write("9,1,2,3\r\n")
    block = read_all(device, 1)
    np.testing.assert_array_equal(block.accel_raw, [[0.01, 0.02, 0.99]])
    garbage = (
        b"\x00\xff\xfe binary junk\r\n"
        b"nan,nan,nan,0,0,0\r\n"          # a glitch on a data line: a lost sample
        b"0.1,0.2\r\n"                     # too short, not data-like enough to count as lost
        b"ovf,0.1,0.2,0.3,0.4,0.5\r\n"     # Arduino's overflow print: lost
        b"0.5,0.5,0.5,1,1,1\r\n"
        + b"x" * 5000 + b"\r\n"            # an endless line
        + b"0.5,0.5,0.5,1,1,2\r\n"
    )
    tty.write(garbage)
    after = read_all(device, 2)
    np.testing.assert_array_equal(after.gyro_raw[:, 2], [1, 2])
    assert after.gap[0] and after.lost_samples == 2
    counters = device.counters
    assert counters.rejected == 5 and counters.samples == 13 and counters.lost_samples == 2
    device.close()


def test_nothing_parsable_says_what_was_seen(tty: Pty) -> None:
    port = tty.port()
    tty.write("Hello from the sketch\r\nWaiting for sensor...\r\n")
    device = TextLineDevice(f"text://{tty.name}?open_timeout=0.3", port=port)
    with pytest.raises(DeviceOpenError) as caught:
        device.open()
    message = str(caught.value)
    assert "no parsable sensor lines within 0.3 s" in message
    assert "'Hello from the sketch'" in message and "ax,ay,az,gx,gy,gz" in message
    assert not device.is_open and not port.is_open


def test_binary_data_suggests_the_baud_rate_or_the_binary_protocol(tty: Pty) -> None:
    port = tty.port()
    tty.write(bytes(range(0, 256, 3)) * 4)
    with pytest.raises(DeviceOpenError, match=r"binary-looking.*baud rate"):
        TextLineDevice(f"text://{tty.name}?open_timeout=0.3", port=port).open()


def test_silence_says_nothing_arrived(tty: Pty) -> None:
    with pytest.raises(DeviceOpenError, match=r"nothing arrived within 0\.3 s"):
        TextLineDevice(f"text://{tty.name}?open_timeout=0.3").open()


class Sketch(threading.Thread):
    """A running sketch: prints a CSV line every 2 ms until stopped (its own pace)."""

    def __init__(self, tty: Pty, header: str = "") -> None:
        super().__init__(daemon=True)
        self.tty, self.header = tty, header
        self.stop = threading.Event()

    def run(self) -> None:
        i = 0
        while not self.stop.is_set():
            if self.header and i % 50 == 0:
                self.tty.write(self.header)
            try:
                self.tty.write(f"{1000 + 2 * i},0.01,0.02,0.99,0.5,-0.5,0.25\r\n")
            except OSError:
                return
            i += 1
            self.stop.wait(0.002)


def test_opened_by_name_from_the_registry_and_unplugged(tty: Pty) -> None:
    sketch = Sketch(tty)
    sketch.start()
    try:
        device = create_device(f"text://{tty.name}?baud=115200&time=ms")
        assert isinstance(device, TextLineDevice)
        info = device.open()
        assert info.odr_hz == pytest.approx(500.0, rel=0.05)  # from the time column
        block = device.read(0.5)
        assert block is not None and len(block) > 0
        np.testing.assert_allclose(np.diff(block.t_s), 0.002, atol=1e-9)
    finally:
        sketch.stop.set()
        sketch.join()
    tty.unplug()
    with pytest.raises(DeviceIOError, match="unplugged"):
        for _ in range(100):  # lines still buffered come first
            device.read(0.1)
    device.close()


def test_host_time_when_the_sketch_prints_no_time(tty: Pty) -> None:
    sketch = Sketch(tty, header="ms,ax,ay,az,gx,gy,gz\r\n")
    sketch.start()
    try:
        device = TextLineDevice(f"text://{tty.name}?time=host")
        device.open()
        start = time.monotonic()
        total = 0
        last_t = -1.0
        while time.monotonic() - start < 0.3:
            block = device.read(0.1)
            if block is not None:
                assert block.t_s[0] > last_t and np.all(np.diff(block.t_s) > 0)
                last_t = float(block.t_s[-1])
                total += len(block)
        assert total > 20
        assert device.layout is not None and "t" not in device.layout.columns
    finally:
        sketch.stop.set()
        sketch.join()
        device.close()


def test_loop_url() -> None:
    port = serial.serial_for_url("loop://", timeout=0.05)
    text, accel, _ = csv_rows(20)
    port.write(text.encode())
    device = TextLineDevice("text://loop://", port=port)
    device.open()
    np.testing.assert_array_equal(read_all(device, 20).accel_raw, accel)
    device.close()


def test_many_lines_take_the_vectorised_path() -> None:
    text, accel, _ = csv_rows(50000)
    lines = text.split("\r\n")[:-1]
    names = ("ax", "ay", "az", "gx", "gy", "gz")
    layout = Layout("columns", 6, {c: i for i, c in enumerate(names)})
    parser = LineParser(layout, TextLineCounters(), threading.Lock())
    started = time.perf_counter()
    parser.feed(lines, np.zeros(len(lines)))
    elapsed = time.perf_counter() - started
    records = parser.records.take()
    assert records is not None
    np.testing.assert_array_equal(records["accel"], accel)
    # About 75 000 lines/s on the CI machine; a serial port at 921600 baud carries ~3 000.
    assert elapsed < 2.5, f"{len(lines) / elapsed:.0f} lines/s"


# -- names, URLs, sniffing ---------------------------------------------------------------------
@pytest.mark.parametrize("name,channel,unit", [
    ("ax", "ax", None), ("accX", "ax", None), ("acc_y", "ay", None), ("ACC_Z[0]", "az", None),
    ("AcX", "ax", None), ("Accel X", "ax", None), ("accelerationZ", "az", None),
    ("ax_g", "ax", "g"), ("ax[m/s^2]", "ax", "m/s2"), ("gx(dps)", "gx", "dps"),
    ("gyroX", "gx", None), ("GYR_Y", "gy", None), ("GyZ", "gz", None),
    ("gyro_x_rads", "gx", "rad/s"),
    ("gyroscopeZ", "gz", None), ("time_ms", "t", "ms"), ("micros", "t", "us"), ("t", "t", None),
    ("Time (s)", "t", "s"), ("temperature", "temp", None), ("MAG_X", "mx", None), ("x", None, None),
    ("magY", "my", None), ("mz_uT", "mz", "uT"), ("mag_x[gauss]", "mx", "gauss"),
    ("Magnetic Z", "mz", None), ("mx", "mx", None),
])
def test_column_names(name: str, channel: str | None, unit: str | None) -> None:
    found = canonical_column(name)
    assert (found.channel, found.unit) == (channel, unit) if channel else found is None


def test_urls() -> None:
    assert parse_text_url("text:///dev/ttyACM0").port == "/dev/ttyACM0"
    assert parse_text_url("text://COM3?baud=9600").baud == 9600
    assert parse_text_url("text://loop://").port == "loop://"
    assert parse_text_url("text://x?port=spy%3A%2F%2F%2Fdev%2FttyUSB0").port == "spy:///dev/ttyUSB0"
    options = parse_text_url("text:///dev/ttyUSB0?columns=t,ax,ay,az&accel=m/s2&gyro=rad/s&time=us")
    assert options.columns == ("t", "ax", "ay", "az") and options.time_unit == "us"
    for url, message in [("text://", "no port"), ("text://COM3?speed=1", "unknown option"),
                         ("text://COM3?accel=furlongs", "g, mg or m/s2"),
                         ("text://COM3?time=hours", "s, ms, us or host"),
                         ("text://COM3?baud=fast", "positive")]:
        with pytest.raises(DeviceUrlError, match=message):
            parse_text_url(url)


def test_looks_like_text_lines() -> None:
    assert looks_like_text_lines(b"garbage\r\n0.1,0.2,0.9,1,2,3\r\n")
    assert looks_like_text_lines(DATALOG.encode())
    assert looks_like_text_lines(b"ax ay az\r\n")
    assert not looks_like_text_lines(b"\x00\x05\x81\x02\x00" * 20)
    assert not looks_like_text_lines(b"0.1,0.2,0.9,1,2,3")  # no complete line yet
