"""The compass beside the bubble: a rose with north up and a needle along the sensor's +x, the
heading readout, and the magnetic disturbance light.

They show what they are handed (:class:`app.core.heading.HeadingReading`,
:class:`app.core.field_light.FieldLight`); the heading and the disturbance are worked out in
:mod:`app.core` and fed by :mod:`app.gui.feeds.heading`.
"""

from __future__ import annotations

import math

from PySide6.QtCore import QPointF, QRectF, QSize, Qt
from PySide6.QtGui import QColor, QFont, QFontMetricsF, QPainter, QPainterPath, QPaintEvent, QPen
from PySide6.QtWidgets import QHBoxLayout, QLabel, QSizePolicy, QVBoxLayout, QWidget

from app.core.field_light import CLEAN, DISTURBED, NO_FIELD, FieldLight
from app.core.heading import HEADING_UNITS, OK, HeadingReading, cardinal
from app.gui import theme
from app.gui.readouts import MINUS, NO_VALUE, _ReadoutTile

_WIDEST_HEADING = "000.0"
TILE_VALUE_PX = 30
"""The heading's digits: a little smaller than the tilt readouts' smallest (28 ... 96), so the
rose above keeps room at 1366x768."""
_CARDINAL_LETTERS = (("N", 0.0), ("E", 90.0), ("S", 180.0), ("W", 270.0))
_STATE_TITLES = {
    "no data": "NO DATA",
    "no magnetometer": "NO MAGNETOMETER",
    "filter without magnetometer": "FILTER WITHOUT MAGNETOMETER",
    "heading unavailable": "HEADING UNAVAILABLE",
}


