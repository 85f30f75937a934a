"""The 3D attitude view: each sensor as a board with its x, y, z axes, and the arm's links.

Two canvases draw the same geometry (:mod:`app.core.scene3d`): an OpenGL one
(pyqtgraph.opengl, when PyOpenGL is installed and an OpenGL context can be made) and a
QPainter one that needs no OpenGL (the offscreen platform, remote desktops, old drivers).
:func:`opengl_support` decides at run time; ``INCLINOMETER_3D=painter`` forces the drawing.
Drag with the mouse to turn the view, wheel to zoom, double-click to reset. The view redraws
only when an attitude turned by more than :data:`REDRAW_THRESHOLD_DEG` or the arm moved.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from PySide6.QtCore import QPointF, QRectF, QSize, Qt
from PySide6.QtGui import (
    QColor,
    QGuiApplication,
    QMouseEvent,
    QOffscreenSurface,
    QOpenGLContext,
    QPainter,
    QPaintEvent,
    QPen,
    QPolygonF,
    QShowEvent,
    QWheelEvent,
)
from PySide6.QtWidgets import QCheckBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.core.scene3d import (
    FACE_NORMALS,
    Camera,
    Scene,
    arm_scene,
    attitudes_differ,
    box_triangles,
    earth_axes_lines,
    render_list,
    sensors_scene,
)
from app.gui import theme

EARTH_LEGEND = "earth: E, N (magnetic), Up"
"""The legend of the earth axes, drawn while the heading comes from the magnetometer."""
REDRAW_THRESHOLD_DEG = 0.1
"""A turn smaller than this does not redraw (it moves nothing by a pixel at usual sizes)."""
ARM_REDRAW_FRACTION = 1e-3
"""The arm redraws when a joint moved by more than this fraction of its reach."""
DEGREES_PER_PIXEL = 0.5
COLORS = {
    "body": QColor("#6f7a86"),
    "body_top": QColor("#3f7fa8"),
    "axis_x": QColor(theme.AXIS_X),
    "axis_y": QColor(theme.AXIS_Y),
    "axis_z": QColor(theme.AXIS_Z),
    "arm": QColor(theme.TRACE_TILT),
    "joint": QColor(theme.TEXT),
    "end": QColor(theme.ALARM_RED),
    "grid": QColor(theme.PLOT_GRID),
    "earth_e": QColor(theme.TEXT_DIM),
    "earth_n": QColor(theme.ALARM_RED),
    "earth_up": QColor(theme.TEXT_DIM),
}


def opengl_support() -> tuple[bool, str]:
    """Whether the OpenGL canvas can run here, and why not."""
    if os.environ.get("INCLINOMETER_3D", "").lower() == "painter":
        return False, "INCLINOMETER_3D=painter"
    try:
        import pyqtgraph.opengl  # noqa: F401  (needs PyOpenGL)
    except Exception as exc:  # ImportError, or PyOpenGL failing to find a GL library
        return False, f"pyqtgraph.opengl unavailable ({type(exc).__name__}: {exc})"
    try:
        context = QOpenGLContext()
        if not context.create():
            return False, f"no OpenGL context on the {QGuiApplication.platformName()} platform"
        surface = QOffscreenSurface()
        surface.setFormat(context.format())
        surface.create()
        if not surface.isValid() or not context.makeCurrent(surface):
            return False, "an OpenGL context cannot be made current"
        context.doneCurrent()
    except Exception as exc:  # a broken driver must not take the app down
        return False, f"OpenGL failed: {exc}"
    return True, "OpenGL"


class PainterCanvas(QWidget):
    """The scene drawn with QPainter from the core's projection (no OpenGL needed)."""

    backend = "painter"

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.scene = Scene()
        self.camera = Camera()
        self._drag: QPointF | None = None
        self.paints = 0
        self.setMinimumSize(200, 160)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)

    def set_scene(self, scene: Scene) -> None:
        self.scene = scene
        self.update()

    def set_camera(self, camera: Camera) -> None:
        self.camera = camera
        self.update()

    def paintEvent(self, event: QPaintEvent) -> None:
        self.paints += 1
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        painter.fillRect(self.rect(), QColor(theme.BASE_BG))
        if not self.scene.bodies and self.scene.arm is None:
            painter.setPen(QColor(theme.TEXT_DIM))
            painter.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter, "No attitude yet")
            return
        for item in render_list(self.scene, self.camera, self.width(), self.height()):
            color = COLORS[item.color]
            if item.kind == "label":
                painter.setPen(color)
                x, y = item.points[0]
                painter.drawText(QRectF(x - 80.0, y, 160.0, 20.0),
                                 Qt.AlignmentFlag.AlignHCenter | Qt.AlignmentFlag.AlignTop,
                                 item.text)
            elif item.kind == "polygon":
                fill = QColor.fromRgbF(*(min(1.0, c * item.shade) for c in color.getRgbF()[:3]))
                painter.setPen(QPen(fill.darker(140), 1.0))
                painter.setBrush(fill)
                painter.drawPolygon(QPolygonF([QPointF(*p) for p in item.points]))
            elif len(item.points) == 1:  # a joint: a dot
                painter.setPen(Qt.PenStyle.NoPen)
                painter.setBrush(color)
                radius = 0.5 * item.width
                painter.drawEllipse(QPointF(*item.points[0]), radius, radius)
            else:
                pen = QPen(color, item.width)
                pen.setCapStyle(Qt.PenCapStyle.RoundCap)
                painter.setPen(pen)
                painter.drawLine(QPointF(*item.points[0]), QPointF(*item.points[1]))
        self._draw_legend(painter)

    def _draw_legend(self, painter: QPainter) -> None:
        font = painter.font()
        font.setBold(True)
        painter.setFont(font)
        x = 10
        for key, name in (("axis_x", "x"), ("axis_y", "y"), ("axis_z", "z")):
            painter.setPen(COLORS[key])
            painter.drawText(x, 20, name)
            x += 16
        if self.scene.earth_axes:
            painter.setPen(COLORS["earth_e"])
            painter.drawText(x + 8, 20, EARTH_LEGEND)

    # -- mouse: turn and zoom -------------------------------------------------------------------
    def mousePressEvent(self, event: QMouseEvent) -> None:
        self._drag = event.position()

    def mouseMoveEvent(self, event: QMouseEvent) -> None:
        if self._drag is None:
            return
        delta = event.position() - self._drag
        self._drag = event.position()
        self.set_camera(
            self.camera.orbit(-delta.x() * DEGREES_PER_PIXEL, delta.y() * DEGREES_PER_PIXEL)
        )

    def mouseReleaseEvent(self, event: QMouseEvent) -> None:
        self._drag = None

    def mouseDoubleClickEvent(self, event: QMouseEvent) -> None:
        self.set_camera(Camera(perspective=self.camera.perspective))

    def wheelEvent(self, event: QWheelEvent) -> None:
        self.set_camera(self.camera.zoomed(1.15 ** (event.angleDelta().y() / 120.0)))


