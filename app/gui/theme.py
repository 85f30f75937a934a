"""The instrument's visual themes: colours, palette, stylesheet, application icon.

Every colour of the application is defined here, once per theme (:class:`Theme`): ``dark``
(the default), ``light`` (for daylight) and ``high-contrast``; the choice ``system`` follows
the operating system's light or dark scheme. The module constants (``theme.TEXT``,
``theme.ALARM_RED``, ...) and :data:`COLORS` always hold the *current* theme's colours, so read
them when painting, not at import time. Widgets that draw their own colours (plots, the
bubble level) also listen to :func:`notifier`'s ``changed`` signal to redraw on a switch.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, fields
from importlib.resources import files
from pathlib import Path

from PySide6.QtCore import QBuffer, QByteArray, QIODevice, QObject, QSize, Qt, Signal
from PySide6.QtGui import QColor, QGuiApplication, QIcon, QImageReader, QPalette, QPixmap
from PySide6.QtWidgets import QApplication, QProxyStyle


@dataclass(frozen=True)
class Theme:
    """The colours of one theme, as ``#rrggbb`` strings (tuples: gradient stops)."""

    name: str
    title: str
    dark: bool
    # Surfaces, darkest (dark themes) or lightest (light themes) first.
    BASE_BG: str  # text fields, plot backgrounds, readout tiles
    WINDOW_BG: str  # main window
    PANEL_BG: str  # docks, group boxes, toolbars
    RAISED_BG: str  # buttons, combo boxes
    RAISED_HOVER: str
    RAISED_PRESSED: str
    PRESSED_BG: str  # pressed tool buttons, alternate table rows
    BORDER: str
    BORDER_SOFT: str
    BORDER_HOVER: str
    SEPARATOR: str
    TEXT: str
    TEXT_DIM: str
    TEXT_DISABLED: str
    TEXT_STRONG: str  # text on checked / selected controls
    TEXT_VALUE: str  # the big readout digits
    TEXT_STALE: str  # readout digits no longer live (the device was lost): greyed, legible
    SELECTION_BG: str
    SELECTION_TEXT: str
    CHECKED_BG: str
    # One accent colour, plus the three state colours of an instrument.
    ACCENT: str
    ACCENT_FILL: str  # slider and progress fill
    OK_GREEN: str
    WARN_AMBER: str
    ALARM_RED: str
    # Plot pens: sensor axes (x, y, z in the usual red, green, blue order)...
    AXIS_X: str
    AXIS_Y: str
    AXIS_Z: str
    # ...angle traces...
    TRACE_ROLL: str
    TRACE_PITCH: str
    TRACE_TILT: str
    TRACE_DIRECTION: str
    TRACE_REFERENCE: str  # truth / reference curves, drawn dashed
    PLOT_GRID: str
    # ...and filters compared side by side on the angle plot, in order.
    COMPARISON_COLORS: tuple[str, ...]
    # The bubble level: turned-metal bezel (7 conical stops), chamfer (top, bottom), liquid
    # (4 radial stops, centre outwards), the engraved +X/+Y and its shadow, and the plate
    # behind printed captions.
    BEZEL_STOPS: tuple[str, ...]
    BEZEL_EDGE: str
    CHAMFER: tuple[str, str]
    VIAL_STOPS: tuple[str, ...]
    VIAL_EDGE: str
    BEZEL_TEXT: str
    BEZEL_TEXT_SHADOW: str
    VIAL_PLATE: str
    BUBBLE_RIM_WHITE: float  # share of white in the bubble's outline (light liquid: less)
    LINE_WIDTH: float = 1.0  # plot pen width


