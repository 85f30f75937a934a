"""The newest attitude of every sensor of a group (live or replayed), for the 3D view and the arm.

:class:`GroupAttitudes` looks at each sensor's pipeline (``source.pipeline(i)``: a
:class:`~app.services.sensor_group.SensorGroup` or a
:class:`~app.services.session_replay.SessionReplay`) and, when any of them wrote new
orientation rows since the last poll, returns a :class:`GroupFrame`: each sensor's newest
quaternion and the newest joint angle of the running
:class:`~app.services.joint_stream.JointStream`. The frame also says how the sensors sit on an
arm's links (:meth:`GroupFrame.link_quaternions`): the sensors of a chain go on the arm's last
links, in order (a JAMRIS arm's column turns about the vertical, which gravity cannot see, so
two sensors measure its upper arm and forearm). Qt-free.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from app.core.pipeline import Pipeline
from app.services.joint_stream import JointStream


class PipelineSource(Protocol):
    def pipeline(self, index: int) -> Pipeline: ...


@dataclass(frozen=True)
class GroupFrame:
    """Every sensor's newest orientation (sensor to earth) and the newest joint angle."""

    quaternions: tuple[np.ndarray, ...]
    labels: tuple[str, ...]
    joint: tuple[int, int, float] | None = None
    """(first sensor, second sensor, angle in degrees) of the joint stream, when finite."""

    def sensor_links(self, n_links: int) -> list[int]:
        """The arm link each sensor sits on: the last ``len(quaternions)`` links, in order."""
        first = max(0, n_links - len(self.quaternions))
        return [first + k for k in range(min(n_links, len(self.quaternions)))]

    def link_quaternions(self, n_links: int) -> list[np.ndarray | None]:
        """One entry per arm link: its sensor's quaternion, or None for a link without one."""
        out: list[np.ndarray | None] = [None] * n_links
        for k, link in enumerate(self.sensor_links(n_links)):
            out[link] = self.quaternions[k]
        return out

    def measured_deg(self, n_links: int) -> list[float | None]:
        """One entry per arm link: the joint stream's angle for the hinge between two
        neighbouring sensors' links (on the second one's joint), None elsewhere."""
        out: list[float | None] = [None] * n_links
        if self.joint is None:
            return out
        first, second, angle = self.joint
        links = self.sensor_links(n_links)
        if second == first + 1 and second < len(links) and links[second] == links[first] + 1:
            out[links[second]] = angle
        return out


class GroupAttitudes:
    """Polls the sensors' pipelines; a frame only when new orientation rows arrived."""

    def __init__(self) -> None:
        self._seen: tuple[tuple[int, int], ...] | None = None

    def reset(self) -> None:
        self._seen = None

    def poll(self, source: PipelineSource | None, labels: list[str],
             stream: JointStream | None = None) -> GroupFrame | None:
        """The newest frame, or None when nothing new arrived (or a sensor has no data yet)."""
        if source is None or not labels:
            self._seen = None
            return None
        rings = [source.pipeline(i).orientation for i in range(len(labels))]
        seen = tuple((id(ring), ring.total_written) for ring in rings)
        if seen == self._seen or any(total == 0 for _ring, total in seen):
            return None
        self._seen = seen
        quaternions = tuple(ring.latest(1, ["quat"])["quat"][-1].copy() for ring in rings)
        joint = None
        if stream is not None and len(stream.angles):
            angle = float(stream.angles.latest(1, ["angle"])["angle"][-1])
            if np.isfinite(angle):
                joint = (stream.first, stream.second, angle)
        return GroupFrame(quaternions, tuple(labels), joint)


@dataclass(frozen=True)
class SensorWindow:
    """The newest seconds of one sensor on an arm's link, for a static capture."""

    link: int
    accel_m_s2: np.ndarray
    """(N, 3) calibrated accelerometer."""
    mag_ut: np.ndarray | None
    """(M, 3) calibrated field samples, None without a magnetometer."""


def sensor_windows(pipelines: list[Pipeline], links: list[int], seconds: float
                   ) -> list[SensorWindow]:
    """Each pipeline's newest ``seconds`` of accelerometer and field (its ring buffers), for
    the link it sits on."""
    windows = []
    for pipeline, link in zip(pipelines, links):
        accel = pipeline.samples.window(seconds, ["accel"])["accel"]
        mag = pipeline.field.window(seconds, ["mag"])["mag"] if pipeline.has_field else None
        windows.append(SensorWindow(link, accel, mag))
    return windows
