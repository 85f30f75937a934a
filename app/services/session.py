"""The GUI-side handle on a device session: starts the worker thread and forwards requests.

Views hold a :class:`DeviceSession`; they never touch the worker, the device or a driver.

The forwarding is generated, not copied by hand: every signal :class:`DeviceWorker`
declares is re-declared on the session under the same name and signature (read from the
worker's Qt meta-object) and forwarded, and each request signal in :data:`REQUESTS` is
declared with the signature of the worker slot it feeds. A signal added to the worker is
forwarded without touching this file; a request needs one line in :data:`REQUESTS`.
"""

from __future__ import annotations

from PySide6.QtCore import QMetaMethod, QMetaObject, QObject, Qt, QThread, Signal

from app.core.calibration_procedures import ProfileStore
from app.core.devices import DeviceInfo
from app.core.pipeline import Pipeline
from app.services.worker import DeviceWorker

REQUESTS: dict[str, str] = {
    "requestConnect": "connect_device",  # url
    "requestDisconnect": "disconnect_device",
    "requestFilter": "set_filter",  # name
    "requestSourceFilter": "follow_source_filter",  # the source's default filter from now on
    "requestFilterParameter": "set_filter_parameter",  # name, value
    "requestSimulatorTarget": "set_simulator_target",  # roll, pitch (degrees)
    "requestComparisons": "set_comparisons",  # filter names
    "requestProfile": "use_profile",  # CalibrationProfile to apply and store
    "requestNoCalibration": "use_no_calibration",  # run uncalibrated, remembered
    "requestStoredProfile": "use_stored_profile",  # the device's stored profile again
    "requestDeleteProfile": "delete_profile",  # the stored profile to history
    "requestTare": "tare",
    "requestClearTare": "clear_tare",
    "requestTareReference": "set_tare",  # TareReference
    "requestStartRecording": "start_recording",  # path, note
    "requestStopRecording": "stop_recording",
    "requestReplayControl": "replay_control",  # name, value
    "requestSelfTest": "run_self_test",
    "requestHealthReset": "reset_health",
    "requestAlarms": "set_alarms",  # AlarmConfig
    "requestLsl": "set_lsl",  # on: stream over Lab Streaming Layer
    "requestDeclination": "set_declination",  # Declination or None
    "requestFieldReference": "set_field_reference",  # FieldReference (WMM here) or None
}
"""The session's request signals and the worker slots they are queued to (GUI -> worker)."""

_PYTHON_TYPES: dict[str, type] = {
    "PyObject": object, "QString": str, "int": int, "double": float, "bool": bool,
    "QVariantList": list, "QVariantMap": dict,
}
"""Qt's names of the argument types that the worker's signals and slots use."""


def _methods(cls: type[QObject], kind: QMetaMethod.MethodType) -> dict[str, tuple[type, ...]]:
    """``cls``'s own signals or slots (not QObject's): name -> argument types."""
    meta = cls.staticMetaObject
    found: dict[str, tuple[type, ...]] = {}
    for index in range(meta.methodOffset(), meta.methodCount()):
        method = meta.method(index)
        if method.methodType() != kind:
            continue
        names = [bytes(name).decode() for name in method.parameterTypes()]
        unknown = [name for name in names if name not in _PYTHON_TYPES]
        if unknown:
            raise TypeError(f"{cls.__name__}.{bytes(method.name()).decode()}: argument type "
                            f"{unknown[0]} has no Python type in session._PYTHON_TYPES")
        found[bytes(method.name()).decode()] = tuple(_PYTHON_TYPES[name] for name in names)
    return found


EVENTS: dict[str, tuple[type, ...]] = _methods(DeviceWorker, QMetaMethod.MethodType.Signal)
"""The worker's signals (worker -> GUI), each forwarded under its own name."""
_SLOTS = _methods(DeviceWorker, QMetaMethod.MethodType.Slot)
_missing = sorted(slot for slot in REQUESTS.values() if slot not in _SLOTS)
if _missing:
    raise TypeError(f"DeviceWorker has no slot {', '.join(_missing)} (session.REQUESTS)")

_SessionSignals = type("_SessionSignals", (QObject,), {
    **{name: Signal(*types) for name, types in EVENTS.items()},
    **{request: Signal(*_SLOTS[slot]) for request, slot in REQUESTS.items()},
})


class DeviceSession(_SessionSignals):  # type: ignore[misc, valid-type]
    """The GUI-side handle: starts the worker thread and forwards requests to it.

    Every request is a queued signal, so the GUI thread never blocks on the device. The
    worker's events (:data:`EVENTS`: ``connected``, ``status``, ``error``, ...) are re-emitted
    by the session's own signals in the GUI thread; connect to those, never to the worker's.
    """

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
        for request, slot in REQUESTS.items():
            getattr(self, request).connect(getattr(self.worker, slot))
        self.device_info: DeviceInfo | None = None
        for event in EVENTS:  # queued into the GUI thread (this object lives there)
            getattr(self.worker, event).connect(getattr(self, event))
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
