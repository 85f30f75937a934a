"""Orientation filters, listed by name for the GUI and the command line."""

from __future__ import annotations

from typing import Any

from app.core.filters.accel_tilt import AccelerometerTilt
from app.core.filters.base import OrientationBlock, OrientationFilter, ParameterSpec
from app.core.filters.complementary import ComplementaryFilter
from app.core.filters.ekf import QuaternionEKF
from app.core.filters.gyro_integration import GyroIntegration
from app.core.filters.kalman_thesis import ThesisKalman
from app.core.filters.madgwick import MadgwickFilter
from app.core.filters.mahony import MahonyFilter
from app.core.filters.offline import EKFSmoother, OfflineVQF
from app.core.filters.vqf_filter import VQFFilter
from app.core.filters.vqf_heading import VQFHeadingFilter

FILTERS: dict[str, type[OrientationFilter]] = {
    cls.name: cls
    for cls in (
        QuaternionEKF, VQFFilter, ComplementaryFilter, MadgwickFilter, MahonyFilter,
        ThesisKalman, AccelerometerTilt, GyroIntegration, EKFSmoother, OfflineVQF,
        VQFHeadingFilter,
    )
}
DEFAULT_FILTER = QuaternionEKF.name
"""The default for a source without a magnetometer (the best inclination on real data)."""
DEFAULT_FILTER_9AXIS = QuaternionEKF.name
"""The default for a source with a magnetometer: the 9-axis filter with the best heading on
the turned BROAD trials (``evaluate --turn``): the EKF with its heading update (1.78 deg mean
against VQF 9D's 2.58), whose inclination is the 6-axis EKF's to float precision."""
ONLINE_FILTERS: tuple[str, ...] = tuple(name for name, cls in FILTERS.items() if not cls.offline)
"""The filters that can run on a live stream (offline smoothers need the whole recording)."""


def default_filter_for(has_magnetometer: bool) -> str:
    """The default filter's name for a source with or without a magnetometer.

    Falls back to :data:`DEFAULT_FILTER` when the 9-axis default cannot be made (its package
    missing), so a source with a field still gets a working filter."""
    if has_magnetometer and _available(DEFAULT_FILTER_9AXIS):
        return DEFAULT_FILTER_9AXIS
    return DEFAULT_FILTER


def _available(name: str) -> bool:
    try:
        FILTERS[name]()
    except (ImportError, ValueError):
        return False
    return True


def known_parameters(name: str, values: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """Split recorded parameter ``values`` of filter ``name`` into those it still has and the
    names of those it no longer has (a recording made by an older version)."""
    cls = FILTERS[name]
    names = {spec.name for spec in cls.parameters}
    return ({k: v for k, v in values.items() if k in names},
            sorted(k for k in values if k not in names))


def create_filter(name: str, **values: Any) -> OrientationFilter:
    """A new filter by registry name, with parameter values applied."""
    try:
        cls = FILTERS[name]
    except KeyError:
        known = ", ".join(FILTERS)
        raise KeyError(f"no filter named {name!r} (available: {known})") from None
    return cls(**values)


__all__ = [
    "DEFAULT_FILTER", "DEFAULT_FILTER_9AXIS", "FILTERS", "ONLINE_FILTERS", "OrientationBlock",
    "OrientationFilter", "ParameterSpec", "create_filter", "default_filter_for",
    "known_parameters",
]
