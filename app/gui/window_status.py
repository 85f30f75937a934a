"""The window's status bar: its fields, most important first, and what they say.

Recording, tare, calibration, device, filter and rate on the left (those that do not fit are
hidden whole, :mod:`app.gui.status_fields`); the channel lights and frames per second on the
right.
"""

from __future__ import annotations

from datetime import timedelta

from PySide6.QtWidgets import QStatusBar

from app.core.calibration_procedures import CalibrationProfile
from app.gui import theme
from app.gui.elided_label import ElidedLabel
from app.gui.health_lights import HealthLights
from app.gui.status_fields import StatusField, StatusFields


def format_age(age: timedelta) -> str:
    """A short human age: '5 min', '3 h', '12 d'."""
    seconds = max(0.0, age.total_seconds())
    if seconds < 3600:
        return f"{seconds / 60:.0f} min"
    if seconds < 86400 * 2:
        return f"{seconds / 3600:.0f} h"
    return f"{seconds / 86400:.0f} d"


class WindowStatus:
    """The status bar's fields (attributes) and the texts and colours they show."""

    def __init__(self, bar: QStatusBar) -> None:
        self.bar = bar
        self.device = StatusField("No device")
        self.rate = StatusField()
        self.filter = StatusField()
        self.fps = ElidedLabel()
        # Never cut, in whatever font the theme gives it (a width fixed in pixels at start
        # was too narrow after a theme with a larger status font: '17 fps' was elided).
        self.fps.reserve("999 fps")
        self.calibration = StatusField()
        self.calibration.setObjectName("calibrationStatus")
        self.tare = StatusField()
        self.recording = StatusField()
        self.health_lights = HealthLights()
        self.fields = StatusFields(
            bar,
            [self.recording, self.tare, self.calibration, self.device, self.filter,
             self.rate],
            [self.health_lights, self.fps],
        )
        self.profile: CalibrationProfile | None = None
        self.show_calibration(None)

    def show_fps(self, fps: float) -> None:
        self.fps.setText(f"{fps:.0f} fps")

    def show_calibration(self, profile: CalibrationProfile | None) -> None:
        """The calibration in use (amber while there is none)."""
        self.profile = profile
        if profile is None:
            self.calibration.setText("Uncalibrated")
            self.calibration.setStyleSheet(f"color: {theme.WARN_AMBER};")
            self.calibration.setToolTip("Run Calibration ▸ Calibration wizard")
            return
        self.calibration.setText(
            f"Calibrated: {profile.calibration.name} ({format_age(profile.age())} old)"
        )
        self.calibration.setStyleSheet(f"color: {theme.OK_GREEN};")
        temperature = (
            "" if profile.temperature_degc is None else f" at {profile.temperature_degc:.1f} °C"
        )
        self.calibration.setToolTip(
            f"{profile.method} profile made {profile.created_utc}{temperature}"
        )

    def show_tare(self, reference) -> None:
        """The tare in use (a TareReference), or none."""
        if reference is None:
            self.tare.setText("")
            return
        angles = reference.reference_angles
        self.tare.setText(
            f"TARE at roll {float(angles.roll_deg):+.2f}°, pitch {float(angles.pitch_deg):+.2f}°"
        )
        self.tare.setStyleSheet(f"color: {theme.ACCENT}; font-weight: bold;")

    def show_recording(self, status) -> None:
        """A recording's WriterStatus, or None when there is none."""
        if status is None:
            self.recording.setText("")
            return
        self.recording.setText(
            f"● REC {status.path.name}  {status.duration_s:.0f} s, {status.rows_written:,} rows"
            if status.state == "recording" else f"Recording {status.state}"
        )
        self.recording.setStyleSheet(f"color: {theme.ALARM_RED}; font-weight: bold;")

    def show_disconnected(self) -> None:
        self.device.setText("No device")
        self.rate.setText("")

    def restyle(self) -> None:
        """Colours set on single fields follow the theme."""
        self.show_calibration(self.profile)
        self.tare.setStyleSheet(f"color: {theme.ACCENT}; font-weight: bold;")
        self.recording.setStyleSheet(f"color: {theme.ALARM_RED}; font-weight: bold;")
