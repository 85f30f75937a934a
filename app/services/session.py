"""The GUI-side handle on a device session: starts the worker thread and forwards requests.

Views hold a :class:`DeviceSession`; they never touch the worker, the device or a driver.
"""

from __future__ import annotations

from PySide6.QtCore import QMetaObject, QObject, Qt, QThread, Signal

from app.core.calibration_procedures import ProfileStore
from app.core.devices import DeviceInfo
from app.core.pipeline import Pipeline
from app.services.worker import DeviceWorker


class DeviceSession(QObject):
    """The GUI-side handle: starts the worker thread and forwards requests to it.

    Every request is a queued signal, so the GUI thread never blocks on the device. The
    worker's events are re-emitted by the session's own signals in the GUI thread; connect
    to those, never to the worker's.
    """

    connected = Signal(object)  # DeviceInfo
    disconnected = Signal(str)
    error = Signal(str)
    notice = Signal(str)  # information (not an error) for the user
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
    faultEvents = Signal(list)  # FaultEvents, as the detector declares them
    alarmEvents = Signal(list)  # AlarmEvents: the alarms' crossings

    requestConnect = Signal(str)
    requestDisconnect = Signal()
    requestFilter = Signal(str)
    requestFilterParameter = Signal(str, object)
    requestSimulatorTarget = Signal(float, float)
    requestComparisons = Signal(list)
    requestProfile = Signal(object)  # CalibrationProfile to apply and store
    requestNoCalibration = Signal()  # run uncalibrated, remembered for the device
    requestStoredProfile = Signal()  # apply the device's stored profile again
    requestDeleteProfile = Signal()  # delete the device's stored profile (to history)
    requestTare = Signal()
    requestClearTare = Signal()
    requestTareReference = Signal(object)  # TareReference
    requestStartRecording = Signal(str, str)  # path, note
    requestStopRecording = Signal()
    requestReplayControl = Signal(str, object)
    requestSelfTest = Signal()
    requestHealthReset = Signal()
    requestAlarms = Signal(object)  # AlarmConfig

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
        self.requestStoredProfile.connect(self.worker.use_stored_profile)
        self.requestDeleteProfile.connect(self.worker.delete_profile)
        self.requestTare.connect(self.worker.tare)
        self.requestClearTare.connect(self.worker.clear_tare)
        self.requestTareReference.connect(self.worker.set_tare)
        self.requestStartRecording.connect(self.worker.start_recording)
        self.requestStopRecording.connect(self.worker.stop_recording)
        self.requestReplayControl.connect(self.worker.replay_control)
        self.requestSelfTest.connect(self.worker.run_self_test)
        self.requestHealthReset.connect(self.worker.reset_health)
        self.requestAlarms.connect(self.worker.set_alarms)
        self.device_info: DeviceInfo | None = None
        # Queued into the GUI thread (this object lives there).
        self.worker.connected.connect(self.connected)
        self.worker.disconnected.connect(self.disconnected)
        self.worker.error.connect(self.error)
        self.worker.notice.connect(self.notice)
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
        self.worker.faultEvents.connect(self.faultEvents)
        self.worker.alarmEvents.connect(self.alarmEvents)
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
