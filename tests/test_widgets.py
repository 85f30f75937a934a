"""Instrument widgets and theme: the bubble goes where it is told, readouts format correctly.

The images are also saved to ``test-artifacts/`` to be looked at.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator

import pytest
from PySide6.QtCore import QPointF, Qt
from PySide6.QtGui import QAction, QColor, QImage
from PySide6.QtWidgets import (
    QApplication,
    QComboBox,
    QDockWidget,
    QDoubleSpinBox,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QMainWindow,
    QProxyStyle,
    QPushButton,
    QSlider,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from app.gui import theme
from app.gui.bubble_level import BubbleLevel, LevelState, _ring_step
from app.gui.readouts import NO_VALUE, TiltReadouts, raised_side_label

SIDE_PX = 300


@pytest.fixture
def themed(qapp: QApplication) -> Iterator[QApplication]:
    """The application with the instrument theme applied, restored afterwards."""
    style_name = qapp.style().name()
    palette = qapp.palette()
    stylesheet = qapp.styleSheet()
    theme.apply_theme(qapp)
    yield qapp
    qapp.setStyleSheet(stylesheet)
    qapp.setPalette(palette)
    if style_name:
        qapp.setStyle(style_name)


@pytest.fixture
def level(qtbot, themed) -> BubbleLevel:
    """A square bubble level, valid, range 1°, tolerance 0.05°."""
    widget = BubbleLevel()
    qtbot.addWidget(widget)
    widget.resize(SIDE_PX, SIDE_PX)
    widget.setRange(1.0)
    widget.setLevelTolerance(0.05)
    widget.setValid(True)
    return widget


def _bright_pixels(image: QImage, max_radius_px: float) -> list[tuple[int, int]]:
    """Pixels brighter than any engraving within ``max_radius_px`` of the centre: the bubble."""
    cx, cy = image.width() / 2.0, image.height() / 2.0
    found = []
    for y in range(image.height()):
        for x in range(image.width()):
            if math.hypot(x - cx, y - cy) > max_radius_px:
                continue
            if QColor(image.pixel(x, y)).lightness() > 165:
                found.append((x, y))
    return found


def _bubble_centroid(widget: BubbleLevel) -> QPointF:
    image = widget.grab().toImage()
    pixels = _bright_pixels(image, SIDE_PX * 0.42)
    assert len(pixels) > 20, "no bubble in the picture"
    return QPointF(sum(x for x, _ in pixels) / len(pixels), sum(y for _, y in pixels) / len(pixels))


# ---- Bubble level -------------------------------------------------------------------------


def test_set_tilt_stores_values(level: BubbleLevel) -> None:
    level.setTilt(0.3, -0.4)
    assert (level.roll(), level.pitch()) == (0.3, -0.4)
    assert level.tilt() == pytest.approx(0.5)
    level.setTilt(0.3, -0.4, tilt_deg=0.55)
    assert level.tilt() == 0.55
    assert level.state() is LevelState.OFF_LEVEL


@pytest.mark.parametrize(
    ("roll", "pitch", "dx_sign", "dy_sign"),
    [(0.0, 0.5, 1, 0), (0.0, -0.5, -1, 0), (0.5, 0.0, 0, -1), (-0.5, 0.0, 0, 1)],
    ids=["pitch+ right", "pitch- left", "roll+ up", "roll- down"],
)
def test_bubble_moves_toward_raised_side(
    level: BubbleLevel, roll: float, pitch: float, dx_sign: int, dy_sign: int
) -> None:
    level.setTilt(roll, pitch)
    center = QPointF(SIDE_PX / 2.0, SIDE_PX / 2.0)
    drawn = level.bubbleCenter() - center
    seen = _bubble_centroid(level) - center
    for value, sign in ((drawn.x(), dx_sign), (drawn.y(), dy_sign)):
        if sign:
            assert value * sign > 20
        else:
            assert value == pytest.approx(0.0, abs=0.5)
    # The bright part of the picture (the bubble and its highlight) is where the bubble is.
    assert math.hypot(seen.x() - drawn.x(), seen.y() - drawn.y()) < 20
    if dx_sign:
        assert seen.x() * dx_sign > 15
    if dy_sign:
        assert seen.y() * dy_sign > 15


def test_half_range_is_half_way(level: BubbleLevel) -> None:
    level.setTilt(0.0, 0.5)
    half = level.bubbleCenter().x() - SIDE_PX / 2.0
    level.setTilt(0.0, 1.0)
    full = level.bubbleCenter().x() - SIDE_PX / 2.0
    assert half == pytest.approx(full / 2.0)


def test_beyond_range_pins_to_rim(level: BubbleLevel) -> None:
    level.setTilt(0.0, 0.9)
    inside = level.bubbleCenter().x() - SIDE_PX / 2.0
    level.setTilt(0.0, 5.0)
    assert level.state() is LevelState.OVER_RANGE
    pinned = level.bubbleCenter().x() - SIDE_PX / 2.0
    level.setTilt(0.0, 50.0)
    assert level.bubbleCenter().x() - SIDE_PX / 2.0 == pytest.approx(pinned)
    assert inside < pinned < SIDE_PX / 2.0
    assert pinned == pytest.approx(inside / 0.9, rel=0.01)
    # Diagonal: same distance from the centre, in the direction of the tilt.
    level.setTilt(-3.0, 3.0)
    spot = level.bubbleCenter() - QPointF(SIDE_PX / 2.0, SIDE_PX / 2.0)
    assert math.hypot(spot.x(), spot.y()) == pytest.approx(pinned)
    assert spot.x() > 0 and spot.y() > 0  # lower right: +x raised, -y raised
    # The alarm arrow is drawn on the bezel, outside the vial, on that side.
    image = level.grab().toImage()
    red = QColor(theme.ALARM_RED)
    arrow_pixels = [
        (x, y)
        for y in range(SIDE_PX // 2, SIDE_PX)
        for x in range(SIDE_PX // 2, SIDE_PX)
        if _close(QColor(image.pixel(x, y)), red)
        and math.hypot(x - SIDE_PX / 2, y - SIDE_PX / 2) > SIDE_PX * 0.42
    ]
    assert len(arrow_pixels) > 10


def test_total_tilt_argument_decides_over_range(level: BubbleLevel) -> None:
    level.setTilt(0.5, 0.5, tilt_deg=1.2)
    assert level.state() is LevelState.OVER_RANGE
    spot = level.bubbleCenter() - QPointF(SIDE_PX / 2.0, SIDE_PX / 2.0)
    level.setTilt(0.0, 5.0)
    rim = level.bubbleCenter().x() - SIDE_PX / 2.0
    assert math.hypot(spot.x(), spot.y()) == pytest.approx(rim)


def test_level_within_tolerance(level: BubbleLevel) -> None:
    level.setTilt(0.03, -0.02)
    assert level.state() is LevelState.LEVEL
    level.setLevelTolerance(0.01)
    assert level.state() is LevelState.OFF_LEVEL
    level.setTilt(0.03, -0.02, tilt_deg=0.005)
    assert level.state() is LevelState.LEVEL


def test_level_bubble_is_green_and_off_level_amber(level: BubbleLevel) -> None:
    def bubble_tint() -> QColor:
        image = level.grab().toImage()
        spot = level.bubbleCenter()
        # A point on the lower right of the bubble, away from the highlight.
        return QColor(image.pixel(round(spot.x() + 8), round(spot.y() + 8)))

    level.setTilt(0.0, 0.0)
    green = bubble_tint()
    assert green.green() > green.red() and green.green() > green.blue()
    level.setTilt(0.0, 0.4)
    amber = bubble_tint()
    assert amber.red() > amber.green() > amber.blue()


def test_invalid_hides_bubble(level: BubbleLevel) -> None:
    level.setTilt(0.2, 0.2)
    assert len(_bright_pixels(level.grab().toImage(), SIDE_PX * 0.42)) > 20
    level.setValid(False)
    assert level.state() is LevelState.NO_DATA
    assert _bright_pixels(level.grab().toImage(), SIDE_PX * 0.42) == []
    level.setValid(True)
    level.setTilt(math.nan, 0.0)
    assert level.state() is LevelState.NO_DATA


def test_reference_marker(level: BubbleLevel) -> None:
    level.setTilt(0.0, 0.0)
    plain = level.grab().toImage()
    level.setReference(0.5, -0.5)
    assert level.hasReference()
    marked = level.grab().toImage()
    assert marked != plain
    level.clearReference()
    assert not level.hasReference()
    assert level.grab().toImage() == plain


def test_square_size_policy(level: BubbleLevel) -> None:
    assert level.hasHeightForWidth()
    assert level.heightForWidth(250) == 250
    assert level.sizeHint().width() == level.sizeHint().height()


def test_bad_range_rejected(level: BubbleLevel) -> None:
    with pytest.raises(ValueError):
        level.setRange(0.0)
    with pytest.raises(ValueError):
        level.setLevelTolerance(-1.0)


@pytest.mark.parametrize(
    ("full_scale", "step"),
    [(0.5, 0.1), (1, 0.25), (2, 0.5), (5, 1), (10, 2.5), (30, 10), (90, 30)],
)
def test_graduation_rings_divide_range_cleanly(full_scale: float, step: float) -> None:
    assert _ring_step(full_scale) == pytest.approx(step)


def _close(color: QColor, target: QColor, tolerance: int = 30) -> bool:
    return (
        abs(color.red() - target.red()) < tolerance
        and abs(color.green() - target.green()) < tolerance
        and abs(color.blue() - target.blue()) < tolerance
    )


# ---- Readouts -----------------------------------------------------------------------------


@pytest.fixture
def readouts(qtbot, themed) -> TiltReadouts:
    widget = TiltReadouts()
    qtbot.addWidget(widget)
    widget.setValid(True)
    return widget


def test_readouts_format_with_sign_and_two_decimals(readouts: TiltReadouts) -> None:
    readouts.setValues(1.234, -0.456, 1.317, 123.44, "°")
    assert readouts.valueLabel("roll").text() == "+1.23"
    assert readouts.valueLabel("pitch").text() == "−0.46"
    assert readouts.valueLabel("tilt").text() == "1.32"
    assert readouts.valueLabel("direction").text() == "123.4"
    assert readouts.readoutText("roll") == "+1.23°"
    assert readouts.readoutText("pitch") == "−0.46°"
    assert readouts.readoutText("tilt") == "1.32°"
    assert readouts.readoutText("direction") == "123.4° −x+y"


def test_readouts_other_units(readouts: TiltReadouts) -> None:
    readouts.setValues(-0.001, 12.5, 12.5, 359.99, "mm/m")
    assert readouts.readoutText("roll") == "+0.00 mm/m"  # no negative zero
    assert readouts.readoutText("pitch") == "+12.50 mm/m"
    assert readouts.readoutText("direction") == "0.0° +x"  # direction stays in degrees
    readouts.setValues(0.5, 0.0, 0.5, 90.0, "%")
    assert readouts.readoutText("roll") == "+0.50 %"


def test_readouts_invalid_show_dashes(readouts: TiltReadouts) -> None:
    readouts.setValues(1.0, 2.0, 2.2, 60.0, "°")
    readouts.setValid(False)
    for name in ("roll", "pitch", "tilt", "direction"):
        assert readouts.valueLabel(name).text() == NO_VALUE
        assert readouts.readoutText(name) == NO_VALUE
    readouts.setValid(True)
    assert readouts.readoutText("roll") == "+1.00°"
    readouts.setValues(math.nan, 0.0, 0.0, 0.0, "°")
    assert readouts.readoutText("roll") == NO_VALUE


def test_readouts_hold_badge(readouts: TiltReadouts) -> None:
    badge = readouts.findChild(QLabel, "HoldBadge")
    assert badge is not None and not badge.isVisibleTo(readouts)
    readouts.setHold(True)
    assert readouts.isHeld() and badge.isVisibleTo(readouts)
    readouts.setHold(False)
    assert not badge.isVisibleTo(readouts)


def test_readout_digits_are_fixed_pitch(readouts: TiltReadouts) -> None:
    font = readouts.valueLabel("roll").font()
    assert font.pixelSize() >= 36
    metrics = readouts.valueLabel("roll").fontMetrics()
    assert len({metrics.horizontalAdvance(digit) for digit in "0123456789"}) == 1


@pytest.mark.parametrize(
    ("direction", "side"),
    [(0, "+x"), (44, "+x+y"), (90, "+y"), (135, "−x+y"), (180, "−x"), (225, "−x−y"),
     (270, "−y"), (315, "+x−y"), (359, "+x")],
)  # fmt: skip
def test_raised_side_label(direction: float, side: str) -> None:
    assert raised_side_label(direction) == side


# ---- Theme --------------------------------------------------------------------------------


def test_stylesheet_and_icon(qapp: QApplication) -> None:
    stylesheet = theme.load_stylesheet()
    assert "QToolBar" in stylesheet and "QDockWidget" in stylesheet
    icon = theme.app_icon()
    assert not icon.isNull()
    assert not icon.pixmap(32, 32).isNull()
    for name, value in theme.COLORS.items():
        assert QColor(value).isValid(), name


def test_apply_theme(themed: QApplication) -> None:
    assert themed.styleSheet() == theme.load_stylesheet()
    assert themed.palette().window().color() == QColor(theme.WINDOW_BG)
    themed.setStyleSheet("")  # unwrap the style sheet style to see the base style
    style = themed.style()  # a window's wheel guard puts its proxy over Fusion
    base = style.baseStyle() if isinstance(style, QProxyStyle) else style
    assert base.name().lower() == "fusion"


# ---- Screenshots --------------------------------------------------------------------------


def test_screenshots(qtbot, themed, artifacts_dir: str) -> None:
    """Save the instrument in its main states, for a person to look at."""
    states = [
        ("level", (0.02, -0.01), True),
        ("0.3° off", (0.3, 0.0), True),
        ("beyond range", (0.9, 1.6), True),
        ("no data", (0.0, 0.0), False),
    ]
    sheet = QWidget()
    qtbot.addWidget(sheet)
    grid = QGridLayout(sheet)
    for column, (title, (roll, pitch), valid) in enumerate(states):
        widget = BubbleLevel()
        widget.setFixedSize(SIDE_PX, SIDE_PX)
        widget.setRange(1.0)
        widget.setLevelTolerance(0.05)
        widget.setTilt(roll, pitch)
        widget.setValid(valid)
        caption = QLabel(title)
        caption.setAlignment(Qt.AlignmentFlag.AlignCenter)
        grid.addWidget(widget, 0, column)
        grid.addWidget(caption, 1, column)
    sheet.show()
    qtbot.waitExposed(sheet)
    image = sheet.grab()
    assert image.save(os.path.join(artifacts_dir, "bubble_level.png"))

    panel = QWidget()
    qtbot.addWidget(panel)
    row = QHBoxLayout(panel)
    level = BubbleLevel()
    level.setFixedSize(380, 380)
    level.setRange(1.0)
    level.setValid(True)
    level.setTilt(0.12, -0.21)
    level.setReference(0.1, -0.2)
    values = TiltReadouts(columns=1)
    values.setValid(True)
    values.setValues(0.12, -0.21, 0.24, 150.3, "°")
    values.setHold(True)
    row.addWidget(level)
    row.addWidget(values)
    panel.show()
    qtbot.waitExposed(panel)
    assert panel.grab().save(os.path.join(artifacts_dir, "instrument.png"))

    strip = TiltReadouts(columns=4)
    qtbot.addWidget(strip)
    strip.setValid(True)
    strip.setValues(-4.19, 2.27, 4.77, 151.5, "mm/m")
    strip.show()
    qtbot.waitExposed(strip)
    assert strip.grab().save(os.path.join(artifacts_dir, "readouts.png"))


def test_theme_screenshot(qtbot, themed, artifacts_dir: str) -> None:
    """Save the styled controls (tool bar, dock, group box, buttons, tabs, status bar)."""
    window = QMainWindow()
    qtbot.addWidget(window)
    toolbar = window.addToolBar("Device")
    toolbar.addWidget(QLabel("Port"))
    port = QComboBox()
    port.addItems(["Simulator", "/dev/ttyACM0"])
    toolbar.addWidget(port)
    connect = QAction("Connect", window)
    connect.setCheckable(True)
    connect.setChecked(True)
    toolbar.addAction(connect)
    toolbar.addAction(QAction("Zero", window))
    toolbar.addSeparator()
    toolbar.addAction(QAction("Hold", window))

    central = QWidget()
    row = QHBoxLayout(central)
    level = BubbleLevel()
    level.setValid(True)
    level.setTilt(0.12, -0.2)
    values = TiltReadouts(columns=1)
    values.setValid(True)
    values.setValues(0.12, -0.2, 0.23, 149.0, "°")
    row.addWidget(level, 1)
    row.addWidget(values)
    window.setCentralWidget(central)

    dock = QDockWidget("Filter", window)
    body = QWidget()
    column = QVBoxLayout(body)
    group = QGroupBox("Complementary filter")
    form = QFormLayout(group)
    slider = QSlider(Qt.Orientation.Horizontal)
    slider.setValue(40)
    form.addRow("Time constant", slider)
    gain = QDoubleSpinBox()
    gain.setValue(0.5)
    form.addRow("Gain", gain)
    column.addWidget(group)
    buttons = QHBoxLayout()
    record = QPushButton("Record")
    record.setCheckable(True)
    record.setChecked(True)
    disabled = QPushButton("Disabled")
    disabled.setEnabled(False)
    for button in (QPushButton("Calibrate…"), record, disabled):
        buttons.addWidget(button)
    column.addLayout(buttons)
    tabs = QTabWidget()
    for title in ("Angles", "Accel", "Gyro"):
        tabs.addTab(QWidget(), title)
    column.addWidget(tabs)
    dock.setWidget(body)
    window.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
    window.statusBar().addWidget(QLabel("Simulator · 104 Hz · 0 dropped"))

    window.resize(1180, 560)
    window.show()
    qtbot.waitExposed(window)
    assert window.grab().save(os.path.join(artifacts_dir, "theme.png"))


def test_a_plots_menu_is_built_on_its_first_right_click(qtbot) -> None:
    from app.gui.plots import LivePlots

    plots = LivePlots()
    qtbot.addWidget(plots)
    plots.resize(500, 400)
    plots.show()
    qtbot.waitExposed(plots)
    views = [plot.getViewBox() for plot in (plots.accel_plot, plots.gyro_plot, plots.angle_plot)]
    assert all(view.menu is None for view in views)  # nothing built with the window
    view = views[1]
    centre = plots.graphics.mapFromScene(view.mapToScene(view.boundingRect().center()))
    qtbot.mouseClick(plots.graphics.viewport(), Qt.MouseButton.RightButton, pos=centre)
    qtbot.waitUntil(lambda: view.menu is not None and view.menu.isVisible())
    assert "View All" in [action.text() for action in view.menu.actions()]
    assert views[0].menu is None and views[2].menu is None  # only the plot clicked
    view.menu.hide()
