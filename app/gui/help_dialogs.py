"""Help: a short user guide, the sheet of keyboard shortcuts and About (versions and paths).

The shortcut sheet is read from the menus, so a shortcut is listed there exactly when it is
in a menu; keys that only a focused table takes (the measurement log's) are added by hand.
"""

from __future__ import annotations

import html
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy
import PySide6
from PySide6.QtCore import qVersion
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QHeaderView,
    QMainWindow,
    QMenu,
    QMenuBar,
    QTableWidget,
    QTableWidgetItem,
    QTextBrowser,
    QVBoxLayout,
    QWidget,
)

from app import __version__


@dataclass(frozen=True)
class ShortcutEntry:
    """One key and what it does, with where to find it."""

    keys: str
    action: str
    where: str


def focused_table_keys() -> list[ShortcutEntry]:
    """Keys that the measurement log's table takes while it has the focus."""
    copy = QKeySequence(QKeySequence.StandardKey.Copy).toString(
        QKeySequence.SequenceFormat.NativeText)
    where = "Measurement log (table focused)"
    return [
        ShortcutEntry("Delete", "Delete the selected stored readings", where),
        ShortcutEntry(copy, "Copy the selected stored readings (tab-separated)", where),
    ]


def _plain(title: str) -> str:
    """A menu title without its mnemonic ampersand and trailing ellipsis."""
    return title.replace("&&", "\0").replace("&", "").replace("\0", "&").rstrip("…").strip()


def menu_shortcuts(menu_bar: QMenuBar) -> list[ShortcutEntry]:
    """Every action with a shortcut in the menus, as (keys, action, menu path)."""

    def walk(menu: QMenu, path: str) -> Iterator[ShortcutEntry]:
        for action in menu.actions():
            sub = action.menu()
            if isinstance(sub, QMenu):
                yield from walk(sub, f"{path} ▸ {_plain(action.text())}")
                continue
            keys = ", ".join(
                sequence.toString(QKeySequence.SequenceFormat.NativeText)
                for sequence in action.shortcuts() if not sequence.isEmpty()
            )
            if keys:
                yield ShortcutEntry(keys, _plain(action.text()), path)

    entries: list[ShortcutEntry] = []
    for action in menu_bar.actions():
        menu = action.menu()
        if isinstance(menu, QMenu):
            entries.extend(walk(menu, _plain(action.text())))
    return entries


def all_shortcuts(menu_bar: QMenuBar) -> list[ShortcutEntry]:
    """The shortcut sheet's rows: the menus' shortcuts, then the focused table's keys."""
    return [*menu_shortcuts(menu_bar), *focused_table_keys()]


def window_shortcut_actions(window: QWidget) -> list[QAction]:
    """Every action of ``window`` (and its children) that has a shortcut."""
    return [action for action in window.findChildren(QAction) if not action.shortcut().isEmpty()]


def _dialog(parent: QWidget | None, title: str, body: QWidget, name: str) -> QDialog:
    dialog = QDialog(parent)
    dialog.setObjectName(name)
    dialog.setWindowTitle(title)
    layout = QVBoxLayout(dialog)
    layout.addWidget(body, 1)
    buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close)
    buttons.rejected.connect(dialog.reject)
    layout.addWidget(buttons)
    return dialog


class ShortcutSheet(QDialog):
    """The table of keyboard shortcuts (Help ▸ Keyboard shortcuts)."""

    def __init__(self, menu_bar: QMenuBar, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("shortcutSheet")
        self.setWindowTitle("Keyboard shortcuts")
        self.entries = all_shortcuts(menu_bar)
        self.table = QTableWidget(len(self.entries), 3)
        self.table.setHorizontalHeaderLabels(["Key", "Does", "Menu"])
        self.table.verticalHeader().hide()
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.table.setSelectionMode(QTableWidget.SelectionMode.NoSelection)
        self.table.setWordWrap(False)
        for row, entry in enumerate(self.entries):
            for column, text in enumerate((entry.keys, entry.action, entry.where)):
                self.table.setItem(row, column, QTableWidgetItem(text))
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        self.table.resizeColumnsToContents()
        layout = QVBoxLayout(self)
        layout.addWidget(self.table, 1)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close)
        buttons.rejected.connect(self.reject)
        layout.addWidget(buttons)
        width = sum(self.table.columnWidth(c) for c in range(3)) + 60
        height = self.table.verticalHeader().length() + header.height() + 90
        self.resize(max(520, width), min(640, height))

    def keys(self) -> list[str]:
        """The keys listed, in order."""
        return [entry.keys for entry in self.entries]


