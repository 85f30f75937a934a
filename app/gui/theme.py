"""The instrument's visual theme: colours, dark palette, stylesheet and application icon.

Other GUI modules take their colours from :data:`COLORS` (or the module constants) so the
whole application shares one palette; plots use the ``AXIS_*`` pens for x/y/z sensor axes and
the ``TRACE_*`` pens for angle traces.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from PySide6.QtCore import QBuffer, QByteArray, QIODevice, QSize
from PySide6.QtGui import QColor, QIcon, QImageReader, QPalette, QPixmap
from PySide6.QtWidgets import QApplication

# Surfaces, darkest first.
BASE_BG = "#15171a"  # text fields, plot backgrounds, vial glass
WINDOW_BG = "#1d2024"  # main window
PANEL_BG = "#24282d"  # docks, group boxes, toolbars, readout tiles
RAISED_BG = "#2d3238"  # buttons, combo boxes
BORDER = "#3a4047"
TEXT = "#dfe3e8"
TEXT_DIM = "#8b939c"
TEXT_DISABLED = "#5d646c"

# One accent colour, plus the three state colours of an instrument.
ACCENT = "#4aa8d8"
OK_GREEN = "#4cc38a"
WARN_AMBER = "#e8a93a"
ALARM_RED = "#e5534b"
# The alarm state (app/core/alarms/): readouts and bubble in alarm, the alarm banner. Read when
# drawn (not copied at import), so a theme that changes it restyles the alarm.
ALARM_STATE = ALARM_RED

# Plot pens: sensor axes (x, y, z in the usual red, green, blue order, softened)...
AXIS_X = "#e86a5f"
AXIS_Y = "#6cc77a"
AXIS_Z = "#5b9be6"
# ...and angle traces.
TRACE_ROLL = "#58c4d0"
TRACE_PITCH = "#c48ce0"
TRACE_TILT = "#e8c468"
TRACE_DIRECTION = "#a0a8b2"
TRACE_REFERENCE = "#9aa0a6"  # truth / reference curves, drawn dashed
PLOT_GRID = "#30353b"
# Filters compared side by side on the angle plot, in order.
COMPARISON_COLORS: tuple[str, ...] = (
    "#f0a35e", "#7fd18b", "#e06c9f", "#8fb3ff", "#d8d36a", "#6fd6c9", "#b89cff",
)

COLORS: dict[str, str] = {
    "BASE_BG": BASE_BG,
    "WINDOW_BG": WINDOW_BG,
    "PANEL_BG": PANEL_BG,
    "RAISED_BG": RAISED_BG,
    "BORDER": BORDER,
    "TEXT": TEXT,
    "TEXT_DIM": TEXT_DIM,
    "TEXT_DISABLED": TEXT_DISABLED,
    "ACCENT": ACCENT,
    "OK_GREEN": OK_GREEN,
    "WARN_AMBER": WARN_AMBER,
    "ALARM_RED": ALARM_RED,
    "ALARM_STATE": ALARM_STATE,
    "AXIS_X": AXIS_X,
    "AXIS_Y": AXIS_Y,
    "AXIS_Z": AXIS_Z,
    "TRACE_ROLL": TRACE_ROLL,
    "TRACE_PITCH": TRACE_PITCH,
    "TRACE_TILT": TRACE_TILT,
    "TRACE_DIRECTION": TRACE_DIRECTION,
    "TRACE_REFERENCE": TRACE_REFERENCE,
    "PLOT_GRID": PLOT_GRID,
}
"""All theme colours by name, as ``#rrggbb`` strings (``QColor(COLORS["ACCENT"])``)."""

AXIS_COLORS: tuple[str, str, str] = (AXIS_X, AXIS_Y, AXIS_Z)
"""Pen colours for the x, y and z sensor axes, in that order."""

_ICON_SIZES = (16, 24, 32, 48, 64, 128, 256)


def load_stylesheet() -> str:
    """The Qt stylesheet ``resources/styles/instrument.qss`` as text.

    ``url("icons:NAME")`` in the file becomes the path of ``resources/icons/NAME``, so that
    the arrows of combo and spin boxes are found wherever the package is installed.
    """
    resources = files("resources")
    stylesheet = (resources / "styles" / "instrument.qss").read_text(encoding="utf-8")
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


def dark_palette() -> QPalette:
    """A dark :class:`QPalette` matching the stylesheet, for the Fusion style."""
    palette = QPalette()
    role = QPalette.ColorRole
    group = QPalette.ColorGroup
    palette.setColor(role.Window, QColor(WINDOW_BG))
    palette.setColor(role.WindowText, QColor(TEXT))
    palette.setColor(role.Base, QColor(BASE_BG))
    palette.setColor(role.AlternateBase, QColor(PANEL_BG))
    palette.setColor(role.ToolTipBase, QColor(PANEL_BG))
    palette.setColor(role.ToolTipText, QColor(TEXT))
    palette.setColor(role.PlaceholderText, QColor(TEXT_DIM))
    palette.setColor(role.Text, QColor(TEXT))
    palette.setColor(role.Button, QColor(RAISED_BG))
    palette.setColor(role.ButtonText, QColor(TEXT))
    palette.setColor(role.BrightText, QColor(ALARM_RED))
    palette.setColor(role.Light, QColor("#3a4047"))
    palette.setColor(role.Midlight, QColor("#32373d"))
    palette.setColor(role.Mid, QColor("#272b30"))
    palette.setColor(role.Dark, QColor("#121417"))
    palette.setColor(role.Shadow, QColor("#000000"))
    palette.setColor(role.Highlight, QColor(ACCENT))
    palette.setColor(role.HighlightedText, QColor("#0d1114"))
    palette.setColor(role.Link, QColor(ACCENT))
    palette.setColor(role.LinkVisited, QColor(TRACE_PITCH))
    for disabled_role in (role.WindowText, role.Text, role.ButtonText):
        palette.setColor(group.Disabled, disabled_role, QColor(TEXT_DISABLED))
    palette.setColor(group.Disabled, role.Highlight, QColor(BORDER))
    return palette


def apply_theme(app: QApplication) -> None:
    """Give ``app`` the instrument look: Fusion style, dark palette, stylesheet and icon."""
    app.setStyle("Fusion")
    app.setPalette(dark_palette())
    app.setStyleSheet(load_stylesheet())
    app.setWindowIcon(app_icon())
