"""The NDR and FDI curves of ``inclinometer evaluate-faults --png DIR``, painted with QPainter.

From the evaluation's JSON document (:func:`app.core.faults.evaluation.evaluation_json`), per
group of sources (``simulator``, ``broad``, ...):

- ``ndr_GROUP.png``: NDR against the injected sigma (multiples of the channel's own noise, log
  scale), on the injected channel (left) and the largest on the five clean channels (right);
- ``fdi_GROUP.png``: FDI (samples until declared, log scale) against sigma, one panel per theta;
  points where at least half the sources never declared are left out.

Offscreen painting on a QImage needs a QGuiApplication (fonts); :func:`save_fault_curves`
makes one when none runs. Accelerometer axes are solid lines with dots, gyroscope axes dashed
with squares, x / y / z in the app's axis colours.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QColor, QFont, QGuiApplication, QImage, QPainter, QPainterPath, QPen

WIDTH, HEIGHT = 1280, 560
AXIS_X, AXIS_Y, AXIS_Z = "#e86a5f", "#6cc77a", "#5b9be6"
"""The x, y and z axes' colours (the dark theme's, app/gui/theme.py, as these curves always
had); on paper whatever the window's theme."""
BACKGROUND = "#ffffff"
INK = "#202428"
GRID = "#dde1e5"
CHANNEL_STYLE: dict[str, tuple[str, bool]] = {
    "ax": (AXIS_X, False), "ay": (AXIS_Y, False), "az": (AXIS_Z, False),
    "gx": (AXIS_X, True), "gy": (AXIS_Y, True), "gz": (AXIS_Z, True),
}
"""Channel -> (colour, dashed): the gyroscope's axes dashed."""


@dataclass(slots=True)
class _Axes:
    """One panel: a plotting rectangle with log x (and linear or log y)."""

    rect: QRectF
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    y_log: bool

    def x(self, value: float) -> float:
        lo, hi = (math.log10(v) for v in self.x_range)
        return self.rect.left() + (math.log10(value) - lo) / (hi - lo) * self.rect.width()

    def y(self, value: float) -> float:
        lo, hi = self.y_range
        if self.y_log:
            lo, hi, value = math.log10(lo), math.log10(hi), math.log10(value)
        return self.rect.bottom() - (value - lo) / (hi - lo) * self.rect.height()


def save_fault_curves(document: dict[str, Any], directory: str | Path) -> list[Path]:
    """Write ``ndr_GROUP.png`` and ``fdi_GROUP.png`` for every group; the paths written."""
    _ = QGuiApplication.instance() or QGuiApplication(["inclinometer"])
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name, group in document.get("groups", {}).items():
        stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", name).strip("-") or "group"
        for kind, painter in (("ndr", _paint_ndr), ("fdi", _paint_fdi)):
            image = QImage(WIDTH, HEIGHT, QImage.Format.Format_RGB32)
            image.fill(QColor(BACKGROUND))
            painter(image, name, group)
            path = out / f"{kind}_{stem}.png"
            if not image.save(str(path), "PNG"):
                raise OSError(f"cannot write {path}")
            written.append(path)
    return written


# -- figures ---------------------------------------------------------------------------------------
def _paint_ndr(image: QImage, name: str, group: dict[str, Any]) -> None:
    multiples = [float(m) for m in group["sigma_multiples"]]
    channels = list(group["channels"])
    sources = len(group["sources"])
    with _painting(image) as p:
        _title(p, f"NDR: fraction of samples flagged faulty with noise injected into one "
                  f"channel ({name}, {sources} source{'s' if sources != 1 else ''})")
        panels = _panel_rects(2)
        for rect, key, title in zip(panels, ("ndr_injected", "ndr_others_max"),
                                    ("on the injected channel",
                                     "largest on the five other (clean) channels"), strict=True):
            axes = _Axes(rect, _x_range(multiples), (0.0, 1.0), y_log=False)
            _frame(p, axes, title, multiples, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0],
                   lambda v: f"{v:.1f}", "NDR")
            for channel in channels:
                _curve(p, axes, channel, multiples, group[key][channel])
        _legend(p, channels, panels[-1])


