"""The device worker: one long-lived object on its own QThread (QtCore only, no widgets).

The GUI talks to it only through queued signals; it reads the device, runs the pipeline and
reports status a few times a second. Samples never travel through signals: the views pull
them from the pipeline's ring buffers on their own timer.
"""

from __future__ import annotations

import logging
import time
import traceback
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from PySide6.QtCore import QMetaObject, QObject, Qt, QThread, QTimer, Signal, Slot

from app.core.calibration import IDENTITY_CALIBRATION
from app.core.calibration_procedures import (
    CalibrationProfile,
    ProfileError,
    ProfileStore,
    SensorSettings,
    TareReference,
    make_profile,
)
from app.core.filters import known_parameters
from app.core.pipeline import Pipeline
from app.core.recording import RecordingError, RecordingWriter, recording_metadata
from app.core.recording.recorder import reference_source_of
from app.core.self_test import SelfTestReport
from drivers.base import Device, DeviceInfo
from drivers.errors import DeviceError, DeviceIOError
from drivers.registry import create_device

log = logging.getLogger(__name__)

READ_TIMEOUT_S = 0.05
STATUS_INTERVAL_MS = 250
RATE_WINDOW_S = 2.0
RECONNECT_INTERVAL_MS = 500


@dataclass(slots=True)
class _Reconnect:
    """A board that was unplugged mid-session and is awaited back (by USB serial number)."""

    url: str
    usb_serial: str
    unique_id: str
    last_t_s: float
    """Pipeline time of the last sample before the cable was pulled."""
    lost_at: float
    """``time.monotonic()`` when it was lost."""
    clock_origin_s: float | None
    """The board clock at the old connection's t = 0, when the driver knows it."""


@dataclass(frozen=True, slots=True)
class StreamStatus:
    """Figures the status bar shows, sent a few times per second."""

    url: str
    measured_rate_hz: float
    samples: int
    lost_samples: int
    gaps: int
    pipeline_load: float
    """Fraction of one core the pipeline used over the last interval."""
    replay: tuple[float, float, bool] | None = None
    """For a replay: position (s), duration (s), playing."""


