"""The alarms (their dock, the red readouts and the alarm banner) and the measurement log
(its dock; Space stores the reading)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication, QWidget

from app.core.alarms import READOUT_OF, AlarmConfig, parse_alarm
from app.core.measurement_log import MeasurementLog
from app.gui.alarm_panel import AlarmPanel
from app.gui.measurement_log_panel import MeasurementLogPanel
from app.services.stream_status import StreamStatus

MainWindow = Any
"""The window this part works for (not imported: the parts sit below
:mod:`app.gui.main_window`, which assembles them)."""


class AlarmsAndLog:
    """Makes the Alarms and Measurement log panels; after :meth:`start`, shows the alarms'
    state and events."""

    def __init__(self, window: MainWindow, log_path: Path, alarms_parent: QWidget | None = None,
                 log_parent: QWidget | None = None) -> None:
        self.window = window
        self.shown: tuple[tuple[str, str], ...] = ()
        self.alarm_panel = AlarmPanel(alarms_parent)
        self.alarm_panel.alarmsChanged.connect(self.apply)
        log, problem = MeasurementLog.load(log_path)
        self.log_panel = MeasurementLogPanel(
            log, lambda label: window.presenter.current_reading(label), log_parent)
        self.log_panel.problem.connect(window.show_error)
        if problem:
            QTimer.singleShot(0, lambda: window.show_error(problem))

    def start(self, start_alarms: AlarmConfig | None) -> None:
        """Follow the session, and use ``start_alarms`` (``--alarm``), else the remembered
        alarms, else the panel's."""
        session = self.window.session
        session.alarmEvents.connect(self._on_events)
        session.status.connect(self._on_status)
        session.disconnected.connect(lambda _reason: self.show(()))
        remembered = self.window.sections.register(
            "alarms", lambda: self.alarm_panel.config().to_dict(),
            lambda stored: self.apply(AlarmConfig.from_dict(stored)))
        if start_alarms is not None:  # inclinometer --alarm SPEC ...
            self.apply(start_alarms)
        elif not remembered:
            self.apply(self.alarm_panel.config())

    def apply(self, config: AlarmConfig) -> None:
        """Use these alarms (the worker evaluates them) and show them in the panel."""
        if config != self.alarm_panel.config():
            self.alarm_panel.set_config(config)
        self.window.session.requestAlarms.emit(config)

    def _on_events(self, events: list) -> None:
        for event in events:
            self.window.log(event.message())
        if self.alarm_panel.config().sound and any(e.raised for e in events):
            QApplication.beep()

    def _on_status(self, status: StreamStatus) -> None:
        self.show(status.alarms)
        if status.alarm_marks_s is not None:
            self.window.replay_bar.overview.show_alarm_marks(status.alarm_marks_s)

    def show(self, alarms: tuple[tuple[str, str], ...]) -> None:
        """Readouts and bubble red, and the banner, while any alarm is raised."""
        if alarms == self.shown:
            return
        self.shown = alarms
        window = self.window
        quantities = {quantity for quantity, _spec in alarms}
        window.readouts.setAlarm(READOUT_OF[q] for q in quantities)
        window.compass.tile.setState("alarm", "heading" in quantities)
        window.level.setAlarm(any(q != "heading" for q in quantities))
        self.alarm_panel.show_active(quantities)
        if alarms:
            listed = " · ".join(parse_alarm(spec).describe() for _q, spec in alarms)
            window.alarm_banner.show_message(f"<b>ALARM</b>&nbsp;&nbsp;{listed}")
        else:
            window.alarm_banner.hide()
