"""Read any CSV of IMU samples through a column and unit mapping.

The mapping names, for each of the recording's columns, the file's column (by its header name,
or ``#N`` for the N-th column, 1-based) and its unit, an optional ``-`` flipping its sign (an
axis pointing the other way)::

    t=time:s,ax=acc_x:g,ay=acc_y:g,az=acc_z:g,gx=gyro_x:dps,gy=gyro_y:dps,gz=-gyro_z:dps

``t`` and the six of ``ax..az``, ``gx..gz`` are required; ``mx..mz`` (all three) and ``temp``
are optional. Units: time ``s ms us ns``; acceleration ``m/s2 m/s^2 g``; angular rate
``rad/s deg/s dps``; field ``uT nT mT G T``; temperature ``degC K``. Time in ``ns`` or ``us``
written as integers is read exactly. The file's first non-blank line is its header.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.interop.imported import (
    DEG,
    ImportedData,
    ImportInputError,
    check_time,
    origin,
    read_table,
    split_header,
)
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.core.version import __version__

FORMAT = "csv"
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
ACCEL_UNITS = {"m/s2": 1.0, "m/s^2": 1.0, "g": STANDARD_GRAVITY_M_S2}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": DEG, "dps": DEG}
MAG_UNITS = {"ut": 1.0, "nt": 1e-3, "mt": 1e3, "g": 100.0, "gauss": 100.0, "t": 1e6}
TEMP_UNITS = {"degc": 1.0, "c": 1.0, "k": 1.0}
TARGETS = {
    "t": TIME_UNITS, **dict.fromkeys(("ax", "ay", "az"), ACCEL_UNITS),
    **dict.fromkeys(("gx", "gy", "gz"), GYRO_UNITS),
    **dict.fromkeys(("mx", "my", "mz"), MAG_UNITS), "temp": TEMP_UNITS,
}
REQUIRED = ("t", "ax", "ay", "az", "gx", "gy", "gz")


@dataclass(frozen=True)
class ColumnMap:
    """One recording column from the file: ``source`` (a header name or ``#N``), its unit
    and sign."""

    target: str
    source: str
    unit: str
    sign: float = 1.0


def parse_mapping(text: str) -> dict[str, ColumnMap]:
    """``t=time:s,ax=acc_x:g,...`` as target -> :class:`ColumnMap` (ValueError, one line)."""
    mapping: dict[str, ColumnMap] = {}
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        target, eq, rest = item.partition("=")
        source, colon, unit = rest.rpartition(":")
        target, source, unit = target.strip(), source.strip(), unit.strip()
        if not eq or not colon or not source or not unit:
            raise ImportInputError(f"--map item {item!r}: write TARGET=COLUMN:UNIT, e.g. "
                                   "ax=acc_x:g")
        if target not in TARGETS:
            raise ImportInputError(f"--map item {item!r}: {target!r} is not one of "
                                   f"{', '.join(TARGETS)}")
        units = TARGETS[target]
        key = unit if target not in ("mx", "my", "mz", "temp") else unit.lower()
        if key not in units:
            raise ImportInputError(f"--map item {item!r}: unit {unit!r} for {target}; use one "
                                   f"of {', '.join(units)}")
        if target in mapping:
            raise ImportInputError(f"--map: {target} is mapped twice")
        sign = -1.0 if source.startswith("-") else 1.0
        mapping[target] = ColumnMap(target, source.lstrip("-").strip(), unit, sign)
    missing = [t for t in REQUIRED if t not in mapping]
    if missing:
        raise ImportInputError(f"--map lacks {', '.join(missing)} (t, ax..az and gx..gz are "
                               "required)")
    mags = [t for t in ("mx", "my", "mz") if t in mapping]
    if mags and len(mags) != 3:
        raise ImportInputError("--map: give all three of mx, my, mz or none")
    return mapping


def _index(header: list[str], column: ColumnMap, path: Path, line: int) -> int:
    if column.source.startswith("#") and column.source[1:].isdigit():
        index = int(column.source[1:]) - 1
        if not 0 <= index < len(header):
            raise ImportInputError(f"{path.name}: --map {column.target}: column "
                                   f"{column.source} does not exist (the file has "
                                   f"{len(header)})")
        return index
    if column.source not in header:
        raise ImportInputError(f"{path.name}: --map {column.target}: no column "
                               f"{column.source!r} in the header on line {line} "
                               f"({', '.join(header)[:120]})")
    return header.index(column.source)


def read_generic(path: str | Path, mapping: str | dict[str, ColumnMap], *,
                 delimiter: str = ",") -> ImportedData:
    """The samples of a CSV file through ``mapping`` (see the module)."""
    path = Path(path)
    columns = parse_mapping(mapping) if isinstance(mapping, str) else mapping
    header, header_line = split_header(path, delimiter=delimiter)
    targets = list(columns)
    indices = [_index(header, columns[t], path, header_line) for t in targets]
    exact_time = columns["t"].unit in ("ns", "us")
    try:
        values, lines = read_table(path, header, header_line=header_line, delimiter=delimiter,
                                   columns=indices, integer=(indices[0],) if exact_time else ())
    except ImportInputError as exc:
        if not exact_time or "integer" not in str(exc):
            raise
        values, lines = read_table(path, header, header_line=header_line, delimiter=delimiter,
                                   columns=indices)
    by_target = dict(zip(targets, values))
    raw_t = by_target["t"]
    check_time(path, raw_t, lines)
    first = raw_t[0]
    t_s = (raw_t - first) * TIME_UNITS[columns["t"].unit]

    def si(target: str) -> np.ndarray:
        column = columns[target]
        units = TARGETS[target]
        key = column.unit if target not in ("mx", "my", "mz", "temp") else column.unit.lower()
        return column.sign * by_target[target].astype(np.float64) * units[key]

    accel = np.column_stack([si(a) for a in ("ax", "ay", "az")])
    gyro = np.column_stack([si(g) for g in ("gx", "gy", "gz")])
    mag = np.column_stack([si(m) for m in ("mx", "my", "mz")]) if "mx" in columns else None
    temp = None
    if "temp" in columns:
        temp = si("temp") - (273.15 if columns["temp"].unit.lower() == "k" else 0.0)
    first_value = int(first) if raw_t.dtype.kind == "i" else float(first)
    return ImportedData(
        t_s=np.asarray(t_s, dtype=np.float64), accel_m_s2=accel, gyro_rad_s=gyro, mag_ut=mag,
        temp_degc=temp,
        origin=origin(FORMAT, path, f"inclinometer {__version__}",
                      mapping={t: {"column": c.source, "unit": c.unit, "sign": int(c.sign)}
                               for t, c in columns.items()},
                      time_origin={"value": first_value, "unit": columns["t"].unit}),
        device={"name": path.name, "sensor": "unknown"},
        magnetometer=None if mag is None else {"chip": "unknown", "path": "imported"},
    )

