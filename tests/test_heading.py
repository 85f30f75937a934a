"""Heading from a 9-axis orientation: conventions, wrap, the vertical case, units, north."""

from __future__ import annotations

import math
from datetime import date

import numpy as np
import pytest

from app.core import quaternion as quat
from app.core.earth_field import Place, earth_field
from app.core.heading import (
    NO_DATA,
    NO_HEADING_FILTER,
    NO_MAGNETOMETER,
    OK,
    VERTICAL,
    VERTICAL_LIMIT_DEG,
    Declination,
    HeadingSettings,
    averaged_heading,
    cardinal,
    circular_mean_deg,
    displayed_heading_deg,
    format_heading,
    heading_metadata,
    heading_reading,
    magnetic_heading_deg,
    parse_place,
    signed_difference_deg,
    typed_declination,
    wmm_declination,
)
from app.core.orientation import quaternion_from_roll_pitch


def pose(heading_deg: float, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """A sensor whose +x points at ``heading`` (clockwise from north), raised by ``pitch``."""
    return quaternion_from_roll_pitch(roll_deg, pitch_deg, 90.0 - heading_deg)


def test_level_sensor_headings_follow_the_x_axis_clockwise_from_north() -> None:
    # Identity: sensor x is earth x, east.
    assert magnetic_heading_deg(np.array([1.0, 0, 0, 0])) == pytest.approx(90.0)
    # A turn of +90 degrees about up (counter-clockwise from above) swings x from east to
    # north: heading 0; another 90 to west: 270.
    about_up = quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(90.0))
    assert magnetic_heading_deg(about_up) % 360.0 == pytest.approx(0.0, abs=1e-9)
    west = quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(180.0))
    assert magnetic_heading_deg(west) == pytest.approx(270.0)


@pytest.mark.parametrize("heading", [0.0, 12.5, 90.0, 179.9, 180.0, 271.0, 359.5])
@pytest.mark.parametrize("pitch, roll", [(0.0, 0.0), (30.0, 0.0), (-40.0, 25.0), (60.0, -170.0)])
def test_roll_and_pitch_leave_the_heading_alone(heading, pitch, roll) -> None:
    got = float(magnetic_heading_deg(pose(heading, pitch, roll)))
    assert signed_difference_deg(got, heading) == pytest.approx(0.0, abs=1e-9)
    assert 0.0 <= got < 360.0


def test_heading_is_undefined_with_the_pointing_axis_near_vertical() -> None:
    steep = [VERTICAL_LIMIT_DEG + 0.5, 89.9, -89.9, -(VERTICAL_LIMIT_DEG + 1.0)]
    assert np.all(np.isnan(magnetic_heading_deg(pose(40.0, np.array(steep)))))
    assert np.all(np.isfinite(magnetic_heading_deg(pose(40.0, np.array(
        [VERTICAL_LIMIT_DEG - 0.5, -(VERTICAL_LIMIT_DEG - 0.5)])))))
    reading = heading_reading(pose(40.0, np.full(5, 88.0)), True, True, HeadingSettings())
    assert reading.state == VERTICAL and reading.text == "" and "unavailable" in reading.message


def test_averaging_wraps_round_north() -> None:
    around_north = pose(np.array([358.0, 359.0, 1.0, 2.0]))
    mean = averaged_heading(around_north)
    assert mean is not None
    assert signed_difference_deg(mean.heading_deg, 0.0) == pytest.approx(0.0, abs=1e-9)
    assert circular_mean_deg(np.array([350.0, 20.0])) == pytest.approx(5.0)
    assert circular_mean_deg(np.array([170.0, 190.0, np.nan])) == pytest.approx(180.0)
    assert circular_mean_deg(np.array([0.0, 180.0])) is None  # cancel out: no mean
    assert circular_mean_deg(np.array([np.nan])) is None
    # Headings spread all round (the sensor spun within the window): no mean direction.
    spun = averaged_heading(pose(np.arange(0.0, 360.0, 10.0)))
    assert spun is not None and not spun.defined


def test_mils_and_degrees_texts() -> None:
    assert format_heading(90.0, "mil") == "1600"
    assert format_heading(359.99, "mil") == "0"
    assert format_heading(123.0, "mil") == "2187"
    assert format_heading(359.96, "deg") == "0.0"
    assert format_heading(-0.5, "deg") == "359.5"
    assert format_heading(math.nan, "deg") == ""
    assert [cardinal(h) for h in (0, 44, 46, 90, 200, 350)] == ["N", "NE", "NE", "E", "S", "N"]


def test_true_north_adds_the_declination_east_positive() -> None:
    east = HeadingSettings("true", "deg", typed_declination(4.5))
    assert displayed_heading_deg(358.0, east) == pytest.approx(2.5)
    west = HeadingSettings("true", "deg", typed_declination(-10.0))
    assert displayed_heading_deg(5.0, west) == pytest.approx(355.0)
    reading = heading_reading(pose(np.full(3, 30.0)), True, True, east)
    assert reading.state == OK and reading.text == "34.5"
    assert reading.clipboard_text() == "Heading 34.5° true"
    mils = heading_reading(pose(np.full(3, 90.0)), True, True, HeadingSettings(unit="mil"))
    assert mils.clipboard_text() == "Heading 1600 mil magnetic"
    with pytest.raises(ValueError, match="declination"):
        HeadingSettings("true")


