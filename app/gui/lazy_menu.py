"""A pyqtgraph view box that builds its right-click menu when it is first asked for.

pyqtgraph builds each view box's menu (``ViewBoxMenu``: axis ranges, mouse mode, export, two
designer forms) in its constructor. The window holds nine plots and a user opens their menus
rarely: those menus were an eighth of the time it took to build the window.
"""

from __future__ import annotations

from typing import Any

import pyqtgraph as pg


class LazyMenuViewBox(pg.ViewBox):
    """A :class:`pyqtgraph.ViewBox` whose menu is built on the first right click (or the
    first request for its actions); everything else is pyqtgraph's own."""

    def __init__(self, *args: Any, enableMenu: bool = True, **kwargs: Any) -> None:
        super().__init__(*args, enableMenu=False, **kwargs)
        self.state["enableMenu"] = enableMenu

    def _built_menu(self) -> None:
        if self.menu is None and self.menuEnabled():
            self._applyMenuEnabled()  # pyqtgraph's own way to make it (and its view list)

    def getMenu(self, ev: Any) -> Any:
        self._built_menu()
        return super().getMenu(ev)

    def getContextMenus(self, event: Any) -> list:
        self._built_menu()
        return super().getContextMenus(event)


def lazy_menu_plot(**kwargs: Any) -> pg.PlotItem:
    """A :class:`pyqtgraph.PlotItem` on a :class:`LazyMenuViewBox`."""
    return pg.PlotItem(viewBox=LazyMenuViewBox(), **kwargs)
