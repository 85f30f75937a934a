"""The device panel: what is connected and how the stream is doing."""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QFormLayout, QGroupBox, QLabel, QPushButton, QVBoxLayout, QWidget

from app.core.devices import BoardStatus, DeviceInfo
from app.core.self_test import SelfTestReport
from app.gui import theme
from app.gui.elided_label import ElidedLabel
from app.services.stream_status import StreamStatus

SELF_TEST_UNAVAILABLE = ("The sensor's self-test needs the NUCLEO firmware or a register-level "
                         "LSM6DSOX (lsm6dsox://).")

_FIELDS = (
    ("name", "Device"), ("url", "URL"), ("unique_id", "Unique id"), ("sensor", "Sensor"),
    ("firmware", "Firmware"), ("odr", "Data rate"), ("ranges", "Full scales"),
    ("rate", "Measured rate"), ("samples", "Samples"), ("lost", "Lost samples"),
    ("gaps", "Gaps"), ("load", "Pipeline load"),
)
_BOARD_FIELDS = (("reset_cause", "Started by"), ("uptime", "Uptime"),
                 *((name, BoardStatus.TITLES[name]) for name in BoardStatus.COUNTERS))
_PROBLEM_COUNTERS = ("uart_tx_dropped_bytes", "uart_rx_errors", "i2c_recoveries",
                     "fifo_overruns", "watchdog_resets")
"""Shown in red when not 0 (I2C errors are not: the probe of an empty address counts too)."""
_LIVE_FIELDS = frozenset({"rate", "samples", "lost", "gaps", "load", "uptime",
                          *BoardStatus.COUNTERS})
"""Fields rewritten with every status (a few times a second)."""


class DevicePanel(QWidget):
    """A read-only form of device facts and stream counters, and the sensor's self-test."""

    selfTestRequested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        form = QFormLayout()
        layout.addLayout(form)
        self.self_test_button = QPushButton("Run sensor self-test")
        self.self_test_button.setToolTip(
            "ST's self-test: a known force on the accelerometer and the gyroscope, and their "
            "output change checked against the datasheet. Keep the sensor still; streaming "
            "pauses for about a second.")
        self.self_test_button.setEnabled(False)
        self.self_test_button.clicked.connect(self._request_self_test)
        self.self_test_result = QLabel(SELF_TEST_UNAVAILABLE)
        self.self_test_result.setWordWrap(True)
        self.self_test_result.setTextInteractionFlags(
            Qt.TextInteractionFlag.TextSelectableByMouse)
        self.board_box = QGroupBox("Board health (counters since power-on)")
        self.board_box.setToolTip(
            "What the board itself counts (NUCLEO firmware STATUS, once a second while "
            "streaming). A rise is also reported in Messages, with its reason.")
        board_form = QFormLayout(self.board_box)
        board_form.setContentsMargins(6, 4, 6, 4)
        board_form.setVerticalSpacing(1)
        self.board_box.setVisible(False)
        layout.addWidget(self.board_box)
        layout.addWidget(self.self_test_button)
        layout.addWidget(self.self_test_result)
        layout.addStretch(1)
        self.values: dict[str, QLabel] = {}
        for key, title in _FIELDS:
            form.addRow(title, self._value_label(self.values, key))
        self.board_values: dict[str, QLabel] = {}
        for key, title in _BOARD_FIELDS:
            board_form.addRow(title, self._value_label(self.board_values, key))

    @staticmethod
    def _value_label(into: dict[str, QLabel], key: str) -> QLabel:
        if key in _LIVE_FIELDS:
            # Rewritten with every status: a label that repaints without a relayout.
            label: QLabel = ElidedLabel("—")
        else:
            label = QLabel("—")
            label.setWordWrap(True)
            label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        into[key] = label
        return label

    def show_info(self, info: DeviceInfo | None) -> None:
        self.board_box.setVisible(False)  # until the (new) device sends its counters
        if info is None:
            for label in self.values.values():
                label.setText("—")
            return
        self.values["name"].setText(info.name)
        self.values["url"].setText(info.url)
        self.values["unique_id"].setText(info.unique_id)
        self.values["sensor"].setText(info.sensor)
        self.values["firmware"].setText(info.firmware or "—")
        self.values["odr"].setText(f"{info.odr_hz:.2f} Hz (\"{info.odr_nominal_hz:g} Hz\" setting)")
        self.values["ranges"].setText(f"±{info.accel_fs_g} g, ±{info.gyro_fs_dps} °/s")

    def set_self_test_available(self, available: bool) -> None:
        self.self_test_button.setEnabled(available)
        self.self_test_result.setText("" if available else SELF_TEST_UNAVAILABLE)
        self.self_test_result.setStyleSheet("")

    def _request_self_test(self) -> None:
        self.self_test_button.setEnabled(False)
        self.self_test_result.setStyleSheet("")
        self.self_test_result.setText("Self-test running: keep the sensor still…")
        self.selfTestRequested.emit()

    def show_self_test(self, report: SelfTestReport | None, error: str) -> None:
        """The outcome (``report``), or why there is none (``error``)."""
        self.self_test_button.setEnabled(True)
        text = "\n".join(report.lines()) if report is not None else f"Self-test not run: {error}"
        good = report is not None and report.passed
        self.self_test_result.setText(text)
        self.self_test_result.setStyleSheet(
            f"color: {theme.OK_GREEN if good else theme.ALARM_RED};")

    def show_status(self, status: StreamStatus) -> None:
        self.values["rate"].setText(f"{status.measured_rate_hz:.1f} Hz")
        self.values["samples"].setText(f"{status.samples:,}")
        self.values["lost"].setText(f"{status.lost_samples:,}")
        self.values["gaps"].setText(f"{status.gaps:,}")
        self.values["load"].setText(f"{100 * status.pipeline_load:.1f} % of a core")
        if status.board is not None:
            self.show_board(status.board)

    def show_board(self, board: BoardStatus) -> None:
        """The board's counters (from its latest STATUS); problems that happened in red."""
        self.board_box.setVisible(True)
        values = self.board_values
        values["reset_cause"].setText(board.reset_cause
                                      + (", internal oscillator" if board.clock_fallback else ""))
        minutes, seconds = divmod(int(board.uptime_s), 60)
        hours, minutes = divmod(minutes, 60)
        values["uptime"].setText(f"{hours}:{minutes:02d}:{seconds:02d}")
        for name in BoardStatus.COUNTERS:
            value = getattr(board, name)
            values[name].setText(f"{value:,}")
            bad = name in _PROBLEM_COUNTERS and value > 0
            style = f"color: {theme.ALARM_RED};" if bad else ""
            if values[name].styleSheet() != style:  # a new stylesheet re-polishes the label
                values[name].setStyleSheet(style)
