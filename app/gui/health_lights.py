"""One light per sensor channel: green ok, amber warning, red fault (the fault detector's view).

Shown in the status bar. A click asks to reset latched faults (a bias step stays lit until
then, since the detector cannot tell when such a fault is over).
"""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QMouseEvent
from PySide6.QtWidgets import QHBoxLayout, QLabel, QWidget

from app.gui import theme

CHANNELS = ("ax", "ay", "az", "gx", "gy", "gz", "link")
COLOUR_NAMES = {"ok": "OK_GREEN", "warning": "WARN_AMBER", "fault": "ALARM_RED"}
"""The theme colour of each state (looked up when drawn, so a theme switch shows)."""
WORDS = {"ok": "working", "warning": "warning", "fault": "FAULT"}


class HealthLights(QWidget):
    """Channel lights; ``resetRequested`` when clicked."""

    resetRequested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(4)
        self.lights: dict[str, QLabel] = {}
        for channel in CHANNELS:
            label = QLabel(channel)
            label.setAlignment(Qt.AlignmentFlag.AlignCenter)
            layout.addWidget(label)
            self.lights[channel] = label
        self.state: dict[str, str] = {}
        self.show_health(None)
        theme.notifier().changed.connect(self._on_theme_changed)

    def show_health(self, health: dict[str, str] | None) -> None:
        """Colour each light (None: no device, all dim). Unchanged health restyles nothing
        (a style sheet change re-polishes and repaints the labels)."""
        if self.lights and hasattr(self, "state") and dict(health or {}) == self.state:
            return
        self.state = dict(health or {})
        for channel, label in self.lights.items():
            state = self.state.get(channel)
            colour = theme.COLORS[COLOUR_NAMES.get(state or "", "TEXT_DISABLED")]
            label.setStyleSheet(
                f"color: {theme.BASE_BG if state in ('warning', 'fault') else colour};"
                f"background: {colour if state in ('warning', 'fault') else 'transparent'};"
                f"border: 1px solid {colour}; border-radius: 3px; padding: 0 3px;"
                "font-size: 11px;")
        lines = [f"{c}: {WORDS.get(self.state.get(c, ''), 'no data')}" for c in CHANNELS]
        self.setToolTip("Sensor health (the fault detector)\n" + "\n".join(lines)
                        + "\nClick to reset latched faults")

    def _on_theme_changed(self, _name: str) -> None:
        self.show_health(self.state)

    def mousePressEvent(self, event: QMouseEvent) -> None:
        if event.button() == Qt.MouseButton.LeftButton:
            self.resetRequested.emit()
        super().mousePressEvent(event)
