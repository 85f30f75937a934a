"""Fault detection on the magnetometer's axes (mx, my, mz): stuck, dead, spike, saturation.

The magnetometer runs slower than the accelerometer: a block's rows hold a field sample only
where one arrived (NaN elsewhere), and some sources repeat the last sample on the rows between
(held values). The tests therefore work on *field samples*, the finite rows, and count a value
as repeated only by the time it lasted and the samples in that time.

stuck / dead
    An axis reading exactly the same value for at least ``STUCK_MIN_S`` and at least as many
    field samples as make such a run improbable under the axis's own noise: with noise sigma
    and LSB q a true value repeats its count with probability ``p0 = erf(q / (2 sqrt 2
    sigma))`` (as for the accelerometer and gyro), so the run must reach ``ln(1e-9) /
    ln(p0)`` samples, at least ``STUCK_MIN_SAMPLES`` (LIS3MDL at +-4 gauss: q = 0.015 uT
    against 0.3 uT of noise, so even 20 samples are a 1e-40 event). Sigma is learnt from the
    samples' second differences (median, so motion and spikes weigh little). ``dead`` when
    the frozen value is exactly 0. The chip falling silent (no field sample for
    ``SILENT_MIN_S`` and 20 of its intervals while the accelerometer goes on) is ``dead`` on
    the ``mag`` channel.

spike
    One field sample out and back on its own: its distance from the mean of its neighbours
    over ``SPIKE_SIGMA`` x its local scale (the noise, raised by the recent activity) and over
    ``SPIKE_MIN_UT``, the neighbours within half of that of each other, and ``SPIKE_OVER_PEAK``
    x the largest such distance of the last half second (a field that changes fast, a turn
    or a magnet going by, builds up; a bad read does not).

saturation (warning)
    The chip's own overflow: a raw count at the int16 limit (when the counts are known), or
    an axis at or beyond the chip's full scale (LIS3MDL at +-4 gauss: +-400 uT), before
    calibration.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.faults.events import FaultEvent
from app.core.faults.rows import column_median

MAG_CHANNELS: tuple[str, ...] = ("mx", "my", "mz")
"""The magnetometer's three axes (the ``mag`` channel is the chip as a whole)."""
STUCK_FALSE_ALARM = 1e-9
STUCK_MIN_S = 1.0
STUCK_MIN_SAMPLES = 20
STUCK_MAX_S = 5.0
"""A run this long is stuck whatever the noise (a quiet sensor still moves its last bit)."""
SILENT_MIN_S = 1.0
SILENT_MIN_INTERVALS = 20
SPIKE_SIGMA = 10.0
SPIKE_MIN_UT = 3.0
"""Ten times the LIS3MDL's 0.3 uT of noise: no smaller step is a spike worth a fault."""
SPIKE_OVER_PEAK = 6.0
SPIKE_PEAK_HALF_LIFE_S = 0.5
SPIKE_LOCAL_ALPHA = 0.05
NOISE_ALPHA = 0.1
D2_MEDIAN_GAIN = math.sqrt(6.0) * 0.6744897501960817
"""Median |second difference| of unit white noise."""
HOLD_S = 5.0
LEARN_MIN_SAMPLES = 64
"""Field samples gathered before the noise, LSB and interval are learnt from them: a block
holds a few (a 100 Hz chip gives one or two per block at the top accelerometer rates), too few
for a median."""
INT16_MAX, INT16_MIN = 32767, -32768


