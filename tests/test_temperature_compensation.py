"""Temperature compensation: the fit against the simulator's drift (``sim://...&warmup=``),
the model applied in the pipeline (live and replay, bit for bit), profile and recording
metadata round trips, ``inclinometer calibrate-temperature`` and its report section."""

from __future__ import annotations

import json
import math
import os
from dataclasses import replace

import numpy as np
import pytest

from app.cli import main
from app.core.calibration import SensorCalibration, TemperatureCompensation
from app.core.calibration_procedures import ProfileStore, SensorSettings, make_profile
from app.core.calibration_procedures.profiles import (
    CalibrationProfile,
    ProfileCorruptError,
    read_profile_file,
    write_profile_file,
)
from app.core.calibration_procedures.temperature import (
    LINEAR,
    QUADRATIC,
    TemperatureFitError,
    fit_temperature,
    merge_temperature,
    truth_of,
)
from app.core.evaluation import concatenate_blocks
from app.core.pipeline import Pipeline
from app.core.recording.format import calibration_from_json, calibration_to_json
from app.core.recording.reader import read_recording
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock, convert_raw_block
from app.services.recorder import record_device
from drivers.errors import DeviceUrlError
from drivers.sim.device import SimulatedDevice

SEED = 3
WARMUP = f"sim://static?warmup=15:120&odr=26&seed={SEED}&realtime=0"
SECONDS = 600.0  # five time constants: 15 degC of warm-up
MDPS = 180.0 / math.pi * 1e3
MG = 1e3 / STANDARD_GRAVITY_M_S2
BINDING_KEYS = ("accel_bias_m_s2", "accel_matrix", "gyro_bias_rad_s", "gyro_matrix")


def _stream(url: str, seconds: float) -> tuple[SampleBlock, SensorSettings, SimulatedDevice]:
    device = SimulatedDevice(url, realtime=False, block=2048)
    info = device.open()
    blocks, n = [], 0
    while n < seconds * info.odr_hz:
        block = convert_raw_block(device.read(1.0))
        blocks.append(block)
        n += len(block)
    device.close()
    return (concatenate_blocks(blocks),
            SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps), device)


@pytest.fixture(scope="module")
def warmup():
    return _stream(WARMUP, SECONDS)


@pytest.fixture(scope="module")
def warmup_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("warmup") / "warmup.csv"
    assert main(["record", "--device", WARMUP, "--duration", f"{SECONDS:g}", "--quiet",
                 str(path)]) == 0
    return path


def test_the_warmup_option_heats_the_simulated_die(warmup):
    block, _, device = warmup
    assert device.unit_errors.self_heating_degc == 15.0
    assert device.unit_errors.self_heating_time_constant_s == 120.0
    rise = block.temp_degc[-1] - block.temp_degc[0]
    assert 14.5 < rise < 15.0  # 1 - exp(-5) of 15 degC
    with pytest.raises(DeviceUrlError, match="warmup="):
        SimulatedDevice("sim://static?warmup=80")


def test_the_fit_recovers_the_simulators_coefficients(warmup):
    block, settings, device = warmup
    fit = fit_temperature(block, settings)
    truth = truth_of(fit, device.unit_errors.as_dict())
    assert fit.span_degc > 14.0 and fit.poses == 1
    # The simulator's drift is linear; the gyro has nothing else that varies this slowly.
    assert fit.gyro.degree == LINEAR
    # Gyro slope within 3 % of the truth (+ 0.05 mdps/degC): the limit is +-10 mdps/degC.
    np.testing.assert_allclose(fit.gyro.k1 * MDPS, truth.gyro_k1 * MDPS,
                               rtol=0.03, atol=0.05)
    np.testing.assert_allclose(fit.gyro_bias_at_reference_rad_s * MDPS,
                               truth.gyro_bias_at_reference * MDPS, atol=1.0)
    # Accelerometer slope (as seen in this pose) within 0.015 mg/degC (limit +-0.1): the
    # bias random walk, not noise, sets this. A quadratic term, if the walk earned one,
    # stays small over the span.
    np.testing.assert_allclose(fit.accel.k1 * MG, truth.accel_k1 * MG, atol=0.015)
    half = fit.span_degc / 2.0
    assert np.all(np.abs(fit.accel.k2) * half**2 * MG < 0.1)
    # The coefficients' stated uncertainty is not absurd.
    assert np.all(fit.gyro.k1_std * MDPS < 0.2)


