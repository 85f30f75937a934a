"""A dock panel that scrolls down, never sideways, and is never narrower than its panel.

A plain ``QScrollArea`` with its horizontal scroll bar off lets the dock shrink below the
panel's minimum width, and the panel is then cut at the right (the Filter dock's combo box
lost half its width at 1366x768). This one asks for the panel's minimum width (plus the
vertical scroll bar) and only a little height: the panel scrolls down instead.
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, QSize, Qt
from PySide6.QtWidgets import QFrame, QScrollArea, QStyle, QWidget

MINIMUM_HEIGHT_PX = 80


class PanelScroller(QScrollArea):
    """Holds a dock's panel: scrolls it vertically (and sideways only if ``sideways``)."""

    def __init__(self, panel: QWidget, sideways: bool = False) -> None:
        super().__init__()
        self.sideways = sideways
        self.setWidgetResizable(True)
        self.setFrameShape(QFrame.Shape.NoFrame)
        if not sideways:
            self.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.setWidget(panel)
        panel.installEventFilter(self)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        """The panel's minimum width changed (a rebuilt form): the dock follows it."""
        if watched is self.widget() and event.type() == QEvent.Type.LayoutRequest:
            self.updateGeometry()
        return super().eventFilter(watched, event)

    def minimumSizeHint(self) -> QSize:
        hint = super().minimumSizeHint()
        panel = self.widget()
        if self.sideways or panel is None:
            return hint
        scroll_bar = self.style().pixelMetric(QStyle.PixelMetric.PM_ScrollBarExtent, None, self)
        margins = self.contentsMargins()
        width = (panel.minimumSizeHint().expandedTo(panel.minimumSize()).width() + scroll_bar
                 + margins.left() + margins.right())
        return QSize(width, min(hint.height(), MINIMUM_HEIGHT_PX))
