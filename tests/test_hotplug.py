"""Pull the cable of an (emulated) NUCLEO mid-session and plug it back in."""

from __future__ import annotations

import os

import numpy as np
import pytest

from app.services.session import DeviceSession
from drivers.emulated_nucleo import EmulatedNucleo

TIMEOUT_MS = 20_000


@pytest.fixture
def nucleo():
    board = EmulatedNucleo("static", odr_hz=104.0, seed=11)
    yield board
    board.close()


def test_unplug_keeps_the_session_and_replug_reconnects_by_usb_serial(qtbot, nucleo):
    session = DeviceSession()
    try:
        with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS) as blocker:
            session.requestConnect.emit(nucleo.port)
        first_port = nucleo.port
        info = blocker.args[0]
        assert info.extra.get("usb_serial")
        pipeline = session.pipeline
        qtbot.waitUntil(lambda: pipeline.counters.samples > 150, timeout=TIMEOUT_MS)

        with qtbot.waitSignal(session.reconnecting, timeout=TIMEOUT_MS) as blocker:
            nucleo.close()
        assert "waiting for the board" in blocker.args[0]
        assert session.device_info is not None  # the session is kept
        before = pipeline.counters.samples
        last_t = float(pipeline.samples.latest(1)["t"][0])

        # Hold the freed pty number so the board comes back under another port name, as a
        # USB device may after re-enumeration.
        squatter = os.openpty()
        try:
            with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS) as blocker:
                nucleo.replug()
        finally:
            for fd in squatter:
                os.close(fd)
        assert nucleo.port != first_port  # another port name, found by the USB serial
        assert blocker.args[0].unique_id == info.unique_id
        qtbot.waitUntil(lambda: pipeline.counters.samples > before + 150, timeout=TIMEOUT_MS)

        rows = pipeline.samples.latest(pipeline.counters.samples, ["t", "gap"])
        t = rows["t"]
        assert np.all(np.diff(t) > 0)  # no sample duplicated, time keeps running
        after = np.flatnonzero(t > last_t)
        assert rows["gap"][after[0]] == 1.0  # the outage is marked
        assert pipeline.counters.gaps >= 1
    finally:
        session.shutdown()
