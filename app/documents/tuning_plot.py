"""The plot of a parameter study (``inclinometer tune --png``), drawn with matplotlib's Agg
canvas: no window, no Qt, no pyplot state.

One panel per parameter: the mean RMSE of every point against that parameter (grey), the
least over the other parameters at each value (the profile, a line), the optimum (a star) and
the sensitivity points (squares); a dashed line marks the cross-validated RMSE.
"""

from __future__ import annotations

import io
import math
from typing import Any

from app.core.filters import FILTERS

MAX_TICKS = 12
"""Up to this many values studied, each is a tick of its own."""


def _numeric(value: Any) -> float:
    return float(value) if not isinstance(value, bool) else float(int(value))


def plot_png(document: dict[str, Any]) -> bytes:
    """The PNG of a study: error against each parameter (ValueError without parameters)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    names = list(document["settings"]["axes"])
    if not names:
        raise ValueError("--png: the study has no parameter to plot (give --param)")
    cls = FILTERS[document["settings"]["filter"]]
    figure = Figure(figsize=(4.2 * len(names), 3.6), dpi=100, layout="tight")
    FigureCanvasAgg(figure)
    axes = figure.subplots(1, len(names), squeeze=False)[0]
    results = [r for r in document["results"] if r["rmse_deg"] is not None]
    best = document["best"]
    for ax, name in zip(axes, names, strict=True):
        spec = cls.parameter_spec(name)
        xs = [_numeric(r["params"][name]) for r in results]
        ys = [r["rmse_deg"] for r in results]
        ax.scatter(xs, ys, s=10, color="0.6", label="every point")
        profile: dict[float, float] = {}
        for x, y in zip(xs, ys, strict=True):
            profile[x] = min(y, profile.get(x, math.inf))
        keys = sorted(profile)
        ax.plot(keys, [profile[k] for k in keys], "-o", color="tab:blue", ms=4,
                label="best over the others")
        for row in document["sensitivity"]:
            if row["param"] == name and row["rmse_deg"] is not None:
                ax.plot(_numeric(row["value"]), row["rmse_deg"], "s", color="tab:orange",
                        ms=6, label="sensitivity" if "sensitivity" not in
                        ax.get_legend_handles_labels()[1] else None)
        if best is not None:
            ax.plot(_numeric(best["params"][name]), best["rmse_deg"], "*", color="tab:red",
                    ms=14, label="optimum")
        cross = document["cross_validated_rmse_deg"]
        if cross is not None:
            ax.axhline(cross, ls="--", color="tab:green", lw=1, label="cross-validated")
        if spec.log_scale and xs and min(xs) > 0:
            ax.set_xscale("log")
        if spec.kind == "bool":
            ax.set_xticks([0.0, 1.0], ["false", "true"])
            ax.set_xlim(-0.5, 1.5)
        elif len(keys) <= MAX_TICKS:  # the values studied, written as given
            ax.set_xticks(keys, [f"{k:g}" for k in keys])
            ax.minorticks_off()
        unit = f" ({spec.unit})" if spec.unit else ""
        ax.set_xlabel(f"{name}{unit}")
        ax.set_ylabel("mean inclination RMSE (deg)")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    figure.suptitle(f"{document['settings']['filter']}: {len(results)} points over "
                    f"{len(document['sources'])} recordings", fontsize=10)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    return buffer.getvalue()
