"""Filter evaluation: run orientation filters over a stream with a known true orientation.

A *stream* is any iterable of :class:`~app.core.samples.SampleBlock` s that carry
``reference_quat``: a recording with reference columns (:func:`recording_source`), or the
simulator (:func:`app.services.simulation.simulator_source`, a layer up: it runs a device).
:func:`evaluate` joins the stream, runs each filter over it in large blocks and scores it:

- **inclination error**: the angle between estimated and true gravity directions
  (:func:`app.core.orientation.inclination_error_deg`), as RMSE and maximum in degrees. The
  first ``skip_s`` seconds (default :data:`DEFAULT_SKIP_S`, 2 s) after the stream's first sample
  are not scored: every filter starts from the accelerometer and needs time to converge.
  Re-convergence after a gap *is* scored (that is what a gap costs). A stream may instead carry
  a **score mask** (:attr:`StreamSource.score_mask`): then exactly the rows it marks are scored
  and ``skip_s`` does not apply. A recording's ``movement`` column gives one
  (:func:`recording_score_mask`: rows with ``movement == 1``; BROAD's metric, whose rest phase
  before the movement is the convergence time). Rows without a known reference are never
  scored.
- **heading and total error** (a source with a magnetometer: its reference's earth frame is
  ENU with y toward magnetic north, as BROAD's and the simulator's): BROAD's split of the error
  rotation (:mod:`app.core.heading_metrics`), RMSE over the same rows. It is computed for every
  filter, but only a filter that takes heading from the magnetometer (``uses_magnetometer`` with
  its switch on: :attr:`FilterScore.magnetic`) has a heading that means anything: a 6-axis
  filter's heading is the gyroscope's from an arbitrary start. :func:`turned_source` turns a
  source's sensor frame by a fixed rotation first (BROAD's trap: see that module).
- **throughput**: samples per second of wall time inside ``filter.process`` only.
- **flag**: ``ok``; ``NaN`` when an estimate is not finite; ``diverged`` when the error RMS over
  the last 10 % of the scored samples exceeds :data:`~app.core.scoring.DIVERGED_DEG` and
  :data:`~app.core.scoring.DIVERGED_RATIO` times that over the rest (the estimate runs away);
  ``error`` when the filter raised (``message`` says what).

An *offline* filter (``OrientationFilter.offline``: an acausal smoother) gets the whole stream
in one ``process`` call; the others get it in blocks of ``block`` samples.

:func:`evaluate_source` scores several filters on one :class:`StreamSource`,
:func:`summarize` gives each filter's mean over several sources, and :func:`results_json`
puts both in a JSON-ready dict (what ``inclinometer evaluate --json`` writes).

This module is numpy only: no Qt, no drivers. Streams that come from running a device are
built in :mod:`app.services.simulation`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.core.calibration import MagnetometerCalibration, SensorCalibration
from app.core.filters import FILTERS, OrientationFilter
from app.core.heading_metrics import turn_block
from app.core.samples import SampleBlock
from app.core.scoring import (
    DEFAULT_SKIP_S,
    SCORE_COLUMN,
    ErrorAccumulator,
    error_statistics,
    scoring_rows,
)

DEFAULT_BLOCK = 65536
"""Samples per ``filter.process`` call during evaluation (large: a batch, as a recording)."""
DEFAULT_REPEATS = 3
"""Runs per filter and stream; the throughput is that of the fastest."""
STREAM_MIN_BYTES = 64 << 20
"""Recordings at least this large are scored in pieces (memory then does not grow)."""
LARGE_STREAM = 1_000_000
"""A stream with at least this many samples is timed in one run (it times well as it is)."""
FilterSpec = str | type[OrientationFilter]
"""A filter to evaluate: a registry name (:data:`app.core.filters.FILTERS`) or a class."""


@dataclass(slots=True)
class FilterScore:
    """How one filter did on one stream (angles in degrees)."""

    name: str
    title: str
    rmse_deg: float = math.nan
    max_deg: float = math.nan
    samples_per_s: float = math.nan
    samples: int = 0
    scored_samples: int = 0
    nan_samples: int = 0
    flag: str = "ok"
    message: str = ""
    heading_rmse_deg: float = math.nan
    """NaN unless the stream has a magnetometer (see :attr:`magnetic`)."""
    total_rmse_deg: float = math.nan
    magnetic: bool = False
    """True when the filter took its heading from the magnetometer: only then does the heading
    error measure anything (a 6-axis heading is arbitrary)."""


@dataclass(slots=True)
class StreamSource:
    """A named stream factory: ``blocks()`` yields the stream afresh each time it is called.

    ``score_mask``: None to score every row after the first ``skip_s`` seconds, or (N,) bool
    over the whole (concatenated) stream: exactly the rows to score, ``skip_s`` then does not
    apply. ``scoring`` says in words which rows the mask marks.
    """

    label: str
    blocks: Callable[[], Iterable[SampleBlock]]
    description: str = ""
    score_mask: np.ndarray | None = None
    scoring: str = ""
    pieces: Callable[[], Iterable[tuple[SampleBlock, np.ndarray | None]]] | None = None
    """Optional: the stream afresh in pieces, each with its own score mask (or None for the
    ``skip_s`` rule), for scoring in memory that does not grow with the stream (a long
    recording). Online filters then read it; ``blocks`` is left to offline filters."""


@dataclass(slots=True)
class SourceResult:
    """Every filter's score on one source, and what the source was."""

    label: str
    description: str
    duration_s: float
    samples: int
    rate_hz: float
    gaps: int
    scored_samples: int
    """Rows that count (mask or time rule, and a known reference), before NaN estimates."""
    scoring: str
    """Which rows are scored, in words."""
    masked: bool
    """True when a score mask chose the rows (False: the first ``skip_s`` s skipped)."""
    scores: list[FilterScore] = field(default_factory=list)
    has_field: bool = False
    """True when the stream has a magnetometer: heading and total errors are scored."""

    def score(self, name: str) -> FilterScore | None:
        return next((s for s in self.scores if s.name == name), None)


