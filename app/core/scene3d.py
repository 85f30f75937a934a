"""The geometry of the 3D attitude view, and its projection to the screen, in numpy.

A scene holds sensor bodies (a board-shaped box with its x, y, z axes) and, optionally, an
arm's links as a polyline. :func:`render_list` projects it through a :class:`Camera`
(orthographic or perspective, orbiting the scene's centre; world z up) into 2D primitives
sorted far to near, so a painter draws them in order (hidden faces culled, faces shaded by
their angle to the light). The widgets only draw what comes out; an OpenGL view uses the same
geometry (:func:`box_triangles`).

Screen coordinates: x to the right, y downwards, in pixels.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from app.core import quaternion as quat

BOARD_SIZE = (1.0, 0.62, 0.1)
"""A sensor board's x, y, z extent (a breakout board's proportions), in scene units."""
AXIS_LENGTH = 0.85
BODY_SPACING = 1.6
BOX_FACES = np.array([
    [0, 1, 3, 2],  # -x
    [4, 6, 7, 5],  # +x
    [0, 4, 5, 1],  # -y
    [2, 3, 7, 6],  # +y
    [0, 2, 6, 4],  # -z
    [1, 5, 7, 3],  # +z (the board's top)
])
"""Corner indices of the six faces, counter-clockwise seen from outside; corner ``i`` has
the signs of bits (x, y, z) = (i >> 2, i >> 1, i) & 1."""
FACE_NORMALS = np.array(
    [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], dtype=np.float64
)
AXIS_KEYS = ("axis_x", "axis_y", "axis_z")
LIGHT = np.array([-0.35, 0.55, 0.76])
"""Light direction in camera coordinates (from the upper left, towards the viewer)."""


def rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    """The 3x3 matrix of a (sensor-to-earth) quaternion: its columns are the sensor axes."""
    return quat.rotate(np.asarray(q, dtype=np.float64), np.eye(3)).T


@dataclass(frozen=True, slots=True)
class Body:
    """One sensor: its rotation (columns = its axes in the scene), centre and size."""

    rotation: np.ndarray
    center: np.ndarray
    size: tuple[float, float, float] = BOARD_SIZE
    axis_length: float = AXIS_LENGTH
    label: str = ""

    def corners(self) -> np.ndarray:
        """(8, 3) corners; corner ``i`` has the signs of bits (x, y, z) of ``i``."""
        bits = (np.arange(8)[:, None] >> np.array([2, 1, 0])) & 1
        local = (bits - 0.5) * np.asarray(self.size)
        return self.center + local @ self.rotation.T

    def axis_tips(self) -> np.ndarray:
        """(3, 3) the tips of the x, y and z axes drawn from the centre."""
        return self.center + self.axis_length * self.rotation.T


@dataclass(frozen=True, slots=True)
class Scene:
    """Bodies, and the arm's joints as a polyline (None without an arm)."""

    bodies: tuple[Body, ...] = ()
    arm: np.ndarray | None = None
    earth_axes: bool = False
    """Draw the earth frame's axes, labelled E, N and Up (ENU, y toward magnetic north): for
    attitudes whose heading comes from the magnetometer, so the scene's directions are real."""

    def points(self) -> np.ndarray:
        parts = [b.corners() for b in self.bodies] + [b.axis_tips() for b in self.bodies]
        if self.arm is not None:
            parts.append(self.arm)
        return np.vstack(parts) if parts else np.zeros((1, 3))

    def bounds(self) -> tuple[np.ndarray, float]:
        """Centre and radius of a sphere around everything (radius at least 1e-6)."""
        points = self.points()
        low, high = points.min(axis=0), points.max(axis=0)
        center = 0.5 * (low + high)
        radius = float(np.max(np.linalg.norm(points - center, axis=1)))
        return center, max(radius, 1e-6)


EARTH_AXES = (("earth_e", "E", (1.0, 0.0, 0.0)), ("earth_n", "N", (0.0, 1.0, 0.0)),
              ("earth_up", "Up", (0.0, 0.0, 1.0)))
"""The earth frame's axes (ENU, y toward magnetic north): colour key, label, direction."""


def earth_axes_lines(scene: Scene) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """The earth axes of a scene with :attr:`Scene.earth_axes`: (colour key, label, start, tip)
    each, from the floor's south-west side (inside the framed sphere), 0.6 of its radius
    long."""
    center, radius = scene.bounds()
    floor = float(scene.points()[:, 2].min())
    origin = np.array([center[0] - 0.65 * radius, center[1] - 0.65 * radius, floor])
    return [(key, label, origin, origin + 0.6 * radius * np.asarray(direction))
            for key, label, direction in EARTH_AXES]


