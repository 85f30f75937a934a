"""The main window's menus as data: every action, its menu, shortcut and callback.

Built by :func:`app.gui.actions.build_menus`; callbacks are names on the window (its parts:
``files``, ``calibration``, ``instrument``, ...). The shortcut sheet (Help ▸ Keyboard
shortcuts) reads the menus, so a key listed here is listed there.
"""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QKeySequence

from app.core.recording import sample_recordings
from app.gui import theme
from app.gui.actions import ActionSpec, Entry, Generated, Separator, Submenu

Key = QKeySequence.StandardKey
FILE, CALIBRATION, EDIT, SENSORS, VIEW, HELP = (
    "&File", "&Calibration", "&Edit", "&Sensors", "&View", "&Help")
SAMPLES = f"{FILE}/Sample &recordings"
THEMES = f"{VIEW}/&Theme"


def menu_table() -> list[Entry]:
    """The menus in order (the sample recordings and themes are listed when called)."""
    return [
        ActionSpec("open_action", "&Open recording…", FILE, "files.open_recording", Key.Open),
        Submenu(SAMPLES),
        *(ActionSpec(f"sample:{path.stem}", path.stem, SAMPLES, "files.open_recording",
                     args=(str(path),)) for path in sample_recordings()),
        ActionSpec("export_plots_action", "&Export plots…", FILE, "files.export_plots",
                   tooltip="Save the live plots as PNG or SVG"),
        ActionSpec("export_recording_action", "Export &recording (MCAP, EuRoC/Kalibr)…", FILE,
                   "files.export_recording",
                   tooltip="A recording for Foxglove / ROS 2 (MCAP) or Kalibr (imu0.csv), "
                   "ENU or NED"),
        ActionSpec("record_action", "&Record…", FILE, "files.record", "Ctrl+R",
                   checkable=True, passes_checked=True),
        ActionSpec("lsl_action", "Stream over &LSL", FILE, "session.requestLsl",
                   checkable=True, passes_checked=True,
                   tooltip="Lab Streaming Layer: the calibrated samples and the filtered "
                   "orientation, stamped on the device's aligned clock, for LabRecorder"),
        Separator(FILE),
        ActionSpec("quit_action", "&Quit", FILE, "close", Key.Quit),

        ActionSpec("wizard_action", "Calibration &wizard…", CALIBRATION,
                   "calibration.open_wizard"),
        ActionSpec("allan_action", "&Allan variance: noise figures…", CALIBRATION,
                   "calibration.open_allan_page"),
        Separator(CALIBRATION),
        ActionSpec("tare_action", "&Tare: take the current attitude as level", CALIBRATION,
                   "session.requestTare", "Ctrl+T"),
        ActionSpec("clear_tare_action", "&Clear tare", CALIBRATION, "session.requestClearTare"),
        Separator(CALIBRATION),
        ActionSpec("no_calibration_action", "Run &uncalibrated", CALIBRATION,
                   "session.requestNoCalibration",
                   tooltip="Disable the device's profile; remembered across reconnects and "
                   "restarts"),
        ActionSpec("stored_profile_action", "Use the &stored profile", CALIBRATION,
                   "session.requestStoredProfile"),
        ActionSpec("delete_profile_action", "&Delete profile", CALIBRATION,
                   "session.requestDeleteProfile",
                   tooltip="The profile moves to the profiles' history folder; Import profile "
                   "brings it back"),
        ActionSpec("import_action", "&Import profile…", CALIBRATION,
                   "calibration.import_profile"),
        ActionSpec("export_action", "&Export profile…", CALIBRATION,
                   "calibration.export_profile"),

        ActionSpec("copy_action", "&Copy reading", EDIT, "copy_reading", Key.Copy,
                   tooltip="Copy roll, pitch and tilt as text, in the chosen units",
                   window_wide=True),
        # H is the window's (the Hold button is hidden in the full-screen instrument).
        ActionSpec("hold_action", "&Hold readouts", EDIT, "level_view.hold_button.toggle",
                   "H", window_wide=True),
        # Space stores anywhere in the window, also on a focused button (a digital level's
        # one key); text and number fields keep it for typing.
        ActionSpec("store_action", "&Store reading", EDIT, "log_panel.store",
                   QKeySequence(Qt.Key.Key_Space).toString(), window_wide=True),

        ActionSpec("add_sensor_action", "&Add sensor…", SENSORS, "attitudes.add_sensor",
                   tooltip="Open another device (URL) beside the others"),
        ActionSpec("arm_action", "Simulated &arm (2 links)", SENSORS, "attitudes.add_arm"),

        Generated(VIEW, "dock_layout.toggle_actions"),
        ActionSpec("reset_layout_action", "&Reset layout", VIEW, "dock_layout.reset",
                   tooltip="Every dock back where it was at the first start"),
        Separator(VIEW),
        ActionSpec("instrument_action", "&Full-screen instrument", VIEW, "set_instrument_mode",
                   "F11", checkable=True, on_toggle=True, window_wide=True,
                   tooltip="Big digits and the bubble only (F11 or Esc leaves)"),
        ActionSpec("leave_instrument_action", "&Leave full screen", VIEW,
                   "set_instrument_mode", QKeySequence(Qt.Key.Key_Escape).toString(),
                   enabled=False, args=(False,), window_wide=True),
        *(ActionSpec(f"theme:{name}", title, THEMES, "set_theme", args=(name,),
                     checkable=True, group="theme") for name, title in theme.CHOICES),

        ActionSpec("guide_action", "&User guide", HELP, "show_user_guide", Key.HelpContents),
        ActionSpec("shortcuts_action", "&Keyboard shortcuts", HELP, "show_shortcut_sheet"),
        ActionSpec("about_action", "&About Inclinometer", HELP, "show_about"),
    ]
