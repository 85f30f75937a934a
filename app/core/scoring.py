"""Scoring an orientation estimate against a reference: which rows count, RMSE, maximum,
divergence; in one call over a whole stream (:func:`error_statistics`) or piece by piece in
bounded memory (:class:`ErrorAccumulator`). Numpy only.

The inclination error is the angle between the estimated and the true gravity directions
(:func:`app.core.orientation.inclination_error_deg`). With ``heading=True`` (a source with a
magnetometer, whose reference's earth frame is ENU with y toward magnetic north) the heading
and total errors of BROAD's split (:mod:`app.core.heading_metrics`) are scored over the same
rows as RMSE too. See :mod:`app.core.evaluation` for how ``inclinometer evaluate`` uses it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.core.heading_metrics import heading_error_deg, total_error_deg
from app.core.orientation import inclination_error_deg

DEFAULT_SKIP_S = 2.0
"""Seconds at the start of a stream that are not scored (filter convergence)."""
SCORE_COLUMN = "movement"
"""The optional recording column that says which rows are scored (1 = score this row)."""
DIVERGED_DEG = 5.0
DIVERGED_RATIO = 1.5
LATE_FRACTION = 0.1


def scoring_rows(
    reference: np.ndarray, t_s: np.ndarray, skip_s: float = DEFAULT_SKIP_S,
    score_mask: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) bool: the rows that count, before any estimate is looked at.

    With ``score_mask``, the rows it marks; else those from ``skip_s`` seconds after the first
    sample on. Either way only rows with a known (finite) reference.
    """
    known = np.all(np.isfinite(reference), axis=1)
    if score_mask is not None:
        mask = np.asarray(score_mask, dtype=bool)
        if mask.shape != t_s.shape:
            raise ValueError(f"the score mask has shape {mask.shape}, the stream {t_s.shape}")
        return mask & known
    if len(t_s) == 0:
        return known
    return (t_s >= t_s[0] + skip_s) & known


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2))) if len(values) else math.nan


