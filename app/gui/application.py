"""Start the GUI: the QApplication, the theme, the device session and the main window."""

from __future__ import annotations

import sys

from pyqtgraph.util.garbage_collector import GarbageCollector
from PySide6.QtWidgets import QApplication

from app import __version__
from app.core.alarms import AlarmConfig
from app.gui import theme
from app.gui.main_window import MainWindow
from app.gui.user_settings import APPLICATION, ORGANIZATION, create_settings
from app.services.session import DeviceSession

__all__ = ["APPLICATION", "ORGANIZATION", "create_settings", "run_gui"]


def run_gui(
    device_url: str | None = None,
    filter_name: str | None = None,
    alarms: AlarmConfig | None = None,
) -> int:
    """Show the main window (with ``alarms``, if given, instead of the remembered ones) and
    run the event loop; returns the exit code."""
    app = QApplication.instance() or QApplication(sys.argv)
    app.setOrganizationName(ORGANIZATION)
    app.setApplicationName(APPLICATION)
    app.setApplicationVersion(__version__)
    app.setDesktopFileName("org.inclinometer.Inclinometer")  # Wayland finds the icon by it
    theme.apply_theme(app)  # the window then applies the remembered theme
    # Python's cycle collector runs in whichever thread allocates; in the device worker it
    # could free a window object mid-timer (a segmentation fault). pyqtgraph's collector
    # turns automatic collection off and collects on a timer in this, the GUI, thread.
    collector = GarbageCollector(interval=1.0)  # noqa: F841 - kept alive until exec returns
    session = DeviceSession()
    window = MainWindow(session, create_settings(), device_url, filter_name, alarms)
    window.show()
    return app.exec()
