"""The replay transport, like a media player: play/pause, step, speed, loop, seek, gaps and
bookmarks.

Shown while a ``replay://`` device is connected. Every action is a request to the worker
(the replay device lives on the worker thread); the position comes back with the stream status.
A click anywhere on the slider's groove goes there; the keys move it by 1 % and 10 %. At the
end the play button says Replay and starts again from the beginning. Bookmarks are drawn on the
slider and on the overview below it, which spans the same width, so its marks line up.

The controls sit in two rows beside the slider and the overview, so that nothing moves into a
toolbar extension on a 1280 px wide window.
"""

from __future__ import annotations

import time

from PySide6.QtCore import QEvent, QPointF, Qt, Signal
from PySide6.QtGui import (
    QColor,
    QMouseEvent,
    QPainter,
    QPaintEvent,
    QPen,
    QPolygonF,
    QResizeEvent,
    QShowEvent,
)
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QHBoxLayout,
    QLabel,
    QSizePolicy,
    QSlider,
    QStyle,
    QStyleOptionSlider,
    QToolBar,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from app.core.recording.index import Overview
from app.gui import theme
from app.gui.replay_overview import ReplayOverview

SPEEDS = (("0.1×", 0.1), ("0.25×", 0.25), ("0.5×", 0.5), ("1×", 1.0), ("2×", 2.0),
          ("5×", 5.0), ("10×", 10.0), ("max", 0.0))
SLIDER_STEPS = 1000
SEEK_SETTLE_S = 1.0
"""After a seek the slider stays where it was sent until a status reports the new position
(or this long): statuses sent before the worker took the seek would pull it back."""
PLAY_TEXT, PAUSE_TEXT, REPLAY_TEXT = "Play", "Pause", "Replay"


