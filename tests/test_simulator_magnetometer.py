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
from app.core.calibration import MagnetometerCalibration
from app.core.earth_field import DEFAULT_PLACE, Place, earth_field
from app.core.orientation import quaternion_from_roll_pitch, up_in_sensor_frame
from app.core.recording.format import simulator_metadata
from app.core.samples import RawBlock, SampleBlock, convert_raw_block
from drivers.errors import DeviceUrlError
from drivers.sim.device import SimulatedDevice
from drivers.sim.magnetometer import LIS2MDL, LIS3MDL, MAG_CHIPS
from drivers.sim.scenarios import SCENARIOS

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
                                          ("lis2mdl", 833), ("lis3mdl&mag_odr=155", 208),
                                          ("lis3mdl&mag_odr=10", 104),
                                          ("lis2mdl&mag_odr=20", 26)])
def test_field_rows_come_at_the_chips_own_rate(mag: str, odr: int) -> None:
    device, block = stream(f"sim://wobble?mag={mag}&odr={odr}", int(10 * odr))
    chip = device.mag_chip
    assert chip is not None and device.info.magnetometer.odr_hz == chip.odr_hz
    mag, _, rate = mag.partition("&mag_odr=")
    assert chip.odr_hz == (float(rate) if rate else MAG_CHIPS[mag].odr_hz)
    magnetometer = device.magnetometer
    assert magnetometer is not None
    rows = field_rows(block)
    chip_rate = chip.odr_hz * (1.0 + device.unit_errors.magnetometer.odr_error)
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
        ("sim://static?mag=lis2mdl&mag_odr=80", ["mag_odr", "10, 20, 50, 100"]),
        ("sim://static?mag_odr=80", ["needs a magnetometer"]),
    ]:
        with pytest.raises(DeviceUrlError) as caught:
            SimulatedDevice(url)
        message = str(caught.value)
        assert all(word in message for word in words), message
    assert SimulatedDevice("sim://magtour").mag_chip is LIS3MDL  # the tour's default
    assert SimulatedDevice("sim://magtour?mag=none").mag_chip is None


