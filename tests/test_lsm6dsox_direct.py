"""The register-level LSM6DSOX driver against the emulated chip, on virtual time (no sleeps).

Expected values come from the emulated chip's truth (what it measured and wrote into its FIFO)
and from drivers.lsm6dsox figures, never typed in, except the documented configuration table.
"""

from __future__ import annotations

import json
import math
import sys
import types
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from app.core.samples import RawBlock, convert_raw_block
from drivers import lsm6dsox
from drivers.errors import DeviceIOError, DeviceOpenError, DeviceUrlError
from drivers.lsm6dsox_direct import mcp2221
from drivers.lsm6dsox_direct import registers as reg
from drivers.lsm6dsox_direct.device import Lsm6dsoxDirectDevice, parse_lsm6dsox_url
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.lsm6dsox_direct.fifo import FifoDecoder
from drivers.lsm6dsox_direct.registers import configuration_sequence
from drivers.registry import available_devices, create_device
from drivers.sim.error_model import UnitErrors, accel_noise_rms_m_s2, gyro_noise_rms_rad_s
from drivers.sim.options import SimOptions

VECTORS = Path(__file__).parent / "vectors" / "lsm6dsox_config.json"
ODRS = list(lsm6dsox.ODR_LABELS_HZ.values())
FULL_SCALES = [(2, 125), (4, 250), (8, 500), (16, 1000), (16, 2000), (2, 2000)]
"""Every accelerometer and every gyroscope full scale at least once."""
TILTING = SimOptions(
    "slow-tilt", seed=5, scenario_params={"amplitude": 30.0, "roll_period": 2.5,
                                          "pitch_period": 3.3}
)
"""Peak rates about 75 dps (inside +-125 dps) and tilts up to 0.5 g on every axis."""


def ideal_unit(freq_fine: int, seed: int = 5) -> UnitErrors:
    """No bias or scale errors, but a trimmed clock (the timestamps must follow the trim)."""
    return replace(UnitErrors.draw(seed).without_errors(), freq_fine=freq_fine)


def make_chip(sim: SimOptions = TILTING, **kwargs: object) -> tuple[EmulatedLsm6dsox, VirtualClock]:
    clock = VirtualClock(100.0)
    kwargs.setdefault("record_truth", True)
    return EmulatedLsm6dsox(sim, clock=clock, **kwargs), clock  # type: ignore[arg-type]


def open_on(chip: EmulatedLsm6dsox, query: str = "odr=104") -> Lsm6dsoxDirectDevice:
    device = Lsm6dsoxDirectDevice(f"lsm6dsox://emulated?{query}", bus=chip)
    device.open()
    return device


def concat(blocks: list[RawBlock]) -> RawBlock:
    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(b, name) for b in blocks])

    return RawBlock(
        t_s=cat("t_s"), accel_raw=cat("accel_raw"), gyro_raw=cat("gyro_raw"),
        temp_raw=cat("temp_raw"), scale=blocks[0].scale, gap=cat("gap"),
        lost_samples=sum(b.lost_samples for b in blocks),
    )


def stream(device: Lsm6dsoxDirectDevice, clock: VirtualClock, seconds: float,
           step_s: float = 0.02) -> RawBlock:
    """Let ``seconds`` of virtual time pass, reading every ``step_s``."""
    blocks = []
    for _ in range(math.ceil(seconds / step_s)):
        clock.advance(step_s)
        block = device.read(0.0)
        if block is not None:
            blocks.append(block)
    assert blocks, "no samples arrived"
    return concat(blocks)


# -- configuration sequence ---------------------------------------------------------------------
def test_configuration_sequence_equals_the_documented_table() -> None:
    # The table in drivers/lsm6dsox_direct/registers.py, for 104 Hz, +-4 g, +-250 dps.
    assert configuration_sequence(104.0, 4, 250) == [
        (0x12, 0x01),  # CTRL3_C SW_RESET
        (0x12, 0x44),  # CTRL3_C BDU | IF_INC
        (0x18, 0xE2),  # CTRL9_XL I3C_DISABLE, DEN bits as reset
        (0x09, 0x44),  # FIFO_CTRL3 BDR_GY = BDR_XL = 104 Hz
        (0x0A, 0xA6),  # FIFO_CTRL4 timestamp every 8, temperature 12.5 Hz, continuous
        (0x19, 0x20),  # CTRL10_C TIMESTAMP_EN
        (0x10, 0x48),  # CTRL1_XL 104 Hz, +-4 g
        (0x11, 0x40),  # CTRL2_G 104 Hz, +-250 dps
    ]


