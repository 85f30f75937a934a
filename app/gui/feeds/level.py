"""The bubble level's feed (it also hands on the newest attitude: the 3D view, the arm)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from app.gui.bubble_level import BubbleLevel
from app.gui.feeds.frame import Frame
from app.gui.feeds.screen import ScreenPresence

LEVEL_INTERVAL_S = 0.04
"""The bubble takes new averages at most this often (25 Hz): it shows a 0.5 s average by
default, which moves less in 40 ms than the eye can follow as separate steps."""


class LevelFeed:
    """Moves the bubble when its averaged input changed, at most every ``interval_s``."""

    def __init__(self, level: BubbleLevel, attitude: Callable[[np.ndarray], None]) -> None:
        self.level = level
        self.attitude = attitude
        self.shown = ScreenPresence(level)
        self.key: tuple | None = None
        self.last_update = -np.inf
        self.interval_s = LEVEL_INTERVAL_S

    def frame(self, frame: Frame, key: tuple, averaged: Callable[[], object]) -> None:
        if key == self.key or not self.shown(frame.now):
            return
        if frame.now - self.last_update >= self.interval_s:
            self.show(averaged())
            self.key = key
            self.last_update = frame.now
            frame.drew = True
        else:
            frame.defer(self.last_update + self.interval_s)

    def show(self, averaged) -> None:
        """The bubble (it repaints itself only when it moves by a visible amount)."""
        if averaged is None:
            return
        recent, angles = averaged
        self.attitude(recent["quat"][-1])
        self.level.setValid(True)
        self.level.setTilt(angles.roll_deg, angles.pitch_deg, angles.tilt_deg)
        ref_roll, ref_pitch = recent["ref_roll"][-1], recent["ref_pitch"][-1]
        if np.isfinite(ref_roll):
            self.level.setReference(float(ref_roll), float(ref_pitch))
        else:
            self.level.clearReference()

    def clear(self) -> None:
        """No data: an empty vial."""
        self.key = None
        self.level.setValid(False)