@njit(cache=True)
def _scan_field(t, x, run_value, run_start, run_count, prev, prev_t, n_prev, local, peak,
                peak_before, sigma, stuck_samples, stuck_s, decay_per_s, flags, spike_t,
                spike_size):  # pragma: no cover (compiled)
    """Per field sample: runs (stuck 1 / dead 2) and the out-and-back test (spike 4, flagged
    on the sample that completes it; ``spike_t`` the spike's own time). Updates the state.

    A sample is tested against the peak *before* its predecessor's residual entered it: that
    residual has the spike for a neighbour (half its size) and would hide it."""
    gain = math.sqrt(math.pi / 2.0)
    for k in range(x.shape[0]):
        for c in range(3):
            if x[k, c] == run_value[c]:
                run_count[c] += 1
            else:
                run_value[c] = x[k, c]
                run_start[c] = t[k]
                run_count[c] = 1
            lasted = t[k] - run_start[c]
            if lasted >= stuck_s and (run_count[c] >= stuck_samples[c] or lasted >= STUCK_MAX_S):
                flags[k, c] |= 2 if x[k, c] == 0.0 else 1
        if n_prev[0] > 0:
            held = True
            for c in range(3):
                if x[k, c] != prev[1, c]:
                    held = False
            if held:
                continue  # a held value, not a new sample
        if n_prev[0] == 2:
            decay = math.exp(-decay_per_s * max(t[k] - prev_t[1], 0.0))
            for c in range(3):
                r = abs(prev[1, c] - 0.5 * (prev[0, c] + x[k, c]))
                back = abs(x[k, c] - prev[0, c])
                scale = max(1.22 * sigma[c], gain * local[c])
                if (r >= SPIKE_SIGMA * scale and r >= SPIKE_MIN_UT and back < 0.5 * r
                        and r > SPIKE_OVER_PEAK * peak_before[c]):
                    flags[k, c] |= 4
                    spike_t[k] = prev_t[1]
                    spike_size[k, c] = r
                local[c] += SPIKE_LOCAL_ALPHA * (min(r, 3.0 * scale + 1e-9) - local[c])
                peak_before[c] = peak[c] * decay
                peak[c] = max(peak[c] * decay, min(r, SPIKE_OVER_PEAK * peak[c] + scale))
        for c in range(3):
            prev[0, c] = prev[1, c]
            prev[1, c] = x[k, c]
        prev_t[0] = prev_t[1]
        prev_t[1] = t[k]
        n_prev[0] = min(n_prev[0] + 1, 2)


