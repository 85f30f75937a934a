"""Sessions with several sensors: one v1 file per sensor and a JSON manifest beside them.

``<name>.session.json`` (docs/recording-format.md, "Session manifest") names the files
(relative to the manifest), each sensor's role, how each file's ``t`` maps to the session's
common time (``common = offset_s + scale * t``), and the joint configuration. Each file stays
an ordinary v1 recording: a reader that knows nothing of manifests reads it on its own.

:func:`load_session` reads and checks a manifest; :func:`write_session` writes one.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from app.core.bounded_input import JsonInputError, load_json
from app.core.recording.errors import RecordingError
from app.core.safe_output import write_output
from app.core.version import __version__

MANIFEST_FORMAT = "inclinometer-session"
MANIFEST_VERSION = 1
MANIFEST_SUFFIX = ".session.json"
MAX_MANIFEST_BYTES = 1 << 20
"""A manifest lists a few files; a larger one is refused."""


class SessionManifestError(RecordingError):
    """A manifest that cannot be read or that contradicts itself; the message says why."""


@dataclass(frozen=True)
class SessionSensor:
    """One sensor's file and how its time maps to the session's."""

    file: str
    """Path relative to the manifest's directory, with ``/`` separators."""
    role: str
    offset_s: float = 0.0
    scale: float = 1.0
    drift_ppm: float = 0.0
    spread_ms: float = math.nan
    """The alignment's quality when it was measured (NaN: unknown, e.g. written by hand)."""
    shared_clock: bool = False
    url: str = ""

    def to_common(self, t: np.ndarray) -> np.ndarray:
        return self.offset_s + self.scale * np.asarray(t, dtype=np.float64)

    def as_dict(self) -> dict[str, Any]:
        clock: dict[str, Any] = {"offset_s": self.offset_s, "scale": self.scale,
                                 "drift_ppm": self.drift_ppm, "shared_clock": self.shared_clock}
        if math.isfinite(self.spread_ms):
            clock["spread_ms"] = self.spread_ms
        return {"file": self.file, "role": self.role, "url": self.url, "clock": clock}


@dataclass(frozen=True)
class JointConfig:
    """A hinge between sensors ``first`` and ``second`` (indices into the sensors)."""

    first: int
    second: int
    axes: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    """The axis in each sensor's frame, None: estimated from the motion (``auto``)."""

    def as_dict(self) -> dict[str, Any]:
        return {"sensors": [self.first, self.second],
                "axis": "auto" if self.axes is None else
                {"in_first": list(self.axes[0]), "in_second": list(self.axes[1])}}


@dataclass(frozen=True)
class Session:
    """A loaded manifest: the files (absolute :attr:`paths`), roles, time maps, joints."""

    manifest: Path
    sensors: tuple[SessionSensor, ...]
    joints: tuple[JointConfig, ...] = ()
    created: str = ""
    app_version: str = __version__
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def paths(self) -> list[Path]:
        return [self.manifest.parent / Path(s.file) for s in self.sensors]

    @property
    def roles(self) -> list[str]:
        return [s.role for s in self.sensors]


def manifest_path(directory: Path, name: str) -> Path:
    return Path(directory) / f"{name}{MANIFEST_SUFFIX}"


def write_session(path: Path, sensors: list[SessionSensor], joints: list[JointConfig],
                  note: str = "") -> Path:
    """Write a manifest (atomically: a temporary file renamed over ``path``)."""
    for joint in joints:
        _check_joint(joint, len(sensors), Path(path))
    document = {
        "format": MANIFEST_FORMAT,
        "version": MANIFEST_VERSION,
        "created": datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z"),
        "app": "inclinometer",
        "app_version": __version__,
        "time_base": "common = offset_s + scale * t of each file, in seconds",
        "sensors": [s.as_dict() for s in sensors],
        "joints": [j.as_dict() for j in joints],
        **({"note": note} if note else {}),
    }
    path = Path(path)  # a new temporary file (never through a link), renamed over ``path``
    write_output(path, json.dumps(document, indent=2) + "\n", overwrite=True)
    return path


def _check_joint(joint: JointConfig, count: int, path: Path) -> None:
    if not (0 <= joint.first < count and 0 <= joint.second < count) or (
            joint.first == joint.second):
        raise SessionManifestError(
            f"{path}: a joint joins sensors {joint.first} and {joint.second}, but the session "
            f"has sensors 0 to {count - 1} (two different ones are needed)", path)


def _number(value: Any, what: str, path: Path) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SessionManifestError(f"{path}: {what} must be a finite number, not {value!r}", path)
    return float(value)


def _axis(value: Any, what: str, path: Path) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise SessionManifestError(f"{path}: {what} must be three numbers", path)
    vector = np.array([_number(v, what, path) for v in value])
    norm = float(np.linalg.norm(vector))
    if norm == 0.0:
        raise SessionManifestError(f"{path}: {what} must not be zero", path)
    x, y, z = (float(v) for v in vector / norm)
    return x, y, z


OUTSIDE_FLAG = "--allow-outside-paths"
"""The command-line option that lets a manifest name files outside its folder."""


def _confined_file(path: Path, k: int, file: str, allow_outside: bool) -> None:
    """Refuse a sensor file that is not inside the manifest's folder: absolute, with ``..``,
    or a link that leads out (unless ``allow_outside``). Never reads the file."""
    if allow_outside:
        return
    relative = Path(file)
    outside = relative.is_absolute() or bool(relative.drive) or ".." in relative.parts
    if not outside:
        folder = os.path.realpath(path.parent)
        target = os.path.realpath(path.parent / relative)
        outside = os.path.commonpath([folder, target]) != folder
    if outside:
        raise SessionManifestError(
            f"{path}: sensor {k}'s file {file!r} is outside the manifest's folder; a manifest "
            f"names its files relative to its folder, inside it ({OUTSIDE_FLAG} reads it "
            "anyway)", path)


