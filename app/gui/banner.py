"""A dismissible one-line message across the top of the window, styled by its severity.

Errors (and alarms) are red; information (a request with nothing to do, such as "No further
bookmark") is in the accent colour, so that it does not read as a failure.
"""

from __future__ import annotations

from PySide6.QtGui import QColor
from PySide6.QtWidgets import QFrame, QHBoxLayout, QLabel, QToolButton, QWidget

from app.gui import theme

SEVERITIES = ("error", "info")


class MessageBanner(QFrame):
    """A dismissible message; :meth:`show_message` takes its severity (``error`` or ``info``)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("errorBanner")
        self._severity = "error"
        self.restyle()
        theme.notifier().changed.connect(self.restyle)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(10, 4, 4, 4)
        self.label = QLabel()
        self.label.setWordWrap(True)
        layout.addWidget(self.label, 1)
        close = QToolButton()
        close.setText("✕")
        close.setAutoRaise(True)
        close.setToolTip("Dismiss")
        close.clicked.connect(self.hide)
        layout.addWidget(close)
        self.hide()

    @property
    def severity(self) -> str:
        """The shown message's severity: ``error`` or ``info``."""
        return self._severity

    def show_message(self, text: str, severity: str = "error") -> None:
        """Show ``text``; ``severity`` picks the colour (ValueError for an unknown one)."""
        if severity not in SEVERITIES:
            raise ValueError(f"banner severity {severity!r}: use one of {', '.join(SEVERITIES)}")
        if severity != self._severity:
            self._severity = severity
            self.restyle()
        self.label.setText(text)
        self.show()

    def colour(self) -> str:
        """The frame's colour for the current severity and theme."""
        return theme.ALARM_RED if self._severity == "error" else theme.ACCENT

    def restyle(self, _theme_name: str = "") -> None:
        """The current theme's colour for the severity."""
        colour = QColor(self.colour())
        # A fifth of the colour over the window: Qt reads "#rrggbbaa" as "#aarrggbb".
        fill = f"rgba({colour.red()}, {colour.green()}, {colour.blue()}, 51)"
        self.setProperty("severity", self._severity)
        self.setStyleSheet(
            f"#errorBanner {{ background: {fill}; border: 1px solid {colour.name()};"
            " border-radius: 4px; }"
        )
