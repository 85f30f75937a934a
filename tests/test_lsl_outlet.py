"""The Lab Streaming Layer outlet (issue 34, item 4): a pylsl inlet in the same test receives
the session's samples and orientation, none lost, with the device's aligned timestamps."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from app.cli import main
from app.core.clock_alignment import MIN_DRIFT_SPAN_S, ClockAligner
from app.core.devices import DeviceInfo
from app.core.pipeline import Pipeline
from app.core.recording.reader import read_recording
from app.core.samples import RawBlock, ScaleFactors, convert_raw_block
from app.services.acquisition import Acquisition, Block, Subscriber, Until
from app.services.connection import Connection
from app.services.lsl_outlet import LslOutlet, source_id
from app.services.recorder import warm_up_kernels

LOOPBACK_CONFIG = """[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
[lab]
KnownPeers = {127.0.0.1}
"""
"""liblsl on this machine alone: discovery and data on 127.0.0.1 (the tests send nothing to
any other address)."""


@pytest.fixture(scope="module", autouse=True)
def loopback_lsl(tmp_path_factory):
    config = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    config.write_text(LOOPBACK_CONFIG)
    before = os.environ.get("LSLAPICFG")
    os.environ["LSLAPICFG"] = str(config)  # read by liblsl at its first stream
    yield
    if before is None:
        os.environ.pop("LSLAPICFG", None)
    else:
        os.environ["LSLAPICFG"] = before


class Collect(Subscriber):
    def __init__(self) -> None:
        self.blocks = []

    def on_block(self, block) -> None:
        self.blocks.append(block.samples)


def inlet_for(sid: str):
    import pylsl

    found = pylsl.resolve_byprop("source_id", sid, 1, 5.0)
    assert found, f"no LSL stream {sid}"
    inlet = pylsl.StreamInlet(found[0], max_buflen=60)
    inlet.open_stream(5.0)
    return inlet


def pull_all(inlet, expected: int, timeout_s: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    data, stamps = [], []
    deadline = time.monotonic() + timeout_s
    while sum(len(s) for s in stamps) < expected and time.monotonic() < deadline:
        chunk, times = inlet.pull_chunk(timeout=0.2, max_samples=100_000)
        if times:
            data.append(np.asarray(chunk))
            stamps.append(np.asarray(times))
    # Anything more would be a duplicate: give it a moment to show up.
    chunk, times = inlet.pull_chunk(timeout=0.05)
    assert not times
    return np.vstack(data), np.concatenate(stamps)


def test_inlet_receives_every_sample_and_the_orientation_on_the_aligned_clock():
    session = Acquisition(Connection(), Pipeline(), detect_faults=False)
    info = session.open("sim://wobble?realtime=0&odr=416&block=100&mag=lis3mdl&seed=3")
    # A known mapping device -> host: 1000 s offset, the device 50 ppm slow.
    aligner = ClockAligner()
    for device_t in (0.0, 20.0, 40.0):  # within the aligner's 60 s window
        aligner.add(device_t, 1000.0 + 1.00005 * device_t)
    seen = session.subscribe(Collect())
    outlet = session.subscribe(LslOutlet(lambda: session.connection.device.info,
                                         session.pipeline, aligner))
    imu_inlet = inlet_for(source_id(info, "imu"))
    quat_inlet = inlet_for(source_id(info, "orientation"))
    stream_info = imu_inlet.info()
    channels = stream_info.desc().child("channels").child("channel")
    labels = []
    while not channels.empty():
        labels.append((channels.child_value("label"), channels.child_value("unit")))
        channels = channels.next_sibling()
    assert labels[0] == ("ax", "m/s^2") and labels[3] == ("gx", "rad/s")
    assert labels[6:] == [("mx", "uT"), ("my", "uT"), ("mz", "uT")]
    assert stream_info.desc().child("device").child_value("unique_id") == info.unique_id

    end = session.run(Until(samples=3000))
    session.close()
    assert end.samples == 3000 == outlet.counts.imu_samples == outlet.counts.orientation_samples

    data, stamps = pull_all(imu_inlet, 3000)
    quats, quat_stamps = pull_all(quat_inlet, 3000)
    outlet.close()
    t = np.concatenate([b.t_s for b in seen.blocks])
    sent = np.hstack([np.concatenate([b.accel_m_s2 for b in seen.blocks]),
                      np.concatenate([b.gyro_rad_s for b in seen.blocks]),
                      np.concatenate([b.mag_ut for b in seen.blocks])])
    assert data.shape == (3000, 9)
    np.testing.assert_array_equal(data, sent)  # double64: every bit, NaN where no field
    assert np.isnan(data[:, 6]).any() and (~np.isnan(data[:, 6])).any()
    expected = 1000.0 + 1.00005 * t + outlet.clock_offset_s
    np.testing.assert_allclose(stamps, expected, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(quat_stamps, stamps)
    np.testing.assert_array_equal(quats, session.pipeline.orientation.latest(3000)["quat"])
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-9)


def test_a_fast_live_source_is_stamped_on_its_own_clock_fit_without_loss():
    """A simulator running 50x faster than the wall clock (a time lapse): 20 s of device time
    at 833 Hz in 0.4 s; the outlet fits the clock itself from the blocks' receive times."""
    import pylsl

    warm_up_kernels(None)  # the filter compiled before the live clock runs
    session = Acquisition(Connection(), Pipeline(), detect_faults=False)
    info = session.open("sim://static?odr=833&speed=50&seed=5")
    outlet = session.subscribe(LslOutlet(lambda: session.connection.device.info,
                                         session.pipeline))
    inlet = inlet_for(source_id(info, "imu"))
    # Finding the stream took a while, and the time lapse ran on meanwhile: open the same
    # device again (the same identity keeps its streams), now with the inlet connected.
    session.close()
    assert session.open(info.url).unique_id == info.unique_id
    seen = session.subscribe(Collect())
    start = pylsl.local_clock()
    end = session.run(Until(duration_s=20.0, wall_s=30.0))
    session.close()
    stop = pylsl.local_clock()
    sent = sum(len(b) for b in seen.blocks)
    assert end.reason == "duration" and sent == outlet.counts.imu_samples > 15_000
    data, stamps = pull_all(inlet, sent)
    outlet.close()
    assert len(stamps) == sent and outlet.counts.streams_opened == 1
    np.testing.assert_array_equal(data[:, :3], np.concatenate([b.accel_m_s2 for b in seen.blocks]))
    assert np.all(np.diff(stamps) > 0)
    t = np.concatenate([b.t_s for b in seen.blocks])
    fit = outlet.aligner.fit()
    assert fit is not None and fit.scale == pytest.approx(0.02, rel=0.05)  # the time lapse
    # Each sample is stamped when it was measured, on the final fit within the receive jitter,
    # once the fit spans the 2 s of device time it needs for a rate (before that it takes the
    # clocks' rates as equal, as a real device's are to some ppm: not this time lapse's).
    final = np.asarray(fit.to_host(t)) + outlet.clock_offset_s
    fitted = t > t[0] + 2 * MIN_DRIFT_SPAN_S
    assert fitted.sum() > 10_000
    # The jitter bound is the receive times' own spread above the envelope (a few ms on an idle
    # machine, more when other processes hold the cores while blocks arrive).
    jitter_s = max(0.02, 3e-3 * fit.spread_ms)
    assert np.max(np.abs(stamps - final)[fitted]) < jitter_s
    assert start - 0.05 < stamps[fitted][0] and stamps[-1] < stop + 0.05


def test_record_lsl_streams_what_it_records(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert main(["record", "--device", "sim://static?realtime=0&odr=208", "--duration", "2",
                 "--lsl", "--quiet", str(out)]) == 0
    rows = len(read_recording(out))
    assert f"LSL: {rows} samples and {rows} orientations sent" in capsys.readouterr().out


def test_a_jump_in_device_time_starts_the_clock_fit_afresh():
    """A replay's seek (or an outage) puts the device clock elsewhere: the pairs before it
    would bend the fit, so the outlet's own alignment starts again from the new block."""
    info = DeviceInfo("replay:///x.csv", "x", "JUMP-1", "LSM6DSOX", 100.0, 104.0, 4, 250)
    outlet = LslOutlet(lambda: info)

    def block(t0: float, received: float) -> Block:
        t = t0 + np.arange(50) / 100.0
        raw = RawBlock(t, np.zeros((50, 3)), np.zeros((50, 3)), np.zeros(50),
                       ScaleFactors(1.0, 1.0))
        samples = convert_raw_block(raw)
        return Block(raw, samples, samples, received)

    try:
        outlet.on_block(block(0.0, 100.5))
        outlet.on_block(block(0.5, 101.0))
        assert len(outlet.aligner) == 2
        outlet.on_block(block(30.0, 101.5))  # 29.5 s further on: a seek
        assert len(outlet.aligner) == 1
        fit = outlet.aligner.fit()
        assert fit.to_host(30.49) == pytest.approx(101.5)
        assert outlet.counts.imu_samples == 150 and outlet.counts.orientation_samples == 0
    finally:
        outlet.close()
