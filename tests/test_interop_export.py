"""``inclinometer export``: MCAP read back with the mcap reader and its ROS 2 decoder, the
EuRoC/Kalibr CSV byte for byte, the NED conversion, and the safe output rules."""

from __future__ import annotations

import errno
import os

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from app.cli import main
from app.core import quaternion as quat
from app.core.interop import frames
from app.core.interop.euroc import EUROC_HEADER, readme_path
from app.core.interop.mcap_ros2 import (
    IMU_DEFINITION,
    IMU_SCHEMA,
    MAG_DEFINITION,
    MAG_SCHEMA,
    _message,
    cdr_records,
    imu_doubles,
)
from app.core.recording.export import run_filters
from app.core.recording.reader import read_recording


@pytest.fixture(scope="module")
def wobble_csv(tmp_path_factory):
    """A moving simulated sensor with a magnetometer (its field on some rows only)."""
    path = tmp_path_factory.mktemp("export") / "wobble.csv"
    assert main(["record", "--device", "sim://wobble?odr=104&seed=2&realtime=0&mag=lis3mdl",
                 "--duration", "3s", str(path)]) == 0
    return path


def read_mcap(path):
    """(summary, metadata {name: map}, {topic: [(log_time, decoded)]})."""
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
        messages: dict[str, list] = {}
        for _, channel, message, decoded in reader.iter_decoded_messages():
            messages.setdefault(channel.topic, []).append((message.log_time, decoded))
    return summary, metadata, messages


def test_mcap_reads_back_with_counts_time_span_values_and_metadata(wobble_csv, tmp_path,
                                                                    capsys):
    out = tmp_path / "wobble.mcap"
    assert main(["export", str(wobble_csv), "--format", "mcap", str(out), "--raw"]) == 0
    assert "Imu and" in capsys.readouterr().out
    recording = read_recording(wobble_csv)
    n = len(recording)
    summary, metadata, messages = read_mcap(out)
    counts = {summary.channels[c].topic: k
              for c, k in summary.statistics.channel_message_counts.items()}
    fresh = np.isfinite(recording.columns["mx"])
    assert counts == {"/imu/data": n, "/imu/mag": int(fresh.sum())}
    assert 0 < fresh.sum() < n  # the magnetometer is slower: only some rows
    t_ns = np.round(recording.t_s * 1e9).astype(np.int64)
    assert summary.statistics.message_start_time == t_ns[0]
    assert summary.statistics.message_end_time == t_ns[-1]
    imu = messages["/imu/data"]
    stamps = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in imu])
    np.testing.assert_array_equal(stamps, t_ns)
    np.testing.assert_array_equal([t for t, _ in imu], t_ns)
    assert {m.header.frame_id for _, m in imu} == {"imu_link"}
    gyro = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                     for _, m in imu])
    accel = np.array([[m.linear_acceleration.x, m.linear_acceleration.y,
                       m.linear_acceleration.z] for _, m in imu])
    np.testing.assert_array_equal(gyro, recording.gyro_rad_s)  # float64 both: exact
    np.testing.assert_array_equal(accel, recording.accel_m_s2)
    expected = run_filters(recording, [recording.filter_name], calibration=None)[0].quat
    got = np.array([[m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z]
                    for _, m in imu])
    np.testing.assert_allclose(got, expected, atol=1e-12)
    assert all(list(m.orientation_covariance) == [0.0] * 9 for _, m in imu)  # unknown
    mag = messages["/imu/mag"]
    field_ut = np.column_stack([recording.columns[c] for c in ("mx", "my", "mz")])[fresh]
    tesla = np.array([[m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z]
                      for _, m in mag])
    np.testing.assert_allclose(tesla, field_ut * 1e-6, rtol=1e-15)
    assert 20e-6 < np.linalg.norm(tesla, axis=1).mean() < 70e-6  # the earth's field, tesla
    export = metadata["inclinometer.export"]
    assert export["frame"] == "ENU" and "REP 103" in export["frame_convention"]
    assert export["frame_id"] == "imu_link" and "nanoseconds" in export["time_axis"]
    recorded = metadata["inclinometer.recording"]
    assert set(recorded) == set(recording.metadata)


