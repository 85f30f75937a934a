"""The device worker: one long-lived QObject on its own QThread that wires the session's parts.

It owns no logic of its own: the :class:`~app.services.connection.Connection` opens, loses and
finds devices again, the :class:`~app.services.acquisition.Acquisition` session moves blocks
through every stage and records them (with the closing metadata every consumer stores),
:mod:`~app.services.replay_control` drives replays and
:class:`~app.services.calibration_state.CalibrationState` holds the profile and the tare. The
worker turns GUI requests (queued slots) into calls on them and their outcomes into signals,
and runs the timers. QtCore only, no widgets.
"""

from __future__ import annotations

import logging
import traceback
from typing import Any

from PySide6.QtCore import QObject, QTimer, Signal, Slot

from app.core.alarms import AlarmConfig, AlarmMonitor
from app.core.calibration_procedures import CalibrationProfile, ProfileStore, TareReference
from app.core.field_check import FieldReference
from app.core.heading import Declination
from app.core.pipeline import Pipeline
from app.core.recording import RecordingError
from app.services.acquisition import Acquisition
from app.services.calibration_state import CalibrationState
from app.services.connection import Connection
from app.services.health import HealthMonitor, recorded_events_note
from app.services.lsl_outlet import LslOutlet, LslUnavailable, lsl_description
from app.services.recorder import warm_up_kernels
from app.services.recording_control import RecordingControl
from app.services.replay_control import (
    OverviewTracker,
    ReplayNotice,
    recorded_alarms_note,
    replay_command,
    restore_recorded_filter,
)
from app.services.stream_status import StatusMeter, stream_status
from drivers.errors import DeviceError, DeviceIOError

log = logging.getLogger(__name__)

STATUS_INTERVAL_MS = 250
RECONNECT_INTERVAL_MS = 500


