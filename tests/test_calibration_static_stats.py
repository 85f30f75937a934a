"""Static angle statistics over 20 s (the measuring-arm paper: 2 000 samples at 100 Hz)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.calibration_procedures import StaticStatistics
from app.core.orientation import angles_from_up, up_in_sensor_frame
from app.core.samples import STANDARD_GRAVITY_M_S2, convert_raw_block
from drivers.registry import open_device


def test_twenty_seconds_of_a_still_ideal_sensor():
    dev = open_device("sim://static?roll=10&pitch=-5&odr=104&realtime=0&block=200&seed=2&errors=0")
    stats = StaticStatistics()
    assert stats.duration_s == 20.0 and stats.progress == 0.0
    last_progress = 0.0
    reference = None
    while True:
        block = convert_raw_block(dev.read(1.0))
        reference = up_in_sensor_frame(block.reference_quat[0])
        done = stats.update_angles(block.t_s, angles_from_up(block.accel_m_s2))
        assert stats.progress >= last_progress
        last_progress = stats.progress
        if done:
            break
    assert stats.is_complete and stats.progress == 1.0
    result = stats.result()
    odr = dev.info.odr_hz
    assert result.samples == math.ceil(20.0 * odr)  # 2 080 samples at 104 Hz
    assert result.duration_s == pytest.approx(20.0, abs=1.0 / odr)
    want = angles_from_up(reference)
    # Noise per sample: accelerometer noise over g, in degrees (0.03 degree here).
    sigma_deg = math.degrees(dev.measurement.accel_noise_rms_m_s2 / STANDARD_GRAVITY_M_S2)
    for got, true in ((result.roll, want.roll_deg), (result.pitch, want.pitch_deg)):
        assert got.samples == result.samples
        assert got.mean == pytest.approx(true, abs=5.0 * sigma_deg / math.sqrt(got.samples) + 0.002)
        assert got.std == pytest.approx(sigma_deg, rel=0.15)
        assert got.spread == pytest.approx(got.maximum - got.minimum)
        assert 4.0 * got.std < got.spread < 10.0 * got.std
        assert got.minimum < got.mean < got.maximum
    assert result.tilt.mean == pytest.approx(want.tilt_deg, abs=0.005)
    # More blocks change nothing once complete.
    assert stats.update(np.array([99.0]), np.array([0.0]), np.array([0.0]), np.array([0.0]))
    assert stats.result().samples == result.samples


def test_roll_statistics_across_the_180_degree_wrap():
    stats = StaticStatistics(duration_s=1.0)
    t = np.arange(100) / 100.0
    roll = np.where(np.arange(100) % 2 == 0, 179.9, -179.9)
    stats.update(t, roll, np.zeros(100), np.full(100, 180.0))
    result = stats.result().roll
    assert abs(abs(result.mean) - 180.0) < 1e-9
    assert result.spread == pytest.approx(0.2)
    assert result.std == pytest.approx(0.1, rel=0.02)
    with pytest.raises(ValueError):
        StaticStatistics(duration_s=0.0)
    with pytest.raises(ValueError):
        StaticStatistics().result()
