"""The display's frame clock: one tick per screen refresh while there is something to draw.

Qt Widgets have no vsync callback, so the clock is a precise timer at the refresh rate of the
screen the window is on (``QScreen.refreshRate``), followed when the window moves to another
screen or the screen's rate changes. Whoever listens says after each tick whether it drew
anything (:meth:`FrameClock.report`); after ``idle_ticks`` ticks without work in a row the
clock rests, ticking only every ``rest_interval_ms`` to notice new data, and is back at the
screen rate on the first tick that does work again.
"""

from __future__ import annotations

import math

from PySide6.QtCore import QEvent, QObject, Qt, QTimer, Signal
from PySide6.QtGui import QGuiApplication, QScreen
from PySide6.QtWidgets import QWidget

FALLBACK_REFRESH_HZ = 60.0
"""Used when the platform reports no (or a nonsensical) refresh rate."""
IDLE_TICKS = 30
"""Ticks without work (half a second at 60 Hz) before the clock rests."""
REST_INTERVAL_MS = 100
"""How often a resting clock looks for new data."""


def frame_interval_ms(refresh_hz: float) -> int:
    """Timer interval for a screen refreshing at ``refresh_hz``: never slower than the screen
    (16 ms at 60 Hz, 6 ms at 144 Hz); the fallback rate when ``refresh_hz`` is unusable."""
    if not math.isfinite(refresh_hz) or not 1.0 <= refresh_hz <= 1000.0:
        refresh_hz = FALLBACK_REFRESH_HZ
    return max(1, math.floor(1000.0 / refresh_hz))


class FrameClock(QObject):
    """Emits ``tick`` at the refresh rate of ``widget``'s screen, or rests when idle."""

    tick = Signal()
    rateChanged = Signal(float)

    def __init__(
        self,
        widget: QWidget,
        idle_ticks: int = IDLE_TICKS,
        rest_interval_ms: int = REST_INTERVAL_MS,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.widget = widget
        self.idle_ticks = idle_ticks
        self.rest_interval_ms = rest_interval_ms
        self._idle = 0
        self._screen: QScreen | None = None
        self._followed_window = None
        self.refresh_hz = FALLBACK_REFRESH_HZ
        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.TimerType.PreciseTimer)
        self.timer.timeout.connect(self.tick)
        self.widget.installEventFilter(self)
        self._follow_screen()

    # -- control ------------------------------------------------------------------------------
    def start(self) -> None:
        self._idle = 0
        self.timer.start(self.interval_ms)

    def stop(self) -> None:
        self.timer.stop()

    @property
    def interval_ms(self) -> int:
        """The timer interval at the screen rate."""
        return frame_interval_ms(self.refresh_hz)

    @property
    def resting(self) -> bool:
        return self.timer.isActive() and self.timer.interval() != self.interval_ms

    def report(self, busy: bool) -> None:
        """After a tick: whether it drew (or still has work pending)."""
        if busy:
            self._idle = 0
            if self.timer.isActive() and self.timer.interval() != self.interval_ms:
                self.timer.setInterval(self.interval_ms)
            return
        self._idle += 1
        if self._idle >= self.idle_ticks and self.timer.isActive():
            self.timer.setInterval(max(self.rest_interval_ms, self.interval_ms))

    def wake(self) -> None:
        """Back to the screen rate now (e.g. a setting changed what is shown)."""
        self.report(True)

    # -- following the screen -------------------------------------------------------------------
    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        if watched is self.widget and event.type() == QEvent.Type.Show:
            self._follow_screen()
        return False

    def _follow_screen(self) -> None:
        handle = self.widget.window().windowHandle()
        if handle is not None and handle is not self._followed_window:
            self._followed_window = handle
            handle.screenChanged.connect(self._use_screen)
        screen = handle.screen() if handle is not None else None
        self._use_screen(screen or self.widget.screen() or QGuiApplication.primaryScreen())

    def _use_screen(self, screen: QScreen | None) -> None:
        if screen is not self._screen:
            if self._screen is not None:
                self._screen.refreshRateChanged.disconnect(self._set_rate)
            self._screen = screen
            if screen is not None:
                screen.refreshRateChanged.connect(self._set_rate)
        self._set_rate(screen.refreshRate() if screen is not None else FALLBACK_REFRESH_HZ)

    def _set_rate(self, refresh_hz: float) -> None:
        usable = math.isfinite(refresh_hz) and 1.0 <= refresh_hz <= 1000.0
        rate = float(refresh_hz) if usable else FALLBACK_REFRESH_HZ
        if rate == self.refresh_hz:
            return
        self.refresh_hz = rate
        if self.timer.isActive() and not self._idle >= self.idle_ticks:
            self.timer.setInterval(self.interval_ms)
        self.rateChanged.emit(rate)
