"""The instrument as a person uses it: themes, units and Ctrl+C, the full-screen instrument,
remembered settings across a restart (and a damaged settings file), and the layout fixes.

Screenshots of every theme and mode at 1024x700 and 1920x1080 go to ``test-artifacts/look/``.
"""

from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path

import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtGui import QColor, QGuiApplication
from PySide6.QtWidgets import QApplication

from app.core.alarms import default_alarm_config
from app.gui import theme
from app.gui.bubble_level import BubbleLevel
from app.gui.main_window import MainWindow
from app.gui.user_settings import SETTINGS_ENV, create_settings, ini_problem
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000
FIRST_DEVICE = "sim://static?odr=52&seed=1"
SECOND_DEVICE = "sim://interactive?odr=104&seed=2&roll=1.5&pitch=-0.7"


@pytest.fixture(autouse=True)
def _dark_again(qapp):
    """Every test starts and ends in the default dark theme."""
    theme.apply_theme(qapp)
    yield
    theme.apply_theme(qapp)


def open_window(qtbot, path: Path, device: str | None) -> MainWindow:
    window = MainWindow(DeviceSession(), QSettings(str(path), QSettings.Format.IniFormat), device)
    qtbot.addWidget(window)
    window.show()
    qtbot.waitUntil(lambda: window.session.device_info is not None, timeout=TIMEOUT_MS)
    return window


def next_frames(qtbot, window: MainWindow, frames: int = 3) -> None:
    """Let the window draw a few frames of live data (after a resize or a theme switch)."""
    start = window.presenter.frames
    qtbot.waitUntil(lambda: window.presenter.frames >= start + frames, timeout=TIMEOUT_MS)


def choose(combo, data) -> None:
    index = combo.findData(data)
    assert index >= 0, data
    combo.setCurrentIndex(index)


# ---- Remembered settings -------------------------------------------------------------------


def test_restart_brings_back_every_choice(qtbot, tmp_path):
    path = tmp_path / "settings.ini"
    window = open_window(qtbot, path, FIRST_DEVICE)
    session = window.session
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        window.connect_device(SECOND_DEVICE)
    device_url = session.device_info.url
    choose(window.unit_combo, "ratio")
    choose(window.averaging_combo, 2.0)
    choose(window.range_combo, 1.0)
    choose(window.window_combo, 30)
    # Picked in the Filter dock (a choice kept for every source, not the source's default).
    with qtbot.waitSignal(session.filterChanged, timeout=TIMEOUT_MS):
        window.filter_panel.filterRequested.emit("complementary")
    with qtbot.waitSignal(session.filterChanged, timeout=TIMEOUT_MS):
        window.filter_panel.parameterChanged.emit("tau_s", 2.25)
    with qtbot.waitSignal(session.comparisonsChanged, timeout=TIMEOUT_MS):
        session.requestComparisons.emit(["accel", "madgwick"])
    window.docks["measure"].hide()
    window.docks["device"].setFloating(True)
    window.resize(777, 555)  # inside the offscreen screen (800 x 800)
    window.set_theme("light")
    alarms = default_alarm_config()
    alarms = replace(alarms, sound=True, limits=(
        replace(alarms.limits[0], upper=2.5, enabled=True), *alarms.limits[1:]))
    window.apply_alarms(alarms)
    window.close()
    assert theme.current().name == "light"
    theme.apply_theme(QApplication.instance())  # the restart starts from the default look
    assert theme.current().name == "dark"

    again = open_window(qtbot, path, None)  # a new QSettings object on the same file
    try:
        assert again.alarm_panel.config() == alarms
        assert again.session.device_info.url == device_url
        assert again.unit_combo.currentData() == "ratio"
        assert again.presenter.settings.unit == "ratio"
        assert again.averaging_combo.currentData() == 2.0
        assert again.presenter.settings.averaging_s == 2.0
        assert again.range_combo.currentData() == 1.0 and again.level.fullScale() == 1.0
        assert again.window_combo.currentData() == 30 and again.plots.window_s == 30
        pipeline = again.session.pipeline
        qtbot.waitUntil(lambda: pipeline.filter.name == "complementary", timeout=TIMEOUT_MS)
        qtbot.waitUntil(
            lambda: pipeline.filter.get_parameter("tau_s") == pytest.approx(2.25),
            timeout=TIMEOUT_MS,
        )
        qtbot.waitUntil(
            lambda: sorted(again.filter_panel.compared_filters()) == ["accel", "madgwick"],
            timeout=TIMEOUT_MS,
        )
        assert sorted(pipeline.comparisons) == ["accel", "madgwick"]
        assert not again.docks["measure"].isVisible()
        assert again.docks["device"].isFloating()
        assert again.docks["filter"].isVisible()
        assert (again.width(), again.height()) == (777, 555)
        assert theme.current().name == "light" and again.theme_actions["light"].isChecked()
    finally:
        again.close()