def test_mcap_without_orientation_sets_covariance_element_0_to_minus_one(wobble_csv, tmp_path):
    out = tmp_path / "no-orientation.mcap"
    assert main(["export", str(wobble_csv), "--format", "mcap", str(out),
                 "--no-orientation"]) == 0
    _, metadata, messages = read_mcap(out)
    first = messages["/imu/data"][0][1]
    assert first.orientation_covariance[0] == -1.0 and first.orientation.w == 1.0
    assert metadata["inclinometer.export"]["orientation"] == "not given"


@pytest.mark.parametrize("frame_id", ["imu", "imu_link", "a_longer_frame_name"])
def test_block_encoder_gives_the_bytes_of_mcap_ros2_support(frame_id):
    rng = np.random.default_rng(len(frame_id))
    t_ns = np.array([0, 999_999_999, 1_000_000_000, 12_345_678_901_234])
    doubles = imu_doubles(rng.normal(size=(4, 3)), rng.normal(size=(4, 3)),
                          quat.normalize(rng.normal(size=(4, 4))))
    for kind, definition, values in ((IMU_SCHEMA, IMU_DEFINITION, doubles),
                                     (MAG_SCHEMA, MAG_DEFINITION, rng.normal(size=(4, 12)))):
        encode = serialize_dynamic(kind, definition)[kind]
        records = cdr_records(frame_id, t_ns, values)
        for stamp, row, data in zip(t_ns.tolist(), values, records, strict=True):
            assert bytes(encode(_message(kind, frame_id, stamp, row.tolist()))) == data


def test_euroc_csv_is_kalibrs_layout_exactly(wobble_csv, tmp_path):
    out = tmp_path / "imu0.csv"
    assert main(["export", str(wobble_csv), "--format", "euroc", str(out), "--raw"]) == 0
    recording = read_recording(wobble_csv)
    lines = out.read_text().splitlines()
    assert lines[0] == EUROC_HEADER == (
        "timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y,w_RS_S_z,a_RS_S_x [m s^-2],a_RS_S_y,"
        "a_RS_S_z")
    rows = [line.split(",") for line in lines[1:]]
    assert len(rows) == len(recording) and {len(r) for r in rows} == {7}
    # Kalibr's bag creator: int(text[0:-9]) seconds, int(text[-9:]) nanoseconds.
    for row, t in zip(rows, recording.t_s, strict=True):
        assert row[0].isdigit() and len(row[0]) >= 10
        assert int(row[0][:-9]) * 10**9 + int(row[0][-9:]) == round(t * 1e9)
    values = np.array([[float(v) for v in row[1:]] for row in rows])
    np.testing.assert_array_equal(values[:, :3], recording.gyro_rad_s)  # shortest repr: exact
    np.testing.assert_array_equal(values[:, 3:], recording.accel_m_s2)
    readme = readme_path(out).read_text()
    assert readme_path(out).name == "imu0.README.txt"
    assert "frame: ENU" in readme and "wobble.csv" in readme and "as measured" in readme


def test_ned_conversion_of_vectors_and_orientation():
    rng = np.random.default_rng(3)
    q = quat.normalize(rng.normal(size=(50, 4)))
    v = rng.normal(size=(50, 3))
    earth_enu = quat.rotate(q, v)
    earth_ned = quat.rotate(frames.orientation("ned", q), frames.body_vectors("ned", v))
    np.testing.assert_allclose(earth_ned, earth_enu[:, [1, 0, 2]] * [1, 1, -1], atol=1e-12)
    # A level sensor: +g up in ENU, -g on z (down) in NED's forward-right-down body frame.
    np.testing.assert_allclose(frames.body_vectors("ned", [[0.0, 0.0, 9.81]]), [[0, 0, -9.81]])
    # Identity in ENU (body x east): in NED body x still points east, the NED y axis.
    level = frames.orientation("ned", quat.IDENTITY[None])
    np.testing.assert_allclose(quat.rotate(level, np.array([[1.0, 0.0, 0.0]])), [[0, 1, 0]],
                               atol=1e-15)
    np.testing.assert_allclose(quat.rotate(level, np.array([[0.0, 0.0, 1.0]])), [[0, 0, 1]],
                               atol=1e-15)  # body down (FRD z) = NED down
    with pytest.raises(ValueError, match="enu, ned"):
        frames.check_frame("nwu")