# -- the unit's errors -----------------------------------------------------------------------
def true_sensor_field(device: SimulatedDevice, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows carrying a field sample among the first ``n`` and the true sensor-frame field there
    (the WMM and disturbances turned by the true orientation at each sample's own time)."""
    magnetometer = device.magnetometer
    assert magnetometer is not None and device.earth_field is not None
    t_true, rows = magnetometer.samples_for_rows(0, n, device.true_odr_hz)
    earth = magnetometer.world.field_ut(device.device_time(t_true))
    return rows, quat.rotate_inverse(device.scenario.orientation(t_true), earth)


def test_the_truths_calibration_recovers_the_field_exactly() -> None:
    device, block = stream(f"sim://magtour?seed=11&noise=0&date={DATE}", 6000)
    rows, truth = true_sensor_field(device, len(block))
    measured = block.mag_ut[rows]
    errors = device.unit_errors.magnetometer
    assert errors is not None
    # The forward model: counts are the errors applied to the truth, rounded to the LSB.
    lsb = LIS3MDL.ut_per_lsb
    assert np.array_equal(np.rint(errors.apply(truth) / lsb), np.rint(measured / lsb))
    # The unit is realistic: tens of uT of hard iron, a few % of soft iron, a 1-2 degree turn.
    assert 5.0 < np.max(np.abs(errors.hard_iron_ut)) <= 40.0
    assert 0.0 < np.max(np.abs(errors.soft_iron - np.eye(3))) <= 0.05
    assert np.allclose(errors.soft_iron, errors.soft_iron.T)
    assert np.allclose(errors.alignment @ errors.alignment.T, np.eye(3), atol=1e-12)
    turn = math.degrees(math.acos((np.trace(errors.alignment) - 1.0) / 2.0))
    assert 1.0 <= turn <= 2.0 and turn == pytest.approx(errors.alignment_deg)
    # The truth as the recording's metadata carries it, in the binding calibrate-mag form.
    unit = simulator_metadata(device)["simulator"]["unit_errors"]
    assert np.allclose(unit["mag_hard_iron_ut"], errors.hard_iron_ut)
    assert np.allclose(unit["mag_soft_iron"], errors.soft_iron)
    assert np.allclose(unit["mag_alignment"], errors.alignment)
    calibration = MagnetometerCalibration.from_json(unit["mag_calibration"])
    recovered = calibration.apply(measured)
    # Exact to the LSB: the quantisation (half an LSB per axis) through the inverse matrix.
    bound = 0.5 * lsb * np.abs(calibration.soft_iron).sum(axis=1) + 1e-9
    assert np.all(np.abs(recovered - truth) <= bound)
    # Uncalibrated, the field is far off (the test could fail).
    assert np.max(np.linalg.norm(measured - truth, axis=1)) > 10.0


def test_errors_off_gives_an_ideal_magnetometer_with_the_datasheet_noise() -> None:
    device, block = stream(f"sim://static?mag=lis3mdl&errors=0&date={DATE}", 8000)
    errors = device.unit_errors.magnetometer
    assert errors is not None and not np.any(errors.hard_iron_ut)
    assert np.array_equal(errors.matrix, np.eye(3)) and errors.odr_error == 0.0
    wmm = earth_field(DEFAULT_PLACE, dt.date.fromisoformat(DATE)).enu_magnetic_ut()
    mag = block.mag_ut[field_rows(block)]
    noise = mag.std(axis=0)
    assert np.allclose(mag.mean(axis=0), wmm, atol=0.05)
    # RMS per axis as the datasheet's (LIS3MDL ultra-high-performance: 3.2, 3.2, 4.1 mgauss).
    assert np.allclose(noise, LIS3MDL.noise_ut, rtol=0.08)


# -- disturbances ----------------------------------------------------------------------------
def disturbed(url: str, seconds: float) -> tuple[SimulatedDevice, np.ndarray, np.ndarray,
                                                 np.ndarray, np.ndarray]:
    """An ideal static chip with disturbances: sample times (device clock), measured field,
    the undisturbed field (sensor frame) and the disturbances' truth."""
    device, block = stream(url, int(seconds * 104))
    assert device.magnetometer is not None and device.earth_field is not None
    t_true, rows = device.magnetometer.samples_for_rows(0, len(block), device.true_odr_hz)
    q = device.scenario.orientation(t_true)
    calm = quat.rotate_inverse(q, device.earth_field.enu_magnetic_ut())
    return device, device.device_time(t_true), block.mag_ut[rows], calm, q


def test_a_passing_magnet_rises_and_falls_inside_its_window() -> None:
    url = (f"sim://static?mag=lis3mdl&errors=0&noise=0&date={DATE}&roll=20&yaw=70"
           "&magdist=magnet:200@4-8")
    device, t, mag, calm, q = disturbed(url, 12)
    extra = np.linalg.norm(mag - calm, axis=1)
    truth = simulator_metadata(device)["simulator"]["mag_disturbances"]
    assert [d["kind"] for d in truth] == ["magnet"]
    magnet = truth[0]
    assert (magnet["start_s"], magnet["end_s"], magnet["closest_s"]) == (4.0, 8.0, 6.0)
    # The dipole's field from the truth's geometry, computed here.
    r = -(np.asarray(magnet["closest_m"]) + (t - 6.0)[:, None] * np.asarray(
        magnet["velocity_m_s"]))
    dist = np.linalg.norm(r, axis=1, keepdims=True)
    m = np.asarray(magnet["moment_a_m2"])
    dipole = 1e-7 * (3.0 * r * (r @ m)[:, None] / dist**2 - m) / dist**3 * 1e6
    assert np.max(np.abs(mag - calm - quat.rotate_inverse(q, dipole))) < 0.02
    near = np.abs(t - 6.0) < 0.02
    assert np.all(extra[near] > 100.0) and extra.max() == pytest.approx(200.0, abs=2.0)
    assert np.all(extra[(t < 4.0) | (t > 8.0)] <= 200.0 / 25)  # 1/25 of it at the edges
    assert np.all(extra[(t < 3.0) | (t > 9.0)] < 1.5)  # and falling as 1/r^3
    inside = (t > 5.0) & (t < 7.0)
    assert np.all(extra[inside] > 20.0)


def test_a_steel_desk_distorts_the_field_while_the_board_lies_on_it() -> None:
    url = (f"sim://static?mag=lis2mdl&errors=0&noise=0&date={DATE}&pitch=10"
           "&magdist=desk:40@3-9")
    device, t, mag, calm, q = disturbed(url, 12)
    desk = simulator_metadata(device)["simulator"]["mag_disturbances"][0]
    extra = quat.rotate_inverse(q, np.asarray(desk["extra_ut"]))
    earth = device.earth_field.enu_magnetic_ut()
    assert np.allclose(desk["extra_ut"], np.asarray(desk["distortion"]) @ earth
                       + np.asarray(desk["offset_ut"]))
    assert np.linalg.norm(desk["offset_ut"]) == pytest.approx(40.0)
    half = 0.5 * LIS2MDL.ut_per_lsb + 1e-9
    on = (t >= 4.0) & (t < 8.0)
    off = (t < 3.0) | (t >= 9.0)
    assert np.all(np.abs(mag[on] - calm[on] - extra[on]) <= half)
    assert np.all(np.abs(mag[off] - calm[off]) <= half)
    ramp = (t > 3.0) & (t < 4.0)
    size = np.linalg.norm(mag[ramp] - calm[ramp], axis=1)
    assert np.all(np.diff(size) > -2 * half)  # it comes in smoothly


def test_a_running_motor_adds_its_ac_field_and_offset() -> None:
    url = (f"sim://static?mag=lis3mdl&errors=0&noise=0&date={DATE}"
           "&magdist=motor:6:60@2")
    device, t, mag, calm, q = disturbed(url, 6)
    motor = simulator_metadata(device)["simulator"]["mag_disturbances"][0]
    assert motor["end_s"] is None and motor["frequency_hz"] == 60.0
    wave = np.sin(2 * np.pi * 60.0 * t + motor["phase_rad"])[:, None]
    field_ = np.asarray(motor["offset_ut"]) + 6.0 * wave * np.asarray(motor["direction"])
    expected = np.where((t >= 2.0)[:, None], quat.rotate_inverse(q, field_), 0.0)
    assert np.max(np.abs(mag - calm - expected)) <= 0.5 * LIS3MDL.ut_per_lsb * 3
    running = t > 2.0
    along = quat.rotate_inverse(q[running], np.asarray(motor["direction"]))
    ac = mag[running] - calm[running] - quat.rotate_inverse(q[running], motor["offset_ut"])
    assert np.sqrt(np.mean(np.sum(ac * along, axis=1) ** 2)) == pytest.approx(
        6.0 / math.sqrt(2.0), rel=0.05)
    assert np.max(np.abs(mag[t < 2.0] - calm[t < 2.0])) <= 0.5 * LIS3MDL.ut_per_lsb + 1e-9


def test_disturbance_specs_are_checked() -> None:
    for text, words in [
        ("magnet", ["@START"]), ("lamp@3", ["unknown kind", "magnet, desk, motor"]),
        ("desk:0", ["SIZE"]), ("magnet@5-4", ["END"]), ("desk:1:2", ["FREQ"]),
        ("motor@x", ["START", "not a number"]), ("desk,,motor", ["empty"]),
    ]:
        with pytest.raises(DeviceUrlError) as caught:
            SimulatedDevice(f"sim://static?mag=lis3mdl&magdist={text}")
        assert all(word in str(caught.value) for word in words), str(caught.value)


# -- faults ------------------------------------------------------------------------------------
def test_faults_on_the_magnetometers_channels() -> None:
    device, block = stream(f"sim://wobble?mag=lis3mdl&date={DATE}&fault=stuck:mx@2"
                           "&fault=bias:mz:50@3-4", 600)
    rows = field_rows(block)
    t, mag = block.t_s[rows], block.mag_ut[rows]
    stuck = mag[t >= 2.0, 0]
    assert len(stuck) > 200 and np.all(stuck == stuck[0])
    assert len(np.unique(mag[t < 2.0, 0])) > 20
    _, clean = stream(f"sim://wobble?mag=lis3mdl&date={DATE}", 600)
    step = mag[:, 2] - clean.mag_ut[rows][:, 2]
    assert np.allclose(step[(t >= 3.0) & (t < 4.0)], 50.0, atol=LIS3MDL.ut_per_lsb)
    assert np.all(step[(t < 3.0) | (t >= 4.0)] == 0.0)
    assert np.array_equal(block.accel_m_s2, clean.accel_m_s2)  # the other chip is untouched
    assert device.injected_faults[0]["unit"] is None and device.injected_faults[1]["unit"] == "uT"
    with pytest.raises(DeviceUrlError, match=r"mx\.\.mz need a magnetometer"):
        SimulatedDevice("sim://wobble?fault=stuck:mx@2")


# -- the calibration tour ----------------------------------------------------------------------
def test_the_magtour_turns_the_field_through_every_direction() -> None:
    device = SimulatedDevice("sim://magtour?seed=5&errors=0&noise=0", realtime=False)
    scenario = device.scenario
    t = np.arange(0.0, scenario.round_s, 0.05)
    b = quat.rotate_inverse(scenario.orientation(t), device.earth_field.enu_magnetic_ut())
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    k = np.arange(200) + 0.5
    z = 1.0 - 2.0 * k / 200
    ring = np.sqrt(1.0 - z * z)
    angle = np.pi * (1.0 + 5.0**0.5) * k
    directions = np.stack([ring * np.cos(angle), ring * np.sin(angle), z], axis=1)
    nearest = np.degrees(np.arccos(np.clip((directions @ b.T).max(axis=1), -1.0, 1.0)))
    assert nearest.max() < 35.0 and np.median(nearest) < 10.0
    # It turns within the gyroscope's range and comes back to its start after a round.
    assert np.degrees(np.abs(scenario.angular_rate(t)).max()) < 200.0
    assert quat.angle_between(scenario.orientation(np.array([0.0]))[0],
                              scenario.orientation(np.array([scenario.round_s]))[0]) < 1e-6
    other = SimulatedDevice("sim://magtour?seed=6", realtime=False).scenario
    assert not np.allclose(other.orientation(t[:50]), scenario.orientation(t[:50]))
    # The same unit on another tour (data a fit never saw), and that tour for any unit.
    elsewhere = SimulatedDevice("sim://magtour?seed=5&path=9", realtime=False)
    unit = SimulatedDevice("sim://magtour?seed=5", realtime=False).unit_errors.magnetometer
    assert np.any(unit.hard_iron_ut)
    assert np.array_equal(elsewhere.unit_errors.magnetometer.hard_iron_ut, unit.hard_iron_ut)
    assert not np.allclose(elsewhere.scenario.orientation(t[:50]), scenario.orientation(t[:50]))
    same_path = SimulatedDevice("sim://magtour?seed=8&path=9", realtime=False).scenario
    assert np.array_equal(same_path.orientation(t), elsewhere.scenario.orientation(t))


def test_blocks_cut_by_the_recorder_and_diagnose_keep_the_field() -> None:
    """A duration-limited recording (and diagnose) cut their last block: the field stays."""
    from app.services.diagnosis import _head
    from app.services.recorder import _cut

    device = SimulatedDevice("sim://magtour?realtime=0&block=300")
    device.open()
    raw = device.read(0.0)
    assert raw is not None and raw.mag_raw is not None
    for cut in (_cut(raw, 123), _head(raw, 123)):
        assert cut.mag_raw is not None and len(cut) == 123
        assert np.array_equal(cut.mag_raw, raw.mag_raw[:123], equal_nan=True)


def test_fault_specs_take_mx_to_mz_only_where_asked() -> None:
    from app.core.faults.injection import FAULT_CHANNELS, parse_fault_spec

    with pytest.raises(ValueError, match="unknown channel 'mx'"):
        parse_fault_spec("stuck:mx@1")  # recordings' evaluate-faults: six channels as before
    spec = parse_fault_spec("bias:mz:25@1-2", FAULT_CHANNELS)
    assert spec.axis == 8 and spec.si_size() == 25.0 and spec.as_dict()["unit"] == "uT"


def test_a_strong_magnet_saturates_the_chip_at_its_16_bits() -> None:
    _, block = stream(f"sim://static?mag=lis3mdl&errors=0&noise=0&date={DATE}"
                      "&magdist=magnet:3000@1-3", 400)
    counts = np.rint(block.mag_ut[field_rows(block)] / LIS3MDL.ut_per_lsb)
    assert counts.max() == 32767 or counts.min() == -32768
    assert np.all((counts >= -32768) & (counts <= 32767))


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_every_scenario_carries_the_field_at_the_true_orientation(scenario: str) -> None:
    device, block = stream(f"sim://{scenario}?mag=lis2mdl&errors=0&noise=0&date={DATE}"
                           "&clock_ppm=300&clock_offset=5", 700)
    rows, truth = true_sensor_field(device, len(block))
    assert np.array_equal(np.flatnonzero(field_rows(block)), rows)
    assert np.all(np.abs(block.mag_ut[rows] - truth) <= 0.5 * LIS2MDL.ut_per_lsb + 1e-9)
    strength = np.linalg.norm(block.mag_ut[rows], axis=1)
    assert np.allclose(strength, device.earth_field.total_ut, atol=0.2)


@pytest.mark.parametrize(("yaw", "compass_deg"), [(90, 0.0), (0, 90.0), (-90, 180.0), (180, 270.0)])
def test_yaw_turns_counter_clockwise_from_magnetic_east(yaw: float, compass_deg: float) -> None:
    """The x axis's magnetic compass heading (clockwise from magnetic north) is 90 - yaw."""
    _, block = stream(f"sim://static?mag=lis3mdl&errors=0&noise=0&date={DATE}&yaw={yaw}", 200)
    mag = block.mag_ut[field_rows(block)].mean(axis=0)
    # Level: x at compass heading h reads H cos h, y (90 degrees counter-clockwise) H sin h.
    heading = math.degrees(math.atan2(mag[1], mag[0])) % 360.0
    assert heading == pytest.approx(compass_deg, abs=0.1) or (
        compass_deg == 0.0 and heading == pytest.approx(360.0, abs=0.1))
