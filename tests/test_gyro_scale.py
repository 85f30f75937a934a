"""Gyroscope scale and misalignment from whole turns, the accelerometer as the reference angle
(app.core.calibration_procedures.gyro_scale and `inclinometer calibrate-gyro-scale`)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from app.cli import main
from app.core import quaternion as quat
from app.core.calibration_procedures.gyro_scale import GyroScaleError, fit_gyro_scale
from app.core.recording import UNIT_SCALE, RecordingWriter, recording_metadata
from app.core.recording.reader import read_recording
from app.core.samples import RawBlock
from drivers.base import DeviceInfo

RATE_HZ = 208.0
G = 9.80665
# A gyroscope that reads 1.2 % too much about x, 0.7 % too little about y, with misalignments
# of some 0.2 degrees: what a MEMS part does.
TRUE_M = np.array([[1.012, 0.003, -0.002],
                   [-0.004, 0.993, 0.0035],
                   [0.0025, -0.003, 1.004]])
BIAS = np.radians([0.4, -0.7, 0.25])


def session(steps, seed=1, m=TRUE_M, noise=True):
    """Rests and turns: ``steps`` of (axis, degrees, seconds), each after 1.5 s of rest."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE_HZ
    q = np.array([1.0, 0.0, 0.0, 0.0])
    t_all, accel_all, gyro_all = [], [], []
    t = 0.0

    def emit(omega_body):
        nonlocal q, t
        for w in omega_body:
            q = quat.normalize(quat.multiply(q, quat.from_rotation_vector(w * dt)))
            f = quat.rotate_inverse(q, np.array([0.0, 0.0, G]))
            gyro = m @ w + BIAS
            if noise:
                f = f + rng.normal(scale=0.01, size=3)
                gyro = gyro + rng.normal(scale=math.radians(0.05), size=3)
            t_all.append(t)
            accel_all.append(f)
            gyro_all.append(gyro)
            t += dt

    rest = int(1.5 * RATE_HZ)
    for axis, degrees, seconds in steps:
        emit(np.zeros((rest, 3)))
        n = int(seconds * RATE_HZ)
        s = (np.arange(n) + 0.5) / n
        rate = math.radians(degrees) / seconds * (1 - np.cos(2 * np.pi * s))  # smooth start, stop
        omega = np.zeros((n, 3))
        omega[:, axis] = rate
        emit(omega)
    emit(np.zeros((rest, 3)))
    return np.array(t_all), np.array(accel_all), np.array(gyro_all)


# Flat: turn about x, then y; laid on its side (x by 90), the z axis lies horizontal: turn it.
PROCEDURE = [(0, 360.0, 4.0), (1, -360.0, 4.0), (0, 90.0, 1.0), (2, 720.0, 6.0)]


def test_whole_turns_give_the_gyroscopes_scale_and_misalignment():
    result = fit_gyro_scale(*session(PROCEDURE))
    used = [turn for turn in result.turns if turn.used]
    assert [(turn.axis, turn.turns) for turn in used] == [(0, 1), (1, -1), (2, 2)]
    np.testing.assert_allclose(result.measured, TRUE_M, atol=3e-4)
    np.testing.assert_allclose(result.matrix @ TRUE_M, np.eye(3), atol=4e-4)
    np.testing.assert_allclose(result.scale_error_pct, [1.2, -0.7, 0.4], atol=0.03)
    np.testing.assert_allclose(result.bias_rad_s, BIAS, atol=math.radians(0.01))


def test_a_turn_the_accelerometer_cannot_see_or_not_whole_is_refused_with_the_reason():
    # Flat, a turn about z is about the vertical; a 330 degree roll about x is not whole.
    turns = fit_gyro_scale_turns([(2, 360.0, 4.0), (0, 330.0, 4.0)])
    assert "out of the horizontal" in turns[0].refused
    assert "same pose" in turns[1].refused or "whole turns" in turns[1].refused
    with pytest.raises(GyroScaleError, match="no whole turn about x, y, z"):
        fit_gyro_scale(*session([(2, 360.0, 4.0), (0, 330.0, 4.0)]))


def fit_gyro_scale_turns(steps):
    from app.core.calibration_procedures.gyro_scale import find_turns

    return find_turns(*session(steps))[0]


def test_a_gyroscope_off_by_more_than_a_turn_is_refused():
    # A gyroscope reading 40 % too much counts 504 degrees for the accelerometer's 360.
    t, a, g = session([(0, 360.0, 4.0)], m=np.diag([1.4, 1.0, 1.0]))
    from app.core.calibration_procedures.gyro_scale import find_turns

    (turn,), _ = find_turns(t, a, g)
    assert "counted" in turn.refused and round(turn.accel_angle_deg) in range(350, 371)


def write_recording(path, t, accel, gyro):
    info = DeviceInfo("sim://static", "Bench unit", "UID-7", "LSM6DSOX", RATE_HZ, 208.0, 4, 250)
    writer = RecordingWriter(path, recording_metadata(device=info)).start()
    n = len(t)
    writer.write(RawBlock(t, accel, gyro, np.full(n, 25.0), UNIT_SCALE, np.zeros(n, bool)))
    assert writer.close().state == "stopped"


def test_the_command_writes_the_gyro_matrix_and_refuses_to_overwrite(tmp_path, capsys):
    t, a, g = session(PROCEDURE, seed=4)
    rec = tmp_path / "turns.csv"
    write_recording(rec, t, a, g)
    out = tmp_path / "gyro.json"
    assert main(["calibrate-gyro-scale", str(rec), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "scale error (x y z)" in printed and printed.count("used") == 3
    document = json.loads(out.read_text())
    np.testing.assert_allclose(document["gyro_scale"]["scale_error_pct"], [1.2, -0.7, 0.4],
                               atol=0.05)
    matrix = np.array(document["gyro_matrix"])
    np.testing.assert_allclose(matrix @ TRUE_M, np.eye(3), atol=5e-4)
    assert main(["calibrate-gyro-scale", str(rec), "--json", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert read_recording(rec).t_s.shape == t.shape  # the input is untouched
