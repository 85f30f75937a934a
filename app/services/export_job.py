"""File > Export recording's work off the GUI thread: :func:`export_recording` in a thread,
its result back as a signal (queued into the receiver's thread)."""

from __future__ import annotations

import contextlib
import threading
from pathlib import Path
from typing import Any

from PySide6.QtCore import QObject, Signal

from app.services.devices import is_replay_url
from app.services.interop_export import (
    ExportFailed,
    ExportRefused,
    ExportRequest,
    export_recording,
)


def replayed_recording(url: str | None) -> Path | None:
    """The recording a replay device URL plays (None for any other device)."""
    if not url or not is_replay_url(url):
        return None
    from drivers.replay import recording_path

    return recording_path(url)


class ExportJob(QObject):
    """Runs one export at a time in a thread: ``finished(summary)`` or ``failed(message)``
    (one line), ``warned(message)`` for each warning the recording raised."""

    finished = Signal(object)
    failed = Signal(str)
    warned = Signal(str)

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self, request: ExportRequest) -> bool:
        """Start ``request``; False (nothing started) while another export runs."""
        if self.running:
            return False
        self._thread = threading.Thread(target=self._run, args=(request,),
                                        name="recording-export", daemon=True)
        self._thread.start()
        return True

    def _run(self, request: ExportRequest) -> None:
        try:
            summary = export_recording(request, warn=lambda text: self._emit(self.warned, text))
        except (ExportRefused, ExportFailed) as exc:
            self._emit(self.failed, str(exc))
        except Exception as exc:  # a bug: the dialog must still hear that it ended
            self._emit(self.failed, f"export stopped: {type(exc).__name__}: {exc}")
        else:
            self._emit(self.finished, summary)

    @staticmethod
    def _emit(signal: Any, value: object) -> None:
        """Emit, unless the job's window was closed meanwhile (the file is written anyway)."""
        with contextlib.suppress(RuntimeError):  # the C++ object is gone
            signal.emit(value)
