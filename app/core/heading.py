"""Heading (azimuth) from a 9-axis orientation, magnetic or true, in degrees or mils.

Conventions
-----------
The orientation quaternion ``q`` rotates sensor-frame vectors into the earth frame, ENU with
y toward **magnetic** north (x east, y magnetic north, z up), as every 9-axis filter gives it
(``OrientationFilter.uses_magnetometer``).

- The **pointing axis** is the sensor's +x axis: the axis whose elevation is the pitch of
  :mod:`app.core.orientation` (``pitch`` is +x raised above the horizon). The instrument points
  where its +x side points, like a sight along that edge.
- **heading** = the azimuth of the pointing axis's horizontal projection, clockwise from
  north seen from above, in [0, 360): 0 north, 90 east. For ``q = Rz(yaw) Ry(-pitch) Rx(roll)``
  (:func:`app.core.orientation.quaternion_from_roll_pitch`) it is ``90 - yaw``; roll does not
  change it.
- Near vertical (the pointing axis within :data:`VERTICAL_LIMIT_DEG` of straight up or down)
  the horizontal projection vanishes and the heading is only noise: it is **undefined** (NaN)
  there, never shown.
- **true heading** = magnetic heading + declination (east positive, :mod:`app.core.earth_field`).
- **mils**: NATO mils, 6400 to the circle.

Averaging (the readouts' averaging time) is done on the pointing vectors in the earth frame,
like the tilt readout averages the up vector, so it is exact across the 0/360 wrap (a circular
mean): the mean of headings 359 and 1 is 0, not 180.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import date
from typing import Any

import numpy as np

from app.core.earth_field import Place, earth_field

VERTICAL_LIMIT_DEG = 75.0
"""Pointing axis steeper than this above or below the horizon: the heading is undefined. At
75 degrees a 1-degree error of the tilt moves the heading by up to 1/cos(75) = 3.9 degrees."""
MIN_CONCENTRATION = 0.5
"""The headings of an averaging window must agree at least this well (the mean resultant
length; 0.5 is a circular spread of about 67 degrees), else the sensor turned so much within
the window that their mean means nothing: undefined."""
MILS_PER_CIRCLE = 6400.0
"""NATO mils."""
NORTHS = ("magnetic", "true")
"""Which north the heading is measured from."""
KEY_HEADING = "heading"
"""The recording metadata key of the heading's declination (docs/recording-format.md)."""


@dataclass(frozen=True, slots=True)
class HeadingUnit:
    """A unit the heading readout can show."""

    key: str
    title: str
    suffix: str
    per_circle: float


HEADING_UNITS: dict[str, HeadingUnit] = {
    unit.key: unit for unit in (
        HeadingUnit("deg", "degrees", "°", 360.0),
        HeadingUnit("mil", "mils (6400)", "mil", MILS_PER_CIRCLE),
    )
}


def pointing_in_earth(q: np.ndarray) -> np.ndarray:
    """The sensor's +x axis (the pointing axis) in the earth frame, shape (..., 3)."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    axis = np.empty((*q.shape[:-1], 3))
    axis[..., 0] = 1.0 - 2.0 * (y * y + z * z)
    axis[..., 1] = 2.0 * (x * y + w * z)
    axis[..., 2] = 2.0 * (x * z - w * y)
    return axis


def heading_from_vector(vector: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Heading (degrees, clockwise from north, [0, 360)) and elevation (degrees) of earth-frame
    vectors (..., 3), which need not be unit length; the heading is NaN where the vector is
    within :data:`VERTICAL_LIMIT_DEG` of vertical (or has no length)."""
    vector = np.asarray(vector, dtype=np.float64)
    east, north, up = vector[..., 0], vector[..., 1], vector[..., 2]
    horizontal = np.hypot(east, north)
    elevation = np.degrees(np.arctan2(up, horizontal))
    heading = np.degrees(np.arctan2(east, north)) % 360.0
    steep = ~(np.abs(elevation) <= VERTICAL_LIMIT_DEG) | ~(horizontal > 0.0)
    heading = np.where(steep, np.nan, heading)
    return heading, elevation


def magnetic_heading_deg(q: np.ndarray) -> np.ndarray:
    """Per-sample magnetic heading (degrees, [0, 360), NaN near vertical) of sensor-to-earth
    quaternions (..., 4) in ENU with y toward magnetic north."""
    return heading_from_vector(pointing_in_earth(q))[0]


