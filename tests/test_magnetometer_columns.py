"""The magnetometer's columns from a device block to the file and back (format v1 extension)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from app.core.calibration import MagnetometerCalibration, SensorCalibration
from app.core.devices import DeviceInfo, MagnetometerInfo
from app.core.recording import (
    UNIT_SCALE,
    RecordingStream,
    RecordingWriter,
    read_recording,
    recording_metadata,
)
from app.core.recording.format import (
    KEY_MAGNETOMETER,
    calibration_from_json,
    calibration_to_json,
)
from app.core.samples import RawBlock, ScaleFactors, convert_raw_block, merge_raw_blocks
from drivers.replay import ReplayDevice, replay_url

BROAD = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "broad"
RATE_HZ = 200.0


def field_rows(n: int, every: int = 4) -> np.ndarray:
    """A field sample on every ``every``-th row (a slower magnetometer), NaN between."""
    mag = np.full((n, 3), np.nan)
    rows = np.arange(0, n, every)
    mag[rows] = np.column_stack([20.0 + rows, -5.0 - rows * 0.5, 40.0 + rows * 0.25])
    return mag


def mag_info() -> DeviceInfo:
    magnetometer = MagnetometerInfo("LIS3MDL", 155.0, 400.0, 100.0 / 6842, address=0x1C,
                                    mode="ultra-high-performance", path="bus")
    return DeviceInfo("sim://static", "Bench", "UID-1", "LSM6DSOX", RATE_HZ, 208.0, 4, 250,
                      magnetometer=magnetometer)


def write(path: Path, n: int = 300, block: int = 7, mag: bool = True) -> np.ndarray:
    t = np.arange(n) / RATE_HZ
    accel = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.full(n, 9.80665)])
    field = field_rows(n)
    info = mag_info() if mag else DeviceInfo("sim://static", "B", "U", "LSM6DSOX", RATE_HZ,
                                             208.0, 4, 250)
    writer = RecordingWriter(path, recording_metadata(device=info)).start()
    for start in range(0, n, block):
        rows = slice(start, start + block)
        writer.write(RawBlock(t[rows], accel[rows], np.zeros((len(t[rows]), 3)),
                              np.full(len(t[rows]), 25.0), UNIT_SCALE,
                              mag_raw=field[rows] if mag else None))
    assert writer.close().state == "stopped"
    return field


def test_a_recording_keeps_the_field_bit_for_bit_with_empty_rows_between(tmp_path):
    path = tmp_path / "mag.csv"
    field = write(path)
    recording = read_recording(path)
    assert recording.header[:10] == ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp", "gap",
                                     "block_start")
    assert recording.header[10:13] == ("mx", "my", "mz")
    assert recording.has_magnetometer
    np.testing.assert_array_equal(recording.mag_ut, field)  # NaN where no sample arrived
    assert recording.metadata["units"]["mx"] == "uT"
    settings = recording.metadata[KEY_MAGNETOMETER]
    assert settings["chip"] == "LIS3MDL" and settings["address"] == 0x1C
    assert settings["ut_per_lsb"] == pytest.approx(100.0 / 6842)
    # the file's text: an empty field between samples, as for an unknown reference
    lines = path.read_text().splitlines()
    body = [line for line in lines if not line.startswith("#")][1:]
    assert body[1].split(",")[10:13] == ["", "", ""]
    assert body[4].split(",")[10:13] == [repr(24.0), repr(-7.0), repr(41.0)]


def test_the_streamed_reader_and_the_replay_driver_carry_the_field(tmp_path):
    path = tmp_path / "mag.csv"
    field = write(path, n=40_000, block=500)
    with RecordingStream(path, chunk_bytes=65536) as stream:
        parts = [chunk.rows.mag_ut for chunk in stream.chunks()]
    assert len(parts) > 1
    np.testing.assert_array_equal(np.concatenate(parts), field)
    device = ReplayDevice(replay_url(path, speed=0))
    device.open()
    got = []
    try:
        while not device.at_end:
            block = device.read(0.5)
            if block is not None:
                assert block.mag_raw is not None
                got.append(convert_raw_block(block).mag_ut)
    finally:
        device.close()
    np.testing.assert_array_equal(np.concatenate(got), field)


def test_a_recording_without_a_magnetometer_has_no_field_columns(tmp_path):
    path = tmp_path / "plain.csv"
    write(path, mag=False)
    recording = read_recording(path)
    assert "mx" not in recording.header
    assert not recording.has_magnetometer and recording.mag_ut is None
    assert KEY_MAGNETOMETER not in recording.metadata
    assert next(recording.raw_blocks()).mag_raw is None


def test_joined_blocks_keep_the_field_and_blocks_without_one_stay_apart():
    scale = ScaleFactors(1.0, 1.0, mag_ut_per_lsb=0.15)
    def raw(t0: float, mag: bool) -> RawBlock:
        t = t0 + np.arange(3) / RATE_HZ
        return RawBlock(t, np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3), scale,
                        mag_raw=np.arange(9.0).reshape(3, 3) if mag else None)
    merged = merge_raw_blocks([raw(0, True), raw(1, True), raw(2, False)])
    assert [len(b) for b in merged] == [6, 3]
    assert merged[1].mag_raw is None
    np.testing.assert_allclose(convert_raw_block(merged[0]).mag_ut[3:],
                               np.arange(9.0).reshape(3, 3) * 0.15)


def test_the_magnetometer_calibration_applies_and_round_trips_through_json():
    soft = np.array([[1.02, 0.01, -0.02], [0.01, 0.97, 0.005], [-0.02, 0.005, 1.0]])
    mag_cal = MagnetometerCalibration(np.array([12.0, -3.0, 40.0]), soft, field_ut=49.5,
                                      dip_deg=64.2, fitness_ut=0.31, coverage=0.93,
                                      extra={"alignment_deg": 1.4})
    calibration = SensorCalibration(name="bench").with_magnetometer(mag_cal)
    assert not calibration.is_identity
    text = json.dumps(calibration_to_json(calibration))
    back = calibration_from_json(json.loads(text))
    assert back.magnetometer is not None
    np.testing.assert_array_equal(back.magnetometer.soft_iron, soft)
    assert back.magnetometer.extra == {"alignment_deg": 1.4}
    assert json.loads(text)["magnetometer"]["hard_iron_uT"] == [12.0, -3.0, 40.0]
    raw = RawBlock(np.arange(2.0), np.zeros((2, 3)), np.zeros((2, 3)), np.zeros(2),
                   UNIT_SCALE, mag_raw=np.array([[22.0, 7.0, 50.0], [np.nan] * 3]))
    out = back.apply(convert_raw_block(raw)).mag_ut
    np.testing.assert_allclose(out[0], soft @ np.array([10.0, 10.0, 10.0]))
    assert np.isnan(out[1]).all()


@pytest.mark.parametrize("bad, message", [
    ({"soft_iron": np.eye(3).tolist()}, "lacks 'hard_iron_uT'"),
    ({"hard_iron_uT": [0, 0], "soft_iron": np.eye(3).tolist()}, "is not (3,) finite"),
    ({"hard_iron_uT": [0, 0, 0], "soft_iron": np.zeros((3, 3)).tolist()}, "singular"),
    ({"hard_iron_uT": [0, 0, 0], "soft_iron": np.eye(3).tolist(), "field_uT": "x"},
     "'field_uT' is not a number"),
])
def test_a_malformed_magnetometer_calibration_is_refused_with_its_reason(bad, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        MagnetometerCalibration.from_json(bad)


@pytest.mark.skipif(not BROAD.is_dir(), reason="needs ../shared/datasets/broad beside the repo")
def test_a_broad_trial_reads_with_its_field():
    recording = read_recording(BROAD / "01_undisturbed_slow_rotation_A.csv")
    assert recording.has_magnetometer
    field = recording.mag_ut
    norms = np.linalg.norm(field[np.isfinite(field).all(axis=1)], axis=1)
    # the earth's field where BROAD was recorded (Berlin, about 49 uT), as the sensor reads it
    assert 35.0 < float(np.median(norms)) < 65.0
    assert math.isclose(recording.mag_ut[0, 1], 15.8218)
