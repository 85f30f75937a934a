"""Live comparison of filters against the reference orientation (when the source has one)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.ring_buffer import RingBuffer


@dataclass(frozen=True, slots=True)
class ErrorSummary:
    """Inclination error of one filter over a time window, in degrees (NaN: no reference)."""

    name: str
    rms_deg: float
    max_deg: float


def summarize_errors(buffer: RingBuffer, name: str, window_s: float) -> ErrorSummary:
    """RMS and maximum of the ``incl_error`` column over the newest ``window_s`` seconds."""
    error = buffer.window(window_s, ["incl_error"])["incl_error"]
    error = error[np.isfinite(error)]
    if len(error) == 0:
        return ErrorSummary(name, float("nan"), float("nan"))
    return ErrorSummary(name, float(np.sqrt(np.mean(error**2))), float(np.max(error)))
