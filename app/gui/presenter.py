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

from app.core.calibration_procedures import StaticStatistics
from app.core.comparison import summarize_errors
from app.core.decimation import IncrementalMinMax, connect_mask, decimation_factor
from app.core.filters import FILTERS
from app.core.measurement_log import Measurement, measure
from app.core.readout import SLOPE_UNITS, averaged_angles, slope_from_angle
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.gui.bubble_level import BubbleLevel
from app.gui.filter_panel import FilterPanel
from app.gui.plots import LivePlots
from app.gui.readouts import TiltReadouts
from app.services.session import DeviceSession

ANGLE_TRACES = ["roll", "pitch", "ref_roll", "ref_pitch"]
ERROR_TABLE_INTERVAL_S = 0.5
UNIT_LABELS = {key: unit.suffix or "1:n" for key, unit in SLOPE_UNITS.items()}


@dataclass(slots=True)
class DisplaySettings:
    """How the readouts present the angles."""

    unit: str = "deg"
    averaging_s: float = 0.5
    hold: bool = False
    frame_rate_hz: float = 30.0
    readout_rate_hz: float = 10.0
    """Numeric readouts change at most this often, like a digital level's display: faster
    figures cannot be read, and every text change repaints the tiles."""


class LivePresenter(QObject):
    """Refreshes the bubble level, the readouts and the plots at a fixed frame rate."""

    framesPerSecond = Signal(float)
    attitudeChanged = Signal(object)  # the newest orientation quaternion, on new data (3D view)

    def __init__(
        self,
        session: DeviceSession,
        level: BubbleLevel,
        readouts: TiltReadouts,
        plots: LivePlots,
        truth_label: QLabel,
        filter_panel: FilterPanel,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.filter_panel = filter_panel
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
        self._last_text_update = 0.0
        self._sensor_trace: IncrementalMinMax | None = None
        self._angle_trace: IncrementalMinMax | None = None
        self._comparison_traces: dict[str, IncrementalMinMax] = {}
        self._last_error_update = 0.0
        self._shown_quat: np.ndarray | None = None
        """The quaternions behind the readouts' figures (what Hold keeps showing)."""

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
                self._update_level(orientation)
                if self.plots_enabled and self.plots.isVisible():
                    self._update_plots(samples, orientation)
        if not connected and total == 0:
            self._show_no_data()
        now = time.monotonic()
        if now - self._last_error_update >= ERROR_TABLE_INTERVAL_S:
            self._last_error_update = now
            self.update_error_table()
        self._count_frame()

    def _show_no_data(self) -> None:
        self.level.setValid(False)
        self.readouts.setValid(False)
        self.truth_label.setText("")
        self.plots.clear()

    def _update_level(self, orientation) -> None:
        if self.settings.hold:
            return
        now = time.monotonic()
        update_text = now - self._last_text_update >= 1.0 / self.settings.readout_rate_hz
        if update_text:
            self._last_text_update = now
        recent = orientation.window(
            self.settings.averaging_s,
            names=["quat", "ref_roll", "ref_pitch", "incl_error"],
        )
        angles = averaged_angles(recent["quat"])
        if angles is None:
            return
        self.attitudeChanged.emit(recent["quat"][-1])
        unit = self.settings.unit
        self.level.setValid(True)
        self.level.setTilt(angles.roll_deg, angles.pitch_deg, angles.tilt_deg)
        ref_roll, ref_pitch = recent["ref_roll"][-1], recent["ref_pitch"][-1]
        has_reference = bool(np.isfinite(ref_roll))
        if has_reference:
            self.level.setReference(float(ref_roll), float(ref_pitch))
        else:
            self.level.clearReference()
        if not update_text:
            return
        self._shown_quat = recent["quat"]
        self.readouts.setValid(True)
        self.readouts.setValues(
            float(slope_from_angle(angles.roll_deg, unit)),
            float(slope_from_angle(angles.pitch_deg, unit)),
            float(slope_from_angle(angles.tilt_deg, unit)),
            angles.direction_deg,
            unit,
        )
        if has_reference:
            rms = float(np.sqrt(np.nanmean(recent["incl_error"] ** 2)))
            self.truth_label.setText(
                f"Simulator truth  roll {ref_roll:+.2f}°  pitch {ref_pitch:+.2f}°  ·  "
                f"inclination error {rms:.3f}° RMS"
            )
        else:
            self.truth_label.setText("")

    def current_reading(self, label: str = "") -> Measurement | None:
        """The reading the readouts show (held, or over the averaging time up to now) with its
        mean and standard deviation, unit, filter, calibration and device; None without data."""
        info = self.session.device_info
        quat = self._shown_quat
        if not self.settings.hold or quat is None:
            quat = self.session.pipeline.orientation.window(self.settings.averaging_s,
                                                            ["quat"])["quat"]
        if info is None and not self.settings.hold:
            return None
        pipeline = self.session.pipeline
        calibration = pipeline.calibration.name
        if pipeline.level_reference is not None:
            calibration += " + tare"
        device = "" if info is None else f"{info.name} ({info.unique_id})"
        return measure(quat, self.settings.unit, self.settings.averaging_s, label=label,
                       filter_name=pipeline.filter.name, calibration=calibration,
                       device=device)

    def _update_plots(self, samples, orientation) -> None:
        if self._sensor_trace is None or self._sensor_trace.ring is not samples:
            self._sensor_trace = IncrementalMinMax(samples, ["accel", "gyro", "gap"])
        if self._angle_trace is None or self._angle_trace.ring is not orientation:
            self._angle_trace = IncrementalMinMax(
                orientation, [*ANGLE_TRACES, "gap", "incl_error"]
            )
        window = self.plots.window_s
        # A min/max pair per two pixel columns: all a plot can show at 1 px line width.
        info = self.session.device_info
        rate = info.odr_hz if info is not None else self._rate_hint(samples)
        expected_rows = min(len(samples), window * rate)
        factor = decimation_factor(int(expected_rows), max(self.plots.width(), 200))
        sensor_t, sensor = self._sensor_trace.window(window, factor)
        angle_t, angle_values = self._angle_trace.window(window, factor)
        if len(sensor_t) == 0:
            return
        newest = sensor_t[-1]
        self._update_comparisons(window, factor, newest)
        self.plots.set_data(
            sensor_t - newest,
            sensor[:, :3] / STANDARD_GRAVITY_M_S2,
            np.degrees(sensor[:, 3:6]),
            angle_t - newest,
            {key: angle_values[:, i] for i, key in enumerate(ANGLE_TRACES)},
            sensor_connect=connect_mask(sensor[:, 6]),
            angle_connect=connect_mask(angle_values[:, len(ANGLE_TRACES)]),
        )
        error = angle_values[:, len(ANGLE_TRACES) + 1]
        self.plots.set_error_visible(len(error) > 0 and bool(np.isfinite(error[-1])))
        self.plots.set_error_data(angle_t - newest, error)

    def _update_comparisons(self, window: float, factor: int, newest: float) -> None:
        buffers = self.session.pipeline.comparison_buffers
        traces = {}
        for name, ring in buffers.items():
            trace = self._comparison_traces.get(name)
            traces[name] = trace if trace is not None and trace.ring is ring else (
                IncrementalMinMax(ring, ["roll", "pitch", "incl_error"])
            )
            t, values = traces[name].window(window, factor)
            self.plots.set_comparison_data(
                name, t - newest, values[:, 0], values[:, 1], values[:, 2]
            )
        self._comparison_traces = traces

    def range_statistics(self, start_rel_s: float, end_rel_s: float):
        """Statistics of roll, pitch and tilt over a range relative to the newest sample."""
        orientation = self.session.pipeline.orientation
        rows = orientation.window(self.plots.window_s, ["t", "roll", "pitch", "tilt"])
        if len(rows["t"]) == 0:
            return None
        newest = rows["t"][-1]
        inside = (rows["t"] >= newest + start_rel_s) & (rows["t"] <= newest + end_rel_s)
        if not np.any(inside):
            return None
        statistics = StaticStatistics(duration_s=float("inf"))
        statistics.update(
            rows["t"][inside], rows["roll"][inside], rows["pitch"][inside], rows["tilt"][inside]
        )
        return statistics.result()

    def update_error_table(self) -> None:
        """Refresh the filter panel's error table (called at a low rate)."""
        pipeline = self.session.pipeline
        window = self.plots.window_s
        rows = [summarize_errors(pipeline.orientation, pipeline.filter.title, window)]
        for name, ring in pipeline.comparison_buffers.items():
            rows.append(summarize_errors(ring, FILTERS[name].title, window))
        self.filter_panel.show_errors([(r.name, r.rms_deg, r.max_deg) for r in rows])

    @staticmethod
    def _rate_hint(samples) -> float:
        """Rows per second in the buffer, from its newest second."""
        recent = samples.window(1.0, ["t"])["t"]
        span = recent[-1] - recent[0] if len(recent) > 1 else 0.0
        return (len(recent) - 1) / span if span > 0 else 1.0

    def _count_frame(self) -> None:
        self.frames += 1
        start, frames_then = self._fps_window
        now = time.monotonic()
        if now - start >= 1.0:
            self.framesPerSecond.emit((self.frames - frames_then) / (now - start))
            self._fps_window = (now, self.frames)