@pytest.mark.parametrize("odr_hz", ODRS)
def test_configuration_sequence_fields_at_every_setting(odr_hz: float) -> None:
    code = lsm6dsox.odr_code_for(odr_hz)
    for accel_fs, gyro_fs in FULL_SCALES:
        writes = dict(configuration_sequence(odr_hz, accel_fs, gyro_fs)[1:])
        assert writes[reg.CTRL1_XL] == code << 4 | lsm6dsox.FS_XL_CODES[accel_fs] << 2
        assert writes[reg.CTRL2_G] == code << 4 | lsm6dsox.FS_G_CODES[gyro_fs] << 1
        assert writes[reg.FIFO_CTRL3] == code << 4 | code


def test_configuration_sequence_rejects_unknown_settings() -> None:
    with pytest.raises(ValueError, match="not an LSM6DSOX rate"):
        configuration_sequence(100.0, 4, 250)
    with pytest.raises(ValueError, match="accel_fs 3"):
        configuration_sequence(104.0, 3, 250)


def test_vector_file_matches_the_sequence() -> None:
    document = json.loads(VECTORS.read_text())
    assert document["settings"], "no settings in the vector file"
    for entry in document["settings"]:
        expected = configuration_sequence(entry["odr_hz"], entry["accel_fs_g"],
                                          entry["gyro_fs_dps"])
        assert [tuple(pair) for pair in entry["sequence"]] == expected


def test_driver_writes_exactly_the_sequence() -> None:
    chip, _clock = make_chip()
    writes: list[tuple[int, int]] = []
    original = chip.write_register

    def spy(address: int, register: int, data: bytes) -> None:
        writes.extend((register + i, b) for i, b in enumerate(data))
        original(address, register, data)

    chip.write_register = spy  # type: ignore[method-assign]
    device = open_on(chip, "odr=833&accel_fs=8&gyro_fs=1000")
    assert writes == configuration_sequence(833.0, 8, 1000)
    assert chip.register_file[reg.FIFO_CTRL4] & reg.FIFO_MODE_MASK == reg.FIFO_MODE_CONTINUOUS
    device.close()


# -- the emulated chip's registers ------------------------------------------------------------
def test_emulated_chip_registers_reset_and_auto_increment() -> None:
    chip, clock = make_chip()
    assert chip.read_registers(0x6A, reg.WHO_AM_I, 1) == b"\x6c"
    chip.write_register(0x6A, reg.CTRL1_XL, bytes([0x48, 0x40]))  # IF_INC: both registers
    assert chip.read_registers(0x6A, reg.CTRL1_XL, 2) == bytes([0x48, 0x40])
    chip.write_register(0x6A, reg.CTRL3_C, bytes([reg.CTRL3_C_SW_RESET]))
    assert chip.read_registers(0x6A, reg.CTRL3_C, 1)[0] & reg.CTRL3_C_SW_RESET
    clock.advance(1e-3)
    assert chip.read_registers(0x6A, reg.CTRL3_C, 1)[0] == reg.CTRL3_C_RESET_VALUE
    assert chip.read_registers(0x6A, reg.CTRL1_XL, 2) == b"\x00\x00"
    chip.write_register(0x6A, reg.CTRL3_C, bytes([0x00]))  # IF_INC off: no auto-increment
    assert chip.read_registers(0x6A, reg.WHO_AM_I, 3) == b"\x6c" * 3
    freq_fine = chip.read_registers(0x6A, reg.INTERNAL_FREQ_FINE, 1)
    assert int.from_bytes(freq_fine, "little", signed=True) == chip.unit.freq_fine
    with pytest.raises(DeviceIOError, match="no ACK from I2C address 0x6B"):
        chip.read_registers(0x6B, reg.WHO_AM_I, 1)


