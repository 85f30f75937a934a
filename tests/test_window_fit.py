"""A window that fits a laptop, whole texts, and input that does what the user means.

The first window takes the screen's available area; no text is elided or cut in the docks,
the status bar or the dialogs, at 1366x768 and 1920x1080, in every theme; the wheel scrolls
panels without changing a field it passes; the keys work from the start; every shortcut is in
a menu and on Help's sheet; About names the versions and the files.
"""

from __future__ import annotations

import contextlib
import math
import sys
from pathlib import Path

import pytest
from PySide6.QtCore import QPoint, QPointF, QRect, QSettings, Qt, QtMsgType, qInstallMessageHandler
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import (
    QAbstractSlider,
    QAbstractSpinBox,
    QApplication,
    QDockWidget,
    QLabel,
    QPushButton,
    QScrollArea,
    QSpinBox,
    QTabBar,
    QVBoxLayout,
    QWidget,
)

from app import launcher
from app.core.alarms import alarms_from_specs
from app.core.recording import sample_recordings
from app.core.screen_fit import Rect, fields_that_fit, first_window_rect, label_step
from app.gui import file_dialogs, help_dialogs, theme
from app.gui.elided_label import ElidedLabel
from app.gui.main_window import MainWindow
from app.gui.panel_scroller import PanelScroller
from app.gui.text_fit import clipped_texts
from app.services.devices import replay_url
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000
SIZES = ((1366, 768), (1920, 1080))
THEMES = ("dark", "light", "high-contrast")

KNOWN_CLIPPING: dict[str, str] = {}
"""Clipped texts in files other helpers own this round (see the issue's split): a problem
whose description contains the key is reported but does not fail the test. Empty: none."""

ALLOWED_QT_MESSAGES = (
    "This plugin does not support propagateSizeHints()",
    "This plugin does not support raise()",
)
"""The offscreen platform's own notices on showing and raising a window (not the app's)."""


@contextlib.contextmanager
def qt_messages():
    """Collect Qt's warnings and worse while the block runs."""
    caught: list[str] = []

    def handler(kind, _context, message):
        if kind != QtMsgType.QtDebugMsg and kind != QtMsgType.QtInfoMsg and not any(
            allowed in message for allowed in ALLOWED_QT_MESSAGES
        ):
            caught.append(message)

    previous = qInstallMessageHandler(handler)
    try:
        yield caught
    finally:
        qInstallMessageHandler(previous)


def open_window(qtbot, tmp_path, url="sim://static?odr=104&seed=2", alarms=None) -> MainWindow:
    theme.apply_theme(QApplication.instance(), "dark")
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(DeviceSession(), settings, url, alarms=alarms)
    qtbot.addWidget(window)
    return window


# ---- pure geometry ----------------------------------------------------------------------------


@pytest.mark.parametrize("width,height", SIZES)
def test_first_window_takes_the_available_screen_and_never_more(width, height):
    panel = 32  # a desktop panel at the top
    available = Rect(0, panel, width, height - panel)
    assert first_window_rect(available) == available
    framed = first_window_rect(available, frame=(4, 28, 4, 4))
    assert framed == Rect(4, panel + 28, width - 8, height - panel - 32)
    assert framed.width + 8 <= width and framed.height + 32 <= height - panel


def test_status_fields_fit_most_important_first():
    # Priority order: recording 100, tare 80, calibration 120, device 200, rate 150.
    widths = [100, 0, 120, 200, 150]
    assert fields_that_fit(widths, 1000, spacing=10) == [True, False, True, True, True]
    # 100 + 10 + 120 + 10 + 200 = 440: the rate (150 more) no longer fits at 500 ...
    assert fields_that_fit(widths, 500, spacing=10) == [True, False, True, True, False]
    # ... and a narrower, less important field may take the room a wide one left.
    assert fields_that_fit([100, 300, 50], 200, spacing=10) == [True, False, True]
    assert fields_that_fit([100], 99) == [False]


