"""Replay a recording as a device: ``replay://PATH`` (or just a path ending in ``.csv``).

Replay is just another device (python-can's ``MessageSync``, x-IMU3's ``FileConnection``): the
recorded raw samples go through the same pipeline (calibration, filters, views) as live ones.
Blocks carry the recorded SI values with scale factors of 1.0, so every sample reaches the
pipeline bit for bit as it did live; the reference orientation and gap flags come along.

URL: ``replay://PATH?option=value&...``. PATH is taken literally up to the first ``?``
(percent-encoding is undone, so write ``%3F`` for a ``?`` in a file name); relative paths are
relative to the working directory: ``replay://data/run.csv``, ``replay:///home/me/run.csv``.
Options:

- ``speed``: 0.1 ... 100 (default 1, the recorded pace), or ``max`` (also ``0``): as fast as
  the reader takes blocks;
- ``loop``: 1 to start again at the end (default 0);
- ``start``: seconds from the beginning of the recording to start at (default 0);
- ``paused``: 1 to open paused (default 0);
- ``exact``: 1 (default) delivers the blocks exactly as the device delivered them while
  recording (the ``block_start`` column), so that every filter computes bit for bit what it
  computed live; 0, or a recording without that column: blocks of whatever is due (paced) or of
  ``block`` samples (``speed=max``);
- ``block``: samples per block when not exact (default 1024).

Pacing: the ``t`` column (device clock) against the wall clock, as the simulator paces itself;
a hole in time longer than :data:`HOLE_LIMIT_S` (lost data, a paused logger) is waited for only
that long.

Controls (thread-safe, for the GUI thread while the worker thread reads): :meth:`play`,
:meth:`pause`, :attr:`loop`, :meth:`step`, :meth:`seek`, :meth:`set_speed`, :meth:`next_gap`,
:meth:`previous_gap`, :meth:`add_bookmark`, :meth:`next_bookmark`, :meth:`previous_bookmark`;
:attr:`position_s` and :attr:`duration_s` for a slider.

After a seek (or a loop back to the start)
------------------------------------------
The stream jumps: backwards in time, or forwards over samples the filters never see. The
first sample of the next block is marked as a gap (every filter restarts its integration
there) and :attr:`generation` goes up. ``seek(position_s, lead_in_s)`` starts that much
earlier and lets the next :meth:`read` return the lead-in up to ``position_s`` at once, in one
block, playing or paused (the filters converge on it, and a paused replay shows the attitude
at the new position); pacing then goes on from ``position_s``. The block's generation is in
:attr:`last_block_generation` right after :meth:`read` returns it. A consumer whose buffers must
hold one continuous, increasing time line (the pipeline's ring buffers) compares it with the
previous block's and, when it changed, starts afresh before processing the block:
``pipeline.configure(info.odr_hz)`` (which clears the buffers and resets the filters).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar
from urllib.parse import unquote

import numpy as np

from app.core.calibration import SensorCalibration
from app.core.devices import MagnetometerInfo
from app.core.recording.errors import RecordingError, RecordingTooLargeError
from app.core.recording.format import KEY_BOOKMARKS, KEY_MAGNETOMETER, KEY_REFERENCE
from app.core.recording.index import Overview
from app.core.recording.reader import (
    UNIT_SCALE,
    Bookmark,
    Recording,
    read_metadata,
    read_recording,
)
from app.core.recording.stream import RecordingStream
from app.core.samples import RawBlock
from drivers.base import Device, DeviceDescriptor, DeviceInfo, DeviceMessage
from drivers.errors import DeviceOpenError, DeviceUrlError
from drivers.replay_rows import MemoryRows, StreamedRows
from drivers.url_options import Option, parse_options

__all__ = [
    "HOLE_LIMIT_S", "OPTIONS", "ReplayDevice", "ReplayOptions", "is_recording_path",
    "parse_replay_url", "parse_speed", "recording_path", "replay_url",
]

SCHEME = "replay"
MIN_SPEED = 0.1
MAX_SPEED = 100.0
DEFAULT_BLOCK = 1024
MAX_BLOCK = 65536
MIN_BLOCK_S = 0.020
"""Paced reads without recorded blocks wait for at least this much data (as the simulator)."""
MAX_BLOCK_S = 1.0
"""A reader that fell behind gets at most this much recorded time per block."""
STREAMED_MIN_BYTES = 64 << 20
"""Recordings at least this large (decompressed) are replayed a chunk at a time, the rest from
memory."""
HOLE_LIMIT_S = 1.0
"""A hole in the recorded time is waited for at most this long (at speed 1)."""


def _speed(text: str) -> float:
    return parse_speed(text)


OPTIONS: tuple[Option, ...] = (
    Option("speed", "number", 1.0, minimum=MIN_SPEED, maximum=MAX_SPEED, parse=_speed,
           help="playback speed factor (1: the recorded pace), or max (also 0): as fast as "
                "the reader takes blocks"),
    Option("loop", "flag", False, help="1: start again at the end"),
    Option("start", "number", 0.0, unit="s", minimum=0.0, field="start_s",
           help="seconds from the beginning of the recording to start at"),
    Option("paused", "flag", False, help="1: open paused"),
    Option("exact", "flag", True,
           help="1: the blocks exactly as recorded (bit for bit what every filter computed "
                "live); 0: blocks of whatever is due, or of block samples"),
    Option("block", "integer", DEFAULT_BLOCK, minimum=1, maximum=MAX_BLOCK,
           help="samples per block when not exact"),
)
"""The ``replay://`` options."""


