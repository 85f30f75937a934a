"""``inclinometer calibrate``: the wizard's procedures on recorded streams of the simulator.

Recordings are made with ``inclinometer record`` (a six-face tour) or assembled from the
simulator's still poses (free orientations); the result is checked against the simulated
unit's true errors and on poses the fit never saw.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from app.cli import main
from app.core.calibration_procedures import ProfileStore
from app.core.orientation import up_in_sensor_frame
from app.core.recording.format import calibration_from_json, metadata_text, simulator_metadata
from app.core.recording.reader import read_recording
from app.core.recording.writer import format_rows
from app.core.samples import STANDARD_GRAVITY_M_S2, convert_raw_block
from drivers.registry import open_device

SEED = 7
TOUR = f"sim://tour?odr=52&seed={SEED}&realtime=0"
BINDING_KEYS = {"accel_bias_m_s2": (3,), "accel_matrix": (3, 3), "gyro_bias_rad_s": (3,),
                "gyro_matrix": (3, 3)}


@pytest.fixture(scope="module")
def tour_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("tour") / "tour.csv"
    assert main(["record", "--device", TOUR, "--duration", "50", str(path)]) == 0
    return path


def _truth(path):
    unit = read_recording(path).metadata["simulator"]["unit_errors"]
    return {key: np.asarray(value) for key, value in unit.items() if isinstance(value, list)}


def _independent_poses(calibration, seed=SEED):
    """Tilt errors of ``calibration`` on still poses that were not in the fit."""
    errors = []
    for roll, pitch in [(0, 0), (60, 0), (0, -60), (-42, 42), (30, 30), (-20, -55)]:
        dev = open_device(f"sim://static?roll={roll}&pitch={pitch}&odr=52&realtime=0"
                          f"&block=104&seed={seed}")
        try:
            block = convert_raw_block(dev.read(1.0))
        finally:
            dev.close()
        mean = calibration.apply(block).accel_m_s2.mean(axis=0)
        up = up_in_sensor_frame(block.reference_quat[0])
        errors.append(math.degrees(math.acos(min(1.0, mean @ up / np.linalg.norm(mean)))))
    return np.array(errors)


def test_six_position_on_a_recorded_tour_recovers_the_true_unit(tour_csv, tmp_path, capsys):
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(tour_csv), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "6 poses accepted, 0 rejected" in printed
    assert "against the simulator's true unit errors" in printed
    document = json.loads(out.read_text())
    for key, shape in BINDING_KEYS.items():
        assert np.asarray(document[key]).shape == shape, key
    # The recording format's convention: a_cal = A (a_raw - b_a).
    calibration = calibration_from_json(document)
    truth = _truth(tour_csv)
    np.testing.assert_allclose(calibration.accel_bias_m_s2, truth["accel_bias_m_s2"],
                               atol=0.1e-3 * STANDARD_GRAVITY_M_S2)  # 0.1 mg (temperature)
    true_m = (np.eye(3) + np.diag(truth["accel_scale_error"])) @ (
        np.eye(3) + truth["accel_cross_axis"])
    np.testing.assert_allclose(np.linalg.inv(calibration.accel_matrix), true_m, atol=2e-4)
    np.testing.assert_allclose(np.degrees(calibration.gyro_bias_rad_s),
                               np.degrees(truth["gyro_bias_rad_s"]), atol=0.01)
    np.testing.assert_array_equal(calibration.gyro_matrix, np.eye(3))
    assert [p["face"] for p in document["poses"]] == ["+z", "-z", "+x", "-x", "+y", "-y"]
    assert max(p["tilt_error_after_deg"] for p in document["poses"]) < 0.01
    assert max(p["tilt_error_before_deg"] for p in document["poses"]) > 0.3
    # On poses the fit never saw:
    assert _independent_poses(calibration).max() < 0.05


def test_save_stores_the_profile_of_the_recorded_device(tour_csv, tmp_path, capsys):
    profiles = tmp_path / "profiles"
    assert main(["calibrate", str(tour_csv), "--save", "--profile-dir", str(profiles)]) == 0
    unique_id = read_recording(tour_csv).device["unique_id"]
    assert f"saved as the profile of device {unique_id}" in capsys.readouterr().out
    profile = ProfileStore(profiles).load(unique_id)
    assert profile.method == "six-position"
    assert profile.residuals["poses"] == 6
    assert profile.settings.accel_fs_g == 4
    assert _independent_poses(profile.calibration).max() < 0.05


def _write_free_poses(path, directions, seed=SEED, seconds=5.0, odr=52):
    """A recording of the simulated unit resting in each direction, gaps in between."""
    blocks, device, info = [], None, None
    for k, up in enumerate(directions):
        up = np.asarray(up, float) / np.linalg.norm(up)
        pitch = math.degrees(math.asin(up[0]))
        roll = math.degrees(math.atan2(up[1], up[2]))
        dev = open_device(f"sim://static?roll={roll:.4f}&pitch={pitch:.4f}&odr={odr}"
                          f"&realtime=0&block={round(seconds * odr)}&seed={seed}")
        info = info or dev.info
        try:
            block = convert_raw_block(dev.read(1.0))
        finally:
            dev.close()
        device = device or dev
        block.t_s = block.t_s + 10.0 * k
        block.gap = np.zeros(len(block), bool)
        block.gap[0] = k > 0
        blocks.append(block)
    metadata = {"device": {"unique_id": info.unique_id, "odr_hz": info.odr_hz,
                           "accel_fs_g": info.accel_fs_g, "gyro_fs_dps": info.gyro_fs_dps},
                **simulator_metadata(device)}
    columns = ["t", "ax", "ay", "az", "gx", "gy", "gz", "temp", "gap", "qw", "qx", "qy", "qz"]
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(metadata_text(metadata))
        handle.write(",".join(columns) + "\n")
        for block in blocks:
            handle.write(format_rows(block, columns, block_start=False))


def _sphere(n):
    """``n`` directions spread over the sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * i
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def test_free_method_on_fourteen_orientations(tmp_path, capsys):
    path = tmp_path / "free.csv"
    _write_free_poses(path, _sphere(14))
    out = tmp_path / "free.json"
    assert main(["calibrate", str(path), "--method", "free", "--out", str(out)]) == 0
    assert "14 poses accepted" in capsys.readouterr().out
    document = json.loads(out.read_text())
    assert document["method"] == "free"
    calibration = calibration_from_json(document)
    truth = _truth(path)
    np.testing.assert_allclose(calibration.accel_bias_m_s2, truth["accel_bias_m_s2"],
                               atol=0.5e-3 * STANDARD_GRAVITY_M_S2)
    # |a| is 1 g after calibration; the frame's rotation stays (see accel_fit's docstring).
    assert document["fit"]["residual_norm_rms_mg"] < 0.1
    before = _independent_poses(calibration_from_json(
        {**document, "accel_bias_m_s2": [0, 0, 0], "accel_matrix": np.eye(3).tolist()}))
    assert _independent_poses(calibration).max() < before.max()


