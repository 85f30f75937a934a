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

**Gravity alone: the displacement must agree.** A hard stroke of the hand at the horizon's end
moves the velocity by metres per second within half a second, where the bias's drift weighs
most, and the fit takes it for a bias (an hour of the simulator's translation raised four 2-3
dps steps, with an ideal chip as well). Summed once more, the velocity is a displacement: a hand
keeps the sensor within reach while a bias's drift grows as t^3 (1.6 dps over 8 s: 20 m). So
without the field a step is declared only where the displacement's own fit (gravity, start
velocity and position free, the same ridge) gives the same sign and at least ``AGREEMENT``
(half) of ``STEP_RAD_S`` on that axis. The displacement does not replace the velocity: its
white-noise scatter overstates its weight, and in the joint fit it drowned the field (clean
BROAD 26 raised two vertical steps), so the field's fit keeps the velocity.

**With the field.** The gyro carries the earth's field as well, and the magnetometer measures
it: per window the mean field, turned sample by sample into the window-start frame, then into
the anchor frame, ``F_i = m0 - [m0]x A_i (b, s)`` with ``A_i`` the bias and scale error's turn
at the window's middle. A static vector, so no motion term: the field part needs no velocity
sum. Gravity sees the bias across gravity, the field across the field; together, every axis,
the vertical one while the attitude is held. The two parts are weighed each by its own residual
scatter (the field's at least ``FIELD_FLOOR_UT``, and times ``(1 + r) / (1 - r)`` for the
lag-1 correlation ``r`` of its residual: calibration errors and field gradients are smooth in
time, so windows in a row are not independent evidence). With the field the ridge gives way
to priors: the bias within 10 dps (``BIAS_PRIOR_RAD_S``), the scale error within 3 %
(``SCALE_ERROR``; without it a bias's own turn, when the hand holds still, passes for a
scale error). No hard iron is solved for: within
8 s a field fixed to the sensor differs from the earth's only by the turn, and a bias's turn
would be taken for it. The field must therefore come calibrated; the detector
(:mod:`app.core.faults.detector`) passes it only while the magnetic disturbance detector calls
it undisturbed, no magnetometer axis is faulty, and the window turns slower than 200 dps.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

HORIZON_S = 8.0
MIN_S = 4.0
STEP_RAD_S = math.radians(1.6)
SIGNIFICANCE = 3.0
FIELD_SIGNIFICANCE = 5.0
"""Standard errors a step needs when the field is in the fit: its residual stays correlated
beyond the lag-1 correction, and with priors in place of the ridge an axis both references
see weakly can wander (clean BROAD 04 and 32, held out, reached 3.9 and 4.3); a 2 dps step
on an axis either reference sees stood at 8-26 standard errors on the tuning trials."""
CONFIRM = 4
AGREEMENT = 0.5
"""Gravity alone: a step is declared only where the displacement's bias has the velocity's
sign and at least this share of ``STEP_RAD_S`` (module docstring)."""
RIDGE = 1e-3
"""Relative to the largest eigenvalue of the normal equations' bias block."""


_CAPACITY = 64
"""Windows the horizon's arrays hold at first (8 s of 0.25 s windows: 33); they grow."""
_EYE3 = np.eye(3)


