"""A study's tables as text (its plot is :mod:`app.documents.tuning_plot`)."""

from __future__ import annotations

import math
from typing import Any


def _fmt(value: float | None, spec: str = ".3f") -> str:
    return "-" if value is None or not math.isfinite(value) else format(value, spec)


def _params(params: dict[str, Any] | None) -> str:
    if params is None:
        return "-"
    if not params:
        return "(defaults)"
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in params.items())


def summary_lines(document: dict[str, Any]) -> list[str]:
    """The study in a few tables: best points, cross-validation, sensitivity."""
    settings = document["settings"]
    results = document["results"]
    lines = [f"{settings['filter']}: {len(results)} points x {len(document['sources'])} "
             f"recordings ({settings['search']}), inclination RMSE over the scored rows"]
    ranked = sorted((r for r in results if r["rmse_deg"] is not None),
                    key=lambda r: (r["rmse_deg"], r["point"]))
    lines.append(f"  {'rank':>4}  {'mean deg':>8}  {'worst':>6}  params")
    for rank, entry in enumerate(ranked[:5], 1):
        lines.append(f"  {rank:>4}  {_fmt(entry['rmse_deg']):>8}  "
                     f"{_fmt(entry['worst_rmse_deg']):>6}  {_params(entry['params'])}")
    failed = len(results) - len(ranked)
    if failed:
        lines.append(f"  {failed} point(s) failed on a recording (see 'flags' in the JSON)")
    validation = document["cross_validation"]
    lines.append("")
    lines.append(f"Cross-validation ({validation['scheme']}): chosen on the other trials, "
                 "scored on the held-out ones")
    width = max(8, *(len(f["name"]) for f in validation["folds"]))
    lines.append(f"  {'fold':<{width}}  {'trials':>6}  {'train':>6}  {'held-out':>8}  chosen")
    for fold in validation["folds"]:
        lines.append(f"  {fold['name']:<{width}}  {len(fold['held_out']):>6}  "
                     f"{_fmt(fold['train_rmse_deg']):>6}  {_fmt(fold['held_out_rmse_deg']):>8}  "
                     f"{_params(fold['params'])}")
    best = document["best"]
    lines.append(f"  cross-validated RMSE (mean over the held-out trials): "
                 f"{_fmt(document['cross_validated_rmse_deg'])} deg; in-sample optimum "
                 f"{_fmt(None if best is None else best['rmse_deg'])} deg")
    if document["sensitivity"]:
        lines.append("")
        lines.append(f"Sensitivity around the optimum ({_params(best['params'])})")
        lines.append(f"  {'parameter':<22}  {'step':>6}  {'value':>9}  {'mean deg':>8}  "
                     f"{'change':>7}")
        for row in document["sensitivity"]:
            value = row["value"]
            text = "-" if value is None else (f"{value:g}" if isinstance(value, float)
                                              else str(value))
            change = "-" if row["delta_deg"] is None else f"{row['delta_deg']:+.3f}"
            lines.append(f"  {row['param']:<22}  {row['step']:>6}  {text:>9}  "
                         f"{_fmt(row['rmse_deg']):>8}  {change:>7}")
    return lines
