"""Between two rebuilds the plots scroll their pixels and draw new samples onto the screen.

At a tilt meter's rate the traces are not rebuilt for every block: the data areas' pixels are
shifted as time goes on (the strip that comes into view is background) and the new samples are
drawn as short lines from each trace's end (:meth:`LivePlots.append`). These tests read the
window's pixels back and check them against where the samples belong; and they check that the
presenter appends at low rates, rebuilds when it must (a value leaves its range, the scene has
to paint, high rates), and that live labels change without re-laying out the window.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from PySide6.QtCore import QEvent, QObject, QPoint
from PySide6.QtGui import QColor, QImage
from PySide6.QtWidgets import QApplication, QHBoxLayout, QWidget
from test_display_refresh import ODR, raw_block

from app.gui import theme
from app.gui.elided_label import ElidedLabel
from app.gui.plots import LivePlots
from app.gui.readouts import TiltReadouts


def settle() -> None:
    """Deliver what is posted (the paints a scroll or an append asked for)."""
    for _ in range(3):
        QApplication.processEvents()


def screen_pixels(widget: QWidget) -> np.ndarray:
    """``widget``'s pixels as they are on screen (not painted anew), (H, W, 3)."""
    window = widget.window()
    image = window.screen().grabWindow(window.winId()).toImage()
    origin = widget.mapTo(window, QPoint(0, 0))
    image = image.copy(origin.x(), origin.y(), widget.width(), widget.height())
    image = image.convertToFormat(QImage.Format.Format_RGB888)
    pixels = np.frombuffer(image.constBits(), np.uint8, image.sizeInBytes())
    return pixels.reshape(image.height(), image.bytesPerLine())[:, : 3 * image.width()].reshape(
        image.height(), image.width(), 3)


def colour_mask(pixels: np.ndarray, colour: str) -> np.ndarray:
    rgb = QColor(colour)
    target = np.array([rgb.red(), rgb.green(), rgb.blue()])
    return np.abs(pixels.astype(int) - target).sum(axis=2) < 60


@pytest.fixture
def strip(qtbot, qapp):
    """A plots widget showing a ramp on the acceleration's x trace, the rest flat."""
    theme.apply_theme(qapp)
    plots = LivePlots()
    qtbot.addWidget(plots)
    plots.resize(800, 500)
    plots.show()
    qtbot.waitExposed(plots)
    t = np.arange(0, 3.0, 1 / ODR)

    def accel(times: np.ndarray) -> np.ndarray:
        return np.column_stack([0.2 * times - 0.3, np.full(len(times), -0.9),
                                np.full(len(times), -0.9)])

    a = accel(t)
    plots.set_data(t - t[-1], a, np.zeros((len(t), 3)), t - t[-1],
                   {"roll": np.linspace(-1.0, 1.0, len(t)), "pitch": np.zeros(len(t))})
    settle()
    return SimpleNamespace(plots=plots, t0=float(t[-1]), accel=accel)


def append_and_scroll(strip, frames: int, every: int = 3) -> float:
    """Scroll at 60 frames a second and append what arrived every ``every`` frames."""
    plots, t0 = strip.plots, strip.t0
    drawn = t0
    for frame in range(1, frames + 1):
        now = t0 + frame / 60.0
        assert plots.scroll_to(now - t0)
        if frame % every == 0:
            times = np.arange(np.ceil(drawn * ODR), np.floor(now * ODR) + 1) / ODR
            times = np.concatenate([[drawn], times[times > drawn]])
            a = strip.accel(times)
            assert plots.append([(plots.accel_curves[0], times - t0, a[:, 0],
                                  np.zeros(len(times), bool))])
            drawn = float(times[-1])
        settle()
    return drawn


def test_appended_samples_are_drawn_where_they_belong_and_join_up(strip):
    plots = strip.plots
    drawn = append_and_scroll(strip, 30)
    pixels = screen_pixels(plots.graphics.viewport())
    red = colour_mask(pixels, theme.AXIS_COLORS[0])
    sx, ox, sy, oy = plots._mapping(plots.accel_plot)
    times = np.arange(np.ceil(strip.t0 * ODR), np.floor(drawn * ODR) + 1) / ODR
    px = np.round(sx * (times - strip.t0) + ox).astype(int)
    py = np.round(sy * strip.accel(times)[:, 0] + oy).astype(int)
    # Every appended sample is on screen where it belongs (within a pixel) ...
    for x, y in zip(px, py, strict=True):
        assert red[y - 1:y + 2, x - 1:x + 2].any(), (x, y)
    # ... and the line has no holes: each column from the rebuilt part to the newest sample.
    first = int(np.round(sx * -0.2 + ox))  # 0.2 s before the rebuild's newest sample
    columns = red[:, first:px[-1]].any(axis=0)
    assert columns.all(), np.flatnonzero(~columns) + first


def test_the_strip_a_scroll_uncovers_is_background(strip):
    plots = strip.plots
    append_and_scroll(strip, 12, every=100)  # scrolling only: nothing new arrives
    pixels = screen_pixels(plots.graphics.viewport())
    red = colour_mask(pixels, theme.AXIS_COLORS[0])
    _, ox, _, _ = plots._mapping(plots.accel_plot)
    newest = int(np.round(ox))  # the rebuild's newest sample, moved left by the scroll
    area = plots._area(plots.accel_plot)
    assert newest < area.right() - 5  # it did move
    assert red[:, newest - 3:newest + 1].any()  # the trace ends there ...
    assert not red[area.top():area.bottom(), newest + 3:area.right() + 1].any()  # ... no further


