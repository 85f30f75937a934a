"""The 9-axis (MARG) forms of Madgwick and Mahony: against the ``ahrs`` package, the frame
(ENU, y toward magnetic north), a slow magnetometer, restarts, and the 6-axis form unchanged.

The ``ahrs`` package is the independent reference. Its Madgwick MARG uses the report's
reference ``b = (b_x, 0, b_z)``: an earth frame with x toward magnetic north and z up (NWU), so
its quaternion is ours turned by -90 degrees about the vertical: ``q_ENU = z90 (x) q_NWU``. Its
Mahony MARG already puts the reference on +y (``(0, |h_xy|, h_z)``): ENU, as ours.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.filters.madgwick import MadgwickFilter, _madgwick_marg_kernel, madgwick_marg_step
from app.core.filters.mahony import MahonyFilter, _mahony_marg_kernel
from app.core.heading_metrics import heading_error_deg
from app.core.orientation import inclination_error_deg
from app.core.samples import SampleBlock
from drivers.sim.scenarios import SCENARIOS

ahrs_filters = pytest.importorskip("ahrs.filters")

DT = 1.0 / 256.0
EARTH_FIELD_UT = np.array([0.0, 19.0, -45.0])  # ENU: north and down, a mid-latitude field
Z90 = quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.pi / 2)
MARG_CLASSES = (MadgwickFilter, MahonyFilter)
CHATTER = 2.0 * 0.041 * DT
"""Madgwick's chatter about a converged estimate, about 2 beta dt (rad) at the default beta."""


def same_sign_as(reference: np.ndarray, q: np.ndarray) -> np.ndarray:
    return q * np.sign(np.sum(q * reference, axis=-1, keepdims=True))


@pytest.fixture(scope="module")
def wobble():
    """12 s of hand-held wobble with a gyro bias and a field every sample, 256 Hz; the start
    is 40 degrees off (tilt and heading)."""
    t = np.arange(1, 3073) * DT
    motion = SCENARIOS["wobble"](np.random.default_rng(3), amplitude=8.0, shake=0.2).motion(t)
    q = motion.orientation_quat
    accel = quat.rotate_inverse(q, np.array([0.0, 0.0, 9.80665]) + motion.linear_accel_m_s2)
    gyro = motion.angular_rate_rad_s + np.array([0.01, -0.02, 0.015])
    field = quat.rotate_inverse(q, EARTH_FIELD_UT)
    n = len(t)
    block = SampleBlock(t, accel, gyro, np.full(n, 25.0), np.zeros(n, bool), q, field)
    q0 = quat.multiply(q[0], quat.from_axis_angle(np.array([1.0, 2.0, 0.5]), np.radians(40.0)))
    return block, q, q0


def run_from(f, q0, block):
    f.reset(q0, last_time_s=float(block.t_s[0]) - DT)
    return f.process(block).quat


def ahrs_marg(cls, block: SampleBlock, q0: np.ndarray, **gains) -> tuple[np.ndarray, object]:
    """ahrs over the block, from q0 one step before it (row 0 is a placeholder)."""
    pad = [np.vstack([x[:1], x]) for x in (block.gyro_rad_s, block.accel_m_s2, block.mag_ut)]
    ref = cls(gyr=pad[0], acc=pad[1], mag=pad[2], q0=q0, Dt=DT, **gains)
    return ref.Q[1:], ref