def face_colors(body) -> np.ndarray:
    """RGBA per triangle of :func:`box_triangles`, lit from above (a fixed light: the OpenGL
    camera turns freely, and a board's top should stay the brightest when it faces up)."""
    normals = np.vstack([FACE_NORMALS, FACE_NORMALS]) @ body.rotation.T
    shade = 0.55 + 0.45 * np.clip(normals @ np.array([0.3, -0.2, 0.93]), 0.0, 1.0)
    base = np.array([COLORS["body"].getRgbF()] * 12)
    base[[5, 11]] = COLORS["body_top"].getRgbF()  # the +z face's two triangles
    base[:, :3] *= shade[:, None]
    return base


def _gl_canvas_class():
    """The OpenGL canvas (defined on demand: pyqtgraph.opengl imports PyOpenGL)."""
    import pyqtgraph.opengl as gl

    class GLCanvas(gl.GLViewWidget):
        """The scene as OpenGL meshes and lines; pyqtgraph's camera turns with the mouse."""

        backend = "opengl"

        def __init__(self, parent: QWidget | None = None) -> None:
            super().__init__(parent)
            self.setBackgroundColor(QColor(theme.BASE_BG))
            self.setMinimumSize(200, 160)
            self.scene = Scene()
            self.paints = 0
            self._items: list = []
            self._shape: tuple | None = None
            self._radius = 0.0
            self._grid = gl.GLGridItem()
            self._grid.setColor(QColor(theme.PLOT_GRID))
            self.addItem(self._grid)
            self.setCameraPosition(distance=6.0, elevation=24.0, azimuth=-55.0)

        def paintGL(self, *args, **kwargs) -> None:
            self.paints += 1
            super().paintGL(*args, **kwargs)

        def set_scene(self, scene: Scene) -> None:
            """Show a scene: items are updated in place while its make-up stays the same."""
            shape = (len(scene.bodies), scene.arm is not None and len(scene.arm),
                     scene.earth_axes)
            if shape != self._shape:
                for item in self._items:
                    self.removeItem(item)
                self._items = self._make_items(scene)
                for item in self._items:
                    self.addItem(item)
                self._shape = shape
            center, radius = scene.bounds()
            items = iter(self._items)
            for body in scene.bodies:
                vertices, faces = box_triangles(body)
                next(items).setMeshData(vertexes=vertices - center, faces=faces,
                                        faceColors=face_colors(body))
                for tip in body.axis_tips():
                    next(items).setData(pos=np.vstack([body.center, tip]) - center)
            if scene.arm is not None:
                next(items).setData(pos=scene.arm - center)
                next(items).setData(pos=scene.arm - center)
            if scene.earth_axes:
                for _key, label, start, tip in earth_axes_lines(scene):
                    next(items).setData(pos=np.vstack([start, tip]) - center)
                    next(items).setData(pos=tip - center, text=label)
            if radius != self._radius:  # a new size: frame it again
                self._radius = radius
                spacing = radius / 4
                self._grid.setSpacing(spacing, spacing, spacing)
                self._grid.setSize(4 * radius, 4 * radius, 1)
                self.opts["distance"] = 3.5 * radius
            floor = float(scene.points()[:, 2].min() - center[2])
            self._grid.resetTransform()
            self._grid.translate(0.0, 0.0, floor)
            self.scene = scene
            self.update()

        @staticmethod
        def _make_items(scene: Scene) -> list:
            items: list = []
            for _body in scene.bodies:
                items.append(gl.GLMeshItem(
                    smooth=False, shader=None, drawEdges=True,
                    edgeColor=QColor(theme.BASE_BG).getRgbF(), glOptions="opaque",
                ))
                for key in ("axis_x", "axis_y", "axis_z"):
                    items.append(gl.GLLinePlotItem(color=COLORS[key].getRgbF(), width=3.0,
                                                   antialias=True))
            if scene.arm is not None:
                items.append(gl.GLLinePlotItem(color=COLORS["arm"].getRgbF(), width=6.0,
                                               antialias=True))
                items.append(gl.GLScatterPlotItem(color=COLORS["joint"].getRgbF(), size=10.0))
            if scene.earth_axes:
                for key, _label, _start, _tip in earth_axes_lines(scene):
                    items.append(gl.GLLinePlotItem(color=COLORS[key].getRgbF(), width=2.0,
                                                   antialias=True))
                    items.append(gl.GLTextItem(color=COLORS[key]))
            return items

    return GLCanvas