def test_a_short_axis_gets_a_coarser_label_step():
    # -5 ... 180 degrees on 35 px: pyqtgraph's step of 50 puts labels 9.5 px apart; 100: 19.
    assert label_step(185.0, 50.0, 35.0, 16.5) == 100.0
    assert label_step(185.0, 50.0, 70.0, 16.5) == 50.0  # 19 px apart: unchanged
    assert label_step(1.1, 0.5, 35.0, 16.5) == 1.0  # 1 -> 2 -> 5 -> 10 times a power of ten
    assert label_step(1.1, 0.2, 35.0, 12.0) == 0.5
    assert label_step(0.2, 0.05, 35.0, 16.5) == 0.1  # 1.3, 1.4, 1.5: labels stay
    assert label_step(3e-3, 1e-3, 10.0, 12.0) == 5e-3
    assert label_step(10.0, 2.0, 0.0, 12.0) == 2.0  # no axis yet: left to pyqtgraph


def test_the_value_labels_of_a_short_plot_never_overlap(qtbot):
    from PySide6.QtGui import QFontMetricsF

    from app.gui.plots import LivePlots

    plots = LivePlots()
    qtbot.addWidget(plots)
    axis = plots.angle_plot.getAxis("left")
    line = QFontMetricsF(axis.font()).height()
    for size in (35.0, 60.0, 120.0, 400.0):
        for low, high in ((-5.0, 180.0), (-1.05, 1.05), (1.31, 1.52)):
            levels = axis.tickSpacing(low, high, size)
            gap = levels[0][0] / (high - low) * size  # between two labels, px
            assert gap >= 1.1 * line, (size, low, high, levels)
            # Still at least one label on the axis.
            assert math.floor(high / levels[0][0]) >= math.ceil(low / levels[0][0])
    # A tall plot keeps pyqtgraph's own steps (and its minor ticks).
    assert axis.tickSpacing(-5.0, 180.0, 400.0) == pg_levels(-5.0, 180.0, 400.0)


def pg_levels(low: float, high: float, size: float):
    import pyqtgraph as pg

    return pg.AxisItem("left").tickSpacing(low, high, size)


def test_the_text_check_finds_elided_cut_and_squeezed_texts(qtbot):
    host = QWidget()
    qtbot.addWidget(host)
    layout = QVBoxLayout(host)
    label = QLabel("Accelerometer bias, a long label")
    label.setMinimumWidth(1)
    elided = ElidedLabel("pipeline 0.4 % of a long status text")
    button = QPushButton("Run sensor self-test")
    button.setMinimumWidth(1)
    tabs = QTabBar()
    tabs.setElideMode(Qt.TextElideMode.ElideRight)
    for title in ("Filter", "Simulator", "Device", "Measure", "Alarms"):
        tabs.addTab(title)
    fine = QLabel("OK")
    for widget in (label, elided, button, tabs, fine):
        layout.addWidget(widget)
    host.resize(400, 200)
    host.show()
    qtbot.waitExposed(host)
    assert clipped_texts(host).problems == []
    host.setFixedWidth(90)
    QApplication.processEvents()
    report = clipped_texts(host)
    assert report.checked >= 5  # and the tab bar's scroll arrows
    flagged = "\n".join(report.problems)
    for name in ("QLabel < ", "ElidedLabel < ", "QPushButton < ", "tab 'Simulator'"):
        assert name in flagged, (name, flagged)
    assert "'OK'" not in flagged


# ---- the real window ----------------------------------------------------------------------------


def test_first_window_fills_the_screen_and_fits_it(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path)
    try:
        screen = window.screen().availableGeometry()
        # No remembered size: the whole available screen (this test screen may be smaller
        # than the window can be: then as small as it can be).
        assert window.geometry().topLeft() == screen.topLeft()
        assert window.size() == screen.size().expandedTo(window.minimumSizeHint())
        for width, height in SIZES:
            window.fit_to_screen(QRect(0, 0, width, height))
            window.show()
            qtbot.waitUntil(lambda w=width: window.width() == w, timeout=TIMEOUT_MS)
            assert window.size().width() == width and window.size().height() == height
            hint = window.minimumSizeHint()
            assert hint.width() <= width and hint.height() <= height
            # Everything of the window is on the screen: the status bar's bottom too.
            bar = window.statusBar()
            assert bar.mapTo(window, QPoint(0, bar.height())).y() <= height
        # Opening the widest and tallest docks does not make the window grow.
        for key in ("arm", "joint", "attitude3d"):
            window.docks[key].toggleViewAction().trigger()
        QApplication.processEvents()
        assert window.minimumSizeHint().height() <= 768
        assert window.minimumSizeHint().width() <= 1366
    finally:
        window.close()


