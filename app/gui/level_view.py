"""The window's centre: the banners, the bubble level with the compass and the readouts beside
it, the display controls (units, averaging, range, Hold) and the simulator-truth line."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QResizeEvent
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from app.core.readout import SLOPE_UNITS
from app.gui.banner import MessageBanner
from app.gui.bubble_level import BubbleLevel
from app.gui.compass import CompassPanel
from app.gui.elided_label import ElidedLabel
from app.gui.heading_controls import HeadingBar
from app.gui.readouts import TiltReadouts

READOUT_MIN_PX, READOUT_MAX_PX = 28, 96
"""Smallest and largest digits beside the level in the usual layout."""
INSTRUMENT_MAX_PX = 400
"""Largest digits in the full-screen instrument mode (they fill the half screen)."""
LEVEL_SHARE, COMPASS_SHARE, SIDE_SHARE = 4, 3, 5
"""The width's shares of the bubble, the compass column and the readouts' column: the compass
takes its room from the bubble (limited by the height, it rarely uses its width), so the
readouts keep the 40 % they had beside the bubble alone; at 1366x768, with the Filter dock
open, the compass's quarter holds its heading readout."""
AVERAGING_S = (0.05, 0.2, 0.5, 1.0, 2.0, 5.0)
LEVEL_RANGES_DEG = (0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 90.0)


class _CompassColumn(QWidget):
    """The compass column: it asks for no width, and hides itself when the row gives it less
    than it needs (never drawn cut or overlapped); the view shows it again on its next resize
    when its share looks wide enough."""

    def resizeEvent(self, event: QResizeEvent) -> None:
        super().resizeEvent(event)
        need = self.minimumSizeHint()
        if self.isVisible() and (event.size().width() < need.width()
                                 or event.size().height() < need.height()):
            self.hide()


class LevelView(QWidget):
    """The central widget; its parts are attributes (the window hands them on)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.banner = MessageBanner()
        self.alarm_banner = MessageBanner()
        self.level = BubbleLevel()
        self.readouts = TiltReadouts()
        self.truth_label = ElidedLabel()
        self.truth_label.setObjectName("dimLabel")
        self.truth_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        outer = QVBoxLayout(self)
        outer.setContentsMargins(12, 8, 12, 8)
        outer.addWidget(self.banner)
        outer.addWidget(self.alarm_banner)
        self.row = QHBoxLayout()
        self.level.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.row.addWidget(self.level, LEVEL_SHARE)
        self.compass = CompassPanel()
        self.heading_bar = HeadingBar()
        # The compass column asks for no width of its own: the window may be made as narrow
        # as before it came; where its share is too narrow for it, it is hidden (never cut).
        self.compass_column = _CompassColumn()
        self.compass_column.setSizePolicy(QSizePolicy.Policy.Ignored,
                                          QSizePolicy.Policy.Ignored)
        compass_column = QVBoxLayout(self.compass_column)
        compass_column.setContentsMargins(0, 0, 0, 0)
        compass_column.addWidget(self.compass, 1)
        compass_column.addWidget(self.heading_bar)
        self.compass_wanted = True
        """False in the full-screen instrument (only the bubble and the digits)."""
        self.row.addWidget(self.compass_column, COMPASS_SHARE)
        side = self.side_layout = QVBoxLayout()
        # The digits grow into the height beside the level (no empty space under them).
        self.readouts.setAutoScale(True, READOUT_MAX_PX, READOUT_MIN_PX, (2, 1))
        side.addWidget(self.readouts, 1)
        side.addWidget(self._build_controls())
        self.row.addLayout(side, SIDE_SHARE)
        outer.addLayout(self.row, 1)
        outer.addWidget(self.truth_label)

    def _build_controls(self) -> QWidget:
        self.controls = QWidget()
        controls = QHBoxLayout(self.controls)
        controls.setContentsMargins(0, 0, 0, 0)
        self.unit_combo = QComboBox()
        for unit in SLOPE_UNITS.values():
            self.unit_combo.addItem(unit.title, unit.key)
        self.unit_combo.setToolTip("Units of roll, pitch and tilt")
        self.averaging_combo = QComboBox()
        for seconds in AVERAGING_S:
            self.averaging_combo.addItem(f"avg {seconds:g} s", seconds)
        self.averaging_combo.setToolTip("The readouts show the mean over this time")
        self.range_combo = QComboBox()
        for degrees in LEVEL_RANGES_DEG:
            self.range_combo.addItem(f"±{degrees:g}°", degrees)
        self.range_combo.setToolTip("Full scale of the bubble level")
        self.hold_button = QPushButton("Hold")
        self.hold_button.setCheckable(True)
        self.hold_button.setToolTip("Freeze the readouts (H)")
        for widget in (self.unit_combo, self.averaging_combo, self.range_combo, self.hold_button):
            controls.addWidget(widget)
        return self.controls

    def set_level_share(self, level: int, side: int, compass: int = COMPASS_SHARE) -> None:
        """How the width is shared between the bubble, the compass (0: none, hidden) and the
        readouts' column."""
        self.row.setStretch(0, level)
        self.row.setStretch(1, compass)
        self.row.setStretch(2, side)
        self.compass_wanted = compass > 0
        self._place_compass()

    def _place_compass(self) -> None:
        """Show the compass column where its share of the width holds it, else hide it."""
        shares = sum(self.row.stretch(i) for i in range(3)) or 1
        margins = self.layout().contentsMargins()
        inner = self.width() - margins.left() - margins.right() - 2 * self.row.spacing()
        # Its share, unless the bubble and the readouts need more than theirs (the row
        # meets every minimum first), and a margin for the row's rounding.
        others = (max(self.level.minimumSizeHint().width(), self.level.minimumWidth())
                  + self.side_layout.minimumSize().width())
        room = min(inner * self.row.stretch(1) / shares, inner - others) - 8
        need = self.compass_column.minimumSizeHint()
        tall = self.row.geometry().height() >= need.height() or not self.row.geometry().isValid()
        fits = self.compass_wanted and room >= need.width() and tall
        if fits != self.compass_column.isVisibleTo(self):
            self.compass_column.setVisible(fits)

    def resizeEvent(self, event: QResizeEvent) -> None:
        super().resizeEvent(event)
        self._place_compass()
