"""Stillness detection: thresholds from the datasheet noise, quick on motion, no false alarm."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.calibration_procedures import SensorNoise, StillnessDetector, stillness
from app.core.samples import SampleBlock, convert_raw_block
from drivers import lsm6dsox
from drivers.registry import open_device
from drivers.sim.error_model import accel_noise_rms_m_s2, gyro_noise_rms_rad_s


def detector_for(dev, **kwargs) -> StillnessDetector:
    info = dev.info
    return StillnessDetector(
        SensorNoise.lsm6dsox(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps), **kwargs
    )


def feed(dev, detector: StillnessDetector, until_s: float) -> tuple[np.ndarray, np.ndarray]:
    times, flags = [], []
    while not times or times[-1][-1] < until_s:
        block = convert_raw_block(dev.read(1.0))
        flags.append(detector.update(block))
        times.append(block.t_s)
    return np.concatenate(times), np.concatenate(flags)


def test_noise_figures_match_the_driver_constants():
    assert stillness.ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS == lsm6dsox.ACCEL_NOISE_G_PER_SQRT_HZ_LOW_FS
    assert stillness.ACCEL_NOISE_G_PER_SQRT_HZ_16G == lsm6dsox.ACCEL_NOISE_G_PER_SQRT_HZ_16G
    assert stillness.GYRO_NOISE_DPS_PER_SQRT_HZ == lsm6dsox.GYRO_NOISE_DPS_PER_SQRT_HZ
    assert stillness.ACCEL_MG_PER_LSB == lsm6dsox.ACCEL_MG_PER_LSB
    assert stillness.GYRO_MDPS_PER_LSB == lsm6dsox.GYRO_MDPS_PER_LSB
    for fs in (2, 4, 8, 16):
        noise = SensorNoise.lsm6dsox(104.0, fs, 250)
        lsb = lsm6dsox.accel_m_s2_per_lsb(fs)
        expected = math.hypot(accel_noise_rms_m_s2(fs, 104.0), lsb / math.sqrt(12.0))
        assert noise.accel_rms_m_s2 == pytest.approx(expected)
    noise = SensorNoise.lsm6dsox(104.0, 4, 2000)
    lsb = lsm6dsox.gyro_rad_s_per_lsb(2000)
    expected = math.hypot(gyro_noise_rms_rad_s(104.0), lsb / math.sqrt(12.0))
    assert noise.gyro_rms_rad_s == pytest.approx(expected)
    with pytest.raises(ValueError):
        SensorNoise.lsm6dsox(104.0, 3, 250)


def test_thresholds_are_k_times_the_noise():
    noise = SensorNoise.lsm6dsox(104.0)
    detector = StillnessDetector(noise, window_s=0.5, k=3.0)
    assert detector.window == 52
    assert detector.accel_threshold_m_s2 == pytest.approx(3.0 * noise.accel_rms_m_s2)
    # About 1.5 mg and 0.08 dps at 104 Hz, +-4 g, +-250 dps.
    assert detector.accel_threshold_m_s2 / 9.80665e-3 == pytest.approx(1.52, abs=0.01)
    assert math.degrees(detector.gyro_threshold_rad_s) == pytest.approx(0.084, abs=0.002)


def test_a_still_sensor_is_still_after_one_window_and_stays_so():
    dev = open_device("sim://static?roll=20&pitch=-30&odr=104&realtime=0&block=100&seed=4")
    detector = detector_for(dev)
    t, flags = feed(dev, detector, 60.0)
    first = t[np.argmax(flags)]
    assert first == pytest.approx(detector.window_s, abs=0.02)
    assert np.all(flags[t > first])  # no false alarm in a minute
    assert detector.is_still
    assert detector.still_duration_s == pytest.approx(t[-1] - t[0], abs=1e-9)
    assert detector.accel_ratio < 0.6 and detector.gyro_ratio < 0.6


def test_motion_is_flagged_within_a_fraction_of_a_second():
    dev = open_device("sim://tour?odr=104&realtime=0&block=8&seed=1")
    detector = detector_for(dev)
    t, flags = feed(dev, detector, 47.0)
    for k in range(5):  # the tour turns at 6, 14, 22, ... s for 2 s
        turn_start = 6.0 + 8.0 * k
        moving = t[(t >= turn_start) & ~flags]
        assert moving[0] - turn_start < 0.05
        assert np.all(~flags[(t > turn_start + 0.05) & (t < turn_start + 2.0)])
        # Still again one window after the turn ends.
        still_again = t[(t >= turn_start + 2.0) & flags][0]
        assert still_again - (turn_start + 2.0) == pytest.approx(detector.window_s, abs=0.03)


def test_a_gentle_nudge_is_flagged_quickly():
    # A 2 degree nudge (glide of 0.35 s): typical of a hand touching the board.
    dev = open_device("sim://interactive?roll=0&pitch=0&odr=104&realtime=0&block=4&seed=2")
    detector = detector_for(dev)
    feed(dev, detector, 3.0)
    assert detector.is_still and detector.still_duration_s > 2.0
    start = detector.last_time_s
    dev.set_target_attitude(2.0, 0.0)
    t, flags = feed(dev, detector, start + 1.0)
    assert not np.all(flags)
    assert t[np.argmin(flags)] - start < 0.1
    # Still again: the still stretch starts where the glide ended (0.3 s after it began).
    assert detector.is_still and detector.still_since_s == pytest.approx(start + 0.3, abs=0.1)


def test_flags_do_not_depend_on_block_size_and_gaps_restart_the_window():
    dev_a = open_device("sim://tour?hold=3&odr=104&realtime=0&block=7&seed=1")
    dev_b = open_device("sim://tour?hold=3&odr=104&realtime=0&block=1000&seed=1")
    _, flags_a = feed(dev_a, detector_for(dev_a), 20.0)
    _, flags_b = feed(dev_b, detector_for(dev_b), 20.0)
    n = min(len(flags_a), len(flags_b))
    np.testing.assert_array_equal(flags_a[:n], flags_b[:n])
    # A gap empties the window: not still again until a full window after it.
    noise = SensorNoise.lsm6dsox(104.0)
    detector = StillnessDetector(noise)
    rng = np.random.default_rng(0)
    n = 300
    gap = np.zeros(n, dtype=bool)
    gap[200] = True
    block = SampleBlock(
        t_s=np.arange(n) / 104.0,
        accel_m_s2=np.array([0.0, 0.0, 9.8]) + rng.normal(0, noise.accel_rms_m_s2, (n, 3)),
        gyro_rad_s=rng.normal(0, noise.gyro_rms_rad_s, (n, 3)),
        temp_degc=np.full(n, 25.0),
        gap=gap,
    )
    flags = detector.update(block)
    assert np.all(flags[51:200]) and not np.any(flags[200:251]) and np.all(flags[251:])
    assert detector.still_since_s == pytest.approx(block.t_s[200])
    # So does a hole in time that no gap flag marks (here 1 s between two blocks).
    later = SampleBlock(
        t_s=block.t_s[-1] + 1.0 + np.arange(n) / 104.0,
        accel_m_s2=block.accel_m_s2,
        gyro_rad_s=block.gyro_rad_s,
        temp_degc=block.temp_degc,
        gap=np.zeros(n, dtype=bool),
    )
    flags = detector.update(later)
    assert not np.any(flags[:51]) and np.all(flags[51:])


def test_a_steady_turn_about_the_vertical_is_not_still():
    noise = SensorNoise.lsm6dsox(104.0)
    n = 200
    rng = np.random.default_rng(1)
    block = SampleBlock(
        t_s=np.arange(n) / 104.0,
        accel_m_s2=np.array([0.0, 0.0, 9.8]) + rng.normal(0, noise.accel_rms_m_s2, (n, 3)),
        gyro_rad_s=np.array([0.0, 0.0, math.radians(10.0)])
        + rng.normal(0, noise.gyro_rms_rad_s, (n, 3)),
        temp_degc=np.full(n, 25.0),
        gap=np.zeros(n, dtype=bool),
    )
    assert not np.any(StillnessDetector(noise).update(block))
    # With the rate known as bias (a chip with a large offset), it is still.
    known = StillnessDetector(noise, gyro_bias_rad_s=np.array([0.0, 0.0, math.radians(10.0)]))
    assert np.all(known.update(block)[51:])