class SeekSlider(QSlider):
    """A horizontal slider that goes where its groove is clicked (not a page step) and draws
    bookmarks; ``clickedAt(fraction)`` on such a click (0 at the start, 1 at the end)."""

    clickedAt = Signal(float)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(Qt.Orientation.Horizontal, parent)
        self._marks: tuple[float, ...] = ()

    def set_marks(self, fractions: tuple[float, ...]) -> None:
        """Bookmarks to draw, as fractions of the range (0 ... 1)."""
        fractions = tuple(min(max(f, 0.0), 1.0) for f in fractions)
        if fractions != self._marks:
            self._marks = fractions
            self.update()

    def marks(self) -> tuple[float, ...]:
        return self._marks

    def _span(self) -> tuple[float, float, float]:
        """(x of the handle's centre at the minimum, pixels from minimum to maximum, handle
        length), as Qt maps positions to values."""
        option = QStyleOptionSlider()
        self.initStyleOption(option)
        style = self.style()
        groove = style.subControlRect(QStyle.ComplexControl.CC_Slider, option,
                                      QStyle.SubControl.SC_SliderGroove, self)
        handle = style.subControlRect(QStyle.ComplexControl.CC_Slider, option,
                                      QStyle.SubControl.SC_SliderHandle, self)
        length = handle.width()
        span = max(groove.right() - length + 1 - groove.x(), 1)
        return groove.x() + length / 2.0, float(span), float(length)

    def fraction_at(self, x: float) -> float:
        """The fraction of the range the handle's centre has at pixel ``x``."""
        start, span, _ = self._span()
        return min(max((x - start) / span, 0.0), 1.0)

    def x_of(self, fraction: float) -> float:
        """Pixel x of the handle's centre at ``fraction`` of the range."""
        start, span, _ = self._span()
        return start + fraction * span

    def handle_length(self) -> float:
        return self._span()[2]

    def mousePressEvent(self, event: QMouseEvent) -> None:
        if event.button() != Qt.MouseButton.LeftButton or not self.isEnabled():
            super().mousePressEvent(event)
            return
        option = QStyleOptionSlider()
        self.initStyleOption(option)
        hit = self.style().hitTestComplexControl(QStyle.ComplexControl.CC_Slider, option,
                                                 event.position().toPoint(), self)
        if hit == QStyle.SubControl.SC_SliderHandle:
            super().mousePressEvent(event)  # dragged: seeks when released
            return
        fraction = self.fraction_at(event.position().x())
        self.setValue(round(fraction * (self.maximum() - self.minimum())) + self.minimum())
        event.accept()
        self.clickedAt.emit(fraction)

    def paintEvent(self, event: QPaintEvent) -> None:
        super().paintEvent(event)
        if not self._marks:
            return
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        colour = QColor(theme.WARN_AMBER)
        painter.setPen(QPen(colour, 2))
        painter.setBrush(colour)
        middle = self.height() / 2.0
        for fraction in self._marks:
            x = self.x_of(fraction)
            painter.drawLine(QPointF(x, middle - 4), QPointF(x, middle + 4))
            painter.drawPolygon(QPolygonF([QPointF(x - 4, 0.0), QPointF(x + 4, 0.0),
                                           QPointF(x, 5.0)]))
        painter.end()


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
        self.play_button.setText(PAUSE_TEXT)
        self.play_button.setToolTip("Play or pause the replay")
        self.play_button.toggled.connect(self._on_play_toggled)
        self.step_button = QToolButton()
        self.step_button.setText("Step")
        self.step_button.setToolTip("Advance one block while paused")
        self.step_button.clicked.connect(lambda: self.control.emit("step", None))
        self.gap_button = QToolButton()
        self.gap_button.setText("Next gap")
        self.gap_button.setToolTip("Go to the next place where data were lost")
        self.gap_button.clicked.connect(lambda: self.control.emit("next_gap", None))
        self.bookmark_button = QToolButton()
        self.bookmark_button.setText("Next bookmark")
        self.bookmark_button.setToolTip("Go to the next bookmark (drawn on the slider)")
        self.bookmark_button.clicked.connect(lambda: self.control.emit("next_bookmark", None))
        self.mark_button = QToolButton()
        self.mark_button.setText("Add bookmark")
        self.mark_button.setToolTip("Bookmark the current position (kept while replaying)")
        self.mark_button.clicked.connect(lambda: self.control.emit("add_bookmark", None))
        self.speed_combo = QComboBox()
        for label, speed in SPEEDS:
            self.speed_combo.addItem(label, speed)
        self.speed_combo.setCurrentIndex(3)
        self.speed_combo.setToolTip("Replay speed (max: as fast as the pipeline takes it)")
        self.speed_combo.activated.connect(
            lambda _i: self.control.emit("speed", self.speed_combo.currentData())
        )
        self.loop_box = QCheckBox("Loop")
        self.loop_box.toggled.connect(lambda on: self.control.emit("loop", on))
        self.slider = SeekSlider()
        self.slider.setRange(0, SLIDER_STEPS)
        self.slider.setSingleStep(SLIDER_STEPS // 100)
        self.slider.setPageStep(SLIDER_STEPS // 10)
        self.slider.setMinimumWidth(200)
        self.slider.setToolTip("Click or drag to go there; arrow keys 1 %, Page keys 10 %")
        self.slider.sliderReleased.connect(self._on_seek)
        self.slider.clickedAt.connect(self._seek_fraction)
        self.slider.actionTriggered.connect(self._on_slider_action)
        self.position_label = QLabel("0.0 / 0.0 s")
        self.goto_spin = QDoubleSpinBox()
        self.goto_spin.setDecimals(2)
        self.goto_spin.setRange(0.0, 1e6)
        self.goto_spin.setSuffix(" s")
        self.goto_spin.setKeyboardTracking(False)
        self.goto_spin.setToolTip("Type a time from the start and press Enter to go there")
        self.goto_spin.lineEdit().returnPressed.connect(
            lambda: self._request_seek(self.goto_spin.value())
        )
        self.overview = ReplayOverview()
        self.overview.seekRequested.connect(self._request_seek)
        self.panel = self._lay_out()
        self.addWidget(self.panel)
        self._duration_s = 0.0
        self._ended = False
        self._label_duration_s = -1.0
        self._bookmarks_key: tuple[tuple[float, ...], float] = ((), 0.0)
        self._seek_target: tuple[float, float] | None = None  # (position s, until monotonic)
        self._align_overview()

    def _lay_out(self) -> QWidget:
        """Two rows of controls on the left; the slider over the overview (same width, so
        their marks line up) in the middle; the position on the right."""
        panel = QWidget()
        panel.setObjectName("replayPanel")
        outer = QHBoxLayout(panel)
        outer.setContentsMargins(4, 2, 4, 2)
        outer.setSpacing(8)
        rows = QVBoxLayout()
        rows.setSpacing(2)
        first, second = QHBoxLayout(), QHBoxLayout()
        for row in (first, second):
            row.setSpacing(4)
            rows.addLayout(row)
        for widget in (self.play_button, self.step_button, QLabel("Speed"), self.speed_combo,
                       self.loop_box):
            first.addWidget(widget)
        first.addStretch(1)
        for widget in (self.gap_button, self.bookmark_button, self.mark_button,
                       QLabel("Go to"), self.goto_spin):
            second.addWidget(widget)
        second.addStretch(1)
        outer.addLayout(rows)
        track = QVBoxLayout()
        track.setSpacing(0)
        track.addWidget(self.slider)
        track.addWidget(self.overview)
        outer.addLayout(track, 1)
        self.position_label.setAlignment(Qt.AlignmentFlag.AlignRight
                                         | Qt.AlignmentFlag.AlignVCenter)
        outer.addWidget(self.position_label)
        panel.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        return panel

    def _align_overview(self) -> None:
        """Inset the overview by half the slider's handle, so that a time is at the same x on
        both."""
        half = round(self.slider.handle_length() / 2.0)
        self.overview.getPlotItem().setContentsMargins(half, 0, half, 0)

    # -- requests ----------------------------------------------------------------------------
    def _on_play_toggled(self, playing: bool) -> None:
        self.play_button.setText(PAUSE_TEXT if playing else PLAY_TEXT)
        self._ended = False
        self.control.emit("play" if playing else "pause", None)

    def _request_seek(self, position_s: float) -> None:
        """Go to ``position_s`` (s from the start); the slider shows it at once."""
        position_s = max(0.0, float(position_s))
        self._seek_target = (position_s, time.monotonic() + SEEK_SETTLE_S)
        if self._duration_s > 0:
            self.slider.setValue(round(SLIDER_STEPS * min(position_s / self._duration_s, 1.0)))
        self.control.emit("seek", position_s)

    def _seek_fraction(self, fraction: float) -> None:
        if self._duration_s > 0:
            self._request_seek(fraction * self._duration_s)

    def _on_seek(self) -> None:
        if self._duration_s > 0:
            self._request_seek(self.slider.value() / SLIDER_STEPS * self._duration_s)

    def _on_slider_action(self, action: int) -> None:
        """A key (arrows, Page Up/Down, Home/End) moved the slider: go there."""
        if action == QSlider.SliderAction.SliderMove.value or self.slider.isSliderDown():
            return  # dragging: the release seeks
        if self._duration_s > 0:
            self._request_seek(self.slider.sliderPosition() / SLIDER_STEPS * self._duration_s)

    # -- what the worker reports -------------------------------------------------------------
    def show_position(self, position_s: float, duration_s: float, playing: bool,
                      ended: bool = False, bookmarks_s: tuple[float, ...] = ()) -> None:
        """Reflect the device's position (unless the user is dragging the slider or a seek is
        on its way), whether it plays or reached the end, and its bookmarks."""
        self._duration_s = duration_s
        self.goto_spin.setMaximum(max(duration_s, 0.0))
        if self._seek_target is not None:
            target, until = self._seek_target
            if abs(position_s - target) <= max(0.01 * duration_s, 0.05) or (
                    time.monotonic() > until):
                self._seek_target = None
        if (self._seek_target is None and not self.slider.isSliderDown()
                and duration_s > 0):
            self.slider.setValue(round(SLIDER_STEPS * position_s / duration_s))
        if duration_s != self._label_duration_s:  # as wide as its widest text: nothing moves
            self._label_duration_s = duration_s
            self.position_label.setText(f" {duration_s:.1f} / {duration_s:.1f} s ")
            self.position_label.setFixedWidth(self.position_label.sizeHint().width())
        self.position_label.setText(f" {position_s:.1f} / {duration_s:.1f} s ")
        self.overview.set_duration(duration_s)
        self.overview.show_position(position_s)
        if self.play_button.isChecked() != playing or self._ended != ended:
            self.play_button.blockSignals(True)
            self.play_button.setChecked(playing)
            self.play_button.blockSignals(False)
        self._ended = ended
        text = PAUSE_TEXT if playing else (REPLAY_TEXT if ended else PLAY_TEXT)
        if self.play_button.text() != text:
            self.play_button.setText(text)
            self.play_button.setToolTip("Play again from the start" if ended
                                        else "Play or pause the replay")
        self.show_bookmarks(bookmarks_s)

    def show_bookmarks(self, bookmarks_s: tuple[float, ...]) -> None:
        """Draw the bookmarks (s from the start) on the slider and on the overview."""
        bookmarks_s = tuple(bookmarks_s)
        duration = self._duration_s
        if (bookmarks_s, duration) == self._bookmarks_key:
            return
        self._bookmarks_key = (bookmarks_s, duration)
        self.slider.set_marks(tuple(b / duration for b in bookmarks_s) if duration > 0 else ())
        self.overview.show_bookmarks(bookmarks_s)

    @property
    def ended(self) -> bool:
        """The replay reached its end (the play button says Replay)."""
        return self._ended

    def show_overview(self, overview: Overview, gaps_s: tuple[float, ...]) -> None:
        """Draw the session's envelope (sent when the replay's index grew)."""
        self.overview.show_overview(overview, self._duration_s, gaps_s)

    def resizeEvent(self, event: QResizeEvent) -> None:
        super().resizeEvent(event)
        self._align_overview()

    def showEvent(self, event: QShowEvent) -> None:
        super().showEvent(event)
        self._fit_play_button()

    def changeEvent(self, event: QEvent) -> None:
        super().changeEvent(event)
        if event.type() in (QEvent.Type.StyleChange, QEvent.Type.FontChange):
            self._fit_play_button()

    def _fit_play_button(self) -> None:
        """As wide as its widest text (Play, Pause, Replay): a new text moves nothing."""
        button = self.play_button
        shown = button.text()
        widths = []
        for text in (PLAY_TEXT, PAUSE_TEXT, REPLAY_TEXT):
            button.setText(text)
            widths.append(button.sizeHint().width())
        button.setText(shown)
        button.setMinimumWidth(max(widths))
