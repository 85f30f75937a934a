"""The firmware's command handling, run on the host against a bus that records register writes.

The bus is the emulated LSM6DSOX behind a recorder, on virtual time. Register writes are checked
against the configuration sequence the Python direct driver uses (``configuration_sequence``,
dumped to tests/vectors/lsm6dsox_config.json); CONFIG figures against what the Python driver
computes for the same chip.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from fwcore import LED_ERROR, LED_IDLE, LED_STREAMING, FirmwareCore, ForwardingBus, rate_fits

from drivers import lsm6dsox
from drivers.errors import DeviceError, DeviceIOError
from drivers.link import protocol as p
from drivers.link.framing import frame_bytes
from drivers.lsm6dsox_direct import registers as reg
from drivers.lsm6dsox_direct.driver import Lsm6dsoxDriver
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.sim.options import SimOptions

CONFIG_VECTORS = json.loads(
    (Path(__file__).parent / "vectors" / "lsm6dsox_config.json").read_text()
)["settings"]
UNIQUE_ID = bytes.fromhex("1A0036000851393235363300")


class RecordingBus(ForwardingBus):
    """Records every register write; ``present=False`` unplugs the chip."""

    def __init__(self, inner: EmulatedLsm6dsox) -> None:
        super().__init__(inner)
        self.writes: list[tuple[int, int]] = []
        self.present = True

    def write_register(self, address: int, register: int, data: bytes) -> None:
        self._check()
        super().write_register(address, register, data)
        self.writes += [(register + i, value) for i, value in enumerate(data)]

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        self._check()
        return super().read_registers(address, register, length)

    def _check(self) -> None:
        if not self.present:
            raise DeviceIOError("unplugged")

    def take_writes(self) -> list[tuple[int, int]]:
        writes, self.writes = self.writes, []
        return writes


def make_board(firmware_lib, *, seed: int = 4, chip_options: dict | None = None,
               **core_options) -> tuple[FirmwareCore, RecordingBus, EmulatedLsm6dsox]:
    chip = EmulatedLsm6dsox(SimOptions("static", seed=seed), clock=VirtualClock(10.0),
                            **(chip_options or {}))
    bus = RecordingBus(chip)
    core_options.setdefault("unique_id", UNIQUE_ID)
    core = FirmwareCore(firmware_lib, bus, **core_options)
    return core, bus, chip


@pytest.fixture
def board(firmware_lib):
    core, bus, chip = make_board(firmware_lib)
    yield core, bus, chip
    core.close()


def only(packets: list[p.Packet], kind: type) -> list:
    return [packet for packet in packets if isinstance(packet, kind)]


def test_power_on_configures_the_default_setting_with_the_shared_sequence(board) -> None:
    core, bus, _ = board
    assert bus.take_writes() == configuration_sequence_for(104.0, 4, 250)
    assert core.led_mode == LED_IDLE
    assert core.packets() == []  # silent until asked


def configuration_sequence_for(odr_hz: float, accel_fs_g: int, gyro_fs_dps: int):
    """From the vector file (which tests/test_lsm6dsox_direct.py ties to the Python driver)."""
    for setting in CONFIG_VECTORS:
        if (setting["odr_hz"], setting["accel_fs_g"], setting["gyro_fs_dps"]) == (
            odr_hz, accel_fs_g, gyro_fs_dps
        ):
            return [tuple(write) for write in setting["sequence"]]
    return reg.configuration_sequence(odr_hz, accel_fs_g, gyro_fs_dps)


def setting_id(setting: dict) -> str:
    return f"{setting['odr_hz']:g}Hz-{setting['accel_fs_g']}g-{setting['gyro_fs_dps']}dps"


@pytest.mark.parametrize("setting", CONFIG_VECTORS, ids=setting_id)
def test_configure_writes_exactly_the_vector_sequence(firmware_lib, setting) -> None:
    core, bus, chip = make_board(firmware_lib, i2c_hz=0)  # every ODR allowed
    bus.take_writes()
    odr_code = lsm6dsox.odr_code_for(setting["odr_hz"])
    core.send(p.Configure(odr_code, setting["accel_fs_g"], setting["gyro_fs_dps"]))
    ack, config = core.packets()
    assert ack == p.Ack(p.CONFIGURE, p.ACK_OK, "")
    assert bus.take_writes() == [tuple(write) for write in setting["sequence"]]
    # CONFIG describes the trimmed clock exactly as the Python driver does for this chip.
    python = Lsm6dsoxDriver(RecordingBus(chip)).configure(
        setting["odr_hz"], setting["accel_fs_g"], setting["gyro_fs_dps"])
    assert config == p.Config(round(python.odr_hz * 1000), setting["accel_fs_g"],
                              setting["gyro_fs_dps"], round(python.tick_s * 1e9))
    core.close()


def test_hello_answers_info_and_config(board) -> None:
    core, _, chip = board
    core.send(p.Hello())
    info, config = core.packets()
    assert info == p.Info(1, (1, 2, 0), 0x6C, UNIQUE_ID, "NUCLEO-F746ZG")
    # "104 Hz" runs at 6666.67 / 64 = 104.167 Hz, times the chip's trim.
    assert config.odr_mhz == lsm6dsox.odr_mhz(4, chip.unit.freq_fine)
    assert config.odr_mhz == pytest.approx(104_166.67 * chip.trim, abs=1)
    assert (config.accel_fs_g, config.gyro_fs_dps) == (4, 250)


@pytest.mark.parametrize(("command", "message"), [
    (p.Configure(11, 4, 250), "odr_code 11: use 1 (12.5 Hz) to 10 (6667 Hz)"),
    (p.Configure(0, 4, 250), "odr_code 0"),
    (p.Configure(4, 3, 250), "accel_fs_g 3: use 2, 4, 8 or 16"),
    (p.Configure(4, 4, 300), "gyro_fs_dps 300: use 125, 250, 500, 1000 or 2000"),
    (p.Configure(9, 4, 250), "kbit/s on I2C1; the bus at 400 kHz carries about 320 "
                             "(highest ODR 1667 Hz)"),
])
def test_bad_settings_are_refused_and_nothing_changes(board, command, message) -> None:
    core, bus, _ = board
    bus.take_writes()
    core.send(command)
    ack, config = core.packets()
    assert (ack.command, ack.status) == (p.CONFIGURE, p.ACK_BAD_ARGUMENT)
    assert message in ack.message
    assert (config.accel_fs_g, config.gyro_fs_dps) == (4, 250)
    assert bus.take_writes() == []


def test_rates_the_uart_cannot_carry_are_refused(firmware_lib) -> None:
    core, _, _ = make_board(firmware_lib, baud=115_200, i2c_hz=0)
    core.send(p.Configure(8, 4, 250))
    ack, _ = core.packets()
    assert ack.status == p.ACK_BAD_ARGUMENT
    full_packet_bytes = 396 + 2 + 1  # packet, COBS overhead, delimiter: 32 samples
    need = lsm6dsox.odr_mhz(8) * full_packet_bytes // 32 // 1000  # the real 1666.67 Hz
    assert ack.message == (f"ODR 1667 Hz needs {need} bytes/s; the UART "
                           f"at 115200 baud carries {115_200 // 10} (highest ODR 833 Hz)")
    core.close()


@pytest.mark.parametrize(("baud", "highest_hz"), [
    (115_200, 833), (230_400, 1667), (460_800, 3333), (921_600, 6667)])
def test_link_limits_match_the_protocol_table(firmware_lib, baud, highest_hz) -> None:
    """docs/protocol.md section 6, and the Python emulated board's rule."""
    from drivers.emulated_nucleo import odr_fits_link

    for code, label in lsm6dsox.ODR_LABELS_HZ.items():
        fits, _ = rate_fits(firmware_lib, code, baud, 0)
        assert fits == (label <= highest_hz) == odr_fits_link(lsm6dsox.ODR_RATES_HZ[code], baud)
    assert rate_fits(firmware_lib, 10, 0, 0)[0]  # native USB, no bus limit


