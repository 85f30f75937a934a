"""Read x-IMU3 data (the x-IMU3 GUI's data logger export) with x-io's ``ximu3csv`` package.

The x-IMU3 GUI logs into a folder with one sub-folder per device (``x-IMU3 - SERIAL (USB)``),
each holding one CSV file per message type and ``Command.json`` (the device's ping: name,
interface, serial number; the time). This reads a device's:

- ``Inertial.csv``: ``Timestamp (us)``, ``Gyroscope X..Z (deg/s)``, ``Accelerometer X..Z (g)``:
  rad/s = deg/s x pi/180, m/s^2 = g x 9.80665 (standard gravity). The x-IMU3's axes are those
  printed on its housing, right-handed, and its accelerometer reads +1 g on z lying flat: the
  recording's conventions, so no axis changes.
- ``Magnetometer.csv`` (optional): ``X..Z Axis (a.u.)``. x-IMU3's calibrated magnetometer is in
  arbitrary units, 1 a.u. being the magnitude of the field where it was calibrated (about
  50 uT, its manual says): no exact conversion exists. It is imported only when the caller
  gives that field (``mag_au_ut``, uT per a.u.), and the scale used is stated in the
  metadata; a file in uT is taken as it is. Its samples go on the next inertial row (the
  format's rule for a slower magnetometer).
- ``Temperature.csv`` (optional): held from each sample on (it comes once a second).

Time: the device's microsecond timestamps, as seconds from the first inertial sample (the
first timestamp is kept in the origin, ``time_origin``).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import tempfile
import warnings
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np

from app.core.interop.imported import (
    DEG,
    ImportedData,
    ImportInputError,
    check_time,
    hold_on_rows,
    origin,
    place_on_rows,
    read_table,
    split_header,
)
from app.core.samples import STANDARD_GRAVITY_M_S2
from app.core.version import __version__

FORMAT = "x-imu3-csv"
INERTIAL = "Inertial.csv"
MAGNETOMETER = "Magnetometer.csv"
TEMPERATURE = "Temperature.csv"
COMMAND = "Command.json"
INERTIAL_UNITS = ("us", "deg/s", "deg/s", "deg/s", "g", "g", "g")
"""The units the x-IMU3 GUI states in ``Inertial.csv``'s header, column by column."""
MAG_UNITS_UT = {"a.u.": None, "uT": 1.0, "µT": 1.0}
"""Magnetometer units: a.u. needs the caller's scale (None), uT is taken as it is."""
_UNIT = re.compile(r"\(([^)]*)\)\s*$")


def _unit(text: str) -> str:
    found = _UNIT.search(text)
    return found.group(1).strip() if found else ""


def looks_like_inertial(header: list[str]) -> bool:
    """True for ``Inertial.csv``'s header (``Timestamp (us),Gyroscope X (deg/s),...``)."""
    return (len(header) == 7 and header[0].lower().startswith("timestamp")
            and header[1].lower().startswith("gyroscope")
            and header[4].lower().startswith("accelerometer"))


def device_folders(path: Path) -> list[Path]:
    """The device folders at ``path``: itself (it has ``Inertial.csv``), or its sub-folders
    that have one (a data logger folder)."""
    if (path / INERTIAL).is_file():
        return [path]
    return sorted(d for d in path.iterdir()
                  if d.is_dir() and not d.name.startswith(".") and (d / INERTIAL).is_file())


def find_device(path: str | Path, device: str = "") -> tuple[Path, Path]:
    """The device folder to import and its inertial file: ``path`` is ``Inertial.csv`` (or a
    copy of it under another name), a device folder or a data logger folder (then ``device``,
    a part of the folder's name such as the serial number, chooses among several)."""
    path = Path(path)
    if path.is_file():
        if path.name != INERTIAL:
            header, _ = split_header(path)
            if not looks_like_inertial(header):
                raise ImportInputError(f"{path}: not an x-IMU3 {INERTIAL} (its header is "
                                       f"{','.join(header)[:100]!r})")
        return path.parent, path
    if not path.is_dir():
        raise ImportInputError(f"{path}: no such file or folder")
    folders = device_folders(path)
    if device:
        folders = [f for f in folders if device.lower() in f.name.lower()]
    if len(folders) == 1:
        return folders[0], folders[0] / INERTIAL
    if not folders:
        raise ImportInputError(f"{path}: no x-IMU3 device folder (one with {INERTIAL})"
                               + (f" matching {device!r}" if device else ""))
    names = ", ".join(repr(f.name) for f in folders)
    raise ImportInputError(f"{path} holds {len(folders)} devices ({names}); choose one with "
                           "--device PART-OF-ITS-NAME")


