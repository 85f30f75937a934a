"""The Measure panel: repeatability statistics and the reversal procedure.

Both are fed from the orientation buffer (the angles the instrument shows) through a
:class:`~app.core.ring_follower.RingFollower`; the statistics and the reversal maths live in
:mod:`app.core.calibration_procedures`.
"""

from __future__ import annotations

from PySide6.QtCore import QTimer, Signal
from PySide6.QtWidgets import (
    QDoubleSpinBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.core.calibration_procedures import (
    ReversalResult,
    StaticStatistics,
    reversal_from_angles,
)
from app.core.ring_follower import RingFollower
from app.services.session import DeviceSession

REVERSAL_AVERAGE_S = 3.0
ANGLE_COLUMNS = ["t", "roll", "pitch", "tilt"]


class MeasurePanel(QWidget):
    """Static statistics over a chosen duration, and the two-position reversal."""

    tareRequested = Signal(object)  # TareReference that removes the instrument's offset

    def __init__(self, session: DeviceSession, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        layout = QVBoxLayout(self)

        stats_box = QGroupBox("Static statistics (repeatability)")
        stats_layout = QVBoxLayout(stats_box)
        row = QHBoxLayout()
        self.duration = QDoubleSpinBox()
        self.duration.setRange(1.0, 3600.0)
        self.duration.setValue(20.0)
        self.duration.setSuffix(" s")
        self.duration.setToolTip("20 s at 100 Hz: the 2 000 samples of the measuring-arm paper")
        self.stats_button = QPushButton("Start")
        self.stats_button.clicked.connect(self.start_statistics)
        row.addWidget(QLabel("Duration"))
        row.addWidget(self.duration)
        row.addWidget(self.stats_button)
        stats_layout.addLayout(row)
        self.stats_progress = QProgressBar()
        self.stats_progress.setRange(0, 1000)
        stats_layout.addWidget(self.stats_progress)
        self.stats_table = QTableWidget(3, 6)
        self.stats_table.setHorizontalHeaderLabels(["", "Mean", "Std", "Min", "Max", "Spread"])
        self.stats_table.verticalHeader().setVisible(False)
        self.stats_table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.stats_table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        for r, name in enumerate(("Roll", "Pitch", "Tilt")):
            self.stats_table.setItem(r, 0, QTableWidgetItem(name))
        self.stats_table.setMaximumHeight(120)
        stats_layout.addWidget(self.stats_table)
        self.stats_note = QLabel("Degrees, after the filter and any tare.")
        self.stats_note.setObjectName("dimLabel")
        stats_layout.addWidget(self.stats_note)
        layout.addWidget(stats_box)

        reversal_box = QGroupBox("Reversal: surface slope and instrument offset")
        form = QFormLayout(reversal_box)
        explanation = QLabel(
            "Measure, turn the instrument 180° about the vertical on the same spot, measure "
            "again. The mean is the instrument's own offset, the half-difference the surface's "
            "slope."
        )
        explanation.setWordWrap(True)
        form.addRow(explanation)
        self.first_button = QPushButton("Measure position 1")
        self.first_button.clicked.connect(lambda: self._start_reversal(0))
        self.first_label = QLabel("—")
        form.addRow(self.first_button, self.first_label)
        self.second_button = QPushButton("Measure position 2")
        self.second_button.clicked.connect(lambda: self._start_reversal(1))
        self.second_button.setEnabled(False)
        self.second_label = QLabel("—")
        form.addRow(self.second_button, self.second_label)
        self.reversal_label = QLabel("")
        self.reversal_label.setWordWrap(True)
        form.addRow(self.reversal_label)
        self.tare_button = QPushButton("Use as level reference")
        self.tare_button.setToolTip("Tare so that the surface's normal reads level")
        self.tare_button.setEnabled(False)
        self.tare_button.clicked.connect(self._tare_from_reversal)
        form.addRow(self.tare_button)
        layout.addWidget(reversal_box)
        layout.addStretch(1)

        self._statistics: StaticStatistics | None = None
        self._reversal_step: int | None = None
        self._reversal_stats: StaticStatistics | None = None
        self._positions: list[tuple[float, float]] = []
        self.reversal: ReversalResult | None = None
        self._follower: RingFollower | None = None
        self.timer = QTimer(self)
        self.timer.setInterval(200)
        self.timer.timeout.connect(self._feed)

    # -- statistics -------------------------------------------------------------------------
    def start_statistics(self) -> None:
        """Start (or restart) collecting statistics over the chosen duration."""
        self._statistics = StaticStatistics(self.duration.value())
        self.stats_progress.setValue(0)
        self.stats_button.setText("Restart")
        self._ensure_running()

    def _start_reversal(self, step: int) -> None:
        self._reversal_step = step
        self._reversal_stats = StaticStatistics(REVERSAL_AVERAGE_S)
        label = self.first_label if step == 0 else self.second_label
        label.setText(f"measuring for {REVERSAL_AVERAGE_S:g} s — keep still…")
        if step == 0:
            self._positions = []
            self.reversal = None
            self.second_button.setEnabled(False)
            self.tare_button.setEnabled(False)
            self.second_label.setText("—")
            self.reversal_label.setText("")
        self._ensure_running()

    def _ensure_running(self) -> None:
        if not self.timer.isActive():
            # Measure from now on: rows that arrived while idle are not part of it.
            self._follower = RingFollower(lambda: self.session.pipeline.orientation, ANGLE_COLUMNS)
            self.timer.start()

    def _feed(self) -> None:
        rows = self._follower.next_rows() if self._follower else None
        if rows is not None:
            args = (rows["t"], rows["roll"], rows["pitch"], rows["tilt"])
            if self._statistics is not None and not self._statistics.is_complete:
                self._statistics.update(*args)
                self._show_statistics()
            if self._reversal_stats is not None and self._reversal_stats.update(*args):
                self._finish_reversal_step()
        busy = (self._statistics is not None and not self._statistics.is_complete) or (
            self._reversal_stats is not None
        )
        if not busy:
            self.timer.stop()

    def _show_statistics(self) -> None:
        statistics = self._statistics
        if statistics is None or statistics.samples == 0:
            return
        self.stats_progress.setValue(round(1000 * statistics.progress))
        result = statistics.result()
        for r, angle in enumerate((result.roll, result.pitch, result.tilt)):
            values = (angle.mean, angle.std, angle.minimum, angle.maximum, angle.spread)
            for c, value in enumerate(values, start=1):
                self.stats_table.setItem(r, c, QTableWidgetItem(f"{value:+.4f}"))
        self.stats_note.setText(
            f"{result.samples:,} samples over {result.duration_s:.1f} s; degrees, after the "
            "filter and any tare."
        )

    def _finish_reversal_step(self) -> None:
        result = self._reversal_stats.result()
        self._reversal_stats = None
        reading = (result.roll.mean, result.pitch.mean)
        text = f"roll {reading[0]:+.3f}°, pitch {reading[1]:+.3f}°"
        if self._reversal_step == 0:
            self._positions = [reading]
            self.first_label.setText(text)
            self.second_button.setEnabled(True)
            return
        self._positions = [*self._positions[:1], reading]
        self.second_label.setText(text)
        (roll1, pitch1), (roll2, pitch2) = self._positions
        try:
            self.reversal = reversal_from_angles(roll1, pitch1, roll2, pitch2)
        except ValueError as exc:
            self.reversal_label.setText(f"Not possible: {exc}")
            return
        r = self.reversal
        self.reversal_label.setText(
            f"<b>Instrument offset</b> roll {r.offset_roll_deg:+.3f}°, pitch "
            f"{r.offset_pitch_deg:+.3f}°<br><b>Surface slope</b> roll {r.slope_roll_deg:+.3f}°,"
            f" pitch {r.slope_pitch_deg:+.3f}° (total {r.slope_deg:.3f}°, in the axes of "
            "position 1)"
        )
        self.tare_button.setEnabled(True)

    def _tare_from_reversal(self) -> None:
        if self.reversal is not None:
            self.tareRequested.emit(self.reversal.tare)

    def stop(self) -> None:
        self.timer.stop()