def right_panels_fit(window: MainWindow) -> bool:
    return all(dock.widget().width() >= dock.widget().fitting_width()
               for dock in window.docks.values()
               if window.dockWidgetArea(dock) == Qt.DockWidgetArea.RightDockWidgetArea
               and not dock.visibleRegion().isEmpty())  # the tab in front


def walk_docks(qtbot, window: MainWindow) -> tuple[int, list[str]]:
    """Measure every dock (each raised in turn), the central view, bars and status bar, in
    the default layout at the window's size: no panel may need a sideways scroll bar."""
    checked, problems = 0, []
    window.reset_layout()
    qtbot.waitUntil(lambda: right_panels_fit(window), timeout=TIMEOUT_MS)
    for key, dock in window.docks.items():
        dock.show()
        dock.raise_()
        QApplication.processEvents()
        report = clipped_texts(dock)
        checked += report.checked
        problems.extend(report.problems)
        scroller = dock.widget()
        if isinstance(scroller, PanelScroller) and scroller.horizontalScrollBar().isVisible():
            problems.append(f"dock {key}: its panel scrolls sideways ({scroller.width()} px "
                            f"wide, needs {scroller.fitting_width()})")
    for part in (window.centralWidget(), window.device_bar, window.statusBar(),
                 window.menuBar()):
        report = clipped_texts(part)
        checked += report.checked
        problems.extend(report.problems)
    for bar in window.findChildren(QTabBar):  # those in use (Qt keeps spare ones)
        if bar.parent() is window and bar.isVisible() and not bar.visibleRegion().isEmpty():
            report = clipped_texts(bar)
            checked += report.checked
            problems.extend(report.problems)
    return checked, problems


def test_no_text_is_clipped_in_any_dock_or_dialog_at_either_size_in_any_theme(
    qtbot, tmp_path, capsys
):
    window = open_window(qtbot, tmp_path)
    counts: dict[tuple[str, str], int] = {}
    problems: list[str] = []
    dialogs = []
    with qt_messages() as warnings:
        try:
            window.show()
            qtbot.waitUntil(lambda: window.session.device_info is not None, timeout=TIMEOUT_MS)
            qtbot.waitUntil(lambda: "samples" in window.status_rate.text(), timeout=TIMEOUT_MS)
            dialogs = [window.show_shortcut_sheet(), window.show_about(),
                       window.show_user_guide(), window.open_calibration_wizard(),
                       window.open_allan_page(), window.files.export_recording()]
            for name in THEMES:
                window.set_theme(name)
                for width, height in SIZES:
                    window.fit_to_screen(QRect(0, 0, width, height))
                    qtbot.waitUntil(lambda w=width: window.width() == w, timeout=TIMEOUT_MS)
                    QApplication.processEvents()  # the docks take the new size
                    checked, found = walk_docks(qtbot, window)
                    for dialog in dialogs:
                        dialog.show()
                        report = clipped_texts(dialog)
                        checked += report.checked
                        found.extend(report.problems)
                    counts[(f"{width}x{height}", name)] = checked
                    problems.extend(f"{width}x{height} {name}: {p}" for p in found)
        finally:
            for dialog in dialogs:
                dialog.reject() if hasattr(dialog, "reject") else dialog.close()
            window.close()
    with capsys.disabled():
        print("\nclipped-text check, widgets measured:", file=sys.stderr)
        for (size, name), checked in counts.items():
            print(f"  {size:>9} {name:<13} {checked}", file=sys.stderr)
    known = [p for p in problems if any(key in p for key in KNOWN_CLIPPING)]
    failing = sorted(set(problems) - set(known))
    assert all(count > 100 for count in counts.values()), counts
    assert not failing, "\n".join(failing[:40])
    assert not warnings, warnings