# -- every ODR and full scale -----------------------------------------------------------------
@pytest.mark.parametrize("accel_fs,gyro_fs", FULL_SCALES)
@pytest.mark.parametrize("odr_hz", ODRS)
def test_every_odr_and_full_scale(odr_hz: float, accel_fs: int, gyro_fs: int) -> None:
    freq_fine = 9 if odr_hz < 500 else -13
    chip, clock = make_chip(unit=ideal_unit(freq_fine))
    device = open_on(chip, f"odr={odr_hz}&accel_fs={accel_fs}&gyro_fs={gyro_fs}")
    info = device.info
    assert info is not None
    real_odr = lsm6dsox.ODR_RATES_HZ[lsm6dsox.odr_code_for(odr_hz)]  # "12.5" runs at 13.02
    trimmed_odr = real_odr * (1.0 + lsm6dsox.FREQ_FINE_STEP * freq_fine)
    assert info.odr_hz == pytest.approx(trimmed_odr, abs=5e-4)  # in mHz, as the firmware's
    assert info.extra["tick_s"] == pytest.approx(25e-6 / (1 + 0.0015 * freq_fine), rel=1e-12)

    raw = stream(device, clock, max(0.3, 50.0 / odr_hz), step_s=min(0.02, 100.0 / odr_hz))
    n = len(raw)
    assert n >= 30
    assert not raw.gap.any() and raw.lost_samples == 0
    # The turn-on transient (the first samples after the ODR write) was dropped.
    skip = lsm6dsox.turn_on_discard(odr_hz)
    assert device.driver.settling_dropped == skip  # type: ignore[union-attr]
    truth = {key: values[skip:] for key, values in chip.truth().items()}
    # Bit-exact words: the decoder paired and ordered the FIFO's samples correctly.
    np.testing.assert_array_equal(raw.accel_raw, truth["accel_raw"][:n])
    np.testing.assert_array_equal(raw.gyro_raw, truth["gyro_raw"][:n])

    # LSB scaling: physical values match the truth within the white noise.
    si = convert_raw_block(raw)
    accel_tol = 5.0 * accel_noise_rms_m_s2(accel_fs, trimmed_odr) + lsm6dsox.accel_m_s2_per_lsb(
        accel_fs)
    gyro_tol = 5.0 * gyro_noise_rms_rad_s(trimmed_odr) + lsm6dsox.gyro_rad_s_per_lsb(gyro_fs)
    assert np.max(np.abs(si.accel_m_s2 - truth["specific_force_m_s2"][:n])) < accel_tol
    assert np.max(np.abs(si.gyro_rad_s - truth["angular_rate_rad_s"][:n])) < gyro_tol
    # The signal is large against those tolerances, so a wrong full scale would show.
    assert np.ptp(truth["angular_rate_rad_s"][:n]) > 20 * gyro_tol or n < 200
    np.testing.assert_allclose(si.temp_degc, truth["temp_degc"][:n], atol=0.01 + 1 / 256)

    # Sample rate from the chip's timestamps is the trimmed ODR.
    assert np.all(np.diff(raw.t_s) > 0)
    rate = (n - 1) / (raw.t_s[-1] - raw.t_s[0])
    assert rate == pytest.approx(trimmed_odr, rel=2e-3)
    device.close()


def test_timestamps_follow_the_real_oscillator_including_the_untrimmed_residual() -> None:
    unit = replace(ideal_unit(-4), clock_residual=1.5e-4)
    chip, clock = make_chip(unit=unit)
    device = open_on(chip, "odr=417")
    raw = stream(device, clock, 2.0)
    truth_t = chip.truth()["t_true_s"][lsm6dsox.turn_on_discard(417):][: len(raw)]
    # t_s counts the chip's own (trimmed) clock: true elapsed time x (1 + residual).
    elapsed_true = truth_t[-1] - truth_t[0]
    assert raw.t_s[-1] - raw.t_s[0] == pytest.approx(elapsed_true * (1 + 1.5e-4), rel=2e-5)


def test_small_bursts_split_slots_and_nothing_is_lost() -> None:
    chip, clock = make_chip()
    chip.max_read_bytes = 5 * reg.FIFO_WORD_BYTES  # bursts end between a slot's words
    device = open_on(chip, "odr=833")
    raw = stream(device, clock, 0.5, step_s=0.004)
    skip = lsm6dsox.turn_on_discard(833)  # the turn-on transient, dropped by the driver
    truth = chip.truth()
    np.testing.assert_array_equal(raw.gyro_raw, truth["gyro_raw"][skip:skip + len(raw)])
    assert not raw.gap.any()
    assert chip.transactions > 200  # many small bursts really happened


