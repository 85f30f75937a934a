"""The window's docks: which there are, where they start, how they are tabbed, and the
layout's upkeep (whole tab titles, View ▸ Reset layout, the first start's sizes)."""

from __future__ import annotations

from dataclasses import dataclass

from PySide6.QtCore import QByteArray, Qt, QTimer
from PySide6.QtGui import QAction
from PySide6.QtWidgets import QDockWidget, QMainWindow, QTabBar, QWidget

from app.gui.panel_scroller import PanelScroller

RIGHT = Qt.DockWidgetArea.RightDockWidgetArea
BOTTOM = Qt.DockWidgetArea.BottomDockWidgetArea


@dataclass(frozen=True)
class DockSpec:
    key: str
    title: str
    area: Qt.DockWidgetArea
    fills: bool = False
    """Its contents fill any size (the others scroll inside their dock)."""
    hidden: bool = False
    """Closed at the first start (opened from the View menu, then in its tab group)."""


DOCKS = (
    DockSpec("plots", "Live plots", BOTTOM, fills=True),
    DockSpec("filter", "Filter", RIGHT),
    DockSpec("simulator", "Simulator", RIGHT),
    DockSpec("device", "Device", RIGHT),
    DockSpec("measure", "Measure", RIGHT),
    # The 3D view and the arm want width: they join the wide bottom group, which keeps the
    # right group to five short titles.
    DockSpec("attitude3d", "3D view", BOTTOM, fills=True, hidden=True),
    DockSpec("arm", "Arm", BOTTOM, hidden=True),
    DockSpec("messages", "Messages", BOTTOM, fills=True),
    DockSpec("alarms", "Alarms", RIGHT),
    DockSpec("log", "Measurement log", BOTTOM),
    DockSpec("joint", "Joint", BOTTOM, hidden=True),
    # Shown while a source delivers a magnetic field (the field presenter opens and closes it).
    DockSpec("field", "Magnetic field", BOTTOM, fills=True, hidden=True),
)
"""The docks in the order they are made (and listed in the View menu)."""
TABS = (("filter", "simulator"), ("simulator", "device"), ("device", "measure"),
        ("plots", "messages"), ("measure", "alarms"), ("messages", "log"),
        ("plots", "joint"), ("joint", "attitude3d"), ("attitude3d", "arm"), ("plots", "field"))
"""Tab groups, as Qt's ``tabifyDockWidget(first, second)`` calls in order."""
IN_FRONT = ("plots", "filter")
"""The tabs in front of their groups at the start and after Reset layout."""