def test_i2c_at_400_khz_limits_the_rate_to_1667_hz(firmware_lib) -> None:
    allowed = [hz for code, hz in lsm6dsox.ODR_LABELS_HZ.items()
               if rate_fits(firmware_lib, code, 921_600, 400_000)[0]]
    assert max(allowed) == 1667.0 and min(allowed) == 12.5


def hz_text(millihertz: int) -> str:
    """How the firmware writes a rate: 105872 -> "105.872", 104000 -> "104"."""
    whole, fraction = divmod(millihertz, 1000)
    return f"{whole}.{fraction:03d}".rstrip("0") if fraction else str(whole)


def test_commands_while_streaming(board) -> None:
    core, _, chip = board
    core.send(p.Start())
    ack, log = core.packets()[:2]
    assert ack == p.Ack(p.START, p.ACK_OK, "")
    real = hz_text(lsm6dsox.odr_mhz(4, chip.unit.freq_fine))
    assert log.text == (f"streaming 104 Hz (really {real} Hz), +-4 g, +-250 dps "
                        "from the LSM6DSOX at 0x6A")
    assert core.streaming and core.led_mode == LED_STREAMING
    core.send(p.Configure(5, 4, 250), p.SelfTest(), p.Start(), p.Hello(), p.Ping(7))
    replies = [x for x in core.packets() if not isinstance(x, p.Samples)]
    assert replies[0] == p.Ack(p.CONFIGURE, p.ACK_BUSY, "streaming: send STOP first")
    assert isinstance(replies[1], p.Config)
    assert replies[2] == p.Ack(p.SELF_TEST, p.ACK_BUSY, "streaming: send STOP first")
    assert replies[3] == p.Ack(p.START, p.ACK_OK, "already streaming")
    assert [type(x) for x in replies[4:]] == [p.Info, p.Config, p.Pong]
    core.send(p.Stop(), p.Stop())
    assert [x for x in core.packets() if isinstance(x, p.Ack)] == [p.Ack(p.STOP, p.ACK_OK, "")] * 2
    assert not core.streaming and core.led_mode == LED_IDLE


