"""The mouse wheel scrolls panels; it never changes a field the user has not clicked into.

Qt gives spin boxes, combo boxes and sliders the wheel as they pass under the pointer, so
scrolling a dock changed whatever parameter happened to be under it (the EKF's initial bias
uncertainty went from 0.5 to 0.3155 that way). :class:`WheelGuard`, an event filter on each
such field, takes the wheel from it unless it has the keyboard focus and hands it to the
scroll area around it (or drops it, when there is none). Fields also get
``Qt.StrongFocus``, so the wheel never focuses them either.

:func:`install` gives the application a style that does both as Qt polishes each widget
(:class:`GuardingStyle`, Fusion underneath): once per field, where an application-wide filter
had every event of every widget pass through Python, which made building the window 40 %
slower and cost the live window the same on each repaint.
"""

from __future__ import annotations

import atexit

from PySide6.QtCore import QEvent, QObject, QPointF, Qt
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import (
    QAbstractScrollArea,
    QAbstractSlider,
    QAbstractSpinBox,
    QApplication,
    QComboBox,
    QProxyStyle,
    QScrollBar,
    QWidget,
)

_WHEEL = QEvent.Type.Wheel
BASE_STYLE = "Fusion"
FIELD_TYPES = (QAbstractSpinBox, QComboBox, QAbstractSlider)
"""Widgets whose value the wheel changes (scroll bars excepted: scrolling is their job)."""


def is_guarded_field(widget: QObject) -> bool:
    """Whether the guard keeps the wheel from ``widget`` while it is not focused."""
    return isinstance(widget, FIELD_TYPES) and not isinstance(widget, QScrollBar)


class WheelGuard(QObject):
    """Event filter on a field: while it is not focused, the wheel goes to its scroll area."""

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        if event.type() != _WHEEL or not isinstance(watched, QWidget) or watched.hasFocus():
            return False
        assert isinstance(event, QWheelEvent)
        scroll_to(watched, event)
        return True  # the field never sees it

    def guard(self, widget: QWidget) -> None:
        """Guard ``widget`` if it is a field (idempotent: Qt keeps one copy of a filter)."""
        if not is_guarded_field(widget):
            return
        if widget.focusPolicy() == Qt.FocusPolicy.WheelFocus:
            widget.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        widget.installEventFilter(self)


class GuardingStyle(QProxyStyle):
    """Fusion, guarding each field as Qt polishes it (a style sheet's style polishes through
    its base style, so themes keep working)."""

    def __init__(self, guard: WheelGuard) -> None:
        super().__init__(BASE_STYLE)  # by name: the proxy makes and owns its base style
        self._guard = guard

    def polish(self, target):  # type: ignore[no-untyped-def, override]
        """Qt's three polish overloads: a widget is guarded; the others pass through."""
        if isinstance(target, QWidget):
            super().polish(target)
            self._guard.guard(target)
            return None
        return super().polish(target)


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
_style: GuardingStyle | None = None


def install(app: QApplication) -> WheelGuard:
    """Give ``app`` the guarding style (once; later calls return the same guard). Widgets
    that exist already are polished again by the new style, so they are guarded too. The
    style is taken back as the application quits (:func:`uninstall`)."""
    global _guard, _style
    if _guard is None:
        _guard = WheelGuard()
        app.aboutToQuit.connect(uninstall)
        atexit.register(uninstall)  # before PySide's own clean-up (registered earlier)
    if _style is None:
        _style = GuardingStyle(_guard)
        app.setStyle(_style)
        for widget in app.allWidgets():
            _guard.guard(widget)
    return _guard


def uninstall() -> None:
    """Plain Fusion again while Python still runs: the widgets Qt deletes at exit are
    re-styled as they go, and the guarding style's polish is Python (called during PySide's
    clean-up at exit, it crashed the process). The filters on the fields stay, harmless."""
    global _style
    app = QApplication.instance()
    if _style is not None and isinstance(app, QApplication):
        app.setStyle(BASE_STYLE)
    _style = None