@dataclass(frozen=True, slots=True)
class ReplayOptions:
    """A validated ``replay://`` URL."""

    path: Path
    speed: float = 1.0
    """``math.inf``: as fast as the reader takes blocks."""
    loop: bool = False
    start_s: float = 0.0
    paused: bool = False
    exact: bool = True
    block: int = DEFAULT_BLOCK


def is_recording_path(url: str) -> bool:
    """True for a plain file path ending in ``.csv`` or ``.csv.gz`` (no ``scheme://``)."""
    return "://" not in url and url.strip().lower().endswith((".csv", ".csv.gz"))


def _reference_of(recording: Recording) -> str | None:
    """What the recording's reference columns hold, as its metadata names it (None without
    them; "recorded reference" when the metadata does not say)."""
    if not recording.has_reference:
        return None
    source = recording.metadata.get(KEY_REFERENCE)
    text = source.get("source") if isinstance(source, dict) else None
    return text if isinstance(text, str) and text else "recorded reference"


def _positive_number(mapping: dict, key: str, default: float) -> float:
    """``mapping[key]`` when it is a positive finite number (not a bool), else ``default``."""
    value = mapping.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return default
    return float(value) if math.isfinite(value) and value > 0 else default


def _recorded_magnetometer(recording: Recording, odr_hz: float) -> MagnetometerInfo | None:
    """The magnetometer of a recording with field columns (``mx,my,mz``): its ``magnetometer``
    metadata, or for a file without it (an import, a BROAD trial) a field sampled with the
    rows; None without field columns. A replay of a 9-axis recording is a 9-axis source."""
    if not recording.has_magnetometer:
        return None
    meta = recording.metadata.get(KEY_MAGNETOMETER)
    meta = meta if isinstance(meta, dict) else {}
    address = meta.get("address")
    return MagnetometerInfo(
        chip=str(meta.get("chip") or "recorded"),
        odr_hz=_positive_number(meta, "odr_hz", odr_hz),
        range_ut=_positive_number(meta, "range_ut", 0.0),
        ut_per_lsb=_positive_number(meta, "ut_per_lsb", 0.0),
        address=address if isinstance(address, int) and not isinstance(address, bool) else None,
        mode=str(meta.get("mode") or ""), path="recording")


def replay_url(path: str | Path, **options: Any) -> str:
    """``replay://`` URL for a file (percent-encoding only what must be)."""
    text = str(path).replace("%", "%25").replace("?", "%3F")
    query = "&".join(f"{key}={value}" for key, value in options.items())
    return f"{SCHEME}://{text}" + (f"?{query}" if query else "")