def test_a_damaged_settings_file_means_defaults_a_message_and_a_copy(qtbot, tmp_path):
    path = tmp_path / "settings.ini"
    garbage = b"\x89PNG\r\n\x1a\n\x00\x00 not settings at all \xff\xfe unit=ratio"
    path.write_bytes(garbage)
    window = open_window(qtbot, path, FIRST_DEVICE)
    try:
        assert window.banner.isVisible()
        assert "damaged" in window.banner.label.text()
        assert window.unit_combo.currentData() == "deg"  # the default
        kept = list(tmp_path.glob("settings.ini.corrupt-*"))
        assert len(kept) == 1 and kept[0].read_bytes() == garbage
        assert str(kept[0]) in window.messages.toPlainText()
        choose(window.unit_combo, "in/ft")
    finally:
        window.close()
    # The new file is sound and is used from now on.
    assert ini_problem(path.read_bytes()) is None
    assert QSettings(str(path), QSettings.Format.IniFormat).value("unit") == "in/ft"


def test_a_section_that_cannot_load_is_reported_and_left_alone(qtbot, tmp_path):
    path = tmp_path / "settings.ini"
    settings = QSettings(str(path), QSettings.Format.IniFormat)
    settings.setValue("sections/alarms", '{"tilt_limit_deg": "steep"}')
    settings.sync()
    window = open_window(qtbot, path, FIRST_DEVICE)
    try:
        def strict(stored: dict) -> None:
            float(stored["tilt_limit_deg"])

        assert not window.sections.register("alarms", dict, strict)
        assert "Remembered alarms settings are not valid" in window.banner.label.text()
    finally:
        window.close()


@pytest.mark.parametrize(
    ("data", "sound"),
    [
        (b"", True),
        (b"[General]\nunit=deg\ngeometry=@ByteArray(\\x1\\xd9)\n\n[filter_parameters]\n"
         b'ekf="{\\"a\\": 1}"\n', True),
        (b'{"unit": "deg"}', False),
        (b"[General\nunit=deg\n", False),
        (b"[General]\nunit=\xff\n", False),
        (b"[General]\n\x00\x00\x00\n", False),
    ],
)  # fmt: skip
def test_ini_check(data: bytes, sound: bool):
    assert (ini_problem(data) is None) is sound


def test_the_settings_file_can_be_named_by_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(SETTINGS_ENV, str(tmp_path / "elsewhere.ini"))
    assert Path(create_settings().fileName()) == tmp_path / "elsewhere.ini"
    explicit = tmp_path / "given.ini"
    assert Path(create_settings(explicit).fileName()) == explicit


# ---- Themes -----------------------------------------------------------------------------------


def test_every_theme_has_every_colour_the_stylesheet_uses(qapp):
    for t in theme.THEMES.values():
        stylesheet = theme.load_stylesheet(t)
        assert "@" not in stylesheet, t.name
        assert t.BASE_BG in stylesheet and t.TEXT in stylesheet