def test_a_real_curvature_is_chosen_and_recovered(warmup):
    block, settings, _ = warmup
    fit = fit_temperature(block, settings)
    k2 = np.radians([0.4e-3, -0.3e-3, 0.2e-3])  # 0.4 mdps/degC^2: 22 mdps at 7.5 degC
    delta = (block.temp_degc - fit.reference_temp_degc)[:, None]
    bent = replace(block, gyro_rad_s=block.gyro_rad_s + delta * delta * k2)
    bent_fit = fit_temperature(bent, settings)
    assert bent_fit.gyro.degree == QUADRATIC
    assert bent_fit.gyro.aicc[LINEAR] - bent_fit.gyro.aicc[QUADRATIC] > 10.0
    np.testing.assert_allclose(bent_fit.gyro.k2 * MDPS, k2 * MDPS, atol=0.03)
    np.testing.assert_allclose(bent_fit.gyro.k1, fit.gyro.k1, atol=np.radians(0.1e-3))


def test_too_narrow_a_span_is_refused_with_the_reason(tmp_path, capsys):
    block, settings, _ = _stream(f"sim://static?odr=26&seed={SEED}&realtime=0", 60.0)
    with pytest.raises(TemperatureFitError, match=r"spans only 0\.\d\d degC"):
        fit_temperature(block, settings)
    path = tmp_path / "cold.csv"
    assert main(["record", "--device", f"sim://static?odr=26&seed={SEED}&realtime=0",
                 "--duration", "60", "--quiet", str(path)]) == 0
    capsys.readouterr()
    assert main(["calibrate-temperature", str(path), "--out", str(tmp_path / "t.json")]) == 1
    err = capsys.readouterr().err
    assert "cannot fit the temperature dependence" in err and "needs at least 3 degC" in err
    assert not (tmp_path / "t.json").exists()


def test_motion_everywhere_and_no_temperature_are_refused(warmup):
    block, settings, _ = warmup
    moving, _, _ = _stream(f"sim://wobble?odr=26&seed={SEED}&realtime=0", 30.0)
    with pytest.raises(TemperatureFitError, match="motion everywhere"):
        fit_temperature(moving, settings)
    blind = replace(block, temp_degc=np.full(len(block), np.nan))
    with pytest.raises(TemperatureFitError, match="no temperature"):
        fit_temperature(blind, settings)


def _model() -> TemperatureCompensation:
    return TemperatureCompensation(
        24.5, accel_k1=np.array([1e-3, -2e-3, 3e-3]), accel_k2=np.array([1e-5, 0.0, -1e-5]),
        gyro_k1=np.radians([5e-3, -4e-3, 6e-3]), gyro_k2=np.radians([1e-5, 2e-5, 0.0]))