class MagnetometerCheck:
    """Stuck, dead, spike and saturation tests on a stream's magnetometer columns.

    Parameters
    ----------
    range_ut : the chip's full scale (+-uT), None when unknown (no full-scale test).
    ut_per_lsb : its count size, None when unknown (learnt from the smallest step seen).
    odr_hz : its own output rate, None when unknown (learnt from the samples' spacing).
    """

    def __init__(self, range_ut: float | None = None, ut_per_lsb: float | None = None,
                 odr_hz: float | None = None) -> None:
        self.range_ut = range_ut
        self.ut_per_lsb = ut_per_lsb
        self.odr_hz = odr_hz
        self.flags = np.zeros((0, 3), dtype=np.uint8)
        """The last block's per-row flags (N, 3), bits as the detector's FLAG_KINDS."""
        self.reset()

    def reset(self) -> None:
        self._prev = np.zeros((2, 3))  # the last two distinct samples, newest last
        self._prev_t = np.zeros(2)
        self._n_prev = np.zeros(1, dtype=np.int64)
        self._run_value = np.full(3, np.nan)
        self._run_start = np.full(3, np.nan)
        self._run_count = np.zeros(3, dtype=np.int64)
        self._sigma = np.full(3, np.nan)
        self._lsb_seen = np.full(3, np.inf)
        self._interval = np.nan if self.odr_hz is None else 1.0 / self.odr_hz
        self._local = np.zeros(3)
        self._peak = np.zeros(3)
        self._peak_before = np.zeros(3)
        self._last_field_t = np.nan
        self._last_flag: dict[tuple[str, str], float] = {}
        self._runs: np.ndarray | None = None  # _stuck_samples for the sigma and LSB learnt
        self._sigma_known = np.zeros(3)  # the noise learnt, 0 where not yet
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []  # field samples to learn from
        self._pending_count = 0

    def update(self, t_s: np.ndarray, mag_ut: np.ndarray, gap: np.ndarray,
               mag_counts: np.ndarray | None = None) -> list[FaultEvent]:
        """Test one block (field in uT before calibration, NaN rows without a sample;
        ``mag_counts`` the raw counts when known); its events in time order."""
        n = len(t_s)
        self.flags = np.zeros((n, 3), dtype=np.uint8)
        out: list[FaultEvent] = []
        if n == 0:
            return out
        rows = np.flatnonzero(np.isfinite(mag_ut).all(axis=1))
        if gap.any():
            # Lost data: a run or a neighbour across the hole proves nothing.
            first_gap = int(np.flatnonzero(gap)[-1])
            self._restart()
            keep = rows >= first_gap
            self._scan(t_s, mag_ut, rows[~keep], out, restart_after=True)
            rows = rows[keep]
        self._scan(t_s, mag_ut, rows, out)
        self._saturation(t_s, mag_ut, mag_counts, rows, out)
        self._silence(t_s, rows, out)
        out.sort(key=lambda e: e.t)
        return out

    # -- internals -------------------------------------------------------------------------------
    def _restart(self) -> None:
        self._n_prev[0] = 0
        self._run_value[:] = np.nan
        self._run_start[:] = np.nan
        self._run_count[:] = 0
        self._last_field_t = np.nan
        self._pending, self._pending_count = [], 0  # no difference across lost data

    def _stuck_samples(self) -> np.ndarray:
        """Run length (field samples) that makes a repeated value a fault, per axis (kept
        until the noise or the LSB is learnt again)."""
        if self._runs is None:
            self._runs = self._runs_for_noise()
        return self._runs

    def _runs_for_noise(self) -> np.ndarray:
        q = ([float(self.ut_per_lsb)] * 3 if self.ut_per_lsb
             else self._lsb_seen.tolist())
        runs = [float(STUCK_MIN_SAMPLES)] * 3
        for axis, sigma in enumerate(self._sigma.tolist()):
            if math.isfinite(q[axis]) and math.isfinite(sigma) and sigma > 0:
                p0 = math.erf(q[axis] / (2.0 * math.sqrt(2.0) * sigma))
                if p0 >= 1.0:
                    runs[axis] = math.inf
                elif p0 > 0.0:
                    runs[axis] = max(runs[axis], math.log(STUCK_FALSE_ALARM) / math.log(p0))
        return np.array(runs)

    def _scan(self, t_s: np.ndarray, mag: np.ndarray, rows: np.ndarray,
              out: list[FaultEvent], restart_after: bool = False) -> None:
        if not len(rows):
            return
        times = np.ascontiguousarray(t_s[rows], dtype=np.float64)
        values = np.ascontiguousarray(mag[rows], dtype=np.float64)
        self._pending.append((times, values))
        self._pending_count += len(times)
        if self._pending_count >= LEARN_MIN_SAMPLES:
            self._learn(np.concatenate([t for t, _ in self._pending]),
                        np.concatenate([v for _, v in self._pending]))
            self._pending, self._pending_count = [], 0
        interval = self._interval if math.isfinite(self._interval) else 0.0
        runs = self._stuck_samples()
        flags = np.zeros((len(rows), 3), dtype=np.uint8)
        spike_t = np.full(len(rows), np.nan)
        spike_size = np.zeros((len(rows), 3))
        _scan_field(times, values, self._run_value, self._run_start, self._run_count,
                    self._prev, self._prev_t, self._n_prev, self._local, self._peak,
                    self._peak_before,
                    self._sigma_known, runs, max(STUCK_MIN_S, STUCK_MIN_SAMPLES * interval),
                    math.log(2.0) / SPIKE_PEAK_HALF_LIFE_S, flags, spike_t, spike_size)
        if flags.any():
            self.flags[rows] |= flags
            for k, axis in zip(*np.nonzero(flags & 4), strict=True):
                self._flag(out, float(spike_t[k]), int(axis), "spike", "fault",
                           f"{MAG_CHANNELS[axis]} one-sample spike of "
                           f"{spike_size[k, axis]:.1f} uT (a bad read or a failing axis)")
            self._emit_runs(t_s, mag, rows, out)
        self._last_field_t = float(times[-1])
        if restart_after:
            self._restart()

    def _learn(self, times: np.ndarray, values: np.ndarray) -> None:
        """Noise (median |second difference| of distinct samples), LSB and interval."""
        self._runs = None
        changed = np.empty(len(values), dtype=bool)  # a row unlike the one before it
        changed[0] = True
        np.any(values[1:] != values[:-1], axis=1, out=changed[1:])
        distinct = values[changed]
        if len(distinct) > 1:
            steps = np.abs(np.diff(distinct, axis=0))
            steps = np.where(steps > 0, steps, np.inf).min(axis=0)
            self._lsb_seen = np.minimum(self._lsb_seen, steps)
            spacing = np.diff(times[changed])
            if self.odr_hz is None and len(spacing):
                interval = float(column_median(spacing[:, None], False, True)[0])  # np.median
                self._interval = interval if not np.isfinite(self._interval) else (
                    self._interval + NOISE_ALPHA * (interval - self._interval))
        if len(distinct) >= 8:
            d2 = np.abs(distinct[2:] - 2.0 * distinct[1:-1] + distinct[:-2])
            sigma = column_median(d2, False, True) / D2_MEDIAN_GAIN  # np.median(axis=0)
            self._sigma = np.where(np.isfinite(self._sigma),
                                   self._sigma + NOISE_ALPHA * (sigma - self._sigma), sigma)
            self._sigma_known = np.where(np.isfinite(self._sigma), self._sigma, 0.0)

    def _emit_runs(self, t_s: np.ndarray, mag: np.ndarray, rows: np.ndarray,
                   out: list[FaultEvent]) -> None:
        for bit, kind in ((1, "stuck"), (2, "dead")):
            for axis in range(3):
                flagged = rows[(self.flags[rows, axis] & bit) > 0]
                if len(flagged):
                    value = float(mag[flagged[0], axis])
                    message = (f"{MAG_CHANNELS[axis]} reads exactly 0 (dead output)"
                               if kind == "dead" else
                               f"{MAG_CHANNELS[axis]} frozen at {value:+.2f} uT "
                               f"(a run no noise would allow)")
                    self._flag(out, float(t_s[flagged[0]]), axis, kind, "fault", message,
                               last_t=float(t_s[flagged[-1]]))

    def _saturation(self, t_s: np.ndarray, mag: np.ndarray, counts: np.ndarray | None,
                    rows: np.ndarray, out: list[FaultEvent]) -> None:
        if not len(rows):
            return
        raw = counts[rows] if counts is not None and self.ut_per_lsb else None
        if ((raw is None or INT16_MIN < raw.min() <= raw.max() < INT16_MAX)
                and (not self.range_ut or np.abs(mag[rows]).max() < self.range_ut * (1 - 1e-9))):
            return  # the usual block: nothing near either limit
        over = np.zeros((len(rows), 3), dtype=bool)
        messages = {}
        if raw is not None:
            limit = (raw >= INT16_MAX) | (raw <= INT16_MIN)
            over |= limit
            for axis in np.flatnonzero(limit.any(axis=0)):
                messages[axis] = (f"{MAG_CHANNELS[axis]} overflowed (raw count at the int16 "
                                  f"limit): the field is beyond what the chip measures")
        if self.range_ut:
            beyond = np.abs(mag[rows]) >= self.range_ut * (1 - 1e-9)
            over |= beyond
            for axis in np.flatnonzero(beyond.any(axis=0)):
                messages.setdefault(axis, (
                    f"{MAG_CHANNELS[axis]} at full scale (±{self.range_ut:g} uT): the reading "
                    f"is clipped (a magnet too close)"))
        for axis in np.flatnonzero(over.any(axis=0)):
            hit = rows[over[:, axis]]
            self.flags[hit, axis] |= 8
            self._flag(out, float(t_s[hit[0]]), int(axis), "saturation", "warning", messages[axis],
                       last_t=float(t_s[hit[-1]]))

    def _silence(self, t_s: np.ndarray, rows: np.ndarray, out: list[FaultEvent]) -> None:
        """The chip stopped delivering while the accelerometer goes on."""
        if not math.isfinite(self._last_field_t) or not math.isfinite(self._interval):
            return
        newest = float(t_s[-1])
        silent = newest - self._last_field_t
        if silent >= max(SILENT_MIN_S, SILENT_MIN_INTERVALS * self._interval):
            self._flag(out, newest, None, "dead", "fault",
                       f"no magnetometer sample for {silent:.1f} s (the chip stopped "
                       f"delivering)")

    def _flag(self, out: list[FaultEvent], t: float, axis: int | None, kind: str,
              severity: str, message: str, last_t: float | None = None) -> None:
        """An event unless the same one was raised within HOLD_S."""
        channel = "mag" if axis is None else MAG_CHANNELS[axis]
        key = (channel, kind)
        last = self._last_flag.get(key, -np.inf)
        self._last_flag[key] = t if last_t is None else last_t
        if t - last > HOLD_S:
            out.append(FaultEvent(round(float(t), 6), channel, kind, severity, message))

    def health(self, now_s: float) -> dict[str, str]:
        """``"ok"``, ``"warning"`` or ``"fault"`` for mx, my, mz and the chip (``mag``)."""
        state = dict.fromkeys((*MAG_CHANNELS, "mag"), "ok")
        for (channel, kind), t_last in self._last_flag.items():
            if now_s - t_last <= HOLD_S:
                level = "warning" if kind == "saturation" else "fault"
                if state[channel] != "fault":
                    state[channel] = level
        return state
