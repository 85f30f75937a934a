"""The compass's feed: the heading over the readouts' averaging window (held with them), and
the disturbance light from the newest field samples against the Field dock's reference."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from app.core.field_check import FieldReference
from app.core.field_light import FieldLight, field_light
from app.core.heading import HeadingReading, HeadingSettings, heading_reading
from app.gui.compass import CompassPanel
from app.gui.feeds.frame import Frame
from app.gui.feeds.screen import ScreenPresence

HEADING_INTERVAL_S = 0.1
"""The heading readout changes at most this often, like the tilt readouts."""
LIGHT_INTERVAL_S = 0.25
"""The disturbance light is judged at most this often (its words change the layout)."""
LIGHT_WINDOW_S = 0.5
"""The light judges the field samples of the newest this many seconds."""


def filter_uses_field(pipeline) -> bool:
    """Whether the pipeline's filter takes heading from the magnetometer now."""
    return pipeline.takes_heading_from_field()


class HeadingFeed:
    """Sets the compass's reading and light when their input changed."""

    def __init__(self, panel: CompassPanel, session,
                 reference: Callable[[], FieldReference | None]) -> None:
        self.panel = panel
        self.session = session
        self.reference = reference
        self.settings = HeadingSettings()
        self.shown = ScreenPresence(panel)
        self.key: tuple | None = None
        self.last_update = -np.inf
        self.light_key: tuple | None = None
        self.last_light = -np.inf
        self.shown_reading: HeadingReading | None = None
        """The reading on show (Hold keeps it, the log and the clipboard take it)."""
        self.on_earth_frame: Callable[[bool], None] | None = None
        """Told whether the attitudes' heading is real (a field, and a filter that takes it)."""
        self._earth_frame: bool | None = None
        self.shown_quat: np.ndarray | None = None
        self.shown_inputs: tuple[bool, bool] = (False, False)
        """The quaternions behind it, and whether a field came and the filter took it."""

    def set_settings(self, settings: HeadingSettings) -> None:
        self.settings = settings
        self.key = None
        self.light_key = None

    def frame(self, frame: Frame, key: tuple, quat: Callable[[], np.ndarray | None],
              hold: bool) -> None:
        if not self.shown(frame.now):
            return
        pipeline = self.session.pipeline
        uses = filter_uses_field(pipeline)
        earth = bool(uses and pipeline.has_field)
        if earth != self._earth_frame and self.on_earth_frame is not None:
            self._earth_frame = earth
            self.on_earth_frame(earth)
        full_key = (*key, pipeline.has_field, uses, self.settings)
        if hold:
            held = self.shown_reading
            if held is not None and self.shown_quat is not None and (
                    held.north, held.unit) != (self.settings.north, self.settings.unit):
                # The held figure, from the other north or in the other unit.
                self.show(heading_reading(self.shown_quat, self.shown_inputs[0],
                                          self.shown_inputs[1], self.settings))
                frame.drew = True
        elif full_key != self.key:
            if frame.now - self.last_update >= HEADING_INTERVAL_S:
                self.shown_quat = quat()
                self.shown_inputs = (pipeline.has_field, uses)
                self.show(heading_reading(self.shown_quat, pipeline.has_field, uses,
                                          self.settings))
                self.key, self.last_update = full_key, frame.now
                frame.drew = True
            else:
                frame.defer(self.last_update + HEADING_INTERVAL_S)
        light_key = (pipeline.field.total_written, id(pipeline.field), id(self.reference()))
        if light_key != self.light_key:
            if frame.now - self.last_light >= LIGHT_INTERVAL_S:
                self.panel.setLight(self.light())
                self.light_key, self.last_light = light_key, frame.now
                frame.drew = True
            else:
                frame.defer(self.last_light + LIGHT_INTERVAL_S)

    def show(self, reading: HeadingReading) -> None:
        declination = self.settings.declination
        text = "" if declination is None else f"{declination.declination_deg:+.1f}°"
        self.shown_reading = reading
        self.panel.setReading(reading, text)

    def reading_for(self, quat: np.ndarray, held: bool) -> HeadingReading:
        """The heading of these quaternions as the compass shows it (held: the one on show)."""
        if held and self.shown_reading is not None:
            return self.shown_reading
        pipeline = self.session.pipeline
        return heading_reading(quat, pipeline.has_field, filter_uses_field(pipeline),
                               self.settings)

    def light(self) -> FieldLight:
        pipeline = self.session.pipeline
        rows = pipeline.field.window(LIGHT_WINDOW_S, ["norm", "dip"])
        calibration = pipeline.calibration.magnetometer
        return field_light(rows["norm"], rows["dip"], self.reference(),
                           calibrated=calibration is not None)

    def clear(self) -> None:
        """No data: no heading; the light as the field ring says."""
        self.key = None
        self.shown_reading = None
        self.shown_quat = None
        self.panel.setReading(HeadingReading("no data", north=self.settings.north,
                                             unit=self.settings.unit), "")
