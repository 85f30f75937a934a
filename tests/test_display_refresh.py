"""The display redraws what changed, when it changed, at the pace of the screen.

Behaviour, not speed: frames follow the screen's refresh rate, a frame without new data hands
the plots nothing, hidden views do no work, labels whose text stays the same and a bubble
that moves less than a visible amount do not repaint. Repaints are counted from paint events;
"no repaint" is checked after a sentinel widget in the same window has been painted, i.e.
after the window's pending paints went out.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from PySide6.QtCore import QEvent, QObject
from PySide6.QtWidgets import QLabel, QWidget

from app.core.orientation import quaternion_from_roll_pitch, up_in_sensor_frame
from app.core.samples import RawBlock, ScaleFactors
from app.gui.bubble_level import REPAINT_THRESHOLD_PX, BubbleLevel
from app.gui.feeds.plots import MAX_SCROLL_LEAD_S, SETTLE_REBUILD_S
from app.gui.frame_clock import FALLBACK_REFRESH_HZ, FrameClock, frame_interval_ms
from app.gui.presenter import PLOT_DATA_INTERVAL_S
from app.gui.readouts import TiltReadouts

G = 9.80665
ODR = 104.0
SCALE = ScaleFactors(0.122e-3 * G, np.radians(8.75e-3), 1 / 256, 25.0)


class Paints(QObject):
    """Counts paint events of the widgets it is installed on."""

    def __init__(self, *widgets: QWidget) -> None:
        super().__init__()
        self.count = 0
        for widget in widgets:
            widget.installEventFilter(self)

    def eventFilter(self, watched, event) -> bool:
        if event.type() == QEvent.Type.Paint:
            self.count += 1
        return False


def flush_paints(qtbot, sentinel: QLabel) -> None:
    """Return once a repaint asked for now has happened: pending paints are done too."""
    painted = Paints(sentinel)
    sentinel.setText(sentinel.text() + ".")
    qtbot.waitUntil(lambda: painted.count > 0, timeout=5000)


def raw_block(start: int, count: int, roll: float = 2.0, pitch: float = -1.0,
              odr: float = ODR) -> RawBlock:
    q = quaternion_from_roll_pitch(roll, pitch)
    accel = np.round(up_in_sensor_frame(q) * G / SCALE.accel_m_s2_per_lsb).astype(np.int16)
    return RawBlock(
        t_s=(start + np.arange(count)) / odr,
        accel_raw=np.tile(accel, (count, 1)),
        gyro_raw=np.zeros((count, 3), np.int16),
        temp_raw=np.full(count, 256, np.int16),
        scale=SCALE,
        reference_quat=np.tile(q, (count, 1)),
    )


# -- frame pacing ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("refresh_hz", "interval_ms"),
    [(60.0, 16), (59.94, 16), (75.0, 13), (120.0, 8), (144.0, 6), (240.0, 4),
     (0.0, 16), (float("nan"), 16), (-1.0, 16)],
)
def test_frame_interval_is_never_slower_than_the_screen(refresh_hz, interval_ms):
    assert frame_interval_ms(refresh_hz) == interval_ms
    if refresh_hz >= 1.0:
        assert 1000.0 / frame_interval_ms(refresh_hz) >= refresh_hz


def test_frame_clock_follows_the_screen_refresh_rate(qtbot):
    widget = QWidget()
    qtbot.addWidget(widget)
    clock = FrameClock(widget, parent=widget)
    widget.show()
    qtbot.waitExposed(widget)
    screen = widget.window().windowHandle().screen()
    rate = screen.refreshRate()
    expected = rate if 1.0 <= rate <= 1000.0 else FALLBACK_REFRESH_HZ
    assert clock.refresh_hz == pytest.approx(expected)
    clock.start()
    assert clock.timer.interval() == frame_interval_ms(expected)
    # The screen's rate changing (a new mode, another screen) changes the pace.
    with qtbot.waitSignal(clock.rateChanged):
        screen.refreshRateChanged.emit(144.0)
    assert clock.timer.interval() == frame_interval_ms(144.0)
    clock.stop()


def test_frame_clock_rests_when_idle_and_wakes_on_work(qtbot):
    widget = QWidget()
    qtbot.addWidget(widget)
    clock = FrameClock(widget, idle_ticks=5, rest_interval_ms=100, parent=widget)
    clock.start()
    for _ in range(4):
        clock.report(False)
    assert not clock.resting and clock.timer.interval() == clock.interval_ms
    clock.report(False)
    assert clock.resting and clock.timer.interval() == 100
    clock.report(True)
    assert not clock.resting and clock.timer.interval() == clock.interval_ms
    ticks = []
    clock.tick.connect(lambda: ticks.append(1))
    qtbot.waitUntil(lambda: len(ticks) >= 3, timeout=2000)
    clock.stop()


# -- widgets repaint only on a visible change -------------------------------------------------
def test_readout_repaints_only_when_its_text_changes(qtbot, host):
    readouts = TiltReadouts()
    host.layout().addWidget(readouts)
    host.show()
    qtbot.waitExposed(host)
    readouts.setValid(True)
    readouts.setValues(1.234, -0.5, 1.3, 45.0, "°")
    flush_paints(qtbot, host.sentinel)
    roll = Paints(readouts.valueLabel("roll"))
    readouts.setValues(1.2349, -0.5, 1.3, 45.0, "°")  # still "+1.23"
    flush_paints(qtbot, host.sentinel)
    assert roll.count == 0
    assert readouts.readoutText("roll") == "+1.23°"
    readouts.setValues(1.24, -0.5, 1.3, 45.0, "°")
    qtbot.waitUntil(lambda: roll.count > 0, timeout=5000)
    assert readouts.readoutText("roll") == "+1.24°"


def test_bubble_repaints_only_when_it_moves_a_visible_amount(qtbot, host):
    level = BubbleLevel()
    level.setMinimumSize(400, 400)
    host.layout().addWidget(level)
    host.show()
    qtbot.waitExposed(host)
    level.setRange(5.0)
    level.setValid(True)
    level.setTilt(2.0, 1.0)
    px_per_degree = level.bubbleCenter().y()
    level.setTilt(1.0, 1.0)
    px_per_degree -= level.bubbleCenter().y()
    assert px_per_degree < 0  # roll raises the bubble: y decreases
    flush_paints(qtbot, host.sentinel)
    paints = Paints(level)
    start = level.bubbleCenter()
    level.setTilt(1.0 + 0.3 * REPAINT_THRESHOLD_PX / abs(px_per_degree), 1.0)
    flush_paints(qtbot, host.sentinel)
    assert level.bubbleCenter() != start  # the value is taken ...
    assert paints.count == 0  # ... but a fraction of the threshold is not drawn
    level.setTilt(1.0 + 3.0 * REPAINT_THRESHOLD_PX / abs(px_per_degree), 1.0)
    qtbot.waitUntil(lambda: paints.count > 0, timeout=5000)
    # A change of state (here: into over range) repaints however small the move.
    level.setTilt(4.999, 0.0)
    flush_paints(qtbot, host.sentinel)
    paints.count = 0
    level.setTilt(4.999, 0.0, 5.01)
    qtbot.waitUntil(lambda: paints.count > 0, timeout=5000)


# -- the presenter: new data only, views on screen only -----------------------------------------
def test_plots_get_no_data_when_no_new_samples_arrived(live):
    live.presenter.incremental_max_per_px = 0.0  # rebuilds for new data, as at high rates
    live.pipeline.process(raw_block(0, 208))
    assert live.presenter.refresh()
    assert len(live.handed) == 1 and live.handed[0] > 100
    for _ in range(5):
        live.presenter.refresh()
    assert len(live.handed) == 1
    live.pipeline.process(raw_block(208, 3))
    live.presenter.refresh()
    assert len(live.handed) == 2


def test_hidden_plots_do_no_work_and_catch_up_when_shown(qtbot, live):
    live.pipeline.process(raw_block(0, 208))
    live.presenter.refresh()
    live.plots.hide()
    live.pipeline.process(raw_block(208, 104, roll=5.0))
    live.presenter.refresh()
    assert len(live.handed) == 1  # hidden: nothing handed over ...
    assert live.level.roll() > 2.0  # ... while the visible bubble followed the data
    live.plots.show()
    qtbot.waitExposed(live.plots)
    live.presenter.refresh()
    assert len(live.handed) == 2  # shown again: the newest data at once


def test_a_stream_that_stopped_lets_the_display_rest(qtbot, live):
    live.pipeline.process(raw_block(0, 208))
    assert live.presenter.refresh()
    live.presenter.settings.readout_rate_hz = 1e9  # no readout update pending
    # Nothing new: the plots scroll on until the lead limit stops them, then nothing is drawn.
    # One refresh that draws nothing is not yet rest (the next may scroll a pixel on): rest is
    # nothing drawn once the last drawing is older than the scroll lead and a settling rebuild.
    feed = live.presenter.plot_feed

    def resting() -> bool:
        drew = live.presenter.refresh()
        return not drew and (time.monotonic() - feed.drawn_wall
                             > max(MAX_SCROLL_LEAD_S, SETTLE_REBUILD_S))

    qtbot.waitUntil(resting, timeout=3000)
    # The first rebuilds may repeat while the value axes settle their width (it depends on the
    # fonts installed); once the display rests nothing is drawn or handed over.
    frames, handed = live.presenter.frames, len(live.handed)
    assert [live.presenter.refresh() for _ in range(3)] == [False] * 3
    assert live.presenter.frames == frames
    assert len(live.handed) == handed


def test_plots_scroll_between_blocks_without_rebuilding(qtbot, live):
    live.presenter.incremental_max_per_px = 0.0  # rebuilds for new data, as at high rates
    live.pipeline.process(raw_block(0, 208))
    live.presenter.refresh()
    curve = live.plots.accel_curves[2]
    x_before = curve.xData.copy()
    view_width_px = live.plots.accel_plot.getViewBox().width()
    step = 2.0 * live.plots.window_s / view_width_px  # two pixels
    assert live.plots.scroll_to(step)
    assert live.plots.scroll_s == pytest.approx(step)  # the screen's pixels moved ...
    assert curve.pos().x() == 0.0  # ... the scene's trace did not (nothing is rebuilt)
    np.testing.assert_array_equal(curve.xData, x_before)
    assert not live.plots.scroll_to(step + 0.1 * live.plots.window_s / view_width_px)
    # When the scene must paint (the window was uncovered), it catches up first.
    live.plots.graphics.viewport().update()
    qtbot.waitUntil(lambda: len(live.handed) == 2, timeout=5000)
    # (rebuilt, and placed where the screen shows the traces)
    assert curve.pos().x() == pytest.approx(-live.plots.scroll_s) and not live.plots.behind
    live.pipeline.process(raw_block(208, 3))
    live.presenter.refresh()
    assert len(live.handed) == 3 and curve.pos().x() == 0.0  # new data: drawn where they belong


def test_new_data_rebuild_the_traces_at_a_lower_rate_while_they_scroll(qtbot, live):
    live.presenter.incremental_max_per_px = 0.0  # rebuilds for new data, as at high rates
    live.presenter.plot_data_interval_s = 60.0  # a long interval: no timing in the test
    live.pipeline.process(raw_block(0, 208))
    assert live.presenter.refresh()
    live.pipeline.process(raw_block(208, 3))
    # Within the interval the new samples wait (the frame is still busy: they are due) ...
    assert live.presenter.refresh()
    assert len(live.handed) == 1
    # ... and are drawn once it is over.
    live.presenter.plot_data_interval_s = PLOT_DATA_INTERVAL_S
    qtbot.waitUntil(lambda: live.presenter.refresh() and len(live.handed) == 2, timeout=2000)
    # The bubble took the new samples at once all the same (its own, shorter interval is 0).
    assert live.presenter._level_key[0] == live.pipeline.orientation.total_written


def test_scrolling_moves_the_traces_by_whole_pixels(live):
    live.pipeline.process(raw_block(0, 208))
    live.presenter.refresh()
    box = live.plots.accel_plot.getViewBox()
    pixels_per_s = box.width() / live.plots.window_s
    assert live.plots.scroll_to(2.4 / pixels_per_s)
    moved_px = live.plots.scroll_s * pixels_per_s
    assert moved_px == pytest.approx(2.0)  # the screen's pixels are copied, so whole pixels
    assert not live.plots.scroll_to(2.6 / pixels_per_s - 0.5 / pixels_per_s + 1e-9)
    # With a range selected (it stays where it is) the data areas are drawn anew, exactly.
    live.plots.set_range_selection(True)
    assert live.plots.scroll_to(3.3 / pixels_per_s)
    assert -live.plots.accel_curves[0].pos().x() * pixels_per_s == pytest.approx(3.3)


def test_an_over_range_bubble_repaints_only_around_itself_and_its_arrow(qtbot, host):
    level = BubbleLevel()
    level.setMinimumSize(400, 400)
    host.layout().addWidget(level)
    host.show()
    qtbot.waitExposed(host)
    level.setRange(1.0)
    level.setValid(True)
    level.setTilt(3.0, 0.0)  # over range: pinned to the rim, an arrow on the bezel
    flush_paints(qtbot, host.sentinel)
    rects = []

    class Rects(QObject):
        def eventFilter(self, watched, event) -> bool:
            if event.type() == QEvent.Type.Paint:
                rects.append(event.rect())
            return False

    spy = Rects()
    level.installEventFilter(spy)
    level.setTilt(3.0, 0.6)  # the bubble and the arrow move round the rim
    qtbot.waitUntil(lambda: len(rects) > 0, timeout=5000)
    painted = rects[-1]
    assert painted.width() * painted.height() < 0.5 * level.width() * level.height()
    arrow = level._arrow_rect(level._geometry(), level.bubbleCenter()).toAlignedRect()
    assert painted.contains(arrow.adjusted(1, 1, -1, -1))


def test_the_axis_labels_stay_readable_on_the_alarm_ring(qtbot, host):
    """The alarm ring lies on the bezel band that carries "+X": the label is drawn over it
    (it was hidden under the ring in every alarm)."""
    from PySide6.QtCore import QRect
    from PySide6.QtGui import QColor

    from app.gui import theme

    level = BubbleLevel()
    level.setFixedSize(400, 400)
    host.layout().addWidget(level)
    host.show()
    qtbot.waitExposed(host)
    level.setRange(5.0)
    level.setValid(True)
    level.setTilt(1.0, 0.5)
    text = QColor(theme.current().BEZEL_TEXT)
    geo = level._geometry()
    band = (geo.outer_radius + geo.vial_radius) / 2
    size = round(geo.outer_radius - geo.vial_radius)
    spot = QRect(round(geo.center.x() + band) - size, round(geo.center.y()) - size // 2,
                 2 * size, size)  # where "+X" is engraved

    ring_half_width = (geo.outer_radius - geo.vial_radius) * 0.55 / 2

    def label_pixels() -> int:
        """Pixels of the label's colour on the alarm ring's band."""
        image = level.grab().toImage()
        return sum(
            1 for x in range(spot.left(), spot.right() + 1)
            for y in range(spot.top(), spot.bottom() + 1)
            if abs(math.hypot(x - geo.center.x(), y - geo.center.y()) - band)
            < ring_half_width - 1
            and sum(abs(a - b) for a, b in zip(image.pixelColor(x, y).getRgb()[:3],
                                               text.getRgb()[:3], strict=True)) < 60)

    normal = label_pixels()
    level.setAlarm(True)
    alarm = label_pixels()
    assert normal >= 5  # its glyphs' core pixels (the band is narrower than the label)
    assert alarm >= normal * 0.8
