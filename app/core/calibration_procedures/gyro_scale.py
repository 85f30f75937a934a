"""Gyroscope scale factors and axis misalignment from whole turns (Ferraris et al. 1995).

The procedure: lay the sensor on a flat surface, hold it still, roll it one whole turn (or
several) about one of its axes lying horizontal, hold it still again; then the same about its
other two axes. Between two rests, the gyroscope's integral is

    integral (w_raw - b) dt = M theta,        theta = 2 pi n e_i (turns n about axis i)

with ``b`` the bias (the rests' mean rate) and ``M`` the gyroscope's scale-and-misalignment
matrix. Each turn gives one column of ``M``; the correction the calibration stage applies is
``G = M^-1`` (``w_cal = G (w_raw - b)``). This is the rotation part of Ferraris' procedure as
the ``imucal`` package implements it, with the turn angle known from the accelerometer instead
of a turntable.

**The accelerometer is the reference angle.** The turn axis lies horizontal, so gravity turns
in the sensor's plane across that axis, once per turn: tracked (low-passed, unwrapped) it says
how many whole turns were made, and the two rests' gravity directions must agree (the sensor
is back in its pose). A turn is refused, with the reason, when

- the rests before and after disagree by more than :data:`SAME_POSE_DEG` (not back in place);
- the turn axis is more than :data:`AXIS_TILT_DEG` out of the horizontal (gravity cannot see a
  turn about the vertical);
- the accelerometer's angle is more than :data:`ANGLE_TOLERANCE_DEG` from whole turns, or
  the gyroscope's angle more than :data:`MAX_SCALE_ERROR` from the accelerometer's;
- the turn is not about one sensor axis (its off-axis part over :data:`OFF_AXIS_LIMIT`).

Scale errors of a MEMS gyroscope are a few 0.1 % to 1 %, misalignments some 0.1 degrees:
the integral over a whole turn resolves them to about the gyroscope's noise over the turn's
seconds, far below (one turn of 4 s at 0.004 dps/sqrt(Hz) is 0.008 degrees: 2e-5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

REST_RATE_DPS = 2.0
"""Below this rate (after the bias, smoothed over :data:`SMOOTH_S`) the sensor is at rest."""
ROUGH_RATE_DPS = 2.5
SMOOTH_S = 0.2
MIN_REST_S = 0.8
"""A rest shorter than this does not separate two turns (a pause mid-roll)."""
MIN_TURN_DEG = 300.0
"""A motion whose gyroscope angle is below this is not a turn (a nudge): left out, noted."""
SAME_POSE_DEG = 3.0
AXIS_TILT_DEG = 20.0
ANGLE_TOLERANCE_DEG = 12.0
OFF_AXIS_LIMIT = 0.1
MAX_SCALE_ERROR = 0.1
"""A gyroscope more than 10 % off is not a scale error to correct (the LSM6DSOX's is within
+-1 %): a wrong full-scale setting or a slip of the turn; refused."""
ACCEL_TAU_S = 0.05
AXES = "xyz"


class GyroScaleError(ValueError):
    """The recording does not give a gyroscope scale calibration (the message says why)."""


@dataclass(frozen=True)
class Turn:
    """One motion between two rests and what the procedure made of it."""

    start_s: float
    end_s: float
    axis: int
    """The sensor axis turned about (0, 1, 2), -1 when unclear."""
    turns: int
    """Whole turns, signed (right-handed about +axis), by the accelerometer."""
    gyro_angle_deg: np.ndarray
    """The integrated rate over the motion, bias removed (3,)."""
    accel_angle_deg: float
    """The accelerometer's tracked angle about the axis (its sign as the gyroscope's)."""
    refused: str = ""
    """Why the turn is not used; empty when it is."""

    @property
    def used(self) -> bool:
        return not self.refused


@dataclass(frozen=True)
class GyroScaleResult:
    """``matrix`` is ``G`` (the correction, ``w_cal = G (w_raw - b)``); ``measured`` is ``M``."""

    matrix: np.ndarray
    measured: np.ndarray
    bias_rad_s: np.ndarray
    turns: list[Turn] = field(default_factory=list)

    @property
    def scale_error_pct(self) -> np.ndarray:
        """Each axis's scale error: how much too much it reads (+) or too little (-), in %."""
        return (np.diag(self.measured) - 1.0) * 100.0

    @property
    def misalignment_deg(self) -> np.ndarray:
        """The off-diagonal part of ``M`` as small angles (3, 3), degrees (0 on the diagonal)."""
        off = self.measured - np.diag(np.diag(self.measured))
        return np.degrees(off)


