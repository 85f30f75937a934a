"""The EKF's heading from the magnetometer and its magnetic disturbance detection (#32).

Synthetic streams with a known attitude: the sensor-frame accelerometer and field are the
earth's gravity and field seen through the true attitude; the gyro is the rate that produced it.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.field_check import FieldReference
from app.core.filters.ekf import QuaternionEKF
from app.core.magnetometer.disturbance import (
    LEARNING,
    NO_SAMPLE,
    OK,
    REDUCED,
    REJECTED,
    DisturbanceSettings,
    describe,
)
from app.core.orientation import inclination_error_deg
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock, slice_block

RATE_HZ = 100.0
DIP_DEG = 66.0
FIELD_UT = 48.0


def earth_field(total: float = FIELD_UT, dip_deg: float = DIP_DEG, east_deg: float = 0.0
                ) -> np.ndarray:
    """ENU field: y north, dipping ``dip_deg`` below the horizontal, turned ``east_deg``."""
    h = total * math.cos(math.radians(dip_deg))
    e = math.radians(east_deg)
    return np.array([h * math.sin(e), h * math.cos(e), -total * math.sin(math.radians(dip_deg))])


def heading_deg(q: np.ndarray) -> np.ndarray:
    """Heading of the sensor's x axis in the earth frame, degrees from east toward north."""
    x = quat.rotate(q, np.array([1.0, 0.0, 0.0]))
    return np.degrees(np.arctan2(x[..., 1], x[..., 0]))


def angle_diff_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0


def stream(seconds: float, rate_body: np.ndarray | None = None,
           start: np.ndarray | None = None, field: np.ndarray | None = None,
           noise: float = 0.0, seed: int = 0) -> tuple[SampleBlock, np.ndarray]:
    """(block, true quaternions): the attitude integrated from ``rate_body`` (N, 3) rad/s, the
    accelerometer and field seen through it."""
    n = int(seconds * RATE_HZ)
    dt = 1.0 / RATE_HZ
    rate = np.zeros((n, 3)) if rate_body is None else np.asarray(rate_body, float)
    q = np.empty((n, 4))
    q[0] = quat.normalize((np.array([1.0, 0, 0, 0]) if start is None else start)[None])[0]
    steps = quat.from_rotation_vector(rate * dt)
    for i in range(1, n):
        q[i] = quat.multiply(q[i - 1][None], steps[i][None])[0]
    q = quat.normalize(q)
    field_e = np.tile(earth_field() if field is None else field, (n, 1)) \
        if (field is None or np.ndim(field) == 1) else field
    accel = quat.rotate_inverse(q, np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2]))
    mag = quat.rotate_inverse(q, field_e)
    rng = np.random.default_rng(seed)
    gyro = rate.copy()
    if noise:
        accel = accel + rng.normal(0.0, 0.05, accel.shape)
        gyro = gyro + rng.normal(0.0, 0.002, gyro.shape)
        mag = mag + rng.normal(0.0, 0.3, mag.shape)
    t = np.arange(n) * dt
    block = SampleBlock(t, accel, gyro, np.full(n, 25.0), np.zeros(n, bool), q, mag)
    return block, q


def pose(roll_deg: float, pitch_deg: float, heading_from_east_deg: float) -> np.ndarray:
    """A sensor-to-earth quaternion: turned about z, then pitched and rolled (body axes)."""
    z = quat.from_rotation_vector(np.array([[0, 0, math.radians(heading_from_east_deg)]]))
    y = quat.from_rotation_vector(np.array([[0, math.radians(pitch_deg), 0]]))
    x = quat.from_rotation_vector(np.array([[math.radians(roll_deg), 0, 0]]))
    return quat.multiply(quat.multiply(z, y), x)[0]


def tumbling_rate(n: int) -> np.ndarray:
    """A body rate that turns and tilts the sensor (tens of dps on every axis)."""
    t = np.arange(n) / RATE_HZ
    return np.stack([0.6 * np.sin(0.7 * t), 0.5 * np.cos(0.45 * t), 0.8 * np.sin(0.3 * t + 1)], 1)


