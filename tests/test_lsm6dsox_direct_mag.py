"""The emulated LIS3MDL / LIS2MDL and the direct driver's magnetometer, on virtual time (#31).

Expected values come from the emulated chips' truth (what they converted, at which true time)
and from the register map, never typed in except the datasheet's register facts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.earth_field import DEFAULT_PLACE, earth_field
from app.core.samples import RawBlock
from drivers.errors import DeviceIOError, DeviceUrlError
from drivers.lsm6dsox_direct import mag_registers as mreg
from drivers.lsm6dsox_direct.device import Lsm6dsoxDirectDevice, parse_lsm6dsox_url
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.lsm6dsox_direct.emulated_mag import EmulatedBus, make_emulated_bus
from drivers.lsm6dsox_direct.mag_driver import MagnetometerDriver
from drivers.sim.options import parse_sim_url

PARTS = ("LIS3MDL", "LIS2MDL")


def make_bus(part: str | None, *, ideal: bool = False, address: int | None = None,
             fail_after_s: float | None = None) -> tuple[EmulatedBus, VirtualClock]:
    """An LSM6DSOX and (unless None) the magnetometer ``part`` on one emulated bus."""
    params = {"seed": "7", "amplitude": "30", "roll_period": "2.5", "pitch_period": "3.3"}
    if part is not None:
        params["mag"] = part.lower()
    if ideal:
        params.update(errors="0", noise="0")
    clock = VirtualClock(100.0)
    chip = EmulatedLsm6dsox(parse_sim_url("sim://slow-tilt", params), clock=clock,
                            record_truth=True)
    bus = make_emulated_bus(chip, part, address=address, record_truth=True,
                            fail_after_s=fail_after_s)
    return bus, clock


def status_register(part: str) -> int:
    return mreg.LIS3MDL_STATUS_REG if part == "LIS3MDL" else mreg.LIS2MDL_STATUS_REG


def out_register(part: str) -> int:
    return mreg.LIS3MDL_OUT_X_L if part == "LIS3MDL" else mreg.LIS2MDL_OUTX_L_REG


def burst(part: str, register: int) -> int:
    """The sub-address of a multi-byte transfer (the LIS3MDL needs the MSB set)."""
    return register | (mreg.LIS3MDL_AUTO_INCREMENT if part == "LIS3MDL" else 0)


def configured(part: str, rate_hz: float, **kwargs: object
               ) -> tuple[EmulatedBus, VirtualClock, MagnetometerDriver]:
    bus, clock = make_bus(part, **kwargs)  # type: ignore[arg-type]
    driver = MagnetometerDriver.probe(bus)
    assert driver is not None and driver.part == part
    driver.configure(rate_hz)
    return bus, clock, driver


# -- the chips' registers ---------------------------------------------------------------------
@pytest.mark.parametrize("part", PARTS)
def test_who_am_i_and_reset_values(part: str) -> None:
    bus, _ = make_bus(part)
    address = bus.magnetometer.address
    if part == "LIS3MDL":
        assert address == 0x1C
        assert bus.read_registers(address, 0x0F, 1) == bytes([0x3D])
        regs = bus.read_registers(address, 0x20 | 0x80, 5)
        assert list(regs) == [mreg.LIS3MDL_RESET_VALUES[r] for r in range(0x20, 0x25)]
    else:
        assert address == 0x1E
        assert bus.read_registers(address, 0x4F, 1) == bytes([0x40])
        assert list(bus.read_registers(address, 0x60, 3)) == [0x03, 0x00, 0x00]
    assert bus.magnetometer.rate_hz == 0.0  # power-down / idle until configured


def test_lis3mdl_auto_increments_only_with_the_msb() -> None:
    bus, _ = make_bus("LIS3MDL")
    bus.write_register(0x1C, 0x20 | 0x80, bytes([0x70, 0x20]))  # CTRL_REG1, CTRL_REG2
    assert list(bus.read_registers(0x1C, 0x20 | 0x80, 2)) == [0x70, 0x20]
    assert list(bus.read_registers(0x1C, 0x20, 3)) == [0x70] * 3
    bus.write_register(0x1C, 0x23, bytes([0x0C, 0x40]))  # no MSB: both bytes to CTRL_REG4
    assert list(bus.read_registers(0x1C, 0x23 | 0x80, 2)) == [0x40, 0x00]


def test_the_lis3mdl_answers_at_0x1e_with_sa1_high_and_nothing_else_acks() -> None:
    bus, _ = make_bus("LIS3MDL", address=0x1E)
    assert bus.read_registers(0x1E, 0x0F, 1) == bytes([0x3D])
    with pytest.raises(DeviceIOError, match="no ACK from I2C address 0x1C"):
        bus.read_registers(0x1C, 0x0F, 1)
    assert MagnetometerDriver.probe(bus).address == 0x1E  # type: ignore[union-attr]


@pytest.mark.parametrize(("part", "asked", "expected"), [
    ("LIS3MDL", 10.0, 10.0), ("LIS3MDL", 79.0, 40.0), ("LIS3MDL", 1000.0, 80.0),
    ("LIS2MDL", 10.0, 10.0), ("LIS2MDL", 60.0, 50.0), ("LIS2MDL", 1000.0, 100.0),
])
def test_configuration_sets_the_rate(part: str, asked: float, expected: float) -> None:
    bus, clock, driver = configured(part, asked)
    chip = bus.magnetometer
    assert driver.settings is not None and driver.settings.odr_hz == expected
    assert chip.rate_hz == expected
    seconds = 4.0
    clock.advance(seconds)
    converted = chip.samples_converted
    true_rate = expected * (1.0 + chip.errors.odr_error)
    assert abs(converted - true_rate * seconds) <= 1.0


def test_lis3mdl_configuration_bits() -> None:
    bus, _, driver = configured("LIS3MDL", 20.0)
    regs = bus.read_registers(0x1C, 0x20 | 0x80, 5)
    assert (regs[0] >> 5) & 3 == 3 and (regs[0] >> 2) & 7 == 5  # OM UHP, DO 20 Hz
    assert (regs[1] >> 5) & 3 == 0  # +-4 gauss
    assert regs[2] & 3 == 0  # continuous
    assert (regs[3] >> 2) & 3 == 3  # OMZ UHP
    assert regs[4] & 0x40  # BDU
    assert driver.settings is not None
    assert driver.settings.ut_per_lsb == pytest.approx(100.0 / 6842.0)


def test_lis2mdl_configuration_bits() -> None:
    bus, _, _ = configured("LIS2MDL", 50.0)
    a, b, c = bus.read_registers(0x1E, 0x60, 3)
    assert a & 0x80 and (a >> 2) & 3 == 2 and a & 3 == 0  # COMP_TEMP_EN, 50 Hz, continuous
    assert b & 0x02  # OFF_CANC
    assert c & 0x10  # BDU


@pytest.mark.parametrize("part", PARTS)
def test_data_ready_then_overrun(part: str) -> None:
    bus, clock, _ = configured(part, 10.0)
    chip, address = bus.magnetometer, bus.magnetometer.address
    period = 1.0 / (10.0 * (1.0 + chip.errors.odr_error))
    assert bus.read_registers(address, status_register(part), 1)[0] & 0x08 == 0
    clock.advance(period * chip.errors.phase + 1e-6)  # the first sample, at phase / rate
    data = bus.read_registers(address, burst(part, status_register(part)), 7)
    assert data[0] & 0x08 and not data[0] & 0x80  # ZYXDA, no ZYXOR
    latest = chip.truth()["raw"][-1]
    assert np.array_equal(np.frombuffer(data[1:], "<i2"), latest)
    assert bus.read_registers(address, status_register(part), 1)[0] == 0  # cleared by the read
    clock.advance(2.0 * period)  # two samples, none read: the first was overwritten
    status = bus.read_registers(address, status_register(part), 1)[0]
    assert status & 0x08 and status & 0x80
    out = bus.read_registers(address, burst(part, out_register(part)), 6)
    assert np.array_equal(np.frombuffer(out, "<i2"), chip.truth()["raw"][-1])
    assert bus.read_registers(address, status_register(part), 1)[0] == 0


@pytest.mark.parametrize("bdu", [True, False])
def test_bdu_holds_the_outputs_between_low_and_high_byte(bdu: bool) -> None:
    bus, clock, _ = configured("LIS3MDL", 10.0)
    if not bdu:
        bus.write_register(0x1C, mreg.LIS3MDL_CTRL_REG5, bytes([0]))
    clock.advance(1.0)
    bus.read_registers(0x1C, 0x28, 1)  # OUT_X_L alone
    old = bus.magnetometer.truth()["raw"][-1]
    clock.advance(0.1)
    rest = np.frombuffer(bus.read_registers(0x1C, 0x2A | 0x80, 4), "<i2")  # Y and Z
    new = bus.magnetometer.truth()["raw"][-1]
    assert not np.array_equal(old[1:], new[1:])  # the test means something
    assert np.array_equal(rest, old[1:] if bdu else new[1:])
    bus.read_registers(0x1C, 0x29, 1)  # OUT_X_H releases the hold
    out = np.frombuffer(bus.read_registers(0x1C, 0x28 | 0x80, 6), "<i2")
    assert np.array_equal(out, new)


@pytest.mark.parametrize("part", PARTS)
def test_soft_reset_restores_the_reset_values(part: str) -> None:
    bus, _, driver = configured(part, 20.0)
    if part == "LIS3MDL":
        bus.write_register(0x1C, mreg.LIS3MDL_CTRL_REG2, bytes([mreg.LIS3MDL_SOFT_RST]))
    else:
        bus.write_register(0x1E, mreg.LIS2MDL_CFG_REG_A, bytes([mreg.LIS2MDL_SOFT_RST]))
    assert bus.magnetometer.rate_hz == 0.0
    driver.configure(20.0)
    assert bus.magnetometer.rate_hz == 20.0


# -- the direct driver ------------------------------------------------------------------------
def stream(bus: EmulatedBus, query: str, seconds: float
           ) -> tuple[Lsm6dsoxDirectDevice, list[RawBlock]]:
    device = Lsm6dsoxDirectDevice(f"lsm6dsox://emulated?odr=104&{query}", bus=bus)
    device.open()
    blocks: list[RawBlock] = []
    stop = bus.monotonic() + seconds
    while bus.monotonic() < stop:
        block = device.read(0.1)
        if block is not None:
            blocks.append(block)
    return device, blocks


def joined(blocks: list[RawBlock], key: str) -> np.ndarray:
    return np.concatenate([getattr(b, key) for b in blocks])


@pytest.mark.parametrize("part", PARTS)
def test_the_driver_finds_the_chip_and_delivers_the_wmm_field(part: str) -> None:
    bus, _ = make_bus(part, ideal=True)
    device, blocks = stream(bus, f"mag={part.lower()}", 6.0)
    info = device.info
    assert info is not None and info.magnetometer is not None
    assert (info.magnetometer.chip, info.magnetometer.path) == (part, "bus")
    assert info.magnetometer.address == bus.magnetometer.address
    assert info.magnetometer.odr_hz == 10.0  # half the 20 Hz poll rate at 104 Hz
    assert blocks[0].scale.mag_ut_per_lsb == info.magnetometer.ut_per_lsb
    mag_raw = joined(blocks, "mag_raw")
    accel_raw = joined(blocks, "accel_raw")
    # The rows are the LSM6DSOX's newest batched samples: their true times from its truth.
    lsm_truth = bus.lsm6dsox.truth()
    n = len(accel_raw)
    assert np.array_equal(lsm_truth["accel_raw"][-n:], accel_raw)
    t_rows = lsm_truth["t_true_s"][-n:]
    truth = bus.magnetometer.truth()
    rows = np.flatnonzero(~np.isnan(mag_raw[:, 0]))
    span = (truth["t_true_s"] > t_rows[0] + 0.2) & (truth["t_true_s"] < t_rows[-1] - 0.2)
    assert len(rows) >= np.count_nonzero(span)  # every sample delivered (no overruns)
    assert device.magnetometer is not None and device.magnetometer.overruns == 0
    for row in rows:
        # The sample is one the chip converted before the row, read at most a poll later.
        match = np.flatnonzero(np.all(truth["raw"] == mag_raw[row], axis=1)
                               & (truth["t_true_s"] <= t_rows[row]))
        assert len(match), f"row {row}: no converted sample before it reads {mag_raw[row]}"
        latency = t_rows[row] - truth["t_true_s"][match[-1]]
        assert latency < 0.1
    # The WMM field in the accelerometer's frame, to the LSB: the dip against gravity too.
    field = earth_field(DEFAULT_PLACE)
    mag_ut = mag_raw[rows] * info.magnetometer.ut_per_lsb
    assert np.allclose(np.linalg.norm(mag_ut, axis=1), field.total_ut, atol=0.5)
    # Against gravity as the accelerometer measured it when the field sample was taken (the
    # row comes up to a poll later, while the board turns): the angle is 90 degrees + dip.
    t_mag = np.array([truth["t_true_s"][np.flatnonzero(np.all(truth["raw"] == mag_raw[r],
                                                              axis=1))[-1]] for r in rows])
    accel = np.column_stack([np.interp(t_mag, lsm_truth["t_true_s"], lsm_truth["accel_raw"][:, i])
                             for i in range(3)])
    cos = np.sum(accel * mag_ut, axis=1) / np.linalg.norm(accel, axis=1) / np.linalg.norm(
        mag_ut, axis=1)
    assert np.allclose(np.degrees(np.arccos(cos)), 90.0 + field.dip_deg, atol=0.5)
    expected = quat.rotate_inverse(bus.lsm6dsox.scenario.orientation(
        truth["t_true_s"]), np.broadcast_to(field.enu_magnetic_ut(), (len(truth["raw"]), 3)))
    assert np.allclose(truth["raw"] * info.magnetometer.ut_per_lsb, expected,
                       atol=info.magnetometer.ut_per_lsb)
    device.close()


@pytest.mark.parametrize("query", ["mag=lis3mdl", "mag=none"])
def test_a_bus_without_magnetometer_streams_as_before(query: str) -> None:
    bus, _ = make_bus(None)
    device, blocks = stream(bus, query, 1.0)
    assert device.info is not None and device.info.magnetometer is None
    assert blocks and all(b.mag_raw is None for b in blocks)
    assert device.take_messages() == []


def test_mag_none_leaves_a_present_chip_alone() -> None:
    bus, _ = make_bus("LIS3MDL")
    device, blocks = stream(bus, "mag=none", 1.0)
    assert device.info is not None and device.info.magnetometer is None
    assert all(b.mag_raw is None for b in blocks)
    assert bus.magnetometer.transactions == 0


@pytest.mark.parametrize("part", PARTS)
def test_a_magnetometer_that_stops_answering_is_reported_and_the_stream_goes_on(
        part: str) -> None:
    bus, _ = make_bus(part, fail_after_s=2.0)
    device, blocks = stream(bus, f"mag={part.lower()}", 4.0)
    messages = device.take_messages()
    assert len(messages) == 1 and messages[0].level == 2
    assert "stopped answering" in messages[0].text and part in messages[0].text
    assert device.magnetometer is None
    t_s = joined(blocks, "t_s")
    mag_raw = joined(blocks, "mag_raw")
    assert t_s[-1] - t_s[0] > 3.5  # the accelerometer went on
    assert np.all(np.isnan(mag_raw[t_s > t_s[0] + 2.2]))
    assert np.count_nonzero(~np.isnan(mag_raw[t_s < t_s[0] + 1.8, 0])) >= 10
    device.close()


def test_the_url_option() -> None:
    assert parse_lsm6dsox_url("lsm6dsox://emulated").mag == "none"
    assert parse_lsm6dsox_url("lsm6dsox://emulated?mag=LIS2MDL").mag == "lis2mdl"
    assert parse_lsm6dsox_url("lsm6dsox://mcp2221").mag == "auto"
    assert parse_lsm6dsox_url("lsm6dsox://mcp2221?mag=none").mag == "none"
    opts = parse_lsm6dsox_url("lsm6dsox://emulated?mag=lis3mdl&mag_fail_after=3")
    assert opts.mag_fail_after_s == 3.0
    for url, words in [
        ("lsm6dsox://emulated?mag=auto", "lis3mdl, lis2mdl or none"),
        ("lsm6dsox://mcp2221?mag=lis3mdl", "auto, none"),
        ("lsm6dsox://emulated?mag=lis3mdl&mag_odr=20", "mag_odr is for sim://"),
        ("lsm6dsox://emulated?mag_fail_after=3", "needs an emulated magnetometer"),
    ]:
        with pytest.raises(DeviceUrlError, match=words):
            parse_lsm6dsox_url(url)


def test_the_emulated_url_puts_the_chip_on_the_bus() -> None:
    device = Lsm6dsoxDirectDevice("lsm6dsox://emulated?mag=lis2mdl&seed=3")
    bus = device._make_bus()
    assert isinstance(bus, EmulatedBus) and bus.magnetometer is not None
    assert bus.magnetometer.part == "LIS2MDL" and bus.magnetometer.address == 0x1E
    assert math.isclose(bus.monotonic(), bus.lsm6dsox.monotonic())
    plain = Lsm6dsoxDirectDevice("lsm6dsox://emulated?seed=3")._make_bus()
    assert isinstance(plain, EmulatedLsm6dsox)


def test_the_field_goes_on_after_a_self_test() -> None:
    bus, _ = make_bus("LIS3MDL", ideal=True)
    device, before = stream(bus, "mag=lis3mdl", 1.5)
    assert device.info is not None and "LIS3MDL" in device.info.name
    assert device.self_test().passed
    after: list[RawBlock] = []
    stop = bus.monotonic() + 1.5
    while bus.monotonic() < stop:
        block = device.read(0.1)
        if block is not None:
            after.append(block)
    for blocks in (before, after):
        t_s, mag_raw = joined(blocks, "t_s"), joined(blocks, "mag_raw")
        count = np.count_nonzero(~np.isnan(mag_raw[:, 0]))
        assert abs(count - 10.0 * (t_s[-1] - t_s[0])) <= 3  # 10 Hz on either side
    assert joined(after, "t_s")[0] > joined(before, "t_s")[-1]
    device.close()
