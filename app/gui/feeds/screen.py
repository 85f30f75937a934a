"""Whether a view can be seen: shown, not in a hidden dock or tab, not covered entirely."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QWidget

EXPOSURE_CHECK_S = 0.25
"""How long a view found uncovered is taken as uncovered (hidden views are noticed at
once: ``isVisible`` is checked every frame; only the costlier region test is kept)."""


def on_screen(widget: QWidget) -> bool:
    """Whether any of ``widget`` can be seen: shown, not in a hidden dock or tab, not covered
    entirely, its window not minimised."""
    return widget.isVisible() and not widget.window().isMinimized() and _exposed(widget)


class ScreenPresence:
    """:func:`on_screen` for a view asked every frame: the region test (the costly part)
    is redone at most every ``EXPOSURE_CHECK_S`` while the view stays visible."""

    def __init__(self, widget: QWidget) -> None:
        self.widget = widget
        self._checked = -np.inf
        self._exposed = False

    def __call__(self, now: float) -> bool:
        widget = self.widget
        if not widget.isVisible() or widget.window().isMinimized():
            self._checked = -np.inf
            return False
        if now - self._checked >= EXPOSURE_CHECK_S:
            self._checked = now
            self._exposed = _exposed(widget)
        return self._exposed


def _exposed(widget: QWidget) -> bool:
    """Some of ``widget`` or of a child is uncovered (children that fill their parent leave
    the parent's own visible region empty)."""
    if not widget.visibleRegion().isEmpty():
        return True
    children = widget.findChildren(QWidget, options=Qt.FindChildOption.FindDirectChildrenOnly)
    return any(child.isVisible() and _exposed(child) for child in children)
