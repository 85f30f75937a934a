"""A two-axis bull's-eye vial that shows roll and pitch like a precision circular level."""

from __future__ import annotations

import enum
import math

from PySide6.QtCore import Property, QEvent, QPointF, QRectF, QSize, Qt
from PySide6.QtGui import (
    QBrush,
    QColor,
    QConicalGradient,
    QFont,
    QFontMetricsF,
    QLinearGradient,
    QPainter,
    QPainterPath,
    QPainterPathStroker,
    QPaintEvent,
    QPen,
    QPixmap,
    QRadialGradient,
    QResizeEvent,
)
from PySide6.QtWidgets import QSizePolicy, QWidget

from app.gui import theme

# Fractions of the vial radius: the bubble, and the bezel's width relative to the outer radius.
_BUBBLE_FRACTION = 0.12
_BEZEL_FRACTION = 0.085
# Divisions tried for the graduation rings, in order of preference, and the "nice" mantissas
# a ring step may have so that its label reads cleanly (0.1, 0.25, 0.5, 1, 2.5, 10, 30 ...).
_RING_DIVISIONS = (4, 5, 3, 2)
_NICE_MANTISSAS = (1.0, 2.0, 2.5, 3.0, 5.0)
REPAINT_THRESHOLD_PX = 0.25
"""New values repaint the vial only when the bubble or the reference marker would move at
least this far from where they were last painted (or the vial's state changes): finer
steps cannot be seen, even with antialiasing."""


class LevelState(enum.Enum):
    """What the vial currently signals (and so which colour it uses)."""

    NO_DATA = "no data"
    LEVEL = "level"
    OFF_LEVEL = "off level"
    OVER_RANGE = "over range"


def _is_nice(step: float) -> bool:
    """True if ``step`` is a mantissa from ``_NICE_MANTISSAS`` times a power of ten."""
    exponent = math.floor(math.log10(step))
    mantissa = step / 10.0**exponent
    return any(math.isclose(mantissa, nice, rel_tol=1e-9) for nice in _NICE_MANTISSAS)


def _ring_step(full_scale_deg: float) -> float:
    """Graduation ring spacing (degrees) that divides the full scale into a few clean steps."""
    for divisions in _RING_DIVISIONS:
        step = full_scale_deg / divisions
        if _is_nice(step):
            return step
    return full_scale_deg / _RING_DIVISIONS[0]


def _with_alpha(color: str | QColor, alpha: int) -> QColor:
    """A copy of ``color`` with the given alpha (0..255)."""
    result = QColor(color)
    result.setAlpha(alpha)
    return result


def _mix(color_a: str | QColor, color_b: str | QColor, weight_b: float) -> QColor:
    """Linear blend of two colours; ``weight_b`` in 0..1 is the share of ``color_b``."""
    a, b = QColor(color_a), QColor(color_b)
    weight_a = 1.0 - weight_b
    return QColor(
        round(a.red() * weight_a + b.red() * weight_b),
        round(a.green() * weight_a + b.green() * weight_b),
        round(a.blue() * weight_a + b.blue() * weight_b),
    )


