"""The readouts show every figure whole, at the same size and place, in every state.

Each readout is rendered at its widest values (-180.00, 1:inf, -1:9999, 999.99 mm/m, in/ft,
% grade, OVER) in every state (normal, alarm, hold, stale, full-screen instrument size) and
theme, and every label's text is measured against the label's contents rectangle.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from PySide6.QtCore import QPoint, QRect, QSize
from PySide6.QtGui import QColor, QFontMetrics, QImage
from PySide6.QtWidgets import QApplication, QLabel, QStyle, QWidget
from test_display_refresh import raw_block

from app.core.readout import slope_from_angle
from app.gui import theme
from app.gui.main_window import INSTRUMENT_MAX_PX, READOUT_MAX_PX, READOUT_MIN_PX
from app.gui.readouts import QUANTITIES, TiltReadouts

# (unit, roll, pitch, tilt, direction): the widest figures each unit can show.
WIDEST = [
    ("deg", -180.0, -179.99, 179.99, 359.94),
    ("ratio", slope_from_angle(-0.0058, "ratio"), slope_from_angle(0.0, "ratio"),
     slope_from_angle(0.0058, "ratio"), 271.5),  # -1:9999, 1:∞, 1:9999
    ("mm/m", -999.99, -999.9, 999.99, 180.0),
    ("in/ft", -999.99, 2000.0, 999.99, 90.0),  # 2000 in/ft reads +OVER
    ("percent", -999.99, -5000.0, 999.99, 45.0),
]
STATES = ("normal", "alarm", "hold", "stale", "alarm+hold+stale", "instrument", "smallest")
NORMAL_SIZE = (700, 420)
INSTRUMENT_SIZE = (1920, 1000)


@pytest.fixture
def app(qapp: QApplication) -> Iterator[QApplication]:
    """The application, its theme restored afterwards."""
    style_name, palette, stylesheet = qapp.style().name(), qapp.palette(), qapp.styleSheet()
    yield qapp
    qapp.setStyleSheet(stylesheet)
    qapp.setPalette(palette)
    if style_name:
        qapp.setStyle(style_name)
    theme._make_current(theme.DARK)


_hosts: list[QWidget] = []


@pytest.fixture(autouse=True)
def _release_hosts() -> Iterator[None]:
    yield
    _hosts.clear()


def _readouts(qtbot) -> TiltReadouts:
    # A child, sized by its parent like in the main window (a top-level widget could not
    # be made smaller than its layout's minimum).
    host = QWidget()
    qtbot.addWidget(host)
    host.resize(*INSTRUMENT_SIZE)
    widget = TiltReadouts(host)
    widget.setAutoScale(True, READOUT_MAX_PX, READOUT_MIN_PX, (2, 1))
    widget.resize(*NORMAL_SIZE)
    host.show()
    qtbot.waitExposed(host)
    _hosts.append(host)  # kept alive for the test (qtbot holds its widgets weakly)
    widget.setValid(True)
    return widget


def _enter(widget: TiltReadouts, state: str, qtbot) -> None:
    alarm = "alarm" in state
    widget.setAlarm(("roll", "pitch", "tilt") if alarm else ())
    widget.setHold("hold" in state)
    widget.setStale(time.time() if "stale" in state else None)
    if state == "instrument":  # what F11 does to the readouts
        widget.setAutoScale(True, INSTRUMENT_MAX_PX, READOUT_MIN_PX, (1, 2))
        widget.resize(*INSTRUMENT_SIZE)
    elif state == "smallest":  # all the room a crowded window gives them
        widget.setAutoScale(True, READOUT_MAX_PX, READOUT_MIN_PX, (2, 1))
        widget.resize(widget.minimumSizeHint())
    else:
        widget.setAutoScale(True, READOUT_MAX_PX, READOUT_MIN_PX, (2, 1))
        widget.resize(*NORMAL_SIZE)
    QApplication.processEvents()


def _fits(label: QLabel) -> bool:
    """Whether ``label``'s text lies inside its contents rectangle (font metrics)."""
    metrics = QFontMetrics(label.font())
    rect = label.contentsRect()
    text = label.text()
    return (metrics.horizontalAdvance(text) <= rect.width()
            and metrics.boundingRect(text).height() <= rect.height() + 1
            and metrics.height() <= rect.height())


def _tile_texts(widget: TiltReadouts) -> list[tuple[str, QRect]]:
    """Every visible tile text (caption, figures, unit, note, raised side) and the rectangle
    its glyphs take, in ``widget``'s coordinates."""
    texts = []
    for name in QUANTITIES:
        tile = widget.valueLabel(name).parentWidget()
        for label in tile.findChildren(QLabel):
            if not label.isVisibleTo(tile) or not label.text():
                continue
            metrics = QFontMetrics(label.font())
            size = QSize(metrics.horizontalAdvance(label.text()), metrics.height())
            rect = QStyle.alignedRect(label.layoutDirection(), label.alignment(), size,
                                      label.contentsRect())
            texts.append((f"{name} {label.text()!r}",
                          rect.translated(label.mapTo(widget, QPoint(0, 0)))))
    return texts