# -- streams ---------------------------------------------------------------------------------
def concatenate_blocks(blocks: Iterable[SampleBlock]) -> SampleBlock:
    """One SampleBlock holding a whole stream (reference and field kept only if every block
    has one)."""
    blocks = [b for b in blocks if len(b)]
    if not blocks:
        empty3 = np.empty((0, 3))
        return SampleBlock(np.empty(0), empty3, empty3.copy(), np.empty(0), np.empty(0, bool))
    references = [b.reference_quat for b in blocks]
    has_reference = all(r is not None for r in references)
    fields = [b.mag_ut for b in blocks]
    has_field = all(f is not None for f in fields)
    return SampleBlock(
        t_s=np.concatenate([b.t_s for b in blocks]),
        accel_m_s2=np.concatenate([b.accel_m_s2 for b in blocks]),
        gyro_rad_s=np.concatenate([b.gyro_rad_s for b in blocks]),
        temp_degc=np.concatenate([b.temp_degc for b in blocks]),
        gap=np.concatenate([b.gap for b in blocks]),
        reference_quat=np.concatenate(references) if has_reference else None,  # type: ignore[arg-type]
        mag_ut=np.concatenate(fields) if has_field else None,  # type: ignore[arg-type]
    )


def split_block(block: SampleBlock, size: int) -> Iterator[SampleBlock]:
    """Consecutive slices of ``block`` with at most ``size`` samples (views, no copies)."""
    for start in range(0, len(block), size):
        yield _rows(block, start, start + size)


def with_gap(block: SampleBlock, start_s: float, length_s: float) -> SampleBlock:
    """``block`` with the samples in ``[start_s, start_s + length_s)`` lost, as a FIFO overflow.

    The first sample after the hole gets ``gap = True``; times and reference are untouched.
    """
    lost = (block.t_s >= start_s) & (block.t_s < start_s + length_s)
    keep = ~lost
    gap = block.gap.copy()
    after = np.flatnonzero(block.t_s >= start_s + length_s)
    if lost.any() and len(after):
        gap[after[0]] = True
    ref, field = block.reference_quat, block.mag_ut
    return SampleBlock(
        block.t_s[keep], block.accel_m_s2[keep], block.gyro_rad_s[keep], block.temp_degc[keep],
        gap[keep], None if ref is None else ref[keep], None if field is None else field[keep],
    )


