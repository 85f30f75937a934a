"""How much of the sphere a magnetometer tour covered: 80 sections, as MAVLink reports it.

MAVLink's ``MAG_CAL_PROGRESS.completion_mask`` is ``uint8[10]``: one bit per section of a
sphere cut into 80 parts, section ``k`` in byte ``k // 8``, bit ``k % 8`` (ArduPilot's
layout). The sections here are those of a geodesic grid, as in ArduPilot: the 20 faces of an
icosahedron, each cut into 4 triangles through its edges' midpoints (projected onto the
sphere), so every section spans about 1/80 of the directions. Section ``4 f + j`` is face
``f``'s corner triangle ``j`` (``j`` = 0, 1, 2) or its middle triangle (``j`` = 3). The
numbering of the faces is this module's own; the bit layout is MAVLink's.

:class:`CoverageTracker` takes field rows as they arrive (NaN rows are skipped), centres them
on the hard iron (given, or estimated from the rows so far by a sphere fit) and marks the
sections their directions fall in; :func:`section_outlines` gives a view what to draw.
"""

from __future__ import annotations

import math

import numpy as np

SECTIONS = 80
MASK_BYTES = SECTIONS // 8


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    """Unit vertices (12, 3) and faces (20, 3) of indices, each face counter-clockwise
    seen from outside."""
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    vertices = np.array([
        [-1, phi, 0], [1, phi, 0], [-1, -phi, 0], [1, -phi, 0],
        [0, -1, phi], [0, 1, phi], [0, -1, -phi], [0, 1, -phi],
        [phi, 0, -1], [phi, 0, 1], [-phi, 0, -1], [-phi, 0, 1],
    ], dtype=np.float64)
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    faces = np.array([
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
        [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
        [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ])
    return vertices, faces


def _grid() -> tuple[np.ndarray, np.ndarray]:
    """The 80 sections' corners (80, 3, 3) on the unit sphere, and the 20 faces' unit
    normals (20, 3)."""
    vertices, faces = _icosahedron()
    corners = np.empty((SECTIONS, 3, 3))
    normals = np.empty((20, 3))
    for f, (a, b, c) in enumerate(faces):
        va, vb, vc = vertices[a], vertices[b], vertices[c]
        centre = va + vb + vc
        normals[f] = centre / np.linalg.norm(centre)

        def mid(p: np.ndarray, q: np.ndarray) -> np.ndarray:
            m = p + q
            return m / np.linalg.norm(m)

        ab, bc, ca = mid(va, vb), mid(vb, vc), mid(vc, va)
        corners[4 * f + 0] = (va, ab, ca)
        corners[4 * f + 1] = (vb, bc, ab)
        corners[4 * f + 2] = (vc, ca, bc)
        corners[4 * f + 3] = (ab, bc, ca)
    return corners, normals


_CORNERS, _FACE_NORMALS = _grid()
# For face f and corner j: the normal of the great circle through the corner triangle's two
# midpoints, pointing toward the corner (a direction beyond it is in the corner triangle).
_CUT_NORMALS = np.empty((20, 3, 3))
for _f in range(20):
    for _j in range(3):
        _vertex, _m1, _m2 = _CORNERS[4 * _f + _j]
        _n = np.cross(_m1, _m2)
        _CUT_NORMALS[_f, _j] = _n if _n @ _vertex > 0 else -_n


def section_of(directions: np.ndarray) -> np.ndarray:
    """Section index (0..79) of each row of ``directions`` (N, 3) (any length but zero;
    -1 for a zero or non-finite row)."""
    v = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    out = np.full(v.shape[0], -1, dtype=np.int64)
    norm = np.linalg.norm(v, axis=1)
    ok = np.isfinite(norm) & (norm > 0)
    if not np.any(ok):
        return out
    u = v[ok] / norm[ok, None]
    # The ray through u meets the face whose normal is closest (all faces are equally far).
    face = np.argmax(u @ _FACE_NORMALS.T, axis=1)
    sides = np.einsum("nk,njk->nj", u, _CUT_NORMALS[face])
    corner = np.argmax(sides, axis=1)
    inside_corner = sides[np.arange(len(u)), corner] > 0
    out[ok] = 4 * face + np.where(inside_corner, corner, 3)
    return out


def completion_mask(mask: np.ndarray) -> bytes:
    """80 booleans -> MAVLink's ``completion_mask`` (10 bytes, section k = byte k//8, bit k%8)."""
    bits = np.asarray(mask, dtype=bool).reshape(SECTIONS)
    return bytes(int(sum(1 << i for i in range(8) if bits[8 * b + i]))
                 for b in range(MASK_BYTES))


def mask_from_completion(data: bytes) -> np.ndarray:
    """Inverse of :func:`completion_mask`."""
    if len(data) != MASK_BYTES:
        raise ValueError(f"a completion mask has {MASK_BYTES} bytes, not {len(data)}")
    return np.array([bool(data[k // 8] >> (k % 8) & 1) for k in range(SECTIONS)])


def coverage_mask(directions: np.ndarray) -> np.ndarray:
    """Which of the 80 sections the rows' directions fall in (80 bools)."""
    mask = np.zeros(SECTIONS, dtype=bool)
    sections = section_of(directions)
    mask[sections[sections >= 0]] = True
    return mask


def _az_el(v: np.ndarray) -> np.ndarray:
    """(..., 3) directions -> (..., 2) azimuth (atan2(y, x), -180..180) and elevation, degrees."""
    return np.stack([np.degrees(np.arctan2(v[..., 1], v[..., 0])),
                     np.degrees(np.arcsin(np.clip(v[..., 2] / np.linalg.norm(v, axis=-1),
                                                  -1.0, 1.0)))], axis=-1)


def section_centres() -> np.ndarray:
    """(80, 3) unit vector at each section's centre."""
    centre = _CORNERS.sum(axis=1)
    return centre / np.linalg.norm(centre, axis=1, keepdims=True)


def section_outlines(points_per_edge: int = 6) -> list[np.ndarray]:
    """Each section's outline as (M, 2) azimuth/elevation in degrees (closed: the first
    point again at the end), following the great-circle edges; the azimuth is unwrapped along
    the outline, so it may leave -180..180 by up to a section's width (draw it shifted by
    +-360 as well). Section order as in :func:`section_of`."""
    outlines = []
    steps = np.linspace(0.0, 1.0, points_per_edge, endpoint=False)
    for corners in _CORNERS:
        edge_points = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            p = corners[a] * (1 - steps[:, None]) + corners[b] * steps[:, None]
            edge_points.append(p / np.linalg.norm(p, axis=1, keepdims=True))
        ring = np.vstack([*edge_points, corners[:1]])
        az_el = _az_el(ring)
        az_el[:, 0] = np.degrees(np.unwrap(np.radians(az_el[:, 0])))
        outlines.append(az_el)
    return outlines


def section_centres_az_el() -> np.ndarray:
    """(80, 2) azimuth/elevation of the section centres, degrees."""
    return _az_el(section_centres())


class CoverageTracker:
    """The sections a tour has covered so far, from field rows given as they arrive.

    ``centre_ut`` is the hard iron to centre the field on; without it the tracker fits a
    sphere to the rows so far (a running least-squares fit, cheap per row) and, when its
    centre moves by more than ``recentre_fraction`` of the radius, sorts every kept row into
    the sections again. ``soft_iron`` (optional) is applied after centring. NaN rows are
    ignored.
    """

    MIN_ROWS_FOR_SPHERE = 20

    def __init__(self, centre_ut: np.ndarray | None = None,
                 soft_iron: np.ndarray | None = None, recentre_fraction: float = 0.02) -> None:
        self._fixed_centre = None if centre_ut is None else np.asarray(centre_ut, float).copy()
        self._soft = None if soft_iron is None else np.asarray(soft_iron, float).copy()
        self._recentre = float(recentre_fraction)
        self._rows: list[np.ndarray] = []
        self._normal = np.zeros((4, 4))
        self._rhs = np.zeros(4)
        self._count = 0
        self._centre: np.ndarray | None = self._fixed_centre
        self._radius = math.nan
        self._mask = np.zeros(SECTIONS, dtype=bool)

    @property
    def rows(self) -> int:
        """Field rows taken so far."""
        return self._count

    @property
    def centre_ut(self) -> np.ndarray | None:
        """The centre in use (None until enough rows for a sphere fit)."""
        return None if self._centre is None else self._centre.copy()

    @property
    def mask(self) -> np.ndarray:
        """80 bools: the sections covered."""
        return self._mask.copy()

    @property
    def fraction(self) -> float:
        """The fraction of the 80 sections covered (0..1)."""
        return float(np.count_nonzero(self._mask)) / SECTIONS

    def completion_mask(self) -> bytes:
        """MAVLink's ``MAG_CAL_PROGRESS.completion_mask`` (10 bytes)."""
        return completion_mask(self._mask)

    def reset(self) -> None:
        self.__init__(self._fixed_centre, self._soft, self._recentre)  # type: ignore[misc]

    def add(self, mag_ut: np.ndarray) -> None:
        """Take field rows (N, 3) in uT; rows with a NaN are skipped."""
        rows = np.asarray(mag_ut, dtype=np.float64).reshape(-1, 3)
        rows = rows[np.all(np.isfinite(rows), axis=1)]
        if rows.shape[0] == 0:
            return
        self._rows.append(rows)
        self._count += rows.shape[0]
        if self._fixed_centre is not None:
            self._mark(rows)
            return
        # Sphere |x|^2 = 2 c.x + k: linear in (c, k); accumulate the normal equations.
        design = np.column_stack([2.0 * rows, np.ones(rows.shape[0])])
        self._normal += design.T @ design
        self._rhs += design.T @ np.einsum("ij,ij->i", rows, rows)
        if self._count < self.MIN_ROWS_FOR_SPHERE:
            return
        try:
            solution = np.linalg.solve(self._normal, self._rhs)
        except np.linalg.LinAlgError:
            return
        centre = solution[:3]
        radius_sq = solution[3] + centre @ centre
        if not np.all(np.isfinite(centre)) or radius_sq <= 0:
            return
        radius = math.sqrt(radius_sq)
        if (self._centre is None
                or np.linalg.norm(centre - self._centre) > self._recentre * radius):
            self._centre, self._radius = centre, radius
            self._mask = coverage_mask(self._directions(np.vstack(self._rows)))
            self._rows = [np.vstack(self._rows)]
        else:
            self._mark(rows)

    def _directions(self, rows: np.ndarray) -> np.ndarray:
        assert self._centre is not None
        centred = rows - self._centre
        return centred if self._soft is None else centred @ self._soft.T

    def _mark(self, rows: np.ndarray) -> None:
        sections = section_of(self._directions(rows))
        self._mask[sections[sections >= 0]] = True
