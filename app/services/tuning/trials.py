"""One filter run on one recording, scored exactly as ``inclinometer evaluate`` scores it.

These are the functions the workers run, so they are module-level and take only picklable
arguments: a :class:`SourceSpec` (the worker reads the recording itself, once per process:
:func:`load_source` keeps it) or a :class:`PreparedSource` (already read, e.g. scattered to a
Dask cluster once). A run is deterministic: the same source, filter and parameters give the
same bits in any process, which is what makes a parallel study identical to a serial one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from app.core import evaluation
from app.core.evaluation import SourceResult, StreamSource
from app.core.filters import FILTERS
from app.core.samples import SampleBlock

SOURCE_CACHE = 64
"""Recordings a worker keeps in memory (tasks come source by source, so a few would do)."""


@dataclass(frozen=True, slots=True)
class SourceSpec:
    """A recording a worker reads itself: an absolute path every worker can see."""

    path: str
    label: str
    compensate: bool = True


@dataclass(slots=True)
class PreparedSource:
    """A recording read whole: the calibrated stream and the rows that are scored."""

    label: str
    stream: SampleBlock
    score_mask: np.ndarray | None
    description: str
    scoring: str


@dataclass(frozen=True, slots=True)
class TrialScore:
    """One filter run on one recording (the figures ``evaluate`` gives it)."""

    rmse_deg: float
    max_deg: float
    flag: str
    message: str = ""

    @property
    def usable(self) -> bool:
        """True when the RMSE may be compared (no error, no NaN estimate)."""
        return self.flag not in ("error", "NaN") and math.isfinite(self.rmse_deg)


def prepare(spec: SourceSpec) -> PreparedSource:
    """Read a recording whole (RecordingError for a bad file, ValueError without reference)."""
    source = evaluation.recording_source(spec.path, recalibrate=spec.compensate,
                                         label=spec.label)
    if source.pieces is not None:  # a recording too large to hold by default: hold it anyway
        pieces = list(source.pieces())
        stream = evaluation.concatenate_blocks(block for block, _ in pieces)
        masks = [mask for _, mask in pieces]
        mask: np.ndarray | None = (None if any(m is None for m in masks)
                                   else np.concatenate(masks))  # type: ignore[arg-type]
    else:
        stream, mask = evaluation.concatenate_blocks(source.blocks()), source.score_mask
    return PreparedSource(spec.label, stream, mask, source.description, source.scoring)


@lru_cache(maxsize=SOURCE_CACHE)
def load_source(spec: SourceSpec) -> PreparedSource:
    """:func:`prepare`, once per process and recording."""
    return prepare(spec)


def _prepared(source: SourceSpec | PreparedSource) -> PreparedSource:
    return load_source(source) if isinstance(source, SourceSpec) else source


def score_points(source: SourceSpec | PreparedSource, filter_name: str,
                 points: list[tuple[int, dict[str, Any]]]) -> list[tuple[int, TrialScore]]:
    """Run ``filter_name`` with each point's parameters over one recording: the task of a
    study (one source, several points: the worker keeps the recording between them)."""
    prepared = _prepared(source)
    scored = []
    for index, values in points:
        score = evaluation.evaluate_filter(filter_name, prepared.stream, repeats=1,
                                           score_mask=prepared.score_mask, **values)
        scored.append((index, TrialScore(score.rmse_deg, score.max_deg, score.flag,
                                         score.message)))
    return scored


def evaluate_recording(spec: SourceSpec, filters: list[str], skip_s: float,
                       repeats: int | None, parameters: dict[str, dict[str, Any]]
                       ) -> SourceResult:
    """``evaluate``'s work for one recording, in a worker (what it does in-process)."""
    source: StreamSource = evaluation.recording_source(spec.path, recalibrate=spec.compensate,
                                                       label=spec.label)
    return evaluation.evaluate_source(source, filters, skip_s=skip_s, repeats=repeats,
                                      parameters=parameters)


def warm_up(filters: tuple[str, ...]) -> None:
    """Load the filters' compiled kernels (numba's on-disk cache) once, in a new worker. A
    filter that cannot start is left alone: its runs say why (flag "error"), as in-process."""
    for name in filters:
        try:
            FILTERS[name]().warm_up()
        except Exception:  # each run of that filter reports it
            continue
