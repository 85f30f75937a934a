"""Large numeric readouts of roll, pitch, tilt and tilt direction."""

from __future__ import annotations

import math

from PySide6.QtCore import Qt
from PySide6.QtGui import QFont, QFontDatabase, QFontMetricsF, QResizeEvent
from PySide6.QtWidgets import QFrame, QGridLayout, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.gui import theme

NO_VALUE = "—"
"""Shown in place of a number when there are no data."""

MINUS = "−"  # U+2212: as wide as "+" in the readout font, unlike the hyphen

QUANTITIES: tuple[str, ...] = ("roll", "pitch", "tilt", "direction")
"""Readout names, in display order; the keys of :meth:`TiltReadouts.readoutText`."""

_CAPTIONS = {"roll": "ROLL", "pitch": "PITCH", "tilt": "TILT", "direction": "DIRECTION"}
_NOTES = {
    "roll": "about x  ·  + when +y raised",
    "pitch": "about y  ·  + when +x raised",
    "tilt": "from vertical",
    "direction": "raised side",
}
# Raised side for each 45° sector of the tilt direction, counter-clockwise from +x.
_SIDES = ("+x", "+x+y", "+y", "−x+y", "−x", "−x−y", "−y", "+x−y")
# The widest text a readout is sized for, so the layout does not jump as digits change.
_WIDEST_VALUE = "−000.00"
_FIXED_FAMILIES = (
    "JetBrains Mono",
    "Cascadia Mono",
    "SF Mono",
    "Consolas",
    "Menlo",
    "DejaVu Sans Mono",
    "Liberation Mono",
)


def _readout_font(pixel_size: int, bold: bool = False) -> QFont:
    """A fixed-pitch font (digits of equal width) at ``pixel_size``."""
    font = QFontDatabase.systemFont(QFontDatabase.SystemFont.FixedFont)
    font.setFamilies([*_FIXED_FAMILIES, font.family()])
    font.setStyleHint(QFont.StyleHint.Monospace)
    font.setPixelSize(pixel_size)
    font.setBold(bold)
    return font


def _format_signed(value: float) -> str:
    """``+1.23`` / ``−1.23``: two decimals, sign always shown, no negative zero."""
    text = f"{value:+.2f}"
    if text == "-0.00":
        text = "+0.00"
    return text.replace("-", MINUS)


def _format_unsigned(value: float) -> str:
    """``1.23``: two decimals."""
    return f"{value:.2f}".replace("-", MINUS)


def _format_direction(direction_deg: float) -> str:
    """``123.4``: one decimal, 360.0 shown as 0.0."""
    text = f"{direction_deg % 360.0:.1f}"
    return "0.0" if text == "360.0" else text


