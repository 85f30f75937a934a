"""Put two sensors' samples on one time axis: the first recording's rows."""

from __future__ import annotations

import numpy as np

from app.core.samples import SampleBlock


def align_to(reference: SampleBlock, other: SampleBlock) -> tuple[SampleBlock, np.ndarray, str]:
    """``other`` on ``reference``'s times, the rows of ``reference`` it covers, and how.

    Same length and times within a tenth of a sample period: taken as they are. Otherwise
    ``other``'s accelerometer and gyroscope are interpolated linearly to ``reference``'s times;
    rows of ``reference`` outside ``other``'s time span are not covered (False), and a gap in
    ``other`` marks the row after it.
    """
    t = reference.t_s
    n = len(t)
    if len(other) == n:
        period = float(np.median(np.diff(t))) if n > 1 else 1.0
        if n == 0 or float(np.max(np.abs(other.t_s - t))) <= 0.1 * period:
            return other, np.ones(n, dtype=bool), "row by row"
    covered = (t >= other.t_s[0]) & (t <= other.t_s[-1])
    accel = np.column_stack([np.interp(t, other.t_s, other.accel_m_s2[:, k]) for k in range(3)])
    gyro = np.column_stack([np.interp(t, other.t_s, other.gyro_rad_s[:, k]) for k in range(3)])
    temp = np.interp(t, other.t_s, other.temp_degc)
    gap = np.zeros(n, dtype=bool)
    gap_times = other.t_s[other.gap]
    if len(gap_times):
        gap[np.clip(np.searchsorted(t, gap_times), 0, n - 1)] = True
    return (SampleBlock(t.copy(), accel, gyro, temp, gap), covered,
            "the second recording interpolated linearly to the first's times")