def _split_url(url: str) -> tuple[Path, str]:
    """The file and the query of a replay URL or a bare recording path."""
    if is_recording_path(url):
        return Path(url.strip()), ""
    prefix = f"{SCHEME}://"
    if not url.lower().startswith(prefix):
        raise DeviceUrlError(f"{url}: not a replay URL; expected replay://PATH or a .csv path")
    rest = url[len(prefix):]
    path_text, _, query = rest.partition("?")
    if not path_text:
        raise DeviceUrlError(f"{url}: no file given; expected replay://PATH")
    if "\0" in unquote(path_text):
        raise DeviceUrlError(f"{url!r}: a file name cannot hold a NUL character (%00)")
    path = Path(unquote(path_text))
    if not path.exists() and Path(path_text).exists():
        path = Path(path_text)  # a literal '%' in the name
    return path, query


def parse_replay_url(url: str) -> ReplayOptions:
    """Validate ``replay://PATH?options`` or a bare ``.csv``/``.csv.gz`` path."""
    path, query = _split_url(url)
    return ReplayOptions(path, **parse_options(url, query, OPTIONS).values)  # type: ignore[arg-type]


def recording_path(url: str) -> Path:
    """The file a ``replay://`` URL names; any other text is taken as a path."""
    if url.lower().startswith(f"{SCHEME}://"):
        return parse_replay_url(url).path
    if "\0" in url:
        raise DeviceUrlError(f"{url!r}: a file name cannot hold a NUL character")
    return Path(url)


def parse_speed(value: float | str) -> float:
    """A speed factor from a number or ``"max"``; ``math.inf`` means as fast as possible."""
    if isinstance(value, str):
        text = value.strip().lower()
        if text in ("max", "inf", "fastest"):
            return math.inf
        text = text.removesuffix("x")  # "2x"
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"speed {value!r}: use a factor 0.1 ... 100 or 'max'") from None
    speed = float(value)
    if speed == 0.0 or speed == math.inf:
        return math.inf
    if not MIN_SPEED <= speed <= MAX_SPEED:
        raise ValueError(f"speed {value!r} is outside {MIN_SPEED:g} ... {MAX_SPEED:g} "
                         "(or 'max')")
    return speed


