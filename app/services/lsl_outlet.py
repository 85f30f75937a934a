"""Live samples out over Lab Streaming Layer (pylsl): a subscriber of the acquisition session.

Two streams per device, so a lab recorder (LabRecorder) can take either and each has one
channel type:

- ``IMU`` (name ``Inclinometer IMU``, source id ``inclinometer:UNIQUE_ID:imu``): the
  calibrated samples as the pipeline hands them on, ``ax ay az`` (m/s^2), ``gx gy gz``
  (rad/s) and, with a magnetometer, ``mx my mz`` (uT, NaN on the rows without a new field
  sample, as in a recording); ``double64``, at the device's rate.
- ``Orientation`` (``Inclinometer orientation``, ``inclinometer:UNIQUE_ID:orientation``): the
  filtered orientation as the window shows it (after the tare), the unit quaternion
  ``qw qx qy qz`` rotating sensor-frame vectors into the earth frame, earth z up; one per IMU
  sample, with the same timestamps. Only with a pipeline (a filter).

Each stream's description holds its channels (label, unit, type), the device (URL, name,
unique id, sensor) and the filter. Timestamps: each sample's device time mapped to the host's
clock by the session's clock alignment (:mod:`app.core.clock_alignment`, the lower envelope of
(device time, receive time) pairs), then to ``pylsl.local_clock()`` (the offset between the
two clocks measured when the outlet opens; on Linux they are the same clock). So the samples
carry the time they were measured, not when they arrived, and LabRecorder files line up with
other devices' streams. A refit never moves a timestamp before the previous one.

The outlet is hooked into the one acquisition session as a :class:`Subscriber` (it reads no
device of its own). A new device (another unique id or URL, or a magnetometer appearing)
opens new streams. The streams open when the outlet is made (when a device is open), so
that inlets can connect before the first sample. No Qt here.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.core.clock_alignment import ClockAligner, ClockFit
from app.core.devices import DeviceInfo
from app.core.pipeline import Pipeline
from app.services.acquisition import Block, Subscriber

IMU_TYPE = "IMU"
ORIENTATION_TYPE = "Orientation"
IMU_CHANNELS = (("ax", "m/s^2", "Accelerometer"), ("ay", "m/s^2", "Accelerometer"),
                ("az", "m/s^2", "Accelerometer"), ("gx", "rad/s", "Gyroscope"),
                ("gy", "rad/s", "Gyroscope"), ("gz", "rad/s", "Gyroscope"))
MAG_CHANNELS = (("mx", "uT", "Magnetometer"), ("my", "uT", "Magnetometer"),
                ("mz", "uT", "Magnetometer"))
ORIENTATION_CHANNELS = (("qw", "1", "Quaternion"), ("qx", "1", "Quaternion"),
                        ("qy", "1", "Quaternion"), ("qz", "1", "Quaternion"))
MIN_STEP_S = 1e-9
"""A refit of the clock never moves a sample before the previous one: at least this after."""
JUMP_S = 1.0
"""A block starting this much after the previous one's end (an outage, a replay's seek), or
before it, starts the outlet's own clock fit afresh: its old pairs belong to another mapping."""


class LslUnavailable(RuntimeError):
    """pylsl (or the liblsl it loads) cannot be used here: says why, in one line."""


def load_pylsl() -> Any:
    """The pylsl module; :class:`LslUnavailable` when it or its liblsl cannot be loaded."""
    try:
        import pylsl
    except ImportError as exc:
        raise LslUnavailable(f"Lab Streaming Layer is not available: pylsl cannot be loaded "
                             f"({exc})") from None
    except RuntimeError as exc:  # pylsl raises this when it finds no liblsl
        raise LslUnavailable(f"Lab Streaming Layer is not available: {exc}") from None
    return pylsl


@dataclass
class LslCounts:
    """What the outlet sent (thread-safe to read as a snapshot)."""

    imu_samples: int = 0
    orientation_samples: int = 0
    chunks: int = 0
    streams_opened: int = 0


def source_id(info: DeviceInfo, kind: str) -> str:
    """The stream's source id: the device's unique id (its URL when it has none) and kind."""
    return f"inclinometer:{info.unique_id or info.url}:{kind}"


def lsl_description(outlet: LslOutlet) -> str:
    """What an outlet streams, for the user: its streams and source ids."""
    info = outlet.info
    if info is None:
        return "LSL: on (the streams open with the next device)"
    kinds = ["imu"] + (["orientation"] if outlet.has_orientation else [])
    return "LSL: " + ", ".join(source_id(info, kind) for kind in kinds)