def calibration_from_unit_errors(unit: Any) -> SensorCalibration:
    """The calibration that undoes a simulated unit's static errors at 25 degC.

    ``unit`` is a :class:`drivers.sim.error_model.UnitErrors`: ``measured = M @ true + bias``
    gives ``A = inv(M)`` and ``b = bias``, for the accelerometer and the gyroscope alike. A
    magnetometer (``unit.magnetometer``: ``measured = S R b + h``, soft iron ``S``, the chips'
    turn ``R``, hard iron ``h``) gets ``hard_iron = h`` and ``soft_iron = inv(S R)``, so its
    field is in the accelerometer's frame and a 9-axis heading is scored without the board's
    iron in it. Temperature terms, random walks and noise stay: no calibration removes them.
    """
    mag = getattr(unit, "magnetometer", None)
    return SensorCalibration(
        accel_bias_m_s2=np.asarray(unit.accel_bias_m_s2, dtype=np.float64),
        accel_matrix=np.linalg.inv(unit.accel_matrix),
        gyro_bias_rad_s=np.asarray(unit.gyro_bias_rad_s, dtype=np.float64),
        gyro_matrix=np.linalg.inv(unit.gyro_matrix),
        name=f"true errors of seed {unit.seed}",
        magnetometer=None if mag is None else MagnetometerCalibration(
            hard_iron_ut=np.asarray(mag.hard_iron_ut, dtype=np.float64),
            soft_iron=np.linalg.inv(np.asarray(mag.soft_iron) @ np.asarray(mag.alignment))),
    )


def recording_source(
    path: str, *, recalibrate: bool = True, label: str | None = None
) -> StreamSource:
    """A :class:`StreamSource` for a recording file with reference columns.

    With ``recalibrate`` (the default) the calibration recorded in the file is applied again,
    as a replay does; otherwise the raw samples are scored. Reads the file at once: raises
    :class:`app.core.recording.errors.RecordingError` for a bad file and ValueError when it
    has no reference orientation.

    When the recording has a ``movement`` column (:data:`SCORE_COLUMN`), its rows with
    ``movement == 1`` are the ones scored (:func:`recording_score_mask`).
    """
    from app.core.recording.errors import RecordingTooLargeError
    from app.core.recording.reader import Recording, read_recording
    from app.core.recording.stream import RecordingStream, prefetched

    with RecordingStream(path) as stream:  # the head only: typed errors for a bad file
        head = Recording(stream.metadata, stream.header, {}, Path(path))
        streamed = stream.file_size() >= STREAM_MIN_BYTES  # else read it whole, as before
    if not streamed:
        try:  # decompressed bytes count: a small .csv.gz may expand a thousandfold
            recording = read_recording(path, max_bytes=STREAM_MIN_BYTES)
        except RecordingTooLargeError:
            streamed = True
    if not streamed:
        if not recording.has_reference:
            raise ValueError(f"{path}: the recording has no reference orientation (columns qw, "
                             "qx, qy, qz) to compare the filters with")
    elif not all(name in head.header for name in ("qw", "qx", "qy", "qz")):
        raise ValueError(f"{path}: the recording has no reference orientation (columns qw, qx, "
                         "qy, qz) to compare the filters with")
    calibration = head.calibration if recalibrate else None
    applied = (f"recorded calibration {calibration.name!r} applied" if calibration is not None
               else "raw samples, no calibration")
    masked = SCORE_COLUMN in head.header
    scoring = f"rows with {SCORE_COLUMN} == 1" if masked else ""
    if not streamed:
        mask = recording_score_mask(recording)
        return StreamSource(label or str(path),
                            lambda: [recording.sample_block(calibration)], applied, mask,
                            scoring)

    def pieces() -> Iterator[tuple[SampleBlock, np.ndarray | None]]:
        with RecordingStream(path) as chunks:
            for chunk in prefetched(chunks.chunks()):  # the next one parses meanwhile
                yield chunk.rows.sample_block(calibration), recording_score_mask(chunk.rows)

    def blocks() -> Iterable[SampleBlock]:  # offline filters need the whole recording
        return [read_recording(path).sample_block(calibration)]

    return StreamSource(label or str(path), blocks, applied, None, scoring, pieces)


