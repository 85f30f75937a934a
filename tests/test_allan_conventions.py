"""Both noise-density conventions of ``inclinometer allan`` and Kalibr's IMU file."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.cli import main
from app.core.allan import CONVENTIONS, SensorNoiseFigures, analyse_static, axis_noise
from app.core.interop.kalibr import KALIBR_KEYS, kalibr_figures, kalibr_yaml
from app.core.samples import STANDARD_GRAVITY_M_S2

RATE = 20.0


def kalibr_model(rng, n, density, walk):
    """(n, 3) as Kalibr's discrete model: white sigma/sqrt(dt), walk steps sigma_b sqrt(dt)."""
    dt = 1.0 / RATE
    return (rng.standard_normal((n, 3)) * density / math.sqrt(dt)
            + np.cumsum(rng.standard_normal((n, 3)), axis=0) * walk * math.sqrt(dt))


@pytest.fixture(scope="module")
def kalibr_result():
    """32 minutes at 20 Hz of white noise + walk with known Kalibr-convention figures."""
    rng = np.random.default_rng(11)
    n = round(32 * 60 * RATE)
    truth = {"gyroscope_noise_density": 2e-3, "gyroscope_random_walk": 2e-4,
             "accelerometer_noise_density": 3e-3, "accelerometer_random_walk": 3e-4}
    gyro = kalibr_model(rng, n, truth["gyroscope_noise_density"],
                        truth["gyroscope_random_walk"])
    accel = kalibr_model(rng, n, truth["accelerometer_noise_density"],
                         truth["accelerometer_random_walk"])
    accel[:, 2] += STANDARD_GRAVITY_M_S2
    return truth, analyse_static(gyro, accel, RATE)


def test_white_noise_of_known_density_is_read_in_both_conventions():
    """Noise generated in the datasheet's one-sided convention (sigma = N sqrt(fs/2)): the
    one-sided figure recovers N, the Allan/Kalibr one N / sqrt(2), which is adev(1 s)."""
    rng = np.random.default_rng(5)
    n, density = round(5 * 60 * RATE), 1e-3
    x = rng.standard_normal((n, 3)) * density * math.sqrt(RATE / 2)
    sensor = SensorNoiseFigures(tuple(axis_noise(x[:, k], RATE, method="allan-fit")
                                      for k in range(3)))
    np.testing.assert_allclose(sensor.noise_density_one_sided, density, rtol=0.06)
    np.testing.assert_allclose(sensor.noise_density_allan, density / math.sqrt(2), rtol=0.06)
    at_1s = [np.interp(0.0, np.log(a.tau_s), np.log(a.adev)) for a in sensor.axes]
    np.testing.assert_allclose(np.exp(at_1s), sensor.noise_density_allan, rtol=0.1)


def test_kalibr_convention_data_gives_kalibrs_figures_back(kalibr_result):
    truth, result = kalibr_result
    figures = kalibr_figures(result)
    assert set(figures) == set(truth)
    for key in ("gyroscope_noise_density", "accelerometer_noise_density"):
        assert figures[key] == pytest.approx(truth[key], rel=0.05)
    for key in ("gyroscope_random_walk", "accelerometer_random_walk"):
        assert figures[key] == pytest.approx(truth[key], rel=0.35)
    # The datasheet's one-sided figure is sqrt(2) larger: what made the two read 41 % apart.
    np.testing.assert_allclose(result.gyro.noise_density_one_sided,
                               truth["gyroscope_noise_density"] * math.sqrt(2), rtol=0.05)


def test_json_keeps_its_keys_adds_both_densities_and_says_which_is_which(kalibr_result):
    _, result = kalibr_result
    document = result.to_json()
    for sensor in ("gyro", "accel"):
        figures = document[sensor]
        assert figures["noise_density"] == figures["noise_density_one_sided"]
        np.testing.assert_allclose(np.array(figures["noise_density_allan"]) * math.sqrt(2),
                                   figures["noise_density"], rtol=1e-12)
    assert document["convention"] == CONVENTIONS
    assert "sqrt(fs/2)" in CONVENTIONS["noise_density_one_sided"]
    assert "tau = 1 s" in CONVENTIONS["noise_density_allan"]


def test_kalibr_yaml_holds_kalibrs_keys_and_says_how(kalibr_result):
    _, result = kalibr_result
    text = kalibr_yaml(result, "static.csv", "/imu0")
    values = {}
    for line in text.splitlines():
        if line.startswith("#"):
            continue
        key, value = line.split(":", 1)
        values[key] = value.split("#")[0].strip()
    assert list(values) == list(KALIBR_KEYS)
    assert values["rostopic"] == "/imu0" and float(values["update_rate"]) == RATE
    figures = kalibr_figures(result)
    for key, value in figures.items():
        assert float(values[key]) == pytest.approx(value, rel=1e-6)
    comments = " ".join(line for line in text.splitlines() if line.startswith("#"))
    assert "static.csv" in comments and "not inflated" in comments.replace("NOT", "not")
    assert "10x" in comments and "Not applied" in comments


def test_kalibr_file_is_refused_for_a_record_too_short_for_the_walks(tmp_path, capsys):
    """A 1-minute record: the table (both densities, their conventions) but no Kalibr file."""
    rec = tmp_path / "static.csv"
    assert main(["record", "--device", "sim://static?odr=26&seed=4&realtime=0",
                 "--duration", "1m", str(rec)]) == 0
    yaml = tmp_path / "imu.yaml"
    assert main(["allan", str(rec), "--kalibr", str(yaml)]) == 1
    captured = capsys.readouterr()
    assert "needs the random walks" in captured.err and "30 min" in captured.err
    assert not yaml.exists()
    assert "noise density (Allan)" in captured.out and "N*sqrt(fs/2)" in captured.out
    assert main(["allan", str(rec), "--kalibr", str(yaml), "--rostopic", "imu 0"]) == 2
    assert "--rostopic" in capsys.readouterr().err