# -- overrun, gaps, unplug --------------------------------------------------------------------
def test_fifo_overrun_marks_a_gap_with_the_lost_samples() -> None:
    chip, clock = make_chip()
    device = open_on(chip, "odr=208")
    before = stream(device, clock, 0.5)
    clock.advance(6.0)  # FIFO holds about 1.2 s at 208 Hz: it overruns
    after = stream(device, clock, 0.5)
    raw = concat([before, after])
    odr = device.info.odr_hz  # type: ignore[union-attr]
    index = np.rint(raw.t_s * odr).astype(np.int64)
    steps = np.diff(index)
    assert np.all(steps >= 1), "a sample was duplicated or went back in time"
    jumps = np.flatnonzero(steps > 1)
    assert len(jumps) == 1
    first_after = jumps[0] + 1
    assert raw.gap[first_after] and raw.gap.sum() == 1
    assert after.lost_samples == steps[jumps[0]] - 1 > 6.0 * odr - 600
    assert device.driver.decoder.counters.overruns >= 1  # type: ignore[union-attr]
    # The samples after the gap are the chip's samples at those indices (no off-by-one).
    truth = chip.truth()
    row = {int(i): k for k, i in enumerate(truth["index"])}
    first_index = truth["index"][lsm6dsox.turn_on_discard(208)] + index[first_after] - index[0]
    np.testing.assert_array_equal(raw.accel_raw[first_after],
                                  truth["accel_raw"][row[int(first_index)]])


def test_unplugged_adapter_raises_device_io_error() -> None:
    chip, clock = make_chip(fail_after_s=1.0)
    device = open_on(chip)
    stream(device, clock, 0.5)
    clock.advance(1.0)
    with pytest.raises(DeviceIOError, match="unplugged"):
        device.read(0.0)
    device.close()  # closing after an unplug is quiet


# -- WHO_AM_I and addresses -------------------------------------------------------------------
def test_who_am_i_mismatch_says_what_answered() -> None:
    chip, _ = make_chip(who_am_i=0x6A)
    device = Lsm6dsoxDirectDevice("lsm6dsox://emulated", bus=chip)
    with pytest.raises(DeviceOpenError) as caught:
        device.open()
    message = str(caught.value)
    assert "reads 0x6A" in message and "LSM6DSL" in message and "answers 0x6C" in message
    assert not device.is_open


def test_who_am_i_fault_from_the_url() -> None:
    with pytest.raises(DeviceOpenError, match="reads 0x6B"):
        create_device("lsm6dsox://emulated?who_am_i=0x6b").open()


def test_wrong_address_is_an_open_error_naming_it() -> None:
    chip, _ = make_chip()
    device = Lsm6dsoxDirectDevice("lsm6dsox://emulated?address=0x6b", bus=chip)
    with pytest.raises(DeviceOpenError, match="no ACK from I2C address 0x6B"):
        device.open()


# -- self-test --------------------------------------------------------------------------------
STILL = replace(TILTING, scenario="static", scenario_params={})
"""The self-test compares outputs 0.1 s apart: the sensor must be still, as on a bench."""


def test_self_test_passes_on_a_healthy_chip_and_streaming_resumes() -> None:
    chip, clock = make_chip(sim=STILL)
    device = open_on(chip)
    before = stream(device, clock, 0.3)
    result = device.self_test()
    assert result.passed, result.summary()
    expected_mg = chip.self_test_response.accel_mg
    expected_dps = chip.self_test_response.gyro_dps_at_2000
    np.testing.assert_allclose(result.accel_delta_mg, expected_mg, atol=3.0)
    np.testing.assert_allclose(result.gyro_delta_dps, expected_dps, atol=1.0)
    after = stream(device, clock, 0.3)
    assert after.t_s[0] > before.t_s[-1] + 0.1  # the pause is kept on the time axis
    assert after.gap[0] and after.lost_samples > 0
    # The first sample after the restart sits at its true time, the dropped turn-on transient
    # (14 samples at "104 Hz", 0.13 s) included.
    truth = chip.truth()
    rows = np.flatnonzero(np.all(truth["gyro_raw"] == after.gyro_raw[0], axis=1)
                          & np.all(truth["accel_raw"] == after.accel_raw[0], axis=1))
    last = np.flatnonzero(np.all(truth["gyro_raw"] == before.gyro_raw[-1], axis=1)
                          & np.all(truth["accel_raw"] == before.accel_raw[-1], axis=1))
    true_step = truth["t_true_s"][rows[-1]] - truth["t_true_s"][last[0]]
    assert after.t_s[0] - before.t_s[-1] == pytest.approx(true_step, abs=0.02)