class ReplayDevice(Device):
    """A recording played back as a device (see the module docstring).

    Parameters
    ----------
    url : ``replay://PATH?options`` or a path ending in ``.csv``.
    clock : wall clock in seconds for pacing (tests pass a fake one).
    recording : an already loaded recording of that file (skips reading it again).
    """

    scheme: ClassVar[str] = SCHEME
    url_options: ClassVar[tuple[Option, ...]] = OPTIONS
    replayable: ClassVar[bool] = True

    def __init__(
        self, url: str, *, clock: Callable[[], float] = time.monotonic,
        recording: Recording | None = None,
    ) -> None:
        super().__init__(url)
        options = parse_replay_url(url)
        self.path = options.path
        self._initial_speed = options.speed
        self._initial_loop = options.loop
        self._initial_paused = options.paused
        self._exact = options.exact
        self._start_s = options.start_s
        self._block = options.block
        self._clock = clock
        self._cond = threading.Condition()
        self._given = recording
        self.recording: Recording | None = None
        self._reset_state()

    def _reset_state(self) -> None:
        self._n = 0
        self._pos = 0
        self._playing = not self._initial_paused
        self._speed = self._initial_speed
        self._loop = self._initial_loop
        self._anchor_wall = 0.0
        self._anchor_t = 0.0
        self._step_samples = 0  # > 0: deliver this many while paused; -1: one block
        self._lead_in_end = 0  # > _pos: a seek's lead-in, delivered at once up to here
        self._discontinuity = False
        self._generation = 0
        self._last_block_generation = 0
        self._closed = False
        self._bookmarks: list[Bookmark] = []
        self._rows: MemoryRows | StreamedRows | None = None
        self._told = ""

    # -- Device template -----------------------------------------------------------------------
    @classmethod
    def discover(cls) -> list[DeviceDescriptor]:
        """The sample recordings shipped with the program."""
        from app.core.recording.samples import sample_recordings

        found = []
        for path in sample_recordings():
            try:
                metadata, _ = read_metadata(path)
            except (OSError, RecordingError):
                continue
            note = metadata.get("note") if isinstance(metadata.get("note"), str) else ""
            found.append(DeviceDescriptor(
                replay_url(path), f"Sample recording: {note or path.name}", "recording"))
        return found

    def _open(self) -> DeviceInfo:
        recording = self._given
        stream = None
        try:
            if recording is None:
                stream = RecordingStream(self.path)
                if stream.file_size() < STREAMED_MIN_BYTES:  # small: all of it in memory
                    try:  # ... counting decompressed bytes: a small .csv.gz may be huge
                        recording = read_recording(self.path, max_bytes=STREAMED_MIN_BYTES)
                    except RecordingTooLargeError:
                        recording = None  # it expands beyond: a chunk at a time
                    else:
                        stream.close()
                        stream = None
            if recording is not None and len(recording) == 0:
                raise DeviceOpenError(f"{self.path}: the recording holds no samples")
            with self._cond:
                self._reset_state()
                if stream is not None:
                    rows: MemoryRows | StreamedRows = StreamedRows(stream, self._cond)
                    recording = Recording(stream.metadata, stream.header, {}, self.path)
                    recording._known_reference = rows.has_reference
                else:
                    assert recording is not None
                    rows = MemoryRows(recording, _rate(recording))
                self.recording = recording
                self._rows = rows
                self._bookmarks = list(recording.bookmarks)
                if self._start_s > 0:
                    self._seek_index(self._index_at(self._start_s))
                    self._discontinuity = False
                self._anchor()
                return self._device_info(recording)
        except RecordingError as exc:
            if stream is not None:
                stream.close()
            raise DeviceOpenError(str(exc)) from exc

    def _read(self, timeout_s: float) -> RawBlock | None:
        with self._cond:
            block, wait_s = self._take()
            if block is not None or self._closed:
                return block
            wait_s = max(0.0, timeout_s) if wait_s is None else min(max(0.0, timeout_s), wait_s)
            if wait_s > 0.0:
                self._cond.wait(wait_s)
                block, _ = self._take()
            return block

    def _close(self) -> None:
        with self._cond:
            self._closed = True
            if self._rows is not None:
                self._rows.close()
            self._cond.notify_all()

    # -- what a GUI uses (thread-safe) -------------------------------------------------------
    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, s (estimated until a long recording is
        indexed: :attr:`indexed`)."""
        with self._cond:
            rows = self._rows
            return float(rows.last_t - rows.first_t) if rows is not None else 0.0

    @property
    def indexed(self) -> bool:
        """True once the whole recording was read: length, gaps and overview are final."""
        with self._cond:
            return self._rows is not None and self._rows.complete()

    @property
    def streamed(self) -> bool:
        """True for a long recording read a chunk at a time (memory does not grow with it)."""
        with self._cond:
            return bool(self._rows is not None and self._rows.streamed)

    def overview(self) -> Overview | None:
        """Minimum and maximum of each axis over the session, in about 2000 bins (a long
        recording's grows while the background index reads the file)."""
        with self._cond:
            return None if self._rows is None else self._rows.overview()

    def take_messages(self) -> list[DeviceMessage]:
        """A problem the background reading of a long recording met (a corrupt row)."""
        with self._cond:
            problem = "" if self._rows is None else self._rows.problem()
            if not problem or problem == self._told:
                return []
            self._told = problem
        return [DeviceMessage(2, f"{problem}; the replay ends there")]

    @property
    def position_s(self) -> float:
        """Time of the next sample to deliver, s from the first (``duration_s`` at the end)."""
        with self._cond:
            return self._position_s()

    @property
    def position_index(self) -> int:
        """Index of the next sample to deliver (``sample_count`` at the end)."""
        with self._cond:
            return self._pos

    @property
    def sample_count(self) -> int:
        """Rows in the recording (estimated until a long one is indexed)."""
        with self._cond:
            return 0 if self._rows is None else self._rows.count

    @property
    def start_t_s(self) -> float:
        """Device time of the first sample (positions count from it)."""
        with self._cond:
            return 0.0 if self._rows is None else self._rows.first_t

    @property
    def at_end(self) -> bool:
        """True when every sample was delivered and the replay does not loop."""
        with self._cond:
            return self._rows is not None and self._ended() and not self._loop

    @property
    def playing(self) -> bool:
        with self._cond:
            return self._playing

    @property
    def speed(self) -> float:
        """Speed factor; ``math.inf`` when as fast as possible."""
        with self._cond:
            return self._speed

    @property
    def loop(self) -> bool:
        with self._cond:
            return self._loop

    @loop.setter
    def loop(self, value: bool) -> None:
        with self._cond:
            self._loop = bool(value)
            self._cond.notify_all()

    @property
    def exact_blocks(self) -> bool:
        """True when blocks are cut as the device delivered them while recording."""
        with self._cond:
            return self._exact_blocks()

    @property
    def generation(self) -> int:
        """Goes up at every seek or loop (see the module docstring)."""
        with self._cond:
            return self._generation

    @property
    def last_block_generation(self) -> int:
        """The generation of the block :meth:`read` returned last."""
        with self._cond:
            return self._last_block_generation

    @property
    def reference_source(self) -> str | None:
        """The recording's reference orientation, as its metadata names it (None without)."""
        return None if self.recording is None else _reference_of(self.recording)

    @property
    def recorded_calibration(self) -> SensorCalibration | None:
        """The calibration the recording was made with: apply it to reproduce the result."""
        return None if self.recording is None else self.recording.calibration

    def play(self) -> None:
        """Play from the current position (from the start again when at the end)."""
        with self._cond:
            if self._rows is not None and self._ended():
                self._seek_index(0)
            self._playing = True
            self._step_samples = 0
            self._anchor()
            self._cond.notify_all()

    def pause(self) -> None:
        with self._cond:
            self._playing = False
            self._cond.notify_all()

    def set_speed(self, speed: float | str) -> float:
        """Set the speed (0.1 ... 100, or ``"max"``/0/inf); returns it. Raises ValueError."""
        value = parse_speed(speed)
        with self._cond:
            self._speed = value
            self._anchor()
            self._cond.notify_all()
        return value

    def step(self, samples: int | None = None) -> None:
        """Pause, then let the next :meth:`read` return one block (or ``samples`` samples)."""
        if samples is not None and samples < 1:
            raise ValueError("step: samples must be at least 1")
        with self._cond:
            self._playing = False
            self._step_samples = -1 if samples is None else int(samples)
            self._cond.notify_all()

    def seek(self, position_s: float, lead_in_s: float = 0.0) -> float:
        """Continue from the first sample at or after ``position_s`` (s from the start).

        With ``lead_in_s`` > 0 the stream restarts that much earlier (at most at the start)
        and the next :meth:`read` returns the lead-in up to ``position_s`` in one block, even
        while paused. Clamped to the recording; returns the position reached. See the module
        docstring for what happens to the stream.
        """
        if not math.isfinite(lead_in_s) or lead_in_s < 0:
            raise ValueError(f"lead-in {lead_in_s!r} must be >= 0 s")
        with self._cond:
            target = self._index_at(position_s)
            start = target
            if lead_in_s and self._rows is not None and self._rows.exists(target):
                reached = self._rows.t(target) - self._rows.first_t  # clamped to the end
                start = self._index_at(max(0.0, reached - lead_in_s))
            self._seek_index(min(start, target))
            self._lead_in_end = target
            self._cond.notify_all()
            return self._position_s()

    def next_gap(self) -> float | None:
        """Seek to the next sample after lost data; None (and no move) when there is none."""
        with self._cond:
            later = self._gap_rows()[0]
            later = later[later > self._pos]
            if len(later) == 0 and isinstance(self._rows, StreamedRows):
                self._rows.wait_for_index()  # the gaps further on are not indexed yet
                later = self._gap_rows()[0]
                later = later[later > self._pos]
            if len(later) == 0:
                return None
            self._seek_index(int(later[0]))
            self._cond.notify_all()
            return self._position_s()

    def previous_gap(self) -> float | None:
        """Seek to the last gap before the current position; None when there is none."""
        with self._cond:
            earlier = self._gap_rows()[0]
            earlier = earlier[earlier < self._pos]
            if len(earlier) == 0:
                return None
            self._seek_index(int(earlier[-1]))
            self._cond.notify_all()
            return self._position_s()

    @property
    def gap_positions_s(self) -> list[float]:
        """Where gaps are, s from the start (for marks on a slider; a long recording's grow
        while it is indexed)."""
        with self._cond:
            if self._rows is None:
                return []
            return (self._gap_rows()[1] - self._rows.first_t).tolist()

    @property
    def bookmarks(self) -> list[Bookmark]:
        """Bookmarks (from the ``bookmarks`` metadata, plus those added), in time order."""
        with self._cond:
            return list(self._bookmarks)

    def add_bookmark(self, position_s: float | None = None, label: str = "") -> Bookmark:
        """Mark ``position_s`` (default: the current position); kept in memory.

        Save them into the file with :func:`app.core.recording.save_bookmarks`.
        """
        with self._cond:
            offset = self._position_s() if position_s is None else float(position_s)
            start = 0.0 if self._rows is None else self._rows.first_t
            mark = Bookmark(start + offset, label)
            self._bookmarks = sorted([*self._bookmarks, mark], key=lambda b: b.t_s)
            return mark

    def bookmark_position_s(self, bookmark: Bookmark) -> float:
        """A bookmark's position in s from the start."""
        with self._cond:
            return bookmark.t_s - (0.0 if self._rows is None else self._rows.first_t)

    def next_bookmark(self) -> Bookmark | None:
        """Seek to the first bookmark after the current position."""
        return self._jump_to_bookmark(forward=True)

    def previous_bookmark(self) -> Bookmark | None:
        """Seek to the last bookmark before the current position."""
        return self._jump_to_bookmark(forward=False)

    def _jump_to_bookmark(self, *, forward: bool) -> Bookmark | None:
        with self._cond:
            rows = self._rows
            if rows is None:
                return None
            indices = [(rows.index_at_t(b.t_s, "left"), b) for b in self._bookmarks]
            if forward:
                candidates = [(i, b) for i, b in indices if i > self._pos and rows.exists(i)]
                chosen = candidates[0] if candidates else None
            else:
                candidates = [(i, b) for i, b in indices if i < self._pos]
                chosen = candidates[-1] if candidates else None
            if chosen is None:
                return None
            self._seek_index(chosen[0])
            self._cond.notify_all()
            return chosen[1]

    # -- internals (called with the condition held) ------------------------------------------
    def _ended(self) -> bool:
        """No sample left at the current position (reads on to find out, for a long file)."""
        return self._rows is None or not self._rows.exists(self._pos)

    def _exact_blocks(self) -> bool:
        return self._exact and self._rows is not None and self._rows.has_block_start

    def _gap_rows(self) -> tuple[np.ndarray, np.ndarray]:
        if self._rows is None:
            return np.empty(0, dtype=np.int64), np.empty(0)
        return self._rows.gaps()

    def _device_info(self, recording: Recording) -> DeviceInfo:
        device = recording.device
        rows = self._rows
        assert rows is not None

        def number(key: str, default: float) -> float:
            return _positive_number(device, key, default)

        odr = number("odr_hz", rows.rate_hz)
        extra = dict(device.get("extra") or {})
        extra["replay"] = {
            "path": str(self.path), "recorded_url": device.get("url"),
            "start_time": recording.metadata.get("start_time"), "note": recording.note,
            "samples": rows.count, "duration_s": rows.last_t - rows.first_t,
            "streamed": rows.streamed,
        }
        return DeviceInfo(
            url=self.url,
            name=str(device.get("name") or f"Recording {self.path.name}"),
            unique_id=str(device.get("unique_id") or f"recording:{self.path.stem}"),
            sensor=str(device.get("sensor") or "unknown"),
            odr_hz=odr,
            odr_nominal_hz=number("odr_nominal_hz", odr),
            accel_fs_g=int(number("accel_fs_g", 0)),
            gyro_fs_dps=int(number("gyro_fs_dps", 0)),
            firmware=str(device.get("firmware") or ""),
            extra=extra,
            magnetometer=_recorded_magnetometer(recording, odr),
            reference=_reference_of(recording) or "",
        )

    def _position_s(self) -> float:
        rows = self._rows
        if rows is None:
            return 0.0
        index = max(self._pos, self._lead_in_end)  # a seek's lead-in is not the position
        if not rows.exists(index):
            return float(rows.last_t - rows.first_t)
        return float(rows.t(index) - rows.first_t)

    def _index_at(self, position_s: float) -> int:
        if not math.isfinite(position_s):
            raise ValueError(f"cannot seek to {position_s!r}")
        rows = self._rows
        assert rows is not None
        index = rows.index_at_t(rows.first_t + max(0.0, position_s), "left")
        while index > 0 and not rows.exists(index):  # past the end: the last sample
            index = min(index - 1, rows.count - 1)
        return index

    def _seek_index(self, index: int) -> None:
        if index != self._pos:
            self._discontinuity = True
            self._generation += 1
        self._pos = index
        self._lead_in_end = 0
        self._anchor()

    def _anchor(self) -> None:
        """Pace from here: the next sample is due now."""
        self._anchor_wall = self._clock()
        rows = self._rows
        if rows is not None:
            self._anchor_t = rows.t(self._pos) if rows.exists(self._pos) else rows.last_t

    def _due_wall(self, index: int) -> float:
        assert self._rows is not None
        return self._anchor_wall + (self._rows.t(index) - self._anchor_t) / self._speed

    def _take(self) -> tuple[RawBlock | None, float | None]:
        """The next block if one is due, else (None, seconds until one is, or None: no idea)."""
        rows = self._rows
        if self._closed or rows is None:
            return None, None
        if self._ended():
            if not self._loop:
                return None, None
            self._pos = 0
            self._discontinuity = True
            self._generation += 1
            self._anchor()
        if self._lead_in_end > self._pos:
            block = self._deliver(self._lead_in_end)
            self._lead_in_end = 0
            self._anchor()  # paced from the seek's position on
            return block, None
        if self._step_samples:
            count = self._step_samples
            self._step_samples = 0
            stop = self._block_end() if count < 0 else self._pos + count
            return self._deliver(stop), None
        if not self._playing:
            return None, None
        if self._exact_blocks():
            stop = self._block_end()
            if self._speed == math.inf:
                return self._deliver(stop), None
            wait = self._due_wall(stop - 1) - self._clock()
            return (self._deliver(stop), None) if wait <= 0.0 else (None, wait)
        if self._speed == math.inf:
            return self._deliver(self._pos + self._block), None
        now = self._clock()
        reached = self._anchor_t + (now - self._anchor_wall) * self._speed
        wanted = max(1, math.ceil(MIN_BLOCK_S * rows.rate_hz))
        ahead = rows.rows(self._pos, self._pos + max(wanted, math.ceil(MAX_BLOCK_S *
                                                                       rows.rate_hz)))
        stop = self._pos + int(np.searchsorted(ahead.t, reached, "right"))
        if stop >= self._pos + min(wanted, len(ahead)):
            return self._deliver(stop), None
        ready = self._pos + min(wanted, len(ahead)) - 1
        return None, max(0.0, self._due_wall(ready) - now)

    def _block_end(self) -> int:
        """End of the block that starts at the current position."""
        if not self._exact_blocks():
            return self._pos + self._block
        assert self._rows is not None
        return self._rows.block_end(self._pos)

    def _deliver(self, stop: int) -> RawBlock:
        rows = self._rows
        assert rows is not None
        start = self._pos
        part = rows.rows(start, max(stop, start + 1))
        stop = start + len(part)
        gap = part.gap.copy()
        lost = sum(rows.lost_at(start + int(k)) for k in np.flatnonzero(gap))
        if self._discontinuity:
            gap[0] = True
            lost -= rows.lost_at(start)
            self._discontinuity = False
        self._last_block_generation = self._generation
        self._pos = stop
        if self._speed != math.inf and stop > 0 and rows.exists(stop):
            hole = rows.t(stop) - float(part.t[-1])
            if hole > HOLE_LIMIT_S:  # wait at most HOLE_LIMIT_S for the next sample
                due = self._due_wall(stop - 1) + HOLE_LIMIT_S / self._speed
                self._anchor_wall, self._anchor_t = due, rows.t(stop)
        return RawBlock(
            t_s=part.t,
            accel_raw=part.accel,
            gyro_raw=part.gyro,
            temp_raw=part.temp,
            scale=UNIT_SCALE,
            gap=gap,
            lost_samples=max(0, lost),
            reference_quat=part.reference,
            mag_raw=part.mag,
        )

    # -- bookmarks for the file ---------------------------------------------------------------
    def bookmarks_metadata(self) -> dict[str, list[dict[str, Any]]]:
        """``{"bookmarks": [...]}``, the metadata entry that stores the current bookmarks."""
        with self._cond:
            return {KEY_BOOKMARKS: [{"t": b.t_s, "label": b.label} for b in self._bookmarks]}


def _rate(recording: Recording) -> float:
    rate = recording.rate_hz
    return rate if math.isfinite(rate) and rate > 0 else 100.0