def _layout(widget: TiltReadouts) -> dict[str, tuple]:
    """Every tile's and label's geometry and font size."""
    result = {}
    for name in QUANTITIES:
        tile = widget.valueLabel(name).parentWidget()
        result[name] = (
            tile.geometry().getRect(),
            *(label.geometry().getRect() for label in tile.findChildren(QLabel)),
            *(label.font().pixelSize() for label in tile.findChildren(QLabel)),
        )
    return result


@pytest.mark.parametrize("theme_name", list(theme.THEMES))
def test_every_readout_fits_its_label_at_its_widest_in_every_state(qtbot, app, theme_name):
    theme.apply_theme(app, theme_name)
    widget = _readouts(qtbot)
    checked_labels = checked_states = 0
    for unit, roll, pitch, tilt, direction in WIDEST:
        widget.setValues(roll, pitch, tilt, direction, unit)
        layouts: dict[str, dict] = {}
        for state in STATES:
            _enter(widget, state, qtbot)
            checked_states += 1
            for name in QUANTITIES:
                value = widget.valueLabel(name)
                tile = value.parentWidget()
                for label in tile.findChildren(QLabel):
                    if not label.isVisibleTo(tile):
                        continue
                    assert _fits(label), (
                        f"{theme_name} {unit} {state}: {name} {label.objectName()} "
                        f"{label.text()!r} wider than its label")
                    checked_labels += 1
                # Digits, unit, caption and note stay apart and inside the tile.
                inside = tile.contentsRect()
                rows = [tile.caption.geometry(), value.geometry(), tile.note.geometry()]
                assert all(inside.contains(r) for r in (*rows, tile.unit.geometry()))
                assert rows[0].bottom() < rows[1].top() and rows[1].bottom() < rows[2].top()
                assert not value.geometry().intersects(tile.unit.geometry())
            for badge_name in ("HoldBadge", "StaleBadge"):
                badge = widget.findChild(QLabel, badge_name)
                if badge.isVisibleTo(widget):
                    assert _fits(badge) and widget.rect().contains(badge.geometry())
                    covered = [text for text, rect in _tile_texts(widget)
                               if rect.intersects(badge.geometry())]
                    assert not covered, (
                        f"{theme_name} {unit} {state}: {badge_name} covers {covered}")
                    checked_labels += 1
            if state not in ("instrument", "smallest"):
                layouts[state] = _layout(widget)
        # Alarm, hold and stale only recolour: the same fonts, sizes and places.
        assert all(layout == layouts["normal"] for layout in layouts.values()), unit
        # Back from full screen: as before it.
        _enter(widget, "normal", qtbot)
        assert _layout(widget) == layouts["normal"]
    assert checked_states == len(WIDEST) * len(STATES)
    print(f"\n{theme_name}: {checked_labels} label renderings checked in "
          f"{checked_states} unit x state combinations ({len(QUANTITIES)} readouts each)")


def test_an_alarm_recolours_without_changing_a_font(qtbot, app):
    theme.apply_theme(app, "dark")
    widget = _readouts(qtbot)
    widget.setValues(-178.33, 0.0, 178.33, 90.0, "deg")
    tilt = widget.valueLabel("tilt")
    font, size = tilt.font().pixelSize(), tilt.size()
    normal = tilt.palette().color(tilt.foregroundRole()).name()
    widget.setAlarm(["tilt"])
    assert tilt.parentWidget().property("alarm") is True
    assert tilt.palette().color(tilt.foregroundRole()).name() == theme.ALARM_STATE != normal
    assert tilt.font().pixelSize() == font and tilt.size() == size
    assert tilt.text() == "178.33" and _fits(tilt)
    widget.setAlarm([])
    assert tilt.palette().color(tilt.foregroundRole()).name() == normal
    assert tilt.parentWidget().property("alarm") is False


def _ink_rows(image: QImage, rect: QRect, background: QColor) -> tuple[int, int]:
    """First and last pixel rows inside ``rect`` that differ from ``background``."""
    rows = [
        y for y in range(rect.top(), rect.bottom() + 1)
        if any(_differs(image.pixelColor(x, y), background)
               for x in range(rect.left(), rect.right() + 1))
    ]
    assert rows, "nothing drawn"
    return rows[0], rows[-1]


def _differs(colour: QColor, background: QColor) -> bool:
    return (abs(colour.red() - background.red()) + abs(colour.green() - background.green())
            + abs(colour.blue() - background.blue())) > 120


