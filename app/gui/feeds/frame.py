"""One frame's bookkeeping, shared by the feeds."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(slots=True)
class Frame:
    """What the feeds did in one frame at ``now`` (``time.monotonic()``)."""

    now: float
    drew: bool = False
    """Something was drawn."""
    pending: bool = False
    """Something is due shortly: the clock keeps the screen's pace until then."""
    due: list[float] = field(default_factory=lambda: [np.inf])
    """When deferred updates fall due."""

    def defer(self, until: float, pending: bool = True) -> None:
        """Something waits until ``until``."""
        self.due.append(until)
        if pending:
            self.pending = True