def test_no_text_is_clipped_on_the_bars_of_a_replay(qtbot, tmp_path):
    recording = sample_recordings()[0]
    window = open_window(qtbot, tmp_path, url=replay_url(str(recording)))
    problems: list[str] = []
    checked = 0
    with qt_messages() as warnings:
        try:
            window.show()
            qtbot.waitUntil(window.replay_bar.isVisible, timeout=TIMEOUT_MS)
            qtbot.waitUntil(lambda: "samples" in window.status_rate.text(), timeout=TIMEOUT_MS)
            for name in THEMES:
                window.set_theme(name)
                for width, height in SIZES:
                    window.fit_to_screen(QRect(0, 0, width, height))
                    qtbot.waitUntil(lambda w=width: window.width() == w, timeout=TIMEOUT_MS)
                    QApplication.processEvents()
                    for bar in (window.replay_bar, window.device_bar, window.statusBar()):
                        report = clipped_texts(bar)
                        checked += report.checked
                        problems.extend(f"{width}x{height} {name}: {p}" for p in report.problems)
        finally:
            window.close()
    known = [p for p in problems if any(key in p for key in KNOWN_CLIPPING)]
    assert checked > 6 * 10
    assert not sorted(set(problems) - set(known)), "\n".join(problems[:20])
    assert not warnings, warnings


def test_docks_tabs_are_whole_an_opened_dock_is_raised_and_the_layout_resets(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path)
    try:
        window.fit_to_screen(QRect(0, 0, 1366, 768))
        window.show()
        qtbot.waitUntil(window.docks["filter"].isVisible, timeout=TIMEOUT_MS)
        for key in ("attitude3d", "arm", "joint"):
            dock = window.docks[key]
            dock.toggleViewAction().trigger()  # View ▸ 3D view, as a user does
            QApplication.processEvents()
            assert dock.isVisible() and not dock.visibleRegion().isEmpty(), key
        bars = [bar for bar in window.findChildren(QTabBar) if bar.parent() is window]
        assert bars
        for bar in bars:
            assert bar.elideMode() == Qt.TextElideMode.ElideNone and bar.usesScrollButtons()
        # Every dock can still be reached: its tab is in a bar (the bars scroll).
        titles = {bar.tabText(i) for bar in bars for i in range(bar.count())}
        assert {"Alarms", "Filter", "Arm", "3D view", "Live plots"} <= titles
        window.docks["filter"].setFloating(True)
        window.reset_layout()
        QApplication.processEvents()
        assert not window.docks["filter"].isFloating()
        assert not window.docks["arm"].isVisible() and window.docks["filter"].isVisible()
        assert window.dockWidgetArea(window.docks["alarms"]) == (
            Qt.DockWidgetArea.RightDockWidgetArea)
    finally:
        window.close()


def test_status_fields_are_hidden_least_important_first_never_elided(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path)
    try:
        window.resize(1366, 768)
        window.show()
        qtbot.waitUntil(lambda: "samples" in window.status_rate.text(), timeout=TIMEOUT_MS)
        fields = window.status_fields.fields
        for width in (1366, 900, 640):
            window.resize(width, 600)
            QApplication.processEvents()
            shown = [not field.isHidden() for field in fields if field.text()]
            assert all(not field.isElided() for field in fields if not field.isHidden())
            # Shown fields are a prefix of the priority order, except a narrower later one.
            assert window.status_calibration.isVisible() or not any(shown[3:])
            lights = window.health_lights.geometry()
            assert window.statusBar().rect().contains(lights)
        assert window.status_rate.isHidden()  # the least important goes first
        assert window.status_rate.text() in window.statusBar().toolTip()
        assert not window.status_calibration.isHidden()
    finally:
        window.close()


def field_scroll_area(widget) -> QScrollArea:
    parent = widget.parentWidget()
    while not isinstance(parent, QScrollArea):
        parent = parent.parentWidget()
    return parent


def wheel(widget, steps: int = -3) -> None:
    centre = QPointF(widget.width() / 2, widget.height() / 2)
    event = QWheelEvent(
        centre, QPointF(widget.mapToGlobal(centre.toPoint())), QPoint(0, 0),
        QPoint(0, 120 * steps), Qt.MouseButton.NoButton, Qt.KeyboardModifier.NoModifier,
        Qt.ScrollPhase.NoScrollPhase, False)
    QApplication.sendEvent(widget, event)


