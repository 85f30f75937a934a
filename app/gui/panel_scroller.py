"""A dock panel that scrolls rather than make the window larger, and is never cut.

A plain ``QScrollArea`` with its horizontal scroll bar off let a dock shrink below its
panel's minimum width, and the panel was then cut at the right (the Filter dock's combo box
lost half its width at 1366x768). This one scrolls both ways as needed, so a narrow dock still
reaches all of its panel, and tells the window how wide the dock must be to show the panel
without a sideways scroll bar (:meth:`fitting_width`, used for the default layout).
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, QSize, Signal
from PySide6.QtWidgets import QFrame, QScrollArea, QStyle, QWidget


class PanelScroller(QScrollArea):
    """Holds a dock's panel; it scrolls when the dock is smaller than the panel.

    ``wantsWidth(int)`` is emitted when the panel grew wider than the room it has (a form
    rebuilt for another filter, say): the window may widen the dock."""

    wantsWidth = Signal(int)

    KEEP_WIDTH_FROM_PX = 1200
    """In a window at least this wide, a panel that ``keeps_width`` is never narrower than
    its contents (the central view cannot take its room); a narrower window lets it scroll."""

    def __init__(self, panel: QWidget | None = None, keeps_width: bool = False,
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.keeps_width = keeps_width
        self.setWidgetResizable(True)
        self.setFrameShape(QFrame.Shape.NoFrame)
        if panel is not None:
            self.set_panel(panel)

    def set_panel(self, panel: QWidget) -> None:
        """Hold ``panel`` (best once this scroller has its final parent: Qt polishes again
        every widget of a polished tree that moves to another parent)."""
        self.setWidget(panel)
        panel.installEventFilter(self)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        if watched is self.widget() and event.type() == QEvent.Type.LayoutRequest:
            wanted = self.fitting_width()
            if self.keeps_width:
                self.updateGeometry()  # a new minimum width
            if self.isVisible() and wanted > self.width():
                self.wantsWidth.emit(wanted)
        return super().eventFilter(watched, event)

    def minimumSizeHint(self) -> QSize:
        hint = super().minimumSizeHint()
        if self.keeps_width and self.window().width() >= self.KEEP_WIDTH_FROM_PX:
            return QSize(max(hint.width(), self.fitting_width()), hint.height())
        return hint

    def fitting_width(self) -> int:
        """The width that shows the whole panel beside a vertical scroll bar."""
        panel = self.widget()
        scroll_bar = self.style().pixelMetric(QStyle.PixelMetric.PM_ScrollBarExtent, None, self)
        margins = self.contentsMargins()
        wanted = panel.minimumSizeHint().expandedTo(panel.minimumSize()).width()
        return wanted + scroll_bar + margins.left() + margins.right()