def recording_score_mask(recording: Any) -> np.ndarray | None:
    """(N,) bool: the rows a recording's ``movement`` column marks 1; None without the column.

    ``recording`` is an :class:`app.core.recording.reader.Recording`. The column is not one of
    format v1's known columns, so the reader keeps it as it keeps any other
    (:attr:`~app.core.recording.reader.Recording.unknown_columns`): as floats (NaN where
    empty), or as text when a field is not a number. Raises ValueError for such text.
    """
    values = recording.columns.get(SCORE_COLUMN)  # unknown_columns today; any column will do
    if values is None:
        return None
    if values.dtype == object:
        try:
            values = np.array([float(v) if str(v).strip() else math.nan for v in values])
        except ValueError:
            where = f"{recording.path}: " if getattr(recording, "path", None) else ""
            raise ValueError(f"{where}the {SCORE_COLUMN!r} column holds text; it must be a "
                             "flag (1 = score this row, 0 or empty = do not)") from None
    return np.asarray(values, dtype=np.float64) == 1.0


def turned_source(source: StreamSource, turn: np.ndarray, label: str | None = None
                  ) -> StreamSource:
    """``source`` with its sensor frame turned by the unit quaternion ``turn``
    (:func:`app.core.heading_metrics.turn_block`: samples, field and reference alike)."""
    pieces = source.pieces

    def turned_pieces() -> Iterator[tuple[SampleBlock, np.ndarray | None]]:
        assert pieces is not None
        for piece, mask in pieces():
            yield turn_block(piece, turn), mask

    return StreamSource(
        label or source.label, lambda: [turn_block(b, turn) for b in source.blocks()],
        source.description, source.score_mask, source.scoring,
        None if pieces is None else turned_pieces,
    )


def magnetic_heading(cls: type[OrientationFilter], values: Mapping[str, Any],
                     stream_has_field: bool) -> bool:
    """True when filter ``cls`` with parameter ``values`` takes heading from the field."""
    if not (stream_has_field and cls.uses_magnetometer):
        return False
    return bool(cls(**dict(values)).parameter_values().get("magnetometer", False))


# -- scoring ---------------------------------------------------------------------------------
def _resolve(spec: FilterSpec) -> type[OrientationFilter]:
    if isinstance(spec, str):
        try:
            return FILTERS[spec]
        except KeyError:
            raise KeyError(f"no filter named {spec!r} (available: {', '.join(FILTERS)})") from None
    return spec


def run_filter(
    orientation_filter: OrientationFilter, stream: SampleBlock, block: int = DEFAULT_BLOCK
) -> tuple[np.ndarray, float]:
    """Quaternions (N, 4) of a filter over ``stream`` and the seconds spent in ``process``.

    The stream goes in blocks of ``block`` samples, except to an offline filter (a smoother,
    ``offline`` True): that one gets the whole stream in a single ``process`` call.
    """
    orientation_filter.warm_up()
    out = np.empty((len(stream), 4))
    elapsed = 0.0
    row = 0
    pieces = [stream] if type(orientation_filter).offline else split_block(stream, block)
    for piece in pieces:
        start = time.perf_counter()
        result = orientation_filter.process(piece)
        elapsed += time.perf_counter() - start
        out[row : row + len(piece)] = result.quat
        row += len(piece)
    return out, elapsed


def evaluate_filter(
    spec: FilterSpec, stream: SampleBlock, *, skip_s: float = DEFAULT_SKIP_S,
    block: int = DEFAULT_BLOCK, repeats: int = DEFAULT_REPEATS,
    score_mask: np.ndarray | None = None, **values: Any,
) -> FilterScore:
    """Score one filter (fresh, with parameter ``values``) on a stream with a reference.

    The stream is run ``repeats`` times by fresh filters; the errors come from the first run,
    the throughput from the fastest (short streams time noisily). ``score_mask`` (N,) bool:
    score exactly these rows instead of those after ``skip_s`` (see :func:`error_statistics`).
    """
    if stream.reference_quat is None:
        raise ValueError("the stream has no reference orientation to compare with")
    cls = _resolve(spec)
    score = FilterScore(cls.name, cls.title or cls.name, samples=len(stream))
    try:
        quat, elapsed = run_filter(cls(**values), stream, block)
        for _ in range(repeats - 1):
            elapsed = min(elapsed, run_filter(cls(**values), stream, block)[1])
    except Exception as exc:  # one broken filter must not end the evaluation
        score.flag = "error"
        score.message = f"{type(exc).__name__}: {exc}"
        return score
    has_field = stream.mag_ut is not None
    stats = error_statistics(quat, stream.reference_quat, stream.t_s, skip_s, score_mask,
                             heading=has_field)
    score.heading_rmse_deg = stats["heading_rmse_deg"]
    score.total_rmse_deg = stats["total_rmse_deg"]
    score.magnetic = magnetic_heading(cls, values, has_field)
    score.rmse_deg = stats["rmse_deg"]
    score.max_deg = stats["max_deg"]
    score.scored_samples = stats["scored"]
    score.nan_samples = stats["nan"]
    score.samples_per_s = len(stream) / elapsed if elapsed > 0.0 else math.inf
    if score.nan_samples:
        score.flag = "NaN"
    elif stats["diverged"]:
        score.flag = "diverged"
    return score