def test_heading_converges_to_a_tilted_poses_heading():
    start = pose(20.0, -12.0, 70.0)
    block, truth = stream(10.0, start=start, noise=1.0)
    out = QuaternionEKF().process(block).quat
    late = slice(len(out) // 2, None)
    assert np.max(np.abs(angle_diff_deg(heading_deg(out[late]), heading_deg(truth[late])))) < 1.0
    # The 6-axis filter knows nothing of north: it starts at heading 0 (not 70).
    six = QuaternionEKF(magnetometer=False).process(block).quat
    assert np.min(np.abs(angle_diff_deg(heading_deg(six[late]), heading_deg(truth[late])))) > 30


def test_heading_follows_a_tumbling_sensor():
    n = int(40 * RATE_HZ)
    block, truth = stream(40.0, tumbling_rate(n), start=pose(10, 5, -120), noise=1.0)
    out = QuaternionEKF().process(block).quat
    error = angle_diff_deg(heading_deg(out), heading_deg(truth))[n // 4:]
    assert np.sqrt(np.mean(error**2)) < 1.0


def test_a_heading_update_never_changes_the_inclination():
    n = int(30 * RATE_HZ)
    # Start 90 degrees off in heading, so that the heading updates are large.
    block, truth = stream(30.0, tumbling_rate(n), start=pose(25, -15, 90), noise=1.0, seed=3)
    with_field = QuaternionEKF().process(block).quat
    without = QuaternionEKF(magnetometer=False).process(block).quat
    # The heading did change...
    assert np.max(np.abs(angle_diff_deg(heading_deg(with_field), heading_deg(without)))) > 30
    # ...the tilt (up in the sensor frame) did not, to float precision.
    assert np.max(inclination_error_deg(with_field, without)) < 1e-6
    assert np.allclose(inclination_error_deg(with_field, truth),
                       inclination_error_deg(without, truth), atol=1e-6)


def test_no_field_gives_exactly_the_six_axis_filter():
    n = int(8 * RATE_HZ)
    block, _ = stream(8.0, tumbling_rate(n), start=pose(5, 30, 10), noise=1.0)
    no_mag = SampleBlock(block.t_s, block.accel_m_s2, block.gyro_rad_s, block.temp_degc,
                         block.gap)
    nan_mag = SampleBlock(block.t_s, block.accel_m_s2, block.gyro_rad_s, block.temp_degc,
                          block.gap, None, np.full((n, 3), np.nan))
    reference = QuaternionEKF().process(no_mag).quat
    switched_off = QuaternionEKF(magnetometer=False)
    assert np.array_equal(switched_off.process(block).quat, reference)
    assert switched_off.field_status is None
    nan_filter = QuaternionEKF()
    assert np.array_equal(nan_filter.process(nan_mag).quat, reference)
    assert np.all(nan_filter.field_status.status == NO_SAMPLE)


def test_state_continues_across_block_cuts():
    n = int(20 * RATE_HZ)
    block, _ = stream(20.0, tumbling_rate(n), start=pose(5, 30, 10), noise=1.0)
    whole = QuaternionEKF()
    expected = whole.process(block).quat
    pieces = QuaternionEKF()
    cuts = [0, 1, 17, 800, 801, n - 5, n]
    parts, status = [], []
    for a, b in itertools.pairwise(cuts):
        parts.append(pieces.process(slice_block(block, a, b)).quat)
        status.append(pieces.field_status.status)
    assert np.array_equal(np.concatenate(parts), expected)
    assert np.array_equal(np.concatenate(status), whole.field_status.status)


def test_switching_the_magnetometer_on_mid_stream_finds_north_at_once():
    block, truth = stream(6.0, start=pose(0, 0, 60))
    ekf = QuaternionEKF(magnetometer=False)
    ekf.process(slice_block(block, 0, 300))
    assert abs(angle_diff_deg(heading_deg(ekf.quaternion), heading_deg(truth[299]))) > 30
    ekf.set_parameter("magnetometer", True)
    out = ekf.process(slice_block(block, 300, 310)).quat
    assert np.max(np.abs(angle_diff_deg(heading_deg(out), heading_deg(truth[300:310])))) < 0.5


def test_a_field_that_jumps_is_rejected_and_the_gyro_holds_the_heading():
    seconds = 20.0
    n = int(seconds * RATE_HZ)
    field = np.tile(earth_field(), (n, 1))
    jump = slice(int(12 * RATE_HZ), int(16 * RATE_HZ))
    # A magnet nearby: the field 30 % stronger and turned 40 degrees east.
    field[jump] = earth_field(1.3 * FIELD_UT, DIP_DEG, 40.0)
    block, truth = stream(seconds, start=pose(0, 0, 30), field=field, noise=1.0)
    ekf = QuaternionEKF()
    out = ekf.process(block).quat
    status = ekf.field_status
    assert np.all(status.status[int(10 * RATE_HZ):jump.start] == OK)  # learnt at rest
    rejected = status.status[jump]
    assert np.mean(rejected == REJECTED) > 0.95
    error = np.abs(angle_diff_deg(heading_deg(out), heading_deg(truth)))
    assert np.max(error[jump]) < 0.5
    # Without rejection the heading is pulled toward the magnet's field.
    pulled = QuaternionEKF(mag_rejection=False).process(block).quat
    assert np.max(np.abs(angle_diff_deg(heading_deg(pulled[jump]), heading_deg(truth[jump])))
                  ) > 2.0
    # The reason, at the end of the disturbance, for the light.
    mid = QuaternionEKF()
    mid.process(slice_block(block, 0, jump.stop - 10))
    assert mid.field_status.disturbed
    assert mid.field_status.reason.startswith("field 30 % above normal")
    assert not ekf.field_status.disturbed  # back to normal by the end


def test_after_the_longest_rejection_the_field_is_used_at_reduced_weight():
    seconds = 16.0
    n = int(seconds * RATE_HZ)
    field = np.tile(earth_field(), (n, 1))
    field[int(10 * RATE_HZ):] = earth_field(1.3 * FIELD_UT, DIP_DEG, 40.0)
    block, _ = stream(seconds, start=pose(0, 0, 0), field=field)
    ekf = QuaternionEKF(mag_rejection_time=2.0)
    out = ekf.process(block).quat
    status = ekf.field_status.status
    assert np.all(status[int(10.1 * RATE_HZ):int(11.9 * RATE_HZ)] == REJECTED)
    assert np.all(status[int(12.2 * RATE_HZ):] == REDUCED)
    assert "reduced weight" in ekf.field_status.reason
    held = heading_deg(out[int(11.9 * RATE_HZ)])
    assert abs(angle_diff_deg(held, heading_deg(out[int(10 * RATE_HZ) - 1]))) < 0.5
    assert abs(angle_diff_deg(heading_deg(out[-1]), held)) > 1.0  # pulled, slowly


def test_a_dip_change_is_flagged_with_its_reason():
    seconds = 14.0
    n = int(seconds * RATE_HZ)
    field = np.tile(earth_field(), (n, 1))
    field[int(12 * RATE_HZ):] = earth_field(FIELD_UT, DIP_DEG + 15.0)
    block, _ = stream(seconds, start=pose(10, 0, 0), field=field)
    ekf = QuaternionEKF()
    ekf.process(block)
    assert ekf.field_status.disturbed
    assert "dip 15° steeper than normal" in ekf.field_status.reason
    assert "field" not in ekf.field_status.reason


def test_a_consistent_new_field_becomes_the_reference_while_turning():
    seconds = 45.0
    n = int(seconds * RATE_HZ)
    rate = np.zeros((n, 3))
    rate[:, 2] = math.radians(30.0)  # turning about the vertical, 30 dps
    rate[: int(8 * RATE_HZ)] = 0.0  # at rest first: the reference is learnt
    field = np.tile(earth_field(), (n, 1))
    field[int(10 * RATE_HZ):] = earth_field(0.8 * FIELD_UT, DIP_DEG - 4.0)  # another room
    block, _ = stream(seconds, rate, field=field)
    ekf = QuaternionEKF()
    ekf.process(block)
    status = ekf.field_status.status
    assert np.all(status[int(10.2 * RATE_HZ):int(25 * RATE_HZ)] == REJECTED)
    assert np.all(status[int(35 * RATE_HZ):] == OK)
    # The candidate is a 20 s low-pass of the new field, started as the field changed.
    assert ekf.field_status.reference.total_ut == pytest.approx(0.8 * FIELD_UT, rel=0.03)
    assert ekf.field_status.reference.source == "learnt while turning"


def test_the_first_reference_must_agree_with_the_world_magnetic_model():
    block, _ = stream(12.0, start=pose(0, 0, 0))
    agreeing = QuaternionEKF()
    agreeing.set_field_reference(FieldReference(FIELD_UT * 1.05, DIP_DEG + 2.0, "WMM test"))
    agreeing.process(block)
    assert agreeing.field_status.status[-1] == OK
    assert agreeing.field_status.reference.source == "learnt at rest"
    assert agreeing.field_status.wmm_message == ""
    far = QuaternionEKF()
    far.set_field_reference(FieldReference(FIELD_UT * 1.5, DIP_DEG, "WMM test"))
    far.process(block)
    assert far.field_status.status[-1] == LEARNING
    assert far.field_status.reference is None
    assert "learning" in far.field_status.reason


def test_reason_lines():
    ref = FieldReference(50.0, 60.0, "t", 0.1, 10.0)
    assert describe(REJECTED, 0.234, 1.0, ref) == "field 23 % above normal"
    assert describe(REJECTED, -0.5, -20.0, ref) == ("field 50 % below normal; dip 20° flatter "
                                                    "than normal")
    assert describe(OK, 0.5, 0.0, ref) == ""
    assert DisturbanceSettings().as_array()[-1] == 1.0