GUIDE_HTML = """
<h2>The first minutes</h2>
<p>The window opens on the simulated sensor (<code>sim://interactive</code>) lying almost level.
Tilt it with the sliders of the <b>Simulator</b> dock, or choose another device in the
device bar at the top and press <b>Connect</b>.</p>
<h3>What you see</h3>
<ul>
<li><b>Bubble level</b> (centre): the bubble moves toward the raised side; green within the
level tolerance, red and pinned to the rim beyond the chosen range (±0.5° to ±90°).</li>
<li><b>Readouts</b>: roll, pitch, total tilt from vertical and the direction of the raised
side, to 0.01, in degrees, % grade, mm/m, in/ft or 1:n, averaged over 0.05-5 s (the combo
boxes under the digits). <b>Hold</b> (H) freezes them; <b>Ctrl+C</b> copies the reading.</li>
<li><b>Live plots</b> (bottom): acceleration, angular rate and angles over the last 2-60 s.
Tick <i>Select range</i> and drag on the angle plot for statistics of a time range.</li>
<li><b>Docks</b>: <i>Filter</i>, <i>Simulator</i>, <i>Device</i>, <i>Measure</i> and
<i>Alarms</i> at the right; <i>Live plots</i>, <i>Messages</i>, <i>Measurement log</i>,
<i>3D view</i>, <i>Arm</i> and <i>Joint</i> at the bottom. Open one from the <b>View</b>
menu (it comes to the front); <b>View ▸ Reset layout</b> puts every dock back.</li>
<li><b>Status bar</b>: device and rate, filter, calibration, tare, recording, the sensor's
health lights (click to reset latched faults) and the display's frame rate. Fields that do
not fit are hidden, least important first; hover the status bar to read them.</li>
</ul>
<h3>Measuring</h3>
<ul>
<li><b>Space</b> stores the current reading in the <i>Measurement log</i> (with its spread
over the averaging time); export it as CSV from the dock.</li>
<li><b>Ctrl+T</b> (<i>Calibration ▸ Tare</i>) takes the current attitude as level.</li>
<li><b>Alarms</b>: limits on tilt, roll, pitch or out of level, with hysteresis and delay;
the digits, the bubble and a banner turn red while one is raised. From the command line:
<code>inclinometer --alarm "tilt&gt;2,delay=0.5"</code>.</li>
<li><b>Calibration ▸ Calibration wizard</b>: the six-face tour for a real sensor.</li>
<li><b>File ▸ Record</b> (Ctrl+R) records the stream; <b>File ▸ Open recording</b> (Ctrl+O)
replays one through the whole pipeline.</li>
</ul>
<h3>Keys and mouse</h3>
<p>The keys work as soon as the window opens (the instrument has the focus, not the device
field). <b>F11</b> shows the full-screen instrument; F11 or Esc leaves it. The mouse wheel
scrolls the docks; it changes a field only after you click into it.
<b>Help ▸ Keyboard shortcuts</b> lists every key.</p>
"""


def user_guide(parent: QWidget | None = None) -> QDialog:
    """The short user guide (Help ▸ User guide)."""
    browser = QTextBrowser()
    browser.setOpenExternalLinks(True)
    browser.setHtml(GUIDE_HTML)
    dialog = _dialog(parent, "Inclinometer user guide", browser, "userGuide")
    dialog.resize(640, 560)
    return dialog


def versions() -> dict[str, str]:
    """The versions that matter in a bug report."""
    return {
        "Inclinometer": __version__,
        "Qt": qVersion(),
        "PySide6": PySide6.__version__,
        "numpy": numpy.__version__,
        "Python": sys.version.split()[0],
    }


def about_html(paths: dict[str, str]) -> str:
    """About's text: the versions and the paths of what the app keeps."""
    rows = "".join(f"<tr><td>{html.escape(k)}&nbsp;&nbsp;</td><td>{html.escape(v)}</td></tr>"
                   for k, v in versions().items())
    places = "".join(
        f"<tr><td>{html.escape(k)}&nbsp;&nbsp;</td><td><code>{html.escape(v)}</code></td></tr>"
        for k, v in paths.items())
    return (f"<h3>Inclinometer {html.escape(__version__)}</h3>"
            "<p>LSM6DSOX tilt meter and IMU workbench.</p>"
            f"<p><b>Versions</b></p><table>{rows}</table>"
            f"<p><b>Files</b></p><table>{places}</table>")


def about_dialog(paths: dict[str, str], parent: QWidget | None = None) -> QDialog:
    """Help ▸ About: versions (app, Qt, PySide6, numpy, Python) and where files are kept."""
    browser = QTextBrowser()
    browser.setObjectName("aboutText")
    browser.setHtml(about_html(paths))
    browser.setLineWrapMode(QTextBrowser.LineWrapMode.NoWrap)
    dialog = _dialog(parent, "About Inclinometer", browser, "aboutDialog")
    document = browser.document()
    document.adjustSize()
    width = int(document.idealWidth()) + 60
    dialog.resize(max(480, width), int(document.size().height()) + 110)
    return dialog


class HelpWindows:
    """Help's dialogs for ``window``: each made once, then brought to the front (About is
    made afresh: the paths it lists may have changed)."""

    def __init__(self, window: QMainWindow, file_paths: Callable[[], dict[str, str]]) -> None:
        self.window = window
        self.file_paths = file_paths
        self.dialogs: dict[str, QDialog] = {}

    def show(self, name: str, build: Callable[[], QDialog]) -> QDialog:
        dialog = self.dialogs.get(name)
        if dialog is None:
            dialog = build()
            self.dialogs[name] = dialog
        dialog.show()
        dialog.raise_()
        return dialog

    def user_guide(self) -> QDialog:
        return self.show("guide", lambda: user_guide(self.window))

    def shortcut_sheet(self) -> QDialog:
        return self.show("shortcuts", lambda: ShortcutSheet(self.window.menuBar(), self.window))

    def about(self) -> QDialog:
        old = self.dialogs.pop("about", None)
        if old is not None:
            old.close()
            old.deleteLater()
        return self.show("about", lambda: about_dialog(self.file_paths(), self.window))