@dataclass(frozen=True)
class _Table:
    path: Path
    header: list[str]
    header_line: int


def _header(path: Path, name: str, width: int) -> _Table | None:
    if not path.is_file():
        return None
    header, line = split_header(path)
    if len(header) != width:
        raise ImportInputError(f"{name}: line {line} has {len(header)} columns, an x-IMU3 "
                               f"{name} has {width}")
    return _Table(path, header, line)


def _read_device(files: dict[str, Path]) -> Any:
    """The ``ximu3csv.Device`` of ``files`` (x-IMU3's file name -> the file). ximu3csv reads
    a data logger folder of device folders, so the files are linked under their x-IMU3 names
    into a device folder of a temporary one. What it prints instead of raising is dropped:
    :func:`_values` finds the bad line itself."""
    import ximu3csv

    wanted = (ximu3csv.DataMessageType.INERTIAL, ximu3csv.DataMessageType.MAGNETOMETER,
              ximu3csv.DataMessageType.TEMPERATURE)
    printed = io.StringIO()
    with tempfile.TemporaryDirectory(prefix="inclinometer-ximu3-") as root:
        linked = Path(root) / "device"
        linked.mkdir()
        for name, source in files.items():
            os.symlink(source.resolve(), linked / name)
        with contextlib.redirect_stdout(printed), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy's "Empty input file": found by _values
            devices = ximu3csv.read(Path(root).resolve(), wanted)
    return devices[0]


def _values(table: _Table, array: np.ndarray, width: int) -> np.ndarray:
    """ximu3csv's array of a table, checked; a row it could not read is found and named."""
    if array.ndim == 2 and array.shape[0] and array.shape[1] >= width \
            and np.isfinite(array[:, :width]).all():
        return array[:, :width]
    # ximu3csv (numpy.genfromtxt) gives NaN for a bad field and nothing for a bad row: find it.
    read_table(table.path, table.header, header_line=table.header_line)
    raise ImportInputError(f"{table.path.name}: ximu3csv could not read it")


def magnetometer_needs_scale(path: str | Path, device: str = "") -> bool:
    """True when the device's ``Magnetometer.csv`` is in a.u. (the caller must give the field
    that 1 a.u. stands for to import it)."""
    folder, _ = find_device(path, device)
    table = _header(folder / MAGNETOMETER, MAGNETOMETER, 4)
    return table is not None and MAG_UNITS_UT.get(_unit(table.header[1]), 1.0) is None


def _check_units(table: _Table, expected: tuple[str, ...]) -> None:
    for column, unit in zip(table.header, expected):
        if _unit(column) != unit:
            raise ImportInputError(f"{table.path.name}: line {table.header_line}, column "
                                   f"{column!r}: unit ({_unit(column)}), expected ({unit})")