def raised_side_label(direction_deg: float) -> str:
    """Short compass label of the raised side (``+x``, ``+x+y``, ``+y``, ``−x+y`` ...)."""
    sector = int(((direction_deg + 22.5) % 360.0) // 45.0) % len(_SIDES)
    return _SIDES[sector]


def _set_text(label: QLabel, text: str) -> None:
    """``label.setText(text)`` unless it already shows ``text`` (no relayout, no repaint)."""
    if label.text() != text:
        label.setText(text)


class _ReadoutTile(QFrame):
    """One readout: caption, big value with unit, and a small note line."""

    def __init__(self, caption: str, note: str, value_px: int, parent: QWidget | None = None):
        super().__init__(parent)
        self.setObjectName("ReadoutTile")
        self.setFrameShape(QFrame.Shape.StyledPanel)

        self.caption = QLabel(caption)
        self.caption.setObjectName("ReadoutCaption")
        caption_font = QFont(self.font())
        caption_font.setPixelSize(max(10, round(value_px * 0.28)))
        caption_font.setBold(True)
        caption_font.setLetterSpacing(QFont.SpacingType.PercentageSpacing, 115)
        self.caption.setFont(caption_font)

        self.value = QLabel(NO_VALUE)
        self.value.setObjectName("ReadoutValue")
        value_font = _readout_font(value_px)
        self.value.setFont(value_font)
        self.value.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignBaseline)
        self.value.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        widest = QFontMetricsF(value_font).horizontalAdvance(_WIDEST_VALUE)
        self.value.setMinimumWidth(math.ceil(widest) + 2)

        self.unit = QLabel("")
        self.unit.setObjectName("ReadoutUnit")
        self.unit.setFont(_readout_font(max(12, round(value_px * 0.45))))
        self.unit.setAlignment(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignBaseline)
        unit_widest = QFontMetricsF(self.unit.font()).horizontalAdvance("mm/m")
        self.unit.setMinimumWidth(math.ceil(unit_widest) + 2)

        self.note = QLabel(note)
        self.note.setObjectName("ReadoutSide")
        self.note.setTextFormat(Qt.TextFormat.RichText)
        note_font = QFont(self.font())
        note_font.setPixelSize(max(10, round(value_px * 0.3)))
        self.note.setFont(note_font)

        self._value_font = value_font
        self._unit_font = self.unit.font()

        value_row = QHBoxLayout()
        value_row.setSpacing(max(2, value_px // 16))
        value_row.addStretch(1)
        value_row.addWidget(self.value, 0, Qt.AlignmentFlag.AlignBaseline)
        value_row.addWidget(self.unit, 0, Qt.AlignmentFlag.AlignBaseline)
        value_row.addStretch(1)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(14, 10, 14, 10)
        layout.setSpacing(2)
        layout.addWidget(self.caption)
        layout.addLayout(value_row)
        layout.addWidget(self.note)

    def setUnit(self, unit_label: str) -> None:
        """Show ``unit_label``; a degree sign is set as large as the digits, like "+1.23°"."""
        if unit_label == self.unit.text():
            return
        self.unit.setFont(self._value_font if unit_label == "°" else self._unit_font)
        self.unit.setText(unit_label)


class TiltReadouts(QWidget):
    """Instrument-style numeric readouts for roll, pitch, tilt and tilt direction.

    Values arrive already in the display unit (degrees, mm/m or %) and are shown to 0.01;
    roll and pitch always carry a sign. The direction is in degrees (0.1) with the raised
    side as a short compass label. The widget formats what it is given and nothing more.

    Parameters
    ----------
    columns
        Tiles per row: 1 (a column), 2 (a 2 x 2 block) or 4 (a strip).
    value_px
        Pixel size of the digits.
    """

    def __init__(self, parent: QWidget | None = None, columns: int = 2, value_px: int = 40) -> None:
        super().__init__(parent)
        if columns not in (1, 2, 4):
            raise ValueError(f"columns must be 1, 2 or 4, got {columns!r}")
        self._valid = False
        self._held = False
        self._unit_label = "°"
        self._values: dict[str, float] = dict.fromkeys(QUANTITIES, math.nan)

        self._tiles: dict[str, _ReadoutTile] = {}
        grid = QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        grid.setSpacing(8)
        for index, name in enumerate(QUANTITIES):
            tile = _ReadoutTile(_CAPTIONS[name], _NOTES[name], value_px, self)
            self._tiles[name] = tile
            grid.addWidget(tile, index // columns, index % columns)
        self._tiles["direction"].setUnit("°")

        self._hold_badge = QLabel("HOLD", self)
        self._hold_badge.setObjectName("HoldBadge")
        badge_font = QFont(self.font())
        badge_font.setPixelSize(max(10, round(value_px * 0.3)))
        badge_font.setBold(True)
        badge_font.setLetterSpacing(QFont.SpacingType.PercentageSpacing, 115)
        self._hold_badge.setFont(badge_font)
        self._hold_badge.setAlignment(Qt.AlignmentFlag.AlignCenter)
        # Readable even without the application stylesheet.
        self._hold_badge.setStyleSheet(
            "background: #e8a93a; color: #15171a; border-radius: 3px; padding: 1px 6px;"
        )
        self._hold_badge.hide()
        self._show_texts()

    # ---- API -----------------------------------------------------------------------------

    def setValues(
        self, roll: float, pitch: float, tilt: float, direction_deg: float, unit_label: str
    ) -> None:
        """Show new values: roll, pitch and tilt in ``unit_label`` units, direction in degrees."""
        self._values = {
            "roll": float(roll),
            "pitch": float(pitch),
            "tilt": float(tilt),
            "direction": float(direction_deg),
        }
        self._unit_label = unit_label
        self._show_texts()

    def setValid(self, valid: bool) -> None:
        """Show the numbers (True) or dashes (False: no data)."""
        if bool(valid) == self._valid:
            return
        self._valid = bool(valid)
        self._show_texts()

    def setHold(self, held: bool) -> None:
        """Show or hide the HOLD badge (the caller decides whether values still change)."""
        self._held = bool(held)
        self._hold_badge.setVisible(self._held)
        if self._held:
            self._place_hold_badge()
            self._hold_badge.raise_()

    def isValid(self) -> bool:
        """Whether numbers (rather than dashes) are shown."""
        return self._valid

    def isHeld(self) -> bool:
        """Whether the HOLD badge is shown."""
        return self._held

    def readoutText(self, quantity: str) -> str:
        """The displayed text of one readout with its unit, e.g. ``"+1.23°"``, ``"0.12 mm/m"``.

        ``quantity`` is one of :data:`QUANTITIES`; the direction text includes its raised side,
        e.g. ``"123.4° +x+y"``.
        """
        tile = self._tiles[quantity]
        number = tile.value.text()
        if number == NO_VALUE:
            return NO_VALUE
        unit = tile.unit.text()
        text = f"{number}{unit}" if unit in ("°", "") else f"{number} {unit}"
        if quantity == "direction":
            text = f"{text} {self._side_text()}"
        return text

    def valueLabel(self, quantity: str) -> QLabel:
        """The label holding the number of one readout (for tests and styling)."""
        return self._tiles[quantity].value

    # ---- Internals -----------------------------------------------------------------------

    def _side_text(self) -> str:
        direction = self._values["direction"]
        if not self._valid or not math.isfinite(direction):
            return NO_VALUE
        return raised_side_label(direction)

    def _show_texts(self) -> None:
        """Put the values into the labels; a label whose text stays the same is not touched,
        so it does not repaint."""
        formatters = {
            "roll": _format_signed,
            "pitch": _format_signed,
            "tilt": _format_unsigned,
            "direction": _format_direction,
        }
        for name, tile in self._tiles.items():
            value = self._values[name]
            text = formatters[name](value) if self._valid and math.isfinite(value) else NO_VALUE
            _set_text(tile.value, text)
            if name != "direction":
                tile.setUnit(self._unit_label)
        _set_text(
            self._tiles["direction"].note,
            f'{_NOTES["direction"]}&nbsp;&nbsp;<span style="color:{theme.TEXT};">'
            f"<b>{self._side_text()}</b></span>",
        )

    def _place_hold_badge(self) -> None:
        self._hold_badge.adjustSize()
        badge = self._hold_badge.size()
        self._hold_badge.move(self.width() - badge.width() - 10, 9)

    def resizeEvent(self, event: QResizeEvent) -> None:
        """Keep the HOLD badge in the top-right corner."""
        super().resizeEvent(event)
        self._place_hold_badge()