class CompassRose(QWidget):
    """A compass card, north up, with a needle along the heading (clockwise from north); without
    a heading the needle goes and the reason is written across the card."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._reading = HeadingReading("no data")
        self.setMinimumSize(100, 100)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setToolTip("Compass: north up, the needle is the sensor's +x axis")
        # A method, not a lambda: Qt drops the connection with the widget.
        theme.notifier().changed.connect(self._on_theme_changed)

    def _on_theme_changed(self, _name: str) -> None:
        self.update()

    def setReading(self, reading: HeadingReading) -> None:
        """Show a heading (or why there is none); repaints only when what is drawn changes."""
        if reading == self._reading:
            return
        old = self._reading
        self._reading = reading
        if (old.state, old.north, old.message) == (reading.state, reading.north,
                                                    reading.message) and reading.ok and \
                abs(((old.heading_deg - reading.heading_deg) + 180.0) % 360.0 - 180.0) < 0.05:
            return  # under a tenth of a pixel at the tip: not worth a repaint
        self.update()

    def reading(self) -> HeadingReading:
        return self._reading

    def stateTitle(self) -> str:
        """The words written across the card ("" while a heading is shown)."""
        return "" if self._reading.ok else _STATE_TITLES.get(self._reading.state,
                                                              self._reading.state.upper())

    def needleAngle(self) -> float | None:
        """Where the needle points, degrees clockwise from the card's north (None: no needle)."""
        return self._reading.heading_deg if self._reading.ok else None

    def sizeHint(self) -> QSize:
        return QSize(180, 180)

    def hasHeightForWidth(self) -> bool:
        return False

    # -- painting -------------------------------------------------------------------------------
    def _geometry(self) -> tuple[QPointF, float]:
        side = min(self.width(), self.height())
        return QPointF(self.width() / 2.0, self.height() / 2.0), side / 2.0 - 3.0

    def titleFont(self) -> QFont:
        """The largest font (up to a fifth of the radius) in which the state's words, wrapped,
        fit the card's inner square."""
        _centre, radius = self._geometry()
        room = self._title_room(radius)
        font = QFont(self.font())
        font.setBold(True)
        size = max(6, int(radius * 0.2))
        while size > 6:
            font.setPixelSize(size)
            if self._fits(font, room):
                break
            size -= 1
        font.setPixelSize(size)
        return font

    @staticmethod
    def _title_room(radius: float) -> QRectF:
        """Across the card, below N and above S (E and W are not drawn then)."""
        width, height = radius * 1.6, radius * 0.9
        return QRectF(-width / 2.0, -height / 2.0, width, height)

    def _fits(self, font: QFont, room: QRectF) -> bool:
        metrics = QFontMetricsF(font)
        bound = metrics.boundingRect(room, int(Qt.AlignmentFlag.AlignCenter
                                               | Qt.TextFlag.TextWordWrap), self.stateTitle())
        words = self.stateTitle().split()
        widest = max((metrics.horizontalAdvance(word) for word in words), default=0.0)
        return bound.height() <= room.height() and widest <= room.width()

    def titleFits(self) -> bool:
        """Whether the state's words fit the card at the font chosen (for the clipping tests)."""
        _centre, radius = self._geometry()
        return not self.stateTitle() or self._fits(self.titleFont(), self._title_room(radius))

    def paintEvent(self, event: QPaintEvent) -> None:
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        centre, radius = self._geometry()
        if radius < 10:
            return
        painter.translate(centre)
        ok = self._reading.ok
        text = QColor(theme.COLORS["TEXT"] if ok else theme.COLORS["TEXT_DISABLED"])
        painter.setPen(QPen(QColor(theme.COLORS["BORDER"]), 2.0))
        painter.setBrush(QColor(theme.COLORS["BASE_BG"]))
        painter.drawEllipse(QPointF(0, 0), radius, radius)
        self._paint_ticks(painter, radius, text)
        self._paint_letters(painter, radius, text)
        if ok:
            self._paint_needle(painter, radius, self._reading.heading_deg)
        else:
            font = self.titleFont()
            painter.setFont(font)
            painter.setPen(QColor(theme.COLORS["WARN_AMBER"]))
            painter.drawText(self._title_room(radius), int(Qt.AlignmentFlag.AlignCenter
                                                           | Qt.TextFlag.TextWordWrap),
                             self.stateTitle())
        painter.end()

    def _paint_ticks(self, painter: QPainter, radius: float, colour: QColor) -> None:
        painter.setPen(QPen(colour, 1.0))
        for degrees in range(0, 360, 10):
            long = degrees % 30 == 0
            inner = radius * (0.86 if long else 0.92)
            a = math.radians(degrees)
            direction = QPointF(math.sin(a), -math.cos(a))
            painter.drawLine(direction * inner, direction * (radius - 2.0))

    def _paint_letters(self, painter: QPainter, radius: float, colour: QColor) -> None:
        font = QFont(self.font())
        font.setBold(True)
        font.setPixelSize(max(8, int(radius * 0.17)))
        painter.setFont(font)
        metrics = QFontMetricsF(font)
        for letter, degrees in _CARDINAL_LETTERS:
            if not self._reading.ok and letter in "EW":
                continue  # the state's words go across the card
            a = math.radians(degrees)
            at = QPointF(math.sin(a), -math.cos(a)) * (radius * 0.68)
            box = QRectF(at.x() - metrics.horizontalAdvance(letter) / 2.0 - 1,
                         at.y() - metrics.height() / 2.0, metrics.horizontalAdvance(letter) + 2,
                         metrics.height())
            north = letter == "N"
            painter.setPen(QColor(theme.COLORS["ALARM_RED"]) if north and self._reading.ok
                           else colour)
            painter.drawText(box, int(Qt.AlignmentFlag.AlignCenter), letter)

    def _paint_needle(self, painter: QPainter, radius: float, heading_deg: float) -> None:
        painter.save()
        painter.rotate(heading_deg)  # clockwise on screen, as a heading turns
        width = radius * 0.1
        tip = QPainterPath()
        tip.moveTo(0, -radius * 0.8)
        tip.lineTo(width, 0)
        tip.lineTo(-width, 0)
        tip.closeSubpath()
        tail = QPainterPath()
        tail.moveTo(0, radius * 0.45)
        tail.lineTo(width, 0)
        tail.lineTo(-width, 0)
        tail.closeSubpath()
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(QColor(theme.COLORS["ACCENT"]))
        painter.drawPath(tip)
        painter.setBrush(QColor(theme.COLORS["TEXT_DISABLED"]))
        painter.drawPath(tail)
        painter.setBrush(QColor(theme.COLORS["TEXT"]))
        painter.drawEllipse(QPointF(0, 0), width * 0.5, width * 0.5)
        painter.restore()


