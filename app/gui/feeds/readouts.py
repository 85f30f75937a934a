"""The numeric readouts' feed: the figures (at a digital level's pace), the simulator-truth
line, figures gone stale when the device is lost, and the reading to store."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from PySide6.QtWidgets import QLabel

from app.core.devices import SIMULATOR_REFERENCE, reference_title
from app.core.measurement_log import Measurement, measure
from app.core.readout import compare_to_truth, slope_from_angle
from app.gui.feeds.frame import Frame
from app.gui.feeds.screen import ScreenPresence
from app.gui.readouts import TiltReadouts


@dataclass(slots=True)
class DisplaySettings:
    """How the readouts present the angles."""

    unit: str = "deg"
    averaging_s: float = 0.5
    hold: bool = False
    readout_rate_hz: float = 10.0
    """Numeric readouts change at most this often, like a digital level's display: faster
    figures cannot be read, and every text change repaints the tiles."""


class ReadoutFeed:
    """Sets the readouts' figures and the truth line when their input changed."""

    def __init__(self, readouts: TiltReadouts, truth_label: QLabel, session,
                 settings: DisplaySettings) -> None:
        self.readouts = readouts
        self.truth_label = truth_label
        self.session = session
        self.settings = settings
        self.shown = ScreenPresence(readouts)
        self.key: tuple | None = None
        self.last_update = -np.inf
        self.shown_quat: np.ndarray | None = None
        """The quaternions behind the figures (what Hold keeps showing)."""
        self.last_live: float | None = None
        """Wall-clock time (``time.time()``) the readouts last showed new data."""
        self.stale_rows: int | None = None
        """Rows written when the device was lost (None: live)."""

    def frame(self, frame: Frame, key: tuple, averaged: Callable[[], object]) -> None:
        if key == self.key or not self.shown(frame.now):
            return
        interval = 1.0 / self.settings.readout_rate_hz
        if frame.now - self.last_update >= interval:
            self.show(averaged())
            self.key = key
            self.last_update = frame.now
            frame.drew = True
        else:
            frame.defer(self.last_update + interval)  # due shortly: the clock keeps its pace

    def show_stale(self) -> None:
        """The device was lost: the figures on show turn grey, with the time they were last
        live, until new data arrive."""
        if self.last_live is not None and self.readouts.isValid():
            # Rows already buffered are not news: only rows after these make it live again.
            self.stale_rows = self.session.pipeline.orientation.total_written
            self.readouts.setStale(self.last_live)

    def show(self, averaged) -> None:
        """The numeric readouts and the simulator-truth line (labels repaint only when their
        text changes)."""
        if averaged is None:
            return
        recent, angles = averaged
        self.shown_quat = recent["quat"]
        unit = self.settings.unit
        self.readouts.setValid(True)
        if self.stale_rows is None:
            self.last_live = time.time()
        elif self.session.pipeline.orientation.total_written > self.stale_rows:
            self.stale_rows = None
            self.last_live = time.time()
            self.readouts.setStale(None)
        self.readouts.setValues(
            float(slope_from_angle(angles.roll_deg, unit)),
            float(slope_from_angle(angles.pitch_deg, unit)),
            float(slope_from_angle(angles.tilt_deg, unit)),
            angles.direction_deg,
            unit,
        )
        self._show_truth(recent)

    def _show_truth(self, recent: dict) -> None:
        """The simulator's truth over the same averaging window as the readouts (so during
        a turn both describe the same time), the error of the shown reading, and the
        per-sample RMS error; empty without a truth."""
        tare = self.session.pipeline.level_reference
        truth = compare_to_truth(recent["quat"], recent["ref_roll"], recent["ref_pitch"],
                                 recent["incl_error"],
                                 None if tare is None else tare.quaternion)
        untared = "" if tare is None else ", not tared"
        info = self.session.device_info
        source = SIMULATOR_REFERENCE if info is None or not info.reference else info.reference
        text = "" if truth is None else (
            f"{reference_title(source)} ({self.settings.averaging_s:g} s mean{untared})  "
            f"roll {truth.roll_deg:+.2f}°  pitch {truth.pitch_deg:+.2f}°  ·  "
            f"reading error {truth.reading_error_deg:.2f}°  ·  "
            f"sample error {truth.sample_rms_deg:.2f}° RMS"
        )
        if self.truth_label.text() != text:
            self.truth_label.setText(text)
            if text:  # the whole line (it may be cut to "…") and where the reference comes from
                self.truth_label.setToolTip(f"{text}\nThe reference: {source}")

    def clear(self) -> None:
        """No data: dashes, no truth line."""
        self.key = None
        self.readouts.setValid(False)
        self.truth_label.setText("")

    def reading_quat(self) -> np.ndarray:
        """The quaternions behind the reading shown: held, or the averaging time up to now."""
        quat = self.shown_quat
        if not self.settings.hold or quat is None:
            quat = self.session.pipeline.orientation.window(self.settings.averaging_s,
                                                            ["quat"])["quat"]
        return quat

    def current_reading(self, label: str = "") -> Measurement | None:
        """The reading the readouts show (held, or over the averaging time up to now) with its
        mean and standard deviation, unit, filter, calibration and device; None without data."""
        settings, session = self.settings, self.session
        info = session.device_info
        quat = self.reading_quat()
        if info is None and not settings.hold:
            return None
        pipeline = session.pipeline
        calibration = pipeline.calibration.name
        if pipeline.level_reference is not None:
            calibration += " + tare"
        device = "" if info is None else f"{info.name} ({info.unique_id})"
        return measure(quat, settings.unit, settings.averaging_s, label=label,
                       filter_name=pipeline.filter.name, calibration=calibration,
                       device=device)