DARK = Theme(
    name="dark", title="Dark", dark=True,
    BASE_BG="#15171a", WINDOW_BG="#1d2024", PANEL_BG="#24282d", RAISED_BG="#2d3238",
    RAISED_HOVER="#343a41", RAISED_PRESSED="#23272c", PRESSED_BG="#1a1d20",
    BORDER="#3a4047", BORDER_SOFT="#30353b", BORDER_HOVER="#4a5159", SEPARATOR="#2b3035",
    TEXT="#dfe3e8", TEXT_DIM="#8b939c", TEXT_DISABLED="#5d646c", TEXT_STRONG="#ffffff",
    TEXT_VALUE="#eef1f4", TEXT_STALE="#7d858e", SELECTION_BG="#2f4656", SELECTION_TEXT="#0d1114",
    CHECKED_BG="#243a48",
    ACCENT="#4aa8d8", ACCENT_FILL="#3b7ea3",
    OK_GREEN="#4cc38a", WARN_AMBER="#e8a93a", ALARM_RED="#ef665e",
    AXIS_X="#e86a5f", AXIS_Y="#6cc77a", AXIS_Z="#5b9be6",
    TRACE_ROLL="#58c4d0", TRACE_PITCH="#c48ce0", TRACE_TILT="#e8c468",
    TRACE_DIRECTION="#a0a8b2", TRACE_REFERENCE="#9aa0a6", PLOT_GRID="#30353b",
    COMPARISON_COLORS=(
        "#f0a35e", "#7fd18b", "#e06c9f", "#8fb3ff", "#d8d36a", "#6fd6c9", "#b89cff",
    ),
    BEZEL_STOPS=("#8d959e", "#4b525a", "#2e3339", "#3a4047", "#2a2e33", "#5c646d", "#8d959e"),
    BEZEL_EDGE="#0c0e10", CHAMFER=("#0e1013", "#5a626b"),
    VIAL_STOPS=("#26343c", "#19232a", "#11181d", "#0a0e11"), VIAL_EDGE="#07090b",
    BEZEL_TEXT="#d5dae0", BEZEL_TEXT_SHADOW="#000000", VIAL_PLATE="#161f25",
    BUBBLE_RIM_WHITE=0.55,
)

LIGHT = Theme(
    name="light", title="Light", dark=False,
    BASE_BG="#ffffff", WINDOW_BG="#eef0f2", PANEL_BG="#e3e6ea", RAISED_BG="#f8f9fa",
    RAISED_HOVER="#ffffff", RAISED_PRESSED="#d5d9de", PRESSED_BG="#f3f5f7",
    BORDER="#a9b0b8", BORDER_SOFT="#c9ced4", BORDER_HOVER="#7f8892", SEPARATOR="#d3d7dc",
    TEXT="#15191e", TEXT_DIM="#4a525b", TEXT_DISABLED="#99a0a8", TEXT_STRONG="#0b1a26",
    TEXT_VALUE="#0b0d10", TEXT_STALE="#6b737c", SELECTION_BG="#cfe3f2", SELECTION_TEXT="#ffffff",
    CHECKED_BG="#cfe3f2",
    ACCENT="#1565a8", ACCENT_FILL="#3d85c2",
    OK_GREEN="#14703a", WARN_AMBER="#935100", ALARM_RED="#c4261d",
    AXIS_X="#c8372d", AXIS_Y="#238a35", AXIS_Z="#1f5fc2",
    TRACE_ROLL="#00838f", TRACE_PITCH="#8e3fb0", TRACE_TILT="#9a6b00",
    TRACE_DIRECTION="#5a626b", TRACE_REFERENCE="#4a525b", PLOT_GRID="#dde1e5",
    COMPARISON_COLORS=(
        "#c95f00", "#2e7d32", "#c2185b", "#3949ab", "#827717", "#00796b", "#6a1b9a",
    ),
    BEZEL_STOPS=("#fbfcfd", "#c2c8ce", "#9fa7af", "#c9ced3", "#a7aeb5", "#dde1e4", "#fbfcfd"),
    BEZEL_EDGE="#6c737a", CHAMFER=("#7b838b", "#f1f3f5"),
    VIAL_STOPS=("#fbfdf6", "#eef4e2", "#dfe9cd", "#c8d5b3"), VIAL_EDGE="#7f8a70",
    BEZEL_TEXT="#15191e", BEZEL_TEXT_SHADOW="#ffffff", VIAL_PLATE="#f4f8ec",
    BUBBLE_RIM_WHITE=0.0,
    LINE_WIDTH=1.5,
)