def sensors_scene(quaternions: Sequence[np.ndarray], labels: Sequence[str] = (),
                  earth_axes: bool = False) -> Scene:
    """Bodies for sensors side by side along the scene's y axis, each at its own attitude
    (with the earth frame's axes drawn when ``earth_axes``)."""
    n = len(quaternions)
    bodies = []
    for i, q in enumerate(quaternions):
        center = np.array([0.0, (i - 0.5 * (n - 1)) * BODY_SPACING, 0.0])
        label = labels[i] if i < len(labels) else ""
        bodies.append(Body(rotation_from_quaternion(q), center, label=label))
    return Scene(tuple(bodies), earth_axes=earth_axes)


def arm_scene(
    points: np.ndarray, rotations: np.ndarray, sensor_links: Sequence[int] | None = None
) -> Scene:
    """The arm's polyline (n + 1, 3), with a board on each sensor link's middle.

    ``rotations`` (n, 3, 3) are the link frames; boards are scaled to the arm's size.
    """
    points = np.asarray(points, dtype=np.float64)
    reach = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    scale = 0.14 * reach if reach > 0 else 1.0
    links = range(len(rotations)) if sensor_links is None else sensor_links
    bodies = tuple(
        Body(
            np.asarray(rotations[i]), 0.5 * (points[i] + points[i + 1]),
            size=tuple(scale * s for s in BOARD_SIZE), axis_length=scale * AXIS_LENGTH,  # type: ignore[arg-type]
        )
        for i in links
    )
    return Scene(bodies, points)


@dataclass(frozen=True, slots=True)
class Camera:
    """A camera orbiting the scene's centre; azimuth from +x towards +y, elevation upwards."""

    azimuth_deg: float = -55.0
    elevation_deg: float = 24.0
    perspective: bool = True
    zoom: float = 1.0

    def orbit(self, d_azimuth_deg: float, d_elevation_deg: float) -> Camera:
        """The camera turned by a mouse drag (elevation kept within +-89 degrees)."""
        elevation = float(np.clip(self.elevation_deg + d_elevation_deg, -89.0, 89.0))
        azimuth = (self.azimuth_deg + d_azimuth_deg + 180.0) % 360.0 - 180.0
        return replace(self, azimuth_deg=azimuth, elevation_deg=elevation)

    def zoomed(self, factor: float) -> Camera:
        return replace(self, zoom=float(np.clip(self.zoom * factor, 0.2, 8.0)))

    def view_matrix(self) -> np.ndarray:
        """Rows: the camera's right, up and towards-the-viewer directions in the world."""
        az, el = np.radians(self.azimuth_deg), np.radians(self.elevation_deg)
        back = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        right = np.cross(-back, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, -back)
        return np.vstack([right, up, back])


@dataclass(frozen=True, slots=True)
class Projection:
    """Maps world points to pixels for one camera, scene and viewport."""

    camera: Camera
    center: np.ndarray
    radius: float
    width: int
    height: int
    view: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "view", self.camera.view_matrix())

    def camera_coordinates(self, points: np.ndarray) -> np.ndarray:
        return (np.asarray(points, dtype=np.float64) - self.center) @ self.view.T

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) and depth (N,) of world points (larger depth = nearer the viewer)."""
        local = self.camera_coordinates(np.atleast_2d(points))
        scale = 0.42 * min(self.width, self.height) / self.radius * self.camera.zoom
        if self.camera.perspective:
            distance = 3.5 * self.radius
            factor = distance / np.maximum(distance - local[:, 2], 1e-6 * self.radius)
            # The scene's sphere keeps its size: the centre's depth has factor 1.
        else:
            factor = np.ones(len(local))
        pixels = np.column_stack([
            0.5 * self.width + scale * factor * local[:, 0],
            0.5 * self.height - scale * factor * local[:, 1],
        ])
        return pixels, local[:, 2]


@dataclass(frozen=True, slots=True)
class DrawItem:
    """A 2D primitive: a 'polygon' (filled, shaded) or a 'line' (k, 2 pixels), far to near."""

    kind: str
    points: np.ndarray
    depth: float
    color: str
    shade: float = 1.0
    width: float = 1.0
    text: str = ""
    """A 'label''s text (drawn at its one point, above everything)."""


