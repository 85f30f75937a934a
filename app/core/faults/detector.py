"""Model-based sensor fault detection and isolation, block by block.

:class:`FaultDetector` takes the :class:`SampleBlock` stream (and the :class:`RawBlock` when
there is one) and returns :class:`FaultEvent` s at the sample where each fault is declared.
A compiled per-sample scan (numba) does the sample-level tests; 0.25 s windows carry the
statistical ones. Thresholds and their basis (details in docs/fault-detection.md):

Per channel (ax .. gz)
    *Noise floor.* The white-noise level is measured by the mean absolute 4th difference
    ``|x[n] - 4x[n-1] + 6x[n-2] - 4x[n-3] + x[n-4]|``: white noise of sigma gives
    ``sqrt(70) sigma sqrt(2/pi)`` while smooth motion is suppressed by ``(2 pi f / ODR)^4``.
    The floor starts at the datasheet value (when the sensor is known) and is learnt in quiet
    windows (windows more than 1.5x the floor never teach it; a drop below 0.3x, which white
    noise cannot do, neither).

    *stuck / dead.* A run of identical outputs is declared when its probability under the
    channel's own noise is below ``STUCK_FALSE_ALARM`` (1e-9): a constant true value reads the
    same count with probability ``p0 = erf(q / (2 sqrt 2 sigma))`` (q the LSB), so the run must
    reach ``ln(1e-9) / ln(p0)`` samples, at least 0.25 s and at most 2 s. ``dead`` when the
    frozen value is exactly 0.

    *spike.* The sample's distance from the mean of its neighbours, ``x[n-1] - (x[n-2] +
    x[n]) / 2`` (1.22 sigma for white noise), above 10x its local scale (the floor, raised by
    the window's own activity) on exactly one channel while every other channel stays under 5x:
    a mechanical shock (a tap) moves several channels at once, a failing channel one.

    *noise.* The floor ratio ``rho`` of each window, averaged over the last 1 s, over the
    largest such ratio of the sensor's two other axes (shared vibration cancels), above 3.5
    (sigma ratio; a noise of 5x the sensor's own gives 5.1). A window counts only when the
    channel is flat but for its noise (spread within 3x its own 4th-difference noise), and only
    while the rotation rate stays under 30 dps: hand motion puts broadband content into the
    4th difference (up to 50x the noise on BROAD's gyro). The window's noise sigma for that is
    the larger of the clipped mean |d4| (which stops at D4_CLIP x the floor: alone it made
    noise above ~40x never look flat, so gross noise went unseen while 5x was found) and the
    median |d4| (not clipped, robust to a few outliers); and the window must be white - its
    autocorrelation at lags 1-3, trend removed, within 3 standard errors of 0 - which a
    vibration tone on one axis is not, at any frequency or amplitude. ``rho`` itself stays
    clipped (at 15 it is far over the 3.5 threshold); the event reports the unclipped level.

    *saturation.* Output at the int16 limit (or at full scale when only that is known).

Analytical redundancy (needs rest: every channel's window spread within 3 sigma of its noise)
    *gyro bias.* At rest the gyro reads its bias. A change of more than 1.2 dps from the bias
    learnt at earlier rests (60 % of the 2 dps to detect, issue 33: a smaller change is learnt
    as drift, so a larger one must not be; turn-on bias is +-1 dps, thermal drift 0.01 dps/K,
    and the mean of 1 s of rest scatters by the noise over sqrt(ODR), under 0.01 dps), or more
    than 10 dps absolute, for 1 s of rest.

    *gyro bias in motion.* Gravity carried by the gyro against the accelerometer's, the
    motion's acceleration averaged out, over 8 s, and with a magnetometer the earth's field
    carried by the gyro against the magnetometer's (:mod:`app.core.faults.carry`): the field
    counts while the magnetic disturbance detector (:mod:`app.core.magnetometer.disturbance`,
    VQF's bands, the dip against a 3 s low-passed tilt) calls it undisturbed, no magnetometer
    axis was declared faulty in the last 5 s, and the window turns slower than 200 dps.

    *noise in motion.* Each channel's band above a quarter of the rate against its own recent
    level and the other channels' (:mod:`app.core.faults.motion`), and what the other
    channels do not explain of it (:mod:`app.core.faults.coherence`).

    *accel bias.* Gravity carried from the previous rest by the gyro (bias removed, under 10 deg
    of rotation and 2 s apart) against the accelerometer: a per-axis difference over 25 mg (half
    of the 50 mg to detect; gyro bias residue and scale error add under 5 mg there) for 1 s.

    *gravity.* ``| |a| - g |`` at rest over 6 % (turn-on offset +-20 mg and sensitivity +-1 %
    give 3 % at most), isolated to the axis carrying gravity.

    *consistency.* Larger rotations between rests (up to 5 s): the angle between the
    gyro-carried and the measured gravity direction over 3 deg + 3 % of the rotation.

The magnetometer's axes (mx, my, mz), when the stream has them: stuck, dead, spike and
saturation on its own, slower samples (:mod:`app.core.faults.magnetometer`).

Gaps (``gap`` flag) and a clock that goes back restart every running test; lost samples are
reported on the ``link`` channel.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numba import njit

from app.core.calibration import MagnetometerCalibration
from app.core.faults.carry import GravityCarry, rotation_matrix
from app.core.faults.events import CHANNELS, FaultEvent, severity_rank
from app.core.faults.magnetometer import MagnetometerCheck
from app.core.faults.motion import BAND, MotionNoiseCheck
from app.core.faults.rows import RowHistory, column_median
from app.core.faults.spec import SensorSpec
from app.core.magnetometer.disturbance import (
    OK,
    DisturbanceSettings,
    detector_step,
    new_state,
    track_rate,
)
from app.core.samples import STANDARD_GRAVITY_M_S2, RawBlock, SampleBlock

G = STANDARD_GRAVITY_M_S2
WINDOW_S = 0.25
D4_GAIN = math.sqrt(70.0) * math.sqrt(2.0 / math.pi)
"""Mean |4th difference| of unit white noise."""
D4_MEDIAN_GAIN = math.sqrt(70.0) * 0.6744897501960817
"""Median |4th difference| of unit white noise (the normal's quartile 0.674 x sqrt(70))."""
STUCK_FALSE_ALARM = 1e-9
STUCK_MIN_S = 0.25
STUCK_MAX_S = 2.0
SPIKE_SIGMA = 10.0
SPIKE_OTHERS_SIGMA = 5.0
SPIKE_NOISE_GAIN = math.sqrt(1.5)
SPIKE_LOCAL_ALPHA = 0.05
"""Local activity: exponential mean of |residual| over about 20 samples."""
SPIKE_LOCAL_GAIN = math.sqrt(math.pi / 2.0)
SPIKE_OVER_PEAK = 6.0
SPIKE_PEAK_HALF_LIFE_S = 0.5
"""A spike stands 6x above the largest residual of the last ~0.5 s (real shocks build up)."""
"""Mean absolute value to standard deviation (Gaussian)."""
D4_CLIP = 15.0
NOISE_RATIO = 3.5
NOISE_SPAN_WINDOWS = 4
NOISE_FLAT = 3.0
"""A window counts for the noise test when its spread is within 3x its own white noise
(the channel is flat but for noise; motion of any kind has a spread far above)."""
NOISE_ARM_RATE_RAD_S = math.radians(30.0)
WHITE_CORR_MAX = 0.6
"""Largest |autocorrelation| at lags 1-3 of a window taken as white (a tone has >= 0.707)."""
REST_SIGMA = 3.0
REST_WINDOWS = 4
GYRO_BIAS_STEP_RAD_S = math.radians(1.2)
GYRO_BIAS_ABS_RAD_S = math.radians(10.0)
ACCEL_BIAS_STEP_M_S2 = 25e-3 * G
ACCEL_CARRY_MAX_RAD = math.radians(10.0)
ACCEL_CARRY_MAX_S = 2.0
GRAVITY_TOLERANCE = 0.06
CONSISTENCY_MAX_S = 5.0
CONSISTENCY_BASE_RAD = math.radians(3.0)
CONSISTENCY_FRACTION = 0.03
FLOOR_ALPHA = 0.1
"""Floor learning per quiet window (time constant 2.5 s)."""
HOLD_S = 5.0
"""An event repeats only after its condition has been clear this long."""
_DISTURBANCE = DisturbanceSettings().as_array()
"""The magnetic disturbance detector's settings for the field part of the gyro bias test
(VQF's: 10 % of strength, 10 deg of dip)."""
TILT_TAU_S = 3.0
FIELD_MAX_RATE_RAD_S = math.radians(200.0)
"""Windows turning faster than this leave the field out of the bias test: at several hundred
dps the magnetometer's and the gyro's sampling instants and filters, a few ms apart, turn the
carried field by degrees (BROAD 28, rotated at 300-400 dps RMS, read 6-15 dps of "bias" from
it; set on the tuning trials: 150 and 250 dps both clean there)."""

STUCK, DEAD, SPIKE, SATURATION, NOISE, BIAS = 1, 2, 4, 8, 16, 32
FLAG_KINDS = {STUCK: "stuck", DEAD: "dead", SPIKE: "spike", SATURATION: "saturation",
              NOISE: "noise", BIAS: "bias"}
LATCHED_KINDS = ("bias", "gravity", "consistency")
"""Kinds whose condition persists once declared: health stays red until :meth:`reset`."""


@njit(cache=True, inline="always")
def _add_turned(out, at, qw, qx, qy, qz, vx, vy, vz):  # pragma: no cover - compiled
    """Add (vx, vy, vz) turned by the unit quaternion (qw, qx, qy, qz) to ``out[at:at + 3]``:
    v + 2w(u x v) + 2u x (u x v)."""
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    out[at] += vx + qw * tx + (qy * tz - qz * ty)
    out[at + 1] += vy + qw * ty + (qz * tx - qx * tz)
    out[at + 2] += vz + qw * tz + (qx * ty - qy * tx)


@njit(cache=True)
def _smallest_steps(x, lsb_seen):  # pragma: no cover
    """Lower ``lsb_seen`` (per column) to the smallest non-zero step between rows of ``x``:
    the LSB where it is not known. True when it did."""
    lowered = False
    for i in range(1, x.shape[0]):
        for c in range(x.shape[1]):
            step = abs(x[i, c] - x[i - 1, c])
            if 0.0 < step < lsb_seen[c]:
                lsb_seen[c] = step
                lowered = True
    return lowered


@njit(cache=True)
def _scan(t, x, gap, hist, ints, run_val, run_len, sums, quat, local, peak, peak_decay,
          stuck_len, spike_scale, d4_clip, sat_level, gyro_ref, window_x, d4_abs, mag,
          flags):  # pragma: no cover
    """Per-sample tests over one chunk; updates the state arrays in place.

    ints: [contiguous samples, window samples, window d4 samples]; sums: (6, 4) window sums
    of clipped |d4|, x, x^2 and, in [:, 3] for the gyro rows, nothing; quat: rotation since the
    window start (gyro minus gyro_ref), (w, x, y, z), then [4] the previous sample time and
    [5:8] the window's sum of accelerometer samples turned into the window-start frame, [8:11]
    that of the field samples (``mag``: (n, 3), NaN rows without one; (0, 3): no field) and
    [11] their count.
    window_x, d4_abs: (window, 6) the window's samples (row ints[1]) and unclipped |d4| (row
    ints[2]), for the median and the autocorrelation at the window's end.
    """
    n = x.shape[0]
    for i in range(n):
        restart = gap[i] or (ints[0] > 0 and t[i] <= quat[4])
        if restart:
            ints[0] = 0
            for c in range(6):
                run_len[c] = 0
        dt = t[i] - quat[4] if ints[0] > 0 else 0.0
        quat[4] = t[i]
        # spike test on sample i-1 (needs i-2 .. i): out and back, on one channel only
        if ints[0] >= 2:
            best = -1
            count = 0
            worst_other = 0.0
            for c in range(6):
                r = abs(hist[0, c] - 0.5 * (hist[1, c] + x[i, c]))
                scale = max(spike_scale[c], SPIKE_LOCAL_GAIN * local[c])
                z = r / scale
                if (z >= SPIKE_SIGMA and abs(x[i, c] - hist[1, c]) < 0.5 * r
                        and r > SPIKE_OVER_PEAK * peak[c]):
                    best = c
                    count += 1
                else:
                    worst_other = max(worst_other, z)
                local[c] += SPIKE_LOCAL_ALPHA * (min(r, 3.0 * scale) - local[c])
                peak[c] = max(peak[c] * peak_decay, min(r, SPIKE_OVER_PEAK * peak[c] + scale))
            if count == 1 and worst_other < SPIKE_OTHERS_SIGMA and run_len[best] == 0:
                flags[i, best] |= 4
        for c in range(6):
            v = x[i, c]
            if ints[0] >= 1 and v == hist[0, c]:
                run_len[c] += 1
            else:
                run_len[c] = 0
                run_val[c] = v
            if run_len[c] + 1 >= stuck_len[c]:
                flags[i, c] |= 2 if v == 0.0 else 1
            if abs(v) >= sat_level[c]:
                flags[i, c] |= 8
            sums[c, 1] += v
            window_x[ints[1], c] = v
            sums[c, 2] += v * v
            if ints[0] >= 4:
                d = v - 4.0 * hist[0, c] + 6.0 * hist[1, c] - 4.0 * hist[2, c] + hist[3, c]
                sums[c, 0] += min(abs(d), d4_clip[c])
                d4_abs[ints[2], c] = abs(d)
        if ints[0] >= 4:
            ints[2] += 1
        ints[1] += 1
        # gyro rotation since the window start
        if dt > 0.0:
            wx = (x[i, 3] - gyro_ref[0]) * dt * 0.5
            wy = (x[i, 4] - gyro_ref[1]) * dt * 0.5
            wz = (x[i, 5] - gyro_ref[2]) * dt * 0.5
            qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
            nw = qw - qx * wx - qy * wy - qz * wz
            nx = qx + qw * wx + qy * wz - qz * wy
            ny = qy + qw * wy + qz * wx - qx * wz
            nz = qz + qw * wz + qx * wy - qy * wx
            norm = math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
            quat[0], quat[1], quat[2], quat[3] = nw / norm, nx / norm, ny / norm, nz / norm
        # the accelerometer in the window-start frame: gravity carried by the gyro (issue 33)
        qw, qx, qy, qz = quat[0], quat[1], quat[2], quat[3]
        _add_turned(quat, 5, qw, qx, qy, qz, x[i, 0], x[i, 1], x[i, 2])
        if mag.shape[0] == n:
            mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
            if math.isfinite(mx) and math.isfinite(my) and math.isfinite(mz):
                _add_turned(quat, 8, qw, qx, qy, qz, mx, my, mz)  # the field likewise
                quat[11] += 1.0
        for k in range(3, 0, -1):
            for c in range(6):
                hist[k, c] = hist[k - 1, c]
        for c in range(6):
            hist[0, c] = x[i, c]
        ints[0] += 1


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


@njit(cache=True)
def _noise_ratios(rho, white, flat):  # pragma: no cover - compiled
    """The noise test's means over its windows (k, 6): ``np.mean(white, axis=0)``, per
    channel the largest mean ``rho`` of its sensor's two other axes and its mean flat ``rho``
    over that (at least 1); the sums in numpy's order (row after row from 0.0)."""
    k = rho.shape[0]
    low = np.zeros(6)
    level = np.zeros(6)
    low_flat = np.zeros(6)
    for i in range(k):
        for c in range(6):
            low[c] += rho[i, c]
            level[c] += white[i, c]
            low_flat[c] += flat[i, c]
    for c in range(6):
        low[c] /= k
        level[c] /= k
        low_flat[c] /= k
    others = np.empty(6)
    ratios = np.empty(6)
    for c in range(6):
        base = 0 if c < 3 else 3
        top = 0.0
        first = True
        for o in range(base, base + 3):
            if o != c and (first or low[o] > top):  # as Python's max()
                top = low[o]
                first = False
        others[c] = top
        ratios[c] = low_flat[c] / (top if top > 1.0 else 1.0)
    return level, others, ratios


def _norm(v: np.ndarray) -> float:
    """``np.linalg.norm(v)`` of a float vector, to the bit (its dot product of the raveled
    vector and the square root), without its per-call checks."""
    v = v.ravel(order="K")
    return math.sqrt(float(v.dot(v)))


def _maximum(a: float, b: float) -> float:
    """``np.maximum`` of two floats (NaN wins)."""
    return a if a != a or a >= b else b


def _rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` (fixed in the frame at the start) seen from the frame after rotation ``q``:
    ``v + 2w (u x v) + 2 u x (u x v)``, ``u = -q[1:]`` (np.cross's operations, one by one)."""
    w2 = 2.0 * float(q[0])
    ux, uy, uz = -float(q[1]), -float(q[2]), -float(q[3])
    vx, vy, vz = float(v[0]), float(v[1]), float(v[2])
    cx, cy, cz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    dx, dy, dz = uy * cz - uz * cy, uz * cx - ux * cz, ux * cy - uy * cx
    return np.array([vx + w2 * cx + 2.0 * dx, vy + w2 * cy + 2.0 * dy, vz + w2 * cz + 2.0 * dz])


def _units(channel: int, value: float) -> str:
    if channel < 3:
        return f"{value / G * 1e3:+.1f} mg"
    return f"{math.degrees(value):+.2f} dps"


@dataclass(slots=True)
class _Rest:
    """The last rest: mean acceleration and the gyro rotation and time since it."""

    accel: np.ndarray
    rotation: np.ndarray
    elapsed_s: float


class FaultDetector:
    """Detects and isolates sensor faults in a sample stream; see the module docstring.

    Parameters
    ----------
    spec : the sensor (rate, LSB, full scale, datasheet noise; unknowns are learnt or skipped).

    Use :meth:`update` per block in stream order; it returns the events declared in that
    block. :attr:`flags` holds the last block's per-sample flags (N, 6), a bit per kind
    (:data:`FLAG_KINDS`), for NDR measures; :meth:`health` the state of each channel.
    """

    def __init__(self, spec: SensorSpec) -> None:
        self.spec = spec
        self.window = max(8, round(WINDOW_S * spec.odr_hz))
        self._peak_decay = 0.5 ** (1.0 / (SPIKE_PEAK_HALF_LIFE_S * spec.odr_hz))
        lsb = [spec.accel_lsb_m_s2] * 3 + [spec.gyro_lsb_rad_s] * 3
        self._lsb = np.array([0.0 if q is None else q for q in lsb])
        sat = np.full(6, np.inf)
        if spec.accel_lsb_m_s2:
            sat[:3] = 32767 * spec.accel_lsb_m_s2 * (1 - 1e-9)
        elif spec.accel_fs_g:
            sat[:3] = spec.accel_fs_g * G * (32767 / 32768) * (1 - 1e-9)
        if spec.gyro_lsb_rad_s:
            sat[3:] = 32767 * spec.gyro_lsb_rad_s * (1 - 1e-9)
        elif spec.gyro_fs_dps:
            sat[3:] = math.radians(spec.gyro_fs_dps) * (32767 / 32768) * (1 - 1e-9)
        self._sat = sat
        noise = [spec.accel_noise_rms_m_s2] * 3 + [spec.gyro_noise_rms_rad_s] * 3
        self._datasheet_floor: np.ndarray | None = None
        if all(v is not None for v in noise):
            sigma = np.sqrt(np.array(noise, dtype=float) ** 2 + self._lsb**2 / 12.0)
            self._datasheet_floor = sigma * D4_GAIN
        self.events: list[FaultEvent] = []
        """Every event so far."""
        self.flags = np.zeros((0, 6), dtype=np.uint8)
        self.magnetometer = MagnetometerCheck(spec.mag_range_ut, spec.mag_ut_per_lsb,
                                              spec.mag_odr_hz)
        """The magnetometer's tests (its flags: ``magnetometer.flags``, (N, 3))."""
        self._field_seen = False
        self.field_calibrated = False
        """The field handed to :meth:`update` is already free of the sensor's own hard and
        soft iron (BROAD's, calibrated by its authors). Otherwise the gyro bias test uses the
        field only through :attr:`field_calibration`: a board's hard iron does not turn with
        the earth's field, and carried as the earth's it reads as a vertical gyro bias."""
        self.field_calibration: MagnetometerCalibration | None = None
        """Applied to the field for the gyro bias test (the magnetometer's own checks keep
        the field as it came). None and not :attr:`field_calibrated`: the test uses gravity
        alone."""
        self._motion = MotionNoiseCheck(self.window, spec.odr_hz)
        self._carry = GravityCarry()
        self.reset()

    # -- public --------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget everything learnt and every latched fault (a new sensor, or the user's reset)."""
        self._floor = np.zeros(6)
        self._lsb_seen = np.full(6, np.inf)
        self._hist = np.zeros((4, 6))
        self._ints = np.zeros(3, dtype=np.int64)
        self._run_val = np.zeros(6)
        self._run_len = np.zeros(6, dtype=np.int64)
        self._sums = np.zeros((6, 4))
        self._window_x = np.zeros((self.window, 6))
        self._d4_abs = np.zeros((self.window, 6))
        self._local = np.zeros(6)
        self._stuck_len = np.full(6, np.iinfo(np.int64).max // 4)
        self._peak = np.zeros(6)
        self._quat = np.array([1.0, 0.0, 0.0, 0.0, -np.inf, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        self._window_t = 0.0
        self._rho = RowHistory(NOISE_SPAN_WINDOWS, 6)
        self._rho_flat = RowHistory(NOISE_SPAN_WINDOWS, 6)
        self._rho_white = RowHistory(NOISE_SPAN_WINDOWS, 6)
        self._rate: deque[float] = deque(maxlen=NOISE_SPAN_WINDOWS)
        self._activity = np.ones(6)
        self._threshold_cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._active_bits = np.zeros(6, dtype=np.uint8)
        self._gyro_ref: np.ndarray | None = None
        self._rest: _Rest | None = None
        self._counts = {"gyro_bias": 0, "accel_bias": 0, "gravity": 0, "gyro_abs": 0}
        self._last_flag: dict[tuple[str, str], float] = {}
        self._latched: dict[str, str] = {}
        self._last_t = -np.inf
        self.magnetometer.reset()
        self._motion.reset()
        self._carry.restart()
        self._field_seen = False
        self._mag = np.zeros((0, 3))
        self._field_state = new_state()
        self._field_trusted = False
        self._tilt: np.ndarray | None = None

    def update(self, block: SampleBlock, raw: RawBlock | None = None) -> list[FaultEvent]:
        """Run every test over ``block``; the events declared in it, in time order."""
        n = len(block)
        self.flags = np.zeros((n, 6), dtype=np.uint8)
        if n == 0:
            return []
        x = np.ascontiguousarray(np.hstack([block.accel_m_s2, block.gyro_rad_s]))
        if raw is not None and raw.scale is not None:
            lsb = [raw.scale.accel_m_s2_per_lsb] * 3 + [raw.scale.gyro_rad_s_per_lsb] * 3
            if lsb != self._lsb.tolist():
                self._lsb = np.array(lsb)
                self._threshold_cache = None
        t = np.ascontiguousarray(block.t_s, dtype=np.float64)
        gap = np.ascontiguousarray(block.gap, dtype=np.bool_)
        out: list[FaultEvent] = []
        self._mag = self._bias_field(block.mag_ut)
        if block.mag_ut is not None:
            # before the windows: a magnetometer fault in this block keeps its field out of
            # the gyro bias test
            self._field_seen = True
            counts = None if raw is None else raw.mag_raw
            out.extend(self.magnetometer.update(t, block.mag_ut, gap, counts))
        if gap[0] or t[0] <= self._last_t:
            self._restart(t[0], out, lost=raw.lost_samples if raw is not None else 0)
        breaks = np.flatnonzero(gap[1:]).tolist()  # rows 1.. that start after a gap
        start = 0
        while start < n:
            stop = min(n, start + self.window - int(self._ints[1]))
            while breaks and breaks[0] + 1 <= start:
                breaks.pop(0)
            if breaks:
                stop = min(stop, breaks[0] + 1)
            if start > 0 and gap[start]:
                self._restart(t[start], out, lost=0)
            self._scan_chunk(t, x, gap, start, stop)
            if self._ints[1] >= self.window:
                self._end_window(float(t[stop - 1]), out)
            start = stop
        self._last_t = float(t[-1])
        self._emit_sample_flags(t, x, out)
        self._mag = np.zeros((0, 3))
        out.sort(key=lambda e: e.t)
        self.events.extend(out)
        return out

    def health(self, now_s: float | None = None) -> dict[str, str]:
        """``"ok"``, ``"warning"`` or ``"fault"`` per channel (ax..gz, accel, gyro, link;
        and mx, my, mz, mag once a magnetometer's samples came).

        Transient kinds count while flagged in the last :data:`HOLD_S`; bias, gravity and
        consistency faults stay until :meth:`reset`.
        """
        now = self._last_t if now_s is None else now_s
        state = {name: "ok" for name in (*CHANNELS, "accel", "gyro", "link")}
        levels = {"saturation": "warning", "gap": "warning"}
        for (channel, kind), t_last in self._last_flag.items():
            if now - t_last <= HOLD_S or kind in LATCHED_KINDS:
                level = levels.get(kind, "fault")
                if severity_rank(level) > severity_rank(state[channel]):
                    state[channel] = level
        if self._field_seen:
            state.update(self.magnetometer.health(now))
        return state

    # -- internals -----------------------------------------------------------------------------
    def _restart(self, t: float, out: list[FaultEvent], lost: int) -> None:
        """A gap or a restart: nothing carries over the hole but what was learnt."""
        if lost > 0:
            self._event(out, t, "link", "gap", "warning",
                        f"{lost} samples lost before t = {t:.3f} s; tests restart")
        self._ints[:] = 0
        self._sums[:] = 0.0
        self._quat[:4] = (1.0, 0.0, 0.0, 0.0)
        self._quat[5:] = 0.0
        self._carry.restart()
        self._rho.clear()
        self._rho_flat.clear()
        self._rho_white.clear()
        self._rate.clear()
        self._rest = None
        self._tilt = None
        self._motion.restart()
        for key in self._counts:
            self._counts[key] = 0

    def _thresholds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stuck-run lengths, spike and clip thresholds; recomputed only after what they
        depend on may have changed (the LSB, the smallest step seen, a window's end: the
        floor and the activity), which sets ``_threshold_cache`` to None."""
        if self._threshold_cache is None:
            self._threshold_cache = self._compute_thresholds(self._floor_or_default())
        return self._threshold_cache

    def _compute_thresholds(self, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sigma = floor / D4_GAIN
        q = np.where(self._lsb > 0, self._lsb, self._lsb_seen)
        spike = sigma * SPIKE_NOISE_GAIN * self._activity
        return self._compute_stuck_runs(sigma, q), np.maximum(spike, 1e-300), floor * D4_CLIP

    def _compute_stuck_runs(self, sigma: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The stuck-run lengths of the module docstring, from the noise and the LSB (per
        channel in floats: numpy's operations one by one, its logs still by np.log)."""
        p0 = []
        for s, step in zip(sigma.tolist(), q.tolist(), strict=True):
            finite = math.isfinite(step)
            known = step if finite else 0.0
            least = 0.05 * (step if finite else s)
            sigma_noise = math.sqrt(_maximum(s * s - known * known / 12, least * least))
            scaled = step / (2.0 * math.sqrt(2.0) * _maximum(sigma_noise, 1e-300))
            p0.append(math.erf(scaled) if finite else 0.0)
        p = np.array(p0)
        with np.errstate(divide="ignore", invalid="ignore"):
            runs = np.where(p < 1.0, np.log(STUCK_FALSE_ALARM) / np.log(np.minimum(p, 1 - 1e-16)),
                            np.inf)
        odr = self.spec.odr_hz
        low, high = max(8, STUCK_MIN_S * odr), STUCK_MAX_S * odr
        # np.nan_to_num(nan=inf, posinf=1e18), np.clip(low, high), np.ceil
        return np.array([math.ceil(min(max(math.inf if r != r else 1e18 if r == math.inf else r,
                                           low), high)) for r in runs.tolist()], dtype=np.int64)

    def _floor_or_default(self) -> np.ndarray:
        if np.all(self._floor > 0):
            return self._floor
        if self._datasheet_floor is not None:
            return self._datasheet_floor
        return np.full(6, np.inf)

    def _scan_chunk(self, t: np.ndarray, x: np.ndarray, gap: np.ndarray, a: int, b: int) -> None:
        stuck, spike, clip = self._thresholds()
        self._stuck_len = stuck
        gyro_ref = self._gyro_ref if self._gyro_ref is not None else np.zeros(3)
        if self._ints[1] == 0:
            self._window_t = float(t[a])
        chunk_x = x[a:b]
        self._motion.filter(chunk_x, int(self._ints[1]))
        if _smallest_steps(chunk_x, self._lsb_seen):
            self._threshold_cache = None
        _scan(t[a:b], chunk_x, gap[a:b], self._hist, self._ints, self._run_val, self._run_len,
              self._sums, self._quat, self._local, self._peak,
              self._peak_decay, stuck, spike, clip, self._sat, gyro_ref, self._window_x,
              self._d4_abs, self._mag[a:b] if len(self._mag) else self._mag,
              self.flags[a:b])
        self.flags[a:b] |= self._active_bits

    def _end_window(self, t_end: float, out: list[FaultEvent]) -> None:
        self._threshold_cache = None  # the floor and the activity are learnt below
        n = float(self._ints[1])
        n_d4 = float(self._ints[2])
        sums = self._sums
        mean = sums[:, 1] / n
        spread = np.sqrt(np.maximum(sums[:, 2] / n - mean**2, 0.0))
        m = sums[:, 0] / max(n_d4, 1.0)
        quat = self._quat[:4].copy()
        carried = self._quat[5:8] / max(n, 1.0)
        field_count = float(self._quat[11])
        field = self._quat[8:11] / field_count if field_count > 0 else None
        duration = t_end - self._window_t
        self._ints[1:] = 0
        sums[:] = 0.0
        self._quat[:4] = (1.0, 0.0, 0.0, 0.0)
        self._quat[5:] = 0.0
        self._motion.end_window(int(n))
        if n_d4 < 0.5 * self.window:
            return
        if not np.all(self._floor > 0):
            first = m.copy()
            if self._datasheet_floor is not None:
                first = np.maximum(self._datasheet_floor,
                                   np.minimum(first, 3.0 * self._datasheet_floor))
            self._floor = np.maximum(first, 1e-12)
        rho = m / self._floor
        self._activity = np.maximum(1.0, rho)
        flat, white = self._flat(spread, m, int(n), int(n_d4))
        self._rho.append(rho)
        self._rho_white.append(white * D4_GAIN / self._floor)
        self._rho_flat.append(np.where(flat, rho, 0.0))
        self._rate.append(_norm(mean[3:] - (self._gyro_ref if self._gyro_ref is not None
                                            else 0.0)))
        self._noise_test(t_end, out)
        self._motion_noise_test(t_end, out)
        sigma = self._floor / D4_GAIN
        resting = bool(np.all(spread <= REST_SIGMA * sigma + 1e-12))
        field = self._trusted_field(field, carried, quat, mean[3:], duration, resting, t_end)
        self._carried_bias_test(quat, carried, duration, t_end, out, field)
        self._rest_tests(resting, mean, quat, duration, t_end, out)
        # learn the floor from quiet windows only
        quiet = (rho < 1.5) & ((rho >= 0.3) | (self._run_len < 4))
        self._floor = np.where(quiet, self._floor + FLOOR_ALPHA * (m - self._floor), self._floor)

    def _flat(self, spread: np.ndarray, m: np.ndarray, n: int, n_d4: int
              ) -> tuple[np.ndarray, np.ndarray]:
        """Channels flat but for their white noise this window, and that noise's sigma.

        Flat: the spread within NOISE_FLAT x the white-noise sigma. The clipped mean |d4| ``m``
        (robust to taps) cannot exceed D4_CLIP x the floor, so noise far above the floor would
        never look flat by it; the median |d4| is not clipped and ignores a few outliers as
        well, but a tone near or above ODR / 4 also has a large |d4|. A flat window must
        therefore also be white: with its straight-line trend removed (slow motion the spread
        test allows), the autocorrelation at lags 1-3 within 3 standard errors of white noise
        (3 / sqrt(n), at most 0.6). No pure tone passes: its largest |cos(k theta)| over
        k = 1..3 is at least 0.707 at every frequency.
        """
        sigma = m / D4_GAIN
        flat = spread <= NOISE_FLAT * sigma + 1e-300
        if n_d4 < 8:
            return flat, sigma
        sigma = np.maximum(sigma, column_median(self._d4_abs[:n_d4], False, True)
                           / D4_MEDIAN_GAIN)
        tested = np.flatnonzero(spread <= NOISE_FLAT * sigma)
        if len(tested):  # all channels at once: the least-squares line in closed form
            x = self._window_x[:n][:, tested]
            x = x - x.mean(axis=0)
            ramp = np.arange(n, dtype=float) - 0.5 * (n - 1)
            x = x - np.outer(ramp, (ramp @ x) / float(ramp @ ramp))
            limit = min(WHITE_CORR_MAX, 3.0 / math.sqrt(n)) * np.einsum("ij,ij->j", x, x)
            white = np.ones(len(tested), dtype=bool)
            for k in (1, 2, 3):
                white &= np.abs(np.einsum("ij,ij->j", x[k:], x[:-k])) <= limit
            flat[tested] = white
        return flat, sigma

    def _noise_test(self, t: float, out: list[FaultEvent]) -> None:
        self._active_bits &= ~np.uint8(NOISE)
        if len(self._rho) < NOISE_SPAN_WINDOWS or max(self._rate) >= NOISE_ARM_RATE_RAD_S:
            return
        level, others, ratios = _noise_ratios(self._rho.rows(), self._rho_white.rows(),
                                              self._rho_flat.rows())
        for c in np.flatnonzero(ratios > NOISE_RATIO):
            self._active_bits[c] |= NOISE
            self._event(out, t, CHANNELS[c], "noise", "fault",
                        f"{CHANNELS[c]} noise {level[c]:.1f}x its level at rest "
                        f"(other axes {others[c]:.1f}x) for 1 s", held=True)

    def _motion_noise_test(self, t: float, out: list[FaultEvent]) -> None:
        """Added noise while moving: the high band of one channel far above its own recent
        level and the other channels' (:mod:`app.core.faults.motion`)."""
        motion = self._motion
        if not motion.flagged.any():
            return
        low = BAND[0] * self.spec.odr_hz
        for c in np.flatnonzero(motion.flagged):
            self._active_bits[c] |= NOISE
            # (the event names the channel and kind: "gx noise: ..." in the banner)
            if motion.by_band[c]:
                why = (f"its band above {low:.0f} Hz is {motion.level[c]:.1f}x the other "
                       "channels' (relative to their own recent levels)")
            else:
                why = (f"the part of its band above {low:.0f} Hz that the other channels do "
                       f"not explain is {motion.residual_level[c]:.1f}x its recent level")
            self._event(out, t, CHANNELS[c], "noise", "fault",
                        f"{why} for 1.5 s; no motion puts it there", held=True)

    def _bias_field(self, mag_ut: np.ndarray | None) -> np.ndarray:
        """The field the gyro bias test carries: calibrated, or (0, 3) (none)."""
        if mag_ut is None or not (self.field_calibrated or self.field_calibration is not None):
            return np.zeros((0, 3))
        if self.field_calibration is not None:
            return np.ascontiguousarray(self.field_calibration.apply(mag_ut))
        return np.ascontiguousarray(mag_ut, dtype=np.float64)

    def _trusted_field(self, field: np.ndarray | None, accel: np.ndarray, quat: np.ndarray,
                       gyro: np.ndarray, duration: float, resting: bool, t: float
                       ) -> np.ndarray | None:
        """The window's mean field (window-start frame) when the gyro bias test may use it:
        the magnetic disturbance detector (:mod:`app.core.magnetometer.disturbance`: strength
        and dip against a reference learnt at rest or while turning) calls it undisturbed,
        and no magnetometer axis was declared faulty in the last HOLD_S. Otherwise None, and
        the field part of the test's horizon is dropped.

        The dip is taken against the direction of gravity from the accelerometer low-passed
        along the gyro's carry over ``TILT_TAU_S`` (VQF's 3 s), as a filter's tilt: a
        window's own mean acceleration tilts by up to 20 deg in a hand's translation (BROAD
        10), while a 2 dps bias moves the low-passed tilt by 6 deg at most."""
        up = self._tilt
        norm_a = _norm(accel)
        if norm_a > 0:
            alpha = duration / (TILT_TAU_S + duration) if up is not None else 1.0
            up = accel / norm_a if up is None else up + alpha * (accel / norm_a - up)
            up = up / _norm(up)
        # carried on into the next window's frame
        self._tilt = None if up is None else rotation_matrix(quat).T @ up
        if field is None or up is None:
            return None
        state = self._field_state
        rate = gyro - (self._gyro_ref if self._gyro_ref is not None else 0.0)
        track_rate(state, float(rate[0]), float(rate[1]), float(rate[2]), duration)
        norm = _norm(field)
        if not norm > 0:
            return None
        dip = math.asin(max(-1.0, min(1.0, -float(field @ up) / norm)))
        status = detector_step(state, _DISTURBANCE, norm, dip, duration, resting)
        healthy = all(level == "ok" for level in self.magnetometer.health(t).values())
        trusted = status == OK and healthy
        if not trusted and self._field_trusted:
            self._carry.forget_field()
        self._field_trusted = trusted
        turned = 2.0 * math.acos(min(1.0, abs(float(quat[0]))))
        if turned > FIELD_MAX_RATE_RAD_S * duration:
            return None  # trusted, but not this window's: see FIELD_MAX_RATE_RAD_S
        return field if trusted else None

    def _carried_bias_test(self, quat: np.ndarray, carried: np.ndarray, duration: float,
                           t: float, out: list[FaultEvent], field: np.ndarray | None = None
                           ) -> None:
        """A gyro bias step in motion: gravity (and the field, when trusted) carried by the
        gyro drift from the accelerometer's (and magnetometer's) (:mod:`app.core.faults.carry`)."""
        noisy = (self._active_bits[3:] & NOISE).any()
        if self._gyro_ref is None or noisy or self._frozen(t).any():
            # a channel already declared frozen or noisy explains a drift: no second culprit
            self._carry.restart()
            return
        found = self._carry.push(quat, carried, duration, field)
        if found is None:
            return
        axis, step = found
        with_field = self._carry.field_windows > 0
        carried_what = "gravity and the field" if with_field else "gravity"
        measured_by = "accelerometer and magnetometer" if with_field else "accelerometer"
        self._event(out, t, CHANNELS[3 + axis], "bias", "fault",
                    f"gyro bias changed by {_units(3 + axis, step[axis])} on "
                    f"{CHANNELS[3 + axis]} in motion ({carried_what} carried by the gyro "
                    f"drifts from what the {measured_by} measures)")
        self._gyro_ref = self._gyro_ref + step
        self._carry.restart()

    def _rest_tests(self, resting: bool, mean: np.ndarray, quat: np.ndarray, duration: float,
                    t: float, out: list[FaultEvent]) -> None:
        rest = self._rest
        if rest is not None:
            rest.rotation = _quat_mul(rest.rotation, quat)
            rest.elapsed_s += duration
        if not resting:
            for key in ("gyro_bias", "gravity", "gyro_abs"):
                self._counts[key] = 0
            if rest is not None and rest.elapsed_s > CONSISTENCY_MAX_S:
                self._rest = None
            return
        accel, gyro = mean[:3], mean[3:]
        frozen = self._frozen(t)
        if frozen[3:].any() or frozen[:3].any():
            # a channel already declared frozen explains any disagreement: no second culprit
            self._rest = None
            return
        self._gyro_rest_test(gyro, t, out)
        norm = _norm(accel)
        if abs(norm - G) > GRAVITY_TOLERANCE * G:
            self._counts["gravity"] += 1
            if self._counts["gravity"] >= REST_WINDOWS:
                axis = int(np.argmax(np.abs(accel)))
                channel = CHANNELS[axis] if abs(accel[axis]) > 0.9 * norm else "accel"
                self._event(out, t, channel, "gravity", "fault",
                            f"|a| = {norm / G:.3f} g at rest (expected 1 g within "
                            f"{GRAVITY_TOLERANCE:.0%})", held=True)
        else:
            self._counts["gravity"] = 0
        if rest is None or self._gyro_ref is None:
            self._rest = _Rest(accel.copy(), np.array([1.0, 0, 0, 0]), 0.0)
            return
        carried = _rotate_inverse(rest.rotation, rest.accel)
        angle = 2.0 * math.acos(min(1.0, abs(float(rest.rotation[0]))))
        if angle <= ACCEL_CARRY_MAX_RAD and rest.elapsed_s <= ACCEL_CARRY_MAX_S + 1e-9:
            diff = accel - carried
            if np.max(np.abs(diff)) > ACCEL_BIAS_STEP_M_S2 and self._counts["gyro_bias"] == 0:
                self._counts["accel_bias"] += 1
                if self._counts["accel_bias"] >= REST_WINDOWS:
                    order = np.argsort(np.abs(diff))
                    axis = int(order[-1])
                    dominant = abs(diff[axis]) > 2.0 * abs(diff[order[-2]])
                    channel = CHANNELS[axis] if dominant else "accel"
                    self._event(out, t, channel, "bias", "fault",
                                f"accelerometer offset changed by {_units(axis, diff[axis])} "
                                f"on {CHANNELS[axis]} at rest (gyro saw no rotation)")
                    self._rest = _Rest(accel.copy(), np.array([1.0, 0, 0, 0]), 0.0)
                return
        elif rest.elapsed_s <= CONSISTENCY_MAX_S:
            cosine = float(np.dot(carried, accel) / (np.linalg.norm(carried) * norm + 1e-300))
            error = math.acos(max(-1.0, min(1.0, cosine)))
            if error > CONSISTENCY_BASE_RAD + CONSISTENCY_FRACTION * angle:
                self._event(out, t, "gyro", "consistency", "fault",
                            f"gyro-carried gravity is {math.degrees(error):.1f} deg from the "
                            f"accelerometer's after a {math.degrees(angle):.0f} deg rotation",
                            held=True)
        self._counts["accel_bias"] = 0
        self._rest = _Rest(accel.copy(), np.array([1.0, 0, 0, 0]), 0.0)

    def _frozen(self, t: float) -> np.ndarray:
        """Channels declared stuck or dead within the last HOLD_S."""
        running = self._run_len + 1 >= np.maximum(self._stuck_len // 2, 2)
        last = self._last_flag
        return running | np.array([
            t - last.get((name, "stuck"), -math.inf) <= HOLD_S
            or t - last.get((name, "dead"), -math.inf) <= HOLD_S
            for name in CHANNELS
        ])

    def _gyro_rest_test(self, gyro: np.ndarray, t: float, out: list[FaultEvent]) -> None:
        if np.max(np.abs(gyro)) > GYRO_BIAS_ABS_RAD_S:
            self._counts["gyro_abs"] += 1
        else:
            self._counts["gyro_abs"] = 0
        if self._gyro_ref is None:
            if self._counts["gyro_abs"] >= REST_WINDOWS:
                axis = int(np.argmax(np.abs(gyro)))
                self._event(out, t, CHANNELS[3 + axis], "bias", "fault",
                            f"{CHANNELS[3 + axis]} reads {_units(3 + axis, gyro[axis])} at rest")
                self._gyro_ref = gyro.copy()
            elif self._counts["gyro_abs"] == 0:
                self._gyro_ref = gyro.copy()
            return
        diff = gyro - self._gyro_ref
        if np.max(np.abs(diff)) > GYRO_BIAS_STEP_RAD_S:
            self._counts["gyro_bias"] += 1
            if self._counts["gyro_bias"] >= REST_WINDOWS:
                axis = int(np.argmax(np.abs(diff)))
                self._event(out, t, CHANNELS[3 + axis], "bias", "fault",
                            f"gyro bias changed by {_units(3 + axis, diff[axis])} on "
                            f"{CHANNELS[3 + axis]} at rest (accelerometer saw no rotation)")
                self._gyro_ref = gyro.copy()
                self._counts["gyro_bias"] = 0
                self._rest = None
        else:
            self._counts["gyro_bias"] = 0
            self._gyro_ref = self._gyro_ref + 0.1 * diff

    def _emit_sample_flags(self, t: np.ndarray, x: np.ndarray, out: list[FaultEvent]) -> None:
        if not self.flags.any():
            return
        for bit in (STUCK, DEAD, SPIKE, SATURATION):
            rows, cols = np.nonzero(self.flags & bit)
            if rows.size == 0:
                continue
            kind = FLAG_KINDS[bit]
            for c in np.unique(cols):
                idx = rows[cols == c]
                times = t[idx]
                channel = CHANNELS[c]
                last = self._last_flag.get((channel, kind), -np.inf)
                prev = np.concatenate([[last], times[:-1]])
                for i in np.flatnonzero(times - prev > HOLD_S):
                    self._event(out, float(times[i]), channel, kind,
                                "warning" if bit == SATURATION else "fault",
                                self._sample_message(bit, c, x[idx[i], c]))
                self._last_flag[(channel, kind)] = float(times[-1])

    def _sample_message(self, bit: int, c: int, value: float) -> str:
        name = CHANNELS[c]
        if bit == STUCK:
            return f"{name} frozen at {_units(c, value)} (a run no noise would allow)"
        if bit == DEAD:
            return f"{name} reads exactly 0 (dead output)"
        if bit == SPIKE:
            return f"{name} one-sample spike on this channel alone (now {_units(c, value)})"
        return f"{name} at full scale ({_units(c, value)}): the reading is clipped"

    def _event(self, out: list[FaultEvent], t: float, channel: str, kind: str, severity: str,
               message: str, *, held: bool = False) -> None:
        """Append an event; ``held``: not while the same one was raised in the last HOLD_S."""
        key = (channel, kind)
        last = self._last_flag.get(key)
        self._last_flag[key] = t
        if held and last is not None and t - last <= HOLD_S:
            return
        out.append(FaultEvent(round(float(t), 6), channel, kind, severity, message))
