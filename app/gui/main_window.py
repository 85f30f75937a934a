"""The main window: it assembles the device bar, the level view, the docks, the status bar
and the menus, and wires them to the device session. The work is in its parts:

=========================  ====================================================
:mod:`.level_view`         the centre: banners, bubble, readouts, display controls
:mod:`.docks`              which docks, where, tabbed how; Reset layout
:mod:`.plots_dock`         the Live plots dock's bar (time window, range statistics)
:mod:`.window_status`      the status bar's fields and texts
:mod:`.window_menus`       the menus as a table (built by :mod:`.actions`)
:mod:`.window_settings`    what the window remembers (through ``SettingsSections``)
:mod:`.device_events`      the session's events shown in the window
:mod:`.file_actions`       open a recording, export the plots, record
:mod:`.calibration_actions` the wizard, Allan variance, profiles to and from files
:mod:`.alarms_and_log`     the alarms and the measurement log
:mod:`.attitude_routing`   the 3D view and the arm: the device or the Joint sensors
:mod:`.instrument_mode`    the full-screen instrument (F11)
=========================  ====================================================
"""

from __future__ import annotations

import time

from PySide6.QtCore import QRect, QSettings, Qt, QTimer
from PySide6.QtGui import QCloseEvent, QGuiApplication, QResizeEvent, QShowEvent
from PySide6.QtWidgets import QApplication, QDialog, QMainWindow, QPlainTextEdit

from app.core.alarms import AlarmConfig
from app.core.measurement_log import default_log_path
from app.gui import file_dialogs, theme, wheel_guard
from app.gui.actions import build_menus
from app.gui.alarms_and_log import AlarmsAndLog
from app.gui.arm_panel import ArmPanel
from app.gui.attitude_routing import AttitudeRouting
from app.gui.attitude_view import AttitudeView
from app.gui.calibration_actions import CalibrationActions
from app.gui.calibration_wizard import CalibrationWizard
from app.gui.device_bar import DeviceBar
from app.gui.device_events import DeviceEvents
from app.gui.device_panel import DevicePanel
from app.gui.docks import DockLayout
from app.gui.feeds.heading import HeadingFeed
from app.gui.field_view import FieldPresenter, FieldView
from app.gui.file_actions import FileActions, recordings_dir
from app.gui.filter_panel import FilterPanel
from app.gui.heading_controls import HeadingControls
from app.gui.help_dialogs import HelpWindows
from app.gui.instrument_mode import InstrumentMode
from app.gui.joint_panel import JointPanel
from app.gui.level_view import INSTRUMENT_MAX_PX, READOUT_MAX_PX, READOUT_MIN_PX, LevelView
from app.gui.measure_panel import MeasurePanel
from app.gui.plots import LivePlots
from app.gui.plots_dock import PlotsDock
from app.gui.presenter import LivePresenter
from app.gui.replay_bar import ReplayBar
from app.gui.simulator_panel import SimulatorPanel
from app.gui.user_settings import SettingsSections, check_settings
from app.gui.window_menus import menu_table
from app.gui.window_settings import WindowSettings, fit_to_screen, fit_with_frame
from app.gui.window_status import WindowStatus
from app.services.devices import available_devices
from app.services.session import DeviceSession

__all__ = ["INSTRUMENT_MAX_PX", "READOUT_MAX_PX", "READOUT_MIN_PX", "MainWindow"]


