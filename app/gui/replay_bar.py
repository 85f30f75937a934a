"""The replay transport: play/pause, step, speed, loop, seek and jump to gaps.

Shown while a ``replay://`` device is connected. Every action is a request to the worker
(the replay device lives on the worker thread); the position comes back with the stream status.
"""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QLabel,
    QSlider,
    QToolBar,
    QToolButton,
    QWidget,
)

from app.core.recording.index import Overview
from app.gui.replay_overview import ReplayOverview

SPEEDS = (("0.1×", 0.1), ("0.25×", 0.25), ("0.5×", 0.5), ("1×", 1.0), ("2×", 2.0),
          ("5×", 5.0), ("10×", 10.0), ("max", 0.0))
SLIDER_STEPS = 1000


class ReplayBar(QToolBar):
    """Transport controls; emits ``control(name, value)`` for the worker."""

    control = Signal(str, object)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Replay", parent)
        self.setObjectName("replayBar")
        self.setMovable(False)
        self.play_button = QToolButton()
        self.play_button.setCheckable(True)
        self.play_button.setChecked(True)
        self.play_button.setText("Pause")
        self.play_button.toggled.connect(self._on_play_toggled)
        self.addWidget(self.play_button)
        self.step_button = QToolButton()
        self.step_button.setText("Step")
        self.step_button.setToolTip("Advance one block while paused")
        self.step_button.clicked.connect(lambda: self.control.emit("step", None))
        self.addWidget(self.step_button)
        self.gap_button = QToolButton()
        self.gap_button.setText("Next gap")
        self.gap_button.clicked.connect(lambda: self.control.emit("next_gap", None))
        self.addWidget(self.gap_button)
        self.bookmark_button = QToolButton()
        self.bookmark_button.setText("Next bookmark")
        self.bookmark_button.clicked.connect(lambda: self.control.emit("next_bookmark", None))
        self.addWidget(self.bookmark_button)
        self.mark_button = QToolButton()
        self.mark_button.setText("Add bookmark")
        self.mark_button.setToolTip("Bookmark the current position (kept while replaying)")
        self.mark_button.clicked.connect(lambda: self.control.emit("add_bookmark", None))
        self.addWidget(self.mark_button)
        self.speed_combo = QComboBox()
        for label, speed in SPEEDS:
            self.speed_combo.addItem(label, speed)
        self.speed_combo.setCurrentIndex(3)
        self.speed_combo.activated.connect(
            lambda _i: self.control.emit("speed", self.speed_combo.currentData())
        )
        self.addWidget(QLabel(" Speed "))
        self.addWidget(self.speed_combo)
        self.loop_box = QCheckBox("Loop")
        self.loop_box.toggled.connect(lambda on: self.control.emit("loop", on))
        self.addWidget(self.loop_box)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setRange(0, SLIDER_STEPS)
        self.slider.setMinimumWidth(300)
        self.slider.sliderReleased.connect(self._on_seek)
        self.addWidget(self.slider)
        self.position_label = QLabel("0.0 / 0.0 s")
        self.addWidget(self.position_label)
        self.goto_spin = QDoubleSpinBox()
        self.goto_spin.setDecimals(2)
        self.goto_spin.setRange(0.0, 1e6)
        self.goto_spin.setSuffix(" s")
        self.goto_spin.setKeyboardTracking(False)
        self.goto_spin.setToolTip("Type a time from the start and press Enter to go there")
        self.goto_spin.lineEdit().returnPressed.connect(
            lambda: self.control.emit("seek", self.goto_spin.value())
        )
        self.addWidget(QLabel(" Go to "))
        self.addWidget(self.goto_spin)
        self.overview = ReplayOverview()
        self.overview.seekRequested.connect(lambda s: self.control.emit("seek", s))
        self.addWidget(self.overview)
        self._duration_s = 0.0

    def _on_play_toggled(self, playing: bool) -> None:
        self.play_button.setText("Pause" if playing else "Play")
        self.control.emit("play" if playing else "pause", None)

    def _on_seek(self) -> None:
        if self._duration_s > 0:
            self.control.emit("seek", self.slider.value() / SLIDER_STEPS * self._duration_s)

    def show_position(self, position_s: float, duration_s: float, playing: bool) -> None:
        """Reflect the device's position (unless the user is dragging the slider)."""
        self._duration_s = duration_s
        self.goto_spin.setMaximum(max(duration_s, 0.0))
        if not self.slider.isSliderDown() and duration_s > 0:
            self.slider.setValue(round(SLIDER_STEPS * position_s / duration_s))
        self.position_label.setText(f" {position_s:.1f} / {duration_s:.1f} s ")
        self.overview.set_duration(duration_s)
        self.overview.show_position(position_s)
        if self.play_button.isChecked() != playing:
            self.play_button.blockSignals(True)
            self.play_button.setChecked(playing)
            self.play_button.setText("Pause" if playing else "Play")
            self.play_button.blockSignals(False)

    def show_overview(self, overview: Overview, gaps_s: tuple[float, ...]) -> None:
        """Draw the session's envelope (sent when the replay's index grew)."""
        self.overview.show_overview(overview, self._duration_s, gaps_s)
