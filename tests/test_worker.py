"""The worker thread streams a real (simulated) device into the pipeline's buffers."""

from __future__ import annotations

import numpy as np
import pytest

from app.services.session import DeviceSession

TIMEOUT_MS = 15_000


@pytest.fixture
def session(qtbot):
    session = DeviceSession()
    yield session
    session.shutdown()


def connect(qtbot, session: DeviceSession, url: str):
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS) as blocker:
        session.requestConnect.emit(url)
    return blocker.args[0]


def test_streaming_fills_the_buffers_with_the_true_tilt(qtbot, session):
    info = connect(qtbot, session, "sim://static?odr=833&roll=5&pitch=-3&seed=2&speed=4")
    assert info.sensor == "LSM6DSOX"
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 1500, timeout=TIMEOUT_MS)
    latest = session.pipeline.orientation.latest(200)
    # Uncalibrated: the unit's biases tilt the reading by up to about a degree.
    assert np.mean(latest["roll"]) == pytest.approx(5.0, abs=2.0)
    assert np.mean(latest["pitch"]) == pytest.approx(-3.0, abs=2.0)
    np.testing.assert_allclose(latest["ref_roll"], 5.0, atol=1e-6)
    samples = session.pipeline.samples.latest(1000)
    assert np.all(np.diff(samples["t"]) > 0)


def test_devices_and_filters_switch_while_running(qtbot, session):
    connect(qtbot, session, "sim://static?odr=208")
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 100, timeout=TIMEOUT_MS)

    with qtbot.waitSignal(session.filterChanged, timeout=TIMEOUT_MS) as blocker:
        session.requestFilter.emit("accel")
    assert blocker.args[0] == "accel"
    assert session.pipeline.filter.name == "accel"
    count = session.pipeline.counters.samples
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > count + 100, timeout=TIMEOUT_MS)

    info = connect(qtbot, session, "sim://wobble?odr=833")
    assert info.url.startswith("sim://wobble")
    assert info.odr_nominal_hz == 833.0
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 500, timeout=TIMEOUT_MS)
    assert session.pipeline.filter.name == "accel"  # the filter choice survives the switch

    with qtbot.waitSignal(session.filterChanged, timeout=TIMEOUT_MS):
        session.requestFilterParameter.emit("average_samples", 8)
    assert session.pipeline.filter.get_parameter("average_samples") == 8


def test_a_device_failing_mid_stream_reports_and_the_session_recovers(qtbot, session):
    errors: list[str] = []
    session.error.connect(errors.append)
    with qtbot.waitSignal(session.disconnected, timeout=TIMEOUT_MS) as blocker:
        session.requestConnect.emit("sim://static?odr=416&fail_after=0.3")
    assert "unplugged" in blocker.args[0]
    assert errors and "unplugged" in errors[0]
    assert session.device_info is None
    # Nothing is lost: what was streamed before the failure is still in the buffers.
    assert session.pipeline.counters.samples > 0
    # And the session is still usable.
    connect(qtbot, session, "sim://static")
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 10, timeout=TIMEOUT_MS)


def test_a_bad_url_gives_a_message_not_a_crash(qtbot, session):
    with qtbot.waitSignal(session.error, timeout=TIMEOUT_MS) as blocker:
        session.requestConnect.emit("nosuch://thing")
    assert "no driver for nosuch://" in blocker.args[0]
    with qtbot.waitSignal(session.error, timeout=TIMEOUT_MS) as blocker:
        session.requestConnect.emit("sim://static?odr=banana")
    assert "odr" in blocker.args[0]


def test_status_reports_the_measured_rate(qtbot, session):
    connect(qtbot, session, "sim://static?odr=417")
    statuses = []
    session.status.connect(statuses.append)
    qtbot.waitUntil(lambda: len(statuses) >= 6, timeout=TIMEOUT_MS)
    info = session.device_info
    assert statuses[-1].measured_rate_hz == pytest.approx(info.odr_hz, rel=0.15)
    assert statuses[-1].samples > 0