def test_ping_unknown_commands_and_wrong_lengths(board) -> None:
    core, _, _ = board
    core.send(p.Ping(0xDEADBEEF))
    assert core.packets() == [p.Pong(0xDEADBEEF)]
    core.receive(frame_bytes(p.PING, b"\x01\x02"))
    core.receive(frame_bytes(p.HELLO, b"\x00"))
    core.receive(frame_bytes(0x99, b"\x01"))
    core.receive(frame_bytes(p.SAMPLES, b""))  # a device packet sent to the device
    assert core.packets() == [
        p.Ack(p.PING, p.ACK_BAD_ARGUMENT, "payload of 2 bytes, expected 4"),
        p.Ack(p.HELLO, p.ACK_BAD_ARGUMENT, "payload of 1 bytes, expected 0"),
        p.Ack(0x99, p.ACK_UNSUPPORTED, "unknown command 0x99 (protocol v1)"),
        p.Ack(p.SAMPLES, p.ACK_UNSUPPORTED, "unknown command 0x03 (protocol v1)"),
    ]


def test_bad_frames_get_no_answer(board) -> None:
    core, _, _ = board
    good = frame_bytes(p.PING, b"\x01\x00\x00\x00")
    bad_crc = bytearray(good)
    bad_crc[3] ^= 0x10
    core.receive(b"\x00" + bytes(bad_crc) + b"\x05\x01\x00" + b"\x42" * 600 + b"\x00" + good)
    assert core.packets() == [p.Pong(1)]
    assert core.counters()["rx_bad_frames"] == 3


def test_no_sensor_then_the_sensor_is_plugged_in(firmware_lib) -> None:
    chip = EmulatedLsm6dsox(SimOptions("static", seed=2), clock=VirtualClock(10.0))
    bus = RecordingBus(chip)
    bus.present = False
    core = FirmwareCore(firmware_lib, bus, unique_id=UNIQUE_ID)
    assert core.led_mode == LED_ERROR
    core.send(p.Hello())
    info, config, log = core.packets()
    assert info.who_am_i == 0x00  # the host reports "nothing driving the bus"
    assert config.odr_mhz == 104_167 and config.tick_ns == 25_000  # untrimmed "104 Hz"
    assert log.level == 3 and "no LSM6DSOX answers on I2C1 (PB8 SCL, PB9 SDA)" in log.text
    core.send(p.Start())
    (ack,) = core.packets()
    assert ack.status == p.ACK_SENSOR_ERROR and "0x6A or 0x6B" in ack.message
    bus.present = True
    core.run(0.6)
    (log,) = core.packets()
    assert log == p.Log(1, "the LSM6DSOX answers again")
    assert core.led_mode == LED_IDLE
    assert bus.take_writes() == configuration_sequence_for(104.0, 4, 250)
    core.close()


def test_another_part_on_the_bus_is_named(firmware_lib) -> None:
    core, _, _ = make_board(firmware_lib, chip_options={"who_am_i": 0x6A})
    core.send(p.Hello())
    info, _, log = core.packets()
    assert info.who_am_i == 0x6A
    assert "WHO_AM_I at I2C address 0x6A reads 0x6A, an LSM6DSOX answers 0x6C" in log.text
    assert core.led_mode == LED_ERROR
    core.close()


