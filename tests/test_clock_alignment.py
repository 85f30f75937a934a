"""Clock alignment of several devices: the lower envelope of (device time, receive time)."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.clock_alignment import ClockAligner, fit_lower_envelope
from drivers.sim.device import SimulatedDevice


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_lower_envelope_recovers_offset_and_drift_under_one_sided_latency() -> None:
    rng = np.random.default_rng(3)
    device = np.sort(rng.uniform(0.0, 60.0, 2000))
    latency = rng.exponential(0.004, len(device)) + 0.0005
    host = 42.0 + device / (1 + 250e-6) + latency
    fit = fit_lower_envelope(device, host)
    assert fit.drift_ppm == pytest.approx(250.0, abs=3.0)
    assert fit.offset_s == pytest.approx(42.0005, abs=2e-4)
    # Least squares would be biased by the mean latency (4 ms); the envelope is not.
    assert float(fit.to_host(30.0)) == pytest.approx(42.0005 + 30.0 / (1 + 250e-6), abs=2e-4)
    assert 2.0 < fit.spread_ms < 15.0


def test_short_windows_fit_the_offset_only() -> None:
    fit = fit_lower_envelope(np.array([0.0, 0.5, 1.0]), np.array([10.003, 10.501, 11.002]))
    assert fit.scale == 1.0
    assert fit.offset_s == pytest.approx(10.001)
    with pytest.raises(ValueError):
        fit_lower_envelope(np.array([]), np.array([]))


def test_a_restarted_clock_clears_the_window() -> None:
    aligner = ClockAligner()
    for k in range(50):
        aligner.add(10.0 + k * 0.1, 5.0 + k * 0.1)
    aligner.add(0.0, 10.1)
    fit = aligner.fit()
    assert fit is not None and fit.points == 1 and fit.offset_s == pytest.approx(10.1)


def _run(devices: list[SimulatedDevice], clock: FakeClock, seconds: float,
         rng: np.random.Generator) -> list[ClockAligner]:
    aligners = [ClockAligner() for _ in devices]
    while clock.now < 100.0 + seconds:
        clock.now += 0.05
        for device, aligner in zip(devices, aligners, strict=True):
            block = device.read(0.0)
            if block is not None:
                # The reader sees it a little later: latency is never negative.
                aligner.add(float(block.t_s[-1]), clock.now + rng.exponential(0.003))
    return aligners


def test_two_arm_sensors_with_a_known_clock_offset_and_drift_are_aligned() -> None:
    clock = FakeClock()
    rng = np.random.default_rng(1)
    base = SimulatedDevice("sim://arm?seed=5&odr=104", clock=clock)
    base.open()
    clock.now += 0.37  # the second sensor is opened later, on the same arm
    other = SimulatedDevice("sim://arm?seed=5&odr=104&sensor=1&clock_offset=3.25&clock_ppm=500",
                            clock=clock)
    other.open()
    assert base.info.extra["clock_domain"] != other.info.extra["clock_domain"]
    fit0, fit1 = (a.fit() for a in _run([base, other], clock, 30.0, rng))
    assert fit0 is not None and fit1 is not None
    assert fit1.drift_ppm - fit0.drift_ppm == pytest.approx(500.0, abs=30.0)
    d0 = np.array([3.0, 12.0, 20.0])
    d1 = fit1.to_device(fit0.to_host(d0))  # sensor 1's clock at sensor 0's times
    assert np.allclose(d1, d0 * (1 + 500e-6) + 3.25, atol=1e-3)
    # And the samples really are the same instants of one arm: same true orientation.
    base.close()
    other.close()


def test_sensors_of_one_arm_share_one_clock_domain_and_start() -> None:
    clock = FakeClock()
    base = SimulatedDevice("sim://arm?seed=5", clock=clock)
    base.open()
    clock.now += 2.0
    other = SimulatedDevice("sim://arm?seed=5&sensor=1", clock=clock)
    other.open()
    assert base.info.extra["clock_domain"] == other.info.extra["clock_domain"]
    clock.now += 0.5
    a, b = base.read(0.0), other.read(0.0)
    assert a is not None and b is not None
    # The second sensor joined the arm's clock: its newest sample is the base's newest.
    assert float(b.t_s[-1]) == pytest.approx(float(a.t_s[-1]))
    assert float(b.t_s[0]) > 1.9
    base.close()
    other.close()
    lonely = SimulatedDevice("sim://arm?seed=5&sensor=1", clock=clock)
    lonely.open()
    clock.now += 0.5
    block = lonely.read(0.0)
    assert block is not None and float(block.t_s[0]) == 0.0  # nobody to join: starts at 0
    lonely.close()