class DeviceWorker(QObject):
    """Owns the open device and the pipeline; lives on the worker thread."""

    connected = Signal(object)  # DeviceInfo
    disconnected = Signal(str)  # the reason, "" when the user asked
    error = Signal(str)
    status = Signal(object)  # StreamStatus
    filterChanged = Signal(str, dict)  # name, parameter values
    comparisonsChanged = Signal(list)  # names of the filters running side by side
    calibrationChanged = Signal(object)  # the active CalibrationProfile, or None
    tareChanged = Signal(object)  # the active TareReference, or None
    reconnecting = Signal(str)  # the cable was pulled; the session waits for the board
    recordingChanged = Signal(object)  # WriterStatus of the recording, or None when none
    deviceMessage = Signal(int, str)  # level (0 debug .. 3 error), text: the device's own LOG
    selfTestAvailable = Signal(bool)  # the connected device can run the sensor's self-test
    selfTestFinished = Signal(object, str)  # SelfTestReport or None, and an error message

    def __init__(self, pipeline: Pipeline, profile_store: ProfileStore | None = None) -> None:
        super().__init__()
        self.pipeline = pipeline
        self.profile_store = profile_store or ProfileStore()
        self.profile: CalibrationProfile | None = None
        self._device: Device | None = None
        self._poll_timer: QTimer | None = None
        self._status_timer: QTimer | None = None
        self._rate_history: deque[tuple[float, int]] = deque()
        self._last_cpu = (time.monotonic(), 0.0)
        self._reconnect: _Reconnect | None = None
        self._reconnect_timer: QTimer | None = None
        self._time_offset_s = 0.0
        """Added to device time so the session's time axis runs on across reconnections."""
        self._align_time = False
        self._gap_pending = False
        self._writer: RecordingWriter | None = None

    # -- lifecycle (worker thread) ----------------------------------------------------------
    @Slot()
    def start(self) -> None:
        """Create the timers in the worker thread and compile the filter."""
        self._poll_timer = QTimer(self)
        self._poll_timer.setInterval(0)
        self._poll_timer.timeout.connect(self._poll)
        self._status_timer = QTimer(self)
        self._status_timer.setInterval(STATUS_INTERVAL_MS)
        self._status_timer.timeout.connect(self._emit_status)
        self._reconnect_timer = QTimer(self)
        self._reconnect_timer.setInterval(RECONNECT_INTERVAL_MS)
        self._reconnect_timer.timeout.connect(self._try_reconnect)
        self.pipeline.filter.warm_up()

    @Slot()
    def shutdown(self) -> None:
        """Close the device and stop the timers (before the thread quits)."""
        self._close_device("")
        for timer in (self._poll_timer, self._status_timer, self._reconnect_timer):
            if timer is not None:
                timer.stop()

    # -- commands from the GUI --------------------------------------------------------------
    @Slot(str)
    def connect_device(self, url: str) -> None:
        """Close any open device, then open ``url`` and start streaming."""
        self._close_device("")
        try:
            device = create_device(url)
            info = device.open()
        except DeviceError as exc:
            self.error.emit(str(exc))
            self.disconnected.emit(str(exc))
            return
        except Exception as exc:  # a driver bug must not take the app down
            log.exception("opening %s failed", url)
            self.error.emit(f"{url}: unexpected error while opening: {exc!r}")
            self.disconnected.emit(str(exc))
            return
        self._device = device
        self._use_recorded_filter(device)
        self.pipeline.configure(info.odr_hz)
        self._time_offset_s = 0.0
        self._align_time = self._gap_pending = False
        self._load_profile(info)
        self._rate_history.clear()
        self._last_cpu = (time.monotonic(), self.pipeline.counters.filter_cpu_s)
        assert self._poll_timer is not None and self._status_timer is not None
        self._poll_timer.start()
        self._status_timer.start()
        self.connected.emit(info)
        self.selfTestAvailable.emit(device.supports_self_test)

    @Slot()
    def disconnect_device(self) -> None:
        self._close_device("")

    @Slot()
    def run_self_test(self) -> None:
        """The sensor's self-test (about a second; streaming pauses and the pause is a gap)."""
        device = self._device
        if device is None or not device.supports_self_test:
            self.selfTestFinished.emit(None, "The connected device has no self-test: it needs "
                                             "the NUCLEO firmware or a register-level LSM6DSOX.")
            return
        try:
            result = device.self_test()  # type: ignore[attr-defined]
        except DeviceIOError as exc:
            self.selfTestFinished.emit(None, str(exc))
            if not self._await_board(device, str(exc)):
                self._close_device(str(exc))
            return
        except DeviceError as exc:
            self.selfTestFinished.emit(None, str(exc))
            return
        self.selfTestFinished.emit(SelfTestReport.from_result(result), "")

    def _use_recorded_filter(self, device: Device) -> None:
        """A replay runs the filter (and parameters) it was recorded with, to reproduce it."""
        recording = getattr(device, "recording", None)
        name = getattr(recording, "filter_name", None)
        if not name:
            return
        try:
            values, dropped = known_parameters(name, recording.filter_parameters)
            if dropped:
                self.deviceMessage.emit(2, f"The recording's {name} parameters "
                                        f"{', '.join(dropped)} are from an older version and "
                                        "are ignored")
            new_filter = self.pipeline.set_filter(name, **values)
        except (KeyError, ValueError) as exc:
            self.error.emit(f"The recording's filter cannot be restored ({exc}); "
                            f"replaying with {self.pipeline.filter.title}")
            return
        self.filterChanged.emit(new_filter.name, new_filter.parameter_values())

    # -- calibration ------------------------------------------------------------------------
    def _load_profile(self, info: DeviceInfo) -> None:
        """Apply the device's stored profile, if any; a bad file is reported, never fatal."""
        recorded = getattr(self._device, "recorded_calibration", None)
        if recorded is not None:
            # A replay reproduces its recording: the calibration it was made with, not the
            # device's current profile (which may have changed since).
            self._apply_profile(None if recorded.is_identity else make_profile(
                info.unique_id, recorded,
                SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps, info.sensor),
                method="recorded",
            ))
            self.pipeline.set_level_reference(None)
            self.tareChanged.emit(None)
            return
        profile = None
        try:
            profile = self.profile_store.load_for_device(info.unique_id)
        except ProfileError as exc:
            self.error.emit(f"Calibration profile not loaded: {exc}")
        if profile is not None:
            differences = profile.settings.differences(
                SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps, info.sensor)
            )
            if differences:
                self.error.emit(
                    f"The calibration profile of {info.unique_id} was made with other sensor "
                    f"settings ({'; '.join(differences)}); it is applied all the same"
                )
        self._apply_profile(profile)
        self.pipeline.set_level_reference(None)
        self.tareChanged.emit(None)

    def _apply_profile(self, profile: CalibrationProfile | None) -> None:
        self.profile = profile
        self.pipeline.set_calibration(
            IDENTITY_CALIBRATION if profile is None else profile.calibration
        )
        self.calibrationChanged.emit(profile)

    @Slot(object)
    def use_profile(self, profile: CalibrationProfile) -> None:
        """Apply a new profile (from the wizard or an import) and store it for the device."""
        try:
            self.profile_store.save(profile)
        except (OSError, ProfileError) as exc:
            self.error.emit(f"The calibration is applied but could not be saved: {exc}")
        self._apply_profile(profile)

    @Slot()
    def use_no_calibration(self) -> None:
        """Run uncalibrated for now (the stored profile is kept)."""
        self._apply_profile(None)

    @Slot()
    def tare(self) -> None:
        """Take the current attitude as level (relative measurement)."""
        if self.pipeline.counters.samples == 0:
            self.error.emit("Nothing to tare yet: no data has arrived")
            return
        reference = TareReference.from_quaternion(self.pipeline.filter.quaternion)
        self.pipeline.set_level_reference(reference)
        self.tareChanged.emit(reference)

    @Slot(object)
    def set_tare(self, reference: TareReference | None) -> None:
        """Use a given level reference (e.g. from the reversal procedure)."""
        self.pipeline.set_level_reference(reference)
        self.tareChanged.emit(self.pipeline.level_reference)

    @Slot()
    def clear_tare(self) -> None:
        self.pipeline.set_level_reference(None)
        self.tareChanged.emit(None)

    @Slot(str)
    def set_filter(self, name: str) -> None:
        try:
            new_filter = self.pipeline.set_filter(name)
        except (KeyError, ValueError) as exc:
            self.error.emit(str(exc))
            return
        self.filterChanged.emit(new_filter.name, new_filter.parameter_values())

    @Slot(str, object)
    def set_filter_parameter(self, name: str, value: Any) -> None:
        try:
            self.pipeline.set_filter_parameter(name, value)
        except (KeyError, ValueError) as exc:
            self.error.emit(str(exc))
            return
        current = self.pipeline.filter
        self.filterChanged.emit(current.name, current.parameter_values())

    @Slot(list)
    def set_comparisons(self, names: list) -> None:
        """Run these filters side by side with the main one."""
        try:
            running = self.pipeline.set_comparisons([str(n) for n in names])
        except (KeyError, ValueError) as exc:
            self.error.emit(str(exc))
            running = list(self.pipeline.comparisons)
        self.comparisonsChanged.emit(running)

    @Slot(float, float)
    def set_simulator_target(self, roll_deg: float, pitch_deg: float) -> None:
        """Tilt an interactive simulator (ignored by devices that cannot be tilted)."""
        device = self._device
        if device is None or not getattr(device, "is_interactive", False):
            return
        try:
            device.set_target_attitude(roll_deg, pitch_deg)
        except DeviceError as exc:
            self.error.emit(str(exc))

    # -- streaming --------------------------------------------------------------------------
    def _poll(self) -> None:
        device = self._device
        if device is None:
            return
        try:
            raw = device.read(READ_TIMEOUT_S)
            for message in device.take_messages():
                self.deviceMessage.emit(message.level, message.text)
            if raw is not None and len(raw):
                self._continue_time_axis(device, raw)
                self.pipeline.process(raw)
                if self._writer is not None:
                    self._writer.write(raw)
        except DeviceIOError as exc:
            if not self._await_board(device, str(exc)):
                self.error.emit(str(exc))
                self._close_device(str(exc))
        except DeviceError as exc:
            self.error.emit(str(exc))
            self._close_device(str(exc))
        except Exception as exc:
            log.error("pipeline failure:\n%s", traceback.format_exc())
            message = f"{device.url}: processing failed ({exc!r}); the device was disconnected"
            self.error.emit(message)
            self._close_device(message)

    def _emit_status(self) -> None:
        device = self._device
        if device is None:
            return
        now = time.monotonic()
        counters = self.pipeline.counters
        history = self._rate_history
        history.append((now, counters.samples))
        while len(history) > 2 and now - history[0][0] > RATE_WINDOW_S:
            history.popleft()
        span = history[-1][0] - history[0][0]
        rate = (history[-1][1] - history[0][1]) / span if span > 0 else 0.0
        last_time, last_cpu = self._last_cpu
        load = (counters.filter_cpu_s - last_cpu) / max(now - last_time, 1e-9)
        self._last_cpu = (now, counters.filter_cpu_s)
        self.status.emit(
            StreamStatus(
                url=device.url, measured_rate_hz=rate, samples=counters.samples,
                lost_samples=counters.lost_samples, gaps=counters.gaps, pipeline_load=load,
                replay=self._replay_position(device),
            )
        )

    # -- replay -----------------------------------------------------------------------------
    @staticmethod
    def _replay_position(device: Device) -> tuple[float, float, bool] | None:
        if getattr(device, "scheme", "") != "replay":
            return None
        return (float(device.position_s), float(device.duration_s), bool(device.playing))

    @Slot(str, object)
    def replay_control(self, name: str, value: object) -> None:
        """play, pause, step, speed (0 = as fast as possible), loop, seek (s from the start),
        next_gap, next_bookmark, add_bookmark."""
        device = self._device
        if getattr(device, "scheme", "") != "replay":
            return
        try:
            if name == "play":
                device.play()
            elif name == "pause":
                device.pause()
            elif name == "step":
                device.step()
            elif name == "speed":
                device.set_speed(value if value else "max")
            elif name == "loop":
                device.loop = bool(value)
            elif name == "add_bookmark":
                device.add_bookmark()
            elif name in ("seek", "next_gap", "next_bookmark"):
                if name == "seek":
                    target = float(value)
                elif name == "next_bookmark":
                    later = [
                        device.bookmark_position_s(b) for b in device.bookmarks
                        if device.bookmark_position_s(b) > device.position_s + 1e-9
                    ]
                    if not later:
                        self.error.emit("No further bookmark in this recording.")
                        return
                    target = min(later)
                else:
                    later = [p for p in device.gap_positions_s if p > device.position_s + 1e-9]
                    if not later:
                        self.error.emit("No further gap in this recording.")
                        return
                    target = later[0]
                # Time would run backwards: start the views afresh at the new position.
                self.pipeline.configure(device.info.odr_hz)
                device.seek(target)
        except (DeviceError, ValueError) as exc:
            self.error.emit(str(exc))

    # -- recording --------------------------------------------------------------------------
    @Slot(str, str)
    def start_recording(self, path: str, note: str) -> None:
        """Record the raw stream (before calibration) to ``path`` in format v1."""
        device = self._device
        if device is None or device.info is None:
            self.error.emit("Connect a device before recording.")
            return
        self.stop_recording()
        metadata = recording_metadata(
            device=device.info, calibration=self.pipeline.calibration,
            orientation_filter=self.pipeline.filter,
            comparison_filters=list(self.pipeline.comparisons.values()), note=note,
            reference_source=reference_source_of(device),
        )
        writer = RecordingWriter(
            path, metadata, on_error=self.error.emit,
            on_flush=self.recordingChanged.emit,
        )
        try:
            writer.start()
        except RecordingError as exc:
            self.error.emit(str(exc))
            return
        self._writer = writer
        self.recordingChanged.emit(writer.status)

    @Slot()
    def stop_recording(self) -> None:
        """Finish the recording (everything queued is written and synced)."""
        writer, self._writer = self._writer, None
        if writer is not None:
            status = writer.close()
            self.recordingChanged.emit(None)
            if status.error:
                self.error.emit(status.error)

    # -- hot-plug ---------------------------------------------------------------------------
    def _await_board(self, device: Device, reason: str) -> bool:
        """After an unplug, keep the session and wait for the board (True) if it can return."""
        info = device.info
        usb_serial = None if info is None else info.extra.get("usb_serial")
        if info is None or not usb_serial or self.pipeline.counters.samples == 0:
            return False
        last_t = self.pipeline.samples.latest(1)["t"]
        self._reconnect = _Reconnect(
            url=info.url, usb_serial=str(usb_serial), unique_id=info.unique_id,
            last_t_s=float(last_t[0]) if len(last_t) else 0.0, lost_at=time.monotonic(),
            clock_origin_s=self._clock_origin(device),
        )
        for timer in (self._poll_timer, self._status_timer):
            if timer is not None:
                timer.stop()
        self._device = None
        try:
            device.close()
        except DeviceError as exc:
            log.warning("closing %s: %s", info.url, exc)
        self.selfTestAvailable.emit(False)
        self.reconnecting.emit(
            f"{reason}. The session is kept: waiting for the board (USB serial {usb_serial}) "
            "to come back on any port."
        )
        assert self._reconnect_timer is not None
        self._reconnect_timer.start()
        return True

    def _clock_origin(self, device: Device) -> float | None:
        origin = getattr(device, "device_clock_origin_s", None)
        return None if origin is None else float(origin) - self._time_offset_s

    def _try_reconnect(self) -> None:
        plan = self._reconnect
        if plan is None:
            return
        from drivers.serial_link import reconnect_url  # only serial boards come back

        url = reconnect_url(plan.url, plan.usb_serial)
        if url is None:
            return
        try:
            device = create_device(url)
            info = device.open()
        except DeviceError as exc:  # still enumerating, or busy for a moment: try again
            log.info("reconnect to %s not yet possible: %s", url, exc)
            return
        if info.unique_id != plan.unique_id:
            device.close()
            return
        assert self._reconnect_timer is not None and self._poll_timer is not None
        self._reconnect_timer.stop()
        self._device = device
        self._align_time = True  # the new connection's time starts at 0 again
        self._gap_pending = True
        self._poll_timer.start()
        assert self._status_timer is not None
        self._status_timer.start()
        self.connected.emit(info)
        self.selfTestAvailable.emit(device.supports_self_test)

    def _continue_time_axis(self, device: Device, raw) -> None:
        """Shift a reconnected board's time so the session's time axis keeps real time."""
        plan = self._reconnect
        if self._align_time and plan is not None:
            origin = getattr(device, "device_clock_origin_s", None)
            if origin is not None and plan.clock_origin_s is not None and (
                origin >= plan.clock_origin_s
            ):
                # Same board, clock still running: its own clock spans the outage exactly.
                self._time_offset_s = float(origin) - plan.clock_origin_s
            else:  # the board was reset: measure the outage on the host's clock
                outage = time.monotonic() - plan.lost_at
                self._time_offset_s = plan.last_t_s + outage - float(raw.t_s[0])
            self._align_time = False
            self._reconnect = None
        if self._time_offset_s:
            raw.t_s = raw.t_s + self._time_offset_s
        if self._gap_pending:
            gap = np.zeros(len(raw), dtype=bool) if raw.gap is None else raw.gap.copy()
            gap[0] = True
            raw.gap = gap
            self._gap_pending = False

    def _close_device(self, reason: str) -> None:
        self.stop_recording()
        device, self._device = self._device, None
        waiting = self._reconnect is not None
        self._reconnect = None
        for timer in (self._poll_timer, self._status_timer, self._reconnect_timer):
            if timer is not None:
                timer.stop()
        if device is None:
            if waiting:
                self.disconnected.emit(reason)
            return
        try:
            device.close()
        except DeviceError as exc:
            log.warning("closing %s: %s", device.url, exc)
        self.selfTestAvailable.emit(False)
        self.disconnected.emit(reason)