def wrap_deg(angle_deg: np.ndarray | float) -> np.ndarray | float:
    """An angle into [0, 360)."""
    wrapped = np.mod(angle_deg, 360.0)
    # -1e-15 % 360 is 360.0 in floating point.
    wrapped = np.where(wrapped >= 360.0, 0.0, wrapped)
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def signed_difference_deg(angle_deg: np.ndarray | float, reference_deg: float
                          ) -> np.ndarray | float:
    """``angle - reference`` wrapped into [-180, 180): how far clockwise of ``reference``."""
    difference = np.mod(np.asarray(angle_deg, dtype=np.float64) - reference_deg + 180.0,
                        360.0) - 180.0
    return float(difference) if np.ndim(difference) == 0 else difference


def circular_mean_deg(angles_deg: np.ndarray) -> float | None:
    """Circular mean (degrees, [0, 360)) of headings, NaNs left out; None when there are none
    or they cancel out (spread evenly round the circle)."""
    angles = np.asarray(angles_deg, dtype=np.float64).ravel()
    angles = angles[np.isfinite(angles)]
    if not len(angles):
        return None
    rad = np.radians(angles)
    s, c = float(np.sin(rad).mean()), float(np.cos(rad).mean())
    if math.hypot(s, c) < 1e-9:
        return None
    return float(wrap_deg(math.degrees(math.atan2(s, c))))


@dataclass(frozen=True, slots=True)
class AveragedHeading:
    """The heading over the readouts' averaging window (magnetic, degrees)."""

    heading_deg: float
    """Magnetic heading of the mean pointing direction; NaN when undefined."""
    elevation_deg: float
    """Elevation of the mean pointing direction (the pitch, degrees)."""
    concentration: float = 1.0
    """Length of the mean horizontal pointing vector over the mean of their lengths: 1 when
    every sample points the same way, near 0 when they spread all round."""

    @property
    def defined(self) -> bool:
        return math.isfinite(self.heading_deg)


def averaged_heading(quat: np.ndarray) -> AveragedHeading | None:
    """The magnetic heading of the mean pointing vector of quaternions (N, 4) (a circular mean
    that knows the elevation: it is undefined when the mean direction is near vertical, or when
    the headings in the window spread so widely that their mean has little horizontal length);
    None without a finite row."""
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    quat = quat[np.all(np.isfinite(quat), axis=1)]
    if not len(quat):
        return None
    pointing = pointing_in_earth(quat)
    mean = pointing.mean(axis=0)
    heading, elevation = heading_from_vector(mean)
    lengths = float(np.hypot(pointing[:, 0], pointing[:, 1]).mean())
    concentration = float(np.hypot(mean[0], mean[1])) / lengths if lengths > 0 else 0.0
    value = float(heading) if concentration >= MIN_CONCENTRATION else math.nan
    return AveragedHeading(value, float(elevation), concentration)


# -- declination -------------------------------------------------------------------------------

DECLINATION_SOURCES = ("wmm", "typed")


