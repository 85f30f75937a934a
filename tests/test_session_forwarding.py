"""The session's forwarding is generated from the worker's declarations (one table)."""

from __future__ import annotations

from PySide6.QtCore import QMetaMethod

from app.core.filters import ONLINE_FILTERS
from app.services import session as session_module
from app.services.session import EVENTS, REQUESTS, DeviceSession
from app.services.worker import DeviceWorker


def _signatures(cls, kind) -> dict[str, bytes]:
    meta = cls.staticMetaObject
    return {bytes(meta.method(i).name()).decode(): bytes(meta.method(i).methodSignature())
            for i in range(meta.methodOffset(), meta.methodCount())
            if meta.method(i).methodType() == kind}


def test_every_worker_signal_is_a_session_signal_with_its_signature() -> None:
    worker = _signatures(DeviceWorker, QMetaMethod.MethodType.Signal)
    session = _signatures(DeviceSession.__mro__[1], QMetaMethod.MethodType.Signal)
    assert set(EVENTS) == set(worker)
    assert len(worker) >= 15
    for name, signature in worker.items():
        assert session[name] == signature


def test_each_request_has_its_worker_slots_signature() -> None:
    slots = _signatures(DeviceWorker, QMetaMethod.MethodType.Slot)
    session = _signatures(DeviceSession.__mro__[1], QMetaMethod.MethodType.Signal)
    for request, slot in REQUESTS.items():
        assert session[request].split(b"(", 1)[1] == slots[slot].split(b"(", 1)[1], request


def test_worker_events_reach_the_session_and_requests_reach_the_worker(qtbot) -> None:
    session = DeviceSession()
    try:
        with qtbot.waitSignal(session.deviceMessage, timeout=5000) as blocker:
            session.worker.deviceMessage.emit(2, "hello")
        assert blocker.args == [2, "hello"]
        name = next(iter(ONLINE_FILTERS))
        with qtbot.waitSignal(session.filterChanged, timeout=5000) as blocker:
            session.requestFilter.emit(name)  # the worker answers with the filter's values
        assert blocker.args[0] == name
    finally:
        session.shutdown()


def test_an_unknown_argument_type_is_refused_with_a_message(monkeypatch) -> None:
    monkeypatch.setattr(session_module, "_PYTHON_TYPES", {"QString": str})
    try:
        session_module._methods(DeviceWorker, QMetaMethod.MethodType.Signal)
    except TypeError as exc:
        assert "has no Python type" in str(exc)
    else:
        raise AssertionError("an unknown type was accepted")
