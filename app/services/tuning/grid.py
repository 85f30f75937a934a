"""The points of a parameter study: a grid over listed values, or a random search.

An :class:`Axis` is one filter parameter with the values to try (already validated against
the filter's :class:`~app.core.filters.ParameterSpec`) or, for a random search only, a range
``low..high`` drawn from uniformly (log-uniformly for a parameter the filter declares
``log_scale``; integers rounded). Points are dicts ``{parameter: value}`` in a fixed order:
a grid is the product of the axes in the order given (the last axis varies fastest); a
random search draws each axis independently from one seeded generator and drops repeated
points, so a seed always gives the same points.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.core.filters import ParameterSpec

MAX_POINTS = 100_000
"""The most points a study may have (a typo such as a doubled list must not run for days)."""


@dataclass(frozen=True, slots=True)
class Axis:
    """One parameter of a study: ``values`` to try, or a range ``(low, high)`` to draw from."""

    filter: str
    spec: ParameterSpec
    values: tuple[Any, ...] = ()
    low: float | None = None
    high: float | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def is_range(self) -> bool:
        return self.low is not None

    def draw(self, rng: np.random.Generator) -> Any:
        """One value: a listed one, or one from the range."""
        if not self.is_range:
            return self.values[int(rng.integers(len(self.values)))]
        assert self.low is not None and self.high is not None
        if self.spec.log_scale and self.low > 0.0:
            value = math.exp(rng.uniform(math.log(self.low), math.log(self.high)))
        else:
            value = float(rng.uniform(self.low, self.high))
        value = min(max(value, self.low), self.high)
        return round(value) if self.spec.kind == "int" else value


def grid_points(axes: list[Axis]) -> list[dict[str, Any]]:
    """Every combination of the axes' values (ValueError for a range: a grid needs values)."""
    ranged = [a for a in axes if a.is_range]
    if ranged:
        raise ValueError(f"{ranged[0].filter}.{ranged[0].name}: a range low..high needs "
                         "--random N (a grid takes listed values: V1,V2,...)")
    count = math.prod(len(a.values) for a in axes)
    if count > MAX_POINTS:
        raise ValueError(f"the grid has {count} points; at most {MAX_POINTS} (use --random N)")
    names = [a.name for a in axes]
    return [dict(zip(names, combo, strict=True))
            for combo in itertools.product(*(a.values for a in axes))]


def random_points(axes: list[Axis], count: int, seed: int) -> list[dict[str, Any]]:
    """``count`` points drawn with ``seed`` (fewer when the listed values allow fewer distinct
    points: repeats are dropped, the first kept)."""
    if not 1 <= count <= MAX_POINTS:
        raise ValueError(f"--random must be from 1 to {MAX_POINTS}")
    if all(not a.is_range for a in axes):
        count = min(count, math.prod(len(a.values) for a in axes))
    rng = np.random.default_rng(seed)
    points: list[dict[str, Any]] = []
    seen: set[tuple[Any, ...]] = set()
    for _ in range(count * 20):  # listed values repeat; give up long before forever
        point = {a.name: a.draw(rng) for a in axes}
        key = tuple(point.values())
        if key not in seen:
            seen.add(key)
            points.append(point)
            if len(points) == count:
                break
    return points


def neighbours(axis_values: list[Any], value: Any) -> list[tuple[str, Any]]:
    """The values next to ``value`` among ``axis_values`` (sorted), labelled "lower" and
    "higher": the sensitivity of an integer or boolean parameter."""
    ordered = sorted(set(axis_values))
    where = ordered.index(value)
    found = []
    if where > 0:
        found.append(("lower", ordered[where - 1]))
    if where + 1 < len(ordered):
        found.append(("higher", ordered[where + 1]))
    return found


def scaled(spec: ParameterSpec, value: float, factor: float) -> float | None:
    """``value * factor`` within the parameter's range; None when that is ``value`` itself
    (zero, or already at the limit)."""
    moved = min(max(value * factor, spec.minimum), spec.maximum)
    return None if moved == value else float(moved)
