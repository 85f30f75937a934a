"""Sessions with several sensors: one v1 file each, a manifest, synchronized replay."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.core.recording.reader import read_recording
from app.core.recording.session import (
    JointConfig,
    SessionManifestError,
    SessionSensor,
    load_session,
    write_session,
)
from app.services.joint_stream import JointStream
from app.services.sensor_group import SensorGroup
from app.services.session_replay import SessionReplay

ARM = "sim://arm?seed=3&odr=104&speed=10"


@pytest.fixture
def group(qtbot):
    group = SensorGroup()
    yield group
    group.shutdown()


def record(qtbot, group: SensorGroup, directory: Path, urls: list[str], seconds: float
           ) -> Path:
    for url in urls:
        group.add(url)
    qtbot.waitUntil(lambda: group.connected_count() == len(urls), timeout=15000)
    manifest = group.start_recording(directory, "arm",
                                     joints=[JointConfig(0, 1)], note="two links")
    # every sensor, not just the first, for ``seconds``: under load one worker thread can
    # starve for a moment, and at 10x speed 0.1 s of host time is a second of device time (a
    # member with under 2 s of clock pairs gets no drift fit: its map is off tenfold)
    buffers = [group.pipeline(k).samples for k in range(len(urls))]
    starts = [b.total_written for b in buffers]
    qtbot.waitUntil(lambda: all(b.total_written - s > seconds * 104
                                for b, s in zip(buffers, starts, strict=True)), timeout=15000)
    with qtbot.waitSignal(group.sessionRecorded, timeout=10000) as written:
        group.stop_recording()
    assert written.args == [str(manifest)]
    return manifest


def test_a_recorded_session_is_one_v1_file_per_sensor_and_a_manifest(qtbot, group,
                                                                     tmp_path) -> None:
    manifest = record(qtbot, group, tmp_path, [ARM, ARM + "&sensor=1"], 3.0)
    document = json.loads(manifest.read_text())
    assert document["format"] == "inclinometer-session" and document["version"] == 1
    session = load_session(manifest)
    assert [p.name for p in session.paths] == ["arm-sensor0.csv", "arm-sensor1.csv"]
    assert session.roles == ["link 0 (base)", "link 1"]
    assert session.joints == (JointConfig(0, 1, None),)
    assert session.note == "two links" and session.created.endswith("Z")
    # One arm, one clock: the same time map for both files.
    a, b = session.sensors
    assert a.shared_clock and b.shared_clock
    assert (a.offset_s, a.scale) == (b.offset_s, b.scale)
    # Each file is an ordinary v1 recording on its own.
    recordings = [read_recording(p) for p in session.paths]
    assert all(len(r) > 250 for r in recordings)
    assert recordings[1].device["url"].endswith("sensor=1")


def test_replaying_a_manifest_keeps_the_sensors_in_sync(qtbot, group, tmp_path) -> None:
    manifest = record(qtbot, group, tmp_path,
                      [ARM, ARM + "&sensor=1&clock_offset=7.5&clock_ppm=2000"], 3.0)
    session = load_session(manifest)
    assert not session.sensors[1].shared_clock
    replay = SessionReplay(session)
    # The manifest's time maps put sensor 1's clock 7.5 s ahead of sensor 0's (2000 ppm fast:
    # too little to see in a session this short, so within what receive jitter allows). The
    # devices run at 10x speed, so the host's receive jitter counts ten times in device time:
    # 15 ms of it (a loaded 2-core machine running three test processes) is 0.15 s here.
    t0 = replay.recordings[0].t_s[[0, -1]]
    assert np.allclose(replay.to_member_clock(0, 1, t0), t0 * (1 + 2000e-6) + 7.5, atol=0.15)
    period = 1.0 / 104.0 / 10.0 * 1.05  # one sample of the 10x-speed device, on the host
    position = replay.start_s
    checked = 0
    while not replay.finished:
        position += 0.037
        replay.advance_to(position)
        newest = [p.samples.latest(1)["t"] for p in replay.pipelines]
        last = min(float(replay.to_common(k, r.t_s[-1:])[0])
                   for k, r in enumerate(replay.recordings))
        if all(len(t) for t in newest) and position < last:
            common = [float(replay.to_common(k, t)[0]) for k, t in enumerate(newest)]
            # Both files have reached the replay clock, and neither ran ahead of it.
            assert all(position - period - 0.01 <= c <= position for c in common)
            checked += 1
    assert checked > 5
    # Matching samples: sensor 1's times put on sensor 0's clock land on sensor 0's times.
    t0 = replay.recordings[0].t_s
    t1_on_0 = replay.to_member_clock(1, 0, replay.recordings[1].t_s)
    inside = (t1_on_0 > t0[0]) & (t1_on_0 < t0[-1])
    nearest = np.abs(t0[np.searchsorted(t0, t1_on_0[inside]).clip(0, len(t0) - 1)]
                     - t1_on_0[inside])
    assert np.median(np.minimum(nearest, 1 / 104 - nearest)) < 0.1 / 104 + 0.02


def test_the_joint_angle_of_a_replayed_session(qtbot, group, tmp_path) -> None:
    manifest = record(qtbot, group, tmp_path, [ARM, ARM + "&sensor=1"], 3.0)
    replay = SessionReplay(manifest)
    stream = JointStream(replay, 0, 1)
    for _ in range(20):
        replay.advance_to(replay.position_s + 0.5)
        stream.step()
    # Every sample of the first file within the second's span, on the manifest's shared clock,
    # found its partner (the files start and stop a few samples apart: each session starts its
    # own writer). The span is taken on that clock, as the stream takes it: the offsets fitted
    # while recording are not exactly 0, and a sample on the span's very edge would otherwise
    # count on one side and not the other.
    ta = replay.recordings[0].t_s
    tb = replay.to_member_clock(1, 0, replay.recordings[1].t_s)
    inside = (ta >= tb[0]) & (ta <= tb[-1])
    assert len(stream.angles) == int(np.count_nonzero(inside)) > 250
    assert np.array_equal(stream.angles.latest(len(stream.angles))["device_t"], ta[inside])


def test_bad_manifests_get_clear_messages(tmp_path) -> None:
    (tmp_path / "a.csv").write_text("x")
    good = write_session(tmp_path / "s.session.json",
                         [SessionSensor("a.csv", "link 0 (base)"),
                          SessionSensor("a.csv", "link 1", offset_s=2.0)],
                         [JointConfig(0, 1, ((0, 0, 2), (1, 0, 0)))])
    session = load_session(good)
    assert session.joints[0].axes == ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0))
    assert session.sensors[1].to_common(np.array([1.0]))[0] == 3.0
    cases = {
        "not JSON": "{",
        "not a session manifest": json.dumps({"format": "other"}),
        "version 2": json.dumps({"format": "inclinometer-session", "version": 2}),
        "is missing": json.dumps({"format": "inclinometer-session", "version": 1,
                                  "sensors": [{"file": "gone.csv"}]}),
        "sensors 0 to 0": json.dumps({"format": "inclinometer-session", "version": 1,
                                      "sensors": [{"file": "a.csv"}],
                                      "joints": [{"sensors": [0, 1]}]}),
    }
    for expected, text in cases.items():
        path = tmp_path / "bad.session.json"
        path.write_text(text)
        with pytest.raises(SessionManifestError, match=expected):
            load_session(path)


# -- inclinometer joint MANIFEST ----------------------------------------------------------------
def _shift_t(source: Path, target: Path, seconds: float) -> None:
    """A copy of a v1 file whose clock reads ``seconds`` more (another device's clock)."""
    lines = source.read_text(encoding="utf-8").splitlines(keepends=True)
    header_at = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    column = lines[header_at].strip().split(",").index("t")
    out = lines[:header_at + 1]
    for line in lines[header_at + 1:]:
        fields = line.rstrip("\n").split(",")
        fields[column] = repr(float(fields[column]) + seconds)
        out.append(",".join(fields) + "\n")
    target.write_text("".join(out), encoding="utf-8")


def _joint_column(path: Path) -> np.ndarray:
    rows = [line for line in path.read_text().splitlines() if not line.startswith("#")][1:]
    return np.array([float(r.split(",")[1]) if r.split(",")[1] else np.nan for r in rows])


def test_cli_joint_takes_a_manifest_and_applies_its_time_maps(tmp_path, capsys) -> None:
    from app import cli
    from app.services.arm_recordings import record_arm

    record_arm("sim://arm?odr=104&seed=5", 20.0, tmp_path)
    _shift_t(tmp_path / "sensor1.csv", tmp_path / "shifted1.csv", 5.0)
    manifest = write_session(tmp_path / "arm.session.json",
                             [SessionSensor("sensor0.csv", "link 0 (base)"),
                              SessionSensor("shifted1.csv", "link 1", offset_s=-5.0)],
                             [JointConfig(0, 1)])
    direct, via = tmp_path / "direct.csv", tmp_path / "via.csv"
    assert cli.main(["joint", str(tmp_path / "sensor0.csv"), str(tmp_path / "sensor1.csv"),
                     "--out", str(direct)]) == 0
    assert cli.main(["joint", str(manifest), "--out", str(via)]) == 0
    assert "axis in A:" in capsys.readouterr().out
    a, b = _joint_column(direct), _joint_column(via)
    assert len(a) == len(b) > 1000 and np.isfinite(a).sum() > 1000
    np.testing.assert_allclose(b, a, atol=1e-6, equal_nan=True)
    # Bad use gets a clear message.
    assert cli.main(["joint", str(manifest), str(tmp_path / "sensor0.csv"),
                     "--out", str(tmp_path / "x.csv")]) == 2
    assert "manifest alone" in capsys.readouterr().err
    assert cli.main(["joint", str(tmp_path / "sensor0.csv"), "--out",
                     str(tmp_path / "x.csv")]) == 2
    assert "session manifest" in capsys.readouterr().err