def test_dashed_traces_keep_their_pattern_across_appended_pieces(strip):
    plots = strip.plots
    curve = plots.angle_curves["ref_roll"]  # dashed
    curve.setVisible(True)
    t0, drawn = strip.t0, strip.t0
    for frame in range(1, 61):
        now = t0 + frame / 60.0
        plots.scroll_to(now - t0)
        if frame % 3 == 0:
            times = np.concatenate([[drawn], np.arange(np.floor(drawn * ODR) + 1,
                                                       np.floor(now * ODR) + 1) / ODR])
            assert plots.append([(curve, times - t0, np.full(len(times), 0.5),
                                  np.zeros(len(times), bool))])
            drawn = float(times[-1])
        settle()
    pixels = screen_pixels(plots.graphics.viewport())
    sx, ox, sy, oy = plots._mapping(plots.angle_plot)
    row = int(np.round(sy * 0.5 + oy))
    line = colour_mask(pixels, theme.TRACE_ROLL)[row - 1:row + 2].any(axis=0)
    span = line[int(np.round(sx * 0.05 + ox)):int(np.round(sx * (drawn - t0) + ox))]
    # A dash pattern: both ink and gaps, and neither solid nor broken into single dots.
    assert 0.3 < span.mean() < 0.9
    runs = np.diff(np.flatnonzero(np.diff(span.astype(int)) != 0))
    assert runs.max() >= 3


# -- the presenter (fixtures `live`, `host`: conftest; blocks: test_display_refresh) -------------

def test_at_a_tilt_meter_rate_new_samples_are_appended_not_rebuilt(live):
    live.pipeline.process(raw_block(0, 208))
    assert live.presenter.refresh()
    assert len(live.handed) == 1
    live.pipeline.process(raw_block(208, 10))
    assert live.presenter.refresh()
    assert len(live.handed) == 1  # no rebuild ...
    assert live.presenter.plot_appends == 1  # ... the ten samples were drawn onto the screen
    tail_x = live.plots._tails[live.plots.accel_curves[0]][0]
    assert tail_x[-1] == pytest.approx(10 / ODR)  # up to the newest, after the rebuild's last
    # A roll far outside the angle plot's range: the range must grow, so a rebuild.
    live.pipeline.process(raw_block(218, 10, roll=40.0))
    live.presenter.refresh()
    assert len(live.handed) == 2
    _, high = live.plots.ranges[live.plots.angle_plot].range
    assert high > 35.0


def test_a_scene_paint_while_the_screen_is_ahead_rebuilds_first(qtbot, live):
    live.pipeline.process(raw_block(0, 208))
    live.presenter.refresh()
    settle()  # the rebuild is on screen
    live.pipeline.process(raw_block(208, 10))
    live.presenter.refresh()
    settle()
    assert len(live.handed) == 1 and live.plots._stale
    live.plots.graphics.viewport().update()  # e.g. the window was uncovered
    qtbot.waitUntil(lambda: len(live.handed) == 2, timeout=5000)
    assert not live.plots._stale
    assert live.handed[-1] == 218  # the rebuild has every sample the screen showed


def test_above_eight_samples_a_pixel_the_traces_are_rebuilt(live):
    odr = 6667.0
    live.pipeline.process(raw_block(0, 13334, odr=odr))
    live.presenter.refresh()
    live.pipeline.process(raw_block(13334, 133, odr=odr))
    live.presenter.refresh()
    assert len(live.handed) == 2 and live.presenter.plot_appends == 0


def test_frames_without_new_data_only_scroll(live, monkeypatch):
    live.pipeline.process(raw_block(0, 208))
    live.presenter.refresh()
    calls = []
    monkeypatch.setattr(live.presenter, "_averaged", lambda *a: calls.append(a))
    for _ in range(5):
        live.presenter.refresh()
    assert calls == []  # nothing new: no averaging, no bubble, no readouts
    live.presenter.settings.unit = "percent"  # a setting changed: the readouts follow
    live.presenter.refresh()
    assert calls


# -- live labels do not re-lay out the window ----------------------------------------------------
class LayoutRequests(QObject):
    def __init__(self, widget: QWidget) -> None:
        super().__init__()
        self.count = 0
        widget.installEventFilter(self)

    def eventFilter(self, watched, event) -> bool:
        if event.type() == QEvent.Type.LayoutRequest:
            self.count += 1
        return False


def test_changing_readouts_and_status_texts_leave_the_window_layout_alone(qtbot, qapp):
    theme.apply_theme(qapp)
    window = QWidget()
    qtbot.addWidget(window)
    row = QHBoxLayout(window)
    readouts = TiltReadouts()
    status = ElidedLabel("102.4 Hz")
    row.addWidget(readouts)
    row.addWidget(status)
    window.show()
    qtbot.waitExposed(window)
    readouts.setValid(True)
    readouts.setValues(0.0, 0.0, 0.0, 100.0, "°")  # the unit is set: that may re-lay out
    settle()
    requests = LayoutRequests(window)
    for value in np.linspace(-9.5, 9.5, 20):
        # (the same raised side: its name is a rich-text note that may change width)
        readouts.setValues(value, -value, abs(value), 100 + 0.1 * value, "°")
        status.setText(f"{100 + value:.1f} Hz")
        settle()
    assert readouts.readoutText("roll") == "+9.50°"
    assert status.text() == "109.5 Hz"
    assert requests.count == 0
    status.setText("a much longer status line than before")  # wider: room is made once
    settle()
    assert requests.count >= 1