def _paint_fdi(image: QImage, name: str, group: dict[str, Any]) -> None:
    multiples = [float(m) for m in group["sigma_multiples"]]
    channels = list(group["channels"])
    thetas = [str(t) for t in group["thetas"]]
    values = [v for th in thetas for c in channels for v in group["fdi_samples"][th][c]
              if v is not None and v > 0]
    lo = 10.0 ** math.floor(math.log10(min(values))) if values else 1.0
    hi = 10.0 ** math.ceil(math.log10(max(values) * 1.0001)) if values else 1e4
    hi = max(hi, lo * 10.0)
    rates = ", ".join(f"{r:.4g}" for r in group.get("rates_hz", []))
    with _painting(image) as p:
        _title(p, f"FDI: samples until a fault is declared (cumulative flagged samples reach "
                  f"theta), median over the sources ({name}, {rates} Hz)")
        _note(p, "median over the sources where declared; hollow: declared in only some of "
                 "them, missing: in none; channels that agree draw on top of each other")
        panels = _panel_rects(len(thetas))
        decades = range(round(math.log10(lo)), round(math.log10(hi)) + 1)
        steps = (1.0, 2.0, 5.0) if len(decades) <= 3 else (1.0,)
        ticks = [step * 10.0 ** k for k in decades for step in steps
                 if step * 10.0 ** k <= hi * 1.0001]
        for rect, th in zip(panels, thetas, strict=True):
            axes = _Axes(rect, _x_range(multiples), (lo, hi), y_log=True)
            _frame(p, axes, f"theta = {th}", multiples, ticks, lambda v: f"{v:g}",
                   "samples" if th == thetas[0] else "")
            total = len(group["sources"])
            for channel in channels:
                partial = [n < total for n in group["fdi_detected"][th][channel]]
                _curve(p, axes, channel, multiples, group["fdi_samples"][th][channel], partial)
        _legend(p, channels, panels[-1])


# -- drawing ---------------------------------------------------------------------------------------
class _painting:
    """``with _painting(image) as p``: an antialiased painter that is always ended."""

    def __init__(self, image: QImage) -> None:
        self.painter = QPainter(image)

    def __enter__(self) -> QPainter:
        self.painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        self.painter.setRenderHint(QPainter.RenderHint.TextAntialiasing)
        font = QFont()
        font.setPixelSize(15)
        self.painter.setFont(font)
        return self.painter

    def __exit__(self, *exc: object) -> None:
        self.painter.end()


def _panel_rects(count: int) -> list[QRectF]:
    left, right, top, bottom, gap = 80.0, 110.0, 70.0, 86.0, 70.0
    width = (WIDTH - left - right - gap * (count - 1)) / count
    return [QRectF(left + i * (width + gap), top, width, HEIGHT - top - bottom)
            for i in range(count)]


def _x_range(multiples: Sequence[float]) -> tuple[float, float]:
    lo, hi = min(multiples), max(multiples)
    if hi <= lo:
        lo, hi = lo / 2.0, hi * 2.0
    return lo / 1.25, hi * 1.25


def _title(p: QPainter, text: str) -> None:
    font = p.font()
    font.setPixelSize(17)
    font.setBold(True)
    p.save()
    p.setFont(font)
    p.setPen(QColor(INK))
    p.drawText(QRectF(0, 12, WIDTH, 30), Qt.AlignmentFlag.AlignCenter, text)
    p.restore()


def _note(p: QPainter, text: str) -> None:
    p.save()
    p.setPen(QColor(INK))
    p.drawText(QRectF(0, HEIGHT - 24, WIDTH, 20), Qt.AlignmentFlag.AlignCenter, text)
    p.restore()