def rotation_matrix(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of unit quaternion ``q`` (w, x, y, z)."""
    w, x, y, z = q.tolist()  # Python floats: the same arithmetic, without numpy scalars
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _skew(v: np.ndarray) -> np.ndarray:
    x, y, z = v.tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


class GravityCarry:
    """The sliding least-squares test of the module docstring, window by window."""

    def __init__(self) -> None:
        self._allocate(_CAPACITY)
        self.restart()

    def _allocate(self, capacity: int) -> None:
        """The horizon's windows, rows ``_head .. _head + _count`` of: rotation matrix, mean
        acceleration, length, rotation vector, mean field (0 without one) and whether it has
        one (arrays, not a deque of tuples turned into arrays at every solve)."""
        self._rotations = np.zeros((capacity, 3, 3))
        self._accels = np.zeros((capacity, 3))
        self._durations = np.zeros(capacity)
        self._turned = np.zeros((capacity, 3))
        self._fields = np.zeros((capacity, 3))
        self._has_field = np.zeros(capacity, dtype=np.bool_)
        self._head = 0
        self._count = 0

    def _append(self, rotation: np.ndarray, accel: np.ndarray, duration: float,
                turned: np.ndarray, field: np.ndarray | None) -> None:
        end = self._head + self._count
        if end == len(self._durations):  # full: move the horizon to the front, or grow
            held = slice(self._head, end)
            parts = (self._rotations[held].copy(), self._accels[held].copy(),
                     self._durations[held].copy(), self._turned[held].copy(),
                     self._fields[held].copy(), self._has_field[held].copy())
            count = self._count
            capacity = len(self._durations)
            self._allocate(2 * capacity if 2 * count > capacity else capacity)
            for array, part in zip((self._rotations, self._accels, self._durations,
                                    self._turned, self._fields, self._has_field), parts,
                                   strict=True):
                array[:count] = part
            self._count = end = count
        self._rotations[end] = rotation
        self._accels[end] = accel
        self._durations[end] = duration
        self._turned[end] = turned
        self._has_field[end] = field is not None
        self._fields[end] = 0.0 if field is None else field
        self._count += 1

    def restart(self) -> None:
        """Forget the horizon (a gap, a new reference bias)."""
        self._head = 0
        self._count = 0
        self._span = 0.0
        self._hits = 0
        self.estimate = np.zeros(3)
        self.error = np.full(3, np.inf)
        self.field_windows = 0
        """Windows of the last solve that carried the field."""
        self.field_scatter = 0.0
        self.field_correlation = 0.0
        """The field residual's lag-1 correlation in the last solve."""
        """The field part's residual scatter in the last solve (uT)."""

    def push(self, rotation: np.ndarray, accel: np.ndarray, duration: float,
             field: np.ndarray | None = None) -> tuple[int, np.ndarray] | None:
        """One window: its rotation quaternion (window start to end), its mean accelerometer
        in the window-start frame, its length and, when the field is trusted this window, its
        mean field in the window-start frame (uT; None: no field part for this window).
        Returns (axis, bias step in rad/s, (3,)) when a step is declared, else None."""
        quat = rotation.tolist()
        if not (duration > 0 and all(map(math.isfinite, accel.tolist()))
                and all(map(math.isfinite, quat))):
            self.restart()
            return None
        half = min(max(quat[0], -1.0), 1.0)
        vector = rotation[1:]
        sine = math.sqrt(float(vector.dot(vector)))  # np.linalg.norm's own sum, without its checks
        turned = (2.0 * math.atan2(sine, half) / sine * vector if sine > 1e-12 else 2.0 * vector)
        kept = (field if field is not None and all(map(math.isfinite, field.tolist()))
                else None)
        self._append(rotation_matrix(rotation), accel, duration, turned, kept)
        self._span += duration
        while self._span - self._durations[self._head] >= HORIZON_S:
            self._span -= self._durations[self._head]
            self._head += 1
            self._count -= 1
        if self._span < MIN_S:
            return None
        self._solve()
        significance = FIELD_SIGNIFICANCE if self.field_windows else SIGNIFICANCE
        big = (np.abs(self.estimate) > STEP_RAD_S) & (np.abs(self.estimate)
                                                    > significance * self.error)
        if big.any() and not self.field_windows:  # gravity alone: the displacement too
            big &= self._displaced() * np.sign(self.estimate) >= AGREEMENT * STEP_RAD_S
        self._hits = self._hits + 1 if big.any() else 0
        if self._hits < CONFIRM:
            return None
        axis = int(np.argmax(np.where(big, np.abs(self.estimate), 0.0)))
        return axis, self.estimate.copy()

    def forget_field(self) -> None:
        """The field is not to be trusted (disturbed, a magnetometer fault): drop the field
        part of every window in the horizon; gravity's part goes on."""
        held = slice(self._head, self._head + self._count)
        self._has_field[held] = False
        self._fields[held] = 0.0

    def _solve(self) -> None:
        k = self._count
        held = slice(self._head, self._head + k)
        has_field = self._has_field[held]
        velocity, drift, elapsed, anchored, angles = _carry_sums(
            self._rotations[held], self._accels[held], self._durations[held],
            self._turned[held], self._fields[held], has_field)
        y = velocity.reshape(3 * k)
        # gravity times the time elapsed and the start velocity, the bias and scale errors
        design = _design(((0, elapsed), (3, 1.0)), drift, _gravity(elapsed, velocity))
        gram = design.T @ design
        fitted = _fit(design, y, 3 * k - 12, gram=gram)
        if fitted is None:
            return
        variance = max(fitted[0], 1e-300)
        normal = gram / variance
        rhs = design.T @ y / variance
        fields = int(np.count_nonzero(has_field))
        part = (self._field_part(anchored[has_field], angles[has_field])
                if fields * 3 >= FIELD_MIN_ROWS else None)
        if part is not None:
            # two references: every axis is seen, given the turn; priors, not a ridge
            joint = _with_priors(normal + part[0])
            try:
                inverse = np.linalg.inv(joint)
            except np.linalg.LinAlgError:
                return
            self.estimate = (inverse @ (rhs + part[1]))[6:9]
            self.error = np.sqrt(np.maximum(np.diag(inverse)[6:9], 1e-300))
            self.field_windows = fields
            return
        self.field_windows = 0
        _ridge(normal)
        try:
            inverse = np.linalg.inv(normal)
        except np.linalg.LinAlgError:
            return
        solution = inverse @ rhs
        self.estimate = solution[6:9]
        self.error = np.sqrt(np.maximum(np.diag(inverse)[6:9], 1e-300))

    def _displaced(self) -> np.ndarray:
        """The bias (3,) the displacement gives over the horizon: the velocity summed once
        more, ``P(t) = g t^2 / 2 - v(0) t + p(t) - p(0) - [g]x M(t) (b, s)`` with ``M`` the
        drift kernel summed; gravity, the start velocity and the start position (in the
        field's columns, unused without the field) free; the velocity fit's ridge. Asked only
        for a step the velocity already declares (zeros when it cannot be solved)."""
        held = slice(self._head, self._head + self._count)
        durations = self._durations[held]
        velocity, drift, elapsed, _, _ = _carry_sums(
            self._rotations[held], self._accels[held], durations, self._turned[held],
            self._fields[held], self._has_field[held])
        design = _design(((0, 0.5 * elapsed * elapsed), (3, elapsed), (12, 1.0)),
                         _summed(drift, durations), _gravity(elapsed, velocity))
        normal = design.T @ design
        _ridge(normal)
        try:
            return np.linalg.solve(normal, design.T @ _summed(velocity, durations).reshape(-1)
                                   )[6:9]
        except np.linalg.LinAlgError:
            return np.zeros(3)

    def _field_part(self, measured: np.ndarray, angles: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The field's normal equations, weighed by the field's own residual scatter.

        Carried into the anchor frame the field of window i is ``F_i = m0 - [m0]x A_i (b,
        s)``: ``m0`` the earth's field there, ``A_i`` the bias and scale error's turn at the
        window's middle. No motion term: the field is a static vector. No hard iron either:
        within 8 s a field fixed to the sensor is told from the earth's only by the turn, and
        a bias's own turn would be taken for one; the field must come calibrated (one left
        in it changes the strength as the sensor turns: the disturbance gate takes it).
        """
        y = measured.reshape(-1)
        rows = len(measured) * 3
        design = np.zeros((rows, PARTS))
        for axis in range(3):
            design[axis::3, 12 + axis] = 1.0
        m0 = measured.mean(axis=0)
        variance = FIELD_GUESS_UT ** 2
        prior = np.zeros(PARTS)
        for _ in range(2):  # the bias's effect depends on m0: linearise, then once again
            design[:, 6:12] = (-_skew(m0) @ angles).reshape(rows, 6)
            prior[9:12] = variance / SCALE_ERROR ** 2
            gram = design.T @ design
            fitted = _fit(design, y, rows - 12, prior, gram)
            if fitted is None:
                return None
            variance, solution, residual = fitted
            variance = max(variance, FIELD_FLOOR_UT ** 2)
            m0 = solution[12:15]
        self.field_scatter = math.sqrt(variance)
        # the field's residual (calibration, a gradient the sensor moves through) is smooth
        # in time, not white: window after window it tells less than its scatter says
        r = residual.reshape(-1, 3)
        lag = float(np.sum(r[1:] * r[:-1])) / max(float(np.sum(r * r)), 1e-300)
        lag = min(max(lag, 0.0), MAX_LAG_CORRELATION)
        self.field_correlation = lag
        variance *= (1.0 + lag) / (1.0 - lag)
        normal = gram / variance
        return normal, design.T @ y / variance


@njit(cache=True)
def _carry_sums(rotations, accels, durations, turned, fields, has_field
                ):  # pragma: no cover - compiled
    """The horizon's windows carried into the anchor frame, one after the other: per window
    the summed velocity (k, 3), its drift's kernel for the bias and scale error (k, 3, 6), the
    time elapsed (k,), and where it has a field, that field in the anchor frame (k, 3) and
    the carry's error kernel at the window's middle (k, 3, 6)."""
    k = len(durations)
    velocity = np.empty((k, 3))
    drift = np.empty((k, 3, 6))
    elapsed = np.empty(k)
    anchored = np.zeros((k, 3))
    middle = np.zeros((k, 3, 6))
    turn = np.eye(3)
    angle = np.zeros((3, 6))
    summed = np.zeros(3)
    drifted = np.zeros((3, 6))
    step = np.empty((3, 6))
    following = np.empty((3, 3))
    clock = 0.0
    for i in range(k):
        d = durations[i]
        for r in range(3):
            for c in range(3):
                step[r, c] = d * turn[r, c]  # the bias's turn
                step[r, 3 + c] = turn[r, c] * turned[i, c]  # the scale error's
            summed[r] += d * (turn[r, 0] * accels[i, 0] + turn[r, 1] * accels[i, 1]
                              + turn[r, 2] * accels[i, 2])
            if has_field[i]:
                anchored[i, r] = (turn[r, 0] * fields[i, 0] + turn[r, 1] * fields[i, 1]
                                  + turn[r, 2] * fields[i, 2])
        for r in range(3):
            for c in range(6):
                drifted[r, c] += d * (angle[r, c] + 0.5 * step[r, c])
                if has_field[i]:
                    middle[i, r, c] = angle[r, c] + 0.5 * step[r, c]
                angle[r, c] += step[r, c]
        clock += d
        velocity[i] = summed
        drift[i] = drifted
        elapsed[i] = clock
        for r in range(3):
            for c in range(3):
                following[r, c] = (turn[r, 0] * rotations[i, 0, c] + turn[r, 1] * rotations[i, 1, c]
                                   + turn[r, 2] * rotations[i, 2, c])
        turn[:, :] = following
    return velocity, drift, elapsed, anchored, middle


PARTS = 15
"""Unknowns: gravity, start velocity, bias, scale error, earth field."""
FIELD_MIN_ROWS = 3 * 16
"""Field rows (3 per window) the field part needs: 4 s of trusted field."""
FIELD_FLOOR_UT = 0.05
"""The field residual's scatter is taken as at least this (uT): a perfect fit is no reason
to trust the field without bound."""
SCALE_ERROR = 0.03
"""The gyro's scale error, a prior (3 %: a consumer MEMS gyro's sensitivity tolerance). A
turn the hand makes tells it from a bias; without one (the attitude held) a bias's own
turn would be taken as a scale error of 100 % unless the prior says no."""
MAX_LAG_CORRELATION = 0.9
"""The field residual's lag-1 correlation counts up to this (its variance up to 19x)."""
BIAS_PRIOR_RAD_S = math.radians(10.0)
"""With the field: a bias step's prior (the rest test's absolute limit); an axis neither
reference sees keeps an error of that size, never significant."""
FIELD_GUESS_UT = 0.5
"""The field residual's scatter assumed before the first fit has measured it."""
NUISANCE_RIDGE = 1e-9
"""Relative ridge on the nuisance unknowns (none without a field: it must stay invertible)."""