def test_the_second_address_is_found(firmware_lib) -> None:
    core, bus, _ = make_board(firmware_lib, chip_options={"address": 0x6B})
    assert bus.take_writes() == configuration_sequence_for(104.0, 4, 250)
    core.send(p.Start())
    assert "at 0x6B" in core.packets()[1].text
    core.close()


def test_self_test_measures_the_chips_response_and_restores_the_setting(firmware_lib) -> None:
    core, bus, chip = make_board(firmware_lib, i2c_hz=0)
    core.send(p.Configure(7, 8, 500))
    core.packets()
    bus.take_writes()
    core.send(p.SelfTest())
    ack, result = core.packets()
    assert ack == p.Ack(p.SELF_TEST, p.ACK_OK, "")
    assert result.accel_pass and result.gyro_pass
    expected_accel = chip.self_test_response.accel_mg
    expected_gyro = chip.self_test_response.gyro_dps_at_2000
    for axis in range(3):
        assert result.accel_delta_mg[axis] == pytest.approx(expected_accel[axis], abs=4)
        assert result.gyro_delta_dps[axis] == pytest.approx(expected_gyro[axis], abs=2)
    writes = bus.take_writes()
    assert (reg.CTRL5_C, reg.CTRL5_C_ST_XL_POSITIVE) in writes
    assert (reg.CTRL5_C, reg.CTRL5_C_ST_G_POSITIVE) in writes
    assert writes[-8:] == configuration_sequence_for(833.0, 8, 500)
    core.send(p.Start())
    assert core.packets()[0].status == p.ACK_OK
    core.close()


def test_a_chip_whose_self_test_does_nothing_fails_it(firmware_lib) -> None:
    core, _, _ = make_board(firmware_lib, chip_options={"self_test_working": False})
    core.send(p.SelfTest())
    ack, result = core.packets()
    assert ack.status == p.ACK_OK
    assert not result.accel_pass and not result.gyro_pass
    assert all(abs(v) < 50 for v in result.accel_delta_mg)
    core.close()


def test_self_test_without_a_sensor_is_a_sensor_error(firmware_lib) -> None:
    core, bus, _ = make_board(firmware_lib)
    bus.present = False
    core.send(p.SelfTest())
    (ack,) = core.packets()
    assert (ack.command, ack.status) == (p.SELF_TEST, p.ACK_SENSOR_ERROR)
    core.close()


def test_led_patterns(board) -> None:
    core, _, _ = board
    assert all(core.led_lit(LED_IDLE, ms) for ms in range(0, 2000, 7))
    streaming = [core.led_lit(LED_STREAMING, ms) for ms in range(2000)]
    assert sum(streaming) == 1000 and streaming[0] and not streaming[500]
    error = [core.led_lit(LED_ERROR, ms) for ms in range(1000)]
    assert sum(error) == 8 * 62  # 8 flashes a second


class StubbornBus(RecordingBus):
    """A chip that ignores writes to one register, or never finishes its software reset."""

    def __init__(self, inner: EmulatedLsm6dsox, *, ignore: int | None = None,
                 stuck_in_reset: bool = False) -> None:
        super().__init__(inner)
        self.ignore = ignore
        self.stuck_in_reset = stuck_in_reset

    def write_register(self, address: int, register: int, data: bytes) -> None:
        if register == self.ignore:
            self.writes.append((register, data[0]))
            return
        super().write_register(address, register, data)

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        data = super().read_registers(address, register, length)
        if self.stuck_in_reset and register == reg.CTRL3_C:
            return bytes([data[0] | reg.CTRL3_C_SW_RESET]) + data[1:]
        return data


@pytest.mark.parametrize(("options", "message"), [
    ({"ignore": reg.CTRL2_G},
     "the LSM6DSOX did not keep its configuration (register read-back differs)"),
    ({"stuck_in_reset": True}, "the LSM6DSOX software reset did not finish within 50 ms"),
])
def test_a_chip_that_does_not_take_the_setting_is_a_sensor_error(firmware_lib, options,
                                                                  message) -> None:
    chip = EmulatedLsm6dsox(SimOptions("static", seed=3), clock=VirtualClock(10.0))
    healthy = RecordingBus(chip)
    core = FirmwareCore(firmware_lib, healthy, unique_id=UNIQUE_ID)
    assert core.led_mode == LED_IDLE
    core.bus = StubbornBus(chip, **options)  # the chip goes bad after power-on
    core.send(p.Configure(5, 8, 500))
    ack, config = core.packets()
    assert ack == p.Ack(p.CONFIGURE, p.ACK_SENSOR_ERROR, message)
    assert (config.accel_fs_g, config.gyro_fs_dps) == (4, 250)  # the settings in effect
    assert core.led_mode == LED_ERROR
    core.send(p.Start())
    (ack,) = core.packets()
    assert ack.status == p.ACK_SENSOR_ERROR
    core.close()


