"""Read a EuRoC / Kalibr ``imu0.csv`` into :class:`~.imported.ImportedData`.

The file (EuRoC MAV dataset, Kalibr's ``kalibr_bagcreater``) has one header line and seven
columns::

    #timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],
    a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]

integer nanoseconds, angular rate in rad/s and specific force in m/s^2 in the IMU's frame
(level, +z up reads +9.81 on z: the recording's conventions). The timestamps are read as
integers (they are often Unix time in ns, beyond float64's 2^53) and become seconds from the
first one, whose exact value is kept in the origin (``time_origin``), so an export can give
the same integers back.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from app.core.interop.imported import (
    ImportedData,
    ImportInputError,
    check_time,
    origin,
    read_table,
    split_header,
)
from app.core.version import __version__

FORMAT = "euroc"
COLUMNS = ("timestamp", "w_RS_S_x", "w_RS_S_y", "w_RS_S_z", "a_RS_S_x", "a_RS_S_y", "a_RS_S_z")
UNITS = ("ns", "rad s^-1", "rad s^-1", "rad s^-1", "m s^-2", "m s^-2", "m s^-2")
"""The units each column's header states in brackets (EuRoC's spelling)."""
_UNIT = re.compile(r"\[([^\]]*)\]")


def looks_like_euroc(header: list[str]) -> bool:
    """True for EuRoC's header (seven fields, the first naming a timestamp in ns, the rest
    ``w_RS_S_*`` and ``a_RS_S_*``), or Kalibr's ``timestamp,omega_x..,alpha_x..``."""
    if len(header) != 7 or "timestamp" not in header[0].lower():
        return False
    names = [h.split("[")[0].strip().lower() for h in header[1:]]
    euroc = [c.lower() for c in COLUMNS[1:]]
    kalibr = ["omega_x", "omega_y", "omega_z", "alpha_x", "alpha_y", "alpha_z"]
    return names in (euroc, kalibr)


def read_euroc(path: str | Path) -> ImportedData:
    """The samples of an ``imu0.csv``; :class:`ImportInputError` names a bad line and column."""
    path = Path(path)
    header, header_line = split_header(path)
    if not looks_like_euroc(header):
        raise ImportInputError(
            f"{path.name}: line {header_line} is not a EuRoC/Kalibr IMU header (expected "
            f"'#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z [m s^-2]', got "
            f"{','.join(header)[:120]!r})")
    for name, text, unit in zip(COLUMNS, header, UNITS):
        stated = _UNIT.search(text)
        if stated and stated.group(1).strip() != unit:
            raise ImportInputError(f"{path.name}: line {header_line}, column {name!r}: unit "
                                   f"[{stated.group(1)}], expected [{unit}]")
    names = [h.lstrip("#").strip() for h in header]
    (stamps, *rest), lines = read_table(path, names, header_line=header_line, integer=(0,))
    check_time(path, stamps, lines)
    first = int(stamps[0])
    t_s = (stamps - first) / 1e9  # exact integer difference, then one correctly rounded divide
    gyro = np.column_stack(rest[0:3])
    accel = np.column_stack(rest[3:6])
    return ImportedData(
        t_s=t_s, accel_m_s2=accel, gyro_rad_s=gyro,
        origin=origin(FORMAT, path, f"inclinometer {__version__}",
                      time_origin={"value": first, "unit": "ns"},
                      units={"t": "ns", "w": "rad/s", "a": "m/s^2"}),
        device={"name": "EuRoC/Kalibr IMU", "sensor": "unknown"},
    )
