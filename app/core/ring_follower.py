"""Read a pipeline's ring buffer incrementally: every call returns only the new rows."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from app.core.ring_buffer import RingBuffer


class RingFollower:
    """Follows the ring that ``get_ring`` returns (it may be replaced on reconnect).

    Parameters
    ----------
    get_ring : returns the current ring (e.g. ``lambda: pipeline.orientation``).
    names : columns to return.
    from_start : also return the rows already in the ring at creation.
    """

    def __init__(
        self, get_ring: Callable[[], RingBuffer], names: list[str], from_start: bool = False
    ) -> None:
        self._get_ring = get_ring
        self.names = list(names)
        self._ring = get_ring()
        self._next = 0 if from_start else self._ring.total_written
        self.skipped = False
        """True when rows were overwritten (or the ring replaced) before the last read."""

    def next_rows(self) -> dict[str, np.ndarray] | None:
        """Rows written since the previous call, oldest first; None when there are none."""
        ring = self._get_ring()
        replaced = ring is not self._ring
        if replaced:
            self._ring, self._next = ring, 0
        asked = self._next
        first, rows = ring.since(asked, self.names)
        count = len(next(iter(rows.values())))
        self.skipped = replaced or first > asked
        if count == 0:
            return None
        self._next = first + count
        return rows