def test_self_test_fails_on_a_chip_whose_self_test_does_nothing() -> None:
    chip, clock = make_chip(sim=STILL, self_test_working=False)
    device = open_on(chip)
    result = device.self_test()
    assert not result.accel_pass and not result.gyro_pass and not result.passed
    assert max(result.accel_delta_mg) < reg.SELF_TEST_ACCEL_WINDOW_MG[0]
    assert "FAIL" in result.summary()
    assert len(stream(device, clock, 0.2)) > 0


# -- the FIFO decoder on crafted words --------------------------------------------------------
def word(tag: int, cnt: int, payload: bytes, *, bad_parity: bool = False) -> bytes:
    tag_byte = (tag << 3) | (cnt << 1)
    tag_byte |= bin(tag_byte).count("1") % 2
    return bytes([tag_byte ^ (1 if bad_parity else 0)]) + payload.ljust(6, b"\0")


def slot(cnt: int, accel: int, gyro: int, ticks: int | None = None) -> bytes:
    out = b"" if ticks is None else word(reg.TAG_TIMESTAMP, cnt, ticks.to_bytes(4, "little"))
    out += word(reg.TAG_GYRO, cnt, np.full(3, gyro, "<i2").tobytes())
    return out + word(reg.TAG_ACCEL, cnt, np.full(3, accel, "<i2").tobytes())


def test_decoder_pairs_by_tag_counter_and_counts_what_it_skips() -> None:
    decoder = FifoDecoder(ticks_per_slot=100.0)
    data = slot(0, 10, 20, ticks=2**32 - 150) + slot(1, 11, 21) + word(0x1F, 2, b"")  # unknown
    data += word(reg.TAG_ACCEL, 2, b"\1\0", bad_parity=True) + word(reg.TAG_GYRO, 2, b"")
    data += slot(3, 13, 23)  # slot 2 lost its accelerometer word to a parity error
    data += slot(0, 14, 24, ticks=250)  # the 32-bit tick counter wrapped
    out = decoder.decode(data + word(reg.TAG_GYRO, 1, b""))  # a half slot stays pending
    np.testing.assert_array_equal(out.accel_raw[:, 0], [10, 11, 13, 14])
    np.testing.assert_array_equal(out.gyro_raw[:, 2], [20, 21, 23, 24])
    np.testing.assert_array_equal(out.ticks - out.ticks[0], [0, 100, 300, 400])
    np.testing.assert_array_equal(out.lost_before, [0, 0, 1, 0])
    counters = decoder.counters
    assert (counters.parity_errors, counters.unknown_tags, counters.incomplete_slots) == (1, 1, 1)
    rest = decoder.decode(word(reg.TAG_ACCEL, 1, np.full(3, 15, "<i2").tobytes()))
    np.testing.assert_array_equal(rest.accel_raw[:, 0], [15])  # the pending half completed
    assert rest.ticks[0] - out.ticks[-1] == pytest.approx(100.0)


# -- URLs, registry, discovery -------------------------------------------------------------------
def test_urls_and_registry() -> None:
    assert isinstance(create_device("lsm6dsox://emulated?odr=100"), Lsm6dsoxDirectDevice)
    assert parse_lsm6dsox_url("lsm6dsox://emulated?odr=100").odr_nominal_hz == 104.0
    assert parse_lsm6dsox_url("lsm6dsox://mcp2221?address=0x6b").address == 0x6B
    urls = [d.url for d in available_devices()]
    assert "lsm6dsox://emulated?odr=104" in urls
    for url, message in [
        ("lsm6dsox://spi", "unknown bus"),
        ("lsm6dsox://emulated?gyro_fs=300", "125, 250"),
        ("lsm6dsox://emulated?address=0x50", "0x6a or 0x6b"),
        ("lsm6dsox://emulated?colour=red", "colour"),
        ("lsm6dsox://emulated?realtime=0", "sim:// only"),
        ("lsm6dsox://mcp2221?odr=833", "417"),
        ("lsm6dsox://mcp2221?serial=1&seed=3", "unknown option 'seed'"),
    ]:
        with pytest.raises(DeviceUrlError, match=message):
            parse_lsm6dsox_url(url)
    assert parse_lsm6dsox_url("lsm6dsox://mcp2221?odr=833&force=1").odr_nominal_hz == 833.0