HIGH_CONTRAST = Theme(
    name="high-contrast", title="High contrast", dark=True,
    BASE_BG="#000000", WINDOW_BG="#000000", PANEL_BG="#0d0d0d", RAISED_BG="#1a1a1a",
    RAISED_HOVER="#2a2a2a", RAISED_PRESSED="#000000", PRESSED_BG="#0d0d0d",
    BORDER="#ffffff", BORDER_SOFT="#bfbfbf", BORDER_HOVER="#ffe14d", SEPARATOR="#8c8c8c",
    TEXT="#ffffff", TEXT_DIM="#e6e6e6", TEXT_DISABLED="#8c8c8c", TEXT_STRONG="#000000",
    TEXT_VALUE="#ffffff", TEXT_STALE="#a6a6a6", SELECTION_BG="#ffe14d", SELECTION_TEXT="#000000",
    CHECKED_BG="#ffe14d",
    ACCENT="#ffe14d", ACCENT_FILL="#ffe14d",
    OK_GREEN="#3dff7a", WARN_AMBER="#ffb224", ALARM_RED="#ff4d4d",
    AXIS_X="#ff6b6b", AXIS_Y="#4dff6b", AXIS_Z="#6bb5ff",
    TRACE_ROLL="#3df2ff", TRACE_PITCH="#ff7aff", TRACE_TILT="#ffe14d",
    TRACE_DIRECTION="#ffffff", TRACE_REFERENCE="#ffffff", PLOT_GRID="#595959",
    COMPARISON_COLORS=(
        "#ff9d3d", "#9dff3d", "#ff3d9d", "#9db5ff", "#ffff3d", "#3dffd8", "#c89dff",
    ),
    BEZEL_STOPS=("#bfbfbf", "#595959", "#262626", "#404040", "#262626", "#737373", "#bfbfbf"),
    BEZEL_EDGE="#ffffff", CHAMFER=("#000000", "#808080"),
    VIAL_STOPS=("#0a0a0a", "#050505", "#000000", "#000000"), VIAL_EDGE="#ffffff",
    BEZEL_TEXT="#ffffff", BEZEL_TEXT_SHADOW="#000000", VIAL_PLATE="#000000",
    BUBBLE_RIM_WHITE=0.7,
    LINE_WIDTH=2.0,
)

TEXT_ON_BACKGROUND: tuple[tuple[str, str, str], ...] = (
    ("TEXT", "WINDOW_BG", "window, dock and dialog text"),
    ("TEXT", "PANEL_BG", "dock panels, tool tips, group boxes"),
    ("TEXT", "BASE_BG", "fields, tables, lists"),
    ("TEXT", "RAISED_BG", "buttons, combo boxes"),
    ("TEXT", "RAISED_HOVER", "a hovered button"),
    ("TEXT_DIM", "WINDOW_BG", "toolbar labels, tabs, group titles"),
    ("TEXT_DIM", "PANEL_BG", "status bar, dock titles, table headers"),
    ("TEXT_DIM", "BASE_BG", "readout captions, units and notes; plot axes and legends"),
    ("TEXT_DIM", "VIAL_PLATE", "the bubble level's scale and captions"),
    ("TEXT_DISABLED", "WINDOW_BG", "disabled controls"),
    ("TEXT_DISABLED", "PANEL_BG", "disabled buttons"),
    ("TEXT_DISABLED", "BASE_BG", "disabled fields"),
    ("TEXT_STRONG", "SELECTION_BG", "the selected menu item"),
    ("TEXT_STRONG", "CHECKED_BG", "checked buttons"),
    ("TEXT_VALUE", "BASE_BG", "the readout digits"),
    ("TEXT_STALE", "BASE_BG", "readout digits no longer live"),
    ("SELECTION_TEXT", "ACCENT", "highlighted rows (the palette's Highlight)"),
    ("ACCENT", "PANEL_BG", "tare in the status bar, links"),
    ("OK_GREEN", "PANEL_BG", "calibrated, self-test passed"),
    ("WARN_AMBER", "PANEL_BG", "uncalibrated, alarm problems"),
    ("ALARM_RED", "PANEL_BG", "recording, failed checks"),
    ("ALARM_RED", "BASE_BG", "readout digits in alarm"),
    ("ALARM_RED", "VIAL_PLATE", "the bubble level's OVER RANGE"),
    ("BASE_BG", "WARN_AMBER", "the HOLD badge"),
    ("BEZEL_TEXT", "VIAL_PLATE", "the bubble level's engraved +X/+Y"),
)
"""Every text colour of a theme with the background it is drawn on (colour names, and
where): what the WCAG contrast check (tests/test_theme_contrast.py) measures."""

THEMES: dict[str, Theme] = {t.name: t for t in (DARK, LIGHT, HIGH_CONTRAST)}
"""The themes by name."""

SYSTEM = "system"
CHOICES: tuple[tuple[str, str], ...] = (
    (SYSTEM, "System"), ("dark", "Dark"), ("light", "Light"), ("high-contrast", "High contrast"),
)
"""What the user may choose (name, menu title): a theme, or the system's scheme."""
DEFAULT_CHOICE = "dark"

_ICON_SIZES = (16, 24, 32, 48, 64, 128, 256)
_TOKEN = re.compile(r"@([A-Z_]+)")