def test_madgwick_marg_steps_the_way_ahrs_does_in_its_frame():
    """Each update moves q in the direction of ahrs's (its NWU frame turned to ENU).

    Only the direction on the unit sphere can agree: Madgwick's objective is written for a unit
    quaternion (``2 (0.5 - x^2 - y^2)`` for ``w^2 - x^2 - y^2 + z^2``), so its gradient has a
    radial part that depends on the frame the reference lies in; the normalised step's length
    along the sphere differs with it, its direction does not. Random poses and measurements,
    far from convergence, zero rate (ahrs skips an exactly zero one: 1e-100), tiny dt.
    """
    rng = np.random.default_rng(5)
    reference = ahrs_filters.Madgwick(gain=1.0)
    dt = 1e-7
    for _ in range(50):
        q = quat.normalize(rng.normal(size=4))
        accel, field = rng.normal(size=3) * 9.0, rng.normal(size=3) * 40.0
        ours = madgwick_marg_step(*q, 0.0, 0.0, 0.0, *accel, *field, 1.0, dt)
        theirs = quat.multiply(Z90, reference.updateMARG(
            quat.multiply(quat.conjugate(Z90), q), np.array([1e-100, 0.0, 0.0]), accel, field,
            dt=dt))
        directions = []
        for result in (np.asarray(ours), theirs):
            result = result * np.sign(result @ q)
            step = result - q * (result @ q)  # the tangential part
            directions.append(step / np.linalg.norm(step))
        np.testing.assert_allclose(directions[0], directions[1], rtol=0, atol=1e-7)


def test_a_madgwick_marg_run_ends_where_ahrs_ends(wobble):
    """The whole run, update by update from ahrs's start (ahrs's batch form ignores q0 with a
    field: its updateMARG is called per sample): the two meet the truth alike."""
    block, q_true, q0 = wobble
    reference = ahrs_filters.Madgwick(gain=0.1)
    theirs = np.empty((len(block), 4))
    q = quat.multiply(quat.conjugate(Z90), q0)
    for k in range(len(block)):
        q = reference.updateMARG(q, block.gyro_rad_s[k], block.accel_m_s2[k], block.mag_ut[k],
                                 dt=DT)
        theirs[k] = q
    theirs = quat.multiply(np.broadcast_to(Z90, theirs.shape), theirs)
    ours = run_from(MadgwickFilter(beta=0.1), q0, block)
    # Step lengths differ while converging (see above): the two part by up to a few degrees,
    # then meet again.
    assert quat.angle_between(ours, theirs)[-256:].max() < np.radians(0.5)
    heading = heading_error_deg(ours, q_true)
    assert heading[0] > 10.0 and heading[-256:].max() < 3.0


def test_mahony_marg_matches_ahrs_and_learns_the_same_bias(wobble):
    block, q_true, q0 = wobble
    f = MahonyFilter(kp=1.0, ki=0.3, exact_integration=False)
    ours = run_from(f, q0, block)
    expected, ref = ahrs_marg(ahrs_filters.Mahony, block, q0, k_P=1.0, k_I=0.3)
    np.testing.assert_allclose(ours, same_sign_as(ours, expected), rtol=0, atol=1e-9)
    np.testing.assert_allclose(f.gyro_bias_rad_s, ref.b, rtol=0, atol=1e-9)
    heading = heading_error_deg(ours, q_true)
    assert heading[0] > 10.0 and heading[-256:].max() < 3.0  # the field found north


def static_block(accel: np.ndarray, field: np.ndarray, n: int = 512) -> SampleBlock:
    t = np.arange(n) * DT
    return SampleBlock(t, np.tile(accel, (n, 1)), np.zeros((n, 3)), np.full(n, 25.0),
                       np.zeros(n, bool), None, np.tile(field, (n, 1)))


@pytest.mark.parametrize("cls", MARG_CLASSES)
def test_a_level_sensor_pointing_30_degrees_east_of_north_reads_so(cls):
    """Written without quaternions: level, the sensor's y axis 30 deg east of magnetic north,
    so its x axis points to azimuth 120 deg; the field (19 uT north, 45 uT down) then reads
    19 (cos 120, cos 30, 0) + (0, 0, -45) in the sensor frame. ENU with y north: the sensor's
    y axis must come out as (sin 30, cos 30, 0)."""
    field = np.array([19.0 * np.cos(np.radians(120.0)), 19.0 * np.cos(np.radians(30.0)), -45.0])
    out = cls().process(static_block(np.array([0.0, 0.0, 9.80665]), field)).quat
    for q in (out[0], out[-1]):
        y_earth = quat.rotate(q, np.array([0.0, 1.0, 0.0]))
        np.testing.assert_allclose(y_earth, [0.5, np.cos(np.radians(30.0)), 0.0], atol=CHATTER)


