"""The fault detector's compiled kernels loaded before a device streams.

The detector's numba kernels (per-sample tests, the band filter, the coherence and carry
fits, the magnetometer's checks) are loaded from numba's cache, or compiled on a cold one, the
first time a detector sees a block. Met with a live sensor's first block, that wait (a second
on a busy machine, many on a cold cache) overflowed its FIFO: samples lost in the first
seconds of every session.
"""

from __future__ import annotations

import math

import numpy as np

from app.core.faults.detector import FaultDetector
from app.core.faults.spec import SensorSpec
from app.core.field_check import FieldMonitor
from app.core.samples import SampleBlock

_loaded = False

ODR_HZ = 416.0
SECONDS = 20.0
"""Long enough for every end-of-window test (0.25 s windows) to run once: the rest tests and
the noise test in the first :data:`REST_S`, the carried bias test in the motion after it."""
REST_S = 6.0
BLOCK = 104


def warm_up_detector() -> None:
    """Run a detector (with a magnetometer) over a made-up sensor at rest and then turning,
    once per process; its events are dropped. The pipeline's field monitor, which runs beside
    it on a source with a magnetometer, is loaded too. A second call costs nothing."""
    global _loaded
    if _loaded:
        return
    n = int(SECONDS * ODR_HZ)
    t = np.arange(n) / ODR_HZ
    rng = np.random.default_rng(0)
    moving = (t >= REST_S)[:, None]
    rate = moving * 0.8 * np.sin(2.0 * math.pi * 0.5 * t)[:, None] * np.array([1.0, 0.5, 0.2])
    gyro = rate + rng.normal(0.0, 0.002, (n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + rng.normal(0.0, 0.02, (n, 3))
    accel[:, 0] += moving[:, 0] * 2.0 * np.sin(2.0 * math.pi * 0.5 * t)
    mag = np.array([18.0, 0.0, -45.0]) + rng.normal(0.0, 0.3, (n, 3))
    mag[1::2] = np.nan  # a slower chip: a field sample every other row
    spec = SensorSpec(ODR_HZ, accel_lsb_m_s2=0.0006, gyro_lsb_rad_s=0.00015, accel_fs_g=4,
                      gyro_fs_dps=2000, mag_range_ut=400.0, mag_ut_per_lsb=0.015,
                      mag_odr_hz=ODR_HZ / 2)
    detector = FaultDetector(spec)
    detector.field_calibrated = True
    for a in range(0, n, BLOCK):
        part = slice(a, a + BLOCK)
        detector.update(SampleBlock(t[part], accel[part], gyro[part], np.full(len(t[part]), 25.0),
                                    np.zeros(len(t[part]), dtype=bool), mag_ut=mag[part]))
    FieldMonitor().update(t, accel, mag)
    _loaded = True