def render_list(
    scene: Scene, camera: Camera, width: int, height: int, grid: bool = True
) -> list[DrawItem]:
    """The scene as 2D primitives for a ``width`` x ``height`` viewport, sorted far to near.

    Colour keys: ``body``, ``body_top`` (the board's +z face), ``axis_x/y/z``, ``arm``,
    ``joint`` (a one-point line: a dot), ``grid`` and ``earth_e/n/up`` (the earth axes, with
    'label' items E, N, Up at their tips); a labelled body's name comes last, a 'label' item
    (text centred under the board).
    """
    center, radius = scene.bounds()
    projection = Projection(camera, center, radius, max(width, 1), max(height, 1))
    items: list[DrawItem] = []
    if grid:
        items.extend(_grid_items(scene, projection, center, radius))
    light = LIGHT / np.linalg.norm(LIGHT)
    for body in scene.bodies:
        corners = body.corners()
        pixels, depth = projection.project(corners)
        normals = (body.rotation @ FACE_NORMALS.T).T @ projection.view.T
        for face, normal in enumerate(normals):
            face_center = corners[BOX_FACES[face]].mean(axis=0)
            world_normal = body.rotation @ FACE_NORMALS[face]
            if not (_faces_viewer(projection, face_center, world_normal) if camera.perspective
                    else normal[2] > 1e-9):
                continue
            shade = 0.45 + 0.55 * max(0.0, float(normal @ light))
            index = BOX_FACES[face]
            items.append(DrawItem(
                "polygon", pixels[index], float(depth[index].mean()),
                "body_top" if face == 5 else "body", shade,
            ))
        tips = body.axis_tips()
        for key, tip in zip(AXIS_KEYS, tips):
            # Two halves, so the painter's order is right where an axis leaves the body.
            middle = 0.5 * (body.center + tip)
            for a, b in ((body.center, middle), (middle, tip)):
                segment, seg_depth = projection.project(np.vstack([a, b]))
                items.append(DrawItem("line", segment, float(seg_depth.mean()) + 1e-9, key,
                                      width=3.0))
    if scene.arm is not None and len(scene.arm) > 1:
        pixels, depth = projection.project(scene.arm)
        for i in range(len(scene.arm) - 1):
            items.append(DrawItem("line", pixels[i:i + 2], float(depth[i:i + 2].mean()), "arm",
                                  width=6.0))
        for i in range(len(scene.arm)):
            items.append(DrawItem("line", pixels[i:i + 1], float(depth[i]) + 1e-6,
                                  "end" if i == len(scene.arm) - 1 else "joint", width=12.0))
    earth_labels = []
    if scene.earth_axes:
        for key, label, start, tip in earth_axes_lines(scene):
            segment, seg_depth = projection.project(np.vstack([start, tip]))
            items.append(DrawItem("line", segment, float(seg_depth.mean()), key, width=2.0))
            earth_labels.append(DrawItem("label", segment[1:] + np.array([0.0, -16.0]),
                                         math.inf, key, text=label))
    items.sort(key=lambda item: item.depth)
    items.extend(earth_labels)
    for body in scene.bodies:  # each sensor's name under its board, on top of the drawing
        if body.label:
            pixels, _depth = projection.project(body.corners())
            anchor = np.array([[pixels[:, 0].mean(), pixels[:, 1].max() + 4.0]])
            items.append(DrawItem("label", anchor, math.inf, "joint", text=body.label))
    return items


def _faces_viewer(projection: Projection, face_center: np.ndarray, normal: np.ndarray) -> bool:
    """Whether a face turns towards a perspective camera (seen from the eye point)."""
    eye_local = np.array([0.0, 0.0, 3.5 * projection.radius])
    eye = projection.center + eye_local @ projection.view
    return float((eye - face_center) @ normal) > 0.0


def _grid_items(
    scene: Scene, projection: Projection, center: np.ndarray, radius: float
) -> list[DrawItem]:
    """A square grid on the floor under the scene (at its lowest point)."""
    floor = float(scene.points()[:, 2].min())
    half = 1.5 * radius
    step = _nice_step(2 * half / 10)
    low = np.floor((center[:2] - half) / step) * step
    high = np.ceil((center[:2] + half) / step) * step
    lines = []
    for x in np.arange(low[0], high[0] + 0.5 * step, step):
        lines.append(([x, low[1], floor], [x, high[1], floor]))
    for y in np.arange(low[1], high[1] + 0.5 * step, step):
        lines.append(([low[0], y, floor], [high[0], y, floor]))
    items = []
    for a, b in lines:
        pixels, depth = projection.project(np.array([a, b]))
        items.append(DrawItem("line", pixels, float(depth.min()) - 10 * radius, "grid"))
    return items


def _nice_step(raw: float) -> float:
    exponent = np.floor(np.log10(raw))
    for mantissa in (1.0, 2.0, 5.0, 10.0):
        if mantissa * 10**exponent >= raw:
            return float(mantissa * 10**exponent)
    return float(10 ** (exponent + 1))


def box_triangles(body: Body) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) and triangles (12, 3) of a body, for a mesh-drawing (OpenGL) view."""
    faces = BOX_FACES
    triangles = np.vstack([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
    return body.corners(), triangles


def attitudes_differ(
    previous: Sequence[np.ndarray] | None, current: Sequence[np.ndarray], threshold_deg: float
) -> bool:
    """Whether any attitude turned by more than ``threshold_deg`` (or their number changed)."""
    if previous is None or len(previous) != len(current):
        return True
    if not len(current):
        return False
    angle = np.degrees(quat.angle_between(np.asarray(previous), np.asarray(current)))
    return bool(np.any(angle > threshold_deg)) or not np.all(np.isfinite(angle))