def test_apply_uses_each_samples_temperature_and_none_at_nan():
    model = _model()
    base = SensorCalibration(accel_bias_m_s2=np.array([0.01, -0.02, 0.03]),
                             gyro_bias_rad_s=np.array([1e-3, 2e-3, -3e-3]), name="b")
    calibrated = base.with_temperature(model)
    assert not calibrated.is_identity
    assert not SensorCalibration(temperature=model).is_identity
    temps = np.array([24.5, 34.5, np.nan, 14.5])
    block = SampleBlock(np.arange(4.0), np.tile([0.0, 0.0, 9.8], (4, 1)), np.zeros((4, 3)),
                        temps, np.zeros(4, bool))
    out = calibrated.apply(block)
    plain = base.apply(block)
    # At T0 and at an unknown temperature: exactly the plain calibration.
    for row in (0, 2):
        np.testing.assert_array_equal(out.gyro_rad_s[row], plain.gyro_rad_s[row])
        np.testing.assert_array_equal(out.accel_m_s2[row], plain.accel_m_s2[row])
    # At T0 + 10: b0 + 10 k1 + 100 k2 is removed.
    expected = -(base.gyro_bias_rad_s + 10 * model.gyro_k1 + 100 * model.gyro_k2)
    np.testing.assert_allclose(out.gyro_rad_s[1], expected, rtol=1e-12)
    expected = -(base.gyro_bias_rad_s - 10 * model.gyro_k1 + 100 * model.gyro_k2)
    np.testing.assert_allclose(out.gyro_rad_s[3], expected, rtol=1e-12)
    # Re-centring keeps the curve's shape: same change between any two temperatures.
    moved = model.recentred(30.0)
    a, g = model.offsets(np.array([20.0, 40.0]))
    a2, g2 = moved.offsets(np.array([20.0, 40.0]))
    np.testing.assert_allclose(g[1] - g[0], g2[1] - g2[0], rtol=1e-12)
    np.testing.assert_allclose(a[1] - a[0], a2[1] - a2[0], rtol=1e-12)
    assert moved.offsets(np.array([30.0]))[1].tolist() == [[0.0, 0.0, 0.0]]


