"""The Arm panel: the measuring arm's layout, its end point (R, θ, Z and x, y, z), repeatability.

The arm's maths lives in :mod:`app.core.arm`; this panel edits the layout (a table of links:
name, length, joint kind and the angle used when no sensor measures the joint), shows the end
point and keeps the captured placements. It is fed by :meth:`ArmPanel.set_joint_angles`
(joint angles from any source) or :meth:`ArmPanel.set_link_orientations` (each link's sensor
quaternion, or None): the main window feeds the Joint dock's sensors (one per link, with the
joint filter's angle) when it has any, else the one connected device through
:meth:`ArmPanel.set_device_orientation`, to the link chosen under the table.

With a capture source (:meth:`ArmPanel.set_capture_source`: the sensors' newest accelerometer
and field) and a magnetometer on a link, the column's angle θ is measured
(:mod:`app.core.arm.azimuth`) instead of typed: live four times a second, and each Capture
from the averaged window, refused with the reason when a link moved or its field is disturbed.
"""

from __future__ import annotations

import functools
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

import numpy as np
from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QFrame,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.core.arm import (
    COORDINATES,
    ArmLayout,
    ArmLayoutError,
    ArmPose,
    Link,
    LinkCapture,
    Placements,
    ThetaMeasurement,
    ThetaZero,
    capture_link,
    forward,
    jamris_layout,
    measure_theta,
    placement_pose,
    pose_from_link_quaternions,
)
from app.core.arm.azimuth import column_joint
from app.core.arm.layout import ALONG_X, PITCH_UP, VERTICAL
from app.core.field_check import FieldReference, wmm_reference
from app.gui import file_dialogs

JOINT_KINDS = {
    "column (vertical)": (VERTICAL, VERTICAL),
    "hinge (raises link)": (PITCH_UP, ALONG_X),
}
"""Joint kinds offered in the table: (hinge axis in the previous link, link direction)."""
STAT_ROWS = ("mean", "sd", "min", "max", "range")
SHOWN_COORDINATES = ("R", "azimuth_deg", "Z", "x", "y", "z")
"""The table's columns: the paper's R, theta, Z, then x, y, z."""
HEADERS = {"azimuth_deg": "θ °"}
HISTORY_S = 30.0
LIVE_THETA_WINDOW_S = 0.5
LIVE_THETA_EVERY_S = 0.25
"""The live theta: measured on the newest half second, four times a second."""


class SensorWindowLike(Protocol):
    link: int
    accel_m_s2: np.ndarray
    mag_ut: np.ndarray | None


CaptureSource = Callable[[float], Sequence[SensorWindowLike]]
"""seconds -> the newest seconds of every sensor on the arm (its link, accelerometer, field)."""
COL_NAME, COL_LENGTH, COL_JOINT, COL_ANGLE = range(4)


def _tile(caption: str, size: int) -> tuple[QFrame, QLabel]:
    tile = QFrame()
    tile.setObjectName("ReadoutTile")
    layout = QVBoxLayout(tile)
    layout.setContentsMargins(8, 4, 8, 4)
    layout.setSpacing(0)
    label = QLabel(caption)
    label.setObjectName("ReadoutCaption")
    value = QLabel("—")
    value.setObjectName("ReadoutValue")
    value.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
    font = QFont()
    font.setPointSize(size)
    font.setBold(True)
    font.setStyleHint(QFont.StyleHint.Monospace)
    value.setFont(font)
    layout.addWidget(label)
    layout.addWidget(value)
    return tile, value


def _fit_height(table: QTableWidget) -> None:
    """Make a table exactly as tall as its rows (no scroll bar, no empty space)."""
    table.resizeRowsToContents()
    height = table.horizontalHeader().height() + table.verticalHeader().length()
    table.setFixedHeight(height + 2 * table.frameWidth() + 2)