def load_session(manifest_path: str | os.PathLike[str], *,
                 allow_outside: bool = False) -> Session:
    """Read a session manifest: files (checked to exist), roles, time maps, joints.

    The files must lie inside the manifest's folder (no absolute paths, no ``..``, no link
    leading out) unless ``allow_outside``. Raises :class:`SessionManifestError` (a
    :class:`RecordingError`) with a message that names the problem: not JSON, another format
    or version, a missing file or one outside the folder, a bad field.
    """
    path = Path(manifest_path)
    try:
        document = load_json(path, max_bytes=MAX_MANIFEST_BYTES)
    except OSError as exc:
        raise SessionManifestError(f"{path}: cannot read the manifest: "
                                   f"{exc.strerror or exc}", path) from exc
    except JsonInputError as exc:
        raise SessionManifestError(f"{path}: not a session manifest (not JSON: {exc})",
                                   path) from exc
    if not isinstance(document, dict) or document.get("format") != MANIFEST_FORMAT:
        raise SessionManifestError(
            f"{path}: not a session manifest (\"format\" is not {MANIFEST_FORMAT!r})", path)
    version = document.get("version")
    if version != MANIFEST_VERSION:
        raise SessionManifestError(
            f"{path}: session manifest version {version!r}; this program reads version "
            f"{MANIFEST_VERSION}", path)
    items = document.get("sensors")
    if not isinstance(items, list) or len(items) < 1:
        raise SessionManifestError(f"{path}: \"sensors\" must list at least one file", path)
    sensors = []
    for k, item in enumerate(items):
        if not isinstance(item, dict) or not isinstance(item.get("file"), str):
            raise SessionManifestError(f"{path}: sensor {k} has no \"file\"", path)
        clock = item.get("clock", {})
        if not isinstance(clock, dict):
            raise SessionManifestError(f"{path}: sensor {k}: \"clock\" must be an object", path)
        scale = _number(clock.get("scale", 1.0), f"sensor {k} clock.scale", path)
        if scale <= 0.0:
            raise SessionManifestError(f"{path}: sensor {k}: clock.scale must be positive", path)
        file = item["file"]
        _confined_file(path, k, file, allow_outside)
        if not (path.parent / file).is_file():
            raise SessionManifestError(
                f"{path}: sensor {k}'s file {file!r} is missing (looked in {path.parent})", path)
        sensors.append(SessionSensor(
            file=file, role=str(item.get("role", f"sensor {k}")),
            offset_s=_number(clock.get("offset_s", 0.0), f"sensor {k} clock.offset_s", path),
            scale=scale,
            drift_ppm=_number(clock.get("drift_ppm", 0.0), f"sensor {k} clock.drift_ppm", path),
            spread_ms=float(clock["spread_ms"]) if isinstance(
                clock.get("spread_ms"), int | float) else math.nan,
            shared_clock=bool(clock.get("shared_clock", False)),
            url=str(item.get("url", "")),
        ))
    joints = []
    for k, item in enumerate(document.get("joints", []) or []):
        pair = item.get("sensors") if isinstance(item, dict) else None
        if not isinstance(pair, list) or len(pair) != 2 or not all(
                isinstance(v, int) and not isinstance(v, bool) for v in pair):
            raise SessionManifestError(f"{path}: joint {k}: \"sensors\" must be two indices",
                                       path)
        axis = item.get("axis", "auto")
        axes = None
        if axis != "auto":
            if not isinstance(axis, dict):
                raise SessionManifestError(
                    f"{path}: joint {k}: \"axis\" must be \"auto\" or an object", path)
            axes = (_axis(axis.get("in_first"), f"joint {k} axis.in_first", path),
                    _axis(axis.get("in_second"), f"joint {k} axis.in_second", path))
        joint = JointConfig(pair[0], pair[1], axes)
        _check_joint(joint, len(sensors), path)
        joints.append(joint)
    known = {"format", "version", "created", "app", "app_version", "time_base", "sensors",
             "joints", "note"}
    return Session(manifest=path, sensors=tuple(sensors), joints=tuple(joints),
                   created=str(document.get("created", "")),
                   app_version=str(document.get("app_version", "")),
                   note=str(document.get("note", "")),
                   extra={k: v for k, v in document.items() if k not in known})


def session_joint_files(session: Session, joint: int = 0
                        ) -> tuple[Path, Path, JointConfig, Callable[[np.ndarray], np.ndarray]]:
    """What ``inclinometer joint MANIFEST`` needs: the two files of joint ``joint`` (the first
    two sensors when the manifest names no joint), the joint, and the map of the second
    file's ``t`` onto the first file's clock. Raises SessionManifestError."""
    if session.joints:
        if not 0 <= joint < len(session.joints):
            raise SessionManifestError(
                f"{session.manifest}: no joint {joint} (it has {len(session.joints)})",
                session.manifest)
        config = session.joints[joint]
    elif len(session.sensors) >= 2:
        config = JointConfig(0, 1)
    else:
        raise SessionManifestError(f"{session.manifest}: a joint needs two sensors; the "
                                   "session has one", session.manifest)
    first, second = session.sensors[config.first], session.sensors[config.second]

    def on_first_clock(t: np.ndarray) -> np.ndarray:
        return (second.to_common(t) - first.offset_s) / first.scale

    paths = session.paths
    return paths[config.first], paths[config.second], config, on_first_clock