def test_the_emulated_url_streams_in_real_time() -> None:
    device = create_device("lsm6dsox://emulated?odr=417&scenario=static")
    info = device.open()
    assert info.sensor == "LSM6DSOX" and "register level" in info.name
    samples = 0
    for _ in range(20):
        block = device.read(0.1)
        samples += 0 if block is None else len(block)
        if samples >= 40:
            break
    device.close()
    assert samples >= 40


# -- the MCP2221A backend, without hardware ------------------------------------------------------
class _NotAck(Exception):
    pass


class _Timeout(Exception):
    pass


class _LowSCL(Exception):
    pass


class _LowSDA(Exception):
    pass


def fake_easymcp2221(chip: EmulatedLsm6dsox | None, *, open_error: Exception | None = None
                     ) -> types.SimpleNamespace:
    """A stand-in for the EasyMCP2221 module, its adapter backed by an emulated chip."""
    calls: list[tuple] = []

    class Device:
        def __init__(self, VID: int, PID: int, devnum: int, usbserial: str | None) -> None:
            calls.append(("Device", VID, PID, devnum, usbserial))
            if open_error is not None:
                raise open_error
            self.usbserial = usbserial or "0001234"
            self.pointer = 0
            self.fault: Exception | None = None

        def I2C_speed(self, speed: int) -> None:
            calls.append(("I2C_speed", speed))

        def I2C_write(self, addr: int, data: bytes, kind: str = "regular",
                      timeout_ms: int = 20) -> None:
            calls.append(("I2C_write", addr, bytes(data), kind))
            if self.fault is not None:
                raise self.fault
            try:
                if kind == "nonstop":
                    chip.read_registers(addr, data[0], 0)  # address phase only
                    self.pointer = data[0]
                else:
                    chip.write_register(addr, data[0], data[1:])
            except DeviceIOError as exc:
                raise _NotAck("Device did not ACK.") from exc

        def I2C_read(self, addr: int, size: int = 1, kind: str = "regular",
                     timeout_ms: int = 20) -> bytes:
            calls.append(("I2C_read", addr, size, kind))
            return chip.read_registers(addr, self.pointer, size)

    exceptions = types.SimpleNamespace(NotAckError=_NotAck, TimeoutError=_Timeout,
                                       LowSCLError=_LowSCL, LowSDAError=_LowSDA)
    return types.SimpleNamespace(Device=Device, exceptions=exceptions, calls=calls)


def test_mcp2221_missing_library_names_the_package(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "EasyMCP2221", None)  # import fails as if not installed
    with pytest.raises(DeviceOpenError, match=r"EasyMCP2221.*pip install"):
        mcp2221.Mcp2221Bus()
    with pytest.raises(DeviceOpenError, match=r"inclinometer\[mcp2221\]"):
        create_device("lsm6dsox://mcp2221?odr=104").open()
    assert mcp2221.list_adapters() == []
    assert not [d for d in available_devices() if "mcp2221" in d.url]


def test_mcp2221_command_mapping_and_a_full_stream(monkeypatch: pytest.MonkeyPatch) -> None:
    chip = EmulatedLsm6dsox(SimOptions("static"))  # wall clock: the bus waits for real
    library = fake_easymcp2221(chip)
    monkeypatch.setattr(mcp2221, "import_library", lambda: library)
    device = create_device("lsm6dsox://mcp2221?serial=0001234&odr=104&speed=100000")
    info = device.open()
    calls = library.calls
    assert calls[0] == ("Device", 0x04D8, 0x00DD, 0, "0001234")
    assert calls[1] == ("I2C_speed", 100000)
    # WHO_AM_I: register pointer without stop, then a repeated-start read.
    assert calls[2:4] == [("I2C_write", 0x6A, b"\x0f", "nonstop"), ("I2C_read", 0x6A, 1, "restart")]
    # Writes: register then value, one regular transfer each, in the documented order.
    writes = [(c[2][0], c[2][1]) for c in calls if c[0] == "I2C_write" and c[3] == "regular"]
    assert writes == configuration_sequence(104.0, 4, 250)
    assert info.unique_id == "MCP2221A-0001234-0x6A" and "MCP2221A" in info.name
    block = device.read(0.5)
    assert block is not None and len(block) >= 1
    bursts = [c for c in calls if c[0] == "I2C_read" and c[2] % reg.FIFO_WORD_BYTES == 0
              and c[2] > 2]
    assert bursts, "the FIFO was not read in bursts"
    device.close()