class BubbleLevel(QWidget):
    """A circular (bull's-eye) spirit level for two axes.

    The bubble's centre sits at (pitch, roll) scaled to the full-scale range, +x (pitch) to
    the right and +y (roll) upwards, so it moves toward the raised side like a real bubble.
    Within the level tolerance the bubble and centre ring are green, otherwise amber; beyond
    full scale the bubble is pinned to the rim in red and an arrow on the bezel points the way.
    The widget maps the given values to pixels and nothing more.
    """

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._roll_deg = 0.0
        self._pitch_deg = 0.0
        self._tilt_deg: float | None = None
        self._full_scale_deg = 1.0
        self._tolerance_deg = 0.05
        self._valid = False
        self._reference: tuple[float, float] | None = None
        self._alarm = False
        self._static_layer: QPixmap | None = None
        self._painted: _Marks | None = None
        self._layers: dict[object, tuple[int, QPixmap]] = {}
        self._reference_outline: tuple[tuple[float, float], QPainterPath] | None = None
        policy = QSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Preferred)
        policy.setHeightForWidth(True)
        self.setSizePolicy(policy)
        self.setMinimumSize(160, 160)
        self._caption_below = False
        self._caption_boxes: dict[tuple, QRectF] = {}
        theme.notifier().changed.connect(self._on_theme_changed)

    # ---- API -----------------------------------------------------------------------------

    def setTilt(self, roll_deg: float, pitch_deg: float, tilt_deg: float | None = None) -> None:
        """Show roll and pitch (degrees); ``tilt_deg`` (total tilt) picks the colour.

        Without ``tilt_deg`` the bubble's distance from the centre, hypot(roll, pitch), is used.
        """
        self._roll_deg = float(roll_deg)
        self._pitch_deg = float(pitch_deg)
        self._tilt_deg = None if tilt_deg is None else float(tilt_deg)
        caption_below = self._caption_below
        self._place_caption()
        if self._caption_below != caption_below:
            self.update()  # the caption moved to the other side
        else:
            self._update_if_moved()

    def setRange(self, full_scale_deg: float) -> None:
        """Set the tilt (degrees) at the outer graduation ring, e.g. 0.5, 1, 2, 5, 10, 30, 90."""
        if not full_scale_deg > 0.0:
            raise ValueError(f"full scale must be positive, got {full_scale_deg!r}")
        self._full_scale_deg = float(full_scale_deg)
        self._static_layer = None
        self._place_caption()
        self.update()

    def setLevelTolerance(self, tolerance_deg: float) -> None:
        """Set the total tilt (degrees) within which the instrument reads "level"."""
        if tolerance_deg < 0.0:
            raise ValueError(f"tolerance must not be negative, got {tolerance_deg!r}")
        self._tolerance_deg = float(tolerance_deg)
        self.update()

    def setAlarm(self, alarm: bool) -> None:
        """Show the alarm state: bubble, centre ring and a ring round the vial in
        ``theme.ALARM_STATE``."""
        if bool(alarm) != self._alarm:
            self._alarm = bool(alarm)
            self.update()

    def isAlarm(self) -> bool:
        """Whether the alarm state is shown."""
        return self._alarm

    alarm = Property(bool, isAlarm, setAlarm)
    """The alarm state as a Qt property (``[alarm="true"]`` in QSS)."""

    def setValid(self, valid: bool) -> None:
        """Show the bubble (True) or hide it and print "no data" (False, e.g. disconnected)."""
        if bool(valid) != self._valid:
            self._valid = bool(valid)
            self._place_caption()
            self._update_if_moved()

    def setReference(self, roll_deg: float, pitch_deg: float) -> None:
        """Show a faint second marker at a reference orientation (e.g. a simulator's truth)."""
        self._reference = (float(roll_deg), float(pitch_deg))
        self._update_if_moved()

    def clearReference(self) -> None:
        """Remove the reference marker."""
        if self._reference is not None:
            self._reference = None
            self._update_if_moved()

    def roll(self) -> float:
        """The roll shown, in degrees."""
        return self._roll_deg

    def pitch(self) -> float:
        """The pitch shown, in degrees."""
        return self._pitch_deg

    def tilt(self) -> float:
        """The total tilt used for the colour, in degrees."""
        if self._tilt_deg is not None:
            return self._tilt_deg
        return math.hypot(self._roll_deg, self._pitch_deg)

    def fullScale(self) -> float:
        """The full-scale range in degrees."""
        return self._full_scale_deg

    def levelTolerance(self) -> float:
        """The level tolerance in degrees."""
        return self._tolerance_deg

    def isValid(self) -> bool:
        """Whether data are shown (False: no data)."""
        return self._valid

    def hasReference(self) -> bool:
        """Whether a reference marker is shown."""
        return self._reference is not None

    def state(self) -> LevelState:
        """What the vial signals for the current values."""
        if not self._valid or not self._finite():
            return LevelState.NO_DATA
        if (
            self.tilt() > self._full_scale_deg
            or self._scaled_offset(self._roll_deg, self._pitch_deg) > 1.0
        ):
            return LevelState.OVER_RANGE
        if self.tilt() <= self._tolerance_deg:
            return LevelState.LEVEL
        return LevelState.OFF_LEVEL

    def bubbleCenter(self) -> QPointF:
        """Where the bubble's centre is drawn, in widget pixels (pinned to the rim if over)."""
        pin = self.state() is LevelState.OVER_RANGE
        return self._position(self._roll_deg, self._pitch_deg, self._geometry(), pin)

    def captionRect(self) -> QRectF:
        """Where the full-scale caption is printed, in widget pixels (empty when none)."""
        geo = self._geometry()
        if geo.outer_radius < 20:
            return QRectF()
        return self._caption_box(geo, self._caption_text(self.state())[0])

    def bubbleRect(self) -> QRectF:
        """The bubble's bounding square in widget pixels (empty when no data)."""
        if self.state() is LevelState.NO_DATA:
            return QRectF()
        geo = self._geometry()
        center, r = self.bubbleCenter(), geo.bubble_radius * 1.25  # with its meniscus
        return QRectF(center.x() - r, center.y() - r, 2 * r, 2 * r)

    def _place_caption(self) -> None:
        """Move the caption to the other side if the bubble now covers it (hysteresis: it
        stays where it is until the bubble reaches it)."""
        geo = self._geometry()
        state = self.state()
        if geo.outer_radius < 20 or state is LevelState.NO_DATA:
            return
        # The caption's plate depends on little that changes while the bubble moves: kept.
        key = (state, self._full_scale_deg, self.width(), self.height(), self._caption_below)
        box = self._caption_boxes.get(key)
        if box is None:
            if len(self._caption_boxes) > 16:
                self._caption_boxes.clear()
            box = self._caption_boxes[key] = self._caption_box(geo, self._caption_text(state)[0])
        if box.intersects(self.bubbleRect()):
            self._caption_below = not self._caption_below

    def _on_theme_changed(self, _name: str) -> None:
        self._static_layer = None
        self._caption_boxes.clear()
        self.update()
    def _marks(self) -> _Marks:
        """What the current values would paint: state, bubble and reference centres."""
        geo = self._geometry()
        state = self.state()
        if state is LevelState.NO_DATA:
            return _Marks(state, None, None, geo.bubble_radius)
        bubble = self._position(
            self._roll_deg, self._pitch_deg, geo, state is LevelState.OVER_RANGE
        )
        reference = None if self._reference is None else self._position(*self._reference, geo)
        return _Marks(state, bubble, reference, geo.bubble_radius)

    def _update_if_moved(self) -> None:
        """Schedule a repaint if the new values look different: of the whole vial when the
        state changes, else of the spots the bubble and reference marker leave and enter."""
        painted, now = self._painted, self._marks()
        if painted is None or painted.state is not now.state or painted.radius != now.radius:
            self.update()
            return
        dirty = QRectF()
        for old, new in ((painted.bubble, now.bubble), (painted.reference, now.reference)):
            if (old is None) != (new is None) or (
                old is not None and new is not None
                and math.hypot(new.x() - old.x(), new.y() - old.y()) >= REPAINT_THRESHOLD_PX
            ):
                for spot in (old, new):
                    if spot is not None:
                        dirty = dirty.united(_spot_rect(spot, now.radius))
        if not dirty.isEmpty():
            if now.state is LevelState.OVER_RANGE:  # the arrow on the bezel moves too
                geo = self._geometry()
                for spot in (painted.bubble, now.bubble):
                    if spot is not None:
                        dirty = dirty.united(self._arrow_rect(geo, spot))
            self.update(dirty.toAlignedRect())

    # ---- Qt size handling ----------------------------------------------------------------

    def sizeHint(self) -> QSize:
        """A comfortable square size."""
        return QSize(340, 340)

    def minimumSizeHint(self) -> QSize:
        """The smallest square in which the labels stay legible."""
        return QSize(160, 160)

    def hasHeightForWidth(self) -> bool:
        """The vial is round: keep the widget square."""
        return True

    def heightForWidth(self, width: int) -> int:
        """Square: as high as wide."""
        return width

    def resizeEvent(self, event: QResizeEvent) -> None:
        """Drop the cached static drawing; it is redrawn at the new size."""
        self._static_layer = None
        super().resizeEvent(event)
        self._place_caption()

    def changeEvent(self, event: QEvent) -> None:
        """Redraw the cached engraving when the widget's font changes."""
        if event.type() == QEvent.Type.FontChange:
            self._static_layer = None
            self._caption_boxes.clear()
        super().changeEvent(event)

    # ---- Geometry (pixels) ---------------------------------------------------------------

    def _geometry(self) -> _VialGeometry:
        return _VialGeometry(self.width(), self.height())

    def _finite(self) -> bool:
        return math.isfinite(self._roll_deg) and math.isfinite(self._pitch_deg)

    def _scaled_offset(self, roll_deg: float, pitch_deg: float) -> float:
        """Distance of (pitch, roll) from the centre as a fraction of full scale."""
        return math.hypot(pitch_deg, roll_deg) / self._full_scale_deg

    def _position(
        self, roll_deg: float, pitch_deg: float, geo: _VialGeometry, pin: bool = False
    ) -> QPointF:
        """Pixel position of (pitch, roll): +x right, +y up; on the rim if beyond or ``pin``."""
        dx = pitch_deg / self._full_scale_deg
        dy = roll_deg / self._full_scale_deg
        norm = math.hypot(dx, dy)
        if norm > 1.0 or (pin and norm > 0.0):
            dx, dy = dx / norm, dy / norm
        return QPointF(
            geo.center.x() + dx * geo.scale_radius, geo.center.y() - dy * geo.scale_radius
        )

    # ---- Painting ------------------------------------------------------------------------

    def paintEvent(self, event: QPaintEvent) -> None:
        """Draw the cached vial, then level ring, caption, markers, bubble and glass sheen."""
        geo = self._geometry()
        if geo.outer_radius < 20:
            return
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        state = self.state()
        state_color = _state_color(state)
        if self._alarm and state is not LevelState.NO_DATA:
            state_color = QColor(theme.ALARM_STATE)
        painter.drawPixmap(0, 0, self._state_pixmap(geo, state, state_color))
        if self._alarm and state is not LevelState.NO_DATA:
            self._paint_alarm_ring(painter, geo, state_color)
            # The ring lies on the bezel band that carries "+X" and "+Y": engraved again on
            # top (under the ring they were lost in every alarm).
            self._paint_axis_labels(painter, geo)
        if state is not LevelState.NO_DATA and self._reference is not None:
            self._paint_reference(painter, geo)
        if state is LevelState.NO_DATA:
            self._paint_no_data(painter, geo)
        else:
            pin = state is LevelState.OVER_RANGE
            center = self._position(self._roll_deg, self._pitch_deg, geo, pin)
            self._paint_bubble(painter, geo, center, state_color)
            if state is LevelState.OVER_RANGE:
                self._paint_over_range_arrow(painter, geo, center)
        painter.drawPixmap(0, 0, self._layer(geo, "sheen", lambda p: self._paint_sheen(p, geo)))
        painter.end()
        self._painted = self._marks()

    def _state_pixmap(self, geo: _VialGeometry, state: LevelState, color: QColor) -> QPixmap:
        """The static vial with the level ring and range caption of ``state``, cached."""

        def paint(painter: QPainter) -> None:
            painter.drawPixmap(0, 0, self._static_pixmap(geo))
            self._paint_level_ring(painter, geo, state, color)
            self._paint_range_caption(painter, geo, state)

        # Keyed by what the layer shows: the state, its colour (theme, alarm) and the side the
        # caption is on.
        return self._layer(geo, (state, color.rgba(), self._caption_below), paint)

    def _layer(self, geo: _VialGeometry, key: object, paint) -> QPixmap:
        """A transparent widget-sized pixmap ``paint`` draws on, cached under ``key`` until
        the static drawing is redone (size, range, font): a moving bubble then costs a few
        pixmap copies instead of repainting gradients across the whole vial."""
        base = self._static_pixmap(geo).cacheKey()
        cached = self._layers.get(key)
        if cached is not None and cached[0] == base:
            return cached[1]
        pixmap = self._painted_pixmap(paint)
        self._layers[key] = (base, pixmap)
        return pixmap

    def _painted_pixmap(self, paint) -> QPixmap:
        """A transparent widget-sized pixmap (at the screen's pixel ratio) ``paint`` draws on."""
        ratio = self.devicePixelRatioF()
        pixmap = QPixmap(round(self.width() * ratio), round(self.height() * ratio))
        pixmap.setDevicePixelRatio(ratio)
        pixmap.fill(Qt.GlobalColor.transparent)
        painter = QPainter(pixmap)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        painter.setRenderHint(QPainter.RenderHint.TextAntialiasing)
        paint(painter)
        painter.end()
        return pixmap

    def _static_pixmap(self, geo: _VialGeometry) -> QPixmap:
        """Bezel, glass, graduations and crosshair, cached until size or range change."""
        ratio = self.devicePixelRatioF()
        if self._static_layer is None or self._static_layer.devicePixelRatio() != ratio:

            def paint(painter: QPainter) -> None:
                self._paint_bezel(painter, geo)
                self._paint_glass(painter, geo)
                self._paint_graduations(painter, geo)
                self._paint_crosshair(painter, geo)
                self._paint_axis_labels(painter, geo)

            self._static_layer = self._painted_pixmap(paint)
        return self._static_layer

    def _paint_bezel(self, painter: QPainter, geo: _VialGeometry) -> None:
        c, r_out, r_in = geo.center, geo.outer_radius, geo.vial_radius
        # Soft drop shadow under the instrument.
        shadow = QRadialGradient(c + QPointF(0, r_out * 0.03), r_out * 1.04)
        shadow.setColorAt(0.9, QColor(0, 0, 0, 110))
        shadow.setColorAt(1.0, QColor(0, 0, 0, 0))
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(shadow)
        painter.drawEllipse(c, r_out * 1.04, r_out * 1.04)
        # Turned-metal ring: a conical gradient gives the machined sheen.
        t = theme.current()
        metal = QConicalGradient(c, 135)
        for stop, colour in zip((0.0, 0.2, 0.45, 0.55, 0.75, 0.9, 1.0), t.BEZEL_STOPS):
            metal.setColorAt(stop, QColor(colour))
        painter.setBrush(metal)
        painter.setPen(QPen(QColor(t.BEZEL_EDGE), 1.2))
        painter.drawEllipse(c, r_out, r_out)
        # A darker inner chamfer between the metal and the glass.
        chamfer = QLinearGradient(c - QPointF(0, r_in), c + QPointF(0, r_in))
        chamfer.setColorAt(0.0, QColor(t.CHAMFER[0]))
        chamfer.setColorAt(1.0, QColor(t.CHAMFER[1]))
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(chamfer)
        chamfer_radius = r_in + (r_out - r_in) * 0.3
        painter.drawEllipse(c, chamfer_radius, chamfer_radius)

    def _paint_glass(self, painter: QPainter, geo: _VialGeometry) -> None:
        c, r = geo.center, geo.vial_radius
        t = theme.current()
        liquid = QRadialGradient(c - QPointF(r * 0.15, r * 0.2), r * 1.2)
        for stop, colour in zip((0.0, 0.55, 0.85, 1.0), t.VIAL_STOPS):
            liquid.setColorAt(stop, QColor(colour))
        painter.setBrush(liquid)
        painter.setPen(QPen(QColor(t.VIAL_EDGE), 1.5))
        painter.drawEllipse(c, r, r)
        # Inner shadow along the wall where the glass meets the bezel.
        wall = QRadialGradient(c, r)
        wall.setColorAt(0.88, QColor(0, 0, 0, 0))
        wall.setColorAt(1.0, QColor(0, 0, 0, 120 if t.dark else 60))
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(wall)
        painter.drawEllipse(c, r, r)

    def _ring_labels(self, geo: _VialGeometry) -> list[tuple[float, str, QRectF]]:
        """Each graduation ring: radius, label and the label's box (lower-right diagonal)."""
        step = _ring_step(self._full_scale_deg)
        ring_count = round(self._full_scale_deg / step)
        metrics = QFontMetricsF(self._label_font(geo))
        label_angle = math.radians(-45.0)
        rings = []
        for index in range(1, ring_count + 1):
            radius = geo.scale_radius * index / ring_count
            label = f"{step * index:g}°"
            anchor = QPointF(
                geo.center.x() + radius * math.cos(label_angle),
                geo.center.y() - radius * math.sin(label_angle),
            )
            width = metrics.horizontalAdvance(label)
            rings.append(
                (radius, label, QRectF(anchor.x() + 3, anchor.y() + 1, width + 2, metrics.height()))
            )
        return rings

    def _paint_graduations(self, painter: QPainter, geo: _VialGeometry) -> None:
        painter.setFont(self._label_font(geo))
        ring_pen = QPen(_with_alpha(theme.TEXT_DIM, 110), max(1.0, geo.outer_radius / 200))
        outer_pen = QPen(_with_alpha(theme.TEXT_DIM, 190), max(1.2, geo.outer_radius / 130))
        rings = self._ring_labels(geo)
        for index, (radius, label, box) in enumerate(rings):
            painter.setPen(outer_pen if index == len(rings) - 1 else ring_pen)
            painter.setBrush(Qt.BrushStyle.NoBrush)
            painter.drawEllipse(geo.center, radius, radius)
            painter.setPen(QColor(theme.TEXT_DIM))
            painter.drawText(box, Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop, label)

    def _paint_crosshair(self, painter: QPainter, geo: _VialGeometry) -> None:
        c, r_scale = geo.center, geo.scale_radius
        reach = geo.vial_radius * 0.97
        painter.setPen(QPen(_with_alpha(theme.TEXT_DIM, 120), max(1.0, geo.outer_radius / 220)))
        painter.drawLine(QPointF(c.x() - reach, c.y()), QPointF(c.x() + reach, c.y()))
        painter.drawLine(QPointF(c.x(), c.y() - reach), QPointF(c.x(), c.y() + reach))
        # Tick marks: major at each ring, minor between, on both axes, both ways.
        step = _ring_step(self._full_scale_deg)
        ring_count = round(self._full_scale_deg / step)
        minor_per_ring = 5 if r_scale / ring_count / 5 >= 5 else 2
        ticks = ring_count * minor_per_ring
        major_len = max(4.0, geo.outer_radius * 0.035)
        minor_len = major_len * 0.5
        major_pen = QPen(_with_alpha(theme.TEXT_DIM, 200), max(1.0, geo.outer_radius / 170))
        minor_pen = QPen(_with_alpha(theme.TEXT_DIM, 140), max(1.0, geo.outer_radius / 240))
        for index in range(1, ticks + 1):
            offset = r_scale * index / ticks
            major = index % minor_per_ring == 0
            half = major_len if major else minor_len
            painter.setPen(major_pen if major else minor_pen)
            for sign in (-1.0, 1.0):
                x = c.x() + sign * offset
                y = c.y() + sign * offset
                painter.drawLine(QPointF(x, c.y() - half), QPointF(x, c.y() + half))
                painter.drawLine(QPointF(c.x() - half, y), QPointF(c.x() + half, y))

    def _paint_axis_labels(self, painter: QPainter, geo: _VialGeometry) -> None:
        """Engrave "+X" and "+Y" on the bezel where those sides point."""
        font = self._label_font(geo)
        font.setBold(True)
        font.setPixelSize(max(8, round((geo.outer_radius - geo.vial_radius) * 0.62)))
        painter.setFont(font)
        band = (geo.outer_radius + geo.vial_radius) / 2
        size = (geo.outer_radius - geo.vial_radius) * 2
        for text, direction in (("+X", QPointF(1, 0)), ("+Y", QPointF(0, -1))):
            spot = geo.center + direction * band
            box = QRectF(spot.x() - size, spot.y() - size / 2, size * 2, size)
            painter.setPen(_with_alpha(theme.current().BEZEL_TEXT_SHADOW, 150))
            painter.drawText(box.translated(0, 1), Qt.AlignmentFlag.AlignCenter, text)
            painter.setPen(QColor(theme.current().BEZEL_TEXT))
            painter.drawText(box, Qt.AlignmentFlag.AlignCenter, text)

    def _paint_level_ring(
        self, painter: QPainter, geo: _VialGeometry, state: LevelState, color: QColor
    ) -> None:
        """The centre ring: just wider than the bubble by the tolerance, like a real vial."""
        tolerance_px = self._tolerance_deg / self._full_scale_deg * geo.scale_radius
        radius = min(geo.bubble_radius + tolerance_px + 1.5, geo.scale_radius)
        width = max(1.5, geo.outer_radius / 90)
        if state is LevelState.LEVEL:
            glow = QRadialGradient(geo.center, radius + width * 3)
            glow.setColorAt(0.75, _with_alpha(color, 0))
            glow.setColorAt(0.9, _with_alpha(color, 60))
            glow.setColorAt(1.0, _with_alpha(color, 0))
            painter.setPen(Qt.PenStyle.NoPen)
            painter.setBrush(glow)
            painter.drawEllipse(geo.center, radius + width * 3, radius + width * 3)
        alpha = 230 if state is LevelState.LEVEL else 170
        painter.setBrush(Qt.BrushStyle.NoBrush)
        painter.setPen(QPen(_with_alpha(color, alpha), width))
        painter.drawEllipse(geo.center, radius, radius)

    def _paint_alarm_ring(self, painter: QPainter, geo: _VialGeometry, color: QColor) -> None:
        """A bright ring on the bezel, readable across a room."""
        width = max(3.0, (geo.outer_radius - geo.vial_radius) * 0.55)
        radius = (geo.outer_radius + geo.vial_radius) / 2.0
        painter.setBrush(Qt.BrushStyle.NoBrush)
        painter.setPen(QPen(_with_alpha(color, 235), width))
        painter.drawEllipse(geo.center, radius, radius)

    def _paint_reference(self, painter: QPainter, geo: _VialGeometry) -> None:
        roll_deg, pitch_deg = self._reference or (0.0, 0.0)
        spot = self._position(roll_deg, pitch_deg, geo)
        color = _with_alpha(theme.TRACE_REFERENCE, 170)
        # The dashed ring's outline is stroked once per size and then only filled where the
        # marker is: dashing a curve anew each frame costs more than the rest of the vial.
        width = max(1.0, geo.outer_radius / 160)
        key = (geo.bubble_radius, width)
        if self._reference_outline is None or self._reference_outline[0] != key:
            ring = QPainterPath()
            ring.addEllipse(QPointF(0.0, 0.0), geo.bubble_radius, geo.bubble_radius)
            stroker = QPainterPathStroker(QPen(color, width, Qt.PenStyle.DashLine))
            self._reference_outline = (key, stroker.createStroke(ring))
        painter.fillPath(self._reference_outline[1].translated(spot), color)
        arm = geo.bubble_radius * 0.35
        painter.setPen(QPen(color, max(1.0, geo.outer_radius / 160)))
        painter.drawLine(spot - QPointF(arm, 0), spot + QPointF(arm, 0))
        painter.drawLine(spot - QPointF(0, arm), spot + QPointF(0, arm))

    def _paint_bubble(
        self, painter: QPainter, geo: _VialGeometry, center: QPointF, color: QColor
    ) -> None:
        r = geo.bubble_radius
        # Meniscus: the liquid darkens in a thin ring around the bubble.
        meniscus = QRadialGradient(center, r * 1.25)
        meniscus.setColorAt(0.78, QColor(0, 0, 0, 0))
        meniscus.setColorAt(0.86, QColor(0, 0, 0, 90))
        meniscus.setColorAt(1.0, QColor(0, 0, 0, 0))
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(meniscus)
        painter.drawEllipse(center, r * 1.25, r * 1.25)
        # The bubble: light and slightly translucent, tinted by the state colour.
        body = QRadialGradient(center - QPointF(r * 0.3, r * 0.35), r * 1.35)
        body.setColorAt(0.0, _with_alpha(_mix(color, "#ffffff", 0.9), 215))
        body.setColorAt(0.45, _with_alpha(_mix(color, "#ffffff", 0.55), 160))
        body.setColorAt(0.8, _with_alpha(_mix(color, "#ffffff", 0.2), 165))
        body.setColorAt(1.0, _with_alpha(_mix(color, "#000000", 0.2), 210))
        painter.setBrush(body)
        rim = _mix(color, "#ffffff", theme.current().BUBBLE_RIM_WHITE)
        painter.setPen(QPen(_with_alpha(rim, 220), max(1.0, r / 14)))
        painter.drawEllipse(center, r, r)
        # Specular highlight, upper left.
        highlight = QRadialGradient(center - QPointF(r * 0.38, r * 0.42), r * 0.42)
        highlight.setColorAt(0.0, QColor(255, 255, 255, 230))
        highlight.setColorAt(1.0, QColor(255, 255, 255, 0))
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(highlight)
        painter.drawEllipse(center - QPointF(r * 0.38, r * 0.42), r * 0.42, r * 0.42)
        # Faint refracted light on the far side.
        painter.setBrush(Qt.BrushStyle.NoBrush)
        painter.setPen(QPen(QColor(255, 255, 255, 70), max(1.0, r / 12)))
        painter.drawArc(
            QRectF(center.x() - r * 0.78, center.y() - r * 0.78, r * 1.56, r * 1.56),
            -80 * 16,
            -70 * 16,
        )

    def _arrow_rect(self, geo: _VialGeometry, bubble: QPointF) -> QRectF:
        """The pixels the over-range arrow for a bubble at ``bubble`` covers (with its pen)."""
        direction = bubble - geo.center
        length = math.hypot(direction.x(), direction.y())
        if length == 0.0:
            return QRectF()
        ux, uy = direction.x() / length, direction.y() / length
        band = geo.outer_radius - geo.vial_radius
        mid = geo.center + QPointF(ux, uy) * (geo.vial_radius + geo.outer_radius) / 2.0
        reach = band + 3.0
        return QRectF(mid.x() - reach, mid.y() - reach, 2 * reach, 2 * reach)

    def _paint_over_range_arrow(
        self, painter: QPainter, geo: _VialGeometry, bubble: QPointF
    ) -> None:
        """A red arrowhead on the bezel, pointing the way the bubble left the scale."""
        direction = bubble - geo.center
        length = math.hypot(direction.x(), direction.y())
        if length == 0.0:
            return
        ux, uy = direction.x() / length, direction.y() / length
        band = geo.outer_radius - geo.vial_radius
        base_radius = geo.vial_radius + band * 0.15
        tip_radius = geo.outer_radius - band * 0.05
        half_width = band * 0.75
        tip = geo.center + QPointF(ux, uy) * tip_radius
        base = geo.center + QPointF(ux, uy) * base_radius
        normal = QPointF(-uy, ux) * half_width
        arrow = QPainterPath(tip)
        arrow.lineTo(base + normal)
        arrow.lineTo(base - normal)
        arrow.closeSubpath()
        painter.setPen(QPen(QColor("#2a0d0b"), 1.0))
        painter.setBrush(QColor(theme.ALARM_RED))
        painter.drawPath(arrow)

    def _paint_sheen(self, painter: QPainter, geo: _VialGeometry) -> None:
        """The curved glass: a soft reflection across the upper part of the vial."""
        c, r = geo.center, geo.vial_radius
        upper = QPainterPath()
        upper.addEllipse(c, r * 0.94, r * 0.94)
        cut = QPainterPath()
        cut.addEllipse(QPointF(c.x() + r * 0.12, c.y() + r * 0.55), r * 1.25, r * 1.2)
        reflection = upper.subtracted(cut)
        shine = QLinearGradient(c - QPointF(0, r), c - QPointF(0, r * 0.2))
        shine.setColorAt(0.0, QColor(255, 255, 255, 38))
        shine.setColorAt(1.0, QColor(255, 255, 255, 0))
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(QBrush(shine))
        painter.drawPath(reflection)

    def _paint_no_data(self, painter: QPainter, geo: _VialGeometry) -> None:
        font = self._label_font(geo)
        font.setPixelSize(max(11, round(geo.vial_radius * 0.11)))
        font.setLetterSpacing(QFont.SpacingType.PercentageSpacing, 115)
        painter.setFont(font)
        metrics = QFontMetricsF(font)
        text = "NO DATA"
        width = metrics.horizontalAdvance(text) + metrics.height()
        height = metrics.height() * 1.5
        box = QRectF(geo.center.x() - width / 2, geo.center.y() - height / 2, width, height)
        painter.setPen(QPen(_with_alpha(theme.TEXT_DIM, 120), 1.0))
        painter.setBrush(_with_alpha(theme.current().VIAL_PLATE, 220))
        painter.drawRoundedRect(box, 4, 4)
        painter.setPen(QColor(theme.TEXT_DIM))
        painter.drawText(box, Qt.AlignmentFlag.AlignCenter, text)

    def _caption_text(self, state: LevelState) -> tuple[str, QColor]:
        """The caption, short ("±5°") where the long one would run into a ring's label."""
        full_scale = f"{self._full_scale_deg:g}°"
        if state is LevelState.OVER_RANGE:
            long, short, colour = f"OVER RANGE  > {full_scale}", f"> {full_scale}", theme.ALARM_RED
        else:
            long, short, colour = f"FULL SCALE ±{full_scale}", f"±{full_scale}", theme.TEXT_DIM
        geo = self._geometry()
        if geo.outer_radius >= 20:
            box = self._caption_box(geo, long)
            if any(box.intersects(label) for _, _, label in self._ring_labels(geo)):
                long = short
        return long, _with_alpha(colour, 230)

    def _caption_font(self, geo: _VialGeometry) -> QFont:
        font = self._label_font(geo)
        font.setLetterSpacing(QFont.SpacingType.PercentageSpacing, 108)
        return font

    def _caption_box(self, geo: _VialGeometry, text: str, below: bool | None = None) -> QRectF:
        """The caption's plate: high on the glass, or as low when the bubble is up there."""
        metrics = QFontMetricsF(self._caption_font(geo))
        width = metrics.horizontalAdvance(text) + metrics.height()
        height = metrics.height() * 1.2
        below = self._caption_below if below is None else below
        offset = geo.scale_radius * 0.6 * (1.0 if below else -1.0)
        return QRectF(
            geo.center.x() - width / 2, geo.center.y() + offset - height / 2, width, height
        )

    def _paint_range_caption(
        self, painter: QPainter, geo: _VialGeometry, state: LevelState
    ) -> None:
        """Full-scale legend printed on the glass ("OVER RANGE" in red when exceeded).

        It sits high on the glass and moves as low only while the bubble would cover it
        there (and back only when the bubble would cover it below), so it never hides
        the bubble and does not flicker.
        """
        text, color = self._caption_text(state)
        box = self._caption_box(geo, text)
        painter.setFont(self._caption_font(geo))
        # A plate of liquid colour, so crosshair and rings do not run through the letters.
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(_with_alpha(theme.current().VIAL_PLATE, 235))
        painter.drawRoundedRect(box, box.height() / 2, box.height() / 2)
        painter.setPen(color)
        painter.drawText(box, Qt.AlignmentFlag.AlignCenter, text)

    def _label_font(self, geo: _VialGeometry) -> QFont:
        font = QFont(self.font())
        font.setPixelSize(max(9, round(geo.outer_radius * 0.058)))
        return font