def evaluate(
    blocks: Iterable[SampleBlock] | SampleBlock,
    filters: Sequence[FilterSpec] | None = None,
    *,
    skip_s: float = DEFAULT_SKIP_S,
    block: int = DEFAULT_BLOCK,
    repeats: int = DEFAULT_REPEATS,
    score_mask: np.ndarray | None = None,
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
) -> list[FilterScore]:
    """Score each filter (default: every registered one) on the same stream.

    ``parameters``: filter name -> parameter values (the others keep their defaults).
    """
    stream = blocks if isinstance(blocks, SampleBlock) else concatenate_blocks(blocks)
    names: Sequence[FilterSpec] = list(FILTERS) if filters is None else filters
    chosen = parameters or {}
    return [
        evaluate_filter(spec, stream, skip_s=skip_s, block=block, repeats=repeats,
                        score_mask=score_mask, **dict(chosen.get(_resolve(spec).name, {})))
        for spec in names
    ]


def _median_rate(steps: np.ndarray) -> float:
    """1 / the median time step; ValueError when time does not advance (every ``t`` equal,
    or going backwards): no rate, no duration, nothing to score against."""
    step = float(np.median(steps))
    if not step > 0.0 or not math.isfinite(step):
        raise ValueError(f"the time column does not advance (median step {step:g} s): the "
                         "rate and the duration are undefined")
    return 1.0 / step


def stream_summary(stream: SampleBlock) -> dict[str, float]:
    """Duration (s), samples, median rate (Hz) and gaps of a stream."""
    n = len(stream)
    duration = float(stream.t_s[-1] - stream.t_s[0]) if n > 1 else 0.0
    steps = np.diff(stream.t_s)
    rate = _median_rate(steps) if len(steps) else math.nan
    return {"duration_s": duration, "samples": n, "rate_hz": rate,
            "gaps": int(np.count_nonzero(stream.gap))}


def evaluate_source(
    source: StreamSource,
    filters: Sequence[FilterSpec] | None = None,
    *,
    skip_s: float = DEFAULT_SKIP_S,
    block: int = DEFAULT_BLOCK,
    repeats: int | None = None,
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
) -> SourceResult:
    """Score each filter on one source (its score mask, if any, chooses the rows).

    ``repeats`` None: one run for a stream of :data:`LARGE_STREAM` samples or more, else
    :data:`DEFAULT_REPEATS` (only the throughput depends on it).
    """
    if source.pieces is not None:
        return _evaluate_pieces(source, filters, skip_s=skip_s, block=block, repeats=repeats,
                                parameters=parameters)
    stream = concatenate_blocks(source.blocks())
    if stream.reference_quat is None:
        raise ValueError(f"{source.label}: the stream has no reference orientation")
    try:
        info = stream_summary(stream)
    except ValueError as exc:
        raise ValueError(f"{source.label}: {exc}") from None
    mask = source.score_mask
    rows = scoring_rows(stream.reference_quat, stream.t_s, skip_s, mask)
    if mask is not None:
        scoring = source.scoring or "rows marked by the score mask"
    else:
        scoring = f"after the first {skip_s:g} s"
    if repeats is None:
        repeats = 1 if len(stream) >= LARGE_STREAM else DEFAULT_REPEATS
    result = SourceResult(
        source.label, source.description, info["duration_s"], info["samples"], info["rate_hz"],  # type: ignore[arg-type]
        info["gaps"], int(np.count_nonzero(rows)), scoring, mask is not None,  # type: ignore[arg-type]
        has_field=stream.mag_ut is not None,
    )
    result.scores = evaluate(stream, filters, skip_s=skip_s, block=block, repeats=repeats,
                             score_mask=mask, parameters=parameters)
    return result