def test_the_wheel_scrolls_panels_and_never_changes_an_unfocused_field(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path, url="sim://interactive?odr=104")
    try:
        window.resize(1366, 600)
        window.show()
        qtbot.waitUntil(window.simulator_panel.roll_slider.isEnabled, timeout=TIMEOUT_MS)
        panel = window.filter_panel
        window.docks["filter"].raise_()
        QApplication.processEvents()
        spins = [w for w in panel.findChildren(QAbstractSpinBox) if w.isVisible()]
        assert spins
        spin = spins[0]
        assert spin.focusPolicy() == Qt.FocusPolicy.StrongFocus  # the wheel never focuses it
        scroller = field_scroll_area(spin).verticalScrollBar()
        assert scroller.maximum() > 0  # the Filter dock is taller than 600 px: it scrolls
        before, scrolled = spin.value(), scroller.value()
        wheel(spin, -3)
        assert spin.value() == before
        assert scroller.value() > scrolled  # the panel scrolled instead
        window.docks["simulator"].raise_()
        QApplication.processEvents()
        slider: QAbstractSlider = window.simulator_panel.roll_slider
        combo = window.simulator_panel.odr_combo
        for field, read in ((slider, slider.value), (combo, combo.currentIndex)):
            before = read()
            wheel(field, -2)
            wheel(field, 2)
            wheel(field, 1)
            assert read() == before, field
        # A field the user clicked into takes the wheel, as usual.
        spin.setFocus()
        qtbot.waitUntil(spin.hasFocus, timeout=TIMEOUT_MS)
        before = spin.value()
        wheel(spin, 1)
        assert spin.value() != before
    finally:
        window.close()


def test_a_field_made_later_in_another_theme_is_guarded_too(qtbot, qapp):
    """The guard comes with the style's polish: a dialog's field made after a theme change
    (a new style sheet) takes no wheel until focused, and scrolls its panel instead."""
    from app.gui import wheel_guard

    wheel_guard.install(qapp)
    try:
        theme.apply_theme(qapp, "light")
        area = QScrollArea()
        qtbot.addWidget(area)
        inner = QWidget()
        inner.setMinimumHeight(2000)
        spin = QSpinBox(inner)
        spin.setRange(0, 100)
        spin.setValue(50)
        area.setWidget(inner)
        area.resize(200, 200)
        area.show()
        qtbot.waitExposed(area)
        assert spin.focusPolicy() == Qt.FocusPolicy.StrongFocus
        wheel(spin, -3)
        assert spin.value() == 50 and area.verticalScrollBar().value() > 0
    finally:
        theme.apply_theme(qapp)


def test_keys_work_from_the_start_focus_is_on_the_instrument(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path, url="sim://interactive?odr=104")
    try:
        window.resize(1366, 768)
        window.show()
        window.activateWindow()
        qtbot.waitUntil(lambda: window.session.device_info is not None, timeout=TIMEOUT_MS)
        qtbot.waitUntil(lambda: QApplication.focusWidget() is window.level, timeout=TIMEOUT_MS)
        url = window.device_bar.current_url()
        qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_H)
        assert window.hold_button.isChecked()
        assert window.device_bar.current_url() == url  # no "h" typed into the URL
        qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_H)
        assert not window.hold_button.isChecked()
        qtbot.waitUntil(window.readouts.isValid, timeout=TIMEOUT_MS)
        rows = len(window.log_panel.log)
        qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_Space)
        assert len(window.log_panel.log) == rows + 1
        qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_Return)
        assert window.session.device_info is not None  # Enter does not disconnect
    finally:
        window.close()


def test_every_shortcut_is_in_a_menu_and_on_the_help_sheet(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path)
    try:
        in_menus = help_dialogs.menu_shortcuts(window.menuBar())
        menu_actions = {entry.action for entry in in_menus}
        listed = {(entry.action, entry.keys) for entry in in_menus}
        actions = help_dialogs.window_shortcut_actions(window)
        assert len(actions) >= 9
        for action in actions:
            keys = action.shortcut().toString(action.shortcut().SequenceFormat.NativeText)
            assert any(name == help_dialogs._plain(action.text()) and keys in shown
                       for name, shown in listed), action.text()
        sheet = window.show_shortcut_sheet()
        keys = sheet.keys()
        for key in ("H", "Space", "Ctrl+C", "Ctrl+T", "F11", "Esc", "Ctrl+R", "Ctrl+O", "F1"):
            assert key in keys, (key, keys)
        assert {"Hold readouts", "Store reading", "Copy reading"} <= menu_actions
        texts = [sheet.table.item(r, 2).text() for r in range(sheet.table.rowCount())]
        assert "Edit" in texts and "View" in texts
    finally:
        window.close()


