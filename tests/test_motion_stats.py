"""The motion statistics (app.core.motion_stats) on streams whose answers are known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.motion_stats import (
    G,
    linear_acceleration_earth,
    motion_stats,
    rest_mask,
    runs,
    summarise_spectrum,
    tilt_deg,
    welch_psd,
)
from app.core.orientation import quaternion_from_roll_pitch

RATE = 200.0


def test_welch_finds_a_tone_and_keeps_its_power():
    t = np.arange(0, 120, 1 / RATE)
    amplitude, freq = 2.0, 1.25  # on a bin of the 8 s segments
    x = np.column_stack([amplitude * np.sin(2 * np.pi * freq * t + 0.3), np.zeros_like(t)])
    freqs, psd, segments = welch_psd(x, RATE)
    assert segments == 29  # 120 s in 8 s segments, half overlapping
    assert freqs[np.argmax(psd)] == freq
    power = np.sum(psd) * (freqs[1] - freqs[0])
    assert power == pytest.approx(amplitude**2 / 2, rel=1e-3)
    summary = summarise_spectrum(freqs, psd)
    assert summary.dominant_hz == freq
    assert summary.median_hz == pytest.approx(freq, abs=0.01)
    assert summary.band90_hz[0] <= freq <= summary.band90_hz[1]


def test_spectrum_summary_splits_the_power():
    t = np.arange(0, 120, 1 / RATE)
    # Three tones of equal power: the median is the middle one, the 50 % band spans it.
    x = sum(np.sin(2 * np.pi * f * t + f) for f in (0.5, 2.0, 8.0))
    freqs, psd, _ = welch_psd(x, RATE)
    summary = summarise_spectrum(freqs, psd)
    assert summary.median_hz == pytest.approx(2.0, abs=0.2)
    assert 0.5 <= summary.band50_hz[0] < 2.0 < summary.band50_hz[1] <= 8.0
    assert summary.band90_hz[0] == pytest.approx(0.5, abs=0.2)
    assert summary.band90_hz[1] == pytest.approx(8.0, abs=0.2)


def test_welch_uses_only_known_stretches():
    t = np.arange(0, 60, 1 / RATE)
    x = np.sin(2 * np.pi * 2.0 * t)
    x[3000:3100] = np.nan  # 0.5 s unknown: segments never straddle it
    freqs, psd, segments = welch_psd(x, RATE)
    assert np.all(np.isfinite(psd)) and freqs[np.argmax(psd)] == 2.0
    assert segments == len(range(0, 3000 - 1600 + 1, 800)) + len(range(3100, 12000 - 1600 + 1,
                                                                      800))
    too_short = welch_psd(x[:1000], RATE)
    assert too_short[2] == 0 and np.all(np.isnan(too_short[1]))
    assert math.isnan(summarise_spectrum(*too_short[:2]).dominant_hz)


def test_linear_acceleration_and_tilt_from_the_reference():
    n = 5
    q = quaternion_from_roll_pitch(np.full(n, 30.0), np.full(n, -20.0), np.full(n, 70.0))
    linear = np.array([[1.0, -2.0, 0.5]] * n)
    force = quat.rotate_inverse(q, linear + np.array([0.0, 0.0, G]))
    q_partly = q.copy()
    q_partly[2] = np.nan
    out = linear_acceleration_earth(force, q_partly)
    np.testing.assert_allclose(np.delete(out, 2, axis=0), linear[:4], atol=1e-12)
    assert np.all(np.isnan(out[2]))
    tilt = tilt_deg(q_partly)
    expected = math.degrees(math.acos(math.cos(math.radians(30)) * math.cos(math.radians(20))))
    np.testing.assert_allclose(np.delete(tilt, 2), expected, atol=1e-9)
    assert math.isnan(tilt[2])


def test_rotation_about_the_mean_orientation():
    t = np.arange(0, 60, 1 / RATE)
    n = len(t)
    base = quaternion_from_roll_pitch(20.0, -30.0, 50.0)
    swing = np.radians(10.0) * np.sin(2 * np.pi * 0.5 * t)
    q = quat.multiply(base, quat.from_rotation_vector(np.column_stack(
        [np.zeros(n), swing, np.zeros(n)])))
    q[::2] *= -1.0  # the sign of a quaternion does not matter
    s = motion_stats(t, quat.rotate_inverse(q, np.tile([0.0, 0.0, G], (n, 1))),
                     np.zeros((n, 3)), q, movement=np.ones(n, bool))
    assert s.rotation_rms_deg == pytest.approx((0.0, 10.0 / math.sqrt(2), 0.0), abs=1e-3)


def test_runs_and_rest():
    assert runs(np.array([0, 1, 1, 0, 1], bool)).tolist() == [[1, 3], [4, 5]]
    assert runs(np.zeros(3, bool)).shape == (0, 2)
    t = np.arange(0, 20, 1 / RATE)
    accel = np.tile([0.0, 0.0, G], (len(t), 1))
    gyro = np.zeros((len(t), 3))
    moving = (t >= 5) & (t < 10) | (t >= 14) & (t < 14.5)
    gyro[moving, 2] = math.radians(40.0)
    rest = rest_mask(accel, gyro, RATE)
    # Still before 5 s, between 10 and 14 s (shortened by the 0.25 s window either side)
    # and after 14.5 s; the moving stretches never.
    assert not rest[moving].any()
    for start, stop in ((0, 4.7), (10.3, 13.7), (14.8, 20)):
        assert rest[(t >= start) & (t < stop)].all()
    # A pause shorter than 2 s is not rest.
    gyro[(t >= 12) & (t < 16), 2] = math.radians(40.0)
    gyro[(t >= 13) & (t < 14), 2] = 0.0
    assert not rest_mask(accel, gyro, RATE)[(t >= 13) & (t < 14)].any()


def test_motion_stats_of_a_known_motion():
    """Turning about the vertical at 30 dps, tilted 10 degrees, moved sideways at 1 Hz."""
    t = np.arange(0, 100, 1 / RATE)
    n = len(t)
    yaw = 30.0 * t
    q = quaternion_from_roll_pitch(np.full(n, 10.0), np.zeros(n), yaw)
    rate_earth = np.array([0.0, 0.0, math.radians(30.0)])
    gyro = quat.rotate_inverse(q, np.tile(rate_earth, (n, 1)))
    moving = t >= 20  # 20 s of rest first, then 80 s of motion
    a = np.where(moving, 3.0 * np.sin(2 * np.pi * 1.0 * t), 0.0)
    linear = np.column_stack([a, np.zeros(n), np.zeros(n)])
    gyro[~moving] = 0.0
    accel = quat.rotate_inverse(q, linear + np.array([0.0, 0.0, G]))
    s = motion_stats(t, accel, gyro, q, movement=moving)
    assert s.moving_s == pytest.approx(80.0)
    assert s.span_s == pytest.approx(80.0) and s.rest_fraction == 0.0 and s.rest_breaks == 0
    assert s.linear_rms_m_s2 == pytest.approx(3.0 / math.sqrt(2), rel=1e-3)
    assert s.linear_spectrum.dominant_hz == pytest.approx(1.0)
    assert s.linear_spectrum.median_hz == pytest.approx(1.0, abs=0.01)
    assert s.gyro_rms_dps == pytest.approx(30.0) and s.gyro_peak_dps == pytest.approx(30.0)
    assert s.tilt_deg == pytest.approx((10.0, 10.0, 10.0)) and s.tilt_max_deg == pytest.approx(10)
    # |a|-g of a horizontal 3 m/s^2: sqrt(g^2 + a^2) - g.
    excess = np.sqrt(G**2 + a[moving] ** 2) - G
    assert s.excess_rms_m_s2 == pytest.approx(np.sqrt(np.mean(excess**2)))
    assert s.excess_peak_g == pytest.approx((math.hypot(G, 3.0) - G) / G, rel=1e-4)
    assert s.reference_fraction == 1.0
    # Without the flag, the moving samples are those not at rest: the same here.
    unflagged = motion_stats(t, accel, gyro, q)
    assert unflagged.moving_s == pytest.approx(80.0 + 0.25, abs=0.01)
    assert unflagged.rest_fraction == pytest.approx(19.75 / 100, abs=1e-3)
    assert unflagged.rest_breaks == 1


def test_rest_breaks_are_counted_within_the_span():
    t = np.arange(0, 60, 1 / RATE)
    n = len(t)
    gyro = np.zeros((n, 3))
    moving = ((t >= 10) & (t < 25)) | ((t >= 35) & (t < 50))
    gyro[moving, 0] = math.radians(50.0)
    accel = np.tile([0.0, 0.0, G], (n, 1))
    s = motion_stats(t, accel, gyro, None, movement=moving)
    assert s.span_s == pytest.approx(40.0)
    assert s.rest_breaks == 1 and s.rest_break_mean_s == pytest.approx(9.5, abs=0.01)
    assert s.rest_fraction == pytest.approx(9.5 / 40, abs=1e-3)
    assert math.isnan(s.linear_rms_m_s2) and math.isnan(s.tilt_max_deg)
    assert s.reference_fraction == 0.0