def test_theme_switch_is_live_for_plots_bubble_and_stylesheet(qtbot, tmp_path, qapp):
    window = open_window(qtbot, tmp_path / "settings.ini", FIRST_DEVICE)
    try:
        qtbot.waitUntil(window.level.isValid, timeout=TIMEOUT_MS)
        plots = window.plots

        def glass_colour() -> QColor:
            image = window.level.grab().toImage()
            return QColor(image.pixel(image.width() // 2 - 20, image.height() // 2 + 35))

        dark_glass = glass_colour()
        assert plots.graphics.backgroundBrush().color() == QColor(theme.DARK.BASE_BG)
        window.set_theme("light")
        assert qapp.styleSheet() == theme.load_stylesheet(theme.LIGHT)
        assert qapp.palette().window().color() == QColor(theme.LIGHT.WINDOW_BG)
        assert plots.graphics.backgroundBrush().color() == QColor(theme.LIGHT.BASE_BG)
        roll_pen = plots.angle_curves["roll"].opts["pen"]
        assert roll_pen.color() == QColor(theme.LIGHT.TRACE_ROLL)
        assert plots.accel_plot.getAxis("left").textPen().color() == QColor(theme.LIGHT.TEXT_DIM)
        assert theme.LIGHT.AXIS_X in plots.accel_plot.titleLabel.text
        light_glass = glass_colour()
        assert light_glass.lightness() > dark_glass.lightness() + 100
        window.set_theme("high-contrast")
        assert plots.graphics.backgroundBrush().color() == QColor("#000000")
        assert window.settings.value("theme") == "high-contrast"
        # A new stylesheet would put back the labels' first fonts: the digits keep their size.
        digits = window.readouts.valueLabel("roll").font().pixelSize()
        assert digits == window.readouts.valuePixelSize()
        # The raised side beside the direction's note follows too, also while held.
        window.hold_button.setChecked(True)
        window.set_theme("light")
        side = window.readouts._tiles["direction"].side
        side.ensurePolished()
        assert side.palette().color(side.foregroundRole()).name() == theme.LIGHT.TEXT.lower()
    finally:
        window.close()


def test_system_choice_follows_the_operating_system(qtbot, qapp):
    hints = qapp.styleHints()
    assert theme.resolve("system", Qt.ColorScheme.Light) is theme.LIGHT
    assert theme.resolve("system", Qt.ColorScheme.Dark) is theme.DARK
    assert theme.resolve("system", Qt.ColorScheme.Unknown) is theme.DARK
    theme.apply_theme(qapp, "system")
    assert theme.choice() == "system"
    with qtbot.waitSignal(theme.notifier().changed, timeout=1000) as switched:
        hints.colorSchemeChanged.emit(Qt.ColorScheme.Light)
    assert switched.args == ["light"]
    assert qapp.palette().window().color() == QColor(theme.LIGHT.WINDOW_BG)
    hints.colorSchemeChanged.emit(Qt.ColorScheme.Dark)
    assert theme.current() is theme.DARK
    theme.apply_theme(qapp, "light")  # a fixed choice ignores the system
    hints.colorSchemeChanged.emit(Qt.ColorScheme.Dark)
    assert theme.current() is theme.LIGHT


# ---- Units and the clipboard ----------------------------------------------------------------


def test_ctrl_c_copies_the_reading_in_the_chosen_units(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path / "settings.ini", SECOND_DEVICE)
    try:
        qtbot.waitUntil(window.readouts.isValid, timeout=TIMEOUT_MS)
        window.hold_button.setChecked(True)  # a steady reading to compare with
        window.activateWindow()
        clipboard = QGuiApplication.clipboard()
        clipboard.clear()
        qtbot.keyClick(window, Qt.Key.Key_C, Qt.KeyboardModifier.ControlModifier)
        text = clipboard.text()
        assert text.startswith("Roll ") and " Pitch " in text and " Tilt " in text
        roll = float(text.split()[1].rstrip("°"))
        assert roll == pytest.approx(1.5, abs=0.3)  # the simulator's roll
        assert window.readouts.readoutText("roll").replace("−", "-").startswith(
            f"{roll:+.2f}"
        )
        window.hold_button.setChecked(False)
        choose(window.unit_combo, "ratio")
        qtbot.waitUntil(lambda: window.readouts.readoutText("roll").startswith("+1:"),
                        timeout=TIMEOUT_MS)
        window.hold_button.setChecked(True)
        assert window.copy_reading().startswith("Roll 1:")
        ratio = float(clipboard.text().split()[1].split(":")[1])
        assert ratio == pytest.approx(1 / math.tan(math.radians(1.5)), rel=0.2)
    finally:
        window.close()


# ---- Full-screen instrument -----------------------------------------------------------------


def test_f11_shows_only_bubble_and_digits_and_esc_restores_the_layout(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path / "settings.ini", FIRST_DEVICE)
    try:
        window.resize(790, 700)  # inside the offscreen screen (800 x 800)
        window.docks["device"].raise_()
        window.docks["messages"].hide()
        qtbot.waitUntil(window.readouts.isValid, timeout=TIMEOUT_MS)
        state, size = window.saveState(), window.size()
        visible_docks = {key for key, dock in window.docks.items() if dock.isVisible()}
        digits = window.readouts.valuePixelSize()
        window.activateWindow()
        qtbot.keyClick(window, Qt.Key.Key_F11)
        assert window.instrument_mode and window.isFullScreen()
        hidden = [*window.docks.values(), window.device_bar, window.menuBar(),
                  window.statusBar(), window.controls, window.truth_label]
        assert not any(widget.isVisible() for widget in hidden)
        assert window.level.isVisible() and window.readouts.isVisible()
        qtbot.keyClick(window, Qt.Key.Key_H)  # Hold works without its button
        assert window.presenter.settings.hold and window.readouts.isHeld()
        qtbot.keyClick(window, Qt.Key.Key_H)
        assert not window.presenter.settings.hold
        window.resize(1920, 1080)  # the offscreen screen is smaller than a real one
        qtbot.waitUntil(lambda: window.readouts.valuePixelSize() >= 100, timeout=TIMEOUT_MS)
        assert window.readouts.valuePixelSize() > 2 * digits
        assert window.level.width() >= 800
        qtbot.keyClick(window, Qt.Key.Key_Escape)
        assert not window.instrument_mode and not window.isFullScreen()
        assert window.size() == size
        assert {key for key, dock in window.docks.items() if dock.isVisible()} == visible_docks
        assert window.menuBar().isVisible() and window.statusBar().isVisible()
        assert window.controls.isVisible() and window.device_bar.isVisible()
        assert window.saveState() == state
        assert window.readouts.valuePixelSize() == digits
        qtbot.keyClick(window, Qt.Key.Key_F11)  # F11 also leaves
        assert window.instrument_mode
        qtbot.keyClick(window, Qt.Key.Key_F11)
        assert not window.instrument_mode and window.saveState() == state
    finally:
        window.close()


def test_closing_in_full_screen_remembers_the_usual_layout(qtbot, tmp_path):
    path = tmp_path / "settings.ini"
    window = open_window(qtbot, path, FIRST_DEVICE)
    window.docks["measure"].hide()
    window.set_instrument_mode(True)
    window.close()
    again = open_window(qtbot, path, FIRST_DEVICE)
    try:
        assert not again.instrument_mode and not again.isFullScreen()
        assert again.docks["filter"].isVisible() and again.docks["plots"].isVisible()
        assert not again.docks["measure"].isVisible()
        assert again.menuBar().isVisible() and again.device_bar.isVisible()
    finally:
        again.close()


# ---- Visual fixes ---------------------------------------------------------------------------


@pytest.mark.parametrize("side", [180, 340])
@pytest.mark.parametrize(("roll", "pitch"), [(3.0, 0.0), (2.9, 0.4), (-3.0, 0.0), (0.0, 0.0),
                                              (7.0, 0.0), (-9.0, 0.2)])
def test_the_full_scale_caption_never_covers_the_bubble(qtbot, roll, pitch, side):
    level = BubbleLevel()
    qtbot.addWidget(level)
    level.resize(side, side)
    level.setRange(2.0)  # four rings, whose labels are in the lower right
    level.setValid(True)
    for step in range(11):  # the bubble moves there from the centre
        level.setTilt(roll * step / 10, pitch * step / 10)
        caption = level.captionRect()
        assert not caption.intersects(level.bubbleRect()), (step, roll, pitch)
        for _, label, box in level._ring_labels(level._geometry()):
            assert not caption.intersects(box), label
    assert not level.captionRect().isEmpty()


def test_plot_legends_sit_above_the_data(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path / "settings.ini", FIRST_DEVICE)
    try:
        plots = window.plots
        with qtbot.waitSignal(window.session.comparisonsChanged, timeout=TIMEOUT_MS):
            window.session.requestComparisons.emit(["accel"])
        assert plots.legend_entries(plots.angle_plot)[-2:] == [
            "Accelerometer only roll", "Accelerometer only pitch"
        ]
        assert "Accelerometer only roll" in plots.angle_plot.titleLabel.text
        for plot in (plots.accel_plot, plots.gyro_plot, plots.angle_plot):
            header = plot.titleLabel.sceneBoundingRect()
            data = plot.getViewBox().sceneBoundingRect()
            assert header.height() > 0 and header.bottom() <= data.top() + 0.5
        assert plots.angle_plot.legend is None  # no legend box on the traces
    finally:
        window.close()


def test_readouts_fill_the_height_beside_the_level(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path / "settings.ini", FIRST_DEVICE)
    try:
        window.resize(1280, 860)
        qtbot.waitUntil(lambda: window.readouts.height() > 200, timeout=TIMEOUT_MS)
        side_bottom = window.controls.geometry().bottom()
        level_bottom = window.level.geometry().bottom()
        assert abs(side_bottom - level_bottom) < 40  # no empty band under the controls
    finally:
        window.close()


# ---- Screenshots ----------------------------------------------------------------------------


def test_screenshots_of_every_theme_and_mode(qtbot, tmp_path, artifacts_dir):
    folder = Path(artifacts_dir) / "look"
    folder.mkdir(exist_ok=True)
    window = open_window(qtbot, tmp_path / "settings.ini", SECOND_DEVICE)
    try:
        with qtbot.waitSignal(window.session.comparisonsChanged, timeout=TIMEOUT_MS):
            window.session.requestComparisons.emit(["accel"])
        choose(window.range_combo, 2.0)
        qtbot.waitUntil(window.readouts.isValid, timeout=TIMEOUT_MS)
        qtbot.waitUntil(
            lambda: window.plots.angle_curves["roll"].getData()[0] is not None, timeout=TIMEOUT_MS
        )
        saved = []
        sizes = ((1024, 700), (1920, 1080))

        def shoot(name: str) -> None:
            if not window.hold_button.isChecked():  # held, nothing new is drawn (by design)
                next_frames(qtbot, window)
            path = folder / f"{name}.png"
            assert window.grab().save(str(path))
            saved.append(path)

        for name in ("dark", "light", "high-contrast"):  # a theme switch re-polishes all
            window.set_theme(name)
            for width, height in sizes:
                window.resize(width, height)
                shoot(f"window-{name}-{width}x{height}")
        window.set_instrument_mode(True)
        # Full screen arrives as a geometry change of its own: let it land before the resizes
        # below, or it overrides the first one (the offscreen screen is 800x800).
        qtbot.waitUntil(lambda: window.isFullScreen()
                        and window.geometry() == window.screen().geometry(), timeout=TIMEOUT_MS)
        for name in ("high-contrast", "light", "dark"):
            window.set_theme(name)
            window.hold_button.setChecked(name == "dark")  # the HOLD badge, once
            for width, height in sizes:
                window.resize(width, height)  # whatever the offscreen screen's size
                qtbot.waitUntil(lambda w=width: window.width() == w, timeout=TIMEOUT_MS)
                shoot(f"fullscreen-{name}-{width}x{height}")
        window.set_instrument_mode(False)
        for path in saved:
            assert os.path.getsize(path) > 10_000
    finally:
        window.close()


def test_status_texts_make_room_whole_in_a_narrow_window(qtbot, tmp_path):
    # Changed on purpose (issue 29): fields are no longer cut with an ellipsis; the least
    # important are hidden whole and their texts are in the status bar's tooltip.
    window = open_window(qtbot, tmp_path / "settings.ini", SECOND_DEVICE)
    try:
        window.resize(760, 600)
        qtbot.waitUntil(lambda: "samples" in window.status_rate.text(), timeout=TIMEOUT_MS)
        labels = (window.status_device, window.status_rate, window.status_filter,
                  window.status_calibration)
        qtbot.waitUntil(lambda: any(label.isHidden() for label in labels), timeout=TIMEOUT_MS)
        assert not any(label.isElided() for label in labels if not label.isHidden())
        # Every hidden field's whole text is in the tooltip, and the lights stay in view.
        tip = window.statusBar().toolTip()
        assert all(label.text() in tip for label in labels if label.isHidden())
        lights = window.health_lights.geometry()
        assert window.statusBar().rect().contains(lights)
    finally:
        window.close()
