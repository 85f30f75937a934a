"""Large numeric readouts of roll, pitch, tilt and tilt direction."""

from __future__ import annotations

import math
import time
from collections.abc import Iterable

from PySide6.QtCore import Property, QSize, Qt
from PySide6.QtGui import QFont, QFontDatabase, QFontMetrics, QFontMetricsF, QResizeEvent
from PySide6.QtWidgets import (
    QFrame,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from app.core.readout import (
    SLOPE_UNITS,
    UNDEFINED,
    format_direction,
    format_slope,
    reading_text,
)
from app.gui import theme
from app.gui.elided_label import ElidedLabel

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
# The widest text a readout is sized for, so the layout does not jump as digits change
# ("−180.00", "−999.99" mm/m, "−1:9999"; more than 999.99 in a slope unit reads OVER).
_WIDEST_VALUE = "−000.00"
_WIDEST_UNIT = "in/ft"
STATES: tuple[str, ...] = ("alarm", "stale")
"""The tiles' dynamic properties, styled by ``[alarm="true"]`` / ``[stale="true"]`` rules in
the stylesheet (resources/styles/instrument.qss); a change only re-polishes, so fonts and
sizes stay as they are."""
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


def _unit_key(unit: str) -> str:
    """A unit's key from its key or its suffix ("°" is "deg")."""
    if unit in SLOPE_UNITS:
        return unit
    for key, slope_unit in SLOPE_UNITS.items():
        if slope_unit.suffix == unit and unit:
            return key
    raise ValueError(f"unknown unit {unit!r}")


def raised_side_label(direction_deg: float) -> str:
    """Short compass label of the raised side (``+x``, ``+x+y``, ``+y``, ``−x+y`` ...)."""
    sector = int(((direction_deg + 22.5) % 360.0) // 45.0) % len(_SIDES)
    return _SIDES[sector]


def _set_text(label: QLabel, text: str) -> None:
    """``label.setText(text)`` unless it already shows ``text`` (no relayout, no repaint)."""
    if label.text() != text:
        label.setText(text)


def _repolish(widget: QWidget) -> None:
    """Re-apply the stylesheet to ``widget`` and its labels after a dynamic property
    changed (Qt does not re-evaluate ``[name="value"]`` selectors by itself)."""
    style = widget.style()
    for target in (widget, *widget.findChildren(QLabel)):
        style.unpolish(target)
        style.polish(target)
        target.update()


_TILE_MARGIN_Y = 10
"""A tile's margin above its caption and below its note (pixels): no text lies there."""


class _ReadoutTile(QFrame):
    """One readout: caption, big value with unit, and a small note line."""

    def __init__(self, caption: str, note: str, value_px: int, parent: QWidget | None = None):
        super().__init__(parent)
        self.setObjectName("ReadoutTile")
        self.setFrameShape(QFrame.Shape.StyledPanel)

        self.caption = QLabel(caption)
        self.caption.setObjectName("ReadoutCaption")
        self.value = QLabel(NO_VALUE)
        self.value.setObjectName("ReadoutValue")
        self.value.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        # Not selectable: a selectable label keeps a text document that it builds anew on
        # every setText (Ctrl+C copies the reading as text).
        self.unit = QLabel("")
        self.unit.setObjectName("ReadoutUnit")
        self.unit.setAlignment(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignBottom)
        self.note = QLabel(note)
        self.note.setObjectName("ReadoutSide")
        self.note.setTextFormat(Qt.TextFormat.PlainText)
        # A figure beside the note (the raised side): it changes while streaming, so it is
        # a label that repaints without re-laying out the window.
        self.side = ElidedLabel("")
        self.side.setObjectName("ReadoutSideValue")

        value_row = QHBoxLayout()
        self._value_row = value_row
        self._value_px = 0
        value_row.addStretch(1)
        value_row.addWidget(self.value)
        value_row.addWidget(self.unit)
        value_row.addStretch(1)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(14, _TILE_MARGIN_Y, 14, _TILE_MARGIN_Y)
        layout.setSpacing(2)
        layout.addWidget(self.caption)
        layout.addStretch(1)
        layout.addLayout(value_row)
        layout.addStretch(1)
        note_row = QHBoxLayout()
        note_row.setSpacing(8)
        note_row.addWidget(self.note)
        note_row.addWidget(self.side)
        note_row.addStretch(1)
        layout.addLayout(note_row)
        for state in STATES:
            self.setProperty(state, False)
        self.setValuePixelSize(value_px)

    def setState(self, state: str, on: bool) -> None:
        """Set a dynamic property (:data:`STATES`) and restyle: colours change, the fonts and
        every size stay (a font swap would change the digits' width inside a fixed label)."""
        if bool(self.property(state)) == bool(on):
            return
        self.setProperty(state, bool(on))
        _repolish(self)
        self.setValuePixelSize(self._value_px)  # unchanged sizes: only asserts the fonts

    def setValuePixelSize(self, value_px: int) -> None:
        """Size the digits (and with them caption, unit and note) to ``value_px`` pixels."""
        self._value_px = value_px
        caption_font = QFont(self.font())
        caption_font.setPixelSize(max(10, round(value_px * 0.28)))
        caption_font.setBold(True)
        caption_font.setLetterSpacing(QFont.SpacingType.PercentageSpacing, 115)
        self.caption.setFont(caption_font)
        value_font = _readout_font(value_px)
        self.value.setFont(value_font)
        value_metrics = QFontMetricsF(value_font)
        widest = value_metrics.horizontalAdvance(_WIDEST_VALUE)
        height = math.ceil(value_metrics.height()) + 2
        # A fixed size: a QLabel whose size may change asks every layout up to the window to
        # be redone on each setText, several times a second for a readout (and the main
        # window's layout then re-places every dock). The widest text always fits.
        self.value.setFixedSize(math.ceil(widest) + 2, height)
        self._value_font = value_font
        self._unit_font = _readout_font(max(12, round(value_px * 0.45)))
        unit_metrics = QFontMetricsF(self._unit_font)
        unit_widest = max(unit_metrics.horizontalAdvance(_WIDEST_UNIT),
                          value_metrics.horizontalAdvance("°"))
        # As high as the digits, the unit's text at the bottom, raised so that its baseline
        # is the digits' (a box layout has no baseline alignment): "°" and "mm/m" stay
        # beside the digits at every size, also after full screen and back.
        self.unit.setFixedSize(math.ceil(unit_widest) + 2, height)
        digits, unit = QFontMetrics(value_font), QFontMetrics(self._unit_font)
        # Centred digits: their baseline lies (height - text height) // 2 + descent above
        # the label's bottom.
        self._unit_lift = (height - digits.height()) // 2 + digits.descent() - unit.descent()
        self._apply_unit_font()
        note_font = QFont(self.font())
        note_font.setPixelSize(max(10, round(value_px * 0.3)))
        self.note.setFont(note_font)
        side_font = QFont(note_font)
        side_font.setBold(True)
        self.side.setFont(side_font)
        # Room for the widest raised side: a direction that appears (the tilt leaves zero)
        # or changes sector does not re-lay out the window.
        side_metrics = QFontMetricsF(side_font)
        self.side.setFixedSize(
            math.ceil(max(side_metrics.horizontalAdvance(side) for side in (*_SIDES, NO_VALUE)))
            + 2, math.ceil(side_metrics.height()))
        self._value_row.setSpacing(max(2, value_px // 16))

    def setUnit(self, unit_label: str) -> None:
        """Show ``unit_label``; a degree sign is set as large as the digits, like "+1.23°"."""
        if unit_label == self.unit.text():
            return
        self.unit.setText(unit_label)
        self._apply_unit_font()

    def _apply_unit_font(self) -> None:
        big = self.unit.text() == "°"
        # A degree sign in the digits' font is placed exactly like them (centred); a
        # smaller unit sits at the bottom, lifted onto the digits' baseline.
        # Only what changes is set: new margins would ask the window to re-lay out.
        font = self._value_font if big else self._unit_font
        if self.unit.font() != font:
            self.unit.setFont(font)
        vertical = Qt.AlignmentFlag.AlignVCenter if big else Qt.AlignmentFlag.AlignBottom
        alignment = Qt.AlignmentFlag.AlignLeft | vertical
        if self.unit.alignment() != alignment:
            self.unit.setAlignment(alignment)
        lift = 0 if big else max(0, self._unit_lift)
        if self.unit.contentsMargins().bottom() != lift:
            self.unit.setContentsMargins(0, 0, 0, lift)


class TiltReadouts(QWidget):
    """Instrument-style numeric readouts for roll, pitch, tilt and tilt direction.

    Values arrive already in the display unit (a key of ``app.core.readout.SLOPE_UNITS`` or
    its suffix: degrees, %, mm/m, in/ft, 1:n) and are shown as ``format_slope`` writes them;
    roll and pitch always carry a sign. The direction is in degrees (0.1) with the raised
    side as a short compass label. The widget shows what it is given and nothing more.
    With :meth:`setAutoScale` the digits grow to fill the space the widget is given.

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
        self._unit = "deg"
        self._values: dict[str, float] = dict.fromkeys(QUANTITIES, math.nan)
        self._columns = columns
        self._base_px = value_px
        self._value_px = value_px
        self._auto_scale = False
        self._max_px = value_px
        self._min_px = value_px
        self._resizing_tiles = False
        self._auto_columns: tuple[int, ...] = ()

        self._tiles: dict[str, _ReadoutTile] = {}
        self._grid = QGridLayout(self)
        self._grid.setContentsMargins(0, 0, 0, 0)
        self._grid.setSpacing(8)
        for name in QUANTITIES:
            self._tiles[name] = _ReadoutTile(_CAPTIONS[name], _NOTES[name], value_px, self)
        self._place_tiles()
        self._tiles["direction"].setUnit("°")
        for name, tile in self._tiles.items():  # only the direction names a raised side
            tile.side.setVisible(name == "direction")
        self._alarm: tuple[str, ...] = ()
        # Space a tile needs per pixel of digit size, measured once on the fonts.
        width_100 = QFontMetricsF(_readout_font(100)).horizontalAdvance(_WIDEST_VALUE)
        width_100 += QFontMetricsF(_readout_font(45)).horizontalAdvance(_WIDEST_UNIT)
        width_100 += 3 * 100 / 16  # the value row's three gaps (1/16 of the digit size)
        height_100 = sum(
            QFontMetricsF(font).height()
            for font in (_readout_font(100), _readout_font(30), _readout_font(28))
        )
        self._digits_per_px = (width_100 / 100.0, height_100 / 100.0)
        self._per_px = self._digits_per_px
        self._measure_notes()
        theme.notifier().changed.connect(self._restore_fonts)

        self._hold_badge = QLabel("HOLD", self)
        self._hold_badge.setObjectName("HoldBadge")
        self._size_badge()
        self._hold_badge.setAlignment(Qt.AlignmentFlag.AlignCenter)
        # Readable even without the application stylesheet.
        self._hold_badge.setStyleSheet(
            "background: #e8a93a; color: #15171a; border-radius: 3px; padding: 1px 6px;"
        )
        self._hold_badge.hide()
        self._stale = False
        self._stale_badge = QLabel("", self)
        self._stale_badge.setObjectName("StaleBadge")
        self._stale_badge.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._stale_badge.hide()
        self._size_badge()
        self._show_texts()

    # ---- API -----------------------------------------------------------------------------

    def setColumns(self, columns: int) -> None:
        """Tiles per row: 1 (a column), 2 (a 2 x 2 block) or 4 (a strip)."""
        if columns not in (1, 2, 4):
            raise ValueError(f"columns must be 1, 2 or 4, got {columns!r}")
        if columns != self._columns:
            self._columns = columns
            self._place_tiles()
            self._fit_digits()

    def columns(self) -> int:
        """Tiles per row."""
        return self._columns

    def setAutoScale(
        self, enabled: bool, maximum_px: int | None = None, minimum_px: int | None = None,
        columns: tuple[int, ...] = (),
    ) -> None:
        """Let the digits fill the widget, from ``minimum_px`` (the widget asks for room
        for these) up to ``maximum_px``; with several ``columns`` (e.g. ``(2, 1)``) the tiles
        are arranged in whichever gives the largest digits (the first when equal). Off: back
        to the size given at construction."""
        self._auto_scale = bool(enabled)
        self._auto_columns = tuple(columns) if enabled else ()
        if self._auto_columns and self._columns != self._auto_columns[0]:
            self._columns = self._auto_columns[0]
            self._place_tiles()
        self._max_px = maximum_px or self._base_px * 6
        self._min_px = minimum_px or self._base_px
        policy = QSizePolicy.Policy.Expanding if enabled else QSizePolicy.Policy.Preferred
        self.setSizePolicy(policy, policy)
        if enabled:
            self._fit_digits()
        else:
            self._set_value_px(self._base_px)
        self.updateGeometry()

    def valuePixelSize(self) -> int:
        """Pixel size of the digits now."""
        return self._value_px

    def reading(self) -> str:
        """The values shown as one line for the clipboard (``Roll 1.23° Pitch -0.45° Tilt
        1.31°``), or ``""`` when no numbers are shown."""
        if not self._valid or not all(
            format_slope(self._values[name], self._unit) for name in ("roll", "pitch", "tilt")
        ):
            return ""
        return reading_text(
            self._values["roll"], self._values["pitch"], self._values["tilt"], self._unit
        )

    def setValues(
        self, roll: float, pitch: float, tilt: float, direction_deg: float, unit_label: str
    ) -> None:
        """Show new values: roll, pitch and tilt in ``unit_label`` (a unit's key or suffix),
        direction in degrees."""
        self._values = {
            "roll": float(roll),
            "pitch": float(pitch),
            "tilt": float(tilt),
            "direction": float(direction_deg),
        }
        self._unit = _unit_key(unit_label)
        self._show_texts()

    def setValid(self, valid: bool) -> None:
        """Show the numbers (True) or dashes (False: no data)."""
        if bool(valid) == self._valid:
            return
        self._valid = bool(valid)
        if not self._valid:
            self.setStale(None)  # dashes are not a reading, live or not
        self._show_texts()

    def setHold(self, held: bool) -> None:
        """Show or hide the HOLD badge (the caller decides whether values still change)."""
        self._held = bool(held)
        self._hold_badge.setVisible(self._held)
        self._place_hold_badge()

    def setStale(self, last_live: float | None) -> None:
        """Grey the figures as no longer live, with the time (``time.time()`` seconds) they
        were last live in a badge, e.g. after the device was lost; ``None``: live again."""
        stale = last_live is not None
        if stale:
            stamp = time.strftime("%H:%M:%S", time.localtime(last_live))
            self._stale_badge.setText(f"NOT LIVE  ·  last live {stamp}")
        if stale != self._stale:
            self._stale = stale
            for tile in self._tiles.values():
                tile.setState("stale", stale)
        self._stale_badge.setVisible(stale)
        self._place_hold_badge()

    def isStale(self) -> bool:
        """Whether the figures are shown as no longer live."""
        return self._stale

    def staleText(self) -> str:
        """The stale badge's text (``""`` while live)."""
        return self._stale_badge.text() if self._stale else ""

    def setAlarm(self, quantities: Iterable[str]) -> None:
        """Show these readouts (``roll``, ``pitch``, ``tilt``) in the alarm state: digits and
        frame in ``theme.ALARM_STATE``; an empty list ends it."""
        wanted = set(quantities)
        alarm = tuple(q for q in QUANTITIES if q in wanted)
        if alarm == self._alarm:
            return
        self._alarm = alarm
        for name, tile in self._tiles.items():
            tile.setState("alarm", name in alarm)

    def alarmQuantities(self) -> tuple[str, ...]:
        """The readouts shown in the alarm state."""
        return self._alarm

    def _is_alarm(self) -> bool:
        return bool(self._alarm)

    alarm = Property(bool, _is_alarm)
    """Whether any readout is in the alarm state (a Qt property: ``[alarm="true"]`` in QSS)."""

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
        if number in (NO_VALUE, UNDEFINED):
            return number
        unit = tile.unit.text()
        text = f"{number}{unit}" if unit in ("°", "") else f"{number} {unit}"
        if quantity == "direction":
            text = f"{text} {self._side_text()}"
        return text

    def valueLabel(self, quantity: str) -> QLabel:
        """The label holding the number of one readout (for tests and styling)."""
        return self._tiles[quantity].value

    # ---- Internals -----------------------------------------------------------------------

    def _direction_text(self) -> str:
        """The direction's figure: undefined (a dash) while the tilt reads zero."""
        tilt_text = format_slope(self._values["tilt"], self._unit)
        return format_direction(self._values["direction"], tilt_text)

    def _side_text(self) -> str:
        direction = self._direction_text()
        if not self._valid or direction in ("", UNDEFINED):
            return NO_VALUE
        return raised_side_label(self._values["direction"])

    def _show_texts(self) -> None:
        """Put the values into the labels; a label whose text stays the same is not touched,
        so it does not repaint."""
        suffix = SLOPE_UNITS[self._unit].suffix
        for name, tile in self._tiles.items():
            value = self._values[name]
            if name == "direction":
                text = self._direction_text()
                tile.setUnit("" if text == UNDEFINED else "°")
            else:
                text = format_slope(value, self._unit, signed=name != "tilt")
                tile.setUnit(suffix)
            _set_text(tile.value, text.replace("-", MINUS) if self._valid and text else NO_VALUE)
        self._tiles["direction"].side.setText(self._side_text())

    def _place_tiles(self) -> None:
        for index, name in enumerate(QUANTITIES):
            self._grid.removeWidget(self._tiles[name])
            self._grid.addWidget(
                self._tiles[name], index // self._columns, index % self._columns
            )

    def _tile_overhead(self) -> tuple[float, float]:
        """Width and height of a tile that do not grow with the digits (margins, spacing)."""
        # Across: margins 2 x 14, frame and padding 2 x 2, the digits' and unit's 2 px each,
        # and slack. Down: margins 2 x 10, frame 2 x 2, four gaps of 2, the digits' 2 px
        # and the rounding of three label heights.
        return 40.0, 38.0

    def _fit(self, columns: int) -> float:
        """The digit size at which tiles in ``columns`` fill the widget."""
        rows = math.ceil(len(QUANTITIES) / columns)
        spacing = self._grid.spacing()
        tile_w = (self.width() - spacing * (columns - 1)) / columns
        tile_h = (self.height() - spacing * (rows - 1)) / rows
        fixed_w, fixed_h = self._tile_overhead()
        return min((tile_w - fixed_w) / self._per_px[0], (tile_h - fixed_h) / self._per_px[1])

    def _fit_digits(self) -> None:
        """Auto scale: the largest digits for which every tile fits the widget."""
        if not self._auto_scale:
            return
        if self._auto_columns:
            best = max(self._auto_columns, key=self._fit)  # the first of equals
            if best != self._columns:
                self._columns = best
                self._place_tiles()
        fit = self._fit(self._columns)
        self._set_value_px(int(max(self._min_px, min(self._max_px, fit))))

    def _size_badge(self) -> None:
        badge_font = QFont(self.font())
        badge_font.setPixelSize(max(10, round(self._value_px * 0.3)))
        badge_font.setBold(True)
        badge_font.setLetterSpacing(QFont.SpacingType.PercentageSpacing, 115)
        self._hold_badge.setFont(badge_font)
        stale_badge = getattr(self, "_stale_badge", None)
        if stale_badge is not None:
            stale_badge.setFont(badge_font)
        self._place_hold_badge()

    def _measure_notes(self) -> None:
        """Room across per pixel of digit size: the digits' and unit's, or a tile's note line
        (note and raised side, in the font the tiles give it: 0.3 of the digit size) where that
        is wider. Measured in the widget's font (a theme may change it), so a note is never cut
        when the digits fill the width."""
        note_font = QFont(self._tiles["roll"].font())  # the tiles' notes derive from it
        note_font.setPixelSize(30)
        side_font = QFont(note_font)
        side_font.setBold(True)
        note_metrics, side_metrics = QFontMetricsF(note_font), QFontMetricsF(side_font)
        side = max(side_metrics.horizontalAdvance(text) for text in (*_SIDES, NO_VALUE))
        notes = max(note_metrics.horizontalAdvance(_NOTES[name])
                    + (8 * 100 / 28 + side if name == "direction" else 0.0)
                    for name in QUANTITIES)
        # The note row's 8 px gap is fixed, not scaled: counted at the smallest digits (28 px).
        self._per_px = (max(self._digits_per_px[0], notes / 100.0), self._digits_per_px[1])

    def _restore_fonts(self, _theme_name: str = "") -> None:
        """After a theme switch: a new application stylesheet puts back the fonts the labels
        had when they were first styled, so size them again; and the raised side's colour
        is the new theme's (the texts are not redrawn while held)."""
        for tile in self._tiles.values():
            tile.setValuePixelSize(self._value_px)
        self._size_badge()
        self._show_texts()
        self._measure_notes()
        self._fit_digits()

    def _set_value_px(self, value_px: int) -> None:
        if value_px == self._value_px:
            return
        self._value_px = value_px
        if self._resizing_tiles:  # a resize while the fonts change: the loop below takes it
            return
        self._resizing_tiles = True
        try:
            applied = None
            while applied != self._value_px:
                applied = self._value_px
                for tile in self._tiles.values():
                    tile.setValuePixelSize(applied)
                self._size_badge()
        finally:
            self._resizing_tiles = False

    def sizeHint(self) -> QSize:
        """Auto scale: the size at the smallest digits (the layout gives what it can)."""
        return self.minimumSizeHint() if self._auto_scale else super().sizeHint()

    def minimumSizeHint(self) -> QSize:
        """Auto scale: room for the smallest digits allowed."""
        if not self._auto_scale:
            return super().minimumSizeHint()
        columns = self._auto_columns[0] if self._auto_columns else self._columns
        rows = math.ceil(len(QUANTITIES) / columns)
        spacing = self._grid.spacing()
        fixed_w, fixed_h = self._tile_overhead()
        tile_w = fixed_w + self._per_px[0] * self._min_px
        tile_h = fixed_h + self._per_px[1] * self._min_px
        return QSize(
            math.ceil(tile_w * columns + spacing * (columns - 1)),
            math.ceil(tile_h * rows + spacing * (rows - 1)),
        )

    def _place_hold_badge(self) -> None:
        """HOLD in the top-right corner, right of the top row's last caption; the stale badge
        (the widest) centred on the gap between the first two rows of tiles, where it covers
        only the tiles' frames and margins, never a caption, a figure or a note (in the top
        right corner it covered the PITCH caption at 1366x768). A single row has no such gap:
        the stale badge then goes left of HOLD."""
        right = self.width() - 10
        hold = self._hold_badge
        if not hold.isHidden():
            hold.adjustSize()
            hold.move(right - hold.width(), 9)
            hold.raise_()
            right -= hold.width() + 6
        stale = getattr(self, "_stale_badge", None)
        if stale is None or stale.isHidden():
            return
        self._fit_stale_badge()
        rows = math.ceil(len(QUANTITIES) / self._columns)
        if rows > 1:  # rows share the height equally (the layout may not have run yet)
            spacing = self._grid.spacing()
            gap_y = (self.height() - spacing * (rows - 1)) / rows + spacing / 2
            stale.move(round((self.width() - stale.width()) / 2),
                       round(gap_y - stale.height() / 2))
        else:
            stale.move(right - stale.width(), 9)
        stale.raise_()

    def _fit_stale_badge(self) -> None:
        """The stale badge's font: the hold badge's, made smaller (not below 8 px) until the
        badge fits between two rows of tiles (their margins and the grid's spacing) and
        within the widget's width."""
        stale = self._stale_badge
        font = QFont(self._hold_badge.font())
        band = self._grid.spacing() + 2 * _TILE_MARGIN_Y
        while True:
            stale.setFont(font)
            stale.adjustSize()
            if (stale.height() <= band and stale.width() <= self.width() - 16) or (
                    font.pixelSize() <= 8):
                return
            font.setPixelSize(font.pixelSize() - 1)

    def resizeEvent(self, event: QResizeEvent) -> None:
        """Keep the HOLD badge in the top-right corner; auto scale: fit the digits."""
        super().resizeEvent(event)
        self._fit_digits()
        self._place_hold_badge()
