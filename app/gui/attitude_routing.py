"""Who drives the 3D view and the arm: the current device (live and replay), or, while the
Joint dock has sensors, those sensors (one body each). The arm is solved only while someone
can see it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from app.services.group_attitudes import sensor_windows

MainWindow = Any
"""The window this part works for (not imported: the parts sit below
:mod:`app.gui.main_window`, which assembles them)."""


class AttitudeRouting:
    """Routes attitudes to ``window``'s 3D view and arm panel."""

    def __init__(self, window: MainWindow) -> None:
        self.window = window
        self.device_q = None
        window.presenter.attitudeChanged.connect(self.on_device_attitude)
        window.joint_panel.attitudesChanged.connect(self.on_group_attitudes)
        window.docks["arm"].visibilityChanged.connect(self._on_arm_shown)
        arm, view = window.arm_panel, window.attitude_view
        arm.poseChanged.connect(
            lambda pose: view.set_arm(pose.points, pose.rotations, arm.sensor_links))
        arm.set_capture_source(self.arm_windows)
        default_reference = arm.field_reference
        # The field view's reference (WMM for the user's place, or learnt at rest); its
        # presenter is made after this part.
        arm.field_reference = lambda: (
            window.field_presenter.reference if hasattr(window, "field_presenter")
            else default_reference())

    def arm_windows(self, seconds: float) -> list:
        """The newest ``seconds`` of every sensor on the arm, for its captures: the Joint
        dock's sensors on the arm's last links, else the device on its chosen link."""
        window = self.window
        arm = window.arm_panel
        n_links = arm.arm.n_joints
        if window.joint_panel.has_sensors:
            pipelines = window.joint_panel.sensor_pipelines()[:n_links]
            first = n_links - len(pipelines)
            links = [first + k for k in range(len(pipelines))]
        else:
            link = arm.device_link.currentData()
            if link is None or not 0 <= link < n_links:
                return []
            pipelines, links = [window.presenter.session.pipeline], [link]
        return sensor_windows(pipelines, links, seconds)

    def _on_arm_shown(self, shown: bool) -> None:
        window = self.window
        if shown and self.device_q is not None and not window.joint_panel.has_sensors:
            window.arm_panel.set_device_orientation(self.device_q)

    def on_device_attitude(self, q) -> None:
        """The main device's attitude: the 3D view and the arm, unless the Joint dock has
        sensors (then those are shown)."""
        window = self.window
        if window.joint_panel.has_sensors:
            return
        window.attitude_view.set_attitude(q)
        self.device_q = q
        # The arm only while someone can see it (the Arm dock, or the arm in the 3D view):
        # solving it for every block costs as much as the bubble.
        if window.docks["arm"].isVisible() or window.attitude_view.showing_arm:
            window.arm_panel.set_device_orientation(q)

    def on_group_attitudes(self, frame) -> None:
        """The Joint dock's sensors (a GroupFrame; None when they were removed): one body
        each in the 3D view, and the arm's links posed from them."""
        arm, view = self.window.arm_panel, self.window.attitude_view
        if frame is None:
            view.set_attitudes([])
            arm.set_joint_angles(arm.entered_angles(), observed=())
            return
        view.set_attitudes(frame.quaternions, frame.labels)
        n_links = arm.arm.n_joints
        arm.set_link_orientations(frame.link_quaternions(n_links), frame.measured_deg(n_links))

    def show_joint(self, then: Callable[[], object]) -> None:
        """The Joint dock in front, then ``then()``."""
        dock = self.window.docks["joint"]
        dock.show()
        dock.raise_()
        then()

    def add_sensor(self) -> None:
        self.show_joint(self.window.joint_panel.ask_add_sensor)

    def add_arm(self) -> None:
        self.show_joint(self.window.joint_panel.add_arm)
