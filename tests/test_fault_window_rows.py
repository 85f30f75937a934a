"""The fault tests' per-window helpers give numpy's values to the bit: the column medians
(numpy's median and the partition median), the ratio over the other channels, the noise
test's means, the rest test's carry, and the gyro bias test's horizon whatever its arrays'
size (:mod:`app.core.faults.rows`, :mod:`app.core.faults.carry`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.faults.carry import GravityCarry
from app.core.faults.detector import (
    STUCK_FALSE_ALARM,
    STUCK_MAX_S,
    STUCK_MIN_S,
    FaultDetector,
    _noise_ratios,
    _rotate_inverse,
)
from app.core.faults.motion import _worst_lag, band_autocorrelation, butterworth_sos
from app.core.faults.rows import RowHistory, column_kth, column_median, less_others
from app.core.faults.spec import SensorSpec
from app.core.samples import STANDARD_GRAVITY_M_S2


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal to the bit (NaN where NaN, the sign of zero too)."""
    return a.tobytes() == np.asarray(b, dtype=np.float64).tobytes()


@pytest.mark.parametrize("rows", [1, 2, 5, 6, 40, 71])
def test_column_medians_are_numpys(rows: int) -> None:
    rng = np.random.default_rng(rows)
    for trial in range(40):
        a = np.round(rng.standard_normal((rows, 7)) * 3.0, trial % 3)  # ties, and -0.0
        if trial % 4 == 1:
            a[rng.random(a.shape) < 0.3] = np.nan
        for square in (False, True):
            b = a**2 if square else a
            assert _same(column_median(a, square, True), np.median(b, axis=0))
            k = int(rng.integers(0, rows))
            if not np.any(b == 0):  # (-0.0 and 0.0: the partition may give either)
                assert _same(column_kth(a, k, square), np.partition(b, k, axis=0)[k])
                half = rows // 2
                part = np.partition(b, (max(half - 1, 0), half), axis=0)
                expected = part[half] if rows % 2 else 0.5 * (part[half - 1] + part[half])
                assert _same(column_median(a, square, False), expected)


def test_the_ratio_over_the_other_channels_is_np_delete_s() -> None:
    rng = np.random.default_rng(5)
    for trial in range(200):
        log_r = rng.standard_normal(6)
        log_r[rng.integers(0, 6)] = (np.nan, 0.0, -0.0, 3.0)[trial % 4]
        expected = [log_r[c] - max(0.0, float(np.max(np.delete(log_r, c)))) for c in range(6)]
        assert _same(less_others(log_r), expected)


def test_a_row_history_keeps_the_last_rows_oldest_first() -> None:
    history = RowHistory(3, 2)
    for i in range(5):
        history.append(np.array([i, -i]))
    assert len(history) == 3
    assert history.rows().tolist() == [[2, -2], [3, -3], [4, -4]]
    history.clear()
    assert len(history) == 0 and history.rows().shape == (0, 2)


def test_the_noise_tests_means_and_ratios_are_numpys() -> None:
    rng = np.random.default_rng(6)
    for _ in range(200):
        rho, white, flat = (np.abs(rng.standard_normal((4, 6))) * 10.0 for _ in range(3))
        low = np.mean(rho, axis=0)
        others = [max(low[o] for o in range(c // 3 * 3, c // 3 * 3 + 3) if o != c)
                  for c in range(6)]
        ratios = np.mean(flat, axis=0) / np.maximum(1.0, others)
        level, got_others, got_ratios = _noise_ratios(rho, white, flat)
        assert _same(level, np.mean(white, axis=0))
        assert _same(got_others, others) and _same(got_ratios, ratios)


def test_the_rest_carry_is_np_cross_s() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        v = rng.standard_normal(3) * 10.0
        w, u = q[0], -q[1:]
        expected = v + 2.0 * w * np.cross(u, v) + 2.0 * np.cross(u, np.cross(u, v))
        assert _same(_rotate_inverse(q, v), expected)


def test_the_bias_horizon_does_not_depend_on_its_arrays_size() -> None:
    # 0.1 s windows: 80 in the 8 s horizon, more than the arrays hold at first (they grow)
    small, large = GravityCarry(), GravityCarry()
    large._allocate(1024)
    rng = np.random.default_rng(8)
    half = math.radians(0.5) * 0.1 / 2.0
    rotation = np.array([math.cos(half), math.sin(half), 0.0, 0.0])
    for i in range(120):
        accel = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2]) + rng.standard_normal(3) * 0.01
        field = np.array([0.0, 15.0, -40.0]) + rng.standard_normal(3) * 0.2
        if i == 90:
            small.forget_field()
            large.forget_field()
        for carry in (small, large):
            carry.push(rotation, accel, 0.1, field if i % 3 else None)
        assert _same(small.estimate, large.estimate) and _same(small.error, large.error)
    assert len(small._durations) > 64 and small.field_windows == large.field_windows


def test_the_band_whiteness_is_einsum_s() -> None:
    reference = band_autocorrelation(np.vstack([butterworth_sos(4, 0.25, "high"),
                                                butterworth_sos(4, 0.45, "low")]))
    rng = np.random.default_rng(9)
    for trial in range(100):
        out = rng.standard_normal(((71, 72, 250)[trial % 3], 6)) * 10.0 ** (trial % 7 - 3)
        if trial % 5 == 0:
            out[:, trial % 6] = 0.0  # no power: the 1e-300 floor
        power = np.einsum("ij,ij->j", out, out)
        worst = np.zeros(6)
        for k, value in enumerate(reference, start=1):
            lagged = np.einsum("ij,ij->j", out[k:], out[:-k]) / np.maximum(power, 1e-300)
            worst = np.maximum(worst, np.abs(lagged - value))
        assert _same(_worst_lag(out, reference), worst)


def _stuck_runs_by_arrays(sigma: np.ndarray, q: np.ndarray, odr: float) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma_noise = np.sqrt(np.maximum(sigma**2 - np.where(np.isfinite(q), q, 0.0)**2 / 12,
                                         (0.05 * np.where(np.isfinite(q), q, sigma))**2))
        p0 = np.where(np.isfinite(q), np.vectorize(math.erf)(
            q / (2.0 * math.sqrt(2.0) * np.maximum(sigma_noise, 1e-300))), 0.0)
        runs = np.where(p0 < 1.0, np.log(STUCK_FALSE_ALARM) / np.log(np.minimum(p0, 1 - 1e-16)),
                        np.inf)
    stuck = np.clip(np.nan_to_num(runs, nan=np.inf, posinf=1e18),
                    max(8, STUCK_MIN_S * odr), STUCK_MAX_S * odr)
    return np.ceil(stuck).astype(np.int64)


@pytest.mark.parametrize("odr", [104.0, 6667.0])
def test_the_stuck_runs_are_the_array_formulas(odr: float) -> None:
    detector = FaultDetector(SensorSpec(odr_hz=odr))
    rng = np.random.default_rng(10)
    for trial in range(300):
        sigma = np.abs(rng.standard_normal(6)) * 10.0 ** rng.uniform(-6, 1, 6)
        q = sigma * rng.uniform(0.0, 10.0, 6) if trial % 2 else rng.uniform(0, 1e-3, 6)
        q[trial % 6] = (np.inf, 0.0, q[0])[trial % 3]
        sigma[(trial + 1) % 6] = (np.inf, np.nan, 0.0, sigma[0])[trial % 4]
        got = detector._compute_stuck_runs(sigma, q)
        assert got.dtype == np.int64
        assert got.tolist() == _stuck_runs_by_arrays(sigma, q, odr).tolist()
