"""The layout of a measuring arm: a chain of links, each joined to the one before by a hinge.

Frames
------
The base frame has z up (the earth's, as everywhere in the app). Link ``i`` has a frame of its
own; with every joint at zero all link frames coincide with the base frame. Joint ``i`` turns
link ``i`` relative to link ``i - 1`` (the base for the first link) about ``axis``, a unit
vector in link ``i - 1``'s frame, by ``offset_deg + angle``; the right-hand rule gives the
sign. Link ``i`` runs from its joint along ``direction`` (in its own frame) for ``length``.

The JAMRIS arm (:func:`jamris_layout`): a column turning about the vertical, then two links
on hinges about horizontal axes, their angles positive upwards.

A layout is plain data; :meth:`ArmLayout.to_dict` / :meth:`ArmLayout.from_dict` (and the JSON
helpers) round-trip it, and bad input raises :class:`ArmLayoutError` with the reason.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from app.core.bounded_input import JsonInputError, loads_json, read_bounded

LAYOUT_FORMAT = "inclinometer-arm-layout"
LAYOUT_VERSION = 1
VERTICAL = (0.0, 0.0, 1.0)
ALONG_X = (1.0, 0.0, 0.0)
PITCH_UP = (0.0, -1.0, 0.0)
"""A hinge about -y: positive angles raise a link that runs along +x."""


class ArmLayoutError(ValueError):
    """A layout that cannot describe an arm (the message says why)."""


def _unit_vector(value, what: str) -> tuple[float, float, float]:
    try:
        vector = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError) as exc:
        raise ArmLayoutError(f"{what} must be three numbers, got {value!r}") from exc
    norm = float(np.linalg.norm(vector))
    if not np.all(np.isfinite(vector)) or norm < 1e-9:
        raise ArmLayoutError(f"{what} must be a finite, non-zero vector, got {value!r}")
    return tuple(float(v) for v in vector / norm)  # type: ignore[return-value]


@dataclass(frozen=True, slots=True)
class Link:
    """One link: its name, its length, and the hinge joining it to the previous link."""

    name: str
    length: float
    axis: tuple[float, float, float] = PITCH_UP
    direction: tuple[float, float, float] = ALONG_X
    offset_deg: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ArmLayoutError("every link needs a name")
        try:
            length = float(self.length)
            offset = float(self.offset_deg)
        except (TypeError, ValueError) as exc:
            raise ArmLayoutError(f"link {self.name!r}: length and offset must be numbers") from exc
        if not np.isfinite(length) or length < 0.0:
            raise ArmLayoutError(f"link {self.name!r}: length must be >= 0, got {self.length!r}")
        if not np.isfinite(offset):
            raise ArmLayoutError(f"link {self.name!r}: offset must be finite")
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "offset_deg", offset)
        object.__setattr__(self, "axis", _unit_vector(self.axis, f"link {self.name!r} axis"))
        object.__setattr__(
            self, "direction", _unit_vector(self.direction, f"link {self.name!r} direction")
        )

    def to_dict(self) -> dict:
        return {
            "name": self.name, "length": self.length, "axis": list(self.axis),
            "direction": list(self.direction), "offset_deg": self.offset_deg,
        }

    @classmethod
    def from_dict(cls, data: dict) -> Link:
        if not isinstance(data, dict):
            raise ArmLayoutError(f"a link must be an object, got {data!r}")
        if "length" not in data:
            raise ArmLayoutError(f"link {data.get('name', '?')!r} has no length")
        return cls(
            name=str(data.get("name", "")),
            length=data["length"],
            axis=tuple(data.get("axis", PITCH_UP)),
            direction=tuple(data.get("direction", ALONG_X)),
            offset_deg=data.get("offset_deg", 0.0),
        )


@dataclass(frozen=True, slots=True)
class ArmLayout:
    """A chain of links from the base; ``unit`` names the unit of the lengths (e.g. mm)."""

    links: tuple[Link, ...]
    unit: str = "mm"
    name: str = "arm"
    base_position: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))

    def __post_init__(self) -> None:
        links = tuple(self.links)
        if not links:
            raise ArmLayoutError("an arm needs at least one link")
        if not all(isinstance(link, Link) for link in links):
            raise ArmLayoutError("links must be Link objects")
        names = [link.name for link in links]
        if len(set(names)) != len(names):
            raise ArmLayoutError(f"link names must differ: {names}")
        base = np.asarray(self.base_position, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(base)):
            raise ArmLayoutError("the base position must be finite")
        object.__setattr__(self, "links", links)
        object.__setattr__(self, "base_position", tuple(float(v) for v in base))

    @property
    def n_joints(self) -> int:
        return len(self.links)

    @property
    def lengths(self) -> np.ndarray:
        return np.array([link.length for link in self.links])

    def with_lengths(self, lengths) -> ArmLayout:
        """The same layout with new link lengths (one per link)."""
        lengths = list(lengths)
        if len(lengths) != len(self.links):
            raise ArmLayoutError(f"{len(lengths)} lengths for {len(self.links)} links")
        links = tuple(
            Link(link.name, length, link.axis, link.direction, link.offset_deg)
            for link, length in zip(self.links, lengths)
        )
        return ArmLayout(links, self.unit, self.name, self.base_position)

    def to_dict(self) -> dict:
        return {
            "format": LAYOUT_FORMAT, "version": LAYOUT_VERSION, "name": self.name,
            "unit": self.unit, "base_position": list(self.base_position),
            "links": [link.to_dict() for link in self.links],
        }

    @classmethod
    def from_dict(cls, data: dict) -> ArmLayout:
        if not isinstance(data, dict):
            raise ArmLayoutError("an arm layout must be a JSON object")
        if data.get("format", LAYOUT_FORMAT) != LAYOUT_FORMAT:
            raise ArmLayoutError(f"not an arm layout (format {data.get('format')!r})")
        version = data.get("version", LAYOUT_VERSION)
        if not isinstance(version, int) or version > LAYOUT_VERSION:
            raise ArmLayoutError(f"arm layout version {version!r} is newer than this program")
        links = data.get("links")
        if not isinstance(links, list):
            raise ArmLayoutError("an arm layout needs a list of links")
        return cls(
            links=tuple(Link.from_dict(item) for item in links),
            unit=str(data.get("unit", "mm")),
            name=str(data.get("name", "arm")),
            base_position=tuple(data.get("base_position", (0.0, 0.0, 0.0))),
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_json(cls, text: str) -> ArmLayout:
        try:
            data = loads_json(text)
        except JsonInputError as exc:
            raise ArmLayoutError(f"not a layout: {exc}") from exc
        return cls.from_dict(data)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ArmLayout:
        """A layout file (a regular file of at most 1 MB); ``OSError`` when it cannot be
        read, :class:`ArmLayoutError` when it is not a layout."""
        return cls.from_json(read_bounded(path, 1 << 20).decode("utf-8", errors="replace"))


def jamris_layout(
    column: float = 200.0, upper: float = 300.0, fore: float = 300.0, unit: str = "mm"
) -> ArmLayout:
    """The JAMRIS measuring arm: a vertical column turning about z, then two pitch hinges."""
    return ArmLayout(
        links=(
            Link("column", column, axis=VERTICAL, direction=VERTICAL),
            Link("upper arm", upper, axis=PITCH_UP, direction=ALONG_X),
            Link("forearm", fore, axis=PITCH_UP, direction=ALONG_X),
        ),
        unit=unit,
        name="JAMRIS arm",
    )