def _smooth(values: np.ndarray, width: int) -> np.ndarray:
    if width <= 1:
        return values
    kernel = np.ones(width) / width
    return np.stack([np.convolve(values[:, k], kernel, mode="same")
                     for k in range(values.shape[1])], axis=1)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index pairs of the True runs of ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def _lowpass(t: np.ndarray, x: np.ndarray, tau: float) -> np.ndarray:
    out = np.empty_like(x)
    out[0] = x[0]
    for i in range(1, len(x)):
        k = min(1.0, max(0.0, (t[i] - t[i - 1]) / tau))
        out[i] = out[i - 1] + k * (x[i] - out[i - 1])
    return out


def find_turns(t_s: np.ndarray, accel: np.ndarray, gyro_rad_s: np.ndarray
               ) -> tuple[list[Turn], np.ndarray]:
    """The motions between rests of a recording, judged; and the bias (rad/s) of its rests."""
    t = np.asarray(t_s, dtype=np.float64)
    gyro = np.asarray(gyro_rad_s, dtype=np.float64)
    accel = np.asarray(accel, dtype=np.float64)
    if len(t) < 10:
        raise GyroScaleError("too few samples for a turn")
    period = float(np.median(np.diff(t)))
    if not period > 0:
        raise GyroScaleError("the time column does not increase")
    width = max(1, round(SMOOTH_S / period))
    # The bias is well under the rest threshold (about 1 dps for a MEMS part): the slow
    # samples' median is a first guess good enough to find the rests.
    near = np.linalg.norm(gyro, axis=1) < math.radians(2 * ROUGH_RATE_DPS)
    rough = np.median(gyro[near], axis=0) if near.any() else np.zeros(3)
    slow = np.linalg.norm(_smooth(gyro - rough, width), axis=1) < math.radians(REST_RATE_DPS)
    rests = [(a, b) for a, b in _runs(slow) if t[b - 1] - t[a] >= MIN_REST_S]
    if len(rests) < 2:
        raise GyroScaleError("no two rests in the recording: hold the sensor still before and "
                             "after each turn")
    # The bias from each rest's core: the smoothing lets a rest run into a turn's slow start.
    cores = [gyro[a + width:b - width] for a, b in rests if b - a > 3 * width]
    bias = np.mean(np.concatenate(cores or [gyro[a:b] for a, b in rests]), axis=0)
    turns = [_judge(t, accel, gyro - bias, before, after)
             for before, after in pairwise(rests)]
    return [turn for turn in turns if turn is not None], bias


