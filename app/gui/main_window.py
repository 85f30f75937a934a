"""The main window: device bar, bubble level with readouts, live plots and dockable panels."""

from __future__ import annotations

import time
from datetime import timedelta
from pathlib import Path
from urllib.parse import urlsplit

from PySide6.QtCore import QRect, QSettings, Qt, QTimer
from PySide6.QtGui import (
    QAction,
    QActionGroup,
    QCloseEvent,
    QGuiApplication,
    QKeySequence,
    QResizeEvent,
    QShowEvent,
)
from PySide6.QtWidgets import (
    QApplication,
    QCheckBox,
    QComboBox,
    QDialog,
    QDockWidget,
    QHBoxLayout,
    QLabel,
    QMainWindow,
    QPlainTextEdit,
    QPushButton,
    QSizePolicy,
    QTabBar,
    QVBoxLayout,
    QWidget,
)

from app.core.alarms import READOUT_OF, AlarmConfig, parse_alarm
from app.core.calibration_procedures import CalibrationProfile, ProfileError
from app.core.calibration_procedures.profiles import read_profile_file
from app.core.devices import DeviceInfo
from app.core.filters import DEFAULT_FILTER, FILTERS, ONLINE_FILTERS
from app.core.measurement_log import MeasurementLog, default_log_path
from app.core.readout import SLOPE_UNITS
from app.core.recording import sample_recordings
from app.core.screen_fit import Rect, first_window_rect
from app.core.self_test import SelfTestReport
from app.gui import file_dialogs, help_dialogs, theme, wheel_guard
from app.gui.alarm_panel import AlarmPanel
from app.gui.arm_panel import ArmPanel
from app.gui.attitude_view import AttitudeView
from app.gui.banner import MessageBanner as ErrorBanner
from app.gui.bubble_level import BubbleLevel
from app.gui.calibration_wizard import CalibrationWizard
from app.gui.device_bar import DeviceBar
from app.gui.device_panel import DevicePanel
from app.gui.elided_label import ElidedLabel
from app.gui.field_view import FieldPresenter, FieldView  # magview #31
from app.gui.filter_panel import FilterPanel
from app.gui.health_lights import HealthLights
from app.gui.joint_panel import JointPanel
from app.gui.measure_panel import MeasurePanel
from app.gui.measurement_log_panel import MeasurementLogPanel
from app.gui.panel_scroller import PanelScroller
from app.gui.plots import LivePlots
from app.gui.presenter import LivePresenter
from app.gui.readouts import TiltReadouts
from app.gui.replay_bar import ReplayBar
from app.gui.simulator_panel import SimulatorPanel
from app.gui.status_fields import StatusField, StatusFields
from app.gui.user_settings import SettingsSections, check_settings, read_json, write_json
from app.services.devices import (
    DEFAULT_DEVICE_URL,
    available_devices,
    is_replay_url,
    replay_url,
)
from app.services.recording_control import recording_cost
from app.services.replay_control import replay_caption
from app.services.session import DeviceSession
from app.services.stream_status import StreamStatus

PLOT_WINDOWS_S = (2, 5, 10, 20, 30, 60)
READOUT_MIN_PX, READOUT_MAX_PX = 28, 96
"""Smallest and largest digits beside the level in the usual layout."""
INSTRUMENT_MAX_PX = 400
"""Largest digits in the full-screen instrument mode (they fill the half screen)."""
AVERAGING_S = (0.05, 0.2, 0.5, 1.0, 2.0, 5.0)
LEVEL_RANGES_DEG = (0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 90.0)
FILLING_DOCKS = frozenset({"plots", "messages", "attitude3d", "field"})  # magview #31: +field
"""Docks whose contents fill any size (the others scroll inside their dock)."""
DEVICE_MESSAGE_WARNING = 2
DEVICE_MESSAGE_ERROR = 3
"""Levels of a device's own messages (the link protocol's LOG levels)."""


RECORDING_FILTER = "Recordings (*.csv)"
COMPRESSED_RECORDING_FILTER = "Compressed recordings (*.csv.gz)"


def recordings_dir() -> Path:
    """Where recordings go by default: the user's documents folder."""
    from platformdirs import user_documents_dir

    return Path(user_documents_dir()) / "Inclinometer recordings"


