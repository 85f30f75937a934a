"""Look-alike parts (WHO_AM_I 0x6C): |a| at rest near 0.5 g or 2 g is a range off by two."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.lookalike import LookAlikeCheck, lookalike_message
from app.core.samples import SampleBlock

G = 9.80665


def block(accel_g: float, n: int = 52, t0: float = 0.0, rate_hz: float = 104.17,
          gyro_dps: float = 0.2) -> SampleBlock:
    t = t0 + np.arange(n) / rate_hz
    accel = np.tile([0.0, 0.0, accel_g * G], (n, 1))
    accel += np.random.default_rng(1).normal(0.0, 0.002 * G, (n, 3))
    gyro = np.full((n, 3), np.radians(gyro_dps))
    return SampleBlock(t, accel, gyro, np.full(n, 25.0), np.zeros(n, dtype=bool))


@pytest.mark.parametrize(("accel_g", "words"), [
    (0.5, ["0.50 g at rest", "LSM6DSO32", "double"]),
    (2.0, ["2.00 g at rest", "half"]),
])
def test_a_range_off_by_two_at_rest_is_named(accel_g, words) -> None:
    check = LookAlikeCheck()
    messages = [check.update(block(accel_g, t0=k * 0.5)) for k in range(3)]
    found = [m for m in messages if m]
    assert len(found) == 1 and all(word in found[0] for word in words)
    assert check.done and check.accel_g == pytest.approx(accel_g, abs=0.01)
    assert check.update(block(accel_g, t0=2.0)) is None  # said once


def test_one_g_at_rest_is_quiet_and_judged() -> None:
    check = LookAlikeCheck()
    assert all(check.update(block(1.0, t0=k * 0.5)) is None for k in range(3))
    assert check.done and check.accel_g == pytest.approx(1.0, abs=0.01)


def test_motion_is_not_judged_until_the_sensor_rests() -> None:
    check = LookAlikeCheck()
    for k in range(4):  # turning at 30 dps: never at rest
        assert check.update(block(0.5, t0=k * 0.5, gyro_dps=30.0)) is None
    assert not check.done
    messages = [check.update(block(0.5, t0=2.0 + k * 0.5)) for k in range(3)]
    assert any(m and "0.50 g" in m for m in messages)


def test_a_sensor_never_at_rest_gets_no_verdict() -> None:
    check = LookAlikeCheck()
    for k in range(70):
        assert check.update(block(0.5, t0=k * 0.5, gyro_dps=30.0)) is None
    assert check.done and check.accel_g is None


def test_the_message_bands() -> None:
    assert lookalike_message(1.0) is None and lookalike_message(1.2) is None
    assert lookalike_message(0.1) is None  # free fall or a dead axis is another story
    assert "LSM6DSO32" in (lookalike_message(0.52) or "")
    assert "half" in (lookalike_message(1.95) or "")


def test_a_link_delivering_one_sample_a_block_is_judged_after_half_a_second() -> None:
    check = LookAlikeCheck()
    rate = 104.17
    found = []
    for k in range(80):  # 0.77 s of one-sample blocks, as a slow link may deliver them
        message = check.update(block(0.5, n=1, t0=k / rate))
        if message:
            found.append(k)
    # Judged once the stretch covers 0.5 s (53 samples at 104.17 Hz), not before, only once.
    assert found == [52]
    assert check.accel_g == pytest.approx(0.5, abs=0.01)