@pytest.mark.parametrize("cls", MARG_CLASSES)
def test_a_tilted_known_pose_has_its_heading_from_the_first_sample(cls):
    """Tilted 25 deg and turned: the first sample takes tilt from the accelerometer and
    heading from the field, and the estimate stays there (Madgwick chatters by about beta dt)."""
    true = quat.multiply(quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(-30.0)),
                         quat.from_axis_angle(np.array([1.0, 0.2, 0.0]), np.radians(25.0)))
    block = static_block(quat.rotate_inverse(true, np.array([0.0, 0.0, 9.80665])),
                         quat.rotate_inverse(true, EARTH_FIELD_UT))
    out = cls().process(block).quat
    reference = np.tile(true, (len(out), 1))
    assert heading_error_deg(out[:1], reference[:1])[0] < 1e-9
    assert heading_error_deg(out, reference).max() < np.degrees(CHATTER)
    assert inclination_error_deg(out, reference).max() < np.degrees(CHATTER)


@pytest.mark.parametrize("cls", MARG_CLASSES)
def test_a_slow_magnetometer_held_between_samples_tracks_heading(cls, wobble):
    """A field only every 8th row (NaN between): the held sample, carried by the gyro, gives
    nearly what a field every row gives."""
    block, _, q0 = wobble
    sparse = block.mag_ut.copy()
    sparse[np.arange(len(sparse)) % 8 != 0] = np.nan
    every = run_from(cls(), q0, block)
    slow = run_from(cls(), q0, dataclasses.replace(block, mag_ut=sparse))
    assert quat.angle_between(every, slow)[256:].max() < np.radians(0.5)


@pytest.mark.parametrize("cls", MARG_CLASSES)
def test_without_a_field_or_switched_off_the_6_axis_form_runs_unchanged(cls, wobble):
    block, _, q0 = wobble
    six = run_from(cls(), q0, dataclasses.replace(block, mag_ut=None))
    off = run_from(cls(magnetometer=False), q0, block)
    nine = run_from(cls(), q0, block)
    np.testing.assert_array_equal(six, off)
    assert quat.angle_between(six, nine).max() > np.radians(5.0)


@pytest.mark.parametrize("cls", MARG_CLASSES)
def test_blocks_cut_anywhere_and_a_gap_give_the_same_output(cls, wobble):
    block, _, _ = wobble
    gap = block.gap.copy()
    gap[1500] = True
    stream = dataclasses.replace(block, gap=gap)
    whole = cls().process(stream).quat
    f = cls()
    cuts = [0, 1, 5, 300, 1499, 1500, 1501, 2000, len(block)]
    pieces = [f.process(SampleBlock(*(None if x is None else x[a:b]
                                      for x in dataclasses.astuple(stream)))).quat
              for a, b in itertools.pairwise(cuts)]
    np.testing.assert_array_equal(np.concatenate(pieces), whole)


@pytest.mark.parametrize("cls", MARG_CLASSES)
def test_warm_up_compiles_the_marg_kernel_and_leaves_the_state_alone(cls, wobble):
    block, _, _ = wobble
    half = len(block) // 2
    parts = [SampleBlock(*(None if x is None else x[a:b] for x in dataclasses.astuple(block)))
             for a, b in ((0, half), (half, len(block)))]
    plain = cls()
    expected = np.concatenate([plain.process(p).quat for p in parts])
    warmed = cls()
    warmed.warm_up()
    first = warmed.process(parts[0]).quat
    warmed.warm_up()
    second = warmed.process(parts[1]).quat
    np.testing.assert_array_equal(np.concatenate([first, second]), expected)
    kernel = _madgwick_marg_kernel if cls is MadgwickFilter else _mahony_marg_kernel
    assert kernel.signatures  # compiled for the field's types