class LslOutlet(Subscriber):
    """Pushes every block of the session to LSL (see the module).

    Parameters
    ----------
    device : the session's current device (asked on every block: a new device opens new
        streams); e.g. ``lambda: connection.device.info``.
    pipeline : where the filtered orientation is (None: the IMU stream alone).
    aligner : a clock alignment fed by its owner (a sensor group's, shared by the sensors of
        one clock); None: the outlet keeps its own, fed with each block's newest sample time
        and receive time.
    """

    def __init__(self, device: Callable[[], DeviceInfo | None], pipeline: Pipeline | None = None,
                 aligner: ClockAligner | None = None) -> None:
        self._pylsl = load_pylsl()
        self._device = device
        self._pipeline = pipeline
        self._own_aligner = aligner is None
        self.aligner = aligner or ClockAligner()
        self._lock = threading.Lock()
        self._key: tuple[str, str, bool] | None = None
        self._imu: Any = None
        self._orientation: Any = None
        self._last_stamp = -np.inf
        self._last_device_t: float | None = None
        self.counts = LslCounts()
        # local_clock() - time.monotonic(), bracketed by two reads of the monotonic clock.
        before = time.monotonic()
        lsl_now = self._pylsl.local_clock()
        after = time.monotonic()
        self.clock_offset_s = lsl_now - 0.5 * (before + after)
        self.info: DeviceInfo | None = None
        self._has_mag = False
        current = device()
        if current is not None:  # open now, so that inlets can connect before the first block
            self._ensure(current)

    def _ensure(self, info: DeviceInfo) -> None:
        key = (info.url, info.unique_id, info.magnetometer is not None)
        if key != self._key:
            self._open(info, key[2])
            self._key = key

    # -- streams ----------------------------------------------------------------------------------
    def _open(self, info: DeviceInfo, has_mag: bool) -> None:
        pylsl = self._pylsl
        channels = IMU_CHANNELS + (MAG_CHANNELS if has_mag else ())
        imu = pylsl.StreamInfo("Inclinometer IMU", IMU_TYPE, len(channels), float(info.odr_hz),
                               "double64", source_id(info, "imu"))
        self._describe(imu, info, channels)
        self._imu = pylsl.StreamOutlet(imu)
        self._orientation = None
        if self._pipeline is not None:
            orientation = pylsl.StreamInfo(
                "Inclinometer orientation", ORIENTATION_TYPE, len(ORIENTATION_CHANNELS),
                float(info.odr_hz), "double64", source_id(info, "orientation"))
            self._describe(orientation, info, ORIENTATION_CHANNELS)
            self._orientation = pylsl.StreamOutlet(orientation)
        self.info = info
        self._has_mag = has_mag
        self._last_stamp = -np.inf
        self.counts.streams_opened += 1

    def _describe(self, stream: Any, info: DeviceInfo,
                  channels: tuple[tuple[str, str, str], ...]) -> None:
        desc = stream.desc()
        desc.append_child_value("manufacturer", "inclinometer")
        node = desc.append_child("channels")
        for label, unit, kind in channels:
            channel = node.append_child("channel")
            channel.append_child_value("label", label)
            channel.append_child_value("unit", unit)
            channel.append_child_value("type", kind)
        device = desc.append_child("device")
        for key in ("url", "name", "unique_id", "sensor"):
            device.append_child_value(key, str(getattr(info, key)))
        if self._pipeline is not None:
            desc.append_child_value("filter", self._pipeline.filter.name)
        desc.append_child_value(
            "clock", "device time mapped to local_clock() by the session's clock alignment")

    @property
    def has_orientation(self) -> bool:
        return self._pipeline is not None

    def close(self) -> None:
        """Close the streams (the inlets see them end)."""
        with self._lock:
            self._imu = self._orientation = None
            self._key = None

    # -- the session's blocks -------------------------------------------------------------------
    def on_block(self, block: Block) -> None:
        info = self._device()
        n = len(block)
        if info is None or n == 0:
            return
        samples = block.samples
        with self._lock:
            self._ensure(info)
            if self._own_aligner:
                first, last = float(block.raw.t_s[0]), float(block.raw.t_s[-1])
                previous = self._last_device_t
                if previous is not None and not 0.0 < first - previous <= JUMP_S:
                    self.aligner = ClockAligner()
                self._last_device_t = last
                self.aligner.add(last, block.received_s)
            fit = self.aligner.fit()
            stamps = self.stamps(samples.t_s, fit, block.received_s)
            columns = [samples.accel_m_s2, samples.gyro_rad_s]
            if self._has_mag:
                columns.append(np.full((n, 3), np.nan) if samples.mag_ut is None
                               else samples.mag_ut)
            stamp_list = stamps.tolist()
            self._imu.push_chunk(np.hstack(columns), stamp_list)
            self.counts.imu_samples += n
            if self._orientation is not None and self._pipeline is not None:
                quat = self._pipeline.orientation.latest(n, ["quat"])["quat"]
                if len(quat) == n:
                    self._orientation.push_chunk(quat, stamp_list)
                    self.counts.orientation_samples += n
            self.counts.chunks += 1

    def stamps(self, t_s: np.ndarray, fit: ClockFit | None, received_s: float) -> np.ndarray:
        """LSL timestamps of device times: the clock fit, then local_clock's offset; never
        before the previous sample. Without a fit yet, the newest sample is ``received_s``."""
        t = np.asarray(t_s, dtype=np.float64)
        if fit is None:
            host = received_s - (t[-1] - t)
        else:
            host = np.asarray(fit.to_host(t), dtype=np.float64)
        stamps = host + self.clock_offset_s
        floor = self._last_stamp + MIN_STEP_S * np.arange(1, len(stamps) + 1)
        stamps = np.maximum(stamps, floor)
        stamps = np.maximum.accumulate(stamps)
        self._last_stamp = float(stamps[-1])
        return stamps