@dataclass(frozen=True, slots=True)
class Declination:
    """The angle from true north to magnetic north, east positive, and where it came from: the
    World Magnetic Model at a place and date (``wmm``) or typed in (``typed``)."""

    declination_deg: float
    source: str = "typed"
    place: Place | None = None
    when: date | None = None

    def __post_init__(self) -> None:
        if not math.isfinite(self.declination_deg) or not -180.0 <= self.declination_deg <= 180.0:
            raise ValueError(f"declination {self.declination_deg} is outside -180 ... 180 degrees")
        if self.source not in DECLINATION_SOURCES:
            raise ValueError(f"declination source {self.source!r}: use wmm or typed")
        if self.source == "wmm" and (self.place is None or self.when is None):
            raise ValueError("a WMM declination needs its place and date")

    def describe(self) -> str:
        """``+4.6° E (WMM 2026-11-27 at 52.51°, 13.33°)`` or ``-2.0° W (typed)``."""
        side = "E" if self.declination_deg >= 0 else "W"
        text = f"{self.declination_deg:+.1f}° {side}"
        if self.source == "wmm" and self.place is not None and self.when is not None:
            return (f"{text} (WMM {self.when.isoformat()} at {self.place.latitude_deg:.2f}°, "
                    f"{self.place.longitude_deg:.2f}°)")
        return f"{text} (typed)"

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON (settings, and the recording's ``heading`` metadata key)."""
        place = None if self.place is None else {
            "latitude_deg": self.place.latitude_deg, "longitude_deg": self.place.longitude_deg,
            "altitude_m": self.place.altitude_m}
        return {"declination_deg": self.declination_deg, "source": self.source,
                "place": place, "date": None if self.when is None else self.when.isoformat()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Declination:
        """Inverse of :meth:`to_dict`; ValueError saying what is wrong."""
        if not isinstance(data, Mapping):
            raise ValueError("the declination must be an object")
        value = data.get("declination_deg")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"declination_deg {value!r} is not a number")
        place_data = data.get("place")
        place = None
        if place_data is not None:
            if not isinstance(place_data, Mapping):
                raise ValueError("the declination's place must be an object")
            numbers = []
            for key in ("latitude_deg", "longitude_deg", "altitude_m"):
                item = place_data.get(key, 0.0)
                if isinstance(item, bool) or not isinstance(item, int | float):
                    raise ValueError(f"the declination's place {key} is not a number")
                numbers.append(float(item))
            place = Place(*numbers)
        text = data.get("date")
        when = None
        if text is not None:
            try:
                when = date.fromisoformat(str(text))
            except ValueError:
                raise ValueError(f"the declination's date {text!r} is not YYYY-MM-DD") from None
        return cls(float(value), str(data.get("source", "typed")), place, when)


def wmm_declination(place: Place, when: date) -> Declination:
    """The World Magnetic Model's declination at ``place`` on ``when`` (ValueError for a date
    the model does not cover)."""
    return Declination(earth_field(place, when).declination_deg, "wmm", place, when)


def typed_declination(declination_deg: float) -> Declination:
    """A declination the user typed in (degrees, east positive)."""
    return Declination(float(declination_deg), "typed")


def parse_place(text: str) -> Place:
    """``LAT,LON[,ALT]`` (degrees, metres) as a :class:`Place`; ValueError with a message."""
    parts = [part.strip() for part in text.split(",")]
    if len(parts) not in (2, 3):
        raise ValueError(f"place {text!r}: write LAT,LON or LAT,LON,ALT (degrees, metres)")
    try:
        numbers = [float(part) for part in parts]
    except ValueError:
        raise ValueError(f"place {text!r}: LAT,LON[,ALT] must be numbers") from None
    if not all(math.isfinite(n) for n in numbers):
        raise ValueError(f"place {text!r}: LAT,LON[,ALT] must be finite numbers")
    return Place(*numbers)


# -- what the readout shows --------------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class HeadingSettings:
    """How the heading is shown: from which north, in which unit, with which declination."""

    north: str = "magnetic"
    unit: str = "deg"
    declination: Declination | None = None

    def __post_init__(self) -> None:
        if self.north not in NORTHS:
            raise ValueError(f"north {self.north!r}: use magnetic or true")
        if self.unit not in HEADING_UNITS:
            raise ValueError(f"heading unit {self.unit!r}: use {' or '.join(HEADING_UNITS)}")
        if self.north == "true" and self.declination is None:
            raise ValueError("a true heading needs the declination (from WMM or typed in)")

    def to_dict(self) -> dict[str, Any]:
        return {"north": self.north, "unit": self.unit,
                "declination": None if self.declination is None else self.declination.to_dict()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> HeadingSettings:
        """Inverse of :meth:`to_dict`; ValueError saying what is wrong."""
        if not isinstance(data, Mapping):
            raise ValueError("the heading settings must be an object")
        declination = data.get("declination")
        return cls(str(data.get("north", "magnetic")), str(data.get("unit", "deg")),
                   None if declination is None else Declination.from_dict(declination))


def displayed_heading_deg(magnetic_deg: np.ndarray | float, settings: HeadingSettings
                          ) -> np.ndarray | float:
    """The heading from the settings' north (degrees, [0, 360)): magnetic, or true =
    magnetic + declination."""
    if settings.north == "true":
        assert settings.declination is not None  # HeadingSettings insists
        return wrap_deg(np.asarray(magnetic_deg, dtype=np.float64)
                        + settings.declination.declination_deg)
    return wrap_deg(magnetic_deg)


def heading_in_unit(heading_deg: float, unit: str) -> float:
    """A heading (degrees) in ``unit`` (a key of :data:`HEADING_UNITS`), in [0, circle)."""
    return float(wrap_deg(heading_deg)) * HEADING_UNITS[unit].per_circle / 360.0


def format_heading(heading_deg: float, unit: str) -> str:
    """The figure: ``123.4`` in degrees (0.1; 359.96 reads 0.0), ``2187`` in mils (whole mils;
    6399.6 reads 0); ``""`` when not finite."""
    if not math.isfinite(heading_deg):
        return ""
    value = heading_in_unit(heading_deg, unit)
    if unit == "deg":
        text = f"{value:.1f}"
        return "0.0" if text == "360.0" else text
    text = f"{value:.0f}"
    return "0" if text == f"{MILS_PER_CIRCLE:.0f}" else text


CARDINALS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")


def cardinal(heading_deg: float) -> str:
    """The nearest of the eight compass points (``N``, ``NE`` ...); ``""`` when not finite."""
    if not math.isfinite(heading_deg):
        return ""
    return CARDINALS[int(((heading_deg % 360.0) + 22.5) // 45.0) % 8]


# States of the heading display, from the worst.
NO_DATA = "no data"
NO_MAGNETOMETER = "no magnetometer"
NO_HEADING_FILTER = "filter without magnetometer"
VERTICAL = "heading unavailable"
OK = "ok"


@dataclass(frozen=True, slots=True)
class HeadingReading:
    """What the compass and the heading readout show."""

    state: str
    """:data:`OK`, or why there is no heading: :data:`NO_DATA`, :data:`NO_MAGNETOMETER`,
    :data:`NO_HEADING_FILTER`, :data:`VERTICAL`."""
    heading_deg: float = math.nan
    """From the settings' north, [0, 360); NaN unless OK."""
    north: str = "magnetic"
    unit: str = "deg"
    message: str = ""
    """One line: why not (empty when OK)."""

    @property
    def ok(self) -> bool:
        return self.state == OK

    @property
    def text(self) -> str:
        """The figure in the unit (``""`` unless OK)."""
        return format_heading(self.heading_deg, self.unit) if self.ok else ""

    def clipboard_text(self) -> str:
        """``Heading 123.4° true`` / ``Heading 2187 mil magnetic``; ``""`` unless OK."""
        if not self.ok:
            return ""
        unit = HEADING_UNITS[self.unit]
        gap = "" if unit.suffix == "°" else " "
        return f"Heading {self.text}{gap}{unit.suffix} {self.north}"


def heading_reading(quat: np.ndarray | None, has_field: bool, filter_uses_field: bool,
                    settings: HeadingSettings) -> HeadingReading:
    """The heading to show for the readouts' window of quaternions: OK with the averaged
    heading, or the reason there is none (no field from the source; a filter that does not take
    heading from it, whose heading is arbitrary; the pointing axis near vertical)."""
    def without(state: str, message: str) -> HeadingReading:
        return HeadingReading(state, math.nan, settings.north, settings.unit, message)

    averaged = None if quat is None else averaged_heading(quat)
    if averaged is None:
        return without(NO_DATA, "no data")
    if not has_field:
        return without(NO_MAGNETOMETER, "no magnetometer: the source has no field")
    if not filter_uses_field:
        return without(NO_HEADING_FILTER,
                       "the filter does not use the magnetometer: its heading is arbitrary")
    if not averaged.defined:
        if abs(averaged.elevation_deg) <= VERTICAL_LIMIT_DEG:
            return without(VERTICAL, "heading unavailable: turning too fast to average")
        return without(VERTICAL, f"heading unavailable: +x is {averaged.elevation_deg:+.0f}° "
                                 f"from level (beyond ±{VERTICAL_LIMIT_DEG:g}°)")
    heading = float(displayed_heading_deg(averaged.heading_deg, settings))
    return HeadingReading(OK, heading, settings.north, settings.unit)


def heading_metadata(declination: Declination | None) -> dict[str, Any]:
    """The recording's ``heading`` metadata key (docs/recording-format.md): the frame of a
    9-axis orientation and the declination in force (its keys absent when none is set)."""
    data: dict[str, Any] = {"frame": "ENU, y magnetic north"}
    if declination is not None:
        data.update(declination.to_dict())
    return data
