"""``inclinometer allan`` and app.core.allan: noise figures against known truths."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.cli import main
from app.core.allan import analyse_static, axis_noise, temperature_slopes
from app.core.samples import STANDARD_GRAVITY_M_S2

GYRO_DENSITY = math.radians(3.8e-3)
ACCEL_DENSITY = 70e-6 * STANDARD_GRAVITY_M_S2


@pytest.fixture(scope="module")
def static_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("allan") / "static.csv"
    assert main(["record", "--device", "sim://static?odr=26&seed=4&realtime=0",
                 "--duration", "4m", str(path)]) == 0
    return path


def test_allan_on_a_simulated_static_recording_writes_the_binding_json(static_csv, tmp_path,
                                                                       capsys):
    out = tmp_path / "allan.json"
    assert main(["allan", str(static_csv), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "truth (simulator)" in printed and "dps/rtHz" in printed and "ug/rtHz" in printed
    document = json.loads(out.read_text())
    for sensor, density in (("gyro", GYRO_DENSITY), ("accel", ACCEL_DENSITY)):
        figures = document[sensor]
        for key in ("noise_density", "bias_instability", "random_walk"):
            assert len(figures[key]) == 3
        tau = np.asarray(figures["tau_s"])
        adev = np.asarray(figures["adev"])
        assert adev.shape == (3, len(tau)) and np.all(np.diff(tau) > 0)
        # Noise densities from 4 minutes at 26 Hz: within 10 % of what the simulator adds
        # (quantisation at 26 Hz adds about 2 % to the gyro's).
        np.testing.assert_allclose(figures["noise_density"], density, rtol=0.10)
        # On the white part the deviation is N / sqrt(2 tau).
        first = np.asarray(figures["noise_density"]) / np.sqrt(2 * tau[0])
        np.testing.assert_allclose(adev[:, 0], first, rtol=0.15)
    assert document["temperature_removed"] is True


def test_json_to_stdout_keeps_the_table_on_stderr(static_csv, capsys):
    assert main(["allan", str(static_csv), "--json", "-"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["gyro"]["noise_density"]
    assert "noise density" in captured.err


def test_random_walk_and_noise_density_of_synthetic_data():
    """A walk well above the white noise (crossing at ~12 s) over 30 min at 20 Hz."""
    rng = np.random.default_rng(3)
    rate, n = 20.0, 36000
    density, walk = 1e-3, 1e-4
    x = (rng.standard_normal((n, 3)) * density * math.sqrt(rate / 2)
         + np.cumsum(rng.standard_normal((n, 3)), axis=0) * walk / math.sqrt(rate))
    for k in range(3):
        axis = axis_noise(x[:, k], rate)
        assert axis.noise_density == pytest.approx(density, rel=0.05)
        assert axis.random_walk == pytest.approx(walk, rel=0.35)
        floor = math.sqrt(2 * math.sqrt(density**2 / 2 * walk**2 / 3)) / 0.664
        assert axis.bias_instability == pytest.approx(floor, rel=0.25)


def test_a_warm_up_drift_is_regressed_out_and_would_spoil_the_walk_otherwise():
    rng = np.random.default_rng(5)
    rate, n = 20.0, 36000
    t = np.arange(n) / rate
    temp = 25 + 3 * -np.expm1(-t / 300)
    slope = np.array([2e-4, -1e-4, 5e-5])  # per degC
    white = rng.standard_normal((n, 3)) * 5e-5 * math.sqrt(rate / 2)  # a gyro's, in rad/s
    x = white + np.outer(temp - 25, slope)
    np.testing.assert_allclose(temperature_slopes(x, temp, rate), slope, atol=2e-5)
    kept = analyse_static(x, x, rate, temp, remove_temperature=False)
    removed = analyse_static(x, x, rate, temp)
    assert removed.temperature_removed and not kept.temperature_removed
    assert np.all(removed.gyro.random_walk < 0.2 * kept.gyro.random_walk)
    np.testing.assert_allclose(removed.gyro.noise_density, 5e-5, rtol=0.05)


def test_too_short_is_refused(tmp_path, capsys):
    path = tmp_path / "short.csv"
    assert main(["record", "--device", "sim://static?odr=26&realtime=0", "--duration", "2",
                 str(path)]) == 0
    capsys.readouterr()
    assert main(["allan", str(path)]) == 1
    assert "record at least a few minutes" in capsys.readouterr().err
