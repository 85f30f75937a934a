"""Uncalibrated sample blocks pulled from the pipeline's buffers, for calibration procedures.

Calibration must see the sensor as it is, before the active calibration is applied: the
pipeline keeps those values in its ``raw_accel`` / ``raw_gyro`` columns. A feed remembers how
far it has read, and starts afresh when the buffers are replaced (another device connected).
"""

from __future__ import annotations

import numpy as np

from app.core.pipeline import Pipeline
from app.core.ring_follower import RingFollower
from app.core.samples import SampleBlock

_COLUMNS = ["t", "raw_accel", "raw_gyro", "temp", "gap", "ref_quat"]


class RawSampleFeed:
    """Hands out the rows written since the last call as uncalibrated :class:`SampleBlock` s."""

    def __init__(self, pipeline: Pipeline) -> None:
        self.pipeline = pipeline
        self._follower = RingFollower(lambda: pipeline.samples, _COLUMNS)

    def next_block(self) -> SampleBlock | None:
        """The new rows, or None when nothing new arrived."""
        rows = self._follower.next_rows()
        if rows is None:
            return None
        ref = rows["ref_quat"]
        known = np.all(np.isfinite(ref), axis=1)
        gap = rows["gap"] > 0.5
        if self._follower.skipped:  # rows were lost before we read them
            gap[0] = True
        return SampleBlock(
            t_s=rows["t"],
            accel_m_s2=rows["raw_accel"],
            gyro_rad_s=rows["raw_gyro"],
            temp_degc=rows["temp"],
            gap=gap,
            reference_quat=ref if known.all() else None,
        )
