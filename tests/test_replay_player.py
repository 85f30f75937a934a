"""Replay like a media player: a seek shows the data at the new place (also while paused), the
groove seeks where clicked, an end state that plays again, bookmarks drawn, a bar that fits a
laptop screen, information banners, "Replay of FILE", and plot exports from a hidden dock."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from PySide6.QtCore import QPoint, QSettings, Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QMainWindow, QToolButton

from app.core.orientation import inclination_error_deg
from app.core.pipeline import Pipeline
from app.core.recording import read_recording, sample_recording
from app.gui import theme
from app.gui.banner import MessageBanner
from app.gui.replay_bar import REPLAY_TEXT, ReplayBar
from app.services.replay_control import (
    SEEK_LEAD_IN_S,
    ReplayCommandError,
    ReplayNotice,
    replay_caption,
    replay_command,
    replay_position,
    restore_recorded_filter,
)
from drivers.replay import ReplayDevice, replay_url

TIMEOUT_MS = 30_000
TOUR = sample_recording("tour-104hz")  # 60 s, a gap at 37 s
TOUR_START_S = float(read_recording(TOUR).columns["t"][0])


def open_replay(path=TOUR, **options) -> tuple[ReplayDevice, Pipeline]:
    device = ReplayDevice(replay_url(path, **options))
    info = device.open()
    pipeline = Pipeline()
    restore_recorded_filter(device, pipeline)
    pipeline.configure(info.odr_hz)
    return device, pipeline


def head(raw, stop_t: float):
    """The rows of ``raw`` up to ``stop_t``."""
    n = int(np.searchsorted(raw.t_s, stop_t, "right"))
    cut = {name: (None if value is None else value[:n]) for name, value in (
        ("t_s", raw.t_s), ("accel_raw", raw.accel_raw), ("gyro_raw", raw.gyro_raw),
        ("temp_raw", raw.temp_raw), ("gap", raw.gap), ("reference_quat", raw.reference_quat))}
    return dataclasses.replace(raw, **cut)


# -- the device and the service (no screen) -------------------------------------------------------
def test_a_paused_seek_delivers_the_lead_in_up_to_the_new_position_at_once():
    device, _ = open_replay(paused=1)
    start = device.start_t_s
    assert device.seek(30.0, lead_in_s=5.0) == pytest.approx(30.0, abs=0.02)
    assert device.position_s == pytest.approx(30.0, abs=0.02)  # not the lead-in's start
    block = device.read(0.05)
    assert block is not None
    assert block.t_s[0] - start == pytest.approx(25.0, abs=0.02)
    assert 29.9 < block.t_s[-1] - start < 30.0
    assert block.gap[0]  # the filters restart where the lead-in begins
    assert device.read(0.01) is None  # still paused
    device.step()
    after = device.read(0.05)
    assert after.t_s[0] - start == pytest.approx(30.0, abs=0.02) and not after.gap[0]
    # Past the end: the lead-in is the last 5 s before the last sample.
    device.seek(1e6, lead_in_s=5.0)
    block = device.read(0.05)
    assert block.t_s[0] - start == pytest.approx(device.duration_s - 5.0, abs=0.02)
    assert device.position_s == pytest.approx(device.duration_s)
    device.close()


def test_a_paused_seek_shows_the_attitude_a_straight_replay_has_there():
    for position in (12.0, 30.0, 50.0):  # at rest, on edge (pitch -90), after the gap
        device, pipeline = open_replay(paused=1)
        replay_command(device, pipeline, "seek", position)
        assert replay_position(device).position_s == pytest.approx(position, abs=0.02)
        pipeline.process(device.read(0.05))
        shown = pipeline.orientation.latest(1)
        assert shown["t"][0] - device.start_t_s == pytest.approx(position, abs=0.02)
        assert pipeline.samples.latest(len(pipeline.samples))["t"][0] - device.start_t_s == (
            pytest.approx(position - SEEK_LEAD_IN_S, abs=0.02))
        device.close()

        straight, whole = open_replay(speed="max", exact=0, block=4096)
        while (raw := straight.read(0.05)) is not None:
            raw = head(raw, float(shown["t"][0]))
            if len(raw.t_s):
                whole.process(raw)
        straight.close()
        reference = whole.orientation.latest(1)
        assert reference["t"][0] == shown["t"][0]
        error = inclination_error_deg(shown["quat"], reference["quat"])[0]
        assert error < 0.1, f"at {position} s the seek's attitude is {error:.3f}° off"


def test_the_end_state_and_play_again_from_the_start():
    device, pipeline = open_replay(speed="max", exact=0, block=4096)
    while (raw := device.read(0.05)) is not None:
        pipeline.process(raw)
    state = replay_position(device)
    assert state.ended and not state.playing
    assert state.position_s == pytest.approx(state.duration_s)
    replay_command(device, pipeline, "play", None)
    assert pipeline.counters.samples == 0  # the views start afresh: time went back
    state = replay_position(device)
    assert state.playing and not state.ended and state.position_s == 0.0
    assert device.read(0.05).t_s[0] == device.start_t_s
    device.close()


def test_nothing_further_is_a_notice_and_bookmarks_are_reported():
    device, pipeline = open_replay(paused=1)
    recorded = replay_position(device).bookmarks_s  # one per face of the tour, 8 s apart
    assert recorded == pytest.approx(tuple(8.0 * k for k in range(8)), abs=0.02)
    replay_command(device, pipeline, "seek", 20.0)
    replay_command(device, pipeline, "add_bookmark", None)
    assert replay_position(device).bookmarks_s == pytest.approx(
        tuple(sorted((*recorded, 20.0))), abs=0.02)
    replay_command(device, pipeline, "seek", 57.0)
    with pytest.raises(ReplayNotice, match="No further bookmark"):
        replay_command(device, pipeline, "next_bookmark", None)
    assert issubclass(ReplayNotice, ReplayCommandError)
    with pytest.raises(ReplayNotice, match="No further gap"):
        replay_command(device, pipeline, "next_gap", None)
    with pytest.raises(ReplayCommandError, match="unknown") as raised:
        replay_command(device, pipeline, "rewind", None)
    assert not isinstance(raised.value, ReplayNotice)  # a real error stays an error
    assert replay_caption(device.info) == "Replay of tour-104hz.csv"
    device.close()


def test_a_loop_back_to_the_start_starts_the_views_afresh():
    from app.services.acquisition import Acquisition
    from app.services.connection import Connection
    from app.services.recording_control import RecordingControl

    pipeline, connection = Pipeline(), Connection()
    acquisition = Acquisition(connection, pipeline,
                              RecordingControl(on_error=print, on_status=lambda _s: None),
                              on_message=lambda _level, _text: None)
    info = connection.open(replay_url(sample_recording("wobble-104hz"), speed="max", loop=1,
                                      exact=0, block=512))
    pipeline.configure(info.odr_hz)
    device = connection.device
    while device.last_block_generation == 0:
        acquisition.step()
    # The first block after the loop: the buffers hold it alone, so the 0.5 s average is
    # over 0.5 s of the new pass, not over the whole recording that came before.
    held = pipeline.orientation.latest(len(pipeline.orientation))["t"]
    assert held[0] == device.start_t_s and np.all(np.diff(held) > 0)
    assert pipeline.counters.samples == len(held) == 512
    t = pipeline.orientation.window(0.5, ["t"])["t"]
    assert 0.4 < t[-1] - t[0] <= 0.5
    connection.close()


# -- the bar and the banner ----------------------------------------------------------------------
@pytest.fixture
def bar(qtbot, qapp):
    theme.apply_theme(qapp)
    window = QMainWindow()
    replay_bar = ReplayBar(window)
    window.addToolBar(replay_bar)
    window.resize(1280, 300)
    qtbot.addWidget(window)
    window.show()
    qtbot.waitExposed(window)
    requests = []
    replay_bar.control.connect(lambda name, value: requests.append((name, value)))
    replay_bar.requests = requests
    yield replay_bar
    window.close()


def test_clicking_the_groove_seeks_there(qtbot, bar):
    bar.show_position(10.0, 200.0, True)
    slider = bar.slider
    x = round(slider.x_of(0.75))
    qtbot.mouseClick(slider, Qt.MouseButton.LeftButton, pos=QPoint(x, slider.height() // 2))
    name, value = bar.requests[-1]
    assert name == "seek"
    assert value == pytest.approx(150.0, abs=200.0 / slider.width())
    assert slider.value() == pytest.approx(750, abs=1000 / slider.width() + 1)
    # A status sent before the worker took the seek does not pull the slider back.
    bar.show_position(10.5, 200.0, True)
    assert slider.value() == pytest.approx(750, abs=1000 / slider.width() + 1)
    bar.show_position(150.0, 200.0, True)
    assert slider.value() == 750
    bar.panel.layout().activate()
    width = slider.width()
    bar.show_position(5.0, 200.0, True)  # fewer digits: the slider keeps its width
    bar.panel.layout().activate()
    assert slider.width() == width
    # The keys seek too: Page Up goes 10 % on.
    slider.setFocus()
    qtbot.keyClick(slider, Qt.Key.Key_PageUp)
    assert bar.requests[-1] == ("seek", pytest.approx(25.0, abs=0.5))  # 5 s + 10 %


def test_the_end_state_says_replay_and_plays_again(qtbot, qapp, bar):
    bar.show_position(199.0, 200.0, True)
    assert bar.play_button.text() == "Pause"
    qapp.processEvents()
    step_at = bar.step_button.mapTo(bar, QPoint(0, 0))
    bar.show_position(200.0, 200.0, False, True)
    assert bar.play_button.text() == REPLAY_TEXT and not bar.play_button.isChecked()
    assert bar.ended
    qapp.processEvents()
    assert bar.step_button.mapTo(bar, QPoint(0, 0)) == step_at  # the longer text moves nothing
    bar.play_button.click()
    assert bar.requests[-1] == ("play", None)
    bar.show_position(0.5, 200.0, True)
    assert bar.play_button.text() == "Pause" and not bar.ended


def test_bookmarks_are_drawn_on_the_slider_and_the_overview(qtbot, bar):
    bar.show_position(0.0, 200.0, False, False, (50.0, 150.0))
    assert bar.slider.marks() == pytest.approx((0.25, 0.75))
    assert bar.overview.bookmarks() == pytest.approx([50.0, 150.0])
    image = bar.slider.grab().toImage()
    amber = QColor(theme.WARN_AMBER)

    def amber_at(x: int) -> bool:
        for y in range(0, 6):
            pixel = image.pixelColor(x, y)
            if abs(pixel.red() - amber.red()) + abs(pixel.green() - amber.green()) < 40:
                return True
        return False

    ratio = image.width() / bar.slider.width()
    assert amber_at(round(bar.slider.x_of(0.25) * ratio))
    assert amber_at(round(bar.slider.x_of(0.75) * ratio))
    assert not amber_at(round(bar.slider.x_of(0.5) * ratio))
    bar.show_position(0.0, 200.0, False, False, ())
    assert bar.slider.marks() == () and bar.overview.bookmarks() == []


@pytest.mark.parametrize("width", [1280, 1366])
def test_every_control_is_on_the_bar_at_laptop_widths(qtbot, bar, width):
    window = bar.window()
    window.resize(width, 300)
    qtbot.waitUntil(lambda: window.width() == width)
    extension = [b for b in bar.findChildren(QToolButton)
                 if b.objectName() == "qt_toolbar_ext_button"]
    assert extension and not extension[0].isVisible()
    shown = bar.rect()
    for widget in (bar.goto_spin, bar.overview, bar.slider, bar.position_label,
                   bar.mark_button, bar.loop_box):
        assert widget.isVisible()
        top_left = widget.mapTo(bar, QPoint(0, 0))
        assert shown.contains(top_left) and shown.contains(
            top_left + QPoint(widget.width() - 1, widget.height() - 1)), widget
    assert bar.overview.width() >= 200 and bar.slider.width() == bar.overview.width()


def test_the_banner_styles_information_apart_from_errors(qtbot):
    banner = MessageBanner()
    qtbot.addWidget(banner)
    banner.show_message("No further bookmark in this recording.", "info")
    assert banner.severity == "info" and banner.colour() == theme.ACCENT
    assert QColor(theme.ACCENT).name() in banner.styleSheet()
    banner.show_message("The device was lost")
    assert banner.severity == "error" and banner.colour() == theme.ALARM_RED
    assert QColor(theme.ALARM_RED).name() in banner.styleSheet()
    with pytest.raises(ValueError, match="severity"):
        banner.show_message("?", "shout")


# -- in the window -----------------------------------------------------------------------------
@pytest.fixture
def window(qtbot, qapp, tmp_path):
    from app.gui.main_window import MainWindow
    from app.services.session import DeviceSession

    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(DeviceSession(), settings, replay_url(TOUR, speed=5))
    qtbot.addWidget(window)
    window.resize(1366, 768)
    window.show()
    qtbot.waitUntil(lambda: window.session.pipeline.counters.samples > 50, timeout=TIMEOUT_MS)
    yield window
    window.close()


def newest_t(window) -> float:
    rows = window.session.pipeline.orientation.latest(1)["t"]
    return float(rows[0]) if len(rows) else float("nan")


def pause(qtbot, window) -> None:
    statuses = []
    window.session.status.connect(statuses.append)
    window.replay_bar.play_button.click()
    qtbot.waitUntil(lambda: bool(statuses) and not statuses[-1].replay.playing,
                    timeout=TIMEOUT_MS)


def test_a_paused_seek_in_the_window_shows_the_data_there_and_notices_are_information(
        qtbot, window):
    import re

    from app.core.readout import averaged_angles
    from app.gui.readouts import NO_VALUE

    assert window.status_device.text().startswith("Replay of tour-104hz.csv")
    pause(qtbot, window)
    qtbot.waitUntil(lambda: window.device_bar.status_label.text() == "Replay paused",
                    timeout=TIMEOUT_MS)
    start = TOUR_START_S
    slider = window.replay_bar.slider
    qtbot.mouseClick(slider, Qt.MouseButton.LeftButton,
                     pos=QPoint(round(slider.x_of(0.5)), slider.height() // 2))
    qtbot.waitUntil(lambda: abs(newest_t(window) - start - 30.0) < 0.5, timeout=TIMEOUT_MS)
    readouts = window.readouts

    def shown_and_held() -> tuple[float, float] | None:
        """(the tilt shown, the tilt of the pipeline's last 0.5 s), once a value is shown."""
        if not readouts.isValid() or readouts.readoutText("tilt") == NO_VALUE:
            return None
        quat = window.session.pipeline.orientation.window(0.5, ["quat"])["quat"]
        shown = float(re.search(r"\d+\.\d+", readouts.readoutText("tilt")).group())
        return shown, averaged_angles(quat).tilt_deg

    # The readouts refresh at their own rate: until then they may show the place before the
    # seek, so wait for the paused display to show the data at the new place.
    qtbot.waitUntil(lambda: (pair := shown_and_held()) is not None
                    and abs(pair[0] - pair[1]) <= 0.006, timeout=TIMEOUT_MS)
    shown, tilt = shown_and_held()
    assert shown == pytest.approx(tilt, abs=0.006)
    assert not window.replay_bar.play_button.isChecked()  # still paused
    assert window.replay_bar.slider.marks()  # the tour's bookmarks are on the slider
    assert len(window.replay_bar.overview.bookmarks()) == 8

    window.replay_bar.goto_spin.setValue(57.0)
    window.replay_bar.goto_spin.lineEdit().returnPressed.emit()
    qtbot.waitUntil(lambda: abs(newest_t(window) - TOUR_START_S - 57.0) < 0.5,
                    timeout=TIMEOUT_MS)
    window.replay_bar.bookmark_button.click()
    qtbot.waitUntil(lambda: window.banner.isVisible(), timeout=TIMEOUT_MS)
    assert "No further bookmark" in window.banner.label.text()
    assert window.banner.severity == "info"
    assert "ERROR" not in window.messages.toPlainText()

    # Played to the end, the button says Replay; pressed, it plays from the start again.
    bar = window.replay_bar
    bar.play_button.click()
    qtbot.waitUntil(lambda: bar.ended, timeout=TIMEOUT_MS)
    assert bar.play_button.text() == REPLAY_TEXT and not bar.play_button.isChecked()
    qtbot.waitUntil(lambda: window.device_bar.status_label.text() == "Replay ended",
                    timeout=TIMEOUT_MS)
    bar.play_button.click()
    qtbot.waitUntil(lambda: newest_t(window) - TOUR_START_S < 5.0, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: bar.play_button.text() == "Pause" and not bar.ended,
                    timeout=TIMEOUT_MS)


def test_export_draws_every_plot_with_the_plots_dock_behind_a_tab(qtbot, window, tmp_path):
    from app.core.samples import STANDARD_GRAVITY_M_S2
    from app.gui.presenter import on_screen

    window.docks["messages"].raise_()  # the plots' dock is behind the Messages tab
    qtbot.waitUntil(lambda: not on_screen(window.plots), timeout=TIMEOUT_MS)
    # The recording again, paused: the views show "no data" (the plots are emptied) ...
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device(replay_url(TOUR, paused=1))
    qtbot.waitUntil(lambda: not window.readouts.isValid(), timeout=TIMEOUT_MS)
    # ... then get data while the plots cannot be seen.
    window.replay_bar.control.emit("seek", 30.0)
    qtbot.waitUntil(lambda: abs(newest_t(window) - TOUR_START_S - 30.0) < 0.5,
                    timeout=TIMEOUT_MS)
    path = tmp_path / "plots.png"
    window.export_plots(str(path))
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    plots = window.plots
    curves = [*plots.accel_curves, *plots.gyro_curves, plots.angle_curves["roll"],
              plots.angle_curves["pitch"], plots.error_curve]
    assert plots.error_visible
    for curve in curves:
        assert curve.xData is not None and len(curve.xData) > 100, curve
    # What the export drew is the data after the seek, up to its newest sample.
    newest = window.session.pipeline.samples.latest(1)
    for axis, curve in enumerate(plots.accel_curves):
        assert curve.xData[-1] == pytest.approx(0.0)
        assert curve.yData[-1] == pytest.approx(newest["accel"][0][axis] / STANDARD_GRAVITY_M_S2)
