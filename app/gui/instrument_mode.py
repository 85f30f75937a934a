"""The full-screen instrument (F11): the bubble and big digits only, readable across a room.

Leaving (F11 or Esc) brings back the layout exactly as it was: the docks, the window's size
and state, and which bars were shown.
"""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Qt

from app.gui.level_view import (
    INSTRUMENT_MAX_PX,
    LEVEL_SHARE,
    READOUT_MAX_PX,
    READOUT_MIN_PX,
    SIDE_SHARE,
)

MainWindow = Any
"""The window this part works for (not imported: the parts sit below
:mod:`app.gui.main_window`, which assembles them)."""


class InstrumentMode:
    """Enters and leaves the full-screen instrument for ``window``."""

    def __init__(self, window: MainWindow) -> None:
        self.window = window
        self.active = False
        self.saved: dict[str, Any] | None = None
        """The usual layout while in the instrument (None outside)."""

    def set(self, enabled: bool) -> None:
        """Enter (True) or leave (False); nothing when already so."""
        if enabled == self.active:
            return
        self.active = enabled
        window = self.window
        window.instrument_action.setChecked(enabled)
        window.leave_instrument_action.setEnabled(enabled)
        if enabled:
            self._enter()
        else:
            self._leave()

    def _chrome(self) -> tuple:
        window = self.window
        return (window.menuBar(), window.statusBar(), window.level_view.controls,
                window.truth_label, window.banner)

    def _enter(self) -> None:
        window = self.window
        self.saved = {
            "state": window.saveState(),
            "geometry": window.saveGeometry(),
            "window_state": window.windowState(),
            "visible": [widget for widget in self._chrome() if widget.isVisible()],
        }
        for widget in (*window.docks.values(), window.device_bar, window.replay_bar,
                       *self._chrome()):
            widget.hide()
        window.readouts.setAutoScale(True, INSTRUMENT_MAX_PX, READOUT_MIN_PX, (1, 2))
        window.level_view.set_level_share(1, 1, compass=0)  # the bubble and the digits only
        window.showFullScreen()

    def _leave(self) -> None:
        window = self.window
        saved = self.saved or {}
        self.saved = None
        window.readouts.setAutoScale(True, READOUT_MAX_PX, READOUT_MIN_PX, (2, 1))
        window.level_view.set_level_share(LEVEL_SHARE, SIDE_SHARE)
        window_state = saved.get("window_state", Qt.WindowState.WindowNoState)
        if window_state & Qt.WindowState.WindowFullScreen:
            window.showFullScreen()
        elif window_state & Qt.WindowState.WindowMaximized:
            window.showMaximized()
        else:
            window.showNormal()
        if "geometry" in saved:
            window.restoreGeometry(saved["geometry"])
        for widget in saved.get("visible", ()):
            widget.show()
        if "state" in saved:
            window.restoreState(saved["state"])
