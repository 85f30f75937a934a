"""How the window fits its screen: the first window's rectangle, which status fields fit and
how far apart a short plot's axis labels must be.

Plain arithmetic on integer pixels, so it is tested without a screen; the GUI passes in what
Qt measured (the screen's available geometry, the fields' widths).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple


class Rect(NamedTuple):
    """A rectangle in pixels: left, top, width, height."""

    x: int
    y: int
    width: int
    height: int


def first_window_rect(available: Rect, frame: tuple[int, int, int, int] = (0, 0, 0, 0)) -> Rect:
    """The first window's client rectangle: the whole available screen (without the task bar
    and panels), less the window manager's frame ``(left, top, right, bottom)``, so that the
    framed window is never larger than the screen."""
    left, top, right, bottom = (max(0, margin) for margin in frame)
    return Rect(
        available.x + left,
        available.y + top,
        max(1, available.width - left - right),
        max(1, available.height - top - bottom),
    )


def fields_that_fit(widths: Sequence[int], available: int, spacing: int = 0) -> list[bool]:
    """Which fields to show, given in priority order (most important first): each in turn
    while the shown ones, with ``spacing`` between them, still fit in ``available`` pixels.
    A field that does not fit is hidden and a less important, narrower one may still fit;
    a field of width 0 (nothing to show) is hidden and takes no room."""
    shown: list[bool] = []
    used = 0
    for width in widths:
        if width <= 0:
            shown.append(False)
            continue
        needed = width + (spacing if used else 0)
        fits = used + needed <= available
        shown.append(fits)
        if fits:
            used += needed
    return shown


def label_step(span: float, step: float, length_px: float, min_gap_px: float) -> float:
    """The tick step of an axis whose labels must not overlap: ``step`` (a 1-2-5 multiple of
    a power of ten), made coarser along 1, 2, 5, 10 ... until two labels lie at least
    ``min_gap_px`` apart on an axis ``length_px`` long showing a range ``span`` wide."""
    if not (span > 0 and step > 0 and length_px > 0):
        return step
    while step / span * length_px < min_gap_px:
        exponent = math.floor(math.log10(step))
        mantissa = step / 10.0 ** exponent
        if mantissa < 1.5:
            step = 2.0 * 10.0 ** exponent
        elif mantissa < 3.5:
            step = 5.0 * 10.0 ** exponent
        else:
            step = 10.0 ** (exponent + 1)
    return step