_current: Theme = DARK
_choice: str = DEFAULT_CHOICE


def _colour_fields(theme: Theme) -> dict[str, str]:
    return {
        f.name: getattr(theme, f.name) for f in fields(theme)
        if f.name.isupper() and isinstance(getattr(theme, f.name), str)
    }


COLORS: dict[str, str] = {}
"""The current theme's colours by name, as ``#rrggbb`` strings (``QColor(COLORS["ACCENT"])``)."""
AXIS_COLORS: tuple[str, str, str] = (DARK.AXIS_X, DARK.AXIS_Y, DARK.AXIS_Z)
"""Pen colours for the x, y and z sensor axes, in that order (current theme)."""
# The current theme's colours as module constants; set by _make_current().
BASE_BG = WINDOW_BG = PANEL_BG = RAISED_BG = BORDER = TEXT = TEXT_DIM = TEXT_DISABLED = ""
ACCENT = OK_GREEN = WARN_AMBER = ALARM_RED = ""
ALARM_STATE = ""
"""The alarm state (app/core/alarms/): readouts and bubble in alarm, the alarm banner; the
theme's ALARM_RED. Read when drawn (not copied at import), so a theme switch restyles it."""
AXIS_X = AXIS_Y = AXIS_Z = TRACE_ROLL = TRACE_PITCH = TRACE_TILT = TRACE_DIRECTION = ""
TRACE_REFERENCE = PLOT_GRID = ""
COMPARISON_COLORS: tuple[str, ...] = ()


def _make_current(theme: Theme) -> None:
    """Make ``theme`` the one the module constants and :data:`COLORS` describe."""
    global _current, AXIS_COLORS, COMPARISON_COLORS
    _current = theme
    colours = _colour_fields(theme)
    colours["ALARM_STATE"] = theme.ALARM_RED
    COLORS.clear()
    COLORS.update(colours)
    globals().update(colours)
    AXIS_COLORS = (theme.AXIS_X, theme.AXIS_Y, theme.AXIS_Z)
    COMPARISON_COLORS = theme.COMPARISON_COLORS


_make_current(DARK)


class _Notifier(QObject):
    """Tells widgets that draw their own colours that the theme changed."""

    changed = Signal(str)  # the new theme's name


_notifier: _Notifier | None = None


def notifier() -> _Notifier:
    """The object whose ``changed(name)`` signal fires after every theme switch."""
    global _notifier
    if _notifier is None:
        _notifier = _Notifier()
    return _notifier


def current() -> Theme:
    """The theme in use."""
    return _current


def choice() -> str:
    """What the user chose: a theme name or ``"system"``."""
    return _choice


def resolve(choice_name: str, scheme: Qt.ColorScheme | None = None) -> Theme:
    """The theme for a choice; ``"system"`` picks light or dark from ``scheme`` (the OS's
    colour scheme; dark when the system does not say). Unknown names give the default."""
    if choice_name == SYSTEM:
        return LIGHT if scheme == Qt.ColorScheme.Light else DARK
    return THEMES.get(choice_name, THEMES[DEFAULT_CHOICE])


def system_scheme() -> Qt.ColorScheme:
    """The operating system's colour scheme (Qt 6.5+), ``Unknown`` when it cannot tell."""
    app = QGuiApplication.instance()
    if app is None:
        return Qt.ColorScheme.Unknown
    return app.styleHints().colorScheme()


def load_stylesheet(theme: Theme | None = None) -> str:
    """The Qt stylesheet ``resources/styles/instrument.qss`` in ``theme``'s colours (current).

    ``@NAME`` becomes the theme's colour ``NAME``; ``url("icons:NAME")`` becomes the path of
    ``resources/icons/NAME``, so that the arrows of combo and spin boxes are found wherever
    the package is installed.
    """
    theme = theme or _current
    colours = _colour_fields(theme)
    colours["ALARM_STATE"] = theme.ALARM_RED
    resources = files("resources")
    template = (resources / "styles" / "instrument.qss").read_text(encoding="utf-8")
    stylesheet = _TOKEN.sub(lambda match: colours[match.group(1)], template)
    icons = resources / "icons"
    if isinstance(icons, Path):  # an ordinary folder (not inside a zip file)
        stylesheet = stylesheet.replace('url("icons:', f'url("{icons.as_posix()}/')
    return stylesheet