def read_ximu3(path: str | Path, *, device: str = "", mag_au_ut: float | None = None
               ) -> ImportedData:
    """An x-IMU3 device's logged data (see the module). ``mag_au_ut``: the field magnitude in
    uT that 1 a.u. stands for (without it an a.u. magnetometer is left out, with a warning)."""
    folder, inertial_path = find_device(path, device)
    inertial = _header(inertial_path, INERTIAL, 7)
    if inertial is None:
        raise ImportInputError(f"{inertial_path}: not a file")
    _check_units(inertial, INERTIAL_UNITS)
    magnetometer = _header(folder / MAGNETOMETER, MAGNETOMETER, 4)
    temperature = _header(folder / TEMPERATURE, TEMPERATURE, 2)
    files = {INERTIAL: inertial_path}
    for table in (magnetometer, temperature):
        if table is not None:
            files[table.path.name] = table.path
    if (folder / COMMAND).is_file():
        files[COMMAND] = folder / COMMAND
    record = _read_device(files)
    rows = _values(inertial, record.inertial._csv, 7)
    t_us = rows[:, 0]
    steps_bad = np.flatnonzero(np.diff(t_us) <= 0)
    if steps_bad.size:  # the line numbers need the file's own rows (blank lines)
        _, lines = read_table(inertial.path, inertial.header,
                              header_line=inertial.header_line, columns=(0,))
        check_time(inertial.path, t_us, lines)
    first_us = float(t_us[0])
    t_s = (t_us - first_us) / 1e6
    warnings: list[str] = []
    mag = None
    mag_meta = None
    units: dict[str, Any] = {"t": "us", "gyroscope": "deg/s", "accelerometer": "g"}
    if magnetometer is not None and len(record.magnetometer.timestamp):
        unit = _unit(magnetometer.header[1])
        if unit not in MAG_UNITS_UT:
            raise ImportInputError(f"{MAGNETOMETER}: line {magnetometer.header_line}: unit "
                                   f"({unit}) unknown (expected a.u. or uT)")
        scale = MAG_UNITS_UT[unit] if MAG_UNITS_UT[unit] is not None else mag_au_ut
        if scale is None:
            warnings.append(f"{MAGNETOMETER} left out: its unit is x-IMU3's a.u. (1 a.u. = the "
                            "field where it was calibrated); give that field in uT "
                            "(--mag-au-ut, about 50) to import it")
        else:
            values = _values(magnetometer, record.magnetometer._csv, 4)
            mag = place_on_rows(t_s, (values[:, 0] - first_us) / 1e6, values[:, 1:4] * scale)
            units["magnetometer"] = unit
            units["magnetometer_ut_per_unit"] = scale
            mag_meta = {"chip": "x-IMU3 magnetometer", "path": "imported", "unit_in_file": unit,
                        "ut_per_unit": scale,
                        "odr_hz": _rate(values[:, 0] / 1e6)}
    temp = None
    if temperature is not None and len(record.temperature.timestamp):
        values = _values(temperature, record.temperature._csv, 2)
        temp = hold_on_rows(t_s, (values[:, 0] - first_us) / 1e6, values[:, 1])
    name, serial = record.device_name, record.serial_number
    if serial is None:  # an older x-IMU3 GUI's ping (deviceName, serialNumber)
        name, serial = _older_ping(folder / COMMAND)
    name = name or "x-IMU3"
    return ImportedData(
        t_s=t_s, accel_m_s2=rows[:, 4:7] * STANDARD_GRAVITY_M_S2, gyro_rad_s=rows[:, 1:4] * DEG,
        mag_ut=mag, temp_degc=temp,
        origin=origin(FORMAT, inertial.path, f"inclinometer {__version__}, ximu3csv "
                      f"{_package_version('ximu3csv')}", folder=folder.name,
                      time_origin={"value": int(first_us), "unit": "us"}, units=units,
                      device_time=None if record.time is None else record.time.isoformat()),
        device={"name": name, "unique_id": serial or folder.name, "sensor": "x-IMU3",
                "extra": {"interface": record.interface, "serial_number": serial}},
        magnetometer=mag_meta, warnings=warnings,
    )


def _older_ping(path: Path) -> tuple[str | None, str | None]:
    """Name and serial number from a Command.json in the older GUI's spelling."""
    try:
        responses = json.loads(path.read_text(encoding="utf-8"))
        for response in responses:
            ping = response.get("ping") if isinstance(response, dict) else None
            if isinstance(ping, dict):
                name, serial = ping.get("deviceName"), ping.get("serialNumber")
                return (name if isinstance(name, str) else None,
                        serial if isinstance(serial, str) else None)
    except (OSError, ValueError, AttributeError, TypeError):
        pass
    return None, None


def _rate(t_s: np.ndarray) -> float | None:
    steps = np.diff(t_s)
    return float(1.0 / np.median(steps)) if steps.size and np.median(steps) > 0 else None


def _package_version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "?"