class FieldLightView(QWidget):
    """A coloured light and its words: green "Field normal", red "Field disturbed: field 23 %
    above normal", grey without a magnetometer or a reference."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._light = FieldLight(NO_FIELD)
        self.dot = QLabel()
        self.dot.setFixedSize(14, 14)
        self.text = QLabel()
        self.text.setWordWrap(True)
        self.text.setObjectName("FieldLightText")
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(6)
        layout.addWidget(self.dot, 0, Qt.AlignmentFlag.AlignTop)
        layout.addWidget(self.text, 1)
        self._show()
        theme.notifier().changed.connect(self._on_theme_changed)

    def _on_theme_changed(self, _name: str) -> None:
        self._show()

    def _reserve_lines(self) -> None:
        """Room for two lines of words, so a reason that wraps does not re-lay out the
        window while the field changes."""
        self.text.setMinimumHeight(2 * self.text.fontMetrics().lineSpacing() + 2)

    def setLight(self, light: FieldLight) -> None:
        if light != self._light:
            self._light = light
            self._show()

    def light(self) -> FieldLight:
        return self._light

    def words(self) -> str:
        light = self._light
        if light.state == DISTURBED:
            return f"Field disturbed: {light.reason}"
        if light.state == CLEAN:
            return "Field normal"
        if light.state == NO_FIELD:
            return "No magnetometer"
        return "Field: no reference"

    def _show(self) -> None:
        colour = theme.COLORS[{CLEAN: "OK_GREEN", DISTURBED: "ALARM_RED"}.get(
            self._light.state, "TEXT_DISABLED")]
        self.dot.setStyleSheet(f"background: {colour}; border-radius: 7px;")
        self.text.setText(self.words())
        self._reserve_lines()
        self.setToolTip("Magnetic disturbance: the field's strength and dip against "
                        + (self._light.reference or "a reference (Field dock)"))


class HeadingTile(_ReadoutTile):
    """The heading readout: as large as the tilt readouts, its figure in degrees or mils, from
    magnetic or true north, the nearest compass point beside the note."""

    def __init__(self, value_px: int = 40, parent: QWidget | None = None) -> None:
        super().__init__("HEADING", "magnetic", value_px, parent)
        self._reading = HeadingReading("no data")
        self._declination_text = ""
        self.setUnit("°")
        self._show()
        theme.notifier().changed.connect(self._restore_fonts)

    def _restore_fonts(self, _name: str = "") -> None:
        """A new application stylesheet puts back the labels' first fonts: size them again
        (as the tilt readouts do), so the digits keep the room measured for them."""
        self.setValuePixelSize(self._value_px)
        self._show()

    def setValuePixelSize(self, value_px: int) -> None:
        """As a tilt tile, with the digits' room for the widest heading, ``000.0`` (mils are
        4 digits): the tile, and the compass column with it, stays narrow."""
        super().setValuePixelSize(value_px)
        widest = QFontMetricsF(self.value.font()).horizontalAdvance(_WIDEST_HEADING)
        self.value.setFixedWidth(math.ceil(widest) + 2)

    def setReading(self, reading: HeadingReading, declination_text: str = "") -> None:
        if (reading, declination_text) != (self._reading, self._declination_text):
            self._reading, self._declination_text = reading, declination_text
            self._show()

    def reading(self) -> HeadingReading:
        return self._reading

    def readoutText(self) -> str:
        """The figure with its unit, e.g. ``123.4°`` or ``2187 mil``; a dash without one."""
        number = self.value.text()
        if number == NO_VALUE:
            return number
        unit = self.unit.text()
        return f"{number}{unit}" if unit == "°" else f"{number} {unit}"

    def _show(self) -> None:
        reading = self._reading
        self.setUnit(HEADING_UNITS[reading.unit].suffix if reading.ok else "")
        text = reading.text.replace("-", MINUS) if reading.ok else NO_VALUE
        if self.value.text() != text:
            self.value.setText(text)
        note = reading.north if reading.north == "magnetic" else \
            f"true · decl {self._declination_text}"
        if self.note.text() != note:
            self.note.setText(note)
        side = cardinal(reading.heading_deg) if reading.ok else NO_VALUE
        if self.side.text() != side:
            self.side.setText(side)
        self.setToolTip(reading.message or "Heading of the sensor's +x axis, clockwise from "
                        f"{reading.north} north")


class CompassPanel(QWidget):
    """The rose above the heading readout and the disturbance light."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.rose = CompassRose()
        self.tile = HeadingTile(TILE_VALUE_PX)
        self.light = FieldLightView()
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(6)
        layout.addWidget(self.rose, 1)
        layout.addWidget(self.tile)
        layout.addWidget(self.light)

    def setReading(self, reading: HeadingReading, declination_text: str = "") -> None:
        self.rose.setReading(reading)
        self.tile.setReading(reading, declination_text)

    def setLight(self, light: FieldLight) -> None:
        self.light.setLight(light)


__all__ = ["OK", "CompassPanel", "CompassRose", "FieldLightView", "HeadingTile"]