def _summed(values: np.ndarray, durations: np.ndarray) -> np.ndarray:
    """The running integral over the windows of ``values`` given at each window's end (zero
    at the anchor), by the trapezoid rule: (k, ...) -> (k, ...)."""
    before = np.empty_like(values)
    before[0] = 0.0
    before[1:] = values[:-1]
    weights = (0.5 * durations).reshape((-1,) + (1,) * (values.ndim - 1))
    return np.cumsum((before + values) * weights, axis=0)


def _gravity(elapsed: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """Gravity in the anchor frame: the slope of each axis's least-squares line of the summed
    velocity over time."""
    centred = elapsed - elapsed.mean()
    return centred @ (velocity - velocity.mean(axis=0)) / max(float(centred @ centred), 1e-300)


def _design(terms: tuple[tuple[int, np.ndarray | float], ...], kernel: np.ndarray,
            gravity: np.ndarray) -> np.ndarray:
    """The gravity part's design (3k, PARTS): per ``(column, values)`` of ``terms`` the
    per-axis columns ``column + axis`` (gravity's, the start velocity's, ...), and the bias
    and scale error's drift ``-[g]x kernel`` (kernel (k, 3, 6))."""
    k = len(kernel)
    design = np.zeros((3 * k, PARTS))
    for axis in range(3):
        for column, values in terms:
            design[axis::3, column + axis] = values
    design[:, 6:12] = (-_skew(gravity) @ kernel).reshape(3 * k, 6)
    return design


def _with_priors(normal: np.ndarray) -> np.ndarray:
    out = normal.copy()
    out[6:9, 6:9] += np.eye(3) / BIAS_PRIOR_RAD_S ** 2
    out[9:12, 9:12] += np.eye(3) / SCALE_ERROR ** 2
    _ridge(out, bias=False)
    return out


def _ridge(normal: np.ndarray, bias: bool = True) -> None:
    """The bias and scale error's ridge (module docstring; ``bias``) and a tiny one on the
    rest."""
    if bias:  # both blocks' largest eigenvalue in one call
        blocks = np.empty((2, 3, 3))
        blocks[0] = normal[6:9, 6:9]
        blocks[1] = normal[9:12, 9:12]
        largest = np.linalg.eigvalsh(blocks)[:, -1]
        for part, top in zip((slice(6, 9), slice(9, 12)), largest.tolist(), strict=True):
            normal[part, part] += RIDGE * max(top, 1e-300) * _EYE3
    nuisance = NUISANCE_RIDGE * float(normal.diagonal().max()) + 1e-300
    for i in range(12, PARTS):
        normal[i, i] += nuisance


def _fit(design: np.ndarray, y: np.ndarray, dof: int, prior: np.ndarray | None = None,
         gram: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray] | None:
    """The residual variance of ``y`` against ``design`` (ridged as in the joint fit), the
    solution (0 on the unknowns ``design`` does not hold) and the residual; ``gram``:
    ``design.T @ design`` when the caller has it."""
    used = np.flatnonzero(design.any(axis=0))
    normal = design.T @ design if gram is None else gram.copy()
    if prior is not None:
        normal += np.diag(prior)
    _ridge(normal)
    first, last = (int(used[0]), int(used[-1]) + 1) if len(used) else (0, 0)
    if last - first == len(used):  # the usual case: a run of columns, sliced, not gathered
        square = normal[first:last, first:last]
        columns = np.asfortranarray(design[:, first:last])  # laid out as design[:, used] is
    else:
        square = normal[np.ix_(used, used)]
        columns = design[:, used]
    try:
        part = np.linalg.solve(square, columns.T @ y)
    except np.linalg.LinAlgError:
        return None
    residual = y - columns @ part
    solution = np.zeros(design.shape[1])
    solution[used] = part
    return float(residual @ residual) / max(dof, 1), solution, residual
