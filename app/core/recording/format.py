"""Recording format v1: the constants, the columns and the metadata (docs/recording-format.md).

A recording is a UTF-8 CSV file::

    # inclinometer-recording 1
    # key: <JSON value>                  (one line per key)
    t,ax,ay,az,gx,gy,gz,temp,gap,block_start,qw,qx,qy,qz
    0.0,0.0011964113,...

This module holds what the writer and the reader share: the magic line, column names and
units, and the JSON form of metadata values (device, sensor settings, calibration, filter).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Iterable, Mapping
from datetime import UTC, datetime
from typing import Any, TypeVar

import numpy as np

from app.core.calibration import (
    MAG_KEY,
    MagnetometerCalibration,
    SensorCalibration,
    temperature_from_json,
    temperature_to_json,
)
from app.core.version import __version__

T = TypeVar("T")

MAGIC = "inclinometer-recording"
FORMAT_VERSION = 1
FIRST_LINE = f"# {MAGIC} {FORMAT_VERSION}"
METADATA_PREFIX = "# "

REQUIRED_COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")
"""Time (s, device clock), raw specific force (m/s^2) and raw angular rate (rad/s)."""
ACCEL_COLUMNS = ("ax", "ay", "az")
GYRO_COLUMNS = ("gx", "gy", "gz")
REFERENCE_COLUMNS = ("qw", "qx", "qy", "qz")
"""Reference orientation, sensor-to-earth, earth z up; empty where unknown."""
MAG_COLUMNS = ("mx", "my", "mz")
"""Magnetic field in uT, sensor frame, as measured (before the magnetometer's calibration);
empty on rows without a new field sample. An extension within v1 (docs/recording-format.md)."""
OPTIONAL_COLUMNS = ("temp", *REFERENCE_COLUMNS, "gap", "block_start", *MAG_COLUMNS)
"""``block_start`` is an extension within v1 (docs/recording-format.md): 1 on the first sample
of each block as the device delivered it, so that a replay cuts the stream exactly as it was
processed live. Readers that do not know it ignore it, as any unknown column."""
KNOWN_COLUMNS = (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS)

UNITS: dict[str, str] = {
    "t": "s", "ax": "m/s^2", "ay": "m/s^2", "az": "m/s^2",
    "gx": "rad/s", "gy": "rad/s", "gz": "rad/s", "temp": "degC",
    "qw": "1", "qx": "1", "qy": "1", "qz": "1", "gap": "flag", "block_start": "flag",
    "mx": "uT", "my": "uT", "mz": "uT",
}
CONVENTIONS = (
    "sensor frame: the LSM6DSOX's x, y, z; a: specific force (level, +z up, reads +9.81 on z); "
    "g: right-handed angular rate; q: unit quaternion (w, x, y, z) rotating sensor-frame "
    "vectors into the earth frame, earth z up"
)

# Metadata keys written by this program (others are kept as they are).
KEY_APP = "app"
KEY_APP_VERSION = "app_version"
KEY_START_TIME = "start_time"
KEY_DEVICE = "device"
KEY_SENSOR_SETTINGS = "sensor_settings"
KEY_CALIBRATION = "calibration"
KEY_FILTER = "filter"
KEY_COMPARISONS = "comparison_filters"
KEY_UNITS = "units"
KEY_CONVENTIONS = "conventions"
KEY_NOTE = "note"
KEY_REFERENCE = "reference"
KEY_BOOKMARKS = "bookmarks"
KEY_SIMULATOR = "simulator"
KEY_MAGNETOMETER = "magnetometer"
"""The magnetometer's identity, settings and calibration (a v1 extension); a recording whose
metadata has it carries the ``mx,my,mz`` columns."""

DEVICE_FIELDS = (
    "url", "name", "unique_id", "sensor", "odr_hz", "odr_nominal_hz", "accel_fs_g",
    "gyro_fs_dps", "firmware", "extra",
)
"""The fields of :class:`drivers.base.DeviceInfo`, in the order the metadata lists them."""


def utc_timestamp(moment: datetime | None = None) -> str:
    """ISO 8601 UTC with milliseconds and a ``Z``: ``2026-05-09T07:35:25.123Z``."""
    moment = (moment or datetime.now(UTC)).astimezone(UTC)
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def to_json_value(value: Any) -> Any:
    """Plain JSON types: arrays to lists, numpy scalars to Python, NaN and inf to None.

    Floats keep every bit: ``json`` writes them with ``repr``, which reads back exactly.
    """
    if isinstance(value, Mapping):
        return {str(k): to_json_value(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return to_json_value({f.name: getattr(value, f.name) for f in dataclasses.fields(value)})
    if isinstance(value, np.ndarray):
        return to_json_value(value.tolist())
    if isinstance(value, list | tuple | set | frozenset):
        return [to_json_value(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)


def metadata_line(key: str, value: Any) -> str:
    """``# key: <JSON>`` on one line (JSON never holds a raw line break)."""
    if not key or ":" in key or "\n" in key or key != key.strip():
        raise ValueError(f"invalid metadata key {key!r}")
    text = json.dumps(to_json_value(value), ensure_ascii=False, allow_nan=False)
    return f"{METADATA_PREFIX}{key}: {text}"


def metadata_text(metadata: Mapping[str, Any]) -> str:
    """The first line and one line per key, each ending in ``\\n``."""
    lines = [FIRST_LINE]
    lines += [metadata_line(key, value) for key, value in metadata.items()]
    return "\n".join(lines) + "\n"


# -- values ----------------------------------------------------------------------------------
def metadata_entries(metadata: Mapping[str, Any], key: str, parse: Callable[[Any], T]) -> list[T]:
    """The list under ``key`` parsed entry by entry (events a recording stores, say): none when
    the key is absent or not a list; an entry ``parse`` rejects (KeyError, TypeError,
    ValueError) is skipped, so one damaged entry does not hide the others."""
    entries = metadata.get(key)
    if not isinstance(entries, list):
        return []
    parsed = []
    for entry in entries:
        try:
            parsed.append(parse(entry))
        except (KeyError, TypeError, ValueError):
            continue
    return parsed


def calibration_to_json(calibration: SensorCalibration) -> dict[str, Any]:
    """The calibration's parameters, as a profile's ``parameters`` plus its name."""
    return {
        "name": calibration.name,
        "accel_bias_m_s2": np.asarray(calibration.accel_bias_m_s2, float).tolist(),
        "accel_matrix": np.asarray(calibration.accel_matrix, float).tolist(),
        "gyro_bias_rad_s": np.asarray(calibration.gyro_bias_rad_s, float).tolist(),
        "gyro_matrix": np.asarray(calibration.gyro_matrix, float).tolist(),
        # Optional (a v1 extension): the temperature terms, only when there are some.
        **temperature_to_json(calibration.temperature),
        # Optional (a v1 extension): the magnetometer's terms, only when there are some.
        **({MAG_KEY: calibration.magnetometer.to_json()}
           if calibration.magnetometer is not None else {}),
    }


def calibration_from_json(value: Any) -> SensorCalibration:
    """Inverse of :func:`calibration_to_json`; raises ValueError for a malformed value."""
    if not isinstance(value, Mapping):
        raise ValueError("the calibration is not a JSON object")

    def array(name: str, shape: tuple[int, ...]) -> np.ndarray:
        try:
            result = np.asarray(value[name], dtype=np.float64)
        except KeyError:
            raise ValueError(f"the calibration lacks {name!r}") from None
        except (TypeError, ValueError):
            raise ValueError(f"the calibration's {name!r} is not numbers") from None
        if result.shape != shape or not np.all(np.isfinite(result)):
            raise ValueError(f"the calibration's {name!r} is not {shape} finite numbers")
        return result

    try:
        temperature = temperature_from_json(value)
    except ValueError as exc:
        raise ValueError(f"the calibration's temperature terms: {exc}") from None
    magnetometer = None
    if value.get(MAG_KEY) is not None:
        magnetometer = MagnetometerCalibration.from_json(value[MAG_KEY])
    return SensorCalibration(
        accel_bias_m_s2=array("accel_bias_m_s2", (3,)),
        accel_matrix=array("accel_matrix", (3, 3)),
        gyro_bias_rad_s=array("gyro_bias_rad_s", (3,)),
        gyro_matrix=array("gyro_matrix", (3, 3)),
        name=str(value.get("name", "recorded")),
        temperature=temperature,
        magnetometer=magnetometer,
    )


def device_to_json(info: Any) -> dict[str, Any]:
    """A :class:`drivers.base.DeviceInfo` (or a mapping with its fields) as a JSON object."""
    if isinstance(info, Mapping):
        return to_json_value(dict(info))
    return to_json_value({name: getattr(info, name, None) for name in DEVICE_FIELDS})


def sensor_settings_from_device(info: Any) -> dict[str, Any]:
    """The sensor configuration part of a device description."""
    get = info.get if isinstance(info, Mapping) else lambda name: getattr(info, name, None)
    return to_json_value({
        "sensor": get("sensor"), "odr_hz": get("odr_hz"), "odr_nominal_hz": get("odr_nominal_hz"),
        "accel_fs_g": get("accel_fs_g"), "gyro_fs_dps": get("gyro_fs_dps"),
    })


def filter_to_json(orientation_filter: Any) -> dict[str, Any]:
    """Name, title and parameter values of an :class:`~app.core.filters.OrientationFilter`."""
    return to_json_value({
        "name": orientation_filter.name,
        "title": orientation_filter.title,
        "parameters": orientation_filter.parameter_values(),
    })


def recording_metadata(
    *,
    device: Any = None,
    calibration: SensorCalibration | None = None,
    orientation_filter: Any = None,
    comparison_filters: Iterable[Any] = (),
    note: str = "",
    reference_source: str | None = None,
    start_time: datetime | None = None,
    bookmarks: Iterable[Mapping[str, Any]] = (),
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The metadata a recording starts with (see docs/recording-format.md).

    Parameters
    ----------
    device : the open device's :class:`~drivers.base.DeviceInfo`.
    calibration : the calibration the pipeline applies (identity when None).
    orientation_filter, comparison_filters : the pipeline's filter objects.
    note : free text from the user.
    reference_source : what the reference columns hold (e.g. the simulator's true orientation);
        None when the recording has none.
    start_time : when recording started (default: now).
    bookmarks : ``{"t": device time s, "label": text}`` entries.
    extra : further keys (e.g. ``{"simulator": {"unit_errors": ...}}``); they win over the
        standard ones of the same name.
    """
    metadata: dict[str, Any] = {
        KEY_APP: "inclinometer",
        KEY_APP_VERSION: __version__,
        KEY_START_TIME: utc_timestamp(start_time),
    }
    if device is not None:
        metadata[KEY_DEVICE] = device_to_json(device)
        metadata[KEY_SENSOR_SETTINGS] = sensor_settings_from_device(device)
        magnetometer = getattr(device, "magnetometer", None)
        if magnetometer is not None:
            metadata[KEY_MAGNETOMETER] = magnetometer_to_json(
                magnetometer, None if calibration is None else calibration.magnetometer)
    metadata[KEY_CALIBRATION] = calibration_to_json(calibration or SensorCalibration())
    if orientation_filter is not None:
        metadata[KEY_FILTER] = filter_to_json(orientation_filter)
    comparisons = [filter_to_json(f) for f in comparison_filters]
    if comparisons:
        metadata[KEY_COMPARISONS] = comparisons
    metadata[KEY_UNITS] = dict(UNITS)
    metadata[KEY_CONVENTIONS] = CONVENTIONS
    if reference_source is not None:
        metadata[KEY_REFERENCE] = {"source": reference_source}
    metadata[KEY_NOTE] = note
    marks = [to_json_value(dict(b)) for b in bookmarks]
    if marks:
        metadata[KEY_BOOKMARKS] = marks
    if extra:
        metadata.update(to_json_value(dict(extra)))
    return metadata


def magnetometer_to_json(info: Any, calibration: MagnetometerCalibration | None = None
                         ) -> dict[str, Any]:
    """The ``magnetometer`` metadata: the chip and its settings (a
    :class:`~app.core.devices.MagnetometerInfo`), and its calibration when one is applied."""
    value = to_json_value(info)
    if calibration is not None:
        value["calibration"] = calibration.to_json()
    return value


def simulator_metadata(device: Any) -> dict[str, Any]:
    """``{"simulator": {...}}`` for a simulated device: its unit's true errors and its URL
    options, so a recording carries what a calibration of it should find. Empty for others.
    """
    unit_errors = getattr(device, "unit_errors", None)
    if unit_errors is None or not hasattr(unit_errors, "as_dict"):
        return {}
    simulator: dict[str, Any] = {"unit_errors": unit_errors.as_dict(),
                                 "true_odr_hz": getattr(device, "true_odr_hz", None)}
    faults = getattr(device, "injected_faults", None)
    if faults:
        simulator["faults"] = list(faults)
    # With a magnetometer: the earth's field and the disturbances' truth (drivers.sim.device).
    simulator.update(getattr(device, "simulator_truth", None) or {})
    return {KEY_SIMULATOR: simulator}
