"""The Joint dock: several sensors at once and the live angle of the hinge between two of them.

The panel shows the :class:`~app.services.sensor_group.SensorGroup`'s sensors with their clock
alignment, lets the user pick the two links and the axis mode (estimated from the motion, or
entered as ``AX,AY,AZ:BX,BY,BZ`` in the two sensors' frames), and shows a large joint-angle
readout (units, averaging and hold as the tilt readout) and a live plot, fed by a
:class:`~app.services.joint_stream.JointStream` on a refresh timer. Views only: the maths is in
:mod:`app.core.joint`, :mod:`app.core.readout` and the services.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QInputDialog,
    QLabel,
    QLineEdit,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.core.readout import averaged_angle_deg
from app.gui import file_dialogs, theme
from app.gui.lazy_menu import lazy_menu_plot
from app.services.group_attitudes import GroupAttitudes
from app.services.joint_stream import JointStream
from app.services.sensor_group import SensorGroup
from app.services.session_replay import SessionReplay

ARM_URL = "sim://arm?seed=1&odr=104"
"""The "Simulated arm (2 links)" shortcut: its two sensors (``&sensor=1`` for the second)."""
PLOT_SPAN_S = 30.0
AVERAGING_S = (0.0, 0.25, 0.5, 1.0, 2.0)
UNITS = {"deg": ("°", 1.0), "rad": (" rad", math.pi / 180.0)}
REFRESH_MS = 33
READOUT_INTERVAL_S = 0.1


def _rate_text(drift_ppm: float, scale: float) -> str:
    """A clock's drift; a time-lapse simulator's clock runs several times the host's: a factor."""
    return f"{drift_ppm:+.0f} ppm" if abs(drift_ppm) < 1e4 else f"runs ×{1.0 / scale:.3f}"


def parse_axes_text(text: str) -> tuple[np.ndarray, np.ndarray]:
    """``AX,AY,AZ:BX,BY,BZ`` -> two unit vectors; ValueError with a message for the user."""
    parts = text.split(":")
    if len(parts) != 2:
        raise ValueError("write the axes as AX,AY,AZ:BX,BY,BZ (sensor A's frame : sensor B's)")
    axes = []
    for part in parts:
        try:
            values = np.array([float(v) for v in part.split(",")])
        except ValueError:
            raise ValueError(f"{part!r} is not three numbers") from None
        if len(values) != 3 or not np.all(np.isfinite(values)) or not np.any(values):
            raise ValueError(f"{part!r} is not a non-zero 3-vector")
        axes.append(values / np.linalg.norm(values))
    return axes[0], axes[1]


