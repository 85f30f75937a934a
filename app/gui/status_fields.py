"""Status bar fields by priority: the important ones are always whole, the others make room.

The status bar used to squeeze every field and cut its end off ("107.3 ...", "Uncalib...").
:class:`StatusFields` shows the fields, given most important first, while they fit at their
full width, and hides the rest (their texts are then in the status bar's tooltip). A field
is never narrower than its text. It re-checks when the bar is resized or a text grows.
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import QEvent, QObject
from PySide6.QtWidgets import QStatusBar, QWidget

from app.core.screen_fit import fields_that_fit
from app.gui.elided_label import ElidedLabel

SAFETY_PX = 16
"""Room kept free so that a field shown never ends up squeezed by rounding."""


class StatusField(ElidedLabel):
    """A status field: an :class:`ElidedLabel` that tells its :class:`StatusFields` when it
    may have to appear or disappear (a hidden widget asks for no layout)."""

    def __init__(self, text: str = "", parent: QWidget | None = None) -> None:
        self.changed: Callable[[], None] | None = None
        super().__init__(text, parent)

    def setText(self, text: str) -> None:  # type: ignore[override]
        was_empty, width = not self.text(), self.sizeHint().width()
        super().setText(text)
        grew = self.sizeHint().width() > width
        if self.changed is not None and (
            grew or was_empty != (not self.text()) or self.isHidden()
        ):
            self.changed()


class StatusFields(QObject):
    """The status bar's left fields in priority order (plus its permanent widgets)."""

    def __init__(
        self, bar: QStatusBar, fields: list[StatusField], permanent: list[QWidget]
    ) -> None:
        super().__init__(bar)
        self.bar = bar
        self.fields = list(fields)
        self.permanent = list(permanent)
        self.hidden_texts: list[str] = []
        for widget in self.permanent:
            bar.addPermanentWidget(widget)
        for label in self.fields:
            bar.addWidget(label)
            label.changed = self.reflow
            label.installEventFilter(self)
        bar.installEventFilter(self)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        kind = event.type()
        bar_changed = watched is self.bar and kind in (
            QEvent.Type.Resize, QEvent.Type.LayoutRequest)
        if bar_changed or kind in (QEvent.Type.FontChange, QEvent.Type.StyleChange):
            self.reflow()
        return False

    def text_width(self, label: StatusField) -> int:
        """The room ``label`` needs for its whole text (0: nothing to show)."""
        if not label.text():
            return 0
        return label.sizeHint().width()

    def reflow(self) -> None:
        """Show the fields that fit, most important first; hide the others."""
        bar = self.bar
        layout = bar.layout()
        spacing = max(0, layout.spacing()) if layout is not None else 6
        margins = bar.contentsMargins()
        permanent = sum(max(w.sizeHint().width(), w.minimumWidth(), w.width()) + spacing
                        for w in self.permanent if not w.isHidden())
        available = (bar.width() - margins.left() - margins.right() - permanent
                     - 2 * spacing - SAFETY_PX)
        widths = [self.text_width(label) for label in self.fields]
        shown = fields_that_fit(widths, available, spacing)
        hidden: list[str] = []
        resized = False
        for label, width, show in zip(self.fields, widths, shown, strict=True):
            if show:
                # Never narrower than the whole text: the layout cannot squeeze it.
                if label.minimumWidth() != width:
                    label.setMinimumWidth(width)
                    resized = True
            elif width:
                hidden.append(label.text())
            if label.isHidden() == show:
                label.setVisible(show)
        if resized and layout is not None and bar.isVisible():
            layout.activate()  # now, not at the next pass: a grown text is never cut
        if hidden != self.hidden_texts:
            self.hidden_texts = hidden
            bar.setToolTip("\n".join(hidden))