class AttitudeView(QWidget):
    """Sensors' attitudes in 3D (and the arm): feed quaternions, an arm pose, or both.

    ``backend`` is "opengl", "painter" or None (OpenGL when it works, else the drawing).
    """

    def __init__(self, parent: QWidget | None = None, backend: str | None = None) -> None:
        super().__init__(parent)
        usable, reason = opengl_support() if backend in (None, "opengl") else (False, backend)
        self.canvas = None
        if usable:
            try:
                self.canvas = _gl_canvas_class()(self)
            except Exception as exc:  # the context was there, the canvas failed: draw instead
                reason = f"OpenGL canvas failed: {exc}"
        if self.canvas is None:
            self.canvas = PainterCanvas(self)
        self.backend_reason = reason
        self.note = QLabel(
            "OpenGL · drag to turn, wheel to zoom" if self.canvas.backend == "opengl"
            else "Drawn without OpenGL · drag to turn, wheel to zoom, double-click to reset"
        )
        self.note.setToolTip(reason)
        self.note.setObjectName("dimLabel")
        self.note.setWordWrap(True)
        self.arm_box = QCheckBox("Show arm")
        self.arm_box.setToolTip("Draw the measuring arm (its layout is in the Arm dock)")
        self.arm_box.setEnabled(False)
        self.arm_box.toggled.connect(lambda _on: self._redraw())
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.canvas, 1)
        row = QHBoxLayout()
        row.setContentsMargins(6, 0, 6, 2)
        row.addWidget(self.note, 1)
        row.addWidget(self.arm_box)
        layout.addLayout(row)
        self._quaternions: list[np.ndarray] | None = None
        self._labels: tuple[str, ...] = ()
        self._earth_frame = False
        self._arm: tuple[np.ndarray, np.ndarray, tuple[int, ...] | None] | None = None
        self.redraws = 0
        self._redraw_pending = False

    @property
    def backend(self) -> str:
        return self.canvas.backend

    def sizeHint(self) -> QSize:
        return QSize(420, 340)

    # -- feeding --------------------------------------------------------------------------
    def set_attitude(self, q: np.ndarray) -> None:
        """One sensor's orientation quaternion (w, x, y, z), sensor to earth."""
        self.set_attitudes([q])

    def set_attitudes(self, quaternions: Sequence[np.ndarray], labels: Sequence[str] = ()) -> None:
        """Every sensor's orientation; redraws only if one turned visibly."""
        current = [np.asarray(q, dtype=np.float64).reshape(4) for q in quaternions]
        if not all(np.all(np.isfinite(q)) for q in current):
            return
        if not attitudes_differ(self._quaternions, current, REDRAW_THRESHOLD_DEG) and (
            tuple(labels) == self._labels
        ):
            return
        self._quaternions = current
        self._labels = tuple(labels)
        if not self.showing_arm:
            self._redraw()

    def set_arm(
        self, points: np.ndarray, rotations: np.ndarray, sensor_links: Sequence[int] | None = None
    ) -> None:
        """The arm: its joints (n + 1, 3) and link frames (n, 3, 3), boards on sensor links.

        It is drawn (instead of the sensors alone) while the view's Arm box is ticked.
        """
        points = np.asarray(points, dtype=np.float64)
        rotations = np.asarray(rotations, dtype=np.float64)
        if not np.all(np.isfinite(points)):
            return
        links = None if sensor_links is None else tuple(sensor_links)
        if self._arm is not None and self._arm[0].shape == points.shape and self._arm[2] == links:
            reach = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))) or 1.0
            moved = float(np.max(np.linalg.norm(self._arm[0] - points, axis=1)))
            if moved <= ARM_REDRAW_FRACTION * reach:
                return
        self._arm = (points, rotations, links)
        first = not self.arm_box.isEnabled()
        self.arm_box.setEnabled(True)
        if self.showing_arm or first:
            self._redraw()

    def set_earth_frame(self, on: bool) -> None:
        """Whether the attitudes' heading is real (a filter taking it from the magnetometer):
        the earth's E, N and Up axes are drawn then."""
        if bool(on) != self._earth_frame:
            self._earth_frame = bool(on)
            self._redraw()

    def earth_frame(self) -> bool:
        return self._earth_frame

    def clear_arm(self) -> None:
        self._arm = None
        self.arm_box.setEnabled(False)
        self._redraw()

    @property
    def showing_arm(self) -> bool:
        return self._arm is not None and self.arm_box.isChecked()

    def showEvent(self, event: QShowEvent) -> None:
        """Shown again: draw what changed while hidden."""
        super().showEvent(event)
        if self._redraw_pending:
            self._redraw()

    def _redraw(self) -> None:
        if not self.isVisible():  # a hidden view (a closed dock, another tab) draws nothing
            self._redraw_pending = True
            return
        self._redraw_pending = False
        if self.showing_arm:
            scene = arm_scene(*self._arm)
        elif self._quaternions:
            scene = sensors_scene(self._quaternions, self._labels, self._earth_frame)
        else:
            scene = Scene()
        self.redraws += 1
        self.canvas.set_scene(scene)
