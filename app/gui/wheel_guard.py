"""The mouse wheel scrolls panels; it never changes a field the user has not clicked into.

Qt gives spin boxes, combo boxes and sliders the wheel as they pass under the pointer, so
scrolling a dock changed whatever parameter happened to be under it (the EKF's initial bias
uncertainty went from 0.5 to 0.3155 that way). :class:`WheelGuard`, installed once on the
application, takes the wheel from such a field unless it has the keyboard focus and hands it
to the scroll area around it (or drops it, when there is none). It also gives those fields
``Qt.StrongFocus`` when they are first polished, so the wheel never focuses them either.

The filter sees every event of the application: it looks only at the event's type for all
but polish and wheel events (a few microseconds each).
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, QPointF, Qt
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import (
    QAbstractScrollArea,
    QAbstractSlider,
    QAbstractSpinBox,
    QApplication,
    QComboBox,
    QScrollBar,
    QWidget,
)

_WHEEL = QEvent.Type.Wheel
_POLISH = QEvent.Type.Polish
FIELD_TYPES = (QAbstractSpinBox, QComboBox, QAbstractSlider)
"""Widgets whose value the wheel changes (scroll bars excepted: scrolling is their job)."""


def is_guarded_field(widget: QObject) -> bool:
    """Whether the guard keeps the wheel from ``widget`` while it is not focused."""
    return isinstance(widget, FIELD_TYPES) and not isinstance(widget, QScrollBar)


class WheelGuard(QObject):
    """Application event filter: unfocused fields pass the wheel to their scroll area."""

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        kind = event.type()
        if kind != _WHEEL and kind != _POLISH:
            return False
        if not is_guarded_field(watched):
            return False
        assert isinstance(watched, QWidget)
        if kind == _POLISH:
            if watched.focusPolicy() == Qt.FocusPolicy.WheelFocus:
                watched.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
            return False
        if watched.hasFocus():
            return False
        assert isinstance(event, QWheelEvent)
        scroll_to(watched, event)
        return True  # the field never sees it


def scroll_to(field: QWidget, event: QWheelEvent) -> bool:
    """Give the wheel ``event`` (at ``field``) to the nearest scroll area around it; returns
    whether there was one."""
    parent = field.parentWidget()
    while parent is not None and not isinstance(parent, QAbstractScrollArea):
        parent = parent.parentWidget()
    if parent is None:
        return False
    viewport = parent.viewport()
    position = QPointF(viewport.mapFromGlobal(event.globalPosition().toPoint()))
    forwarded = QWheelEvent(
        position, event.globalPosition(), event.pixelDelta(), event.angleDelta(),
        event.buttons(), event.modifiers(), event.phase(), event.inverted(), event.source(),
    )
    QApplication.sendEvent(viewport, forwarded)
    return True


_guard: WheelGuard | None = None


def install(app: QApplication) -> WheelGuard:
    """Install the guard on ``app`` (once; later calls return the same guard)."""
    global _guard
    if _guard is None:
        _guard = WheelGuard()
        app.installEventFilter(_guard)
    return _guard