class DeviceSession(QObject):
    """The GUI-side handle: starts the worker thread and forwards requests to it.

    Every request is a queued signal, so the GUI thread never blocks on the device. The
    worker's events are re-emitted by the session's own signals in the GUI thread; connect
    to those, never to the worker's.
    """

    connected = Signal(object)  # DeviceInfo
    disconnected = Signal(str)
    error = Signal(str)
    status = Signal(object)  # StreamStatus
    filterChanged = Signal(str, dict)
    comparisonsChanged = Signal(list)
    calibrationChanged = Signal(object)
    tareChanged = Signal(object)
    reconnecting = Signal(str)
    recordingChanged = Signal(object)
    deviceMessage = Signal(int, str)
    selfTestAvailable = Signal(bool)
    selfTestFinished = Signal(object, str)

    requestConnect = Signal(str)
    requestDisconnect = Signal()
    requestFilter = Signal(str)
    requestFilterParameter = Signal(str, object)
    requestSimulatorTarget = Signal(float, float)
    requestComparisons = Signal(list)
    requestProfile = Signal(object)  # CalibrationProfile to apply and store
    requestNoCalibration = Signal()
    requestTare = Signal()
    requestClearTare = Signal()
    requestTareReference = Signal(object)  # TareReference
    requestStartRecording = Signal(str, str)  # path, note
    requestStopRecording = Signal()
    requestReplayControl = Signal(str, object)
    requestSelfTest = Signal()

    def __init__(
        self,
        pipeline: Pipeline | None = None,
        parent: QObject | None = None,
        profile_store: ProfileStore | None = None,
    ) -> None:
        super().__init__(parent)
        self.pipeline = pipeline or Pipeline()
        self.profile_store = profile_store or ProfileStore()
        self.worker = DeviceWorker(self.pipeline, self.profile_store)
        self.thread = QThread()
        self.thread.setObjectName("device-worker")
        self.worker.moveToThread(self.thread)
        self.thread.started.connect(self.worker.start)
        self.requestConnect.connect(self.worker.connect_device)
        self.requestDisconnect.connect(self.worker.disconnect_device)
        self.requestFilter.connect(self.worker.set_filter)
        self.requestFilterParameter.connect(self.worker.set_filter_parameter)
        self.requestSimulatorTarget.connect(self.worker.set_simulator_target)
        self.requestComparisons.connect(self.worker.set_comparisons)
        self.requestProfile.connect(self.worker.use_profile)
        self.requestNoCalibration.connect(self.worker.use_no_calibration)
        self.requestTare.connect(self.worker.tare)
        self.requestClearTare.connect(self.worker.clear_tare)
        self.requestTareReference.connect(self.worker.set_tare)
        self.requestStartRecording.connect(self.worker.start_recording)
        self.requestStopRecording.connect(self.worker.stop_recording)
        self.requestReplayControl.connect(self.worker.replay_control)
        self.requestSelfTest.connect(self.worker.run_self_test)
        self.device_info: DeviceInfo | None = None
        # Queued into the GUI thread (this object lives there).
        self.worker.connected.connect(self.connected)
        self.worker.disconnected.connect(self.disconnected)
        self.worker.error.connect(self.error)
        self.worker.status.connect(self.status)
        self.worker.filterChanged.connect(self.filterChanged)
        self.worker.comparisonsChanged.connect(self.comparisonsChanged)
        self.worker.calibrationChanged.connect(self.calibrationChanged)
        self.worker.tareChanged.connect(self.tareChanged)
        self.worker.reconnecting.connect(self.reconnecting)
        self.worker.recordingChanged.connect(self.recordingChanged)
        self.worker.deviceMessage.connect(self.deviceMessage)
        self.worker.selfTestAvailable.connect(self.selfTestAvailable)
        self.worker.selfTestFinished.connect(self.selfTestFinished)
        self.connected.connect(self._on_connected)
        self.disconnected.connect(self._on_disconnected)
        self.thread.start()

    def _on_connected(self, info: DeviceInfo) -> None:
        self.device_info = info

    def _on_disconnected(self, _reason: str) -> None:
        self.device_info = None

    def shutdown(self) -> None:
        """Close the device and stop the thread; blocks until the thread has finished."""
        if not self.thread.isRunning():
            return
        # Runs in the worker thread, after whatever slot is in progress (at most one read).
        blocking = Qt.ConnectionType.BlockingQueuedConnection
        QMetaObject.invokeMethod(self.worker, "shutdown", blocking)
        self.thread.quit()
        self.thread.wait()