def test_mcp2221_errors_become_messages(monkeypatch: pytest.MonkeyPatch) -> None:
    for error, message in [(RuntimeError("No devices found"), "no MCP2221A adapter"),
                           (OSError("open failed"), "udev")]:
        library = fake_easymcp2221(None, open_error=error)
        with pytest.raises(DeviceOpenError, match=message):
            mcp2221.Mcp2221Bus(library=library)  # type: ignore[arg-type]
    chip = EmulatedLsm6dsox(SimOptions("static"))
    library = fake_easymcp2221(chip)
    bus = mcp2221.Mcp2221Bus(library=library)  # type: ignore[arg-type]
    with pytest.raises(DeviceIOError, match="no ACK from I2C address 0x6B"):
        bus.read_registers(0x6B, reg.WHO_AM_I, 1)
    for fault, message in [(_LowSDA("SDA low"), "stuck"), (_Timeout("slow"), "timed out"),
                           (OSError("read error"), "unplugged")]:
        bus._device.fault = fault
        with pytest.raises(DeviceIOError, match=message):
            bus.read_registers(0x6A, reg.WHO_AM_I, 1)
    bus.close()
    with pytest.raises(DeviceIOError, match="closed"):
        bus.read_registers(0x6A, reg.WHO_AM_I, 1)


@pytest.mark.parametrize("part", ["LIS3MDL", "LIS2MDL", None])
def test_mcp2221_probes_for_a_magnetometer_on_its_bus(
        monkeypatch: pytest.MonkeyPatch, part: str | None) -> None:
    from drivers.lsm6dsox_direct import mag_registers as mreg
    from drivers.lsm6dsox_direct.emulated_mag import make_emulated_bus

    bus = make_emulated_bus(EmulatedLsm6dsox(SimOptions("static")), part)
    library = fake_easymcp2221(bus)  # type: ignore[arg-type]
    monkeypatch.setattr(mcp2221, "import_library", lambda: library)
    device = create_device("lsm6dsox://mcp2221?odr=104")
    info = device.open()
    device.close()
    others = [c for c in library.calls if c[0] == "I2C_write" and c[1] != 0x6A]
    if part is None:  # nothing answers: the stream is as before
        assert info.magnetometer is None
        assert {c[1] for c in others} == {0x1C, 0x1E}
        return
    assert info.magnetometer is not None and info.magnetometer.path == "bus"
    assert (info.magnetometer.chip, info.magnetometer.address) == (part, bus.magnetometer.address)
    writes = [(c[2][0], c[2][1]) for c in others if c[3] == "regular"]
    rate = info.magnetometer.odr_hz
    if part == "LIS3MDL":
        expected = [(mreg.LIS3MDL_CTRL_REG2, mreg.LIS3MDL_SOFT_RST),
                    *mreg.lis3mdl_sequence(rate), (mreg.LIS3MDL_CTRL_REG3, 0x03)]
    else:
        expected = [(mreg.LIS2MDL_CFG_REG_A, mreg.LIS2MDL_SOFT_RST),
                    *mreg.lis2mdl_sequence(rate), (mreg.LIS2MDL_CFG_REG_A, 0x03)]
    assert writes == expected  # reset, configuration, and power-down at close


def test_mcp2221_mag_none_leaves_the_bus_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    from drivers.lsm6dsox_direct.emulated_mag import make_emulated_bus

    bus = make_emulated_bus(EmulatedLsm6dsox(SimOptions("static")), "LIS3MDL")
    library = fake_easymcp2221(bus)  # type: ignore[arg-type]
    monkeypatch.setattr(mcp2221, "import_library", lambda: library)
    device = create_device("lsm6dsox://mcp2221?odr=104&mag=none")
    assert device.open().magnetometer is None
    device.close()
    assert {c[1] for c in library.calls if c[0] in ("I2C_write", "I2C_read")} == {0x6A}