class _Marks:
    """What a paint showed: the state and the bubble's and reference's centres (pixels)."""

    __slots__ = ("bubble", "radius", "reference", "state")

    def __init__(
        self, state: LevelState, bubble: QPointF | None, reference: QPointF | None,
        radius: float,
    ) -> None:
        self.state = state
        self.bubble = bubble
        self.reference = reference
        self.radius = radius


def _spot_rect(center: QPointF, bubble_radius: float) -> QRectF:
    """The pixels a bubble (with its meniscus) or reference marker at ``center`` covers."""
    reach = bubble_radius * 1.25 + 3.0
    return QRectF(center.x() - reach, center.y() - reach, 2 * reach, 2 * reach)


class _VialGeometry:
    """Pixel layout of the vial for a widget size: centre and radii."""

    __slots__ = ("bubble_radius", "center", "outer_radius", "scale_radius", "vial_radius")

    def __init__(self, width: int, height: int) -> None:
        side = min(width, height)
        self.center = QPointF(width / 2.0, height / 2.0)
        self.outer_radius = side / 2.0 - max(2.0, side * 0.02)
        self.vial_radius = self.outer_radius * (1.0 - _BEZEL_FRACTION)
        self.bubble_radius = self.vial_radius * _BUBBLE_FRACTION
        # Full scale puts the bubble against the wall of the vial.
        self.scale_radius = self.vial_radius - self.bubble_radius - 1.0


def _state_color(state: LevelState) -> QColor:
    """The current theme's colour for what the vial signals."""
    return QColor({
        LevelState.NO_DATA: theme.TEXT_DISABLED,
        LevelState.LEVEL: theme.OK_GREEN,
        LevelState.OFF_LEVEL: theme.WARN_AMBER,
        LevelState.OVER_RANGE: theme.ALARM_RED,
    }[state])
