"""Added noise in motion by analytic redundancy between the channels (issue 33): a vibration
that drives all six channels coherently is explained by the other channels and raises
nothing; white noise added to one channel is not, and is found on that channel. Synthetic
streams through :class:`MotionNoiseCheck` (fast); the real trials are
``evaluate-faults --in-motion`` (docs/fault-evaluation/in-motion-coherent.txt)."""

from __future__ import annotations

import math

import numpy as np

from app.core.faults.coherence import DIM, LAGS, SPAN, lagged
from app.core.faults.motion import BAND, ORDER, MotionNoiseCheck, _band_filter, butterworth_sos

ODR = 400.0
WINDOW = 100
GAINS = np.array([1.0, 0.7, -0.5, 0.012, -0.009, 0.006])
"""A rigid body's vibration on each channel (m/s^2 and rad/s per unit)."""
DELAYS = (0, 1, 0, 2, 1, 0)
FLOOR = np.array([0.02, 0.02, 0.03, 0.001, 0.001, 0.001])
"""Each channel's own white noise (m/s^2, rad/s)."""


def _vibration(n: int, rng: np.random.Generator) -> np.ndarray:
    """A phone-like vibration in the band: a tone at 0.3 of the rate plus band-limited
    noise, its amplitude swelling 0.5-1.5 every 5 s."""
    t = np.arange(n) / ODR
    sos = np.vstack([butterworth_sos(ORDER, BAND[0], "high"),
                     butterworth_sos(ORDER, BAND[1], "low")])
    broad = np.zeros((n, 1))
    _band_filter(rng.normal(0.0, 1.0, (n, 1)), sos, np.zeros((sos.shape[0], 1, 2)), broad)
    tone = np.sin(2 * math.pi * 0.3 * ODR * t + 0.3 * np.sin(2 * math.pi * 0.7 * t))
    return (1.0 + 0.5 * np.sin(2 * math.pi * 0.2 * t)) * (tone + 0.5 * broad[:, 0])


def _stream(seconds: float, seed: int = 1, vibration: float = 1.0) -> np.ndarray:
    """(N, 6) ax..gz: hand motion (~1 Hz, tens of dps), the coherent vibration, the floor."""
    rng = np.random.default_rng(seed)
    n = round(seconds * ODR)
    t = np.arange(n) / ODR
    v = vibration * _vibration(n + 2, rng)
    x = np.empty((n, 6))
    for c in range(6):
        x[:, c] = GAINS[c] * v[2 - DELAYS[c]:2 - DELAYS[c] + n]
    x[:, :3] += [0.5, -0.3, 9.81] + np.sin(2 * math.pi * 0.8 * t)[:, None] * [1.0, 0.5, 0.3]
    x[:, 3:] += np.sin(2 * math.pi * 1.1 * t + np.array([[0.0, 1.0, 2.0]]).T).T * 0.5
    return x + rng.normal(0.0, 1.0, x.shape) * FLOOR


