"""What the main window remembers, under which keys, read and written through
:class:`~app.gui.user_settings.SettingsSections` (the keys are those the window always used,
so a user's settings load as before); and the window's size on a screen it must fit."""

from __future__ import annotations

from PySide6.QtCore import QByteArray, QRect
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QComboBox, QMainWindow, QWidget

from app.core.filters import FILTERS, ONLINE_FILTERS
from app.core.screen_fit import Rect, first_window_rect
from app.gui import theme
from app.gui.user_settings import SettingsSections
from app.services.devices import DEFAULT_DEVICE_URL

DISPLAY_DEFAULTS: dict[str, str | float] = {"unit": "deg", "averaging_s": 0.5, "range_deg": 5.0}
"""The display controls' keys and defaults."""
PLOT_WINDOW_DEFAULT_S = 10


class WindowSettings:
    """The window's own keys: geometry and docks, display, filter, device, theme."""

    def __init__(self, sections: SettingsSections) -> None:
        self.sections = sections

    # -- window and docks -----------------------------------------------------------------------
    def has_layout(self) -> tuple[bool, bool]:
        """Whether a geometry and a dock state are remembered."""
        return self.sections.has("geometry"), self.sections.has("window_state")

    def geometry(self) -> QByteArray | None:
        return self.sections.value("geometry")

    def dock_state(self) -> QByteArray | None:
        return self.sections.value("window_state")

    def save_layout(self, geometry: QByteArray, state: QByteArray) -> None:
        self.sections.set_value("geometry", geometry)
        self.sections.set_value("window_state", state)

    def restore_layout(self, window: QMainWindow) -> None:
        """The remembered size and docks (a size that cannot be restored: the screen's)."""
        geometry = self.geometry()
        if geometry is None or not window.restoreGeometry(geometry):
            fit_to_screen(window)
        state = self.dock_state()
        if state is not None:
            window.restoreState(state)

    # -- display --------------------------------------------------------------------------------
    def restore_display(self, view) -> list[QComboBox]:
        """Select the remembered units, averaging and range in ``view`` (a LevelView);
        returns those controls."""
        combos = {"unit": view.unit_combo, "averaging_s": view.averaging_combo,
                  "range_deg": view.range_combo}
        for key, combo in combos.items():
            self.choose(combo, key)
        return list(combos.values())

    def choose(self, combo: QComboBox, key: str) -> None:
        """Select the remembered item of a display control (its default when none fits)."""
        default = DISPLAY_DEFAULTS[key]
        if isinstance(default, str):
            remembered: str | float = self.sections.text(key, default)
        else:
            remembered = self.sections.number(key, default)
        index = combo.findData(remembered)
        combo.setCurrentIndex(index if index >= 0 else combo.findData(default))

    def save_display(self, values: dict[str, str | float]) -> None:
        for key, value in values.items():
            self.sections.set_value(key, value)

    def plot_window_s(self) -> int:
        return self.sections.number("plot_window_s", PLOT_WINDOW_DEFAULT_S, int)

    def save_plot_window_s(self, seconds: int) -> None:
        self.sections.set_value("plot_window_s", seconds)

    def theme(self) -> str:
        return self.sections.text("theme", theme.DEFAULT_CHOICE)

    def save_theme(self, choice: str) -> None:
        self.sections.set_value("theme", choice)

    # -- filter and device ------------------------------------------------------------------------
    def filter(self, chosen: str | None = None) -> str | None:
        """The filter to start with: ``chosen``, else the one the user chose last time; None
        when the user never chose one (the source's default, which follows each source:
        with a magnetometer it differs). An unknown or offline one (never live) is None."""
        name = chosen or (self.sections.text("filter", "")
                          if self.sections.flag("filter_chosen", False) else "")
        return name if name in ONLINE_FILTERS else None

    def save_filter_chosen(self, chosen: bool) -> None:
        """Whether the user chose the filter (in the Filter dock) rather than the source."""
        self.sections.set_value("filter_chosen", chosen)

    def filter_parameters(self, name: str) -> dict:
        """The remembered parameters of filter ``name`` that it has."""
        saved = self.sections.json(f"filter_parameters/{name}")
        if not isinstance(saved, dict):
            return {}
        names = {spec.name for spec in FILTERS[name].parameters}
        return {key: value for key, value in saved.items() if key in names}

    def save_filter(self, name: str, values: dict) -> None:
        self.sections.set_value("filter", name)
        self.sections.set_json(f"filter_parameters/{name}", values)

    def comparisons(self) -> list[str]:
        saved = self.sections.text("comparisons", "").split(",")
        return [name for name in saved if name in ONLINE_FILTERS]

    def save_comparisons(self, names: list[str]) -> None:
        self.sections.set_value("comparisons", ",".join(names))

    def device_url(self, chosen: str | None = None) -> str:
        return chosen or self.sections.text("device_url", DEFAULT_DEVICE_URL)

    def save_device_url(self, url: str) -> None:
        self.sections.set_value("device_url", url)


def fit_to_screen(window: QWidget, available: QRect | None = None) -> None:
    """Give ``window`` the screen's available area (the first start, or a remembered size
    that no longer fits): never larger than it."""
    if available is None:
        screen = window.screen() or QGuiApplication.primaryScreen()
        if screen is None:
            return
        available = screen.availableGeometry()
    rect = first_window_rect(
        Rect(available.x(), available.y(), available.width(), available.height()))
    window.setGeometry(rect.x, rect.y, rect.width, rect.height)


def fit_with_frame(window: QWidget) -> None:
    """Once the window manager has framed ``window``: the frame fits the screen too."""
    frame, inner = window.frameGeometry(), window.geometry()
    margins = (inner.left() - frame.left(), inner.top() - frame.top(),
               frame.right() - inner.right(), frame.bottom() - inner.bottom())
    screen = window.screen()
    if any(margins) and screen is not None and not window.isFullScreen():
        available = screen.availableGeometry()
        rect = first_window_rect(
            Rect(available.x(), available.y(), available.width(), available.height()),
            margins)
        window.setGeometry(rect.x, rect.y, rect.width, rect.height)
