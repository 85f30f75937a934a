"""The 3D attitude view: projection maths, the drawing without OpenGL, and its live feed."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PySide6.QtCore import QEvent, QPointF, QSettings, Qt
from PySide6.QtGui import QImage, QMouseEvent
from PySide6.QtWidgets import QApplication

from app.core.arm import forward, jamris_layout
from app.core.orientation import angles_from_quaternion, quaternion_from_roll_pitch
from app.core.scene3d import (
    Body,
    Camera,
    Projection,
    Scene,
    attitudes_differ,
    render_list,
    rotation_from_quaternion,
    sensors_scene,
)
from app.gui import theme
from app.gui.attitude_view import AttitudeView
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000
SIDE_VIEW = Camera(azimuth_deg=-90.0, elevation_deg=0.0, perspective=False)
"""Looking along +y from -y: screen right is world x, screen up is world z."""


def test_side_view_puts_a_pitched_boards_x_axis_tip_where_expected():
    rotation = rotation_from_quaternion(quaternion_from_roll_pitch(0.0, 30.0))
    body = Body(rotation, np.zeros(3), axis_length=0.85)
    projection = Projection(SIDE_VIEW, np.zeros(3), 1.0, 200, 200)
    pixels, _ = projection.project(body.axis_tips())
    scale = 0.42 * 200  # 0.42 of the smaller side per scene radius
    c30, s30 = np.cos(np.radians(30)), np.sin(np.radians(30))
    x_tip = (100 + scale * 0.85 * c30, 100 - scale * 0.85 * s30)
    assert pixels[0] == pytest.approx(x_tip, abs=1e-9)
    assert pixels[2] == pytest.approx(  # z axis: tilted back by the pitch, up on the screen
        (100 - scale * 0.85 * np.sin(np.radians(30)), 100 - scale * 0.85 * np.cos(np.radians(30))),
        abs=1e-9,
    )


def test_render_list_draws_the_x_axis_out_to_its_projected_tip():
    q = quaternion_from_roll_pitch(0.0, 30.0)
    scene = sensors_scene([q])
    items = render_list(scene, SIDE_VIEW, 300, 200, grid=False)
    center, radius = scene.bounds()
    tip, _ = Projection(SIDE_VIEW, center, radius, 300, 200).project(scene.bodies[0].axis_tips())
    x_segments = [item.points for item in items if item.color == "axis_x"]
    assert any(np.allclose(segment[1], tip[0]) for segment in x_segments)
    # Seen from the side, a level-ish board shows its -y face, never its far +y face.
    assert sum(item.kind == "polygon" for item in items) <= 3
    # Far to near: the painter's order.
    depths = [item.depth for item in items]
    assert depths == sorted(depths)


def test_perspective_keeps_the_centre_and_enlarges_what_is_near():
    camera = Camera(azimuth_deg=0.0, elevation_deg=0.0, perspective=True)
    projection = Projection(camera, np.zeros(3), 1.0, 200, 200)
    pixels, depth = projection.project(np.array([[0, 0, 0], [0.5, 0, 0.5], [-0.5, 0, 0.5]]))
    assert pixels[0] == pytest.approx((100, 100))
    assert depth[1] > depth[2]  # the camera sits on +x
    assert 100 - pixels[1][1] > 100 - pixels[2][1] > 0  # the nearer point stands higher


def test_camera_orbit_wraps_azimuth_and_clamps_elevation():
    camera = Camera(azimuth_deg=170.0, elevation_deg=80.0).orbit(20.0, 30.0)
    assert camera.azimuth_deg == pytest.approx(-170.0)
    assert camera.elevation_deg == 89.0
    rows = camera.view_matrix()
    assert rows @ rows.T == pytest.approx(np.eye(3))


def test_attitudes_differ_only_beyond_the_threshold():
    a = quaternion_from_roll_pitch(10.0, 5.0)
    assert not attitudes_differ([a], [quaternion_from_roll_pitch(10.05, 5.0)], 0.1)
    assert attitudes_differ([a], [quaternion_from_roll_pitch(10.3, 5.0)], 0.1)
    assert attitudes_differ(None, [a], 0.1)
    assert attitudes_differ([a], [a, a], 0.1)


def image_of(view) -> QImage:
    QApplication.processEvents()
    return view.grab().toImage().convertToFormat(QImage.Format.Format_RGB32)


def pixels_of(image: QImage) -> np.ndarray:
    data = np.frombuffer(image.constBits(), dtype=np.uint8, count=image.sizeInBytes())
    # A copy: the QImage (and the memory the view points into) goes when the caller drops it.
    return data.reshape(image.height(), image.bytesPerLine())[:, : 4 * image.width()].copy()


def test_view_falls_back_to_a_drawing_offscreen_and_follows_the_attitude(
    qtbot, qapp, artifacts_dir
):
    theme.apply_theme(qapp)
    view = AttitudeView()
    qtbot.addWidget(view)
    view.resize(480, 400)
    view.show()
    assert view.backend == "painter"  # no OpenGL context on the offscreen platform
    assert "OpenGL" in view.backend_reason or "opengl" in view.backend_reason
    view.set_attitude(quaternion_from_roll_pitch(25.0, 30.0))
    first = pixels_of(image_of(view))
    assert len(np.unique(first.reshape(-1, 4)[:, :3], axis=0)) > 20  # a drawing, not a fill
    assert image_of(view).save(os.path.join(artifacts_dir, "attitude_view_fallback.png"))
    redraws = view.redraws
    view.set_attitude(quaternion_from_roll_pitch(25.02, 30.0))  # not visible: no redraw
    assert view.redraws == redraws
    view.set_attitude(quaternion_from_roll_pitch(-10.0, 5.0))
    assert view.redraws == redraws + 1
    second = pixels_of(image_of(view))
    assert np.count_nonzero(np.any(first != second, axis=1)) > 100


def send_mouse(widget, kind: QEvent.Type, x: float, y: float) -> None:
    buttons = Qt.MouseButton.NoButton if kind == QEvent.Type.MouseButtonRelease else (
        Qt.MouseButton.LeftButton
    )
    point = QPointF(x, y)
    event = QMouseEvent(kind, point, widget.mapToGlobal(point), Qt.MouseButton.LeftButton,
                        buttons, Qt.KeyboardModifier.NoModifier)
    QApplication.sendEvent(widget, event)


def test_dragging_turns_the_drawn_view(qtbot):
    view = AttitudeView(backend="painter")
    qtbot.addWidget(view)
    view.resize(400, 320)
    view.show()
    view.set_attitude(quaternion_from_roll_pitch(0.0, 20.0))
    before = pixels_of(image_of(view))
    camera = view.canvas.camera
    send_mouse(view.canvas, QEvent.Type.MouseButtonPress, 100, 100)
    send_mouse(view.canvas, QEvent.Type.MouseMove, 160, 120)
    send_mouse(view.canvas, QEvent.Type.MouseButtonRelease, 160, 120)
    assert view.canvas.camera.azimuth_deg == pytest.approx(camera.azimuth_deg - 30.0)
    assert view.canvas.camera.elevation_deg == pytest.approx(camera.elevation_deg + 10.0)
    assert np.any(pixels_of(image_of(view)) != before)


def test_view_draws_the_arm_when_asked(qtbot, qapp, artifacts_dir):
    theme.apply_theme(qapp)
    view = AttitudeView(backend="painter")
    qtbot.addWidget(view)
    view.resize(480, 400)
    view.show()
    view.set_attitude(quaternion_from_roll_pitch(0.0, 30.0))
    pose = forward(jamris_layout(), [30.0, 40.0, -70.0])
    view.set_arm(pose.points, pose.rotations, [1, 2])
    assert view.arm_box.isEnabled() and not view.showing_arm
    view.arm_box.setChecked(True)
    assert isinstance(view.canvas.scene, Scene) and view.canvas.scene.arm is not None
    assert view.canvas.scene.arm[-1] == pytest.approx(pose.end)
    assert len(view.canvas.scene.bodies) == 2
    assert image_of(view).save(os.path.join(artifacts_dir, "attitude_view_arm.png"))


@pytest.fixture
def window(qtbot, qapp, tmp_path):
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession()
    window = MainWindow(session, settings, "sim://interactive?odr=104")
    qtbot.addWidget(window)
    window.resize(1280, 860)
    window.show()
    qtbot.waitUntil(lambda: session.device_info is not None, timeout=TIMEOUT_MS)
    yield window
    window.close()


def test_main_window_3d_view_and_arm_follow_the_device(qtbot, window, artifacts_dir):
    assert window.docks["attitude3d"].isHidden()  # opened from the View menu
    window.docks["attitude3d"].toggleViewAction().trigger()
    window.docks["attitude3d"].raise_()
    qtbot.waitUntil(window.simulator_panel.roll_slider.isEnabled, timeout=TIMEOUT_MS)
    window.simulator_panel.set_target(15.0, 25.0, emit=True)
    view = window.attitude_view

    def shown_angles():
        if not view._quaternions:
            return (np.nan, np.nan)
        angles = angles_from_quaternion(view._quaternions[0])
        return float(angles.roll_deg), float(angles.pitch_deg)

    # The simulated unit is uncalibrated: the level reads a degree or two off the truth; the
    # 3D view and the arm show what the level shows.
    qtbot.waitUntil(lambda: abs(window.level.pitch() - 25.0) < 4.0, timeout=TIMEOUT_MS)
    qtbot.waitUntil(
        lambda: np.allclose(shown_angles(), (window.level.roll(), window.level.pitch()), atol=1.0),
        timeout=TIMEOUT_MS,
    )
    # The arm dock puts the device on the upper arm: its joint angle is the device's pitch.
    # (The arm is solved while someone can see it: open its dock.)
    window.docks["arm"].toggleViewAction().trigger()
    window.docks["arm"].raise_()
    panel = window.arm_panel
    qtbot.waitUntil(lambda: panel.pose is not None
                    and abs(panel.pose.joint_angles_deg[1] - window.level.pitch()) < 1.0,
                    timeout=TIMEOUT_MS)
    assert window.docks["attitude3d"].toggleViewAction().text() == "3D view"
    window.docks["attitude3d"].raise_()  # the screenshot shows the 3D view
    assert window.grab().save(os.path.join(artifacts_dir, "main_window_3d_view.png"))
