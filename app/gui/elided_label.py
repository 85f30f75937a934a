"""A one-line label for text that changes while streaming (status fields, live figures).

A ``QLabel`` asks every layout above it, up to the main window, to be redone on each
``setText``: the main window then re-places every dock and repaints large areas, several times
a second for a status line. :class:`ElidedLabel` keeps its text itself and repaints only its
own rectangle; it asks for a new layout only when a text is wider than any it has shown (its
width grows to fit the widest text, and does not shrink back as figures change). When it is
given less room than the text needs, the end becomes "…" and the whole text is in the tooltip.
"""

from __future__ import annotations

import math

from PySide6.QtCore import QEvent, QSize, Qt
from PySide6.QtGui import QFontMetricsF, QPainter, QPaintEvent
from PySide6.QtWidgets import QLabel, QStyle, QStyleOption, QWidget


class ElidedLabel(QLabel):
    """A one-line label that repaints, without relayout, when its text changes; elided with
    "…" when narrower than its text."""

    MINIMUM_WIDTH = 48

    def __init__(self, text: str = "", parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._text = ""
        self._widest = 0.0
        self._reserve = ""
        self.setText(text)

    def reserve(self, text: str) -> None:
        """Never give this label less room than ``text`` needs in its current font (a figure
        that must never be cut, "999 fps"): the room follows font and theme changes."""
        self._reserve = text
        self.updateGeometry()

    def text(self) -> str:  # type: ignore[override]
        return self._text

    def setText(self, text: str) -> None:  # type: ignore[override]
        """Show ``text`` (the same text again does nothing)."""
        text = str(text)
        if text == self._text:
            return
        self._text = text
        self.setToolTip(text)
        width = self._advance(text)
        if width > self._widest:
            self._widest = width
            self.updateGeometry()
        self.update()

    def clear(self) -> None:
        self.setText("")

    def changeEvent(self, event: QEvent) -> None:
        """A new font or style: measure the text again."""
        if event.type() in (QEvent.Type.FontChange, QEvent.Type.StyleChange):
            self._widest = self._advance(self._text)
            self.updateGeometry()
        super().changeEvent(event)

    def _advance(self, text: str) -> float:
        """The text's exact width: whole pixels (``QFontMetrics``) can be a fraction short,
        and the end of a text given exactly that room was cut to "…"."""
        return QFontMetricsF(self.font()).horizontalAdvance(text)

    def sizeHint(self) -> QSize:
        return self._size_for(max(self._widest, self._advance(self._reserve)))

    def minimumSizeHint(self) -> QSize:
        hint = self.sizeHint()
        if self._reserve:
            return self._size_for(self._advance(self._reserve))
        return QSize(min(hint.width(), self.MINIMUM_WIDTH), hint.height())

    def _size_for(self, text_width: float) -> QSize:
        margins = self.contentsMargins()
        return QSize(
            math.ceil(text_width) + 1 + margins.left() + margins.right() + 2 * self.margin(),
            self.fontMetrics().height() + margins.top() + margins.bottom() + 2 * self.margin(),
        )

    def isElided(self) -> bool:
        """Whether the text is cut short now."""
        shown = self.fontMetrics().elidedText(self._text, Qt.TextElideMode.ElideRight,
                                              self.contentsRect().width())
        return shown != self._text

    def paintEvent(self, event: QPaintEvent) -> None:
        painter = QPainter(self)
        option = QStyleOption()
        option.initFrom(self)
        self.style().drawPrimitive(QStyle.PrimitiveElement.PE_Widget, option, painter, self)
        rect = self.contentsRect()
        text = self.fontMetrics().elidedText(self._text, Qt.TextElideMode.ElideRight,
                                             rect.width())
        painter.setPen(self.palette().color(self.foregroundRole()))
        painter.drawText(rect, int(self.alignment()) | Qt.AlignmentFlag.AlignVCenter, text)
        painter.end()