def format_age(age: timedelta) -> str:
    """A short human age: '5 min', '3 h', '12 d'."""
    seconds = max(0.0, age.total_seconds())
    if seconds < 3600:
        return f"{seconds / 60:.0f} min"
    if seconds < 86400 * 2:
        return f"{seconds / 3600:.0f} h"
    return f"{seconds / 86400:.0f} d"


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
        self._start_alarms = alarms
        self.sections = SettingsSections(settings, self.show_error)
        """Components that keep a dict of settings register here (e.g. the alarms:
        ``window.sections.register("alarms", config.to_dict, load)``)."""
        self._instrument_mode = False
        self._help_dialogs: dict[str, QDialog] = {}
        self._layout_before_instrument: dict | None = None
        self._calibration_profile: CalibrationProfile | None = None
        self.setWindowTitle("Inclinometer")
        self.setWindowIcon(theme.app_icon())
        self.setDockOptions(
            QMainWindow.DockOption.AnimatedDocks | QMainWindow.DockOption.AllowTabbedDocks
        )

        # Device bar.
        self.device_bar = DeviceBar(self)
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, self.device_bar)
        self.addToolBarBreak()
        self.replay_bar = ReplayBar(self)
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, self.replay_bar)
        self.replay_bar.hide()

        # Central level view.
        self.banner = ErrorBanner()
        self.level = BubbleLevel()
        self.readouts = TiltReadouts()
        self.truth_label = ElidedLabel()
        self.truth_label.setObjectName("dimLabel")
        self.truth_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.setCentralWidget(self._build_level_view())

        # Docks.
        self.plots = LivePlots()
        self.filter_panel = FilterPanel()
        self.simulator_panel = SimulatorPanel()
        self.device_panel = DevicePanel()
        self.messages = QPlainTextEdit()
        self.messages.setReadOnly(True)
        self.messages.setMaximumBlockCount(2000)
        self.docks: dict[str, QDockWidget] = {}
        plots_host = self._build_plots_host()
        self._add_dock("plots", "Live plots", plots_host, Qt.DockWidgetArea.BottomDockWidgetArea)
        self._add_dock("filter", "Filter", self.filter_panel, Qt.DockWidgetArea.RightDockWidgetArea)
        self._add_dock(
            "simulator", "Simulator", self.simulator_panel, Qt.DockWidgetArea.RightDockWidgetArea
        )
        self._add_dock("device", "Device", self.device_panel, Qt.DockWidgetArea.RightDockWidgetArea)
        self.measure_panel = MeasurePanel(session)
        self.measure_panel.tareRequested.connect(session.requestTareReference)
        right = Qt.DockWidgetArea.RightDockWidgetArea
        self._add_dock("measure", "Measure", self.measure_panel, right)
        # The 3D view and the arm want width: they join the wide bottom group, which keeps
        # the right group to five short titles.
        bottom = Qt.DockWidgetArea.BottomDockWidgetArea
        self.attitude_view = AttitudeView()
        self._add_dock("attitude3d", "3D view", self.attitude_view, bottom)
        self.arm_panel = ArmPanel()
        self._add_dock("arm", "Arm", self.arm_panel, bottom)
        self._add_dock("messages", "Messages", self.messages, bottom)
        self.tabifyDockWidget(self.docks["filter"], self.docks["simulator"])
        self.tabifyDockWidget(self.docks["simulator"], self.docks["device"])
        self.tabifyDockWidget(self.docks["device"], self.docks["measure"])
        self.tabifyDockWidget(self.docks["plots"], self.docks["messages"])
        self._build_alarms_and_log()
        self._build_joint_dock()
        self.tabifyDockWidget(self.docks["joint"], self.docks["attitude3d"])
        self.tabifyDockWidget(self.docks["attitude3d"], self.docks["arm"])
        self.docks["attitude3d"].hide()  # opened from the View menu (then in this tab group)
        # --- magview (#31): the Field dock, beside the live plots, for a source with a field ---
        self.field_view = FieldView()
        self._add_dock("field", "Magnetic field", self.field_view, bottom)
        self.tabifyDockWidget(self.docks["plots"], self.docks["field"])
        self.docks["field"].hide()
        # --- end magview ---
        self.docks["arm"].hide()
        self.docks["plots"].raise_()
        self.docks["filter"].raise_()
        self._default_state = self.saveState()
        """The docks as first built, for View ▸ Reset layout."""
        self._default_layout_pending = True

        # Status bar: fields most important first; those that do not fit are hidden whole.
        self.status_device = StatusField("No device")
        self.status_rate = StatusField()
        self.status_filter = StatusField()
        self.status_fps = ElidedLabel("999 fps")
        self.status_fps.setMinimumWidth(self.status_fps.sizeHint().width())  # never cut
        self.status_fps.setText("")
        self.status_calibration = StatusField()
        self.status_calibration.setObjectName("calibrationStatus")
        self.status_tare = StatusField()
        self.status_recording = StatusField()
        self.health_lights = HealthLights()
        self.health_lights.resetRequested.connect(self._reset_health)
        self.status_fields = StatusFields(
            self.statusBar(),
            [self.status_recording, self.status_tare, self.status_calibration,
             self.status_device, self.status_filter, self.status_rate],
            [self.health_lights, self.status_fps],
        )
        self._fault_shown = ""

        self._build_menus()

        # Live presenter.
        self.presenter = LivePresenter(
            session, self.level, self.readouts, self.plots, self.truth_label, self.filter_panel,
            self,
        )
        self.presenter.framesPerSecond.connect(
            lambda fps: self.status_fps.setText(f"{fps:.0f} fps")
        )
        # The 3D view and the arm follow the current device (live and replay).
        # While the Joint dock has sensors, they drive both instead (one body per sensor).
        # The arm is solved only while someone can see it (see _on_device_attitude).
        self._device_q = None
        self.presenter.attitudeChanged.connect(self._on_device_attitude)
        # --- magview (#31): the field views follow the frame clock; shown while a field comes ---
        self.field_presenter = FieldPresenter(session, self.field_view, self)
        self.presenter.clock.tick.connect(self.field_presenter.refresh)
        self.field_presenter.availabilityChanged.connect(self.docks["field"].setVisible)
        self.field_presenter.problem.connect(self.show_error)
        self.sections.register("field_reference", self.field_presenter.settings_dict,
                               self.field_presenter.apply_settings)
        # --- end magview ---
        self.joint_panel.attitudesChanged.connect(self._on_group_attitudes)
        self.docks["arm"].visibilityChanged.connect(
            lambda shown: shown and self._device_q is not None
            and not self.joint_panel.has_sensors
            and self.arm_panel.set_device_orientation(self._device_q)
        )
        self.arm_panel.poseChanged.connect(
            lambda pose: self.attitude_view.set_arm(
                pose.points, pose.rotations, self.arm_panel.sensor_links
            )
        )

        # Wiring: GUI -> session (queued to the worker) and worker -> GUI.
        self.device_bar.connectRequested.connect(self.connect_device)
        self.device_bar.disconnectRequested.connect(session.requestDisconnect)
        self.device_bar.refreshRequested.connect(self.refresh_devices)
        self.filter_panel.filterRequested.connect(session.requestFilter)
        self.filter_panel.parameterChanged.connect(session.requestFilterParameter)
        self.filter_panel.comparisonsRequested.connect(session.requestComparisons)
        session.comparisonsChanged.connect(self._on_comparisons_changed)
        session.calibrationChanged.connect(self._on_calibration_changed)
        session.tareChanged.connect(self._on_tare_changed)
        session.reconnecting.connect(self._on_reconnecting)
        session.recordingChanged.connect(self._on_recording_changed)
        self.replay_bar.control.connect(session.requestReplayControl)
        self.plots.rangeSelected.connect(self.show_range_statistics)
        self.simulator_panel.deviceRequested.connect(self.connect_device)
        self.simulator_panel.targetChanged.connect(session.requestSimulatorTarget)
        session.connected.connect(self._on_connected)
        session.disconnected.connect(self._on_disconnected)
        session.error.connect(self.show_error)
        session.notice.connect(self.show_notice)
        session.deviceMessage.connect(self._on_device_message)
        self.device_panel.selfTestRequested.connect(session.requestSelfTest)
        session.selfTestAvailable.connect(self.device_panel.set_self_test_available)
        session.selfTestFinished.connect(self._on_self_test_finished)
        session.faultEvents.connect(self._on_fault_events)
        session.status.connect(self._on_status)
        session.filterChanged.connect(self._on_filter_changed)

        self._awaiting_board = False
        self.calibration_wizard: CalibrationWizard | None = None
        self._show_calibration(None)
        self._restore_settings()
        self.refresh_devices()
        chosen_filter = filter_name or str(self.settings.value("filter", DEFAULT_FILTER))
        if chosen_filter not in ONLINE_FILTERS:  # unknown, or offline (never live)
            chosen_filter = DEFAULT_FILTER
        session.requestFilter.emit(chosen_filter)
        saved = str(self.settings.value("comparisons", "")).split(",")
        compared = [name for name in saved if name in ONLINE_FILTERS]
        if compared:
            session.requestComparisons.emit(compared)
        url = device_url or str(self.settings.value("device_url", DEFAULT_DEVICE_URL))
        saved_parameters = read_json(self.settings, f"filter_parameters/{chosen_filter}")
        if isinstance(saved_parameters, dict):
            names = {spec.name for spec in FILTERS[chosen_filter].parameters}
            for key, value in saved_parameters.items():
                if key in names:
                    session.requestFilterParameter.emit(key, value)
        self.presenter.start()
        self.connect_device(url)
        theme.notifier().changed.connect(self._on_theme_changed)
        if settings_problem:
            self.show_error(settings_problem)
        # The keys (H, Space, ...) go to the instrument from the start, not to the device
        # field (H typed "h" into the URL there, and Enter then connected to it).
        self.level.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.level.setFocus(Qt.FocusReason.OtherFocusReason)

    # -- construction -----------------------------------------------------------------------
    def _build_level_view(self) -> QWidget:
        view = QWidget()
        outer = QVBoxLayout(view)
        outer.setContentsMargins(12, 8, 12, 8)
        outer.addWidget(self.banner)
        row = QHBoxLayout()
        self._level_row = row
        self.level.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        row.addWidget(self.level, 3)
        side = QVBoxLayout()
        # The digits grow into the height beside the level (no empty space under them).
        self.readouts.setAutoScale(True, READOUT_MAX_PX, READOUT_MIN_PX, (2, 1))
        side.addWidget(self.readouts, 1)
        self.controls = QWidget()
        controls = QHBoxLayout(self.controls)
        controls.setContentsMargins(0, 0, 0, 0)
        self.unit_combo = QComboBox()
        for unit in SLOPE_UNITS.values():
            self.unit_combo.addItem(unit.title, unit.key)
        self.unit_combo.setToolTip("Units of roll, pitch and tilt")
        self.averaging_combo = QComboBox()
        for seconds in AVERAGING_S:
            self.averaging_combo.addItem(f"avg {seconds:g} s", seconds)
        self.averaging_combo.setToolTip("The readouts show the mean over this time")
        self.range_combo = QComboBox()
        for degrees in LEVEL_RANGES_DEG:
            self.range_combo.addItem(f"±{degrees:g}°", degrees)
        self.range_combo.setToolTip("Full scale of the bubble level")
        self.hold_button = QPushButton("Hold")
        self.hold_button.setCheckable(True)
        self.hold_button.setToolTip("Freeze the readouts (H)")
        self.hold_button.toggled.connect(lambda on: self.presenter.set_hold(on))
        # H is the window's (the button is hidden in the full-screen instrument).
        self.hold_action = QAction("Hold", self)
        self.hold_action.setShortcut(QKeySequence("H"))
        self.hold_action.triggered.connect(self.hold_button.toggle)
        self.addAction(self.hold_action)
        for widget in (self.unit_combo, self.averaging_combo, self.range_combo, self.hold_button):
            controls.addWidget(widget)
        side.addWidget(self.controls)
        row.addLayout(side, 2)
        outer.addLayout(row, 1)
        outer.addWidget(self.truth_label)
        return view

    def _build_plots_host(self) -> QWidget:
        host = QWidget()
        layout = QVBoxLayout(host)
        layout.setContentsMargins(4, 0, 4, 4)
        bar = QHBoxLayout()
        bar.addWidget(QLabel("Window"))
        self.window_combo = QComboBox()
        for seconds in PLOT_WINDOWS_S:
            self.window_combo.addItem(f"{seconds} s", seconds)
        self.window_combo.setCurrentIndex(self.window_combo.findData(10))
        self.window_combo.currentIndexChanged.connect(self._on_plot_window_changed)
        bar.addWidget(self.window_combo)
        self.range_box = QCheckBox("Select range")
        self.range_box.setToolTip("Drag a time range on the angle plot for its statistics")
        self.range_box.toggled.connect(self._on_range_toggled)
        bar.addWidget(self.range_box)
        self.range_label = QLabel()
        self.range_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        bar.addWidget(self.range_label, 1)
        bar.addStretch(1)
        layout.addLayout(bar)
        layout.addWidget(self.plots, 1)
        return host

    def _add_dock(self, key: str, title: str, widget: QWidget, area: Qt.DockWidgetArea) -> None:
        dock = QDockWidget(title, self)
        dock.setObjectName(f"dock-{key}")
        if key not in FILLING_DOCKS:
            # Panels scroll rather than forcing their full size on the window (the Arm panel
            # alone wants 812 px of height, the Joint panel 1079 px of width): the window
            # fits a 1366x768 screen whatever is open, and a narrow dock cuts nothing off.
            right = area == Qt.DockWidgetArea.RightDockWidgetArea
            widget = PanelScroller(widget, keeps_width=right)
            if right:
                widget.wantsWidth.connect(lambda width, d=dock: self.resizeDocks(
                    [d], [width], Qt.Orientation.Horizontal))
        dock.setWidget(widget)
        self.addDockWidget(area, dock)
        self.docks[key] = dock
        # Opened from the View menu: in front of its tab group, not behind another tab.
        dock.toggleViewAction().triggered.connect(
            lambda checked, d=dock: checked and self.raise_dock(d))
        dock.dockLocationChanged.connect(lambda _area: self.tidy_tab_bars())
        dock.topLevelChanged.connect(lambda _floating: self.tidy_tab_bars())

    def raise_dock(self, dock: QDockWidget) -> None:
        """Show ``dock`` in front of its tab group."""
        dock.show()
        dock.raise_()
        self.tidy_tab_bars()

    def tidy_tab_bars(self) -> None:
        """The docks' tab bars show whole titles and scroll (arrows) when they do not fit.
        Qt makes these bars as docks are tabbed, so this runs after every change."""
        for bar in self.findChildren(QTabBar):
            if bar.parent() is not self:  # only the main window's dock tab bars
                continue
            if bar.elideMode() != Qt.TextElideMode.ElideNone:
                bar.setElideMode(Qt.TextElideMode.ElideNone)
            if not bar.usesScrollButtons():
                bar.setUsesScrollButtons(True)

    def reset_layout(self) -> None:
        """View ▸ Reset layout: every dock where and as large as at the first start."""
        if self._instrument_mode:
            self.set_instrument_mode(False)
        for dock in self.docks.values():
            dock.setFloating(False)
        self.restoreState(self._default_state)
        self.docks["plots"].raise_()
        self.docks["filter"].raise_()
        self.tidy_tab_bars()
        # Dock sizes stick only once the restored layout is in place (as at the first show).
        QTimer.singleShot(0, self, self._apply_default_layout)

    def _build_menus(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        open_action = QAction("&Open recording…", self)
        open_action.setShortcut(QKeySequence.StandardKey.Open)
        open_action.triggered.connect(lambda: self.open_recording())
        file_menu.addAction(open_action)
        samples_menu = file_menu.addMenu("Sample &recordings")
        for path in sample_recordings():
            action = QAction(path.stem, self)
            action.triggered.connect(lambda _=False, p=path: self.open_recording(str(p)))
            samples_menu.addAction(action)
        export_plots = QAction("&Export plots…", self)
        export_plots.setToolTip("Save the live plots as PNG or SVG")
        export_plots.triggered.connect(lambda: self.export_plots())
        file_menu.addAction(export_plots)
        self.record_action = QAction("&Record…", self)
        self.record_action.setCheckable(True)
        self.record_action.setShortcut(QKeySequence("Ctrl+R"))
        self.record_action.triggered.connect(self._on_record_triggered)
        file_menu.addAction(self.record_action)
        file_menu.addSeparator()
        quit_action = QAction("&Quit", self)
        quit_action.setShortcut(QKeySequence.StandardKey.Quit)
        quit_action.triggered.connect(self.close)
        file_menu.addAction(quit_action)
        calibration_menu = self.menuBar().addMenu("&Calibration")
        self.wizard_action = QAction("Calibration &wizard…", self)
        self.wizard_action.triggered.connect(self.open_calibration_wizard)
        self.allan_action = QAction("&Allan variance: noise figures…", self)
        self.allan_action.triggered.connect(self.open_allan_page)
        self.tare_action = QAction("&Tare: take the current attitude as level", self)
        self.tare_action.setShortcut(QKeySequence("Ctrl+T"))
        self.tare_action.triggered.connect(self.session.requestTare)
        self.clear_tare_action = QAction("&Clear tare", self)
        self.clear_tare_action.triggered.connect(self.session.requestClearTare)
        self.no_calibration_action = QAction("Run &uncalibrated", self)
        self.no_calibration_action.setToolTip(
            "Disable the device's profile; remembered across reconnects and restarts")
        self.no_calibration_action.triggered.connect(self.session.requestNoCalibration)
        self.stored_profile_action = QAction("Use the &stored profile", self)
        self.stored_profile_action.triggered.connect(self.session.requestStoredProfile)
        self.delete_profile_action = QAction("&Delete profile", self)
        self.delete_profile_action.setToolTip(
            "The profile moves to the profiles' history folder; Import profile brings it back")
        self.delete_profile_action.triggered.connect(self.session.requestDeleteProfile)
        self.import_action = QAction("&Import profile…", self)
        self.import_action.triggered.connect(self.import_profile)
        self.export_action = QAction("&Export profile…", self)
        self.export_action.triggered.connect(self.export_profile)
        for action in (
            self.wizard_action, self.allan_action, None, self.tare_action,
            self.clear_tare_action, None,
            self.no_calibration_action, self.stored_profile_action,
            self.delete_profile_action, self.import_action, self.export_action,
        ):
            if action is None:
                calibration_menu.addSeparator()
            else:
                calibration_menu.addAction(action)
        edit_menu = self.menuBar().addMenu("&Edit")
        self.copy_action = QAction("&Copy reading", self)
        self.copy_action.setShortcut(QKeySequence.StandardKey.Copy)
        self.copy_action.setToolTip("Copy roll, pitch and tilt as text, in the chosen units")
        self.copy_action.triggered.connect(self.copy_reading)
        edit_menu.addAction(self.copy_action)
        self.hold_action.setText("&Hold readouts")
        edit_menu.addAction(self.hold_action)
        self.store_action.setText("&Store reading")
        edit_menu.addAction(self.store_action)
        self._build_sensors_menu()
        view_menu = self.menuBar().addMenu("&View")
        for dock in self.docks.values():
            view_menu.addAction(dock.toggleViewAction())
        self.reset_layout_action = QAction("&Reset layout", self)
        self.reset_layout_action.setToolTip("Every dock back where it was at the first start")
        self.reset_layout_action.triggered.connect(self.reset_layout)
        view_menu.addAction(self.reset_layout_action)
        view_menu.addSeparator()
        self.instrument_action = QAction("&Full-screen instrument", self)
        self.instrument_action.setCheckable(True)
        self.instrument_action.setShortcut(QKeySequence("F11"))
        self.instrument_action.setToolTip("Big digits and the bubble only (F11 or Esc leaves)")
        self.instrument_action.toggled.connect(self.set_instrument_mode)
        view_menu.addAction(self.instrument_action)
        self.leave_instrument_action = QAction("&Leave full screen", self)
        self.leave_instrument_action.setShortcut(QKeySequence(Qt.Key.Key_Escape))
        self.leave_instrument_action.setEnabled(False)
        self.leave_instrument_action.triggered.connect(lambda: self.set_instrument_mode(False))
        view_menu.addAction(self.leave_instrument_action)
        theme_menu = view_menu.addMenu("&Theme")
        self.theme_actions: dict[str, QAction] = {}
        group = QActionGroup(self)
        for name, title in theme.CHOICES:
            action = QAction(title, self)
            action.setCheckable(True)
            action.triggered.connect(lambda _=False, n=name: self.set_theme(n))
            group.addAction(action)
            theme_menu.addAction(action)
            self.theme_actions[name] = action
        # The window keeps these working while the menu bar is hidden (full screen).
        for action in (self.copy_action, self.instrument_action, self.leave_instrument_action):
            self.addAction(action)
        help_menu = self.menuBar().addMenu("&Help")
        self.guide_action = QAction("&User guide", self)
        self.guide_action.setShortcut(QKeySequence.StandardKey.HelpContents)
        self.guide_action.triggered.connect(self.show_user_guide)
        self.shortcuts_action = QAction("&Keyboard shortcuts", self)
        self.shortcuts_action.triggered.connect(self.show_shortcut_sheet)
        about = QAction("&About Inclinometer", self)
        about.triggered.connect(self.show_about)
        for action in (self.guide_action, self.shortcuts_action, about):
            help_menu.addAction(action)

    # -- actions ----------------------------------------------------------------------------
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

    # -- worker events ----------------------------------------------------------------------
    # -- time-range statistics -----------------------------------------------------------------
    def _on_range_toggled(self, enabled: bool) -> None:
        self.plots.set_range_selection(enabled)
        if not enabled:
            self.range_label.setText("")

    def show_range_statistics(self, *_args: object) -> None:
        """Statistics per angle over the range selected on the angle plot."""
        selected = self.plots.selected_range()
        if selected is None:
            return
        result = self.presenter.range_statistics(*selected)
        if result is None:
            self.range_label.setText("No data in the selected range")
            return
        parts = [
            f"{name} mean {a.mean:+.3f}° std {a.std:.3f}° min {a.minimum:+.3f}° "
            f"max {a.maximum:+.3f}° spread {a.spread:.3f}°"
            for name, a in (("roll", result.roll), ("pitch", result.pitch))
        ]
        self.range_label.setText(
            f"{result.duration_s:.2f} s, {result.samples:,} samples · " + " · ".join(parts)
        )

    # -- recording and replay ------------------------------------------------------------------
    def open_recording(self, path: str | None = None) -> None:
        """Replay a recording through the whole pipeline (it becomes the device)."""
        if path is None:
            path = file_dialogs.open_file_name(
                self, "Open recording", "Recordings (*.csv *.csv.gz);;All files (*)",
                recordings_dir())
            if not path:
                return
        self.connect_device(replay_url(path))

    def export_plots(self, path: str | None = None) -> None:
        """Save the plots as they are shown: PNG (raster) or SVG (vector), by file suffix."""
        if path is None:
            path, _ = file_dialogs.save_file_name(
                self, "Export plots", "inclinometer-plots.png",
                "PNG image (*.png);;SVG drawing (*.svg)", recordings_dir(),
            )
            if not path:
                return
        try:
            self.plots.export(path)
        except (OSError, ValueError) as exc:
            self.show_error(f"Plots not exported: {exc}")
            return
        self.log(f"Exported the plots to {path}")

    def start_recording(self, path: str, note: str = "") -> None:
        self.session.requestStartRecording.emit(path, note)

    def _on_record_triggered(self, checked: bool) -> None:
        if not checked:
            self.session.requestStopRecording.emit()
            return
        self.record_action.setChecked(False)  # until the worker says it records
        if self.session.device_info is None:
            self.show_error("Connect a device before recording.")
            return
        folder = recordings_dir()
        folder.mkdir(parents=True, exist_ok=True)
        name = time.strftime("inclinometer-%Y%m%d-%H%M%S.csv")
        info = self.session.device_info
        cost = recording_cost(folder, info.odr_hz, reference=info.url.startswith("sim:"))
        path, chosen = file_dialogs.save_file_name(
            self, f"Record to ({cost})", name,
            f"{RECORDING_FILTER};;{COMPRESSED_RECORDING_FILTER}", folder,
        )
        if not path:
            return
        if chosen == COMPRESSED_RECORDING_FILTER and not path.lower().endswith(".gz"):
            path += ".gz"
        self.log(f"Recording to {path}: {cost}")
        self.start_recording(path)

    def _on_recording_changed(self, status) -> None:
        recording = status is not None and status.state == "recording"
        self.record_action.setChecked(recording)
        if status is None:
            self.status_recording.setText("")
            return
        self.status_recording.setText(
            f"● REC {status.path.name}  {status.duration_s:.0f} s, {status.rows_written:,} rows"
            if recording else f"Recording {status.state}"
        )
        self.status_recording.setStyleSheet(f"color: {theme.ALARM_RED}; font-weight: bold;")

    def _on_self_test_finished(self, report: SelfTestReport | None, error: str) -> None:
        self.device_panel.show_self_test(report, error)
        if report is None:
            self.show_error(f"Self-test not run: {error}")
        else:
            self.log(report.summary(), error=not report.passed)

    def _on_device_message(self, level: int, text: str) -> None:
        """A message from the device itself (the board's firmware): errors also on the banner."""
        info = self.session.device_info
        source = info.name if info is not None else "device"
        if level >= DEVICE_MESSAGE_ERROR:
            self.show_error(f"{source}: {text}")
        else:
            prefix = "warning: " if level == DEVICE_MESSAGE_WARNING else ""
            self.log(f"{source}: {prefix}{text}")

    def _on_fault_events(self, events: list) -> None:
        """The detector's events go to Messages (faults in red)."""
        for event in events:
            self.log(f"sensor {event.channel} {event.kind} at {event.t:.2f} s: {event.message}",
                     error=event.severity == "fault")

    def _show_health(self, health: dict[str, str] | None, fault: str) -> None:
        """Lights, and the banner while the reading cannot be trusted."""
        self.health_lights.show_health(health)
        if fault and fault != self._fault_shown and not self._awaiting_board:
            self.banner.show_message(f"The reading cannot be trusted: {fault}. Click the "
                                     "channel lights in the status bar to reset latched faults.")
        elif not fault and self._fault_shown and not self._awaiting_board:
            self.banner.hide()
        self._fault_shown = fault

    def _reset_health(self) -> None:
        self.session.requestHealthReset.emit()
        self.log("Fault detection reset: latched faults cleared, noise levels learnt afresh")

    def _on_reconnecting(self, message: str) -> None:
        self._awaiting_board = True
        self.device_bar.set_state("stalled", "Unplugged — waiting for the board…")
        self.banner.show_message(message)
        self.log(message, error=True)

    def _on_connected(self, info: DeviceInfo) -> None:
        if self._awaiting_board:  # the board is back: the unplug warning is over
            self._awaiting_board = False
            self.banner.hide()
        self.device_bar.select_url(info.url)
        self.device_bar.set_state("streaming", "Streaming")
        self.device_panel.show_info(info)
        self.status_device.setText(f"{replay_caption(info) or info.name}  ·  {info.odr_hz:.1f} Hz")
        self.replay_bar.setVisible(is_replay_url(info.url))
        is_sim = urlsplit(info.url).scheme == "sim"
        if is_sim:
            self.simulator_panel.show_url(info.url)
            params = info.extra.get("scenario_params", {})
            if "roll" in params and "pitch" in params:
                self.simulator_panel.set_target(float(params["roll"]), float(params["pitch"]))
        else:
            self.simulator_panel.set_interactive(False)
        self.settings.setValue("device_url", info.url)
        self.log(f"Connected to {info.name} ({info.url}), id {info.unique_id}")

    def _on_disconnected(self, reason: str) -> None:
        if reason:
            self.device_bar.set_state("error", "Disconnected: error")
        else:
            self.device_bar.set_state("disconnected", "Disconnected")
        self.status_device.setText("No device")
        self.status_rate.setText("")
        self._show_health(None, "")
        self.simulator_panel.set_interactive(False)
        self.log("Disconnected" + (f": {reason}" if reason else ""))

    def _on_status(self, status: StreamStatus) -> None:
        if self.range_box.isChecked():
            self.show_range_statistics()
        if status.replay is not None:
            self.replay_bar.show_position(*status.replay)
        self._show_health(status.health, status.fault)
        if status.overview is not None:
            self.replay_bar.show_overview(status.overview, status.gaps_s or ())
        stalled = status.measured_rate_hz <= 0.0 and status.samples > 0
        lost = f"  ·  lost {status.lost_samples:,}" if status.lost_samples else ""
        text = f"{status.measured_rate_hz:.1f} Hz{lost}"
        if status.replay is not None and not status.replay.playing:  # not stalled: paused
            stalled, text = False, "Replay ended" if status.replay.ended else "Replay paused"
        self.device_bar.set_state("stalled" if stalled else "streaming", text)
        self.status_rate.setText(
            f"{status.samples:,} samples  ·  lost {status.lost_samples:,}  ·  "
            f"pipeline {100 * status.pipeline_load:.1f} %"
        )
        self.device_panel.show_status(status)

    def _on_filter_changed(self, name: str, values: dict) -> None:
        self.filter_panel.show_filter(name, values)
        self.status_filter.setText(f"Filter: {FILTERS[name].title}")
        self.settings.setValue("filter", name)
        write_json(self.settings, f"filter_parameters/{name}", values)

    # -- alarms and the measurement log -------------------------------------------------------
    def _build_alarms_and_log(self) -> None:
        """The Alarms dock, the alarm banner, and the Measurement log dock (Space stores)."""
        self.alarm_banner = ErrorBanner()
        self.centralWidget().layout().insertWidget(1, self.alarm_banner)
        self._alarms_shown: tuple[tuple[str, str], ...] = ()
        self.alarm_panel = AlarmPanel()
        self.alarm_panel.alarmsChanged.connect(self.apply_alarms)
        self._add_dock("alarms", "Alarms", self.alarm_panel, Qt.DockWidgetArea.RightDockWidgetArea)
        self.tabifyDockWidget(self.docks["measure"], self.docks["alarms"])
        log, problem = MeasurementLog.load(default_log_path())
        self.log_panel = MeasurementLogPanel(
            log, lambda label: self.presenter.current_reading(label))
        self.log_panel.problem.connect(self.show_error)
        self._add_dock("log", "Measurement log", self.log_panel,
                       Qt.DockWidgetArea.BottomDockWidgetArea)
        self.tabifyDockWidget(self.docks["messages"], self.docks["log"])
        if problem:
            QTimer.singleShot(0, lambda: self.show_error(problem))
        # Space stores anywhere in the window, also on a focused button (a digital level's
        # one key); text and number fields keep it for typing.
        self.store_action = QAction("Store reading", self)
        self.store_action.setShortcut(QKeySequence(Qt.Key.Key_Space))
        self.store_action.triggered.connect(lambda: self.log_panel.store())
        self.addAction(self.store_action)
        self.session.alarmEvents.connect(self._on_alarm_events)
        self.session.status.connect(self._on_alarm_status)
        self.session.disconnected.connect(lambda _reason: self._show_alarms(()))
        remembered = self.sections.register(
            "alarms", lambda: self.alarm_panel.config().to_dict(),
            lambda stored: self.apply_alarms(AlarmConfig.from_dict(stored)))
        if self._start_alarms is not None:  # inclinometer --alarm SPEC ...
            self.apply_alarms(self._start_alarms)
        elif not remembered:
            self.apply_alarms(self.alarm_panel.config())

    def apply_alarms(self, config: AlarmConfig) -> None:
        """Use these alarms (the worker evaluates them) and show them in the panel."""
        if config != self.alarm_panel.config():
            self.alarm_panel.set_config(config)
        self.session.requestAlarms.emit(config)

    def _on_alarm_events(self, events: list) -> None:
        for event in events:
            self.log(event.message())
        if self.alarm_panel.config().sound and any(e.raised for e in events):
            QApplication.beep()

    def _on_alarm_status(self, status: StreamStatus) -> None:
        self._show_alarms(status.alarms)
        if status.alarm_marks_s is not None:
            self.replay_bar.overview.show_alarm_marks(status.alarm_marks_s)

    def _show_alarms(self, alarms: tuple[tuple[str, str], ...]) -> None:
        """Readouts and bubble red, and the banner, while any alarm is raised."""
        if alarms == self._alarms_shown:
            return
        self._alarms_shown = alarms
        quantities = {quantity for quantity, _spec in alarms}
        self.readouts.setAlarm(READOUT_OF[q] for q in quantities)
        self.level.setAlarm(bool(alarms))
        self.alarm_panel.show_active(quantities)
        if alarms:
            listed = " · ".join(parse_alarm(spec).describe() for _q, spec in alarms)
            self.alarm_banner.show_message(f"<b>ALARM</b>&nbsp;&nbsp;{listed}")
        else:
            self.alarm_banner.hide()

    # -- calibration --------------------------------------------------------------------------
    def open_calibration_wizard(self) -> CalibrationWizard | None:
        """Open the (non-modal) wizard for the connected device."""
        if self.session.device_info is None:
            self.show_error("Connect a device before calibrating it.")
            return None
        if self.calibration_wizard is not None and self.calibration_wizard.isVisible():
            self.calibration_wizard.raise_()
            return self.calibration_wizard
        wizard = CalibrationWizard(self.session, self)
        wizard.profileAccepted.connect(self.session.requestProfile)
        self.calibration_wizard = wizard
        wizard.show()
        return wizard

    def open_allan_page(self):
        """The Allan variance page (a window); its button tunes the filters' noise figures."""
        from app.gui.allan_page import AllanPage

        page = getattr(self, "allan_page", None)
        if page is None:
            def current(name: str, keys: list[str]) -> dict[str, float] | None:
                running = self.session.pipeline.filter
                if running.name != name:
                    return None
                return {key: float(running.get_parameter(key)) for key in keys}

            page = AllanPage(settings=self.settings, current_parameters=current)
            page.parametersApplied.connect(self.apply_noise_parameters)
            self.allan_page = page
        page.show()
        page.raise_()
        return page

    def apply_noise_parameters(self, name: str, values: dict, source: str) -> None:
        """Set a filter's noise parameters (the running one live) and log where they came from."""
        listed = ", ".join(f"{key} = {value:.4g}" for key, value in values.items())
        if name == self.filter_panel.current_filter:
            for key, value in values.items():
                self.session.requestFilterParameter.emit(key, value)
            self.log(f"{name}: {listed} set from {source}")
        else:
            self.log(f"{name} (not running): {listed} from {source}; choose {name} and set "
                     "them again to use them")

    def import_profile(self, path: str | None = None) -> None:
        info = self.session.device_info
        if info is None:
            self.show_error("Connect the device the profile belongs to first.")
            return
        if path is None:
            path = file_dialogs.open_file_name(
                self, "Import calibration profile", "Calibration profiles (*.json)")
            if not path:
                return
        try:
            profile = read_profile_file(Path(path), info.unique_id)
        except (ProfileError, OSError) as exc:
            self.show_error(f"Profile not imported: {exc}")
            return
        self.session.requestProfile.emit(profile)
        self.log(f"Imported calibration profile {path}")

    def export_profile(self, path: str | None = None) -> None:
        info = self.session.device_info
        if info is None:
            self.show_error("Connect a device to export its profile.")
            return
        if path is None:
            path, _ = file_dialogs.save_file_name(
                self, "Export calibration profile", f"{info.unique_id}.json",
                "Calibration profiles (*.json)",
            )
            if not path:
                return
        try:
            self.session.profile_store.export(info.unique_id, path, overwrite=True)
        except (ProfileError, OSError) as exc:
            self.show_error(f"Profile not exported: {exc}")
            return
        self.log(f"Exported the calibration profile to {path}")

    # -- display: theme, clipboard, full-screen instrument ---------------------------------------
    def set_theme(self, choice: str) -> None:
        """Use a theme (``dark``, ``light``, ``high-contrast``) or follow the system."""
        app = QApplication.instance()
        if isinstance(app, QApplication):
            theme.apply_theme(app, choice)
        self.theme_actions[theme.choice()].setChecked(True)
        self.settings.setValue("theme", theme.choice())

    def _on_theme_changed(self, _name: str) -> None:
        """Colours set on single widgets follow the theme."""
        self._show_calibration(self._calibration_profile)
        self.status_tare.setStyleSheet(f"color: {theme.ACCENT}; font-weight: bold;")
        self.status_recording.setStyleSheet(f"color: {theme.ALARM_RED}; font-weight: bold;")

    def copy_reading(self) -> str:
        """Put the reading shown (roll, pitch, tilt in the chosen units) on the clipboard."""
        text = self.readouts.reading()
        if not text:
            self.statusBar().showMessage("No reading to copy", 3000)
            return ""
        QGuiApplication.clipboard().setText(text)
        self.statusBar().showMessage(f"Copied: {text}", 3000)
        return text

    @property
    def instrument_mode(self) -> bool:
        """Whether the window shows only the big digits and the bubble, full screen."""
        return self._instrument_mode

    def set_instrument_mode(self, enabled: bool) -> None:
        """Full-screen instrument (F11): bubble and big digits only, readable across a room;
        leaving (F11 or Esc) brings back the layout exactly as it was."""
        if enabled == self._instrument_mode:
            return
        self._instrument_mode = enabled
        self.instrument_action.setChecked(enabled)
        self.leave_instrument_action.setEnabled(enabled)
        if enabled:
            self._layout_before_instrument = {
                "state": self.saveState(),
                "geometry": self.saveGeometry(),
                "window_state": self.windowState(),
                "visible": [
                    widget for widget in (
                        self.menuBar(), self.statusBar(), self.controls, self.truth_label,
                        self.banner,
                    ) if widget.isVisible()
                ],
            }
            for widget in (
                *self.docks.values(), self.device_bar, self.replay_bar, self.menuBar(),
                self.statusBar(), self.controls, self.truth_label, self.banner,
            ):
                widget.hide()
            self.readouts.setAutoScale(True, INSTRUMENT_MAX_PX, READOUT_MIN_PX, (1, 2))
            self._level_row.setStretch(0, 1)
            self._level_row.setStretch(1, 1)
            self.showFullScreen()
            return
        saved = self._layout_before_instrument or {}
        self._layout_before_instrument = None
        self.readouts.setAutoScale(True, READOUT_MAX_PX, READOUT_MIN_PX, (2, 1))
        self._level_row.setStretch(0, 3)
        self._level_row.setStretch(1, 2)
        window_state = saved.get("window_state", Qt.WindowState.WindowNoState)
        if window_state & Qt.WindowState.WindowFullScreen:
            self.showFullScreen()
        elif window_state & Qt.WindowState.WindowMaximized:
            self.showMaximized()
        else:
            self.showNormal()
        if "geometry" in saved:
            self.restoreGeometry(saved["geometry"])
        for widget in saved.get("visible", ()):
            widget.show()
        if "state" in saved:
            self.restoreState(saved["state"])

    def _on_plot_window_changed(self, _index: int) -> None:
        self.plots.set_window(self.window_combo.currentData())
        self.settings.setValue("plot_window_s", self.window_combo.currentData())

    def _on_calibration_changed(self, profile: CalibrationProfile | None) -> None:
        self._show_calibration(profile)
        if profile is not None:
            self.log(f"Calibration applied: {profile.calibration.name} ({profile.method})")

    def _show_calibration(self, profile: CalibrationProfile | None) -> None:
        self._calibration_profile = profile
        if profile is None:
            self.status_calibration.setText("Uncalibrated")
            self.status_calibration.setStyleSheet(f"color: {theme.WARN_AMBER};")
            self.status_calibration.setToolTip("Run Calibration ▸ Calibration wizard")
            return
        self.status_calibration.setText(
            f"Calibrated: {profile.calibration.name} ({format_age(profile.age())} old)"
        )
        self.status_calibration.setStyleSheet(f"color: {theme.OK_GREEN};")
        temperature = (
            "" if profile.temperature_degc is None else f" at {profile.temperature_degc:.1f} °C"
        )
        self.status_calibration.setToolTip(
            f"{profile.method} profile made {profile.created_utc}{temperature}"
        )

    def _on_tare_changed(self, reference) -> None:
        if reference is None:
            self.status_tare.setText("")
            return
        angles = reference.reference_angles
        self.status_tare.setText(
            f"TARE at roll {float(angles.roll_deg):+.2f}°, pitch {float(angles.pitch_deg):+.2f}°"
        )
        self.status_tare.setStyleSheet(f"color: {theme.ACCENT}; font-weight: bold;")

    def _on_comparisons_changed(self, names: list) -> None:
        self.filter_panel.show_comparisons(names)
        self.plots.set_comparisons([(name, FILTERS[name].title) for name in names])
        self.settings.setValue("comparisons", ",".join(names))

    def _on_display_changed(self) -> None:
        self.presenter.settings.unit = self.unit_combo.currentData()
        self.presenter.settings.averaging_s = self.averaging_combo.currentData()
        self.level.setRange(self.range_combo.currentData())
        self.presenter.refresh()
        self.settings.setValue("unit", self.presenter.settings.unit)
        self.settings.setValue("averaging_s", self.presenter.settings.averaging_s)
        self.settings.setValue("range_deg", self.range_combo.currentData())

    # -- help ---------------------------------------------------------------------------------
    def file_paths(self) -> dict[str, str]:
        """Where the app keeps its files (shown in About)."""
        return {
            "Settings": self.settings.fileName(),
            "Calibration profiles": str(self.session.profile_store.base_dir),
            "Measurement log": str(default_log_path()),
            "Recordings": str(recordings_dir()),
            "Last folder of a file dialog": str(file_dialogs.last_folder() or "(none yet)"),
        }

    def _show_dialog(self, name: str, build) -> QDialog:
        """Show one of Help's dialogs (made once, then brought to the front)."""
        dialog = self._help_dialogs.get(name)
        if dialog is None:
            dialog = build()
            self._help_dialogs[name] = dialog
        dialog.show()
        dialog.raise_()
        return dialog

    def show_user_guide(self) -> QDialog:
        return self._show_dialog("guide", lambda: help_dialogs.user_guide(self))

    def show_shortcut_sheet(self) -> QDialog:
        return self._show_dialog(
            "shortcuts", lambda: help_dialogs.ShortcutSheet(self.menuBar(), self))

    def show_about(self) -> QDialog:
        old = self._help_dialogs.pop("about", None)  # the paths may have changed
        if old is not None:
            old.close()
            old.deleteLater()
        return self._show_dialog(
            "about", lambda: help_dialogs.about_dialog(self.file_paths(), self))

    # -- settings ---------------------------------------------------------------------------
    def fit_to_screen(self, available: QRect | None = None) -> None:
        """Take the screen's available area (the first start, or a remembered size that no
        longer fits): never larger than it."""
        if available is None:
            screen = self.screen() or QGuiApplication.primaryScreen()
            if screen is None:
                return
            available = screen.availableGeometry()
        rect = first_window_rect(
            Rect(available.x(), available.y(), available.width(), available.height()))
        self.setGeometry(rect.x, rect.y, rect.width, rect.height)

    def _fit_with_frame(self) -> None:
        """Once the window manager has framed the window: the frame fits the screen too."""
        frame, inner = self.frameGeometry(), self.geometry()
        margins = (inner.left() - frame.left(), inner.top() - frame.top(),
                   frame.right() - inner.right(), frame.bottom() - inner.bottom())
        screen = self.screen()
        if any(margins) and screen is not None and not self.isFullScreen():
            available = screen.availableGeometry()
            rect = first_window_rect(
                Rect(available.x(), available.y(), available.width(), available.height()),
                margins)
            self.setGeometry(rect.x, rect.y, rect.width, rect.height)

    def _restore_settings(self) -> None:
        geometry = self.settings.value("geometry")
        if geometry is None or not self.restoreGeometry(geometry):
            self.fit_to_screen()
        state = self.settings.value("window_state")
        if state is not None:
            self.restoreState(state)
        for combo, key, default in (
            (self.unit_combo, "unit", "deg"),
            (self.averaging_combo, "averaging_s", 0.5),
            (self.range_combo, "range_deg", 5.0),
        ):
            try:
                index = combo.findData(type(default)(self.settings.value(key, default)))
            except (TypeError, ValueError):
                index = -1
            combo.setCurrentIndex(index if index >= 0 else combo.findData(default))
            combo.currentIndexChanged.connect(self._on_display_changed)
        self._on_display_changed()
        try:
            window_s = int(self.settings.value("plot_window_s", 10))
        except (TypeError, ValueError):
            window_s = 10
        if self.window_combo.findData(window_s) >= 0:
            self.window_combo.setCurrentIndex(self.window_combo.findData(window_s))
        self.set_theme(str(self.settings.value("theme", theme.DEFAULT_CHOICE)))

    def showEvent(self, event: QShowEvent) -> None:
        super().showEvent(event)
        self.tidy_tab_bars()
        if self._default_layout_pending:
            self._default_layout_pending = False
            self.level.setFocus(Qt.FocusReason.OtherFocusReason)
            if self.settings.value("geometry") is None:
                QTimer.singleShot(0, self, self._fit_with_frame)  # the frame is known after show
            if self.settings.value("window_state") is None:
                # Dock sizes only stick once the window has its final size.
                QTimer.singleShot(0, self, self._apply_default_layout)

    def resizeEvent(self, event: QResizeEvent) -> None:
        super().resizeEvent(event)
        threshold = PanelScroller.KEEP_WIDTH_FROM_PX
        if (event.oldSize().width() >= threshold) != (event.size().width() >= threshold):
            for dock in self.docks.values():  # their minimum width changes at the threshold
                dock.widget().updateGeometry()

    def _apply_default_layout(self) -> None:
        height = max(300, int(self.height() * 0.45))
        # The panels take at most a third of a narrow window (1024 px: the level keeps room),
        # but never so little that they scroll sideways.
        fitting = max((dock.widget().fitting_width() for dock in self.docks.values()
                       if isinstance(dock.widget(), PanelScroller)
                       and self.dockWidgetArea(dock) == Qt.DockWidgetArea.RightDockWidgetArea),
                      default=0)
        width = max(min(400, int(self.width() * 0.3)), fitting)
        self.resizeDocks([self.docks["filter"]], [width], Qt.Orientation.Horizontal)
        self.resizeDocks([self.docks["plots"]], [height], Qt.Orientation.Vertical)

    def closeEvent(self, event: QCloseEvent) -> None:
        self.joint_panel.shutdown()
        self.presenter.stop()
        self.measure_panel.stop()
        saved = self._layout_before_instrument  # full screen: remember the usual layout
        self.settings.setValue("geometry", saved["geometry"] if saved else self.saveGeometry())
        self.settings.setValue("window_state", saved["state"] if saved else self.saveState())
        self.sections.save_all()
        self.settings.sync()
        self.session.shutdown()
        super().closeEvent(event)

    # -- several sensors and the joint angle (app/gui/joint_panel.py) ---------------------------
    def _build_joint_dock(self) -> None:
        self.joint_panel = JointPanel(parent=self)
        self._add_dock("joint", "Joint", self.joint_panel, Qt.DockWidgetArea.BottomDockWidgetArea)
        self.tabifyDockWidget(self.docks["plots"], self.docks["joint"])
        self.docks["joint"].hide()

    def _build_sensors_menu(self) -> None:
        menu = self.menuBar().addMenu("&Sensors")
        self.add_sensor_action = QAction("&Add sensor…", self)
        self.add_sensor_action.setToolTip("Open another device (URL) beside the others")
        self.add_sensor_action.triggered.connect(lambda: self._show_joint(
            self.joint_panel.ask_add_sensor))
        self.arm_action = QAction("Simulated &arm (2 links)", self)
        self.arm_action.triggered.connect(lambda: self._show_joint(self.joint_panel.add_arm))
        menu.addAction(self.add_sensor_action)
        menu.addAction(self.arm_action)

    def _on_device_attitude(self, q) -> None:
        """The main device's attitude: the 3D view and the arm, unless the Joint dock has
        sensors (then those are shown)."""
        if self.joint_panel.has_sensors:
            return
        self.attitude_view.set_attitude(q)
        self._device_q = q
        # The arm only while someone can see it (the Arm dock, or the arm in the 3D view):
        # solving it for every block costs as much as the bubble.
        if self.docks["arm"].isVisible() or self.attitude_view.showing_arm:
            self.arm_panel.set_device_orientation(q)

    def _on_group_attitudes(self, frame) -> None:
        """The Joint dock's sensors (a GroupFrame; None when they were removed): one body
        each in the 3D view, and the arm's links posed from them."""
        if frame is None:
            self.attitude_view.set_attitudes([])
            self.arm_panel.set_joint_angles(self.arm_panel.entered_angles(), observed=())
            return
        self.attitude_view.set_attitudes(frame.quaternions, frame.labels)
        n_links = self.arm_panel.arm.n_joints
        self.arm_panel.set_link_orientations(frame.link_quaternions(n_links),
                                             frame.measured_deg(n_links))

    def _show_joint(self, then) -> None:
        dock = self.docks["joint"]
        dock.show()
        dock.raise_()
        then()
