"""The device panel: what is connected and how the stream is doing."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QFormLayout, QLabel, QVBoxLayout, QWidget

from app.worker import StreamStatus
from drivers.base import DeviceInfo

_FIELDS = (
    ("name", "Device"), ("url", "URL"), ("unique_id", "Unique id"), ("sensor", "Sensor"),
    ("firmware", "Firmware"), ("odr", "Data rate"), ("ranges", "Full scales"),
    ("rate", "Measured rate"), ("samples", "Samples"), ("lost", "Lost samples"),
    ("gaps", "Gaps"), ("load", "Pipeline load"),
)


class DevicePanel(QWidget):
    """A read-only form of device facts and stream counters."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        form = QFormLayout()
        layout.addLayout(form)
        layout.addStretch(1)
        self.values: dict[str, QLabel] = {}
        for key, title in _FIELDS:
            label = QLabel("—")
            label.setWordWrap(True)
            label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            self.values[key] = label
            form.addRow(title, label)

    def show_info(self, info: DeviceInfo | None) -> None:
        if info is None:
            for label in self.values.values():
                label.setText("—")
            return
        self.values["name"].setText(info.name)
        self.values["url"].setText(info.url)
        self.values["unique_id"].setText(info.unique_id)
        self.values["sensor"].setText(info.sensor)
        self.values["firmware"].setText(info.firmware or "—")
        self.values["odr"].setText(f"{info.odr_hz:.2f} Hz (nominal {info.odr_nominal_hz:g} Hz)")
        self.values["ranges"].setText(f"±{info.accel_fs_g} g, ±{info.gyro_fs_dps} °/s")

    def show_status(self, status: StreamStatus) -> None:
        self.values["rate"].setText(f"{status.measured_rate_hz:.1f} Hz")
        self.values["samples"].setText(f"{status.samples:,}")
        self.values["lost"].setText(f"{status.lost_samples:,}")
        self.values["gaps"].setText(f"{status.gaps:,}")
        self.values["load"].setText(f"{100 * status.pipeline_load:.1f} % of a core")
