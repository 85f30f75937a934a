"""The earth's field from the World Magnetic Model (app/core/earth_field.py)."""

from __future__ import annotations

from datetime import date

import numpy as np
import pytest

from app.core.earth_field import DEFAULT_PLACE, Place, decimal_year, earth_field


def test_berlin_has_the_field_a_compass_there_meets():
    field = earth_field(DEFAULT_PLACE, date(2026, 11, 27))
    # published WMM2025 values for Berlin: about 50 uT, dip 68 degrees, declination 5 E
    assert 49.0 < field.total_ut < 51.5
    assert 67.0 < field.dip_deg < 69.5
    assert 4.0 < field.declination_deg < 6.5
    enu = field.enu_magnetic_ut()
    assert enu[0] == 0.0 and enu[1] > 0 and enu[2] < 0  # toward magnetic north and down
    assert np.linalg.norm(enu) == pytest.approx(field.total_ut)
    assert np.linalg.norm(field.enu_true_ut()) == pytest.approx(field.total_ut)
    # the magnetic frame is the true one turned by the declination about the vertical
    east, north = field.enu_true_ut()[:2]
    assert np.degrees(np.arctan2(east, north)) == pytest.approx(field.declination_deg)


def test_the_field_points_up_in_the_southern_hemisphere():
    assert earth_field(Place(-33.87, 151.21), 2026.0).dip_deg < -55.0


def test_dates_outside_the_model_and_places_off_the_earth_are_refused():
    with pytest.raises(ValueError, match="covers 2025 to 2030"):
        earth_field(DEFAULT_PLACE, 2031.5)
    with pytest.raises(ValueError, match="latitude"):
        Place(91.0, 0.0)


def test_decimal_year_counts_the_days():
    assert decimal_year(date(2026, 1, 1)) == pytest.approx(2026.0 + 0.5 / 365)
    assert decimal_year(2027.25) == 2027.25


def test_missing_coefficient_files_are_a_clear_error_not_a_crash(monkeypatch):
    from app.core import earth_field as module

    def missing():
        raise FileNotFoundError(2, "No such file or directory")

    monkeypatch.setattr(module, "_model", missing)
    module.earth_field.cache_clear()
    try:
        with pytest.raises(ValueError, match=r"coefficients cannot be read.*reinstall pygeomag"):
            module.earth_field(DEFAULT_PLACE, 2026.5)
    finally:
        module.earth_field.cache_clear()