@pytest.mark.parametrize("unit", ["deg", "percent"])
def test_the_unit_sits_with_the_digits_after_full_screen_and_back(qtbot, app, unit):
    """F11 then Esc once left the degree sign ~30 px below the digits: a "°" starts at the
    digits' top, a "%" ends on their baseline, before and after."""
    theme.apply_theme(app, "dark")
    widget = _readouts(qtbot)
    widget.setValues(-12.34, 5.0, 13.3, 90.0, unit)
    background = QColor(theme.BASE_BG)

    def offsets() -> tuple[int, int]:
        tile = widget.valueLabel("roll").parentWidget()
        image = tile.grab().toImage()
        digits = _ink_rows(image, widget.valueLabel("roll").geometry(), background)
        mark = _ink_rows(image, tile.unit.geometry(), background)
        return mark[0] - digits[0], mark[1] - digits[1]

    before = offsets()
    _enter(widget, "instrument", qtbot)
    big = widget.valueLabel("roll").font().pixelSize()
    _enter(widget, "normal", qtbot)
    assert big > widget.valueLabel("roll").font().pixelSize()
    after = offsets()
    top, bottom = after
    if unit == "deg":
        assert abs(top) <= 3, f"degree sign {top} px below the digits' top"
    else:
        assert abs(bottom) <= 2, f"% ends {bottom} px off the digits' baseline"
    assert after == before


# -- stale, undefined direction: the readouts fed by the presenter (fixture `live`: conftest) --

@pytest.fixture
def dark(app: QApplication) -> QApplication:
    """The dark theme, applied before the views are made (asked for before ``live``)."""
    theme.apply_theme(app, "dark")
    return app


def test_figures_of_a_lost_device_are_greyed_with_when_they_were_live(dark, live):
    readouts = live.presenter.readouts
    live.presenter.settings.readout_rate_hz = 1e6  # every refresh updates the texts
    live.pipeline.process(raw_block(0, 104, roll=131.0, pitch=0.0))
    before = time.time()
    assert live.presenter.refresh()
    value = readouts.valueLabel("roll")
    live_colour = value.palette().color(value.foregroundRole()).name()
    assert readouts.readoutText("roll") == "+131.00°" and not readouts.isStale()
    # The last rows before the loss are still buffered when it is reported: shown, but
    # they do not make the figures live again.
    live.pipeline.process(raw_block(104, 10, roll=131.0, pitch=0.0))
    live.presenter.show_stale("simulated cable unplugged")
    assert readouts.isStale()
    live.presenter.refresh()
    assert readouts.isStale()
    assert value.palette().color(value.foregroundRole()).name() == theme.TEXT_STALE != live_colour
    stamp = readouts.staleText().rsplit(" ", 1)[-1]
    shown = time.strftime("%H:%M:%S", time.localtime(before))
    assert "last live" in readouts.staleText() and stamp >= shown  # HH:MM:SS, same day
    assert readouts.readoutText("roll") == "+131.00°"  # the last figures stay, greyed
    live.pipeline.process(raw_block(114, 20, roll=131.0, pitch=0.0))
    live.presenter.refresh()
    assert not readouts.isStale() and readouts.staleText() == ""
    assert value.palette().color(value.foregroundRole()).name() == live_colour


def test_direction_of_a_level_reading_is_a_dash(qtbot, app):
    theme.apply_theme(app, "dark")
    widget = _readouts(qtbot)
    widget.setValues(0.0012, -0.003, 0.0032, 211.7, "deg")  # after a tare: noise
    assert widget.readoutText("tilt") == "0.00°"
    assert widget.readoutText("direction") == "—"
    assert widget.valueLabel("direction").parentWidget().side.text() == "—"
    widget.setValues(0.021, -0.052, 0.056, 211.7, "mm/m")  # the same tilt: 0.06 mm/m
    assert widget.readoutText("direction") == "211.7° −x−y"
    widget.setValues(1.5, -0.8, 1.7, 331.9, "deg")
    assert widget.readoutText("direction") == "331.9° +x−y"


def test_the_truth_line_is_averaged_like_the_readouts(live):
    live.presenter.settings.readout_rate_hz = 1e6
    live.presenter.settings.averaging_s = 0.5
    # Half the window at roll 10°, half at 30°: the truth's newest row says 30°, the mean 20°.
    live.pipeline.process(raw_block(0, 26, roll=10.0, pitch=0.0))
    live.pipeline.process(raw_block(26, 26, roll=30.0, pitch=0.0))
    live.presenter.refresh()
    truth = live.presenter.truth_label.text()
    shown = float(live.presenter.readouts.readoutText("roll").rstrip("°"))
    assert "(0.5 s mean)" in truth
    truth_roll = float(truth.split("roll ")[1].split("°")[0])
    assert abs(truth_roll - 20.0) < 1.0
    error = float(truth.split("reading error ")[1].split("°")[0])
    assert error == pytest.approx(abs(shown - truth_roll), abs=0.02)
