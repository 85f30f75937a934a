"""Several sensors at once: one :class:`DeviceSession` (pipeline + worker thread) per device URL,
on one time base.

Each member's worker reports (session time of a block's newest sample, host receive time); a
:class:`~app.core.clock_alignment.ClockAligner` per *clock* turns them into the mapping of that
device's clock to the host's monotonic clock (offset and drift, lower envelope). Members whose
devices name the same ``clock_domain`` (the sensors of one ``sim://arm``, two chips on one
board) share one aligner, so their mapping is the same and their relative alignment exact.
The group's common time is host monotonic time minus :attr:`SensorGroup.epoch_s`.

QtCore only; views reach the members' pipelines through :attr:`GroupMember.session`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, Signal

from app.core.clock_alignment import ClockAligner, ClockFit
from app.core.devices import DeviceInfo
from app.core.pipeline import Pipeline
from app.core.recording.session import (
    JointConfig,
    SessionSensor,
    manifest_path,
    write_session,
)
from app.services.session import DeviceSession


def default_role(index: int) -> str:
    """The role of the ``index``-th sensor of a chain: ``link 0 (base)``, ``link 1``, ..."""
    return "link 0 (base)" if index == 0 else f"link {index}"


@dataclass(eq=False)
class GroupMember:
    """One sensor of the group: its URL, role, session and the aligner of its clock."""

    url: str
    role: str
    session: DeviceSession
    aligner: ClockAligner = field(default_factory=ClockAligner)
    info: DeviceInfo | None = None

    @property
    def pipeline(self) -> Pipeline:
        return self.session.pipeline

    @property
    def clock_domain(self) -> str | None:
        domain = None if self.info is None else self.info.extra.get("clock_domain")
        return None if domain is None else str(domain)


@dataclass(frozen=True)
class MemberAlignment:
    """How a member's clock maps to the group's time: ``common = offset + scale * device``."""

    role: str
    offset_s: float
    scale: float
    drift_ppm: float
    spread_ms: float
    points: int
    shared_clock: bool
    """True when this clock is shared with another member (exact relative alignment)."""

    def as_dict(self) -> dict[str, object]:
        return {"role": self.role, "offset_s": self.offset_s, "scale": self.scale,
                "drift_ppm": self.drift_ppm,
                "spread_ms": self.spread_ms, "points": self.points,
                "shared_clock": self.shared_clock}


class SensorGroup(QObject):
    """Two or more devices at once, each with its own session, on one time base."""

    membersChanged = Signal()
    memberConnected = Signal(int, object)  # index, DeviceInfo
    error = Signal(str)
    sessionRecorded = Signal(str)  # the manifest's path, once every file is closed

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.members: list[GroupMember] = []
        self.epoch_s = time.monotonic()
        self._recording: _GroupRecording | None = None

    # -- members ------------------------------------------------------------------------------
    def add(self, url: str, role: str | None = None) -> GroupMember:
        """Open ``url`` in a new session of its own (asynchronously: see memberConnected)."""
        session = DeviceSession(Pipeline())
        member = GroupMember(url=url, role=role or default_role(len(self.members)),
                             session=session)
        # Runs in the member's worker thread; reads member.aligner when called, so a member
        # moved onto a shared clock feeds the shared aligner from then on.
        session.worker.acquisition.on_received = (
            lambda device_t, host_t, m=member: m.aligner.add(device_t, host_t))
        session.connected.connect(lambda info, m=member: self._on_connected(m, info))
        session.error.connect(lambda text, m=member: self.error.emit(f"{m.role}: {text}"))
        session.recordingChanged.connect(
            lambda status, m=member: self._on_recording_changed(m, status))
        self.members.append(member)
        session.requestConnect.emit(url)
        self.membersChanged.emit()
        return member

    def _on_connected(self, member: GroupMember, info: DeviceInfo) -> None:
        member.info = info
        domain = member.clock_domain
        if domain is not None:
            for other in self.members:
                if other is not member and other.clock_domain == domain:
                    member.aligner = other.aligner
                    break
        if member in self.members:
            self.memberConnected.emit(self.members.index(member), info)

    def pipeline(self, index: int) -> Pipeline:
        return self.members[index].pipeline

    def connected_count(self) -> int:
        return sum(m.info is not None for m in self.members)

    def clear(self) -> None:
        """Close every member's device and stop its thread."""
        members, self.members = self.members, []
        for member in members:
            member.session.shutdown()
        self.membersChanged.emit()

    shutdown = clear

    # -- time base ----------------------------------------------------------------------------
    def clock_fit(self, index: int) -> ClockFit | None:
        """Member ``index``'s clock -> host monotonic clock; None before its first block."""
        return self.members[index].aligner.fit()

    def to_common(self, index: int, device_t: np.ndarray) -> np.ndarray | None:
        """Member ``index``'s session times on the group's time axis (None before a fit)."""
        fit = self.clock_fit(index)
        if fit is None:
            return None
        return np.asarray(fit.to_host(device_t)) - self.epoch_s

    def to_member_clock(self, source: int, target: int, device_t: np.ndarray
                        ) -> np.ndarray | None:
        """Member ``source``'s times on member ``target``'s clock (identity on a shared clock)."""
        a, b = self.members[source].aligner, self.members[target].aligner
        if a is b:
            return np.asarray(device_t, dtype=np.float64)
        fa, fb = a.fit(), b.fit()
        if fa is None or fb is None:
            return None
        return np.asarray(fb.to_device(fa.to_host(device_t)))

    def alignment(self) -> list[MemberAlignment | None]:
        """Each member's mapping to the group's time and its quality (None before a fit)."""
        out: list[MemberAlignment | None] = []
        for member in self.members:
            fit = member.aligner.fit()
            if fit is None:
                out.append(None)
                continue
            shared = any(o is not member and o.aligner is member.aligner for o in self.members)
            out.append(MemberAlignment(member.role, fit.offset_s - self.epoch_s, fit.scale,
                                       fit.drift_ppm, fit.spread_ms, fit.points, shared))
        return out

    # -- recording ----------------------------------------------------------------------------
    @property
    def recording(self) -> bool:
        return self._recording is not None

    def start_recording(self, directory: str | Path, name: str,
                        joints: list[JointConfig] | None = None, note: str = "") -> Path:
        """Record every member to ``DIR/NAME-sensorK.csv`` (format v1); :meth:`stop_recording`
        writes ``DIR/NAME.session.json`` (docs/recording-format.md, "Session manifest").

        Returns the manifest's path. Raises ValueError when a member is not connected, a
        file exists or the directory does not.
        """
        directory = Path(directory)
        if self._recording is not None:
            raise ValueError("the sensors are being recorded already")
        if not self.members or any(m.info is None for m in self.members):
            raise ValueError("connect every sensor before recording the session")
        if not directory.is_dir():
            raise ValueError(f"{directory}: no such directory")
        files = [f"{name}-sensor{k}.csv" for k in range(len(self.members))]
        target = manifest_path(directory, name)
        for path in [target, *(directory / f for f in files)]:
            if path.exists():
                raise ValueError(f"{path} exists; choose another session name")
        self._recording = _GroupRecording(target, files, list(joints or []), note,
                                          set(self.members))
        for member, file in zip(self.members, files, strict=True):
            member.session.requestStartRecording.emit(str(directory / file), note)
        return target

    def stop_recording(self) -> None:
        """Close every file; the manifest is written when the last one is closed."""
        plan = self._recording
        if plan is None:
            return
        plan.stopping = True
        plan.alignment = self.alignment()
        for member in self.members:
            member.session.requestStopRecording.emit()

    def _on_recording_changed(self, member: GroupMember, status: object) -> None:
        plan = self._recording
        if plan is None or status is not None or not plan.stopping:
            return
        plan.waiting.discard(member)
        if plan.waiting:
            return
        self._recording = None
        sensors = []
        for k, (m, file) in enumerate(zip(self.members, plan.files, strict=True)):
            align = plan.alignment[k] if k < len(plan.alignment) else None
            if align is None:
                sensors.append(SessionSensor(file=file, role=m.role, url=m.url))
            else:
                sensors.append(SessionSensor(
                    file=file, role=m.role, offset_s=align.offset_s, scale=align.scale,
                    drift_ppm=align.drift_ppm, spread_ms=align.spread_ms,
                    shared_clock=align.shared_clock, url=m.url))
        try:
            write_session(plan.manifest, sensors, plan.joints, plan.note)
        except (OSError, ValueError) as exc:
            self.error.emit(f"cannot write the session manifest {plan.manifest}: {exc}")
            return
        self.sessionRecorded.emit(str(plan.manifest))


@dataclass(eq=False)
class _GroupRecording:
    manifest: Path
    files: list[str]
    joints: list[JointConfig]
    note: str
    waiting: set[GroupMember]
    stopping: bool = False
    alignment: list[MemberAlignment | None] = field(default_factory=list)