def test_about_lists_versions_and_the_files_paths(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path)
    try:
        dialog = window.show_about()
        text = dialog.findChild(help_dialogs.QTextBrowser).toPlainText()
        for name, version in help_dialogs.versions().items():
            assert name in text and version in text
        paths = window.file_paths()
        assert paths["Settings"] == str(tmp_path / "settings.ini")
        for value in paths.values():
            assert value in text
        guide = window.show_user_guide().findChild(help_dialogs.QTextBrowser).toPlainText()
        assert "Bubble level" in guide and "Reset layout" in guide
    finally:
        window.close()


def test_file_dialogs_start_in_the_last_folder_chosen(qtbot, tmp_path, monkeypatch):
    settings = QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat)
    file_dialogs.use_settings(settings)
    starts: list[str] = []
    folder = tmp_path / "elsewhere"
    folder.mkdir()

    def fake_open(_parent, _caption, start, _filter):
        starts.append(start)
        return str(folder / "a.csv"), _filter

    def fake_save(_parent, _caption, start, _filter):
        starts.append(start)
        return start, _filter

    monkeypatch.setattr(file_dialogs.QFileDialog, "getOpenFileName", fake_open)
    monkeypatch.setattr(file_dialogs.QFileDialog, "getSaveFileName", fake_save)
    try:
        recordings = tmp_path / "recordings"
        recordings.mkdir()
        assert file_dialogs.open_file_name(None, "Open", "*.csv", recordings).endswith("a.csv")
        assert starts[-1] == str(recordings)  # nothing chosen yet: the fallback
        path, _ = file_dialogs.save_file_name(None, "Export", "plots.png", "*.png")
        assert starts[-1] == str(folder / "plots.png")  # the folder of the last file
        assert Path(path).parent == folder
        assert settings.value(file_dialogs.LAST_FOLDER_KEY) == str(folder)
        folder.rmdir() if not any(folder.iterdir()) else None
        file_dialogs.save_file_name(None, "Export", "x.png", "*.png")
        assert starts[-1] == str(Path.home() / "x.png")  # a vanished folder: home, not cwd
    finally:
        file_dialogs.use_settings(None)


def test_alarm_option_starts_the_window_with_those_alarms(qtbot, tmp_path, monkeypatch, capsys):
    started = {}
    monkeypatch.setattr("app.gui.application.run_gui",
                        lambda device, name, alarms: started.update(alarms=alarms) or 0)
    assert launcher.main(["--alarm", "tilt>2.0,hyst=0.2,delay=0.5", "--alarm", "|roll|>1"]) == 0
    assert started["alarms"] == alarms_from_specs(["tilt>2.0,hyst=0.2,delay=0.5", "|roll|>1"])
    assert launcher.main(["--alarm", "tilt>>2"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("inclinometer: --alarm:") and error.count("\n") == 1
    window = open_window(qtbot, tmp_path, alarms=started["alarms"])
    try:
        shown = [limit for limit in window.alarm_panel.config().limits if limit.enabled]
        assert shown == list(started["alarms"].limits)
    finally:
        window.close()


def test_dock_panels_scroll_rather_than_grow_the_window(qtbot, tmp_path):
    window = open_window(qtbot, tmp_path)
    try:
        for key in ("arm", "joint", "filter", "alarms"):
            assert isinstance(window.docks[key].widget(), QScrollArea), key
        assert isinstance(window.docks["arm"], QDockWidget)
    finally:
        window.close()


def test_a_reserved_figure_keeps_its_room_when_the_theme_enlarges_the_font(qtbot):
    """The status bar's fps figure is never cut: its room follows the font, not the pixels of
    the first theme (a larger status font once elided '17 fps')."""
    label = ElidedLabel()
    qtbot.addWidget(label)
    label.reserve("999 fps")
    small = label.minimumSizeHint().width()
    font = label.font()
    font.setPointSizeF(font.pointSizeF() * 2)
    label.setFont(font)
    label.setText("17 fps")
    assert label.minimumSizeHint().width() > 1.8 * small
    label.resize(label.minimumSizeHint())
    label.show()
    assert not label.isElided()
