"""Replay a multi-sensor session (its manifest): every file on one replay clock, in sync.

:class:`SessionReplay` reads the manifest (:func:`~app.core.recording.session.load_session`),
puts each file's ``t`` on the session's common time (the manifest's offset and scale) and feeds
each file's rows into a pipeline of its own (the same pipeline a live device has) up to one
common position: :meth:`SessionReplay.advance_to` (as fast as the caller wants) or
:meth:`SessionReplay.step` (paced by a clock, times ``speed``). A sample is delivered when
its common time has come, so samples of one instant reach every pipeline in the same step.
It offers what :class:`~app.services.joint_stream.JointStream` needs (``pipeline``,
``to_member_clock``, ``to_common``), so the joint angle of a replayed session is computed as
a live one. Qt-free.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from app.core.pipeline import Pipeline
from app.core.recording.reader import Recording, read_recording
from app.core.recording.session import Session, load_session


class SessionReplay:
    """All files of a session on one replay clock (see the module)."""

    def __init__(self, session: Session | str | Path, speed: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.session = session if isinstance(session, Session) else load_session(session)
        self.recordings: list[Recording] = [read_recording(p) for p in self.session.paths]
        self.pipelines: list[Pipeline] = []
        for recording in self.recordings:
            pipeline = Pipeline()
            rate = recording.rate_hz
            pipeline.configure(rate if np.isfinite(rate) and rate > 0 else 104.0)
            if recording.calibration is not None:
                pipeline.set_calibration(recording.calibration)
            self.pipelines.append(pipeline)
        self._common = [s.to_common(r.t_s) for s, r in
                        zip(self.session.sensors, self.recordings, strict=True)]
        filled = [c for c in self._common if len(c)]
        self.start_s = min(float(c[0]) for c in filled) if filled else 0.0
        self.end_s = max(float(c[-1]) for c in filled) if filled else 0.0
        self.position_s = self.start_s
        self._next = [0] * len(self.recordings)
        self.speed = speed
        self._clock = clock
        self._started_at: float | None = None

    @property
    def roles(self) -> list[str]:
        return self.session.roles

    @property
    def finished(self) -> bool:
        return all(n >= len(r) for n, r in zip(self._next, self.recordings, strict=True))

    def pipeline(self, index: int) -> Pipeline:
        return self.pipelines[index]

    def advance_to(self, common_t: float) -> list[int]:
        """Feed every file's rows up to common time ``common_t``; the rows fed per file."""
        fed = []
        for k, (common, recording) in enumerate(zip(self._common, self.recordings,
                                                    strict=True)):
            stop = int(np.searchsorted(common, common_t, side="right"))
            start = self._next[k]
            if stop > start:
                self.pipelines[k].process(recording.raw_block(start, stop))
                self._next[k] = stop
            fed.append(max(0, stop - start))
        self.position_s = max(self.position_s, float(common_t))
        return fed

    def step(self) -> list[int]:
        """Advance to where the replay clock is now (the first call starts the clock)."""
        now = self._clock()
        if self._started_at is None:
            self._started_at = now - (self.position_s - self.start_s) / self.speed
        return self.advance_to(self.start_s + (now - self._started_at) * self.speed)

    # -- what a JointStream needs ---------------------------------------------------------------
    def to_common(self, index: int, t: np.ndarray) -> np.ndarray:
        return self.session.sensors[index].to_common(t)

    def to_member_clock(self, source: int, target: int, t: np.ndarray) -> np.ndarray:
        """File ``source``'s times on file ``target``'s clock."""
        into = self.session.sensors[target]
        return (self.to_common(source, t) - into.offset_s) / into.scale