@pytest.mark.parametrize("bus_hz", [100_000, 400_000, 1_000_000])
def test_the_emulated_board_limits_rates_as_the_firmware_does(firmware_lib, bus_hz) -> None:
    """``inclinometer simulate`` (the Python emulated NUCLEO) follows the firmware's rule."""
    from drivers.emulated_nucleo import odr_fits_sensor_bus

    for code, hz in lsm6dsox.ODR_RATES_HZ.items():
        assert odr_fits_sensor_bus(hz, bus_hz) == rate_fits(firmware_lib, code, 0, bus_hz)[0]


def test_the_emulated_board_refuses_what_i2c_cannot_carry() -> None:
    from drivers.emulated_nucleo import EmulatedNucleo
    from drivers.serial_link import SerialLinkDevice

    board = EmulatedNucleo("static", sensor_bus_hz=400_000)
    device = SerialLinkDevice(f"serial://{board.port}?odr=3333")
    try:
        with pytest.raises(DeviceError, match=r"kbit/s on I2C1; the bus at 400 kHz"):
            device.open()
        device.close()
        ok = SerialLinkDevice(f"serial://{board.port}?odr=1667")
        assert ok.open().odr_nominal_hz == 1667.0
        ok.close()
    finally:
        board.close()


def test_the_firmware_rate_and_discard_tables_are_the_python_ones(firmware_lib) -> None:
    """drivers/lsm6dsox.py is the source of truth; firmware/core/lsm6dsox.c holds a copy."""
    import ctypes

    firmware_lib.lsm_odr_nominal_mhz.restype = ctypes.c_uint32
    firmware_lib.lsm_odr_nominal_mhz.argtypes = [ctypes.c_uint8]
    firmware_lib.lsm_odr_label_mhz.restype = ctypes.c_uint32
    firmware_lib.lsm_odr_label_mhz.argtypes = [ctypes.c_uint8]
    firmware_lib.lsm_turn_on_discard.restype = ctypes.c_uint16
    firmware_lib.lsm_turn_on_discard.argtypes = [ctypes.c_uint8, ctypes.c_bool]
    for code, label in lsm6dsox.ODR_LABELS_HZ.items():
        assert firmware_lib.lsm_odr_nominal_mhz(code) == lsm6dsox.odr_mhz(code)
        assert firmware_lib.lsm_odr_nominal_mhz(code) == round(lsm6dsox.ODR_RATES_HZ[code] * 1000)
        assert firmware_lib.lsm_odr_label_mhz(code) == round(label * 1000)
        accel, gyro = lsm6dsox.TURN_ON_DISCARD[code]
        assert firmware_lib.lsm_turn_on_discard(code, False) == accel
        assert firmware_lib.lsm_turn_on_discard(code, True) == gyro
    assert firmware_lib.lsm_odr_nominal_mhz(1) == 13_021  # "12.5 Hz" is 13.02 Hz
    assert firmware_lib.lsm_odr_nominal_mhz(11) == firmware_lib.lsm_odr_label_mhz(0) == 0


@pytest.mark.parametrize("freq_fine", [-128, -37, -1, 0, 1, 19, 127])
def test_config_odr_matches_the_python_rounding_for_every_trim(firmware_lib, freq_fine) -> None:
    chip = EmulatedLsm6dsox(SimOptions("static", seed=2), clock=VirtualClock(1.0))
    chip.unit = replace(chip.unit, freq_fine=freq_fine)  # INTERNAL_FREQ_FINE after a reset
    core = FirmwareCore(firmware_lib, RecordingBus(chip), unique_id=UNIQUE_ID)
    for code in (1, 4, 8):
        core.send(p.Configure(code, 4, 250))
        _, config = core.packets()
        assert config.odr_mhz == lsm6dsox.odr_mhz(code, freq_fine)
        assert config.tick_ns == lsm6dsox.tick_ns(freq_fine)
    core.close()
