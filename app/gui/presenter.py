"""The live presenter: on a fixed-rate timer, pull from the ring buffers and feed the views.

This is the one place where buffered data meets widgets. The maths it needs (averaging,
unit conversion) comes from :mod:`app.core`; the widgets only receive finished numbers.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal
from PySide6.QtWidgets import QLabel

from app.core.orientation import slope_from_angle
from app.core.readout import averaged_angles
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.gui.bubble_level import BubbleLevel
from app.gui.plots import LivePlots
from app.gui.readouts import TiltReadouts
from app.worker import DeviceSession

UNIT_LABELS = {"deg": "°", "percent": "%", "mm/m": "mm/m"}


@dataclass(slots=True)
class DisplaySettings:
    """How the readouts present the angles."""

    unit: str = "deg"
    averaging_s: float = 0.5
    hold: bool = False
    frame_rate_hz: float = 30.0


class LivePresenter(QObject):
    """Refreshes the bubble level, the readouts and the plots at a fixed frame rate."""

    framesPerSecond = Signal(float)

    def __init__(
        self,
        session: DeviceSession,
        level: BubbleLevel,
        readouts: TiltReadouts,
        plots: LivePlots,
        truth_label: QLabel,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.session = session
        self.level = level
        self.readouts = readouts
        self.plots = plots
        self.truth_label = truth_label
        self.settings = DisplaySettings()
        self.plots_enabled = True
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.refresh)
        self.frames = 0
        self._fps_window = (time.monotonic(), 0)
        self._shown_total = -1

    def start(self) -> None:
        self.timer.start(round(1000.0 / self.settings.frame_rate_hz))

    def stop(self) -> None:
        self.timer.stop()

    def set_hold(self, hold: bool) -> None:
        self.settings.hold = hold
        self.readouts.setHold(hold)

    # -- the frame --------------------------------------------------------------------------
    def refresh(self) -> None:
        """Draw one frame from the newest buffered data."""
        pipeline = self.session.pipeline
        samples, orientation = pipeline.samples, pipeline.orientation
        connected = self.session.device_info is not None
        total = orientation.total_written
        if total != self._shown_total:
            self._shown_total = total
            if total == 0:
                self._show_no_data()
            else:
                self._update_readouts(orientation)
                if self.plots_enabled and self.plots.isVisible():
                    self._update_plots(samples, orientation)
        if not connected and total == 0:
            self._show_no_data()
        self._count_frame()

    def _show_no_data(self) -> None:
        self.level.setValid(False)
        self.readouts.setValid(False)
        self.truth_label.setText("")
        self.plots.clear()

    def _update_readouts(self, orientation) -> None:
        if self.settings.hold:
            return
        recent = orientation.window(
            self.settings.averaging_s,
            names=["quat", "ref_roll", "ref_pitch", "incl_error"],
        )
        angles = averaged_angles(recent["quat"])
        if angles is None:
            return
        unit = self.settings.unit
        self.level.setValid(True)
        self.level.setTilt(angles.roll_deg, angles.pitch_deg, angles.tilt_deg)
        self.readouts.setValid(True)
        self.readouts.setValues(
            float(slope_from_angle(angles.roll_deg, unit)),
            float(slope_from_angle(angles.pitch_deg, unit)),
            float(slope_from_angle(angles.tilt_deg, unit)),
            angles.direction_deg,
            UNIT_LABELS[unit],
        )
        ref_roll, ref_pitch = recent["ref_roll"][-1], recent["ref_pitch"][-1]
        if np.isfinite(ref_roll):
            self.level.setReference(float(ref_roll), float(ref_pitch))
            error = recent["incl_error"]
            rms = float(np.sqrt(np.nanmean(error**2)))
            self.truth_label.setText(
                f"Simulator truth  roll {ref_roll:+.2f}°  pitch {ref_pitch:+.2f}°  ·  "
                f"inclination error {rms:.3f}° RMS"
            )
        else:
            self.level.clearReference()
            self.truth_label.setText("")

    def _update_plots(self, samples, orientation) -> None:
        window = self.plots.window_s
        data = samples.window(window, names=["t", "accel", "gyro"])
        angles = orientation.window(window, names=["t", "roll", "pitch", "ref_roll", "ref_pitch"])
        t = data["t"]
        if len(t) == 0:
            return
        newest = t[-1]
        self.plots.set_data(
            t - newest,
            data["accel"] / STANDARD_GRAVITY_M_S2,
            np.degrees(data["gyro"]),
            angles["t"] - newest,
            {key: angles[key] for key in ("roll", "pitch", "ref_roll", "ref_pitch")},
        )

    def _count_frame(self) -> None:
        self.frames += 1
        start, frames_then = self._fps_window
        now = time.monotonic()
        if now - start >= 1.0:
            self.framesPerSecond.emit((self.frames - frames_then) / (now - start))
            self._fps_window = (now, self.frames)
