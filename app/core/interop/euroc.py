"""EuRoC/Kalibr IMU CSV (``imu0.csv``): what Kalibr's bag creator (``kalibr_bagcreater``) reads.

One header line, then per sample ``timestamp [ns]`` (an integer) and the angular rate (rad/s)
and specific force (m/s^2), in the column order of :data:`EUROC_HEADER`. Kalibr's reader skips
the first line only, reads columns 0-6 by position, and splits the timestamp's text into
seconds (all digits but the last nine) and nanoseconds (the last nine): timestamps are written
with at least ten digits (zero-padded), so a recording whose clock starts near 0 reads too.
A comment line would break it, so the axis convention and the origin are stated in a sidecar
file beside the CSV (:func:`readme_path`), whose name Kalibr's reader passes over (it takes
files named ``imu*.csv`` only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.core.recording.writer import format_table_bytes

EUROC_HEADER = ("timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y,w_RS_S_z,a_RS_S_x [m s^-2],"
                "a_RS_S_y,a_RS_S_z")
"""The header line (Kalibr's column order: time, gyroscope x y z, accelerometer x y z)."""
TIMESTAMP_DIGITS = 10
"""Kalibr's reader needs a digit before the last nine (the seconds); zero-padded to this."""


def timestamps_ns(t_s: np.ndarray) -> np.ndarray:
    """Integer nanoseconds of times in seconds (rounded); ValueError for negative times."""
    t = np.asarray(t_s, dtype=np.float64)
    if len(t) and not (np.all(np.isfinite(t)) and t.min() >= 0.0):
        raise ValueError("a time before 0 s or not a number: EuRoC timestamps are unsigned "
                         "nanoseconds")
    return np.round(t * 1e9).astype(np.int64)


def euroc_rows(t_ns: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray) -> bytes:
    """The CSV rows (no header) for these samples; shortest round-trip float text.

    ValueError when a gyroscope or accelerometer value is not finite (Kalibr's reader would
    stop at its empty field).
    """
    gyro = np.asarray(gyro_rad_s, dtype=np.float64).reshape(-1, 3)
    accel = np.asarray(accel_m_s2, dtype=np.float64).reshape(-1, 3)
    if len(gyro) == 0:
        return b""
    if not (np.all(np.isfinite(gyro)) and np.all(np.isfinite(accel))):
        raise ValueError("a gyroscope or accelerometer value is not a number: the EuRoC format "
                         "has no empty fields")
    values = format_table_bytes([*gyro.T, *accel.T]).splitlines()
    stamps = [b"%0*d" % (TIMESTAMP_DIGITS, v) for v in np.asarray(t_ns, np.int64).tolist()]
    return b"".join(b"%s,%s\n" % pair for pair in zip(stamps, values, strict=True))


def readme_path(csv_path: str | Path) -> Path:
    """The sidecar beside ``imu0.csv``: ``imu0.README.txt``."""
    path = Path(csv_path)
    return path.with_name(f"{path.stem}.README.txt")


def euroc_readme(csv_name: str, lines: list[str]) -> str:
    """The sidecar's text: what the CSV holds, then ``lines`` (frame, origin, time axis)."""
    return "\n".join([
        f"{csv_name}: IMU samples in the EuRoC/Kalibr CSV layout, written by inclinometer export.",
        f"Header: {EUROC_HEADER}",
        "Columns: timestamp in integer nanoseconds (zero-padded to at least "
        f"{TIMESTAMP_DIGITS} digits for Kalibr's bag creator), angular rate in rad/s, specific "
        "force in m/s^2 (gravity included: a level sensor reads about 9.81 on its up axis).",
        *lines,
    ]) + "\n"
