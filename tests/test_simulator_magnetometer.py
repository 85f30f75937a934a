"""The simulated magnetometer (issue 31): the earth's field (WMM), the chip's rate, LSB and
noise, the unit's errors, disturbances and faults.

Expected values come from app.core.earth_field (the WMM), the chip table and the device's
``unit_errors``, never typed in.
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.earth_field import DEFAULT_PLACE, Place, earth_field
from app.core.orientation import quaternion_from_roll_pitch, up_in_sensor_frame
from app.core.recording.format import simulator_metadata
from app.core.samples import RawBlock, SampleBlock, convert_raw_block
from drivers.errors import DeviceUrlError
from drivers.sim.device import SimulatedDevice
from drivers.sim.magnetometer import LIS2MDL, LIS3MDL, MAG_CHIPS

DATE = "2026-06-01"


def stream(url: str, n: int, **overrides: object) -> tuple[SimulatedDevice, SampleBlock]:
    """Open ``url`` (realtime=0) and read ``n`` rows as one converted block."""
    device = SimulatedDevice(url, realtime=False, block=min(n, 4096), **overrides)
    device.open()
    blocks: list[RawBlock] = []
    total = 0
    while total < n:
        block = device.read(0.0)
        assert block is not None
        blocks.append(block)
        total += len(block)
    samples = [convert_raw_block(b) for b in blocks]

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(s, name) for s in samples])

    joined = SampleBlock(cat("t_s"), cat("accel_m_s2"), cat("gyro_rad_s"), cat("temp_degc"),
                         cat("gap"), cat("reference_quat"),
                         None if samples[0].mag_ut is None else cat("mag_ut"))
    return device, joined


def field_rows(block: SampleBlock) -> np.ndarray:
    assert block.mag_ut is not None
    return ~np.isnan(block.mag_ut[:, 0])


def test_without_mag_nothing_changes() -> None:
    device, block = stream("sim://static", 300)
    assert block.mag_ut is None and device.mag_chip is None and device.magnetometer is None
    assert device.info is not None and device.info.magnetometer is None
    assert device.scale.mag_ut_per_lsb == 1.0
    truth = simulator_metadata(device)["simulator"]
    assert not [key for key in truth["unit_errors"] if key.startswith("mag")]
    assert "earth_field" not in truth


@pytest.mark.parametrize("name", list(MAG_CHIPS))
def test_the_chip_is_described_and_scaled_as_its_datasheet(name: str) -> None:
    chip = MAG_CHIPS[name]
    device, _ = stream(f"sim://static?mag={name}", 200)
    info = device.info
    assert info is not None and info.magnetometer == chip.info()
    assert info.magnetometer.path == "simulated" and chip.name in info.name
    assert device.scale.mag_ut_per_lsb == chip.ut_per_lsb
    raw = device.read(0.0)
    assert raw is not None and raw.mag_raw is not None and raw.mag_raw.shape == (len(raw), 3)
    counts = raw.mag_raw[~np.isnan(raw.mag_raw[:, 0])]
    assert len(counts) and np.array_equal(counts, np.rint(counts))


def test_datasheet_figures() -> None:
    # LIS3MDL: 6842 LSB/gauss at +-4 gauss, 1 gauss = 100 uT; LIS2MDL: 1.5 mgauss/LSB.
    assert LIS3MDL.ut_per_lsb * 6842 == pytest.approx(100.0)
    assert LIS3MDL.range_ut == 400.0 and LIS3MDL.address == 0x1C and LIS3MDL.odr_hz == 80.0
    assert LIS2MDL.ut_per_lsb == pytest.approx(0.15) and LIS2MDL.address == 0x1E
    assert LIS2MDL.odr_hz == 100.0 and LIS2MDL.range_ut == pytest.approx(4915.2)


@pytest.mark.parametrize(("roll", "pitch", "yaw"), [(0, 0, 0), (30, -20, 40), (170, 60, -120)])
def test_ideal_chip_reads_the_wmm_field_turned_into_the_sensor_frame(roll, pitch, yaw) -> None:
    _, block = stream(
        f"sim://static?mag=lis3mdl&errors=0&noise=0&date={DATE}&roll={roll}&pitch={pitch}"
        f"&yaw={yaw}", 400)
    wmm = earth_field(DEFAULT_PLACE, dt.date.fromisoformat(DATE))
    q = quaternion_from_roll_pitch(roll, pitch, yaw)
    expected = quat.rotate_inverse(q, wmm.enu_magnetic_ut())
    mag = block.mag_ut[field_rows(block)]
    assert len(mag) > 200
    # Exactly the WMM vector, to the quantisation (half an LSB per axis).
    assert np.max(np.abs(mag - expected)) <= 0.5 * LIS3MDL.ut_per_lsb + 1e-9
    # Its strength and its dip below the horizon against the true "up".
    strength = np.linalg.norm(mag, axis=1)
    up = up_in_sensor_frame(q)
    dip = np.degrees(np.arcsin(-(mag @ up) / strength))
    assert np.allclose(strength, wmm.total_ut, atol=0.02)
    assert np.allclose(dip, wmm.dip_deg, atol=0.03)


def test_level_sensor_at_yaw_zero_reads_zero_east_horizontal_north_and_down() -> None:
    """The earth frame is ENU with y to magnetic north: x east reads 0, y reads H, z -Z."""
    _, block = stream(f"sim://static?mag=lis2mdl&errors=0&noise=0&date={DATE}"
                      "&place=-33.9,18.4,10", 300)
    wmm = earth_field(Place(-33.9, 18.4, 10.0), dt.date.fromisoformat(DATE))
    mag = block.mag_ut[field_rows(block)]
    half = 0.5 * LIS2MDL.ut_per_lsb + 1e-9
    assert np.all(np.abs(mag[:, 0]) <= half)
    assert np.all(np.abs(mag[:, 1] - wmm.horizontal_ut) <= half)
    assert np.all(np.abs(mag[:, 2] + wmm.down_ut) <= half)
    assert wmm.down_ut < 0  # Cape Town: the field points up, the other sign from Berlin


@pytest.mark.parametrize(("mag", "odr"), [("lis3mdl", 104), ("lis3mdl", 416), ("lis2mdl", 52),
                                          ("lis2mdl", 833)])
def test_field_rows_come_at_the_chips_own_rate(mag: str, odr: int) -> None:
    device, block = stream(f"sim://wobble?mag={mag}&odr={odr}", int(10 * odr))
    magnetometer = device.magnetometer
    assert magnetometer is not None
    rows = field_rows(block)
    chip_rate = MAG_CHIPS[mag].odr_hz * (1.0 + device.unit_errors.magnetometer.odr_error)
    assert magnetometer.true_odr_hz == chip_rate
    # Sample k of the chip lands on the first row at or after its true time.
    n = len(block)
    span = n / device.true_odr_hz
    times = (np.arange(0, math.ceil(span * chip_rate) + 2) + device.unit_errors.magnetometer.phase
             ) / chip_rate
    landing = np.ceil(times * device.true_odr_hz - 1e-9).astype(int)
    expected = np.zeros(n, dtype=bool)
    expected[np.unique(landing[landing < n])] = True
    assert np.array_equal(rows, expected)
    if chip_rate < device.true_odr_hz:  # each sample on a row of its own
        assert rows.sum() == np.count_nonzero(landing < n)
        assert np.isnan(block.mag_ut[~rows]).all()
    else:  # faster than the rows: every row carries the newest (row 0 at t = 0 precedes them)
        assert rows[1:].all()


def test_the_same_seed_gives_the_same_field_however_the_stream_is_cut() -> None:
    url = "sim://magtour?seed=3"
    _, one = stream(url, 3000)
    device = SimulatedDevice(url, realtime=False, block=77)
    device.open()
    parts = []
    while sum(len(p) for p in parts) < 3000:
        parts.append(convert_raw_block(device.read(0.0)).mag_ut)
    two = np.concatenate(parts)[:3000]
    assert np.array_equal(np.isnan(one.mag_ut[:3000]), np.isnan(two))
    rows = field_rows(one)[:3000]
    assert np.array_equal(one.mag_ut[:3000][rows], two[rows])


def test_url_options_are_checked() -> None:
    for url, words in [
        ("sim://static?mag=hmc5883", ["mag=", "lis3mdl", "lis2mdl", "none"]),
        ("sim://static?place=1,2", ["place", "needs a magnetometer"]),
        ("sim://static?mag=lis3mdl&place=95,2", ["latitude"]),
        ("sim://static?mag=lis3mdl&place=north", ["place", "LAT,LON"]),
        ("sim://static?mag=lis3mdl&place=1,north", ["place", "not a number"]),
        ("sim://static?mag=lis3mdl&date=2019-01-01", ["date", "2025"]),
        ("sim://static?mag=lis3mdl&date=tomorrow", ["YYYY-MM-DD"]),
    ]:
        with pytest.raises(DeviceUrlError) as caught:
            SimulatedDevice(url)
        message = str(caught.value)
        assert all(word in message for word in words), message
    assert SimulatedDevice("sim://magtour").mag_chip is LIS3MDL  # the tour's default
    assert SimulatedDevice("sim://magtour?mag=none").mag_chip is None
