"""A parameter study: every point on every recording, then cross-validation by trial and the
sensitivity around the optimum, as one JSON-ready dict (what ``inclinometer tune --json``
writes).

The runs go out in chunks of one recording and several points (:func:`plan_chunks`), so a
worker reads a recording once and keeps its compiled filter between runs; the chunks are
sized for a few per worker, which keeps them all busy to the end. Results are put back by
(point, recording) whatever the order they finish in, so any runner gives the same bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from app.core.filters import FILTERS
from app.services.tuning import cv, grid
from app.services.tuning.grid import Axis
from app.services.tuning.runner import Runner
from app.services.tuning.trials import SourceSpec, TrialScore, score_points

CHUNKS_PER_WORKER = 8
"""Chunks a worker gets on average: enough to even out their lengths at the end."""


class ProgressSink(Protocol):
    """What a study tells about its progress (the CLI draws a bar from it)."""

    def extend(self, runs: int) -> None: ...

    def advance(self, runs: int) -> None: ...


@dataclass(slots=True)
class StudyRequest:
    """What to study: one filter, its axes and points, the recordings, the folds."""

    filter: str
    axes: list[Axis]
    points: list[dict[str, Any]]
    sources: list[SourceSpec]
    folds: int | None = None
    """k for k-fold; None with ``groups`` False: leave-one-trial-out."""
    groups: bool = False
    search: str = "grid"
    seed: int | None = None
    settings: dict[str, Any] = field(default_factory=dict)


def plan_chunks(points: int, sources: int, workers: int) -> list[tuple[int, list[int]]]:
    """(recording index, point indices) per task: each recording's points cut into as many
    slices as it takes to give every worker about :data:`CHUNKS_PER_WORKER` tasks."""
    slices = max(1, math.ceil(CHUNKS_PER_WORKER * workers / max(1, sources))) \
        if workers > 1 else 1
    size = max(1, math.ceil(points / slices))
    return [(s, list(range(start, min(start + size, points))))
            for s in range(sources) for start in range(0, points, size)]


def run_points(runner: Runner, filter_name: str, sources: list[SourceSpec],
               points: list[dict[str, Any]], progress: ProgressSink | None = None
               ) -> list[list[TrialScore]]:
    """``scores[point][recording]`` for every point on every recording."""
    chunks = plan_chunks(len(points), len(sources), runner.workers)
    handles = [runner.source(spec) for spec in sources]
    calls = [(handles[s], filter_name, [(p, points[p]) for p in members])
             for s, members in chunks]
    if progress is not None:
        progress.extend(len(points) * len(sources))
    results = runner.run(score_points, calls, [len(m) for _, m in chunks],
                         None if progress is None else progress.advance)
    table: list[list[TrialScore | None]] = [[None] * len(sources) for _ in points]
    for (s, _), scored in zip(chunks, results, strict=True):
        for p, score in scored:
            table[p][s] = score
    return table  # type: ignore[return-value]


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _mean(row: list[TrialScore]) -> float:
    """Mean RMSE over the recordings; NaN unless every run is usable (as ``evaluate``)."""
    if not row or not all(s.usable for s in row):
        return math.nan
    return float(np.mean([s.rmse_deg for s in row]))


def _entry(index: int, params: dict[str, Any], row: list[TrialScore],
           labels: list[str]) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "point": index, "params": params, "rmse_deg": _number(_mean(row)),
        "worst_rmse_deg": _number(max((s.rmse_deg for s in row if s.usable),
                                      default=math.nan)),
        "trials": {label: _number(s.rmse_deg) for label, s in zip(labels, row, strict=True)},
    }
    flags = {label: (s.flag if not s.message else f"{s.flag}: {s.message}")
             for label, s in zip(labels, row, strict=True) if s.flag != "ok"}
    if flags:
        entry["flags"] = flags
    return entry


def _folds(request: StudyRequest, labels: list[str]) -> tuple[list[cv.Fold], str]:
    if request.groups:
        return cv.group_folds(labels), "leave-one-group-out"
    if len(labels) < 2:
        raise ValueError("cross-validation needs two recordings or more")
    if request.folds is None:
        folds = cv.kfold(len(labels), len(labels))
        for fold in folds:
            fold.name = labels[fold.held_out[0]]
        return folds, "leave-one-trial-out"
    return cv.kfold(len(labels), request.folds), f"{request.folds}-fold"


def sensitivity_points(axes: list[Axis], points: list[dict[str, Any]],
                       optimum: dict[str, Any]) -> list[tuple[str, str, dict[str, Any] | None]]:
    """(parameter, step, point or None) around the optimum: a real parameter at x0.5 and x2
    (None where that is the optimum itself: zero, or at its limit), an integer or a boolean
    at the neighbouring values of the study (a boolean: the other value)."""
    found: list[tuple[str, str, dict[str, Any] | None]] = []
    for axis in axes:
        value = optimum[axis.name]
        if axis.spec.kind == "float":
            for step, factor in (("x0.5", 0.5), ("x2", 2.0)):
                moved = grid.scaled(axis.spec, float(value), factor)
                found.append((axis.name, step,
                              None if moved is None else {**optimum, axis.name: moved}))
            continue
        if axis.spec.kind == "bool":
            steps = [("other", not value)]
        else:
            steps = grid.neighbours([p[axis.name] for p in points], value) or [
                (step, v) for step, v in (("lower", value - 1), ("higher", value + 1))
                if axis.spec.minimum <= v <= axis.spec.maximum]
        found.extend((axis.name, step, {**optimum, axis.name: v}) for step, v in steps)
    return found


def _sensitivity(request: StudyRequest, runner: Runner, table: list[list[TrialScore]],
                 best: int, labels: list[str], progress: ProgressSink | None
                 ) -> tuple[list[dict[str, Any]], int]:
    """The sensitivity rows, and how many points were run for them (those not in the study)."""
    optimum = request.points[best]
    planned = sensitivity_points(request.axes, request.points, optimum)
    extra = [p for _, _, p in planned if p is not None and p not in request.points]
    extra = [p for i, p in enumerate(extra) if p not in extra[:i]]
    extra_table = run_points(runner, request.filter, request.sources, extra, progress) \
        if extra else []
    best_mean = _mean(table[best])
    rows = []
    for name, step, point in planned:
        row: dict[str, Any] = {"param": name, "step": step}
        if point is None:
            row.update(value=None, rmse_deg=None, delta_deg=None,
                       note="the optimum itself (zero or at the limit)")
        else:
            scores = (table[request.points.index(point)] if point in request.points
                      else extra_table[extra.index(point)])
            mean = _mean(scores)
            row.update(value=point[name], rmse_deg=_number(mean),
                       delta_deg=_number(mean - best_mean),
                       trials={label: _number(s.rmse_deg)
                               for label, s in zip(labels, scores, strict=True)})
        rows.append(row)
    return rows, len(extra)


def run_study(request: StudyRequest, runner: Runner,
              progress: ProgressSink | None = None) -> dict[str, Any]:
    """Run the study and return its JSON-ready document (NaN as null): ``settings``,
    ``sources``, ``results`` (per point: ``params``, mean ``rmse_deg``, ``trials``), ``best``,
    ``cross_validation``, ``cross_validated_rmse_deg``, ``sensitivity``, ``runs`` (filter
    runs, the sensitivity's included)."""
    labels = [s.label for s in request.sources]
    folds, scheme = _folds(request, labels)
    table = run_points(runner, request.filter, request.sources, request.points, progress)
    rmse = np.array([[s.rmse_deg for s in row] for row in table], dtype=np.float64)
    usable = np.array([[s.usable for s in row] for row in table], dtype=bool)
    best = cv.best_point(rmse, usable, list(range(len(labels))))
    validation = cv.cross_validate(rmse, usable, folds, scheme)
    document: dict[str, Any] = {
        "settings": {
            **request.settings, "filter": request.filter, "search": request.search,
            "seed": request.seed, "points": len(request.points),
            "axes": {a.name: (list(a.values) if not a.is_range else [a.low, a.high])
                     for a in request.axes},
            "filter_defaults": FILTERS[request.filter]().parameter_values(),
        },
        "sources": [{"label": label, "group": cv.broad_group(label)} for label in labels],
        "results": [_entry(i, p, table[i], labels) for i, p in enumerate(request.points)],
        "best": None if best < 0 else {"point": best, "params": request.points[best],
                                       "rmse_deg": _number(_mean(table[best]))},
        "cross_validation": {
            "scheme": scheme,
            "folds": [{"name": f.name, "held_out": [labels[t] for t in f.held_out],
                       "chosen_point": None if f.chosen_point < 0 else f.chosen_point,
                       "params": (None if f.chosen_point < 0
                                  else request.points[f.chosen_point]),
                       "train_rmse_deg": _number(f.train_rmse_deg),
                       "held_out_rmse_deg": _number(f.held_out_rmse_deg)}
                      for f in validation.folds],
            "held_out_per_trial": {label: _number(v) for label, v in
                                   zip(labels, validation.held_out_per_trial, strict=True)},
        },
        "cross_validated_rmse_deg": _number(validation.cross_validated_rmse_deg),
    }
    sensitivity, extra = (([], 0) if best < 0 or not request.axes
                          else _sensitivity(request, runner, table, best, labels, progress))
    document["sensitivity"] = sensitivity
    document["runs"] = (len(request.points) + extra) * len(labels)
    return document