class DeviceWorker(QObject):
    """Owns the open device and the pipeline; lives on the worker thread."""

    connected = Signal(object)  # DeviceInfo
    disconnected = Signal(str)  # the reason, "" when the user asked
    error = Signal(str)
    notice = Signal(str)  # information for the user (a request with nothing to do)
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
    faultEvents = Signal(list)  # FaultEvents the detector declared in a block
    alarmEvents = Signal(list)  # AlarmEvents: the alarms' crossings in a block
    lslChanged = Signal(str)  # what streams over Lab Streaming Layer, "" when off

    def __init__(self, pipeline: Pipeline, profile_store: ProfileStore | None = None,
                 connection: Connection | None = None) -> None:
        super().__init__()
        self.pipeline = pipeline
        self.connection = connection or Connection()
        self.calibration = CalibrationState(pipeline, profile_store or ProfileStore())
        self.recording = RecordingControl(on_error=self.error.emit,
                                          on_status=self.recordingChanged.emit)
        self.health = HealthMonitor()
        self.alarms = AlarmMonitor()
        self.acquisition = Acquisition(self.connection, pipeline, self.recording,
                                       on_message=self.deviceMessage.emit, health=self.health,
                                       on_events=self.faultEvents.emit, alarms=self.alarms,
                                       on_alarms=self.alarmEvents.emit,
                                       ask_board_status=False)
        self.meter = StatusMeter()
        self.overviews = OverviewTracker()
        self._poll_timer: QTimer | None = None
        self._status_timer: QTimer | None = None
        self._reconnect_timer: QTimer | None = None
        self._lsl: LslOutlet | None = None

    @property
    def profile(self) -> CalibrationProfile | None:
        return self.calibration.profile

    # -- lifecycle (worker thread) ----------------------------------------------------------
    @Slot()
    def start(self) -> None:
        """Create the timers in the worker thread and load the compiled kernels."""
        self._poll_timer = self._timer(0, self._poll)
        self._status_timer = self._timer(STATUS_INTERVAL_MS, self._emit_status)
        self._reconnect_timer = self._timer(RECONNECT_INTERVAL_MS, self._try_reconnect)
        # Before any device streams: loaded on its first block, they cost samples (the
        # source's default filter and the fault detector, too, were loaded only then).
        warm_up_kernels(None)
        self.pipeline.filter.warm_up()

    def _timer(self, interval_ms: int, slot: Any) -> QTimer:
        timer = QTimer(self)
        timer.setInterval(interval_ms)
        timer.timeout.connect(slot)
        return timer

    def _streaming(self, on: bool) -> None:
        for timer in (self._poll_timer, self._status_timer):
            if timer is not None:
                timer.start() if on else timer.stop()

    @Slot()
    def shutdown(self) -> None:
        """Close the device and stop the timers (before the thread quits)."""
        self._close_device("")
        if self._lsl is not None:
            self.set_lsl(False)

    # -- Lab Streaming Layer ----------------------------------------------------------------
    @Slot(bool)
    def set_lsl(self, on: bool) -> None:
        """Stream the session's samples and orientation over LSL (a subscriber of the one
        acquisition session), or stop; ``lslChanged`` says what is streamed."""
        if on and self._lsl is None:
            try:
                outlet = LslOutlet(
                    lambda: None if self.connection.device is None else self.connection.device.info,
                    self.pipeline)
            except LslUnavailable as exc:
                self.error.emit(str(exc))
                self.lslChanged.emit("")
                return
            self._lsl = outlet
            self.acquisition.subscribe(outlet)
        elif not on and self._lsl is not None:
            outlet, self._lsl = self._lsl, None
            if outlet in self.acquisition.subscribers:
                self.acquisition.subscribers.remove(outlet)
            outlet.close()
        self.lslChanged.emit("" if self._lsl is None else lsl_description(self._lsl))

    # -- connection -------------------------------------------------------------------------
    @Slot(str)
    def connect_device(self, url: str) -> None:
        """Close any open device, then open ``url`` and start streaming."""
        self._close_device("")
        try:
            info = self.connection.open(url)
        except DeviceError as exc:
            self.error.emit(str(exc))
            self.disconnected.emit(str(exc))
            return
        except Exception as exc:  # a driver bug must not take the app down
            log.exception("opening %s failed", url)
            self.error.emit(f"{url}: unexpected error while opening: {exc!r}")
            self.disconnected.emit(str(exc))
            return
        device = self.connection.device
        before = self.pipeline.filter
        self.acquisition.begin(info)  # a filter that follows the source takes its default
        restored = restore_recorded_filter(device, self.pipeline)
        if restored.warning:
            self.deviceMessage.emit(2, restored.warning)
        if restored.error:
            self.error.emit(restored.error)
        if self.pipeline.filter is not before:
            self._emit_filter()
        for problem in self.calibration.load_for(info, device):
            self.error.emit(problem)
        for note in self.calibration.notes:
            self.deviceMessage.emit(1, note)
        self.calibrationChanged.emit(self.calibration.profile)
        self.tareChanged.emit(None)
        self.meter.reset(self.pipeline.counters.filter_cpu_s)
        self.overviews.reset()
        self.health.start(info)
        recorded = {} if device is None or device.recording is None else (
            device.recording.metadata)
        for note in (recorded_events_note(recorded), recorded_alarms_note(recorded)):
            if note:
                self.deviceMessage.emit(1, note)
        self._streaming(True)
        self.connected.emit(info)
        self.selfTestAvailable.emit(bool(device and device.supports_self_test))

    @Slot()
    def disconnect_device(self) -> None:
        self._close_device("")

    def _lost(self, reason: str, report: bool = True) -> None:
        """The device failed: await the board if it can come back, else end the session
        (and say why, unless ``report`` is False because the reason was told already)."""
        message = self.connection.await_board(reason, self.acquisition.last_sample_time())
        if message is None:
            if report:
                self.error.emit(reason)
            self._close_device(reason)
            return
        self._streaming(False)
        self.selfTestAvailable.emit(False)
        self.reconnecting.emit(message)
        assert self._reconnect_timer is not None
        self._reconnect_timer.start()

    def _try_reconnect(self) -> None:
        info = self.connection.try_reconnect()
        if info is None:
            return
        assert self._reconnect_timer is not None
        self._reconnect_timer.stop()
        self._streaming(True)
        self.connected.emit(info)
        device = self.connection.device
        self.selfTestAvailable.emit(bool(device and device.supports_self_test))

    def _close_device(self, reason: str) -> None:
        self.stop_recording()
        self.health.stop()
        was_open, was_waiting = self.connection.close()
        self._streaming(False)
        if self._reconnect_timer is not None:
            self._reconnect_timer.stop()
        if was_open:
            self.selfTestAvailable.emit(False)
        if was_open or was_waiting:
            self.disconnected.emit(reason)

    @Slot()
    def run_self_test(self) -> None:
        """The sensor's self-test (about a second; streaming pauses and the pause is a gap)."""
        try:
            report = self.connection.self_test()
        except DeviceIOError as exc:
            self.selfTestFinished.emit(None, str(exc))
            self._lost(str(exc), report=False)
            return
        except DeviceError as exc:
            self.selfTestFinished.emit(None, str(exc))
            return
        self.selfTestFinished.emit(report, "")

    @Slot(float, float)
    def set_simulator_target(self, roll_deg: float, pitch_deg: float) -> None:
        """Tilt an interactive simulator (ignored by devices that cannot be tilted)."""
        device = self.connection.device
        if device is None or not device.is_steerable:
            return
        try:
            device.set_target_attitude(roll_deg, pitch_deg)
        except DeviceError as exc:
            self.error.emit(str(exc))

    # -- streaming --------------------------------------------------------------------------
    def _poll(self) -> None:
        device = self.connection.device
        if device is None:
            return
        try:
            self.acquisition.step()
        except DeviceIOError as exc:
            self._lost(str(exc))
        except DeviceError as exc:
            self.error.emit(str(exc))
            self._close_device(str(exc))
        except Exception as exc:
            log.error("pipeline failure:\n%s", traceback.format_exc())
            message = f"{device.url}: processing failed ({exc!r}); the device was disconnected"
            self.error.emit(message)
            self._close_device(message)

    def _emit_status(self) -> None:
        status = stream_status(self.acquisition, self.meter, self.overviews)
        if status is not None:
            self.status.emit(status)

    @Slot()
    def reset_health(self) -> None:
        """Forget latched faults (bias, gravity) and what the detector learnt."""
        self.health.reset()

    # -- alarms -------------------------------------------------------------------------------
    @Slot(object)
    def set_alarms(self, config: AlarmConfig) -> None:
        """Use these alarms from the next block on (an alarm switched off while raised
        clears)."""
        events = self.alarms.configure(config)
        if events:
            self.alarmEvents.emit(events)

    # -- filters ----------------------------------------------------------------------------
    def _emit_filter(self) -> None:
        current = self.pipeline.filter
        self.filterChanged.emit(current.name, current.parameter_values())

    @Slot(str)
    def set_filter(self, name: str) -> None:
        try:
            self.pipeline.set_filter(name)
        except (KeyError, ValueError) as exc:
            self.error.emit(str(exc))
            return
        self._emit_filter()

    @Slot()
    def follow_source_filter(self) -> None:
        """The filter is the source's default from now on (none chosen)."""
        device = self.connection.device
        info = None if device is None else device.info
        self.pipeline.follow_source(info is not None and info.magnetometer is not None)
        self._emit_filter()

    @Slot(str, object)
    def set_filter_parameter(self, name: str, value: Any) -> None:
        try:
            self.pipeline.set_filter_parameter(name, value)
        except (KeyError, ValueError) as exc:
            self.error.emit(str(exc))
            return
        self._emit_filter()

    @Slot(list)
    def set_comparisons(self, names: list) -> None:
        """Run these filters side by side with the main one."""
        try:
            running = self.pipeline.set_comparisons([str(n) for n in names])
        except (KeyError, ValueError) as exc:
            self.error.emit(str(exc))
            running = list(self.pipeline.comparisons)
        self.comparisonsChanged.emit(running)

    # -- calibration and tare ---------------------------------------------------------------
    @Slot(object)
    def use_profile(self, profile: CalibrationProfile) -> None:
        """Apply a new profile (from the wizard or an import) and store it for the device."""
        problem = self.calibration.use(profile)
        if problem:
            self.error.emit(problem)
        self.calibrationChanged.emit(self.calibration.profile)

    @Slot()
    def use_no_calibration(self) -> None:
        """Run uncalibrated; the stored profile is kept, disabled until enabled again."""
        self.deviceMessage.emit(1, self.calibration.disable())
        self.calibrationChanged.emit(None)

    @Slot()
    def use_stored_profile(self) -> None:
        """Apply the device's stored profile again (undoes "Run uncalibrated")."""
        problem = self.calibration.enable()
        if problem:
            self.error.emit(problem)
        self.calibrationChanged.emit(self.calibration.profile)

    @Slot()
    def delete_profile(self) -> None:
        """Delete the device's stored profile (to history) and run uncalibrated."""
        self.deviceMessage.emit(1, self.calibration.delete())
        self.calibrationChanged.emit(None)

    @Slot()
    def tare(self) -> None:
        """Take the current attitude as level (relative measurement)."""
        try:
            reference = self.calibration.tare()
        except ValueError as exc:
            self.error.emit(str(exc))
            return
        self.tareChanged.emit(reference)

    @Slot(object)
    def set_field_reference(self, reference: FieldReference | None) -> None:
        """The WMM field at the user's place, for the filters' check of the field they learn."""
        self.pipeline.set_field_reference(reference)

    @Slot(object)
    def set_declination(self, declination: Declination | None) -> None:
        """The declination the window's heading uses, stored with the next recordings."""
        self.acquisition.declination = declination

    @Slot(object)
    def set_tare(self, reference: TareReference | None) -> None:
        """Use a given level reference (e.g. from the reversal procedure)."""
        self.tareChanged.emit(self.calibration.set_tare(reference))

    @Slot()
    def clear_tare(self) -> None:
        self.tareChanged.emit(self.calibration.set_tare(None))

    # -- replay -----------------------------------------------------------------------------
    @Slot(str, object)
    def replay_control(self, name: str, value: object) -> None:
        """play, pause, step, speed (0 = as fast as possible), loop, seek (s from the start),
        next_gap, next_bookmark, add_bookmark."""
        try:
            replay_command(self.connection.device, self.pipeline, name, value)
        except ReplayNotice as exc:
            self.notice.emit(str(exc))
        except (DeviceError, ValueError) as exc:
            self.error.emit(str(exc))

    # -- recording --------------------------------------------------------------------------
    @Slot(str, str)
    def start_recording(self, path: str, note: str) -> None:
        """Record the raw stream (before calibration) to ``path`` in format v1."""
        device = self.connection.device
        if device is None or device.info is None:
            self.error.emit("Connect a device before recording.")
            return
        self.stop_recording()
        try:
            status = self.acquisition.start_recording(path, note)
        except (ValueError, RecordingError) as exc:
            self.error.emit(str(exc))
            return
        self.recordingChanged.emit(status)

    @Slot()
    def stop_recording(self) -> None:
        """Finish the recording (everything queued is written and synced)."""
        closed = self.acquisition.stop_recording(background=True, on_error=self.error.emit)
        if closed is None:
            return
        status = closed.status
        self.recordingChanged.emit(None)
        if status.error:
            self.error.emit(status.error)
        if closed.fault_events:
            self.deviceMessage.emit(1, f"{len(closed.fault_events)} fault event(s) stored in "
                                       f"{status.path.name}")
        if closed.alarm_events and status.rows_written:
            self.deviceMessage.emit(1, f"{len(closed.alarm_events)} alarm crossing(s) stored in "
                                       f"{status.path.name}")