def _run(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per window: flagged, flagged by the band test, flagged by the residual test."""
    check = MotionNoiseCheck(WINDOW, ODR)
    flagged, band, residual = [], [], []
    for start in range(0, len(x) - WINDOW + 1, WINDOW):
        check.filter(np.ascontiguousarray(x[start:start + WINDOW]), 0)
        check.end_window(WINDOW)
        flagged.append(check.flagged.copy())
        band.append(check.by_band.copy())
        residual.append(check.by_residual.copy())
    return np.array(flagged), np.array(band), np.array(residual)


def test_lagged_rows_hold_each_channel_at_each_delay() -> None:
    band = np.arange(30.0).reshape(5, 6)
    tail = -np.arange(1.0, 2 * LAGS * 6 + 1).reshape(2 * LAGS, 6)
    z = lagged(band, tail)
    assert z.shape == (5, DIM)
    whole = np.vstack([tail, band])
    for i in range(5):
        for c in range(6):
            for j in range(SPAN):
                assert z[i, c * SPAN + j] == whole[2 * LAGS + i - j, c]


def test_a_coherent_vibration_raises_nothing() -> None:
    flagged, _, _ = _run(_stream(24.0))
    assert not flagged.any()


def test_one_gyro_axis_with_1_dps_noise_in_the_vibration_is_found_on_it() -> None:
    x = _stream(24.0, seed=2)
    onset = round(20.0 * ODR)
    rng = np.random.default_rng(7)
    x[onset:, 4] += rng.normal(0.0, math.radians(1.0), len(x) - onset)
    flagged, band, residual = _run(x)
    first = onset // WINDOW
    assert not flagged[:first].any()
    hits = np.flatnonzero(flagged[first:].any(axis=1))
    assert len(hits) and hits[0] * WINDOW / ODR <= 2.0, "not found within 2 s"
    assert set(np.flatnonzero(flagged[first + hits[0]])) == {4}, "not on gy alone"
    # the vibration fills gy's band: its power alone (the band test) does not see the noise
    assert not band[first:first + 8, 4].any()
    assert residual[first + hits[0], 4]


def test_one_accelerometer_axis_with_noise_in_the_vibration_is_found_on_it() -> None:
    x = _stream(24.0, seed=3)
    onset = round(20.0 * ODR)
    rng = np.random.default_rng(8)
    x[onset:, 2] += rng.normal(0.0, 0.2, len(x) - onset)
    flagged, _, residual = _run(x)
    first = onset // WINDOW
    assert not flagged[:first].any()
    hits = np.flatnonzero(flagged[first:].any(axis=1))
    assert len(hits) and hits[0] * WINDOW / ODR <= 2.0
    assert set(np.flatnonzero(flagged[first + hits[0]])) == {2}
    assert residual[first + hits[0], 2]


def test_a_window_whose_rate_left_the_historys_regime_does_not_count() -> None:
    """Motion starting after rest raises one gyro axis' band with its rate (a rotation's own
    artefact, not explained by the other channels): against a history learnt at rest that
    is no evidence, and the window does not count; at a steady rate the same rise does."""
    from app.core.faults.coherence import CoherenceCheck

    rng = np.random.default_rng(4)
    reference = np.zeros(6)

    def feed(check: CoherenceCheck, rate: float, gx_sigma: float) -> np.ndarray:
        band = rng.normal(0.0, 1.0, (WINDOW, 6)) * FLOOR
        band[:, 3] += rng.normal(0.0, gx_sigma, WINDOW)
        log_s, _ = check.window(band, rate, np.zeros(6), np.zeros(6, dtype=bool))
        return log_s

    for rate, expect_counted in ((0.01, False), (3.0, True)):
        check = CoherenceCheck(40, 2, 16, reference, 1.0)
        for _ in range(60):
            feed(check, rate, 0.0)
        log_s = feed(check, 3.0, 0.01)  # the band of gx 10x its floor
        assert np.isfinite(log_s[3]) == expect_counted
        if expect_counted:
            assert log_s[3] > math.log(20.0)


def test_the_detector_names_the_channel_and_says_the_others_do_not_explain_it() -> None:
    from app.core.faults import FaultDetector, SensorSpec
    from app.core.samples import SampleBlock

    x = _stream(24.0, seed=2)
    onset = round(20.0 * ODR)
    x[onset:, 4] += np.random.default_rng(7).normal(0.0, math.radians(1.0), len(x) - onset)
    n = len(x)
    t = np.arange(n) / ODR
    detector = FaultDetector(SensorSpec(odr_hz=ODR))
    events = []
    for start in range(0, n, 40):
        stop = min(n, start + 40)
        events += detector.update(SampleBlock(t[start:stop], x[start:stop, :3],
                                              x[start:stop, 3:], np.zeros(stop - start),
                                              np.zeros(stop - start, dtype=bool)))
    alarms = [e for e in events if e.channel != "link"]
    assert alarms, "nothing found"
    first = alarms[0]
    assert (first.channel, first.kind) == ("gy", "noise")
    assert onset / ODR <= first.t <= onset / ODR + 2.0
    assert "do not explain" in first.message
