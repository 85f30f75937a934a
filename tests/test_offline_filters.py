"""Offline filters for recordings: the EKF smoother and VQF's offline variant."""

from __future__ import annotations

import numpy as np
import pytest
from broad_trials import broad_rmse, load_trial
from synthetic_blocks import block

from app.core.filters import FILTERS, ONLINE_FILTERS
from app.core.filters.ekf import QuaternionEKF
from app.core.filters.gyro_integration import GyroIntegration
from app.core.filters.offline import EKFSmoother, OfflineVQF, restarts, reversed_block
from app.core.orientation import inclination_error_deg, quaternion_from_roll_pitch
from app.core.samples import SampleBlock


def test_offline_filters_are_registered_and_never_offered_live():
    assert FILTERS["ekf-smoother"] is EKFSmoother and FILTERS["vqf-offline"] is OfflineVQF
    assert EKFSmoother.offline and OfflineVQF.offline
    assert "ekf-smoother" not in ONLINE_FILTERS and "vqf-offline" not in ONLINE_FILTERS
    assert "ekf" in ONLINE_FILTERS


def test_the_reversed_stream_turns_the_attitude_back_exactly():
    """Integrating forward then backward returns to the start: each gyro sample is used for
    the interval it measured in both directions."""
    rng = np.random.default_rng(3)
    n = 500
    t = np.cumsum(rng.uniform(0.004, 0.006, n))
    gyro = rng.normal(0.0, 2.0, (n, 3))
    accel = np.tile([0.0, 0.0, 9.81], (n, 1))
    forward = block(t, accel, gyro)
    start = quaternion_from_roll_pitch(10.0, -20.0)
    f = GyroIntegration()
    f.reset(start, t[0])
    end = f.process(SampleBlock(t[1:], accel[1:], gyro[1:], np.zeros(n - 1),
                                np.zeros(n - 1, bool))).quat[-1]
    back = reversed_block(forward)
    assert np.all(np.diff(back.t_s) > 0)
    g = GyroIntegration()
    g.reset(end, back.t_s[0])
    returned = g.process(SampleBlock(back.t_s[1:], back.accel_m_s2[1:], back.gyro_rad_s[1:],
                                     np.zeros(n - 1), np.zeros(n - 1, bool))).quat[-1]
    assert abs(abs(float(np.dot(returned, start))) - 1.0) < 1e-12


def test_gaps_stay_in_place_backwards():
    t = np.arange(10) * 0.01
    gap = np.zeros(10, bool)
    gap[4] = True  # a restart between samples 3 and 4
    b = block(t, np.tile([0.0, 0.0, 9.81], (10, 1)), np.zeros((10, 3)))
    b.gap[:] = gap
    back = reversed_block(b)
    # backwards, sample 3 (index 6) comes right after the hole
    assert list(np.flatnonzero(back.gap)) == [6]
    assert list(restarts(b.t_s, b.gap)) == [0, 4]


@pytest.fixture(scope="module")
def slow_rotation():
    return load_trial("04_undisturbed_slow_rotation_with_breaks_A")


def test_the_smoother_beats_the_causal_ekf_on_real_motion(slow_rotation):
    samples, _ = slow_rotation
    stem = "04_undisturbed_slow_rotation_with_breaks_A"
    causal = broad_rmse(QuaternionEKF().process(samples).quat, stem)
    smoothed = broad_rmse(EKFSmoother().process(samples).quat, stem)
    assert smoothed < 0.8 * causal


def test_offline_vqf_is_the_packages_offline_vqf(slow_rotation):
    vqf = pytest.importorskip("vqf")
    samples, _ = slow_rotation
    ours = OfflineVQF().process(samples).quat
    ts = float(np.median(np.diff(samples.t_s)))
    theirs = vqf.offlineVQF(np.ascontiguousarray(samples.gyro_rad_s),
                            np.ascontiguousarray(samples.accel_m_s2), None, ts,
                            {"tauAcc": 3.0, "biasSigmaInit": 0.5})["quat6D"]
    assert np.max(inclination_error_deg(ours, theirs)) < 1e-9


def test_offline_filters_restart_at_a_gap_without_nan(slow_rotation):
    samples, _ = slow_rotation
    part = SampleBlock(samples.t_s[:20000].copy(), samples.accel_m_s2[:20000],
                       samples.gyro_rad_s[:20000], samples.temp_degc[:20000],
                       samples.gap[:20000].copy(), samples.reference_quat[:20000])
    part.t_s[10000:] += 5.0  # five seconds lost
    for cls in (EKFSmoother, OfflineVQF):
        quat = cls().process(part).quat
        assert np.all(np.isfinite(quat))
        errors = inclination_error_deg(quat[12000:], part.reference_quat[12000:])
        assert np.sqrt(np.nanmean(errors**2)) < 3.0


def test_parameters_of_an_older_version_are_left_out_of_a_replay(tmp_path):
    from app.core.filters import known_parameters
    from app.core.recording.export import recorded_filter_parameters

    class Old:
        def __init__(self) -> None:
            self.metadata = {"filter": {"name": "ekf", "parameters": {
                "lp_tau": 1.0, "accel_tolerance": 15.0}}}

    assert recorded_filter_parameters(Old()) == {"ekf": {"lp_tau": 1.0}}
    assert known_parameters("ekf", {"lp_tau": 1.0, "accel_tolerance": 15.0}) == (
        {"lp_tau": 1.0}, ["accel_tolerance"])


def test_a_switch_reads_the_words_true_and_false():
    from app.core.filters.ekf import QuaternionEKF as EKF

    assert EKF(estimate_bias="false").get_parameter("estimate_bias") is False
    assert EKF(estimate_bias="On").get_parameter("estimate_bias") is True
    with pytest.raises(ValueError, match="not true or false"):
        EKF(estimate_bias="maybe")