class MainWindow(QMainWindow):
    """The instrument window. It owns the device session and the live presenter."""

    def __init__(
        self,
        session: DeviceSession,
        settings: QSettings,
        device_url: str | None = None,
        filter_name: str | None = None,
        alarms: AlarmConfig | None = None,
    ) -> None:
        super().__init__()
        self.session = session
        self.settings = settings
        settings_problem = check_settings(settings)
        app = QApplication.instance()
        if isinstance(app, QApplication):
            wheel_guard.install(app)  # the wheel scrolls panels, never an unfocused field
        file_dialogs.use_settings(settings)
        self.sections = SettingsSections(settings, self.show_error)
        """Every setting goes through here; components that keep a dict of settings register
        a section (``window.sections.register("alarms", config.to_dict, load)``)."""
        self.window_settings = WindowSettings(self.sections)
        self.setWindowTitle("Inclinometer")
        self.setWindowIcon(theme.app_icon())
        self.setDockOptions(
            QMainWindow.DockOption.AnimatedDocks | QMainWindow.DockOption.AllowTabbedDocks
        )
        self._build_views()
        self.status_view = WindowStatus(self.statusBar())
        for name in ("device", "rate", "filter", "fps", "calibration", "tare", "recording"):
            setattr(self, f"status_{name}", getattr(self.status_view, name))
        self.status_fields = self.status_view.fields
        self.health_lights = self.status_view.health_lights

        self.presenter = LivePresenter(
            session, self.level, self.readouts, self.plots, self.truth_label, self.filter_panel,
            self,
        )
        self.files = FileActions(self)
        self.calibration = CalibrationActions(self)
        self.instrument = InstrumentMode(self)
        self.attitudes = AttitudeRouting(self)
        self.events = DeviceEvents(self)
        self.help = HelpWindows(self, self.file_paths)
        actions = build_menus(self, menu_table())
        self.__dict__.update({key: a for key, a in actions.items() if key.endswith("_action")})
        self.theme_actions = {key.removeprefix("theme:"): action
                              for key, action in actions.items() if key.startswith("theme:")}
        self._wire()
        self.alarms.start(alarms)
        self._restore_settings()
        self.refresh_devices()
        self._start_session(filter_name, device_url)
        theme.notifier().changed.connect(self._on_theme_changed)
        if settings_problem:
            self.show_error(settings_problem)
        # The keys (H, Space, ...) go to the instrument from the start, not to the device
        # field (H typed "h" into the URL there, and Enter then connected to it).
        self.level.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.level.setFocus(Qt.FocusReason.OtherFocusReason)

    # -- assembly ---------------------------------------------------------------------------
    def _build_views(self) -> None:
        """The bars, the centre and the docks' contents, then the docks."""
        self.device_bar = DeviceBar(self)
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, self.device_bar)
        self.addToolBarBreak()
        self.replay_bar = ReplayBar(self)
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, self.replay_bar)
        self.replay_bar.hide()
        self.level_view = view = LevelView(self)
        self.setCentralWidget(view)
        self.banner, self.alarm_banner, self.level = view.banner, view.alarm_banner, view.level
        self.readouts, self.truth_label, self.controls = view.readouts, view.truth_label, \
            view.controls
        self.unit_combo, self.averaging_combo = view.unit_combo, view.averaging_combo
        self.range_combo, self.hold_button = view.range_combo, view.hold_button
        self.compass, self.heading_bar = view.compass, view.heading_bar
        # The docks first, then each one's contents made in it (made elsewhere and moved in,
        # Qt polished every widget again: the window took half as long again to build).
        self.dock_layout = docks = DockLayout(self)
        self.plots = LivePlots()
        self.plots_dock = PlotsDock(
            self.plots, lambda start, end: self.presenter.range_statistics(start, end),
            docks.home("plots"))
        self.window_combo = self.plots_dock.window_combo
        self.range_box, self.range_label = self.plots_dock.range_box, self.plots_dock.range_label
        self.filter_panel = FilterPanel(docks.home("filter"))
        self.simulator_panel = SimulatorPanel(docks.home("simulator"))
        self.device_panel = DevicePanel(docks.home("device"))
        self.measure_panel = MeasurePanel(self.session, docks.home("measure"))
        self.attitude_view = AttitudeView(docks.home("attitude3d"))
        self.arm_panel = ArmPanel(parent=docks.home("arm"))
        self.messages = QPlainTextEdit(docks.home("messages"))
        self.messages.setReadOnly(True)
        self.messages.setMaximumBlockCount(2000)
        self.alarms = AlarmsAndLog(self, default_log_path(), docks.home("alarms"),
                                   docks.home("log"))
        self.alarm_panel, self.log_panel = self.alarms.alarm_panel, self.alarms.log_panel
        self.joint_panel = JointPanel(parent=docks.home("joint"))
        self.field_view = FieldView(docks.home("field"))
        docks.fill({
            "plots": self.plots_dock, "filter": self.filter_panel,
            "simulator": self.simulator_panel, "device": self.device_panel,
            "measure": self.measure_panel, "attitude3d": self.attitude_view,
            "arm": self.arm_panel, "messages": self.messages, "alarms": self.alarm_panel,
            "log": self.log_panel, "joint": self.joint_panel, "field": self.field_view,
        })
        self.docks = self.dock_layout.docks
        self._default_layout_pending = True

    def _wire(self) -> None:
        """Views -> session (queued to the worker) and session -> views."""
        session, events, status = self.session, self.events, self.status_view
        # The field views follow the frame clock; their dock shows while a field comes.
        self.field_presenter = FieldPresenter(session, self.field_view, self)
        self.presenter.clock.tick.connect(self.field_presenter.refresh)
        self.field_presenter.availabilityChanged.connect(self.docks["field"].setVisible)
        self.field_presenter.problem.connect(self.show_error)
        # The filters check the field they learn against the WMM's at the dock's place.
        self.field_presenter.wmmChanged.connect(session.requestFieldReference)
        session.requestFieldReference.emit(
            self.field_presenter.for_filters(self.field_presenter.reference))
        self.sections.register("field_reference", self.field_presenter.settings_dict,
                               self.field_presenter.apply_settings)
        # The compass: its heading shares the readouts' window, its light the Field dock's
        # reference; its settings are a section, the declination goes with recordings.
        self.heading_feed = HeadingFeed(self.compass, session,
                                        lambda: self.field_presenter.reference)
        self.presenter.attach_heading(self.heading_feed)
        # The 3D view in the earth frame (E, N, Up) while the main device's heading is real.
        self.heading_feed.on_earth_frame = lambda on: self.attitude_view.set_earth_frame(
            on and not self.joint_panel.has_sensors)
        self.heading_controls = HeadingControls(self.heading_bar, self)
        self.heading_controls.settingsChanged.connect(self._on_heading_settings)
        self.heading_controls.declinationChanged.connect(session.requestDeclination)
        self.sections.register("heading", self.heading_controls.settings_dict,
                               self.heading_controls.apply_settings)
        self.presenter.framesPerSecond.connect(status.show_fps)
        self.hold_button.toggled.connect(lambda on: self.presenter.set_hold(on))
        self.health_lights.resetRequested.connect(events.reset_health)
        self.measure_panel.tareRequested.connect(session.requestTareReference)
        self.window_combo.currentIndexChanged.connect(
            lambda _i: self.window_settings.save_plot_window_s(self.window_combo.currentData()))
        for signal, slot in (
            (self.device_bar.connectRequested, self.connect_device),
            (self.device_bar.disconnectRequested, session.requestDisconnect),
            (self.device_bar.refreshRequested, self.refresh_devices),
            (self.filter_panel.filterRequested, session.requestFilter),
            (self.filter_panel.filterRequested, self._on_filter_chosen),
            (self.filter_panel.parameterChanged, session.requestFilterParameter),
            (self.filter_panel.parameterChanged, self._on_filter_chosen),
            (self.filter_panel.sourceDefaultRequested, session.requestSourceFilter),
            (self.filter_panel.sourceDefaultRequested, self._on_source_filter),
            (self.filter_panel.comparisonsRequested, session.requestComparisons),
            (self.replay_bar.control, session.requestReplayControl),
            (self.simulator_panel.deviceRequested, self.connect_device),
            (self.simulator_panel.targetChanged, session.requestSimulatorTarget),
            (self.device_panel.selfTestRequested, session.requestSelfTest),
            (session.comparisonsChanged, events.on_comparisons_changed),
            (session.calibrationChanged, self.calibration.show_profile),
            (session.tareChanged, status.show_tare),
            (session.reconnecting, events.on_reconnecting),
            (session.recordingChanged, self.files.show_recording),
            (session.lslChanged, self.files.show_lsl),
            (session.connected, events.on_connected),
            (session.disconnected, events.on_disconnected),
            (session.error, self.show_error),
            (session.notice, self.show_notice),
            (session.deviceMessage, events.on_device_message),
            (session.selfTestAvailable, self.device_panel.set_self_test_available),
            (session.selfTestFinished, events.on_self_test_finished),
            (session.faultEvents, events.on_fault_events),
            (session.status, events.on_status),
            (session.filterChanged, events.on_filter_changed),
        ):
            signal.connect(slot)

    def _restore_settings(self) -> None:
        self.window_settings.restore_layout(self)
        for combo in self.window_settings.restore_display(self.level_view):
            combo.currentIndexChanged.connect(self._on_display_changed)
        self._on_display_changed()
        self.plots_dock.choose_window(self.window_settings.plot_window_s())
        self.set_theme(self.window_settings.theme())

    def _start_session(self, filter_name: str | None, device_url: str | None) -> None:
        """The remembered (or given) filter, comparisons and device; the frames start."""
        remembered, session = self.window_settings, self.session
        chosen_filter = remembered.filter(filter_name)
        self.filter_panel.set_follows_source(chosen_filter is None)
        if chosen_filter is None:  # none chosen: each source's default (9-axis or not)
            session.requestSourceFilter.emit()
        else:
            session.requestFilter.emit(chosen_filter)
            for key, value in remembered.filter_parameters(chosen_filter).items():
                session.requestFilterParameter.emit(key, value)
        compared = remembered.comparisons()
        if compared:
            session.requestComparisons.emit(compared)
        url = remembered.device_url(device_url)
        self.presenter.start()
        self.connect_device(url)

    def _on_filter_chosen(self, *_args: object) -> None:
        """The user picked a filter or set a parameter: it is kept for every source."""
        self.window_settings.save_filter_chosen(True)
        self.filter_panel.set_follows_source(False)

    def _on_source_filter(self) -> None:
        """The user asked for each source's default filter again."""
        self.window_settings.save_filter_chosen(False)
        self.filter_panel.set_follows_source(True)

    def _on_theme_changed(self, _name: str) -> None:
        """Colours set on single widgets follow the theme (a method: Qt drops the
        connection with the window)."""
        self.status_view.restyle()

    def _on_heading_settings(self, settings) -> None:
        self.heading_feed.set_settings(settings)
        self.presenter.clock.wake()

    def _on_display_changed(self) -> None:
        display = self.presenter.settings
        display.unit = self.unit_combo.currentData()
        display.averaging_s = self.averaging_combo.currentData()
        self.level.setRange(self.range_combo.currentData())
        self.presenter.refresh()
        self.window_settings.save_display({"unit": display.unit,
                                           "averaging_s": display.averaging_s,
                                           "range_deg": self.range_combo.currentData()})

    # -- what the window offers (menus, other windows, tests) ---------------------------------
    def connect_device(self, url: str) -> None:
        """Ask the worker to open ``url`` (any open device is closed first)."""
        self.banner.hide()
        self.device_bar.select_url(url)
        self.device_bar.set_state("connecting", f"Connecting to {url}…")
        self.session.requestConnect.emit(url)

    def refresh_devices(self) -> None:
        devices = available_devices()
        self.device_bar.set_devices(devices)
        self.simulator_panel.set_scenarios([d for d in devices if d.kind == "simulator"])

    def show_error(self, message: str) -> None:
        self.banner.show_message(message)
        self.log(message, error=True)

    def show_notice(self, message: str) -> None:
        """Information on the banner (styled as information, not as an error) and in Messages."""
        self.banner.show_message(message, "info")
        self.log(message)

    def log(self, message: str, error: bool = False) -> None:
        stamp = time.strftime("%H:%M:%S")
        self.messages.appendPlainText(f"{stamp}  {'ERROR  ' if error else ''}{message}")

    def copy_reading(self) -> str:
        """Put the reading shown (roll, pitch, tilt in the chosen units, and the heading when
        the compass shows one) on the clipboard."""
        text = self.readouts.reading()
        heading = self.compass.tile.reading().clipboard_text()
        if text and heading:
            text = f"{text} {heading}"
        if not text:
            self.statusBar().showMessage("No reading to copy", 3000)
            return ""
        QGuiApplication.clipboard().setText(text)
        self.statusBar().showMessage(f"Copied: {text}", 3000)
        return text

    def set_theme(self, choice: str) -> None:
        """Use a theme (``dark``, ``light``, ``high-contrast``) or follow the system."""
        app = QApplication.instance()
        if isinstance(app, QApplication):
            theme.apply_theme(app, choice)
        self.theme_actions[theme.choice()].setChecked(True)
        self.window_settings.save_theme(theme.choice())

    @property
    def instrument_mode(self) -> bool:
        """Whether the window shows only the big digits and the bubble, full screen."""
        return self.instrument.active

    def set_instrument_mode(self, enabled: bool) -> None:
        """Full-screen instrument (F11) on or off (:mod:`app.gui.instrument_mode`)."""
        self.instrument.set(enabled)

    def reset_layout(self) -> None:
        """View ▸ Reset layout: every dock where and as large as at the first start."""
        self.set_instrument_mode(False)
        self.dock_layout.reset()

    def file_paths(self) -> dict[str, str]:
        """Where the app keeps its files (shown in About)."""
        return {
            "Settings": self.sections.file_name(),
            "Calibration profiles": str(self.session.profile_store.base_dir),
            "Measurement log": str(default_log_path()),
            "Recordings": str(recordings_dir()),
            "Last folder of a file dialog": str(file_dialogs.last_folder() or "(none yet)"),
        }

    def show_user_guide(self) -> QDialog:
        return self.help.user_guide()

    def show_shortcut_sheet(self) -> QDialog:
        return self.help.shortcut_sheet()

    def show_about(self) -> QDialog:
        return self.help.about()

    def open_recording(self, path: str | None = None) -> None:
        self.files.open_recording(path)

    def export_plots(self, path: str | None = None) -> None:
        self.files.export_plots(path)

    def start_recording(self, path: str, note: str = "") -> None:
        self.files.start_recording(path, note)

    def open_calibration_wizard(self) -> CalibrationWizard | None:
        return self.calibration.open_wizard()

    def open_allan_page(self):
        return self.calibration.open_allan_page()

    def import_profile(self, path: str | None = None) -> None:
        self.calibration.import_profile(path)

    def apply_alarms(self, config: AlarmConfig) -> None:
        self.alarms.apply(config)

    def _show_joint(self, then) -> None:
        self.attitudes.show_joint(then)

    def fit_to_screen(self, available: QRect | None = None) -> None:
        """Take the screen's available area: never larger than it."""
        fit_to_screen(self, available)

    # -- Qt's events ------------------------------------------------------------------------------
    def showEvent(self, event: QShowEvent) -> None:
        super().showEvent(event)
        self.dock_layout.tidy_tab_bars()
        if self._default_layout_pending:
            self._default_layout_pending = False
            self.level.setFocus(Qt.FocusReason.OtherFocusReason)
            has_geometry, has_docks = self.window_settings.has_layout()
            if not has_geometry:
                QTimer.singleShot(0, self, lambda: fit_with_frame(self))  # framed after show
            if not has_docks:
                # Dock sizes only stick once the window has its final size.
                QTimer.singleShot(0, self, self.dock_layout.apply_default_sizes)

    def resizeEvent(self, event: QResizeEvent) -> None:
        super().resizeEvent(event)
        self.dock_layout.width_changed(event.oldSize().width(), event.size().width())

    def closeEvent(self, event: QCloseEvent) -> None:
        self.joint_panel.shutdown()
        self.presenter.stop()
        self.measure_panel.stop()
        saved = self.instrument.saved  # full screen: remember the usual layout
        self.window_settings.save_layout(saved["geometry"] if saved else self.saveGeometry(),
                                         saved["state"] if saved else self.saveState())
        self.sections.save_all()
        self.sections.sync()
        self.session.shutdown()
        super().closeEvent(event)