def heading_figures(quat: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """``heading_rmse_deg`` and ``total_rmse_deg`` of rows already chosen (NaN for none)."""
    return {"heading_rmse_deg": _rms(heading_error_deg(quat, reference)),
            "total_rmse_deg": _rms(total_error_deg(quat, reference))}


NO_HEADING = {"heading_rmse_deg": math.nan, "total_rmse_deg": math.nan}


def error_statistics(
    quat: np.ndarray, reference: np.ndarray, t_s: np.ndarray, skip_s: float = DEFAULT_SKIP_S,
    score_mask: np.ndarray | None = None, heading: bool = False,
) -> dict[str, Any]:
    """RMSE and maximum inclination error (degrees) over the scored rows.

    The scored rows are those ``score_mask`` (N,) marks, or without one those after the first
    ``skip_s`` seconds (:func:`scoring_rows`); rows without a known reference never count.

    Returns ``rmse_deg``, ``max_deg``, ``scored`` (samples scored), ``nan`` (samples whose
    estimate is not finite, counted over the whole stream), ``diverged`` (see the module
    docstring), and ``heading_rmse_deg`` and ``total_rmse_deg`` (NaN unless ``heading``).
    Non-finite estimates are left out of RMSE and maximum.
    """
    finite = np.all(np.isfinite(quat), axis=1)
    nan_count = int(np.count_nonzero(~finite))
    if len(t_s) == 0:
        return {"rmse_deg": math.nan, "max_deg": math.nan, "scored": 0, "nan": 0,
                "diverged": False, **NO_HEADING}
    scored = scoring_rows(reference, t_s, skip_s, score_mask) & finite
    errors = inclination_error_deg(quat[scored], reference[scored])
    if len(errors) == 0:
        return {"rmse_deg": math.nan, "max_deg": math.nan, "scored": 0, "nan": nan_count,
                "diverged": False, **NO_HEADING}
    split = heading_figures(quat[scored], reference[scored]) if heading else NO_HEADING
    late_count = max(1, int(len(errors) * LATE_FRACTION))
    late = float(np.sqrt(np.mean(errors[-late_count:] ** 2)))
    early_errors = errors[:-late_count]
    early = float(np.sqrt(np.mean(early_errors**2))) if len(early_errors) else 0.0
    return {
        "rmse_deg": float(np.sqrt(np.mean(errors**2))),
        "max_deg": float(errors.max()),
        "scored": len(errors),
        "nan": nan_count,
        "diverged": late > DIVERGED_DEG and late > DIVERGED_RATIO * early,
        **split,
    }


class ErrorAccumulator:
    """:func:`error_statistics` over a stream given in pieces, in memory that does not grow.

    Feed it each piece's estimate, reference and scored rows (:meth:`add`); :meth:`result`
    gives the same keys. RMSE, maximum and counts are exact; the divergence check's "last
    10 % of the scored samples" is resolved to bins of consecutive scored samples (at most
    :data:`BINS` of them, merged pairwise as the stream grows), so its RMS is exact up to one
    bin's share of the samples.
    """

    BINS = 1024

    def __init__(self, heading: bool = False) -> None:
        self.heading = heading
        self.heading_sum_sq = 0.0
        self.total_sum_sq = 0.0
        self.sum_sq = 0.0
        self.count = 0
        self.max_deg = -math.inf
        self.nan = 0
        self._width = 1
        self._bins: list[float] = []  # sum of squares per bin of ``_width`` scored samples
        self._open_sum = 0.0
        self._open_count = 0

    def add(self, quat: np.ndarray, reference: np.ndarray, scored: np.ndarray) -> None:
        """One piece: (n, 4) estimates and references, (n,) bool rows that count."""
        finite = np.all(np.isfinite(quat), axis=1)
        self.nan += int(np.count_nonzero(~finite))
        rows = np.asarray(scored, dtype=bool) & finite
        if not rows.any():
            return
        squares = inclination_error_deg(quat[rows], reference[rows]) ** 2
        if self.heading:
            self.heading_sum_sq += float(np.sum(heading_error_deg(quat[rows], reference[rows])**2))
            self.total_sum_sq += float(np.sum(total_error_deg(quat[rows], reference[rows]) ** 2))
        self.sum_sq += float(squares.sum())
        self.count += len(squares)
        self.max_deg = max(self.max_deg, float(np.sqrt(squares.max())))
        self._bin(squares)

    def _bin(self, squares: np.ndarray) -> None:
        start = 0
        if self._open_count:  # top up the open bin first
            take = min(self._width - self._open_count, len(squares))
            self._open_sum += float(squares[:take].sum())
            self._open_count += take
            start = take
            if self._open_count == self._width:
                self._bins.append(self._open_sum)
                self._open_sum, self._open_count = 0.0, 0
        rest = squares[start:]
        whole = len(rest) // self._width * self._width
        if whole:
            self._bins.extend(rest[:whole].reshape(-1, self._width).sum(axis=1).tolist())
        if whole < len(rest):
            self._open_sum = float(rest[whole:].sum())
            self._open_count = len(rest) - whole
        while len(self._bins) > 2 * self.BINS:  # halve the resolution, keep one width
            if len(self._bins) % 2:  # the odd last bin goes back into the open one
                self._open_sum += self._bins.pop()
                self._open_count += self._width
            self._bins = np.asarray(self._bins).reshape(-1, 2).sum(axis=1).tolist()
            self._width *= 2

    def result(self) -> dict[str, Any]:
        """``rmse_deg``, ``max_deg``, ``scored``, ``nan``, ``diverged``, ``heading_rmse_deg``
        and ``total_rmse_deg``, as :func:`error_statistics` gives them."""
        if self.count == 0:
            return {"rmse_deg": math.nan, "max_deg": math.nan, "scored": 0, "nan": self.nan,
                    "diverged": False, **NO_HEADING}
        late_count = max(1, int(self.count * LATE_FRACTION))
        late_sum, covered = self._open_sum, self._open_count
        for value in reversed(self._bins):
            if covered >= late_count:
                break
            share = min(1.0, (late_count - covered) / self._width)
            late_sum += value * share
            covered += self._width * share  # type: ignore[assignment]
        late = math.sqrt(late_sum / late_count) if covered else 0.0
        early_count = self.count - late_count
        early = math.sqrt(max(self.sum_sq - late_sum, 0.0) / early_count) if early_count else 0.0
        return {
            "rmse_deg": math.sqrt(self.sum_sq / self.count),
            "max_deg": self.max_deg,
            "scored": self.count,
            "nan": self.nan,
            "diverged": late > DIVERGED_DEG and late > DIVERGED_RATIO * early,
            "heading_rmse_deg": (math.sqrt(self.heading_sum_sq / self.count) if self.heading
                                 else math.nan),
            "total_rmse_deg": (math.sqrt(self.total_sum_sq / self.count) if self.heading
                               else math.nan),
        }