def test_wmm_declination_is_the_models() -> None:
    place, when = Place(48.1, 11.6), date(2026, 6, 1)
    declination = wmm_declination(place, when)
    assert declination.declination_deg == earth_field(place, when).declination_deg
    assert 3.0 < declination.declination_deg < 6.0  # Munich, mid-2020s: about 4-5 degrees east
    assert declination.source == "wmm" and "WMM 2026-06-01" in declination.describe()
    with pytest.raises(ValueError, match="covers"):
        wmm_declination(place, date(2031, 1, 1))


def test_states_say_why_there_is_no_heading() -> None:
    settings = HeadingSettings()
    level = pose(np.full(4, 10.0))
    assert heading_reading(None, True, True, settings).state == NO_DATA
    assert heading_reading(level, False, True, settings).state == NO_MAGNETOMETER
    assert heading_reading(level, True, False, settings).state == NO_HEADING_FILTER
    assert heading_reading(level, True, True, settings).state == OK


def test_settings_and_metadata_round_trip() -> None:
    settings = HeadingSettings("true", "mil", wmm_declination(Place(-33.9, 151.2, 20.0),
                                                              date(2027, 3, 4)))
    assert HeadingSettings.from_dict(settings.to_dict()) == settings
    typed = HeadingSettings("magnetic", "deg", typed_declination(-2.25))
    assert HeadingSettings.from_dict(typed.to_dict()) == typed
    assert HeadingSettings.from_dict({}) == HeadingSettings()
    for bad in ({"north": "grid"}, {"unit": "grad"}, {"declination": {"declination_deg": "x"}},
                {"declination": {"declination_deg": 400}},
                {"declination": {"declination_deg": 1, "source": "wmm"}}):
        with pytest.raises(ValueError):
            HeadingSettings.from_dict(bad)
    metadata = heading_metadata(typed.declination)
    assert metadata["declination_deg"] == -2.25 and metadata["source"] == "typed"
    assert Declination.from_dict(metadata) == typed.declination
    assert heading_metadata(None) == {"frame": "ENU, y magnetic north"}


def test_place_text() -> None:
    assert parse_place("52.5, 13.3") == Place(52.5, 13.3)
    assert parse_place("1,2,300") == Place(1.0, 2.0, 300.0)
    for bad in ("52.5", "a,b", "91,0", "1,2,3,4", "nan,1"):
        with pytest.raises(ValueError):
            parse_place(bad)


def test_heading_agrees_with_a_compass_on_the_field_a_level_sensor_reads() -> None:
    """A level magnetic compass: the field's horizontal part in the sensor's x-y plane gives
    the heading of +x as atan2(m_y, m_x) (north along +y reads 90: +x points east)."""
    field_enu = earth_field(Place(52.5, 13.3), date(2026, 6, 1)).enu_magnetic_ut()
    rng = np.random.default_rng(3)
    headings = rng.uniform(0.0, 360.0, 50)
    q = pose(headings)
    sensor_field = quat.rotate_inverse(q, np.broadcast_to(field_enu, (50, 3)))
    compass = np.degrees(np.arctan2(sensor_field[:, 1], sensor_field[:, 0])) % 360.0
    got = magnetic_heading_deg(q)
    assert np.max(np.abs(signed_difference_deg(got, 0.0) - signed_difference_deg(compass, 0.0))
                  ) < 1e-9


def test_field_light_says_how_far_off_the_field_is() -> None:
    from app.core.field_check import FieldReference
    from app.core.field_light import CLEAN, DISTURBED, NO_FIELD, NO_REFERENCE, field_light

    reference = FieldReference(50.0, 67.0, "WMM test", 0.15, 8.0)
    clean = field_light(np.array([49.0, 51.0, 52.0]), np.array([66.0, np.nan, 68.0]), reference)
    assert clean.state == CLEAN and clean.reason == "" and clean.reference == "WMM test"
    strong = field_light(np.array([50.0, 61.5, 55.0]), np.array([67.0, 67.0, 67.0]), reference)
    assert strong.state == DISTURBED and strong.reason == "field 23 % above normal"
    both = field_light(np.array([30.0, 50.0]), np.array([np.nan, 58.0]), reference)
    assert both.disturbed and both.reason == "field 40 % below normal · dip 9° off"
    assert field_light(np.array([]), np.array([]), reference).state == NO_FIELD
    # Without a calibration the sensor's own iron may be the cause: the reason says so.
    uncalibrated = field_light(np.array([50.0]), np.array([13.0]), reference, calibrated=False)
    assert uncalibrated.reason == "dip 54° off · magnetometer not calibrated"
    assert field_light(np.array([50.0]), np.array([67.0]), reference, calibrated=False
                       ).reason == ""  # a field that matches is normal, calibrated or not
    assert field_light(np.array([50.0]), np.array([67.0]), None).state == NO_REFERENCE