def app_icon() -> QIcon:
    """The application icon, rendered crisply from ``resources/icons/inclinometer.svg``.

    The SVG is rasterised at the usual icon sizes (this needs Qt's SVG image plugin, which
    PySide6-Essentials ships).
    """
    svg_bytes = (files("resources") / "icons" / "inclinometer.svg").read_bytes()
    icon = QIcon()
    for size in _ICON_SIZES:
        pixmap = _render_svg(svg_bytes, size)
        if not pixmap.isNull():
            icon.addPixmap(pixmap)
    return icon


def _render_svg(svg_bytes: bytes, size: int) -> QPixmap:
    """Rasterise SVG data into a ``size`` x ``size`` pixmap (null on failure)."""
    buffer = QBuffer()
    buffer.setData(QByteArray(svg_bytes))
    buffer.open(QIODevice.OpenModeFlag.ReadOnly)
    reader = QImageReader(buffer, QByteArray(b"svg"))
    reader.setScaledSize(QSize(size, size))
    image = reader.read()
    buffer.close()
    return QPixmap.fromImage(image)


def palette(theme: Theme | None = None) -> QPalette:
    """A :class:`QPalette` matching the stylesheet, for the Fusion style."""
    t = theme or _current
    result = QPalette()
    role = QPalette.ColorRole
    group = QPalette.ColorGroup
    shade = QColor(t.WINDOW_BG)
    for name, value in (
        ("Window", t.WINDOW_BG), ("WindowText", t.TEXT), ("Base", t.BASE_BG),
        ("AlternateBase", t.PANEL_BG), ("ToolTipBase", t.PANEL_BG), ("ToolTipText", t.TEXT),
        ("PlaceholderText", t.TEXT_DIM), ("Text", t.TEXT), ("Button", t.RAISED_BG),
        ("ButtonText", t.TEXT), ("BrightText", t.ALARM_RED), ("Light", t.BORDER),
        ("Midlight", t.BORDER_SOFT), ("Mid", t.PANEL_BG),
        ("Dark", shade.darker(160).name()), ("Shadow", "#000000"),
        ("Highlight", t.ACCENT), ("HighlightedText", t.SELECTION_TEXT),
        ("Link", t.ACCENT), ("LinkVisited", t.TRACE_PITCH),
    ):
        result.setColor(getattr(role, name), QColor(value))
    for disabled_role in (role.WindowText, role.Text, role.ButtonText):
        result.setColor(group.Disabled, disabled_role, QColor(t.TEXT_DISABLED))
    result.setColor(group.Disabled, role.Highlight, QColor(t.BORDER))
    return result


def dark_palette() -> QPalette:
    """The dark theme's palette."""
    return palette(DARK)


def apply_theme(app: QApplication, choice_name: str | None = None) -> Theme:
    """Give ``app`` the instrument look in the chosen theme (``"dark"`` when not given):
    Fusion style, palette, stylesheet and icon. With ``"system"`` the theme follows the
    operating system's colour scheme, also when it changes later. Returns the theme used."""
    global _choice
    _choice = choice_name if choice_name in dict(CHOICES) else DEFAULT_CHOICE
    _follow_system(app)
    return _apply(app, resolve(_choice, system_scheme()))


def _apply(app: QApplication, theme: Theme) -> Theme:
    changed = theme is not _current
    _make_current(theme)
    # Under a stylesheet the style reports no name; the base is Fusion when no stylesheet
    # is set yet (a new style would re-polish every widget: only when needed).
    style = app.style()
    base = style.baseStyle() if isinstance(style, QProxyStyle) else style  # the wheel guard's
    if not app.styleSheet() and base.name().lower() != "fusion":
        app.setStyle("Fusion")
    # Setting an equal stylesheet again would still re-polish every widget: skip it.
    stylesheet = load_stylesheet(theme)
    if app.styleSheet() != stylesheet:
        app.setPalette(palette(theme))
        app.setStyleSheet(stylesheet)
    elif app.palette() != palette(theme):
        app.setPalette(palette(theme))
    if app.windowIcon().isNull():
        app.setWindowIcon(app_icon())
    if changed:
        notifier().changed.emit(theme.name)
    return theme


_following: set[int] = set()


def _follow_system(app: QApplication) -> None:
    """Re-apply the theme when the system's scheme changes (if the choice is "system")."""
    if id(app) in _following:
        return
    _following.add(id(app))

    def scheme_changed(scheme: Qt.ColorScheme) -> None:
        if _choice == SYSTEM:
            wanted = resolve(SYSTEM, scheme)
            if wanted is not _current:
                _apply(app, wanted)

    app.styleHints().colorSchemeChanged.connect(scheme_changed)

