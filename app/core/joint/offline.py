"""The joint angle of a whole recorded pair (what ``inclinometer joint`` runs).

The hinge axis may use the whole recording (it is a constant of the mounting): the gyroscopes,
corrected by each VQF's final bias estimate, go into :func:`~app.core.joint.axis.
estimate_hinge_axes` at once, and the orientations fix the axes' signs. The angle itself is
then the causal :class:`~app.core.joint.estimator.JointEstimator` with those axes, exactly
what a live session would show once its axis estimate has settled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.core.filters.vqf_filter import VQFFilter
from app.core.joint.axis import AxisEstimate, consistent_sign, estimate_hinge_axes
from app.core.joint.estimator import JointBlock, JointEstimator
from app.core.samples import SampleBlock

RICH_QUARTER = 0.25
"""A quarter of the recording counts towards the axis spread when its smallest singular value
is at least this fraction of the whole recording's."""


@dataclass
class JointResult:
    """The angle of every sample pair and the axes used."""

    angles: JointBlock
    j1: np.ndarray
    j2: np.ndarray
    axis_estimate: AxisEstimate | None
    """None when the axes were given."""
    axis_spread_deg: float = math.nan
    """Largest angle between the axes fitted on each quarter of the recording and on the whole,
    over the quarters whose motion shows the axis (:data:`RICH_QUARTER`); NaN when the axes
    were given or fewer than two quarters qualify: how repeatable the estimate is."""


def estimate_axes_offline(block1: SampleBlock, block2: SampleBlock
                          ) -> tuple[AxisEstimate, float]:
    """Hinge axes from a whole recorded pair, with consistent signs (see the module), and
    their spread over the quarters of the recording (:attr:`JointResult.axis_spread_deg`)."""
    filters = (VQFFilter(), VQFFilter())
    quats = [f.process(b).quat for f, b in zip(filters, (block1, block2), strict=True)]
    w1 = block1.gyro_rad_s - filters[0].bias_estimate_rad_s
    w2 = block2.gyro_rad_s - filters[1].bias_estimate_rad_s
    found = estimate_hinge_axes(w1, w2)
    j2 = consistent_sign(found.j1, found.j2, quats[0], quats[1])
    spread, counted = 0.0, 0
    for rows in np.array_split(np.arange(len(w1)), 4):
        try:
            part = estimate_hinge_axes(w1[rows], w2[rows], start=(found.j1, j2))
        except ValueError:
            continue
        if part.smallest_singular < RICH_QUARTER * found.smallest_singular:
            continue  # e.g. a rest of the base: this quarter cannot show the axis
        counted += 1
        for a, b in ((part.j1, found.j1), (part.j2, j2)):
            spread = max(spread, math.degrees(math.acos(min(1.0, abs(float(a @ b))))))
    if counted < 2:
        spread = math.nan
    estimate = AxisEstimate(found.j1, j2, found.residual_rms_rad_s, found.smallest_singular,
                            found.uncertainty_deg, found.samples)
    return estimate, spread


def joint_angle_offline(block1: SampleBlock, block2: SampleBlock,
                        axes: tuple[np.ndarray, np.ndarray] | None = None) -> JointResult:
    """Joint angle for simultaneous samples of two sensors (same length); ``axes`` given or
    estimated from the whole recording. Raises ValueError when the motion cannot give them."""
    estimate = None
    spread = math.nan
    if axes is None:
        estimate, spread = estimate_axes_offline(block1, block2)
        axes = (estimate.j1, estimate.j2)
    estimator = JointEstimator(axes=axes)
    angles = estimator.update(block1, block2)
    assert estimator.axes is not None
    return JointResult(angles, estimator.axes[0], estimator.axes[1], estimate, spread)