def _frame(p: QPainter, axes: _Axes, title: str, x_ticks: Sequence[float],
           y_ticks: Sequence[float], y_text, y_label: str) -> None:
    rect = axes.rect
    p.setPen(QPen(QColor(GRID), 1))
    for v in x_ticks:
        p.drawLine(QPointF(axes.x(v), rect.top()), QPointF(axes.x(v), rect.bottom()))
    for v in y_ticks:
        p.drawLine(QPointF(rect.left(), axes.y(v)), QPointF(rect.right(), axes.y(v)))
    p.setPen(QPen(QColor(INK), 1.2))
    p.drawRect(rect)
    for v in x_ticks:
        p.drawText(QRectF(axes.x(v) - 30, rect.bottom() + 6, 60, 20),
                   Qt.AlignmentFlag.AlignHCenter | Qt.AlignmentFlag.AlignTop, f"{v:g}")
    for v in y_ticks:
        p.drawText(QRectF(rect.left() - 70, axes.y(v) - 10, 62, 20),
                   Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter, y_text(v))
    p.drawText(QRectF(rect.left(), rect.bottom() + 30, rect.width(), 22),
               Qt.AlignmentFlag.AlignHCenter,
               "sigma (x own noise)" if rect.width() < 400 else
               "injected sigma / the channel's own noise per sample")
    p.drawText(QRectF(rect.left(), rect.top() - 26, rect.width(), 22),
               Qt.AlignmentFlag.AlignHCenter, title)
    if y_label:
        p.save()
        p.translate(rect.left() - 62, rect.center().y())
        p.rotate(-90)
        p.drawText(QRectF(-100, -20, 200, 20), Qt.AlignmentFlag.AlignCenter, y_label)
        p.restore()


def _curve(p: QPainter, axes: _Axes, channel: str, xs: Sequence[float],
           ys: Sequence[float | None], hollow: Sequence[bool] | None = None) -> None:
    colour, dashed = CHANNEL_STYLE.get(channel, ("#808080", False))
    pen = QPen(QColor(colour), 2.2)
    if dashed:
        pen.setStyle(Qt.PenStyle.DashLine)
    p.setPen(pen)
    lo, hi = axes.y_range
    path = QPainterPath()
    started = False
    points: list[tuple[QPointF, bool]] = []
    hollow = hollow if hollow is not None else [False] * len(xs)
    for x, y, empty in zip(xs, ys, hollow, strict=True):
        usable = y is not None and math.isfinite(y) and (not axes.y_log or y > 0)
        if not usable:
            started = False
            continue
        point = QPointF(axes.x(x), axes.y(min(max(float(y), lo), hi)))
        points.append((point, empty))
        if started:
            path.lineTo(point)
        else:
            path.moveTo(point)
            started = True
    p.setBrush(Qt.BrushStyle.NoBrush)
    p.drawPath(path)
    p.setPen(QPen(QColor(colour), 1.5))
    for point, empty in points:
        p.setBrush(QColor(BACKGROUND) if empty else QColor(colour))
        if dashed:
            p.drawRect(QRectF(point.x() - 3.5, point.y() - 3.5, 7, 7))
        else:
            p.drawEllipse(point, 4.0, 4.0)
    p.setBrush(Qt.BrushStyle.NoBrush)


def _legend(p: QPainter, channels: Sequence[str], last: QRectF) -> None:
    x = last.right() + 18
    y = last.top() + 10
    for channel in channels:
        colour, dashed = CHANNEL_STYLE.get(channel, ("#808080", False))
        pen = QPen(QColor(colour), 2.2)
        if dashed:
            pen.setStyle(Qt.PenStyle.DashLine)
        p.setPen(pen)
        p.drawLine(QPointF(x, y + 10), QPointF(x + 34, y + 10))
        p.setPen(QPen(QColor(INK), 1))
        p.drawText(QRectF(x + 40, y, 50, 20), Qt.AlignmentFlag.AlignVCenter, channel)
        y += 26
