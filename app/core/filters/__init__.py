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
from app.core.filters.vqf_filter import VQF_AVAILABLE, VQFFilter
from app.core.filters.vqf_heading import VQFHeadingFilter

FILTERS: dict[str, type[OrientationFilter]] = {
    cls.name: cls
    for cls in (
        QuaternionEKF, VQFFilter, ComplementaryFilter, MadgwickFilter, MahonyFilter,
        ThesisKalman, AccelerometerTilt, GyroIntegration, EKFSmoother, OfflineVQF,
        VQFHeadingFilter,
    )
}
DEFAULT_FILTER = VQFFilter.name if VQF_AVAILABLE else QuaternionEKF.name
"""The default for a source without a magnetometer: the filter with the best inclination on
trials it was not tuned on. Cross-validated by trial on the twelve BROAD trials (`tune`), VQF
beats the EKF on held-out folds in every scheme (leave one trial out 0.834 against 0.839 deg,
4-fold 0.790 against 0.800, leave one group out 0.824 against 0.877), as it does on the
eighteen trials nobody tuned on (0.69 against 0.72); the EKF's 0.774 on the twelve was partly
fitted there. Without the ``vqf`` package, the EKF."""
DEFAULT_FILTER_9AXIS = VQFHeadingFilter.name if VQF_AVAILABLE else QuaternionEKF.name
"""The default for a source with a magnetometer: VQF 6D's tilt (the 6-axis default's, so the
inclination is no worse) with the EKF's heading filter and disturbance detector about the
vertical. On the twelve BROAD trials turned as ``evaluate --turn``: heading 1.80 deg against
online VQF 9D's 2.58 (the EKF's own 1.78, with the EKF's tilt, 0.72 deg on unseen trials
against VQF's 0.69). Without the ``vqf`` package, the EKF with its heading update."""
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
