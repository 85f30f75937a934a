"""The Joint dock's sensors drive the 3D view (one body each) and the Arm dock (links posed
from them), live from sim://arm faster than real time; without sensors, the main device does."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PySide6.QtCore import QSettings

from app.core import quaternion as quat
from app.core.arm import pose_from_link_quaternions
from app.core.scene3d import Camera, Projection, render_list, sensors_scene
from app.gui import theme
from app.gui.attitude_view import REDRAW_THRESHOLD_DEG
from app.gui.main_window import MainWindow
from app.services.group_attitudes import GroupFrame
from app.services.session import DeviceSession

ARM = "sim://arm?seed=3&odr=104&speed=16"
TIMEOUT_MS = 30_000


@pytest.fixture
def window(qtbot, qapp, tmp_path):
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(DeviceSession(), settings, "sim://static?seed=2")
    qtbot.addWidget(window)
    window.resize(1400, 900)
    window.show()
    yield window
    window.close()


def _in_ring(q: np.ndarray, pipeline) -> bool:
    """Whether ``q`` is exactly one of the pipeline's recent orientation rows."""
    recent = pipeline.orientation.latest(4096, ["quat"])["quat"]
    return bool(np.any(np.all(recent == q, axis=1)))


def test_two_sensors_drive_the_3d_view_and_the_arm(qtbot, window, artifacts_dir):
    panel, view, arm = window.joint_panel, window.attitude_view, window.arm_panel
    frames: list[GroupFrame | None] = []
    panel.attitudesChanged.connect(frames.append)
    for name in ("attitude3d", "arm"):
        window.docks[name].show()
    window._show_joint(lambda: panel.add_arm(ARM))
    qtbot.waitUntil(lambda: panel.group.connected_count() == 2, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: view._quaternions is not None and len(view._quaternions) == 2
                    and frames and frames[-1] is not None, timeout=TIMEOUT_MS)

    # The view holds the two sensors' own quaternions, in order (not the main device's).
    frame = frames[-1]
    assert view._labels == ("link 0 (base)", "link 1")
    pipelines = [panel.group.pipeline(k) for k in range(2)]
    for k in range(2):
        # The view keeps its last drawn attitude while a turn stays under its threshold.
        turned = np.degrees(quat.angle_between(frame.quaternions[k], view._quaternions[k]))
        assert turned <= REDRAW_THRESHOLD_DEG + 1e-9
        assert _in_ring(frame.quaternions[k], pipelines[k])
    assert not _in_ring(frame.quaternions[0], pipelines[1])
    assert not np.allclose(frame.quaternions[0], frame.quaternions[1])

    # The Arm dock: two sensors on the JAMRIS arm's upper arm and forearm, its end point the
    # forward kinematics of what it got, and moving with the sensors.
    assert arm.sensor_links == (1, 2)
    qtbot.waitUntil(lambda: frames[-1] is not None and frames[-1].joint is not None,
                    timeout=TIMEOUT_MS)
    ends = []

    def end_moved() -> bool:
        ends.append(arm.pose.end.copy())
        return float(np.linalg.norm(ends[-1] - ends[0])) > 5.0

    qtbot.waitUntil(end_moved, timeout=TIMEOUT_MS)
    frame = frames[-1]
    n = arm.arm.n_joints
    expected, observed = pose_from_link_quaternions(
        arm.arm, frame.link_quaternions(n), known_deg=arm.entered_angles(),
        measured_deg=frame.measured_deg(n))
    assert np.allclose(arm.pose.end, expected.end)
    assert observed.tolist() == [False, True, True]
    # The forearm's hinge takes the joint filter's angle (the stream's newest, wrapped).
    assert frame.joint is not None and frame.joint[:2] == (0, 1)
    assert abs(((arm.pose.joint_angles_deg[2] - frame.joint[2]) + 180) % 360 - 180) < 1e-9
    coordinates = arm.pose.coordinates()
    assert arm.values["R"].text() == f"{coordinates['R']:.1f} mm"
    # Capture works on the two-sensor arm.
    assert arm.capture() and len(arm.placements) == 1

    # Screenshots: the Joint dock's readout and the 3D view's two bodies; then the arm.
    stream = panel.stream
    qtbot.waitUntil(lambda: panel.value_deg is not None and
                    stream.angles.latest(1)["device_t"][0] > 30.0, timeout=TIMEOUT_MS)
    window.docks["attitude3d"].raise_()
    assert window.grab().save(os.path.join(artifacts_dir, "arm_two_sensors_3d.png"))
    view.arm_box.setChecked(True)
    assert view.showing_arm
    assert window.grab().save(os.path.join(artifacts_dir, "arm_two_sensors_arm.png"))
    view.arm_box.setChecked(False)

    # Removing the sensors hands the view and the arm back to the main device.
    panel.clear()
    assert frames[-1] is None and not panel.has_sensors
    q = np.array([0.9659258, 0.2588190, 0.0, 0.0])  # 30° roll
    window.presenter.attitudeChanged.emit(q)
    assert len(view._quaternions) == 1 and np.allclose(view._quaternions[0], q)
    assert arm.sensor_links == (arm.device_link.currentData(),)


def test_a_group_frame_puts_the_sensors_on_the_last_links_and_the_joint_between_them():
    q0, q1 = np.array([1.0, 0, 0, 0]), np.array([0.0, 1, 0, 0])
    frame = GroupFrame((q0, q1), ("a", "b"), joint=(0, 1, 42.0))
    links = frame.link_quaternions(3)
    assert links[0] is None and links[1] is q0 and links[2] is q1
    assert frame.measured_deg(3) == [None, None, 42.0]
    assert frame.measured_deg(1) == [None]  # one link: the two sensors cannot both sit on it
    assert GroupFrame((q0, q1), ("a", "b"), joint=(1, 0, 5.0)).measured_deg(3) == [None] * 3
    assert GroupFrame((q0, q1), ("a", "b")).measured_deg(2) == [None, None]


def test_each_sensor_is_named_under_its_board():
    scene = sensors_scene([np.array([1.0, 0, 0, 0])] * 2, ["link 0 (base)", "link 1"])
    items = render_list(scene, Camera(), 400, 300)
    labels = [item for item in items if item.kind == "label"]
    assert [item.text for item in labels] == ["link 0 (base)", "link 1"]
    assert items[-2:] == labels  # drawn last, on top
    center, radius = scene.bounds()
    projection = Projection(Camera(), center, radius, 400, 300)
    for label, body in zip(labels, scene.bodies, strict=True):  # centred under its board
        corners, _depth = projection.project(body.corners())
        assert label.points[0, 0] == pytest.approx(corners[:, 0].mean())
        assert label.points[0, 1] > corners[:, 1].max()
    assert labels[0].points[0, 0] != pytest.approx(labels[1].points[0, 0])
    assert not [i for i in render_list(sensors_scene([np.array([1.0, 0, 0, 0])]), Camera(),
                                       400, 300) if i.kind == "label"]