def _judge(t: np.ndarray, accel: np.ndarray, rate: np.ndarray, before: tuple[int, int],
           after: tuple[int, int]) -> Turn | None:
    # From the middle of one rest to the middle of the next: the whole motion, its slow start
    # and end included (the rests add their noise only, the bias taken out).
    start, end = (before[0] + before[1]) // 2, (after[0] + after[1]) // 2 + 1
    span = slice(start, end)
    dt = np.diff(t[span])
    integral = np.sum(0.5 * (rate[span][1:] + rate[span][:-1]) * dt[:, None], axis=0)
    size = float(np.linalg.norm(integral))
    angle_deg = np.degrees(integral)
    if math.degrees(size) < MIN_TURN_DEG:
        return None
    axis = int(np.argmax(np.abs(integral)))
    unit = integral / size

    def turn(refused: str, turns: int = 0, accel_deg: float = math.nan, ax: int = axis) -> Turn:
        return Turn(float(t[start]), float(t[end - 1]), ax, turns, angle_deg, accel_deg, refused)

    g0 = accel[before[0]:before[1]].mean(axis=0)
    g1 = accel[after[0]:after[1]].mean(axis=0)
    apart = math.degrees(math.acos(np.clip(g0 @ g1 / (np.linalg.norm(g0) * np.linalg.norm(g1)),
                                           -1.0, 1.0)))
    if apart > SAME_POSE_DEG:
        return turn(f"not back in the same pose (the rests' gravity {apart:.1f} deg apart)")
    off_axis = math.sqrt(max(0.0, 1.0 - unit[axis] ** 2))
    if off_axis > OFF_AXIS_LIMIT:
        return turn(f"not about one sensor axis ({off_axis:.0%} of the turn off {AXES[axis]})",
                    ax=-1)
    tilt = math.degrees(math.asin(min(1.0, abs(g0 @ unit) / np.linalg.norm(g0))))
    if tilt > AXIS_TILT_DEG:
        return turn(f"the axis {AXES[axis]} was {tilt:.0f} deg out of the horizontal: the "
                    "accelerometer cannot see a turn about the vertical")
    # Gravity in the sensor's plane across the axis turns against the sensor's turn.
    p = np.cross(unit, [1.0, 0.0, 0.0] if abs(unit[0]) < 0.9 else [0.0, 1.0, 0.0])
    p /= np.linalg.norm(p)
    q = np.cross(unit, p)
    a = _lowpass(t[span], accel[span], ACCEL_TAU_S)
    tracked = np.unwrap(np.arctan2(a @ q, a @ p))
    accel_deg = -math.degrees(float(tracked[-1] - tracked[0]))
    gyro_deg = float(np.degrees(integral @ unit))
    turns = round(accel_deg / 360.0)
    if turns == 0 or abs(accel_deg - 360.0 * turns) > ANGLE_TOLERANCE_DEG:
        return turn(f"the accelerometer saw {accel_deg:.0f} deg, not whole turns", 0, accel_deg)
    if abs(gyro_deg / (360.0 * turns) - 1.0) > MAX_SCALE_ERROR:
        return turn(f"the gyroscope counted {gyro_deg:.0f} deg against the accelerometer's "
                    f"{accel_deg:.0f}: more off than a scale error (a wrong range setting, "
                    "or a slip)", turns, accel_deg)
    sign = 1 if integral[axis] > 0 else -1
    return Turn(float(t[start]), float(t[end - 1]), axis, sign * abs(turns), angle_deg,
                accel_deg)


def fit_gyro_scale(t_s: np.ndarray, accel: np.ndarray, gyro_rad_s: np.ndarray
                   ) -> GyroScaleResult:
    """``G`` from the whole turns in a recording: at least one turn about each sensor axis
    (several about one axis are averaged). Raises :class:`GyroScaleError` with the reason (a
    missing axis, the refused turns) when they do not give one."""
    turns, bias = find_turns(t_s, accel, gyro_rad_s)
    columns: list[list[np.ndarray]] = [[], [], []]
    for turn in turns:
        if turn.used:
            columns[turn.axis].append(np.radians(turn.gyro_angle_deg) / (2 * math.pi * turn.turns))
    missing = [AXES[i] for i in range(3) if not columns[i]]
    if missing:
        reasons = "; ".join(f"{x.start_s:.1f}-{x.end_s:.1f} s: {x.refused}"
                            for x in turns if not x.used)
        raise GyroScaleError(
            f"no whole turn about {', '.join(missing)} (found {sum(x.used for x in turns)} "
            f"usable of {len(turns)})" + (f"; refused: {reasons}" if reasons else ""))
    measured = np.column_stack([np.mean(c, axis=0) for c in columns])
    if np.linalg.cond(measured) > 10.0:
        raise GyroScaleError("the turns do not give an invertible matrix")
    return GyroScaleResult(np.linalg.inv(measured), measured, bias, turns)