def rebatch(pieces: Iterable[tuple[SampleBlock, np.ndarray | None]], size: int
            ) -> Iterator[tuple[SampleBlock, np.ndarray | None]]:
    """The pieces again as blocks of exactly ``size`` rows (the last may be shorter), so a
    filter sees the same blocks as when the whole stream is split (:func:`split_block`)."""
    held: list[tuple[SampleBlock, np.ndarray | None]] = []
    count = 0
    for piece, mask in pieces:
        held.append((piece, mask))
        count += len(piece)
        if count < size:
            continue
        joined, joined_mask = _join_pieces(held)
        whole = count // size * size
        for start in range(0, whole, size):
            yield (next(split_block(_rows(joined, start, start + size), size)),
                   None if joined_mask is None else joined_mask[start:start + size])
        held = [(_rows(joined, whole, count),
                 None if joined_mask is None else joined_mask[whole:])] if whole < count else []
        count -= whole
    if held and count:
        yield _join_pieces(held)


def _join_pieces(held: list[tuple[SampleBlock, np.ndarray | None]]
                 ) -> tuple[SampleBlock, np.ndarray | None]:
    if len(held) == 1:
        return held[0]
    masks = [m for _, m in held]
    mask: np.ndarray | None = (None if any(m is None for m in masks)
                               else np.concatenate(masks))  # type: ignore[arg-type]
    return concatenate_blocks(b for b, _ in held), mask


def _rows(block: SampleBlock, start: int, stop: int) -> SampleBlock:
    """Rows ``start:stop`` of every column (views)."""
    ref, field = block.reference_quat, block.mag_ut
    return SampleBlock(block.t_s[start:stop], block.accel_m_s2[start:stop],
                       block.gyro_rad_s[start:stop], block.temp_degc[start:stop],
                       block.gap[start:stop], None if ref is None else ref[start:stop],
                       None if field is None else field[start:stop])


def _evaluate_pieces(
    source: StreamSource, filters: Sequence[FilterSpec] | None, *, skip_s: float, block: int,
    repeats: int | None, parameters: Mapping[str, Mapping[str, Any]] | None,
) -> SourceResult:
    """:func:`evaluate_source` over ``source.pieces``, in memory that does not grow with the
    stream: one pass feeds every online filter each block in turn (more passes only to time
    them when ``repeats`` > 1); offline filters get the stream whole."""
    assert source.pieces is not None
    names: Sequence[FilterSpec] = list(FILTERS) if filters is None else filters
    chosen = parameters or {}
    classes = [_resolve(spec) for spec in names]
    runs = [_OnlineRun(cls, dict(chosen.get(cls.name, {}))) for cls in classes
            if not cls.offline]
    figures = _StreamFigures()
    for repeat in range(1 if repeats is None else max(1, repeats)):
        for run in runs:
            run.start()
        t0: float | None = None
        for piece, mask in rebatch(source.pieces(), block):
            if t0 is None:
                t0 = float(piece.t_s[0])
            rows = None
            if repeat == 0:
                if piece.reference_quat is None:
                    raise ValueError(f"{source.label}: the stream has no reference orientation")
                rows = (mask if mask is not None else piece.t_s >= t0 + skip_s) & np.all(
                    np.isfinite(piece.reference_quat), axis=1)
                figures.add(piece, rows, mask is not None)
            if repeat == 0 and piece.mag_ut is not None:
                figures.has_field = True
            for run in runs:
                run.process(piece, rows)
        for run in runs:
            run.finish()
    scores = []
    for cls in classes:
        if cls.offline:
            stream, mask = _join_pieces(list(source.pieces()))
            scores.append(evaluate_filter(cls, stream, skip_s=skip_s, block=block,
                                          repeats=1 if repeats is None else repeats,
                                          score_mask=mask, **dict(chosen.get(cls.name, {}))))
        else:
            scores.append(next(r for r in runs if r.cls is cls).score(figures.samples,
                                                                       figures.has_field))
    scoring = ((source.scoring or "rows marked by the score mask") if figures.masked
               else f"after the first {skip_s:g} s")
    result = SourceResult(source.label, source.description, figures.duration_s,
                          figures.samples, figures.rate_hz, figures.gaps, figures.scored,
                          scoring, figures.masked, has_field=figures.has_field)
    result.scores = scores
    return result


