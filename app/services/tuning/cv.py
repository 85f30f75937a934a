"""Cross-validation by trial: which trials are held out together, and the held-out score.

A study's errors are a matrix ``rmse[point, trial]``. For each fold the parameters are chosen
on the other trials (the point with the least mean RMSE over them; a point that failed on one
of them, an error or a NaN estimate, is not eligible; ties go to the earlier point) and then
scored on the held-out trials. Every trial is held out exactly once, so the cross-validated
figure is the mean over the trials of their held-out RMSE: comparable with ``evaluate``'s mean
over the same trials, but never scored on data that chose the parameters.

Folds: ``k``-fold, trial ``i`` (in the order given) in fold ``i mod k``; or
leave-one-group-out with the groups of BROAD read from the file names (:func:`broad_group`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

GROUP_WORDS = (("disturbed", r"(?<!un)disturbed"), ("combined", r"combined"),
               ("rotation", r"rotation"), ("translation", r"translation"))
"""BROAD's trial groups and how a file name shows them (the first that matches wins)."""


@dataclass(slots=True)
class Fold:
    """One fold: the held-out trials (indices), and what was chosen and scored."""

    held_out: list[int]
    name: str = ""
    chosen_point: int = -1
    train_rmse_deg: float = math.nan
    held_out_rmse_deg: float = math.nan
    held_out_per_trial: list[float] = field(default_factory=list)


@dataclass(slots=True)
class CrossValidation:
    """Every fold, each trial's held-out RMSE and their mean."""

    scheme: str
    folds: list[Fold]
    held_out_per_trial: list[float]
    cross_validated_rmse_deg: float


def broad_group(label: str) -> str | None:
    """The BROAD group of a trial from its file name (``24_disturbed_tapping_A.csv`` ->
    "disturbed"), or None."""
    stem = Path(label).name.lower()
    for group, pattern in GROUP_WORDS:
        if re.search(pattern, stem):
            return group
    return None


def kfold(trials: int, k: int) -> list[Fold]:
    """``k`` folds over ``trials`` trials (ValueError unless 2 <= k <= trials)."""
    if not 2 <= k <= trials:
        raise ValueError(f"--folds must be from 2 to the number of trials ({trials}), not {k}")
    return [Fold(list(range(fold, trials, k)), f"fold {fold + 1}") for fold in range(k)]


def group_folds(labels: list[str]) -> list[Fold]:
    """One fold per BROAD group (ValueError when a name shows no group, or only one group)."""
    groups: dict[str, list[int]] = {}
    for index, label in enumerate(labels):
        group = broad_group(label)
        if group is None:
            words = ", ".join(g for g, _ in GROUP_WORDS)
            raise ValueError(f"--groups: {label}: the file name names no group ({words})")
        groups.setdefault(group, []).append(index)
    if len(groups) < 2:
        raise ValueError(f"--groups: every trial is in the group {next(iter(groups))!r}; "
                         "leave-one-group-out needs two groups or more (use --folds K)")
    return [Fold(members, name) for name, members in groups.items()]


def _mean_or_inf(values: np.ndarray) -> float:
    return float(np.mean(values)) if np.all(np.isfinite(values)) else math.inf


def best_point(rmse: np.ndarray, usable: np.ndarray, trials: list[int]) -> int:
    """The point with the least mean RMSE over ``trials`` among those usable on all of them
    (the earliest on a tie); -1 when none is."""
    means = [_mean_or_inf(np.where(usable[p, trials], rmse[p, trials], math.inf))
             for p in range(rmse.shape[0])]
    best = int(np.argmin(means)) if means else -1
    return best if best >= 0 and math.isfinite(means[best]) else -1


def cross_validate(rmse: np.ndarray, usable: np.ndarray, folds: list[Fold],
                   scheme: str) -> CrossValidation:
    """Choose on the training trials, score on the held-out ones, for every fold.

    ``rmse`` (points, trials) and ``usable`` (same shape, bool). A fold whose training trials
    leave no usable point, or whose chosen point fails on a held-out trial, scores NaN: so
    does the cross-validated figure then (a failure is never averaged away).
    """
    trials = rmse.shape[1]
    per_trial = [math.nan] * trials
    for fold in folds:
        training = [t for t in range(trials) if t not in set(fold.held_out)]
        fold.chosen_point = best_point(rmse, usable, training)
        if fold.chosen_point < 0:
            continue
        row, ok = rmse[fold.chosen_point], usable[fold.chosen_point]
        fold.train_rmse_deg = float(np.mean(row[training]))
        fold.held_out_per_trial = [float(row[t]) if ok[t] else math.nan
                                   for t in fold.held_out]
        fold.held_out_rmse_deg = float(np.mean(fold.held_out_per_trial))
        for t, value in zip(fold.held_out, fold.held_out_per_trial, strict=True):
            per_trial[t] = value
    return CrossValidation(scheme, folds, per_trial, float(np.mean(per_trial)))
