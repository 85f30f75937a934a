"""vqf-heading: VQF 6D's tilt with the EKF's heading filter (q9 = Rz(delta) q6).

Synthetic streams with a known attitude (the EKF heading tests' generator): the accelerometer
and the field are the earth's seen through the true attitude.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from app.core.filters import FILTERS, create_filter
from app.core.filters.ekf import QuaternionEKF
from app.core.filters.vqf_filter import VQF_AVAILABLE, VQFFilter
from app.core.magnetometer.disturbance import NO_SAMPLE, OK, REJECTED
from app.core.orientation import inclination_error_deg
from app.core.samples import SampleBlock, slice_block
from tests.test_ekf_heading import (
    DIP_DEG,
    FIELD_UT,
    RATE_HZ,
    angle_diff_deg,
    earth_field,
    heading_deg,
    pose,
    stream,
    tumbling_rate,
)

pytestmark = pytest.mark.skipif(not VQF_AVAILABLE, reason="the vqf package is not installed")


def hybrid(**values) -> object:
    return create_filter("vqf-heading", **values)


def without_field(block: SampleBlock, nan: bool = False) -> SampleBlock:
    n = len(block)
    return SampleBlock(block.t_s, block.accel_m_s2, block.gyro_rad_s, block.temp_degc,
                       block.gap, None, np.full((n, 3), np.nan) if nan else None)


def test_registered_with_the_tilt_knobs_of_vqf_and_the_heading_knobs_of_the_ekf():
    cls = FILTERS["vqf-heading"]
    assert cls.uses_magnetometer
    names = {spec.name for spec in cls.parameters}
    assert "magnetometer" in names
    for spec in cls.parameters:
        tilt = spec.name in {"tau_acc_s", "motion_bias_estimation", "rest_bias_estimation",
                             "bias_sigma_init_dps"}
        source = VQFFilter if tilt else QuaternionEKF  # the EKF's disturbance bands too
        assert source.parameter_spec(spec.name) == spec
    assert {"tau_acc_s", "mag_noise", "mag_timing", "mag_rejection"} <= names


def test_without_a_field_the_output_is_vqf_6d_bit_for_bit():
    n = int(8 * RATE_HZ)
    block, _ = stream(8.0, tumbling_rate(n), start=pose(5, 30, 10), noise=1.0)
    reference = VQFFilter(magnetometer=False).process(block).quat
    assert np.array_equal(hybrid().process(without_field(block)).quat, reference)
    nan_filter = hybrid()
    assert np.array_equal(nan_filter.process(without_field(block, nan=True)).quat, reference)
    assert np.all(nan_filter.field_status.status == NO_SAMPLE)
    switched_off = hybrid(magnetometer=False)
    assert np.array_equal(switched_off.process(block).quat, reference)
    assert switched_off.field_status is None


def test_with_a_field_the_inclination_is_vqf_6d_to_float_precision():
    n = int(30 * RATE_HZ)
    # 90 degrees off in heading at the start, so that the heading updates are large.
    block, truth = stream(30.0, tumbling_rate(n), start=pose(25, -15, 90), noise=1.0, seed=3)
    six = VQFFilter(magnetometer=False).process(block).quat
    nine = hybrid().process(block).quat
    assert np.max(np.abs(angle_diff_deg(heading_deg(nine), heading_deg(six)))) > 30
    assert np.max(inclination_error_deg(nine, six)) < 1e-6
    assert np.allclose(inclination_error_deg(nine, truth), inclination_error_deg(six, truth),
                       atol=1e-6)


def test_heading_converges_to_a_tilted_poses_heading_and_follows_a_tumbling_sensor():
    block, truth = stream(10.0, start=pose(20.0, -12.0, 70.0), noise=1.0)
    out = hybrid().process(block).quat
    late = slice(len(out) // 2, None)
    assert np.max(np.abs(angle_diff_deg(heading_deg(out[late]), heading_deg(truth[late])))) < 1.0
    six = VQFFilter(magnetometer=False).process(block).quat
    assert np.min(np.abs(angle_diff_deg(heading_deg(six[late]), heading_deg(truth[late])))) > 30
    n = int(40 * RATE_HZ)
    block, truth = stream(40.0, tumbling_rate(n), start=pose(10, 5, -120), noise=1.0)
    error = angle_diff_deg(heading_deg(hybrid().process(block).quat), heading_deg(truth))
    assert np.sqrt(np.mean(error[n // 4:] ** 2)) < 1.0


def test_a_field_that_jumps_is_rejected_and_the_gyro_holds_the_heading():
    seconds = 20.0
    n = int(seconds * RATE_HZ)
    field = np.tile(earth_field(), (n, 1))
    jump = slice(int(12 * RATE_HZ), int(16 * RATE_HZ))
    field[jump] = earth_field(1.3 * FIELD_UT, DIP_DEG, 40.0)  # a magnet nearby
    block, truth = stream(seconds, start=pose(0, 0, 30), field=field, noise=1.0)
    f = hybrid()
    out = f.process(block).quat
    status = f.field_status.status
    assert np.all(status[int(10 * RATE_HZ):jump.start] == OK)  # reference learnt at rest
    assert np.mean(status[jump] == REJECTED) > 0.95
    error = np.abs(angle_diff_deg(heading_deg(out), heading_deg(truth)))
    assert np.max(error[jump]) < 0.5
    pulled = hybrid(mag_rejection=False).process(block).quat
    assert np.max(np.abs(angle_diff_deg(heading_deg(pulled[jump]), heading_deg(truth[jump])))
                  ) > 2.0
    assert not f.field_status.disturbed


def test_block_cuts_give_the_result_of_one_block():
    n = int(20 * RATE_HZ)
    block, _ = stream(20.0, tumbling_rate(n), start=pose(5, 30, 10), noise=1.0)
    # Times exact in binary (a 1/128 s step), so every block gives VQF the same Ts and VQF 6D
    # itself is cut-invariant to the bit; then so must the heading be.
    block = SampleBlock(np.arange(n) / 128.0, block.accel_m_s2, block.gyro_rad_s,
                        block.temp_degc, block.gap, None, block.mag_ut)
    whole = hybrid()
    expected = whole.process(block).quat
    pieces = hybrid()
    parts, status = [], []
    for a, b in itertools.pairwise([0, 2, 17, 800, 801, n - 5, n]):
        parts.append(pieces.process(slice_block(block, a, b)).quat)
        status.append(pieces.field_status.status)
    assert np.array_equal(np.concatenate(parts), expected)
    assert np.array_equal(np.concatenate(status), whole.field_status.status)
    # Without a field, cut the same way: VQF 6D's one-block output, bit for bit.
    six = VQFFilter(magnetometer=False).process(without_field(block)).quat
    pieces = hybrid()
    parts = [pieces.process(slice_block(without_field(block), a, b)).quat
             for a, b in itertools.pairwise([0, 2, 17, 800, 801, n - 5, n])]
    assert np.array_equal(np.concatenate(parts), six)


def test_a_gap_restarts_the_heading_which_the_next_field_sample_sets_at_once():
    block, truth = stream(12.0, start=pose(0, 0, 60), noise=1.0)
    gap = block.gap.copy()
    gap[600] = True  # a marked gap: VQF restarts at heading 0, the field sets it again
    cut = SampleBlock(block.t_s, block.accel_m_s2, block.gyro_rad_s, block.temp_degc, gap,
                      None, block.mag_ut)
    out = hybrid().process(cut).quat
    after = slice(600, 620)
    assert np.max(np.abs(angle_diff_deg(heading_deg(out[after]), heading_deg(truth[after])))
                  ) < 2.0
    six = VQFFilter(magnetometer=False).process(cut).quat
    assert np.max(inclination_error_deg(out, six)) < 1e-6


def test_warm_up_leaves_the_state_untouched():
    block, _ = stream(3.0, tumbling_rate(300), start=pose(5, 10, 40), noise=1.0)
    f = hybrid()
    f.warm_up()
    assert f.last_time_s is None
    assert np.array_equal(f.process(block).quat, hybrid().process(block).quat)


def test_switching_the_magnetometer_on_mid_stream_finds_north_at_once_and_off_holds_it():
    block, truth = stream(6.0, start=pose(0, 0, 60))
    f = hybrid(magnetometer=False)
    f.process(slice_block(block, 0, 300))
    assert abs(angle_diff_deg(heading_deg(f.quaternion), heading_deg(truth[299]))) > 30
    f.set_parameter("magnetometer", True)
    out = f.process(slice_block(block, 300, 310)).quat
    assert np.max(np.abs(angle_diff_deg(heading_deg(out), heading_deg(truth[300:310])))) < 0.5
    f.set_parameter("magnetometer", False)  # the gyro carries the heading found: no jump
    out = f.process(slice_block(block, 310, 400)).quat
    assert np.max(np.abs(angle_diff_deg(heading_deg(out), heading_deg(truth[310:400])))) < 0.5