def test_free_method_on_a_tour_has_too_few_poses(tour_csv, tmp_path, capsys):
    out = tmp_path / "x.json"
    assert main(["calibrate", str(tour_csv), "--method", "free", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "too few poses" in err and "6 of 12" in err
    assert not out.exists()


def test_a_face_missing_is_named(tmp_path, capsys):
    path = tmp_path / "short.csv"
    assert main(["record", "--device", TOUR, "--duration", "30", str(path)]) == 0
    capsys.readouterr()
    assert main(["calibrate", str(path), "--out", str(tmp_path / "x.json")]) == 1
    err = capsys.readouterr().err
    assert "faces missing for the six-position fit: +y, -y" in err
    assert "captured: +z, -z, +x, -x" in err


def test_motion_everywhere_is_refused(tmp_path, capsys):
    path = tmp_path / "wobble.csv"
    assert main(["record", "--device", "sim://wobble?odr=52&realtime=0", "--duration", "10",
                 str(path)]) == 0
    capsys.readouterr()
    assert main(["calibrate", str(path), "--out", str(tmp_path / "x.json")]) == 1
    assert "motion everywhere" in capsys.readouterr().err


def test_a_live_device_for_n_seconds(tmp_path, capsys):
    out = tmp_path / "live.json"
    assert main(["calibrate", "--device", "sim://tour?odr=52&seed=3&realtime=0",
                 "--seconds", "50", "--out", str(out)]) == 0
    assert "6 poses accepted" in capsys.readouterr().out
    assert json.loads(out.read_text())["device_unique_id"].startswith("SIM-")


@pytest.mark.parametrize("argv, message", [
    (["calibrate", "missing.csv", "--out", "x.json"], "no such file"),
    (["calibrate", "--device", "sim://tour"], "--out FILE.json, --save and/or"),
    (["calibrate", "--device", "sim://tour", "--out", "x.json"], "--seconds"),
    (["calibrate", "--device", "nosuch://x", "--seconds", "5", "--out", "x.json"], "nosuch"),
])
def test_usage_errors_exit_2(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("suffix", [".html", ".pdf"])
def test_report_from_calibrate(tour_csv, tmp_path, suffix, qapp, artifacts_dir, capsys):
    path = tmp_path / f"report{suffix}"
    assert main(["calibrate", str(tour_csv), "--report", str(path)]) == 0
    assert f"wrote the report {path}" in capsys.readouterr().out
    data = path.read_bytes()
    unique_id = read_recording(tour_csv).device["unique_id"]
    if suffix == ".pdf":
        assert data.startswith(b"%PDF") and len(data) > 10_000
        return
    text = data.decode("utf-8")
    for needle in (unique_id, "Accelerometer bias", "Gyroscope bias", "±", "+z up", "-y up",
                   "Against the simulator's truth", "data:image/png;base64,", "°C"):
        assert needle in text, needle
    # The preview is the document the PDF prints.
    from app.core.calibration_procedures import SensorSettings, make_profile
    from app.core.calibration_procedures.offline import calibrate_stream
    from app.documents.calibration_report import render_preview, report_from_offline

    recording = read_recording(tour_csv)
    d = recording.device
    result = calibrate_stream(recording.sample_block(),
                              SensorSettings(d["odr_hz"], d["accel_fs_g"], d["gyro_fs_dps"]))
    profile = make_profile(unique_id, result.calibration, result.settings,
                           method=result.fit.method, temperature_degc=result.temperature_degc)
    report = report_from_offline(result, profile, d, str(tour_csv),
                                 recording.metadata["simulator"]["unit_errors"])
    # Printed black on white whatever the window's theme: a dark theme's light text colour
    # made the report light grey on white.
    from PySide6.QtGui import QColor, QPalette

    saved = qapp.palette()
    dark = QPalette(saved)
    for role in (QPalette.ColorRole.Text, QPalette.ColorRole.WindowText):
        dark.setColor(role, QColor("#e0e0e0"))
    qapp.setPalette(dark)
    try:
        image = render_preview(report)
    finally:
        qapp.setPalette(saved)
    assert image.height() > 800
    image.save(os.path.join(artifacts_dir, "calibration_report.png"))
    title = image.copy(0, 0, image.width(), 40)
    darkest = min(QColor(title.pixel(x, y)).lightness()
                  for x in range(0, title.width(), 2) for y in range(title.height()))
    assert darkest < 60, darkest