class _StreamFigures:
    """Duration, samples, rate, gaps and scored rows of a stream seen in pieces."""

    def __init__(self) -> None:
        self.samples = self.gaps = self.scored = 0
        self.first = self.last = self.rate_hz = math.nan
        self.masked = False
        self.has_field = False

    def add(self, piece: SampleBlock, rows: np.ndarray, masked: bool) -> None:
        self.masked = self.masked or masked
        self.samples += len(piece)
        self.gaps += int(np.count_nonzero(piece.gap))
        self.scored += int(np.count_nonzero(rows))
        if math.isnan(self.first):
            self.first = float(piece.t_s[0])
        self.last = float(piece.t_s[-1])
        if math.isnan(self.rate_hz) and len(piece) > 1:  # the first block's median step
            self.rate_hz = _median_rate(np.diff(piece.t_s))

    @property
    def duration_s(self) -> float:
        return self.last - self.first if self.samples > 1 else 0.0


class _OnlineRun:
    """One online filter over a stream in pieces: its errors (first run) and fastest time."""

    def __init__(self, cls: type[OrientationFilter], values: dict[str, Any]) -> None:
        self.cls = cls
        self.values = values
        self.errors = ErrorAccumulator()
        self.best = math.inf
        self.failure = ""
        self.filter: OrientationFilter | None = None
        self.elapsed = 0.0

    def start(self) -> None:
        self.elapsed = 0.0
        if self.failure:
            return
        try:  # one broken filter must not end the evaluation
            self.filter = self.cls(**self.values)
            self.filter.warm_up()
        except Exception as exc:
            self.failure = f"{type(exc).__name__}: {exc}"

    def process(self, piece: SampleBlock, rows: np.ndarray | None) -> None:
        if self.failure or self.filter is None:
            return
        start = time.perf_counter()
        try:
            result = self.filter.process(piece)
        except Exception as exc:
            self.failure = f"{type(exc).__name__}: {exc}"
            return
        self.elapsed += time.perf_counter() - start
        if rows is not None:
            self.errors.heading = self.errors.heading or piece.mag_ut is not None
            self.errors.add(result.quat, piece.reference_quat, rows)  # type: ignore[arg-type]

    def finish(self) -> None:
        if not self.failure:
            self.best = min(self.best, self.elapsed)

    def score(self, samples: int, has_field: bool = False) -> FilterScore:
        score = FilterScore(self.cls.name, self.cls.title or self.cls.name, samples=samples)
        if self.failure:
            score.flag, score.message = "error", self.failure
            return score
        stats = self.errors.result()
        score.heading_rmse_deg = stats["heading_rmse_deg"]
        score.total_rmse_deg = stats["total_rmse_deg"]
        score.magnetic = magnetic_heading(self.cls, self.values, has_field)
        score.rmse_deg, score.max_deg = stats["rmse_deg"], stats["max_deg"]
        score.scored_samples, score.nan_samples = stats["scored"], stats["nan"]
        score.samples_per_s = samples / self.best if self.best > 0.0 else math.inf
        if score.nan_samples:
            score.flag = "NaN"
        elif stats["diverged"]:
            score.flag = "diverged"
        return score


def _complete_mean(values: Sequence[float]) -> float:
    """The mean, NaN unless every value is finite (a mean over fewer would not compare)."""
    return (float(np.mean(values)) if values and all(math.isfinite(v) for v in values)
            else math.nan)