def test_the_pipeline_compensates_a_warmup(warmup):
    block, settings, _ = warmup
    fit = fit_temperature(block, settings)
    # A base calibration measured cold (the first 20 s), as a six-position run would be.
    cold = slice(0, round(20 * settings.odr_hz))
    base_temp = float(block.temp_degc[cold].mean())
    base = SensorCalibration(gyro_bias_rad_s=block.gyro_rad_s[cold].mean(axis=0), name="cold")
    compensated, _ = merge_temperature(fit, base, base_temp, name="cold + temperature")
    assert compensated.temperature.reference_temp_degc == base_temp
    # Another warm-up of the same unit, tilted, through the pipeline.
    # Twice the rate: the same unit, but a bias random walk the fit did not see.
    url = f"sim://static?roll=20&pitch=-10&warmup=15:120&odr=52&seed={SEED}&realtime=0"
    errors = {}
    for calibration in (base, compensated):
        run = SimulatedDevice(url, block=512)
        run.open()
        pipeline = Pipeline(run.odr_hz, "ekf")
        pipeline.set_calibration(calibration)
        gyro = []
        while sum(len(g) for g in gyro) < SECONDS * run.odr_hz:
            gyro.append(pipeline.process(run.read(1.0)).gyro_rad_s)
        run.close()
        gyro = np.concatenate(gyro)
        # Bias error: 20 s means of the calibrated rate at rest (truth 0).
        n = round(20 * run.odr_hz)
        means = gyro[: len(gyro) // n * n].reshape(-1, n, 3).mean(axis=1)
        errors[calibration.name] = float(np.abs(means).max())
    before, after = errors["cold"] * MDPS, errors["cold + temperature"] * MDPS
    assert before > 30.0  # the unit's drift over 15 degC is tens of mdps
    assert after < before / 8.0, (before, after)


def test_replay_reproduces_the_compensated_live_run_bit_for_bit(tmp_path, warmup, capsys):
    block, settings, _ = warmup
    calibration, _ = merge_temperature(fit_temperature(block, settings))
    sim = SimulatedDevice("sim://slow-tilt?warmup=15:120&odr=52&seed=4", realtime=False, block=7)
    source = tmp_path / "run.csv"
    outcome = record_device(sim, source, duration_s=20.0, filter_name="ekf",
                            calibration=calibration)
    live = outcome.pipeline
    n = live.counters.samples
    recorded = read_recording(source).calibration
    assert recorded is not None and recorded.temperature is not None
    np.testing.assert_array_equal(recorded.temperature.gyro_k1, calibration.temperature.gyro_k1)
    angles = tmp_path / "angles.csv"
    assert main(["replay", str(source), "--filter", "ekf", "--out", str(angles)]) == 0
    capsys.readouterr()
    lines = [line for line in angles.read_text().splitlines() if not line.startswith("#")]
    names = lines[0].split(",")
    rows = np.array([[float(x) if x else np.nan for x in line.split(",")] for line in lines[1:]])
    table = {name: rows[:, k] for k, name in enumerate(names)}
    for name in ("roll", "pitch", "tilt"):
        assert np.array_equal(table[f"ekf.{name}"], live.orientation.latest(n)[name]), name
    # Without the temperature terms the angles differ: they were really applied.
    plain = replace(calibration, temperature=None)
    check = Pipeline(sim.odr_hz, "ekf")
    check.set_calibration(plain)
    replayed = SimulatedDevice("sim://slow-tilt?warmup=15:120&odr=52&seed=4", realtime=False,
                               block=7)
    replayed.open()
    while check.counters.samples < n:
        check.process(replayed.read(1.0))
    replayed.close()
    assert not np.array_equal(check.orientation.latest(n)["roll"][-100:],
                              live.orientation.latest(n)["roll"][-100:])


def test_profile_and_recording_metadata_round_trips(tmp_path):
    calibration = SensorCalibration(
        accel_bias_m_s2=np.array([0.01, 0.02, -0.03]), accel_matrix=np.eye(3) * 1.001,
        gyro_bias_rad_s=np.array([1e-3, -2e-3, 3e-3]), name="six + temperature",
        temperature=_model())
    settings = SensorSettings(104.0, 4, 250)
    profile = make_profile("SIM-1", calibration, settings, method="six-position + temperature",
                           temperature_degc=24.5)
    path = tmp_path / "p.json"
    write_profile_file(path, profile)
    back = read_profile_file(path).calibration
    for name in ("accel_k1", "accel_k2", "gyro_k1", "gyro_k2"):
        np.testing.assert_array_equal(getattr(back.temperature, name),
                                      getattr(calibration.temperature, name))
    assert back.temperature.reference_temp_degc == 24.5
    # The recording's calibration key: the same optional keys, exact floats.
    value = json.loads(json.dumps(calibration_to_json(calibration)))
    assert {"temperature_reference_degc", "gyro_bias_tc1_rad_s_per_degc"} <= set(value)
    again = calibration_from_json(value)
    np.testing.assert_array_equal(again.temperature.accel_k2, calibration.temperature.accel_k2)
    # A reader keeps ignoring keys it does not know; a calibration without terms writes none.
    assert calibration_from_json({**value, "from_the_future": [1, 2]}).temperature is not None
    assert "temperature_reference_degc" not in calibration_to_json(SensorCalibration())
    broken = {**value, "gyro_bias_tc1_rad_s_per_degc": [1.0, "x", 2.0]}
    with pytest.raises(ValueError, match="gyro_bias_tc1_rad_s_per_degc"):
        calibration_from_json(broken)


def test_an_old_profile_without_the_keys_still_loads(tmp_path):
    old = {  # a format-1 profile as written before temperature compensation existed
        "format": "inclinometer-calibration-profile", "format_version": 1,
        "device_unique_id": "SIM-OLD", "name": "six-position", "created_utc":
        "2026-05-01T10:00:00Z", "app_version": "0.1.0", "method": "six-position",
        "temperature_degc": 23.0,
        "sensor_settings": {"sensor": "LSM6DSOX", "odr_hz": 104.0, "accel_fs_g": 4,
                            "gyro_fs_dps": 250},
        "parameters": {"accel_bias_m_s2": [0.1, 0.2, 0.3], "accel_matrix": np.eye(3).tolist(),
                       "gyro_bias_rad_s": [0.01, 0.02, 0.03],
                       "gyro_matrix": np.eye(3).tolist()},
        "tare_quaternion": None, "residuals": {}, "notes": "",
    }
    path = tmp_path / "old.json"
    path.write_text(json.dumps(old))
    profile = read_profile_file(path)
    assert profile.calibration.temperature is None
    assert profile.calibration.gyro_bias_rad_s.tolist() == [0.01, 0.02, 0.03]
    old["parameters"]["temperature_reference_degc"] = "warm"
    path.write_text(json.dumps(old))
    with pytest.raises(ProfileCorruptError, match="temperature terms"):
        read_profile_file(path)


def test_cli_merges_with_the_devices_six_position_profile(warmup_csv, tmp_path, capsys):
    store_dir = tmp_path / "profiles"
    unique_id = read_recording(warmup_csv).device["unique_id"]
    six = SensorCalibration(accel_bias_m_s2=np.array([0.05, -0.04, 0.1]),
                            accel_matrix=np.array([[1.01, 0.002, 0], [0, 0.99, 0],
                                                   [0, 0, 1.005]]),
                            gyro_bias_rad_s=np.array([0.01, 0.005, -0.008]), name="six-position")
    ProfileStore(store_dir).save(make_profile(unique_id, six, SensorSettings(25.8, 4, 250),
                                              method="six-position", temperature_degc=22.0))
    out = tmp_path / "t.json"
    assert main(["calibrate-temperature", str(warmup_csv), "--save", "--out", str(out),
                 "--profile-dir", str(store_dir)]) == 0
    printed = capsys.readouterr().out
    assert "against the simulator's truth" in printed and "gyro: linear" in printed
    assert "added to calibration 'six-position'" in printed
    saved: CalibrationProfile = ProfileStore(store_dir).load(unique_id)
    cal = saved.calibration
    np.testing.assert_array_equal(cal.accel_matrix, six.accel_matrix)
    np.testing.assert_array_equal(cal.gyro_bias_rad_s, six.gyro_bias_rad_s)
    assert cal.temperature.reference_temp_degc == 22.0 and saved.temperature_degc == 22.0
    assert saved.method == "six-position + temperature"
    assert saved.residuals["temperature_fit"]["gyro"]["model"] == "linear"
    assert len(ProfileStore(store_dir).history(unique_id)) == 1  # the old one kept
    document = json.loads(out.read_text())
    for key in BINDING_KEYS:
        assert key in document
    for key in ("temperature_reference_degc", "gyro_bias_tc1_rad_s_per_degc",
                "accel_bias_tc1_m_s2_per_degc", "accel_bias_tc2_m_s2_per_degc2"):
        assert key in document, key
    np.testing.assert_array_equal(calibration_from_json(document).temperature.gyro_k1,
                                  cal.temperature.gyro_k1)


def test_cli_usage_errors(warmup_csv, tmp_path, capsys):
    assert main(["calibrate-temperature", str(warmup_csv)]) == 2
    assert "say what to do" in capsys.readouterr().err
    assert main(["calibrate-temperature", str(warmup_csv), "--out", str(tmp_path / "x.json"),
                 "--base", str(tmp_path / "none.json")]) == 2
    assert "--base" in capsys.readouterr().err


def test_report_has_the_temperature_section(warmup_csv, tmp_path, qapp, artifacts_dir, capsys):
    html_path = tmp_path / "t.html"
    pdf_path = tmp_path / "t.pdf"
    for path in (html_path, pdf_path):
        assert main(["calibrate-temperature", str(warmup_csv), "--no-merge", "--report",
                     str(path)]) == 0
    capsys.readouterr()
    text = html_path.read_text(encoding="utf-8")
    for needle in ("Temperature compensation", "m°/s/°C", "mg/°C", "Against the simulator",
                   "linear"):
        assert needle in text, needle
    assert text.count("data:image/png;base64,") == 1  # the bias plot (no poses: no tilt plot)
    assert pdf_path.read_bytes()[:4] == b"%PDF"
    from app.core.calibration_procedures.temperature import fit_temperature as fit_fn
    from app.documents.calibration_report import render_preview, report_from_temperature

    recording = read_recording(warmup_csv)
    d = recording.device
    fit = fit_fn(recording.sample_block(), SensorSettings(d["odr_hz"], d["accel_fs_g"],
                                                          d["gyro_fs_dps"]))
    calibration, _ = merge_temperature(fit)
    profile = make_profile(d["unique_id"], calibration, fit.settings, method="temperature",
                           temperature_degc=fit.reference_temp_degc)
    report = report_from_temperature(fit, calibration, profile, d, str(warmup_csv),
                                     recording.metadata["simulator"]["unit_errors"])
    image = render_preview(report)
    assert image.height() > 600
    image.save(os.path.join(artifacts_dir, "temperature_report.png"))