class JointPanel(QWidget):
    """Sensors, joint configuration, the joint-angle readout and its plot."""

    attitudesChanged = Signal(object)
    """A :class:`~app.services.group_attitudes.GroupFrame`, on a refresh when new data arrived
    (every sensor's newest quaternion and the joint angle: the 3D view and the Arm dock);
    None when the sensors were removed."""

    def __init__(self, group: SensorGroup | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.group = group if group is not None else SensorGroup(self)
        self.stream: JointStream | None = None
        self.replay: SessionReplay | None = None
        """A session manifest being replayed (instead of the live sensors)."""
        self.hold = False
        self._held_text = ""
        self._last_readout = 0.0
        self.value_deg: float | None = None
        """The figure the readout shows (degrees), None when there is none."""
        self.attitudes = GroupAttitudes()

        # Three columns, for a wide dock under the level view: the readout, the sensors and
        # the joint's configuration, the plot.
        row = QHBoxLayout(self)
        row.setContentsMargins(6, 6, 6, 6)
        outer = QVBoxLayout()
        config = QVBoxLayout()
        row.addLayout(outer, 3)
        row.addLayout(config, 4)

        self.caption = QLabel("joint angle")
        self.caption.setObjectName("dimLabel")
        self.readout = QLabel("—")
        self.readout.setObjectName("JointReadout")
        font = QFont(self.font())
        font.setPixelSize(52)
        font.setBold(True)
        self.readout.setFont(font)
        self.readout.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.readout.setMinimumHeight(70)
        outer.addWidget(self.caption)
        outer.addWidget(self.readout)
        controls = QHBoxLayout()
        self.unit_combo = QComboBox()
        self.unit_combo.addItem("degrees", "deg")
        self.unit_combo.addItem("radians", "rad")
        self.averaging_combo = QComboBox()
        for seconds in AVERAGING_S:
            self.averaging_combo.addItem("no averaging" if seconds == 0 else f"avg {seconds:g} s",
                                         seconds)
        self.averaging_combo.setCurrentIndex(AVERAGING_S.index(0.5))
        self.hold_button = QPushButton("Hold")
        self.hold_button.setCheckable(True)
        self.hold_button.toggled.connect(self.set_hold)
        for widget in (self.unit_combo, self.averaging_combo, self.hold_button):
            controls.addWidget(widget)
        outer.addLayout(controls)

        self.plot = pg.PlotWidget(plotItem=lazy_menu_plot())
        self.plot.setMinimumSize(320, 200)
        self.plot.showGrid(x=True, y=True, alpha=0.3)
        self.plot.setLabel("left", "joint", units="°")
        self.plot.setLabel("bottom", "time", units="s")
        self.plot.getPlotItem().setDownsampling(auto=True, mode="peak")
        self.curve = self.plot.plot(pen=pg.mkPen(theme.TRACE_ROLL, width=1.5))
        row.addWidget(self.plot, 6)
        self.quality = QLabel("Add two sensors, then start the joint.")
        self.quality.setWordWrap(True)
        self.quality.setObjectName("dimLabel")
        outer.addWidget(self.quality)
        outer.addStretch(1)

        sensors_box = QGroupBox("Sensors")
        sensors = QVBoxLayout(sensors_box)
        self.table = QTableWidget(0, 2)
        self.table.setHorizontalHeaderLabels(["sensor", "clock → common time"])
        self.table.verticalHeader().hide()
        self.table.verticalHeader().setDefaultSectionSize(max(20, self.fontMetrics().height() + 6))
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(1, QHeaderView.ResizeMode.Stretch)
        self.table.setWordWrap(False)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        rows_px = self.table.verticalHeader().defaultSectionSize()
        self.table.setFixedHeight(self.table.horizontalHeader().sizeHint().height()
                                  + 2 * rows_px + 6)  # two sensors without scrolling
        sensors.addWidget(self.table)
        buttons = QHBoxLayout()
        self.add_button = QPushButton("Add sensor…")
        self.add_button.clicked.connect(lambda: self.ask_add_sensor())
        self.arm_button = QPushButton("Simulated arm (2 links)")
        self.arm_button.clicked.connect(lambda: self.add_arm())
        self.clear_button = QPushButton("Remove all")
        self.clear_button.clicked.connect(self.clear)
        for button in (self.add_button, self.arm_button, self.clear_button):
            buttons.addWidget(button)
        sensors.addLayout(buttons)
        session_buttons = QHBoxLayout()
        self.record_button = QPushButton("Record session…")
        self.record_button.setCheckable(True)
        self.record_button.setToolTip("One v1 file per sensor and NAME.session.json")
        self.record_button.clicked.connect(self._on_record_clicked)
        self.open_button = QPushButton("Replay session…")
        self.open_button.setToolTip("Play a session manifest's files in sync")
        self.open_button.clicked.connect(lambda: self.ask_open_session())
        session_buttons.addWidget(self.record_button)
        session_buttons.addWidget(self.open_button)
        sensors.addLayout(session_buttons)
        config.addWidget(sensors_box)

        joint_box = QGroupBox("Joint")
        form = QFormLayout(joint_box)
        links = QHBoxLayout()
        self.first_combo = QComboBox()
        self.second_combo = QComboBox()
        links.addWidget(self.first_combo, 1)
        links.addWidget(QLabel("→"))
        links.addWidget(self.second_combo, 1)
        self.apply_button = QPushButton("Start joint")
        self.apply_button.clicked.connect(lambda: self.start_joint())
        links.addWidget(self.apply_button)
        form.addRow("Links", links)
        axis_row = QHBoxLayout()
        self.axis_combo = QComboBox()
        self.axis_combo.addItem("estimated from the motion", "auto")
        self.axis_combo.addItem("entered", "entered")
        self.axis_edit = QLineEdit()
        self.axis_edit.setPlaceholderText("AX,AY,AZ:BX,BY,BZ")
        self.axis_edit.setEnabled(False)
        self.axis_combo.currentIndexChanged.connect(
            lambda: self.axis_edit.setEnabled(self.axis_combo.currentData() == "entered"))
        axis_row.addWidget(self.axis_combo)
        axis_row.addWidget(self.axis_edit, 1)
        form.addRow("Axis", axis_row)
        config.addWidget(joint_box)
        config.addStretch(1)


        self.group.sessionRecorded.connect(self._on_session_recorded)
        self.group.membersChanged.connect(self._refresh_members)
        self.group.memberConnected.connect(lambda *_: self._refresh_members())
        self.group.error.connect(self._show_error)
        self.timer = QTimer(self)
        self.timer.setInterval(REFRESH_MS)
        self.timer.timeout.connect(self.refresh)
        self._run_timer()

    def _run_timer(self) -> None:
        """Frames only while there is something to show: sensors, or a session replaying
        (a tilt meter left running costs nothing here)."""
        active = bool(self.group.members) or self.replay is not None
        if active and not self.timer.isActive():
            self.timer.start()
        elif not active and self.timer.isActive():
            self.timer.stop()

    # -- sensors ------------------------------------------------------------------------------
    def ask_add_sensor(self) -> None:
        url, ok = QInputDialog.getText(self, "Add sensor", "Device URL (e.g. sim://arm?sensor=1,"
                                       " /dev/ttyACM0, serial://...?sensor=1, a .csv file):")
        if ok and url.strip():
            self.add_sensor(url.strip())

    def add_sensor(self, url: str) -> None:
        if self.replay is not None:  # back to live sensors
            self.clear()
        self.group.add(url)

    def add_arm(self, url: str = ARM_URL, links: int = 2) -> None:
        """Open every sensor of a simulated arm and start the joint between the first two."""
        self.clear()
        sep = "&" if "?" in url else "?"
        for k in range(links):
            self.group.add(url if k == 0 else f"{url}{sep}sensor={k}")
        self._refresh_members()
        self.first_combo.setCurrentIndex(0)
        self.second_combo.setCurrentIndex(1)
        self.axis_combo.setCurrentIndex(0)
        self.start_joint()

    def clear(self) -> None:
        had_sensors = self.has_sensors
        self.stream = None
        self.replay = None
        self.group.clear()
        self.attitudes.reset()
        if had_sensors:
            self.attitudesChanged.emit(None)  # back to the main device
        self.curve.setData([], [])
        self._show_value(None)
        self._run_timer()

    def _roles(self) -> list[tuple[str, str]]:
        """(role, source) of every sensor: the live group's, or the replayed session's."""
        if self.replay is not None:
            return [(s.role, str(p)) for s, p in zip(self.replay.session.sensors,
                                                      self.replay.session.paths, strict=True)]
        return [(m.role, m.url) for m in self.group.members]

    def _refresh_members(self) -> None:
        self._run_timer()
        members = self._roles()
        self.table.setRowCount(len(members))
        for row, (role, source) in enumerate(members):
            item = QTableWidgetItem(role)
            item.setToolTip(source)
            self.table.setItem(row, 0, item)
        for combo, default in ((self.first_combo, 0), (self.second_combo, 1)):
            keep = combo.currentIndex()
            combo.blockSignals(True)
            combo.clear()
            for role, _source in members:
                combo.addItem(role)
            clash = combo is self.second_combo and keep == self.first_combo.currentIndex()
            combo.setCurrentIndex(keep if 0 <= keep < len(members) and not clash else
                                  min(default, len(members) - 1))
            combo.blockSignals(False)
        self._show_alignment()

    def _show_alignment(self) -> None:
        if self.replay is not None:
            for row, sensor in enumerate(self.replay.session.sensors):
                self.table.setItem(row, 1, QTableWidgetItem(
                    f"replay · {sensor.offset_s:+.3f} s · "
                    f"{_rate_text(sensor.drift_ppm, sensor.scale)}"))
            return
        for row, align in enumerate(self.group.alignment()):
            if row >= self.table.rowCount():
                break
            if align is None:
                text = "waiting for data"
            else:
                shared = "shared clock · " if align.shared_clock else ""
                rate = _rate_text(align.drift_ppm, align.scale)
                text = f"{shared}{align.offset_s:+.3f} s · {rate} · ±{align.spread_ms:.1f} ms"
            item = QTableWidgetItem(text)
            item.setToolTip("device clock → common time: offset, drift (ppm), spread of the "
                            "receive latency above the fitted line (90 %)")
            self.table.setItem(row, 1, item)

    def _show_error(self, text: str) -> None:
        self.quality.setText(f"⚠ {text}")

    # -- joint --------------------------------------------------------------------------------
    def start_joint(self) -> bool:
        """(Re)start the joint between the chosen links with the chosen axis mode."""
        first, second = self.first_combo.currentIndex(), self.second_combo.currentIndex()
        if first < 0 or second < 0 or first == second:
            self.quality.setText("Choose two different sensors for the joint.")
            return False
        axes = None
        if self.axis_combo.currentData() == "entered":
            try:
                axes = parse_axes_text(self.axis_edit.text())
            except ValueError as exc:
                self.quality.setText(f"Axis: {exc}")
                return False
        source = self.replay if self.replay is not None else self.group
        self.stream = JointStream(source, first, second, axes)
        roles = [role for role, _ in self._roles()]
        self.caption.setText(f"joint angle, {roles[first]} → {roles[second]}")
        self.curve.setData([], [])
        self._show_value(None)
        return True

    def set_hold(self, on: bool) -> None:
        self.hold = bool(on)
        self.readout.setStyleSheet(f"color: {theme.WARN_AMBER};" if on else "")

    def sensor_pipelines(self) -> list:
        """Every sensor's pipeline, in the dock's order (the arm's captures read them)."""
        source = self.replay if self.replay is not None else self.group
        return [source.pipeline(i) for i in range(len(self._roles()))]

    @property
    def has_sensors(self) -> bool:
        """True while the dock has sensors (live or a replayed session)."""
        return self.replay is not None or bool(self.group.members)

    def refresh(self) -> None:
        """One frame: run the joint on what arrived, redraw the plot and the readout, and
        publish the sensors' newest attitudes (only when new data arrived)."""
        if self.replay is not None:
            self.replay.step()
        self._refresh_joint()
        source = self.replay if self.replay is not None else self.group
        frame = self.attitudes.poll(source, [role for role, _ in self._roles()], self.stream)
        if frame is not None:
            self.attitudesChanged.emit(frame)

    def _refresh_joint(self) -> None:
        if self.group.members and time.monotonic() - self._last_readout >= READOUT_INTERVAL_S:
            self._show_alignment()
        stream = self.stream
        if stream is None or (self.replay is None and self.group.connected_count() < 2):
            return
        stream.step()
        if not len(stream.angles):
            self._show_quality(stream)
            return
        rows = stream.angles.window(PLOT_SPAN_S, ["t", "angle"])
        symbol, factor = UNITS[str(self.unit_combo.currentData())]
        self.curve.setData(rows["t"], rows["angle"] * factor, connect="finite")
        self.plot.setLabel("left", "joint", units=symbol.strip())
        now = time.monotonic()
        if self.hold or now - self._last_readout < READOUT_INTERVAL_S:
            return
        self._last_readout = now
        seconds = float(self.averaging_combo.currentData())
        self._show_value(averaged_angle_deg(stream.recent_angles(seconds)))
        self._show_quality(stream)

    def _show_value(self, value_deg: float | None) -> None:
        self.value_deg = value_deg
        if value_deg is None:
            self.readout.setText("—")
            return
        symbol, factor = UNITS[str(self.unit_combo.currentData())]
        digits = 1 if symbol == "°" else 3
        self.readout.setText(f"{value_deg * factor:+.{digits}f}{symbol}")

    def _show_quality(self, stream: JointStream) -> None:
        quality = stream.axis_quality
        if quality.source == "waiting":
            axis = "axis: waiting for 5 s of motion to estimate it"
        elif quality.source == "entered":
            axis = "axis: entered"
        else:
            verdict = "well determined" if quality.well_determined else "POORLY determined"
            axis = f"axis: estimated, ±{quality.uncertainty_deg:.2f}° (1σ), {verdict}"
        alignment = [a for a in self.group.alignment() if a is not None]
        if self.replay is not None:
            clock = "replay: every file on one clock" + (
                " (finished)" if self.replay.finished else "")
        elif alignment and all(a.shared_clock for a in alignment):
            clock = "clocks: one shared clock (exact alignment)"
        elif alignment:
            clock = f"clocks: aligned within {max(a.spread_ms for a in alignment):.1f} ms"
        else:
            clock = "clocks: waiting for data"
        self.quality.setText(f"{axis} · {clock}")

    # -- sessions -----------------------------------------------------------------------------
    def _on_record_clicked(self, checked: bool) -> None:
        if not checked:
            self.group.stop_recording()
            return
        path, _ = file_dialogs.save_file_name(self, "Record session", "",
                                              "Session manifest (*.session.json)")
        started = None
        if path:
            target = Path(path)
            name = target.name.removesuffix(".json").removesuffix(".session")
            started = self.start_session_recording(target.parent, name)
        self.record_button.setChecked(started is not None)

    def _on_session_recorded(self, manifest: str) -> None:
        self.record_button.setChecked(False)
        self.quality.setText(f"Session recorded: {manifest}")

    def ask_open_session(self) -> None:
        path = file_dialogs.open_file_name(self, "Replay session",
                                           "Session manifest (*.session.json)")
        if path:
            self.open_session(path)

    def open_session(self, path: str | Path, speed: float = 1.0) -> bool:
        """Replay a session manifest: every file on one clock, the joint it names."""
        from app.core.recording.errors import RecordingError

        try:
            replay = SessionReplay(path, speed=speed)
        except (RecordingError, OSError) as exc:
            self._show_error(str(exc))
            return False
        self.clear()
        self.replay = replay
        self._refresh_members()
        joints = replay.session.joints
        first, second = (joints[0].first, joints[0].second) if joints else (0, 1)
        if len(replay.session.sensors) < 2:
            self.quality.setText("The session has one sensor: no joint to show.")
            return True
        self.first_combo.setCurrentIndex(first)
        self.second_combo.setCurrentIndex(second)
        axes = joints[0].axes if joints else None
        self.axis_combo.setCurrentIndex(0 if axes is None else 1)
        if axes is not None:
            self.axis_edit.setText(":".join(",".join(f"{v:.6f}" for v in a) for a in axes))
        return self.start_joint()

    def start_session_recording(self, directory: str | Path, name: str) -> Path | None:
        """Record every sensor (one v1 file each) and the session manifest."""
        joints = []
        if self.stream is not None:
            from app.core.recording.session import JointConfig

            axes = self.stream.estimator.axes if self.stream.estimator.fixed_axes else None
            joints.append(JointConfig(
                self.stream.first, self.stream.second,
                None if axes is None else (tuple(float(v) for v in axes[0]),  # type: ignore[arg-type]
                                           tuple(float(v) for v in axes[1]))))
        try:
            return self.group.start_recording(directory, name, joints)
        except ValueError as exc:
            self._show_error(str(exc))
            return None

    def shutdown(self) -> None:
        self.group.shutdown()
        self.timer.stop()  # after: the group's last membersChanged may have started it
