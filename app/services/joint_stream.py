"""The live joint angle between two members of a :class:`~app.services.sensor_group.SensorGroup`
(or the files of a :class:`~app.services.session_replay.SessionReplay`).

:meth:`JointStream.step` takes the samples both members' pipelines wrote since the last call
(calibrated accelerometer and gyroscope), puts the second sensor's on the first one's clock
(the group's clock fits; exact on a shared clock), interpolates it to the first sensor's sample
times, and runs the causal :class:`~app.core.joint.estimator.JointEstimator` on the pairs up to
the newest time both sensors have reached. The angles go into a ring buffer (``t`` on the
group's time axis, ``angle``, ``orientation_angle``) that views read like a pipeline's.
Qt-free: the caller decides where it runs (the GUI's refresh timer, a test).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.core.joint.estimator import JointEstimator
from app.core.ring_buffer import RingBuffer
from app.core.ring_follower import RingFollower
from app.core.samples import SampleBlock
from app.services.sensor_group import SensorGroup
from app.services.session_replay import SessionReplay

COLUMNS = {"t": 1, "angle": 1, "orientation_angle": 1, "device_t": 1}
CAPACITY = 200_000
MAX_PENDING = 50_000
"""Rows either side keeps while the other sensor delivers nothing (a stalled link)."""
KEEP_SECOND_S = 2.0
"""Seconds of the second sensor kept for interpolation behind the newest pair."""
_SAMPLE_NAMES = ["t", "accel", "gyro", "temp", "gap"]


@dataclass(frozen=True)
class AxisQuality:
    """How well the hinge axis is known (for the view)."""

    source: str
    """``entered`` or ``estimated``; ``waiting`` before the first estimate."""
    j1: tuple[float, float, float] | None
    j2: tuple[float, float, float] | None
    uncertainty_deg: float
    """Largest 1-sigma axis uncertainty, NaN when entered or unknown."""
    well_determined: bool


class JointStream:
    """Joint angle of the hinge between group members ``first`` and ``second``."""

    def __init__(self, group: SensorGroup | SessionReplay, first: int, second: int,
                 axes: tuple[np.ndarray, np.ndarray] | None = None,
                 capacity: int = CAPACITY) -> None:
        if first == second:
            raise ValueError("a joint needs two different sensors")
        self.group = group
        self.first, self.second = first, second
        self.estimator = JointEstimator(axes=axes)
        self.angles = RingBuffer(capacity, COLUMNS)
        self._follow_a = RingFollower(lambda: group.pipeline(first).samples, _SAMPLE_NAMES,
                                      from_start=True)
        self._follow_b = RingFollower(lambda: group.pipeline(second).samples, _SAMPLE_NAMES,
                                      from_start=True)
        self._pending_a: dict[str, np.ndarray] | None = None
        self._held_b: dict[str, np.ndarray] | None = None

    @property
    def axis_quality(self) -> AxisQuality:
        est = self.estimator
        axes = est.axes
        j1 = None if axes is None else tuple(float(v) for v in axes[0])
        j2 = None if axes is None else tuple(float(v) for v in axes[1])
        if est.fixed_axes:
            return AxisQuality("entered", j1, j2, math.nan, True)  # type: ignore[arg-type]
        found = est.axis_estimate
        if found is None:
            return AxisQuality("waiting", None, None, math.nan, False)
        return AxisQuality("estimated", j1, j2, float(np.max(found.uncertainty_deg)),  # type: ignore[arg-type]
                           found.well_determined)

    def recent_angles(self, seconds: float) -> np.ndarray:
        """The angles (degrees) of the last ``seconds`` of the first sensor's own clock (as
        the tilt readout averages over device time); the newest one alone for 0."""
        if seconds <= 0:
            return self.angles.latest(1, ["angle"])["angle"]
        rows = self.angles.latest(min(len(self.angles), 1 + int(seconds * 20_000)),
                                  ["device_t", "angle"])
        if not len(rows["angle"]):
            return rows["angle"]
        return rows["angle"][rows["device_t"] >= rows["device_t"][-1] - seconds]

    def step(self) -> int:
        """Process what both sensors delivered since the last call; returns the new angles."""
        self._pending_a = _append(self._pending_a, self._follow_a.next_rows())
        self._held_b = _append(self._held_b, self._follow_b.next_rows())
        self._pending_a = _last(self._pending_a, MAX_PENDING)
        self._held_b = _last(self._held_b, MAX_PENDING)
        a, b = self._pending_a, self._held_b
        if a is None or b is None or len(a["t"]) == 0 or len(b["t"]) < 2:
            return 0
        tb = self.group.to_member_clock(self.second, self.first, b["t"])
        if tb is None:
            return 0
        ta = a["t"]
        ready = ta <= tb[-1]
        covered = ready & (ta >= tb[0])
        n_ready = int(np.count_nonzero(ready))
        if n_ready == 0:
            return 0
        rows = np.flatnonzero(covered)
        produced = 0
        if len(rows):
            t = ta[rows]
            gyro_b = np.column_stack([np.interp(t, tb, b["gyro"][:, k]) for k in range(3)])
            accel_b = np.column_stack([np.interp(t, tb, b["accel"][:, k]) for k in range(3)])
            gap_b = np.zeros(len(t), dtype=bool)
            gap_times = tb[b["gap"].ravel().astype(bool)]
            if len(gap_times):
                gap_b[np.clip(np.searchsorted(t, gap_times), 0, len(t) - 1)] = True
            block1 = SampleBlock(t, a["accel"][rows], a["gyro"][rows], a["temp"][rows].ravel(),
                                 a["gap"][rows].ravel().astype(bool))
            block2 = SampleBlock(t.copy(), accel_b, gyro_b, np.zeros(len(t)), gap_b)
            out = self.estimator.update(block1, block2)
            common = self.group.to_common(self.first, t)
            assert common is not None
            self.angles.write({"t": common, "angle": out.angle_deg,
                               "orientation_angle": out.orientation_angle_deg, "device_t": t})
            produced = len(t)
        # Keep A's rows not yet reached by B, and B's recent past for the next interpolation.
        keep_a = ~ready
        self._pending_a = {k: v[keep_a] for k, v in a.items()}
        horizon = float(ta[n_ready - 1]) - KEEP_SECOND_S
        keep_b = tb >= min(horizon, float(tb[-2]))
        self._held_b = {k: v[keep_b] for k, v in b.items()}
        return produced


def _last(rows: dict[str, np.ndarray] | None, limit: int) -> dict[str, np.ndarray] | None:
    if rows is None or len(rows["t"]) <= limit:
        return rows
    return {k: v[-limit:] for k, v in rows.items()}


def _append(held: dict[str, np.ndarray] | None, new: dict[str, np.ndarray] | None
            ) -> dict[str, np.ndarray] | None:
    if new is None:
        return held
    if held is None or len(held["t"]) == 0:
        return new
    return {k: np.concatenate([held[k], new[k]]) for k in held}
