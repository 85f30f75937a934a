"""The earth's magnetic field for a place and date, from the World Magnetic Model (WMM).

The model's coefficients come with the ``pygeomag`` package (NOAA's published WMM files, not
numbers typed in here). Frames: the field is given in the local north-east-down components a
navigator uses, and as a vector in this program's earth frame, ENU with y toward **magnetic**
north (x east, y magnetic north, z up), where a level sensor pointing at magnetic north reads
``(0, H, -Z)``: the horizontal strength ``H`` along y and the field dipping below the horizon
(down, negative z) in the northern hemisphere. True north is magnetic north turned by the
declination: ``true heading = magnetic heading + declination`` (east positive).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from datetime import UTC, date, datetime

import numpy as np

WMM_VALID_YEARS = (2025.0, 2030.0)
"""The span of the coefficients in use (WMM2025); dates outside it are refused."""


@dataclass(frozen=True, slots=True)
class Place:
    """Where on the earth: WGS-84 latitude and longitude in degrees, height above the
    ellipsoid in metres."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float = 0.0

    def __post_init__(self) -> None:
        if not -90.0 <= self.latitude_deg <= 90.0:
            raise ValueError(f"latitude {self.latitude_deg} is outside -90 ... 90 degrees")
        if not -180.0 <= self.longitude_deg <= 360.0:
            raise ValueError(f"longitude {self.longitude_deg} is outside -180 ... 360 degrees")
        if not -1000.0 <= self.altitude_m <= 850_000.0:
            raise ValueError(f"altitude {self.altitude_m} m is outside -1 ... 850 km")


DEFAULT_PLACE = Place(52.5125, 13.3269, 50.0)
"""TU Berlin, where the BROAD trials were recorded; the simulator's place unless given."""


@dataclass(frozen=True, slots=True)
class EarthField:
    """The main field at a place and date (WMM), in microtesla and degrees."""

    north_ut: float
    east_ut: float
    down_ut: float
    declination_deg: float
    """Magnetic north's bearing from true north, east positive."""
    place: Place
    year: float
    """Decimal year the field was computed for."""

    @property
    def total_ut(self) -> float:
        return math.sqrt(self.north_ut ** 2 + self.east_ut ** 2 + self.down_ut ** 2)

    @property
    def horizontal_ut(self) -> float:
        return math.hypot(self.north_ut, self.east_ut)

    @property
    def dip_deg(self) -> float:
        """Inclination: the field's angle below the horizontal (positive pointing down)."""
        return math.degrees(math.atan2(self.down_ut, self.horizontal_ut))

    def enu_magnetic_ut(self) -> np.ndarray:
        """The field in this program's earth frame (ENU, y toward magnetic north): (0, H, -Z)."""
        return np.array([0.0, self.horizontal_ut, -self.down_ut])

    def enu_true_ut(self) -> np.ndarray:
        """The field in ENU with y toward true (geographic) north: (E, N, -Z)."""
        return np.array([self.east_ut, self.north_ut, -self.down_ut])


def decimal_year(when: date | datetime | float) -> float:
    """``2026.9``-style decimal year of a date (a float passes through)."""
    if isinstance(when, int | float):
        return float(when)
    if isinstance(when, datetime):
        moment = when.astimezone(UTC) if when.tzinfo else when.replace(tzinfo=UTC)
    else:
        moment = datetime(when.year, when.month, when.day, 12, tzinfo=UTC)
    start = datetime(moment.year, 1, 1, tzinfo=UTC)
    end = datetime(moment.year + 1, 1, 1, tzinfo=UTC)
    return moment.year + (moment - start).total_seconds() / (end - start).total_seconds()


@functools.lru_cache(maxsize=1)
def _model():  # type: ignore[no-untyped-def]
    from pygeomag import GeoMag  # imported on first use: it reads the coefficient file

    return GeoMag(base_year=2025)


@functools.lru_cache(maxsize=256)
def earth_field(place: Place = DEFAULT_PLACE, when: date | datetime | float | None = None
                ) -> EarthField:
    """The WMM field at ``place`` on ``when`` (default: today). Raises ValueError for a date
    outside the model's span (its values would be guesses) and when the model's coefficient
    files cannot be read."""
    year = decimal_year(datetime.now(UTC) if when is None else when)
    low, high = WMM_VALID_YEARS
    if not low <= year < high:
        raise ValueError(f"the World Magnetic Model in use covers {low:.0f} to {high:.0f}; "
                         f"{year:.2f} is outside it")
    try:
        model = _model()
    except OSError as exc:  # a bundle or an install without the coefficient files
        raise ValueError(f"the World Magnetic Model's coefficients cannot be read "
                         f"({exc.strerror or exc}): reinstall pygeomag") from None
    result = model.calculate(glat=place.latitude_deg, glon=place.longitude_deg,
                             alt=place.altitude_m / 1000.0, time=year)
    return EarthField(north_ut=result.x / 1000.0, east_ut=result.y / 1000.0,
                      down_ut=result.z / 1000.0, declination_deg=float(result.d),
                      place=place, year=year)
