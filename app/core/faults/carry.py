"""A gyro bias step while moving (issue 33): the gyro carries gravity, the accelerometer
measures it.

Per 0.25 s window the detector gives the gyro's rotation over the window (its learnt bias
removed) and the window's mean accelerometer reading turned into the window-start frame
sample by sample. Over the last ``HORIZON_S`` (8 s) those means are turned into the frame at
the horizon's start (the anchor) and summed over time: a velocity, ``V(t) = g t + v(t) -
v(0)``. Were the gyro right, the motion's own part ``v`` would stay bounded (a hand moves at
about 1 m/s) while gravity grows with t: this is the motion's acceleration averaged out, as
the filters do. A bias ``b`` left in the gyro turns the carried frame by ``theta(t) =
integral of C(s) b ds`` (C: sensor to anchor), which adds ``-[g]x N(t) b`` with ``N`` the
integral of ``theta``'s kernel: 2 dps over 8 s moves V by 11 m/s, hand motion by 1. Least
squares over the horizon for g, v(0) and b gives b and its standard error from the scatter.

A step is declared when an axis's ``b`` exceeds ``STEP_RAD_S`` (1.6 dps, 80 % of the 2 dps to
find; slow translation by hand scatters ``b`` by up to 1.3 dps over 8 s, the simulator's
magtour by 1.4, the turn-on bias is
learnt at rest and drifts 0.01 dps/K) and ``SIGNIFICANCE`` (3) standard errors, in
``CONFIRM`` windows running (1 s). Each axis's scale error is solved for with the bias
(its turn adds ``C diag(angle turned) s``): a hand turning fast back and forth makes a
scale error of 1 % look like a bias of up to 0.5 dps otherwise, while a bias keeps adding up
whichever way the hand turns. The component of ``b`` along gravity moves nothing
while the sensor keeps its attitude: a small ridge keeps that part at zero until the
rotation makes it seen. Without a magnetometer the vertical axis's bias is found only as the
sensor turns.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

HORIZON_S = 8.0
MIN_S = 4.0
STEP_RAD_S = math.radians(1.6)
SIGNIFICANCE = 3.0
CONFIRM = 4
RIDGE = 1e-3
"""Relative to the largest eigenvalue of the normal equations' bias block."""


def _rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class GravityCarry:
    """The sliding least-squares test of the module docstring, window by window."""

    def __init__(self) -> None:
        self.restart()

    def restart(self) -> None:
        """Forget the horizon (a gap, a new reference bias)."""
        self._windows: deque[tuple[np.ndarray, np.ndarray, float, np.ndarray]] = deque()
        self._span = 0.0
        self._hits = 0
        self.estimate = np.zeros(3)
        self.error = np.full(3, np.inf)

    def push(self, rotation: np.ndarray, accel: np.ndarray, duration: float
             ) -> tuple[int, np.ndarray] | None:
        """One window: its rotation quaternion (window start to end), its mean accelerometer
        in the window-start frame, its length. Returns (axis, bias step in rad/s, (3,)) when a
        step is declared, else None."""
        if not (duration > 0 and np.all(np.isfinite(accel)) and np.all(np.isfinite(rotation))):
            self.restart()
            return None
        half = float(np.clip(rotation[0], -1.0, 1.0))
        sine = float(np.linalg.norm(rotation[1:]))
        turned = (2.0 * math.atan2(sine, half) / sine * rotation[1:] if sine > 1e-12
                  else 2.0 * rotation[1:])
        self._windows.append((_rotation(rotation), accel.copy(), duration, turned))
        self._span += duration
        while self._span - self._windows[0][2] >= HORIZON_S:
            self._span -= self._windows.popleft()[2]
        if self._span < MIN_S:
            return None
        self._solve()
        big = (np.abs(self.estimate) > STEP_RAD_S) & (np.abs(self.estimate)
                                                    > SIGNIFICANCE * self.error)
        self._hits = self._hits + 1 if big.any() else 0
        if self._hits < CONFIRM:
            return None
        axis = int(np.argmax(np.where(big, np.abs(self.estimate), 0.0)))
        return axis, self.estimate.copy()

    def _solve(self) -> None:
        k = len(self._windows)
        velocity = np.empty((k, 3))
        drift = np.empty((k, 3, 6))
        elapsed = np.empty(k)
        turn = np.eye(3)
        angle = np.zeros((3, 6))
        summed = np.zeros(3)
        drifted = np.zeros((3, 6))
        clock = 0.0
        for i, (rotation, accel, duration, turned) in enumerate(self._windows):
            step = np.hstack([duration * turn, turn * turned])  # bias, scale error
            summed = summed + duration * (turn @ accel)
            drifted = drifted + duration * (angle + 0.5 * step)
            angle = angle + step
            clock += duration
            velocity[i], drift[i], elapsed[i] = summed, drifted, clock
            turn = turn @ rotation
        # first gravity and the start velocity alone, then with the bias and scale errors
        plain = np.zeros((3 * k, 6))
        plain[:, :3] = np.kron(elapsed[:, None], np.eye(3))
        plain[:, 3:] = np.tile(np.eye(3), (k, 1))
        y = velocity.reshape(3 * k)
        gravity = np.linalg.lstsq(plain, y, rcond=None)[0][:3]
        design = np.zeros((3 * k, 12))
        design[:, :6] = plain
        design[:, 6:] = (-_skew(gravity) @ drift).reshape(3 * k, 6)
        normal = design.T @ design
        for part in (slice(6, 9), slice(9, 12)):
            block = normal[part, part]
            normal[part, part] += RIDGE * max(float(np.linalg.eigvalsh(block)[-1]),
                                              1e-12) * np.eye(3)
        try:
            inverse = np.linalg.inv(normal)
        except np.linalg.LinAlgError:
            return
        solution = inverse @ (design.T @ y)
        residual = y - design @ solution
        variance = float(residual @ residual) / max(3 * k - 12, 1)
        self.estimate = solution[6:9]
        self.error = np.sqrt(np.maximum(np.diag(inverse)[6:9] * variance, 1e-300))