class ArmPanel(QWidget):
    """Layout table, the end point's readouts, and repeatability over captured placements."""

    poseChanged = Signal(object)  # ArmPose; sensor_links says which links carry a sensor
    layoutChanged = Signal(object)  # ArmLayout

    def __init__(
        self,
        parent: QWidget | None = None,
        layout: ArmLayout | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(parent)
        self._clock = clock
        self.arm = layout or jamris_layout()
        self.pose: ArmPose | None = None
        self.sensor_links: tuple[int, ...] = ()
        self.placements = Placements(self.arm.base_position, self.arm.unit)
        self._history: deque[tuple[float, np.ndarray]] = deque()
        self._filling = False
        self._capture_source: CaptureSource | None = None
        self.field_reference: Callable[[], FieldReference | None] = _default_reference
        """What the field should read (the field view's reference in the window)."""
        self.theta_zero = ThetaZero()
        self.live_theta: ThetaMeasurement | None = None
        self._has_field: bool | None = None
        """Whether the capture source has a magnetometer (None: not known yet)."""
        self._live_theta_at = -np.inf
        outer = QVBoxLayout(self)

        layout_box = QGroupBox("Arm layout")
        box = QVBoxLayout(layout_box)
        self.table = QTableWidget(0, 4)
        self.table.setHorizontalHeaderLabels(["Link", "Length", "Joint", "Angle °"])
        self.table.verticalHeader().setVisible(False)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(COL_JOINT, QHeaderView.ResizeMode.Stretch)
        self.table.setToolTip(
            "Links from the base. The angle is used when no sensor measures that joint "
            "(a column's turn about the vertical cannot be seen by an accelerometer)."
        )
        self.table.itemChanged.connect(self._on_table_edited)
        box.addWidget(self.table)
        buttons = QHBoxLayout()
        self.add_button = QPushButton("Add link")
        self.add_button.clicked.connect(self.add_link)
        self.remove_button = QPushButton("Remove last")
        self.remove_button.clicked.connect(self.remove_link)
        self.load_button = QPushButton("Load…")
        self.load_button.clicked.connect(lambda: self.load_layout())
        self.save_button = QPushButton("Save…")
        self.save_button.clicked.connect(lambda: self.save_layout())
        for button in (self.add_button, self.remove_button, self.load_button, self.save_button):
            buttons.addWidget(button)
        box.addLayout(buttons)
        form = QFormLayout()
        self.unit_edit = QLineEdit(self.arm.unit)
        self.unit_edit.setMaximumWidth(80)
        self.unit_edit.editingFinished.connect(self._on_table_edited)
        form.addRow("Length unit", self.unit_edit)
        self.device_link = QComboBox()
        self.device_link.setToolTip("The link the connected device sits on (x along the link)")
        self.device_link.currentIndexChanged.connect(self._on_device_link_changed)
        form.addRow("Current device on", self.device_link)
        box.addLayout(form)
        outer.addWidget(layout_box)

        end_box = QGroupBox("End point (base frame)")
        grid = QGridLayout(end_box)
        self.values: dict[str, QLabel] = {}
        for column, name in enumerate(("R", "azimuth_deg", "Z")):
            tile, value = _tile(HEADERS.get(name, name).split()[0], 20)
            self.values[name] = value
            grid.addWidget(tile, 0, column * 2, 1, 2)
        for column, name in enumerate(("x", "y", "z")):
            tile, value = _tile(name, 13)
            self.values[name] = value
            grid.addWidget(tile, 1, column * 2, 1, 2)
        self.pose_note = QLabel()
        self.pose_note.setObjectName("dimLabel")
        self.pose_note.setWordWrap(True)
        grid.addWidget(self.pose_note, 2, 0, 1, 6)
        theta_row = QHBoxLayout()
        self.theta_label = QLabel()
        self.theta_label.setWordWrap(True)
        self.theta_label.setToolTip(
            "θ, the column's angle: measured from each link's gravity and magnetic field "
            "when a link has a magnetometer (calibrate it first), else the angle typed in "
            "the table. Its zero is magnetic north until set at a placement.")
        self.zero_button = QPushButton("Set θ zero")
        self.zero_button.setToolTip("Make the column's present direction θ = 0 (the arm held "
                                    "still on the reference direction)")
        self.zero_button.clicked.connect(self.set_theta_zero)
        self.north_button = QPushButton("Zero at north")
        self.north_button.setToolTip("θ from magnetic north again")
        self.north_button.clicked.connect(self.reset_theta_zero)
        theta_row.addWidget(self.theta_label, 1)
        theta_row.addWidget(self.zero_button)
        theta_row.addWidget(self.north_button)
        grid.addLayout(theta_row, 3, 0, 1, 6)
        outer.addWidget(end_box)

        stats_box = QGroupBox("Repeatability over placements")
        stats = QVBoxLayout(stats_box)
        row = QHBoxLayout()
        self.window = QDoubleSpinBox()
        self.window.setRange(0.1, HISTORY_S)
        self.window.setValue(1.0)
        self.window.setSuffix(" s")
        self.window.setToolTip("A placement is the mean end point over this time")
        self.capture_button = QPushButton("Capture")
        self.capture_button.setToolTip("Capture the end point of this placement (averaged)")
        self.capture_button.clicked.connect(self.capture)
        self.undo_button = QPushButton("Undo")
        self.undo_button.clicked.connect(self.undo_capture)
        self.clear_button = QPushButton("Clear")
        self.clear_button.clicked.connect(self.clear_captures)
        self.export_button = QPushButton("Export CSV…")
        self.export_button.clicked.connect(lambda: self.export_csv())
        row.addWidget(QLabel("Average"))
        row.addWidget(self.window)
        for button in (self.capture_button, self.undo_button, self.clear_button,
                       self.export_button):
            row.addWidget(button)
        stats.addLayout(row)
        self.count_label = QLabel()
        stats.addWidget(self.count_label)
        self.stats_table = QTableWidget(len(STAT_ROWS), len(SHOWN_COORDINATES))
        self.stats_table.setVerticalHeaderLabels(["Mean", "SD", "Min", "Max", "Range"])
        self.stats_table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.stats_table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.Stretch
        )
        stats.addWidget(self.stats_table)
        self.message = QLabel()
        self.message.setObjectName("dimLabel")
        self.message.setWordWrap(True)
        stats.addWidget(self.message)
        outer.addWidget(stats_box)
        outer.addStretch(1)

        self.set_layout(self.arm)
        self._show_statistics()
        self._show_theta_source()

    # -- the layout -----------------------------------------------------------------------
    def set_layout(self, layout: ArmLayout) -> None:
        """Show and use a layout (the table is rebuilt; placements of another arm are kept)."""
        self._filling = True
        try:
            self.table.setRowCount(0)
            for link in layout.links:
                self._append_row(link, 0.0)
            self.unit_edit.setText(layout.unit)
        finally:
            self._filling = False
        _fit_height(self.table)
        self._apply_layout(layout)

    def _append_row(self, link: Link, angle: float) -> None:
        row = self.table.rowCount()
        self.table.insertRow(row)
        self.table.setItem(row, COL_NAME, QTableWidgetItem(link.name))
        length = QDoubleSpinBox()
        length.setRange(0.0, 1e6)
        length.setDecimals(1)
        length.setValue(link.length)
        length.valueChanged.connect(self._on_table_edited)
        self.table.setCellWidget(row, COL_LENGTH, length)
        joint = QComboBox()
        joint.addItems(list(JOINT_KINDS))
        kind = next((name for name, (axis, direction) in JOINT_KINDS.items()
                     if np.allclose(axis, link.axis) and np.allclose(direction, link.direction)),
                    None)
        if kind is None:  # a layout from a file with another joint: keep it, say so
            joint.addItem(f"custom axis {tuple(round(v, 3) for v in link.axis)}")
            joint.setItemData(joint.count() - 1, (link.axis, link.direction))
            kind = joint.itemText(joint.count() - 1)
        joint.setCurrentText(kind)
        joint.currentIndexChanged.connect(self._on_table_edited)
        self.table.setCellWidget(row, COL_JOINT, joint)
        angle_box = QDoubleSpinBox()
        angle_box.setRange(-180.0, 180.0)
        angle_box.setDecimals(2)
        angle_box.setValue(angle)
        angle_box.setWrapping(True)
        angle_box.valueChanged.connect(self._on_angles_edited)
        self.table.setCellWidget(row, COL_ANGLE, angle_box)

    def layout_from_table(self) -> ArmLayout:
        """The layout the table describes (raises ArmLayoutError with the reason)."""
        links = []
        for row in range(self.table.rowCount()):
            item = self.table.item(row, COL_NAME)
            name = item.text().strip() if item is not None else ""
            joint: QComboBox = self.table.cellWidget(row, COL_JOINT)
            axis, direction = JOINT_KINDS.get(joint.currentText()) or joint.currentData()
            length = self.table.cellWidget(row, COL_LENGTH).value()
            links.append(Link(name or f"link {row + 1}", length, axis, direction))
        return ArmLayout(tuple(links), self.unit_edit.text().strip() or "mm", self.arm.name)

    def entered_angles(self) -> list[float]:
        return [self.table.cellWidget(r, COL_ANGLE).value() for r in range(self.table.rowCount())]

    def add_link(self) -> None:
        self._filling = True  # the row is complete only at the end
        try:
            self._append_row(Link(f"link {self.table.rowCount() + 1}", 100.0), 0.0)
        finally:
            self._filling = False
        self._on_table_edited()

    def remove_link(self) -> None:
        if self.table.rowCount() > 1:
            self.table.removeRow(self.table.rowCount() - 1)
            self._on_table_edited()

    def _on_table_edited(self, *_args) -> None:
        _fit_height(self.table)
        if self._filling:
            return
        try:
            layout = self.layout_from_table()
        except ArmLayoutError as exc:
            self.message.setText(f"Layout not used: {exc}")
            return
        self._apply_layout(layout)

    def _apply_layout(self, layout: ArmLayout) -> None:
        changed_unit = layout.unit != self.arm.unit
        self.arm = layout
        self.placements.unit = layout.unit
        if changed_unit:
            self.clear_captures()
        chosen = self.device_link.currentIndex()
        self.device_link.blockSignals(True)
        self.device_link.clear()
        self.device_link.addItem("no link", -1)
        for i, link in enumerate(layout.links):
            self.device_link.addItem(link.name, i)
        default = 2 if layout.n_joints > 1 else 1  # the first hinge after a column
        self.device_link.setCurrentIndex(chosen if 0 <= chosen < self.device_link.count()
                                         else min(default, self.device_link.count() - 1))
        self.device_link.blockSignals(False)
        self._history.clear()
        self.layoutChanged.emit(layout)
        self.set_joint_angles(self.entered_angles(), observed=())

    def _on_angles_edited(self, *_args) -> None:
        if not self._filling and not self.sensor_links:
            self.set_joint_angles(self.entered_angles(), observed=())

    def _on_device_link_changed(self, *_args) -> None:
        self.sensor_links = ()
        self.set_joint_angles(self.entered_angles(), observed=())

    # -- feeding --------------------------------------------------------------------------
    def set_joint_angles(self, angles_deg: Sequence[float], observed: Sequence[int] = ()) -> None:
        """Show the end point for these joint angles (degrees, one per link).

        ``observed`` lists the links whose angle a sensor measured (drawn with a board).
        """
        try:
            pose = forward(self.arm, angles_deg)
        except ArmLayoutError as exc:
            self.message.setText(f"Joint angles not used: {exc}")
            return
        self.sensor_links = tuple(observed)
        self._show_pose(pose)

    def set_link_orientations(self, quaternions: Sequence[np.ndarray | None],
                              measured_deg: Sequence[float | None] | None = None) -> None:
        """Each link's sensor orientation (sensor to earth; None: no sensor on that link).

        ``measured_deg`` gives joint angles measured otherwise (the joint filter between two
        links' sensors; None where there is none): they win over gravity. Joints the sensors
        cannot see (a vertical axis, a link without a sensor) take the angle in the table.
        """
        known: list[float | None] = list(self.entered_angles())
        theta = self._update_live_theta()
        if theta is not None and theta.ok:
            known[0] = theta.theta_deg
        try:
            pose, observed = pose_from_link_quaternions(
                self.arm, quaternions, known_deg=known, measured_deg=measured_deg,
            )
        except ArmLayoutError as exc:
            self.message.setText(f"Orientations not used: {exc}")
            return
        self.sensor_links = tuple(i for i, q in enumerate(quaternions) if q is not None)
        self._show_pose(pose, observed)

    def set_device_orientation(self, q: np.ndarray) -> None:
        """The one connected device's orientation, on the link chosen under the table."""
        link = self.device_link.currentData()
        if link is None or link < 0 or link >= self.arm.n_joints:
            return
        quaternions: list[np.ndarray | None] = [None] * self.arm.n_joints
        quaternions[link] = np.asarray(q, dtype=np.float64)
        self.set_link_orientations(quaternions)

    def _show_pose(self, pose: ArmPose, observed: np.ndarray | None = None) -> None:
        self.pose = pose
        now = self._clock()
        self._history.append((now, pose.end.copy()))
        while self._history and self._history[0][0] < now - HISTORY_S:
            self._history.popleft()
        coordinates = pose.coordinates()
        unit = self.arm.unit
        for name in SHOWN_COORDINATES:
            self.values[name].setText(f"{coordinates[name]:.1f} °" if name == "azimuth_deg"
                                      else f"{coordinates[name]:.1f} {unit}")
        angles = ", ".join(
            f"{link.name} {angle:+.1f}°" + (" (sensor)" if observed is not None and seen else "")
            for link, angle, seen in zip(
                self.arm.links, pose.joint_angles_deg,
                observed if observed is not None else [False] * self.arm.n_joints,
            )
        )
        self.pose_note.setText(f"Joints: {angles}.")
        self.poseChanged.emit(pose)

    # -- placements -----------------------------------------------------------------------
    # -- theta from the magnetometers -----------------------------------------------------
    def set_capture_source(self, source: CaptureSource | None) -> None:
        """Where captures read the sensors' samples (None: captures average the end point,
        theta typed)."""
        self._capture_source = source
        self._has_field = None
        self.live_theta = None
        self._live_theta_at = -np.inf
        self._show_theta_source()

    def link_captures(self, seconds: float) -> list[LinkCapture | None] | None:
        """Every link's capture over the newest ``seconds`` (None for a link without a
        sensor), or None when no sensor has a magnetometer (theta stays typed)."""
        if self._capture_source is None:
            return None
        windows = [w for w in self._capture_source(seconds) if 0 <= w.link < self.arm.n_joints]
        if not any(w.mag_ut is not None for w in windows):
            return None
        captures: list[LinkCapture | None] = [None] * self.arm.n_joints
        reference = self.field_reference()
        for window in windows:
            captures[window.link] = capture_link(window.link, window.accel_m_s2, window.mag_ut,
                                                 reference, self.arm.links[window.link].name)
        return captures

    def _update_live_theta(self) -> ThetaMeasurement | None:
        now = self._clock()
        if now - self._live_theta_at < LIVE_THETA_EVERY_S:
            return self.live_theta
        self._live_theta_at = now
        captures = self.link_captures(LIVE_THETA_WINDOW_S)
        self._has_field = captures is not None
        self.live_theta = (None if captures is None else
                           measure_theta(self.arm, captures, self.theta_zero,
                                         self.entered_angles()))
        self._show_theta_source()
        return self.live_theta

    def set_theta_zero(self) -> bool:
        """θ = 0 at the column's present direction (measured over the averaging window);
        refused while there are placements (their θ is from the present zero)."""
        if not self._zero_may_change():
            return False
        captures = self.link_captures(self.window.value())
        if captures is None:
            self.message.setText("θ zero not set: no link has a magnetometer (θ is typed).")
            return False
        theta = measure_theta(self.arm, captures, self.theta_zero, self.entered_angles())
        if not theta.ok:
            self.message.setText(f"θ zero not set: {theta.refused}")
            return False
        self.theta_zero = ThetaZero(theta.psi_deg, f"set at {theta.azimuth_deg:.1f}° magnetic")
        self.message.setText(f"θ = 0 where the column points {theta.azimuth_deg:.1f}° "
                             "(magnetic).")
        self._live_theta_at = -np.inf
        self._show_theta_source()
        return True

    def _zero_may_change(self) -> bool:
        if len(self.placements) and "measured" in self.placements.theta_sources:
            self.message.setText("θ zero not changed: the placements' θ is from the present "
                                 "zero; Export and Clear them first.")
            return False
        return True

    def reset_theta_zero(self) -> None:
        if not self._zero_may_change():
            return
        self.theta_zero = ThetaZero()
        self._live_theta_at = -np.inf
        self._show_theta_source()

    def _show_theta_source(self) -> None:
        theta = self.live_theta
        measurable = column_joint(self.arm) is not None
        self.zero_button.setEnabled(measurable and self._capture_source is not None)
        self.north_button.setEnabled(self.theta_zero.source != ThetaZero().source)
        if not measurable:
            text = "θ: the layout has no column at its base (it is typed)."
        elif theta is None and self._capture_source is not None and self._has_field is None:
            text = "θ typed in the table until the sensors' samples arrive."
        elif theta is None:
            text = "θ typed in the table (no magnetometer on the arm's links)."
        elif theta.ok:
            text = (f"θ measured by the magnetometers (zero: {self.theta_zero.source}); the "
                    f"column points {theta.azimuth_deg:.1f}° magnetic.")
        else:
            text = f"θ not measured now: {theta.refused}"
        self.theta_label.setText(text)

    def capture(self) -> bool:
        """Capture a placement: the mean end point over the averaging window, or with a
        magnetometer on the arm the links' averaged gravity and field (θ measured; refused
        with the reason when a link moved or the field is disturbed)."""
        captures = self.link_captures(self.window.value())
        if captures is not None:
            return self._capture_measured(captures)
        now = self._clock()
        recent = [point for t, point in self._history if t >= now - self.window.value()]
        if not recent:
            self.message.setText("Nothing to capture yet: no end point in the averaging window.")
            return False
        self.placements.base = np.asarray(self.arm.base_position)
        self.placements.capture(np.array(recent))
        self.message.setText(f"Captured placement {len(self.placements)} "
                             f"(mean of {len(recent)} end points).")
        self._show_statistics()
        return True

    def _capture_measured(self, captures: list[LinkCapture | None]) -> bool:
        result = placement_pose(self.arm, captures, self.theta_zero, self.entered_angles())
        if result.pose is None:
            self.message.setText(f"Placement refused: {result.refused}")
            return False
        self.placements.base = np.asarray(self.arm.base_position)
        self.placements.capture(result.pose.end[None, :], result.theta_source,
                                result.column_azimuth_deg)
        samples = sum(c.samples for c in captures if c is not None)
        how = ("θ measured" if result.theta is not None else "θ typed")
        self.message.setText(f"Captured placement {len(self.placements)} ({how}; "
                             f"{samples} samples averaged).")
        self._show_statistics()
        return True

    def undo_capture(self) -> None:
        self.placements.remove_last()
        self._show_statistics()

    def clear_captures(self) -> None:
        self.placements.clear()
        self._show_statistics()

    def _show_statistics(self) -> None:
        stats = self.placements.statistics()
        n = len(self.placements)
        self.count_label.setText(f"{n} placement{'s' if n != 1 else ''} · {self.arm.unit}")
        self.stats_table.setHorizontalHeaderLabels([HEADERS.get(name, name)
                                                    for name in SHOWN_COORDINATES])
        for column, name in enumerate(SHOWN_COORDINATES):
            for row, what in enumerate(STAT_ROWS):
                value = getattr(stats[name], what) if stats else float("nan")
                text = "—" if not np.isfinite(value) else f"{value:.2f}"
                item = QTableWidgetItem(text)
                item.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
                self.stats_table.setItem(row, column, item)
        _fit_height(self.stats_table)
        self.export_button.setEnabled(n > 0)
        self.undo_button.setEnabled(n > 0)

    def export_csv(self, path: str | None = None) -> bool:
        if not len(self.placements):
            return False
        if path is None:
            path, _ = file_dialogs.save_file_name(
                self, "Export repeatability", "arm-repeatability.csv", "CSV (*.csv)")
            if not path:
                return False
        try:
            self.placements.export_csv(path)
        except OSError as exc:
            self.message.setText(f"Not exported: {exc}")
            return False
        self.message.setText(f"Exported {len(self.placements)} placements to {path}")
        return True

    def save_layout(self, path: str | None = None) -> bool:
        if path is None:
            path, _ = file_dialogs.save_file_name(
                self, "Save arm layout", "arm-layout.json", "JSON (*.json)")
            if not path:
                return False
        try:
            Path(path).write_text(self.arm.to_json(), encoding="utf-8")
        except OSError as exc:
            self.message.setText(f"Layout not saved: {exc}")
            return False
        self.message.setText(f"Saved the layout to {path}")
        return True

    def load_layout(self, path: str | None = None) -> bool:
        if path is None:
            path = file_dialogs.open_file_name(self, "Load arm layout", "JSON (*.json)")
            if not path:
                return False
        try:
            layout = ArmLayout.load(path)
        except (OSError, UnicodeDecodeError, ArmLayoutError) as exc:
            self.message.setText(f"Layout not loaded: {exc}")
            return False
        self.set_layout(layout)
        self.message.setText(f"Loaded the layout {layout.name!r} from {path}")
        return True


@functools.lru_cache(maxsize=1)
def _default_reference() -> FieldReference | None:
    """The WMM field at the default place today (the window gives the field view's)."""
    try:
        return wmm_reference()
    except ValueError:  # a date outside the model's span: strength and dip unchecked
        return None


__all__ = ["COORDINATES", "JOINT_KINDS", "ArmPanel"]
