"""``inclinometer allan`` and app.core.allan: noise figures against known truths."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.cli import main
from app.core.allan import (
    _dst1,
    analyse_static,
    axis_noise,
    binned_difference_spectra,
    fit_white_and_walk,
    random_walk_bound,
    temperature_slopes,
)
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
    assert document["method"] == "likelihood"
    # Both density conventions, named (issue 34); the old key keeps the datasheet's.
    assert document["gyro"]["noise_density"] == document["gyro"]["noise_density_one_sided"]
    assert "tau = 1 s" in document["convention"]["noise_density_allan"]
    assert all(v is None or v > 0 for v in document["gyro"]["random_walk_log_sd"])


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
    for method in ("likelihood", "allan-fit"):
        for k in range(3):
            axis = axis_noise(x[:, k], rate, method=method)
            assert axis.method == method
            assert axis.noise_density == pytest.approx(density, rel=0.05)
            assert axis.random_walk == pytest.approx(walk, rel=0.35)
            floor = math.sqrt(2 * math.sqrt(density**2 / 2 * walk**2 / 3)) / 0.664
            assert axis.bias_instability == pytest.approx(floor, rel=0.25)


GYRO_RATE = 104.0


def _gyro_record(rng, minutes, walk, n_axes):
    """White noise at the datasheet's gyro density plus a bias walk, ``n_axes`` columns."""
    n = round(minutes * 60 * GYRO_RATE)
    return (rng.standard_normal((n, n_axes)) * GYRO_DENSITY * math.sqrt(GYRO_RATE / 2)
            + np.cumsum(rng.standard_normal((n, n_axes)), axis=0) * walk / math.sqrt(GYRO_RATE))


def test_the_sine_transform_diagonalises_the_binned_model_exactly():
    """The likelihood's shortcut, checked against the covariance built sample by sample."""
    n_bins, m = 6, 4
    k = np.arange(1, n_bins)
    basis = np.sqrt(2 / n_bins) * np.sin(np.pi * np.outer(k, k) / n_bins)
    np.testing.assert_allclose(_dst1(np.eye(n_bins - 1)), basis.T, atol=1e-12)
    samples = n_bins * m
    walk = np.minimum.outer(np.arange(1, samples + 1), np.arange(1, samples + 1)).astype(float)
    mean = np.kron(np.eye(n_bins), np.full((1, m), 1 / m))  # bin means
    diff = np.eye(n_bins)[1:] - np.eye(n_bins)[:-1]
    a, b = binned_difference_spectra(n_bins - 1, m)
    for cov, eigen in ((np.eye(samples), a), (walk, b)):
        binned = diff @ mean @ cov @ mean.T @ diff.T
        np.testing.assert_allclose(basis @ binned @ basis.T, np.diag(eigen), atol=1e-12)


def test_the_walk_at_the_simulators_gyro_ratio_over_30_minutes():
    """Issue 16's hard case: a gyro walk of 3.5 deg/h/sqrt(h) crosses the white noise only
    after ~290 s. Over 12 records of 30 min the likelihood's walk is unbiased in the median and
    within 35 % of the truth for the median record, never 0, and the noise density is within
    5 %; the Allan-curve fit on the same records is worse (and often 0)."""
    walk = math.radians(3.5 / 3600) / 60
    x = _gyro_record(np.random.default_rng(16), 30, walk, 12)
    fits = [fit_white_and_walk(x[:, k], GYRO_RATE) for k in range(x.shape[1])]
    errors = np.array([f.random_walk / walk - 1 for f in fits])
    assert np.all(errors > -1)
    assert abs(np.median(errors)) <= 0.35
    assert np.median(np.abs(errors)) <= 0.35
    np.testing.assert_allclose([f.noise_density for f in fits], GYRO_DENSITY, rtol=0.05)
    # The posterior width is the data's, near the Cramer-Rao bound (0.48 here).
    bound = random_walk_bound(GYRO_DENSITY, walk, GYRO_RATE, 1800)
    assert 0.4 < bound < 0.55
    assert 0.7 * bound < np.median([f.random_walk_log_sd for f in fits]) < 1.5 * bound
    allan = np.array([axis_noise(x[:, k], GYRO_RATE, method="allan-fit").random_walk / walk - 1
                      for k in range(x.shape[1])])
    assert np.mean(np.abs(errors) <= 0.35) > np.mean(np.abs(allan) <= 0.35)


def test_a_warm_up_regressor_does_not_take_the_walk_with_it():
    """The temperature's residual slope is fitted jointly (restricted likelihood): with a
    warm-up curve that has no effect on the data, the walk stays where it was."""
    rng = np.random.default_rng(8)
    walk = math.radians(5 / 3600) / 60
    x = _gyro_record(rng, 30, walk, 8)
    t = np.arange(len(x)) / GYRO_RATE
    temp = 25 + 3 * -np.expm1(-t / 300)
    plain = np.array([fit_white_and_walk(x[:, k], GYRO_RATE).random_walk for k in range(8)])
    with_t = [fit_white_and_walk(x[:, k], GYRO_RATE, temp) for k in range(8)]
    ratio = np.array([f.random_walk for f in with_t]) / plain
    assert 0.8 < np.median(ratio) < 1.2
    assert np.all(np.abs([f.regressor_slope for f in with_t]) < 5e-5)  # rad/s per degC


def test_a_walk_far_above_the_white_noise_is_found_to_a_few_percent():
    rng = np.random.default_rng(2)
    walk = math.radians(60 / 3600) / 60  # crossing after ~25 s: many clusters in 30 min
    x = _gyro_record(rng, 30, walk, 3)
    for k in range(3):
        fit = fit_white_and_walk(x[:, k], GYRO_RATE)
        assert fit.random_walk == pytest.approx(walk, rel=0.25)
        assert fit.random_walk_ml == pytest.approx(fit.random_walk, rel=0.1)
        assert fit.random_walk_log_sd < 0.2


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