def test_mcap_in_ned_holds_the_enu_export_converted(wobble_csv, tmp_path):
    enu, ned = tmp_path / "enu.mcap", tmp_path / "ned.mcap"
    assert main(["export", str(wobble_csv), "--format", "mcap", str(enu)]) == 0
    assert main(["export", str(wobble_csv), "--format", "mcap", str(ned), "--frame", "ned"]) == 0
    _, meta_enu, enu_messages = read_mcap(enu)
    assert meta_enu["inclinometer.export"]["frame"] == "ENU"
    _, meta_ned, ned_messages = read_mcap(ned)
    assert meta_ned["inclinometer.export"]["frame"] == "NED"
    for (_, a), (_, b) in zip(enu_messages["/imu/data"], ned_messages["/imu/data"],
                              strict=True):
        assert (b.linear_acceleration.y, b.linear_acceleration.z) == (
            -a.linear_acceleration.y, -a.linear_acceleration.z)
        q_enu = np.array([a.orientation.w, a.orientation.x, a.orientation.y, a.orientation.z])
        q_ned = np.array([b.orientation.w, b.orientation.x, b.orientation.y, b.orientation.z])
        np.testing.assert_allclose(q_ned, frames.orientation("ned", q_enu), atol=1e-15)
    b = ned_messages["/imu/mag"][0][1]
    a = enu_messages["/imu/mag"][0][1]
    assert (b.magnetic_field.x, b.magnetic_field.y, b.magnetic_field.z) == (
        a.magnetic_field.x, -a.magnetic_field.y, -a.magnetic_field.z)


def test_existing_output_is_refused_without_overwrite_or_force(wobble_csv, tmp_path, capsys):
    out = tmp_path / "imu0.csv"
    out.write_text("keep me\n")
    assert main(["export", str(wobble_csv), "--format", "euroc", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "exists; pass --overwrite" in err
    assert out.read_text() == "keep me\n" and not readme_path(out).exists()
    assert main(["export", str(wobble_csv), "--format", "euroc", str(out), "--force"]) == 0
    assert out.read_text().startswith("timestamp [ns]")
    assert main(["export", str(wobble_csv), "--format", "euroc", str(out), "--overwrite"]) == 0
    assert main(["export", str(wobble_csv), "--format", "euroc", str(wobble_csv),
                 "--force"]) == 2
    assert "recording itself" in capsys.readouterr().err


def test_a_bad_recording_gets_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("this is not a recording\n1,2,3\n")
    assert main(["export", str(bad), "--format", "mcap", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("inclinometer") and err.count("\n") == 0
    assert not (tmp_path / "x.mcap").exists()


class FullDisk:
    """A file on a disk with ``free`` bytes left: then ENOSPC, as write(2) gives."""

    def __init__(self, handle, free: int) -> None:
        self.handle, self.free = handle, free

    def write(self, data) -> int:
        if len(data) > self.free:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.free -= len(data)
        return self.handle.write(data)

    def __getattr__(self, name):
        return getattr(self.handle, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.handle.close()


@pytest.mark.parametrize("fmt", ["mcap", "euroc"])
def test_a_full_disk_leaves_nothing_and_says_so(wobble_csv, tmp_path, monkeypatch, capsys, fmt):
    import app.core.safe_output as safe_output

    real = os.fdopen
    monkeypatch.setattr(safe_output.os, "fdopen",
                        lambda fd, mode: FullDisk(real(fd, mode), free=3000))
    out = tmp_path / f"imu0.{'csv' if fmt == 'euroc' else 'mcap'}"
    assert main(["export", str(wobble_csv), "--format", fmt, str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert "No space left on device" in err and err.count("\n") == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no target, no temporary file


def test_an_offline_filter_is_refused_with_the_choice(wobble_csv, tmp_path, capsys):
    assert main(["export", str(wobble_csv), "--format", "mcap", str(tmp_path / "s.mcap"),
                 "--filter", "ekf-smoother"]) == 2
    assert "offline smoother" in capsys.readouterr().err
    assert not (tmp_path / "s.mcap").exists()


def test_metadata_values_are_strings_and_json_has_no_nan():
    from app.core.interop.mcap_ros2 import metadata_strings

    values = metadata_strings({"note": "text", "odr_hz": 104.0, "bias": [0.1, float("nan")],
                               "nested": {"k": float("inf")}})
    assert values == {"note": "text", "odr_hz": "104.0", "bias": "[0.1, null]",
                      "nested": '{"k": null}'}