class DockLayout:
    """Makes ``window``'s docks from :data:`DOCKS` and keeps their layout tidy.

    Two steps, so that each panel is made where it stays: the docks (with a scroller for
    each panel that scrolls) first; then :meth:`fill` with the panels, made with
    :meth:`home` as their parent. Under the app's style sheet Qt polishes every widget of a
    polished tree again each time the tree moves to another parent."""

    def __init__(self, window: QMainWindow) -> None:
        self.window = window
        self.docks: dict[str, QDockWidget] = {}
        self._scrollers: dict[str, PanelScroller] = {}
        for spec in DOCKS:
            self._add(spec)

    def home(self, key: str) -> QWidget:
        """The parent to make dock ``key``'s contents with."""
        scroller = self._scrollers.get(key)
        return scroller.viewport() if scroller is not None else self.docks[key]

    def fill(self, contents: dict[str, QWidget]) -> None:
        """Put each dock's contents in, then tab, hide and raise the docks as at a first
        start (:attr:`default_state`)."""
        window = self.window
        for spec in DOCKS:
            scroller = self._scrollers.get(spec.key)
            if scroller is not None:
                scroller.set_panel(contents[spec.key])
            else:
                self.docks[spec.key].setWidget(contents[spec.key])
        for first, second in TABS:
            window.tabifyDockWidget(self.docks[first], self.docks[second])
        for spec in DOCKS:
            if spec.hidden:
                self.docks[spec.key].hide()
        self._raise_front()
        self.default_state: QByteArray = window.saveState()
        """The docks as first built, for View ▸ Reset layout."""

    def _add(self, spec: DockSpec) -> None:
        window = self.window
        dock = QDockWidget(spec.title, window)
        dock.setObjectName(f"dock-{spec.key}")
        if not spec.fills:
            # Panels scroll rather than forcing their full size on the window (the Arm panel
            # alone wants 812 px of height, the Joint panel 1079 px of width): the window
            # fits a 1366x768 screen whatever is open, and a narrow dock cuts nothing off.
            right = spec.area == RIGHT
            scroller = PanelScroller(keeps_width=right, parent=dock)
            if right:
                scroller.wantsWidth.connect(lambda width, d=dock: window.resizeDocks(
                    [d], [width], Qt.Orientation.Horizontal))
            dock.setWidget(scroller)
            self._scrollers[spec.key] = scroller
        window.addDockWidget(spec.area, dock)
        self.docks[spec.key] = dock
        # Opened from the View menu: in front of its tab group, not behind another tab.
        dock.toggleViewAction().triggered.connect(
            lambda checked, d=dock: checked and self.raise_dock(d))
        dock.dockLocationChanged.connect(lambda _area: self.tidy_tab_bars())
        dock.topLevelChanged.connect(lambda _floating: self.tidy_tab_bars())

    def _raise_front(self) -> None:
        for key in IN_FRONT:
            self.docks[key].raise_()

    def toggle_actions(self) -> list[QAction]:
        """The docks' show/hide actions (the View menu)."""
        return [dock.toggleViewAction() for dock in self.docks.values()]

    def raise_dock(self, dock: QDockWidget) -> None:
        """Show ``dock`` in front of its tab group."""
        dock.show()
        dock.raise_()
        self.tidy_tab_bars()

    def tidy_tab_bars(self) -> None:
        """The docks' tab bars show whole titles and scroll (arrows) when they do not fit.
        Qt makes these bars as docks are tabbed, so this runs after every change."""
        for bar in self.window.findChildren(QTabBar):
            if bar.parent() is not self.window:  # only the main window's dock tab bars
                continue
            if bar.elideMode() != Qt.TextElideMode.ElideNone:
                bar.setElideMode(Qt.TextElideMode.ElideNone)
            if not bar.usesScrollButtons():
                bar.setUsesScrollButtons(True)

    def reset(self) -> None:
        """Every dock where and as large as at the first start (the caller leaves the
        full-screen instrument first)."""
        for dock in self.docks.values():
            dock.setFloating(False)
        self.window.restoreState(self.default_state)
        self._raise_front()
        self.tidy_tab_bars()
        # Dock sizes stick only once the restored layout is in place (as at the first show).
        QTimer.singleShot(0, self.window, self.apply_default_sizes)

    def apply_default_sizes(self) -> None:
        """The first start's dock sizes, for the window's size now."""
        window = self.window
        height = max(300, int(window.height() * 0.45))
        # The panels take at most a third of a narrow window (1024 px: the level keeps room),
        # but never so little that they scroll sideways.
        fitting = max((dock.widget().fitting_width() for dock in self.docks.values()
                       if isinstance(dock.widget(), PanelScroller)
                       and window.dockWidgetArea(dock) == RIGHT), default=0)
        width = max(min(400, int(window.width() * 0.3)), fitting)
        window.resizeDocks([self.docks["filter"]], [width], Qt.Orientation.Horizontal)
        window.resizeDocks([self.docks["plots"]], [height], Qt.Orientation.Vertical)

    def width_changed(self, old: int, new: int) -> None:
        """The window's width changed: panels' minimum widths change at a threshold."""
        threshold = PanelScroller.KEEP_WIDTH_FROM_PX
        if (old >= threshold) != (new >= threshold):
            for dock in self.docks.values():
                dock.widget().updateGeometry()