def summarize(results: Sequence[SourceResult]) -> dict[str, dict[str, float | int]]:
    """Per filter over the sources: ``mean_rmse_deg`` (NaN unless every source has an RMSE:
    a mean over fewer sources would not compare), ``worst_rmse_deg`` (the largest per-source
    RMSE), ``max_deg`` (the largest error anywhere) and ``sources`` (how many have an RMSE);
    ``mean_heading_rmse_deg`` and ``mean_total_rmse_deg`` (NaN unless every source scored
    them) and ``magnetic`` (the filter took heading from the field on every source)."""
    names = list(dict.fromkeys(s.name for r in results for s in r.scores))
    summary: dict[str, dict[str, float | int]] = {}
    for name in names:
        scores = [r.score(name) for r in results]
        rmses = [s.rmse_deg if s is not None else math.nan for s in scores]
        finite = [v for v in rmses if math.isfinite(v)]
        maxima = [s.max_deg for s in scores if s is not None and math.isfinite(s.max_deg)]
        complete = len(finite) == len(rmses) and len(rmses) > 0
        headings = [s.heading_rmse_deg if s is not None else math.nan for s in scores]
        totals = [s.total_rmse_deg if s is not None else math.nan for s in scores]
        summary[name] = {
            "mean_heading_rmse_deg": _complete_mean(headings),
            "mean_total_rmse_deg": _complete_mean(totals),
            "magnetic": all(s is not None and s.magnetic for s in scores) and len(scores) > 0,
            "mean_rmse_deg": float(np.mean(finite)) if complete else math.nan,
            "worst_rmse_deg": max(finite) if finite else math.nan,
            "max_deg": max(maxima) if maxima else math.nan,
            "sources": len(finite),
        }
    return summary


def _json_number(value: float) -> float | None:
    """JSON has no NaN or infinity: those become null."""
    return float(value) if math.isfinite(value) else None


def results_json(
    results: Sequence[SourceResult], *, settings: Mapping[str, Any] | None = None,
    filters: Sequence[FilterSpec] | None = None,
    parameters: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict[str, Any]:
    """The results as a JSON-ready dict (NaN and infinity as null).

    ``{"settings": ..., "filters": [{name, title, offline, reference_only, parameters}],
    "sources": [{label, description, duration_s, samples, rate_hz, gaps, scored_samples,
    scoring, masked, filters: {name: {rmse_deg, max_deg, samples_per_s, flag, message,
    scored_samples, nan_samples, heading_rmse_deg, total_rmse_deg,
    heading_from_magnetometer}}, magnetometer}], "mean": {name: {rmse_deg, worst_rmse_deg,
    max_deg, sources, heading_rmse_deg, total_rmse_deg, heading_from_magnetometer}}}``.
    """
    specs = list(filters) if filters is not None else list(
        dict.fromkeys(s.name for r in results for s in r.scores))
    chosen = parameters or {}
    described = []
    for spec in specs:
        cls = _resolve(spec)
        values = cls(**dict(chosen.get(cls.name, {}))).parameter_values()
        described.append({"name": cls.name, "title": cls.title or cls.name,
                          "offline": bool(cls.offline),
                          "reference_only": bool(cls.reference_only), "parameters": values})
    sources = []
    for result in results:
        sources.append({
            "label": result.label, "description": result.description,
            "duration_s": _json_number(result.duration_s), "samples": result.samples,
            "rate_hz": _json_number(result.rate_hz), "gaps": result.gaps,
            "scored_samples": result.scored_samples, "scoring": result.scoring,
            "masked": result.masked, "magnetometer": result.has_field,
            "filters": {
                s.name: {"rmse_deg": _json_number(s.rmse_deg), "max_deg": _json_number(s.max_deg),
                         "samples_per_s": _json_number(s.samples_per_s), "flag": s.flag,
                         "message": s.message, "scored_samples": s.scored_samples,
                         "nan_samples": s.nan_samples,
                         "heading_rmse_deg": _json_number(s.heading_rmse_deg),
                         "total_rmse_deg": _json_number(s.total_rmse_deg),
                         "heading_from_magnetometer": s.magnetic}
                for s in result.scores
            },
        })
    mean = {
        name: {"rmse_deg": _json_number(float(v["mean_rmse_deg"])),
               "worst_rmse_deg": _json_number(float(v["worst_rmse_deg"])),
               "max_deg": _json_number(float(v["max_deg"])), "sources": v["sources"],
               "heading_rmse_deg": _json_number(float(v["mean_heading_rmse_deg"])),
               "total_rmse_deg": _json_number(float(v["mean_total_rmse_deg"])),
               "heading_from_magnetometer": bool(v["magnetic"])}
        for name, v in summarize(results).items()
    }
    return {"settings": dict(settings or {}), "filters": described, "sources": sources,
            "mean": mean}
