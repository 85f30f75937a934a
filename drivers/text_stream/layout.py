"""Which column is which, and the units, from the lines seen while connecting.

See :mod:`drivers.text_lines` for the rules (headers, headerless rows, unit guesses).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from drivers.errors import DeviceOpenError
from drivers.text_stream.lexer import MAG_CHANNELS, TIME_UNITS, Line, canonical_column


# -- layout ----------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Layout:
    """How lines map to channels, and the units (decided while connecting)."""

    kind: str
    """``columns`` (numeric rows) or ``labelled``."""
    n_columns: int = 0
    columns: dict[str, int] = field(default_factory=dict)
    """Channel -> column index (``columns`` layouts)."""
    accel_unit: str = "g"
    gyro_unit: str = "dps"
    time_unit: str = "host"
    """s, ms, us, or host (no time column used)."""
    has_gyro: bool = True
    mag_unit: str | None = None
    """uT, gauss or mgauss; None: the stream has no magnetometer."""

    def describe(self) -> str:
        if self.kind == "labelled":
            what = "labelled lines"
        else:
            order = sorted(self.columns, key=self.columns.get)  # type: ignore[arg-type]
            what = f"{self.n_columns} columns ({','.join(order)})"
        units = f"accel in {self.accel_unit}, gyro in {self.gyro_unit}, time {self.time_unit}"
        if self.mag_unit is not None:
            units += f", field in {self.mag_unit}"
        return f"{what}; {units}"


def default_columns(n: int, rows: np.ndarray) -> dict[str, int] | None:
    """The channel of each column of a headerless row of ``n`` numbers (module docstring)."""
    nine = ("ax", "ay", "az", "gx", "gy", "gz", *MAG_CHANNELS)
    if n in (3, 6, 9):
        return {name: i for i, name in enumerate(nine[:n])}
    if n in (4, 7, 10):
        first = rows[:, 0]
        rising = len(first) >= 2 and bool(np.all(np.diff(first) > 0))
        single_time = len(first) == 1 and first[0] == round(first[0]) and first[0] > 200
        lead = "t" if rising or single_time else "temp"
        names = (lead, *nine[: n - 1])
        return {name: i for i, name in enumerate(names)}
    if n == 8:
        return {name: i for i, name in enumerate(("t", *nine[:6], "temp"))}
    return None


def columns_from_names(names: list[str], time_col: str | None) -> tuple[dict[str, int], dict]:
    """Channel -> index from header or ``columns=`` names, and the unit hints they carry."""
    columns: dict[str, int] = {}
    hints: dict[str, str] = {}
    wanted_time = time_col.strip().lower() if time_col else None
    for index, name in enumerate(names):
        if name.strip() in ("", "_", "-", "skip"):
            continue
        if wanted_time is not None and name.strip().lower() == wanted_time:
            columns["t"] = index
            continue
        meaning = canonical_column(name)
        if meaning is None or meaning.channel in columns:
            continue
        if meaning.channel == "t" and wanted_time is not None:
            continue
        columns[meaning.channel] = index
        if meaning.unit:
            hints[meaning.channel[0] if meaning.channel not in ("temp", "t") else meaning.channel
                  ] = meaning.unit
    return columns, hints



# -- deciding the layout while connecting --------------------------------------------------
def _guess_accel_unit(magnitude: float) -> str:
    if magnitude < 4.0:
        return "g"
    return "m/s2" if magnitude < 60.0 else "mg"


def _guess_gyro_unit(accel_unit: str, magnitude: float) -> str:
    unit = {"g": "dps", "m/s2": "rad/s", "mg": "mdps"}[accel_unit]
    if unit == "rad/s" and magnitude > 35.0:
        unit = "dps"
    if unit == "dps" and magnitude > 2500.0:
        unit = "mdps"
    return unit


def _guess_mag_unit(magnitude: float) -> str:
    """The earth's field is 25 to 65 uT: 0.25 to 0.65 gauss, 250 to 650 mgauss."""
    if magnitude < 2.0:
        return "gauss"
    return "uT" if magnitude < 200.0 else "mgauss"


def _guess_time_unit(times: np.ndarray, arrivals: np.ndarray) -> str:
    steps = np.diff(times)
    steps = steps[steps > 0]
    if len(steps) and arrivals[-1] - arrivals[0] > 0.05:
        host_period = (arrivals[-1] - arrivals[0]) / (len(arrivals) - 1)
        step = float(np.median(steps))
        return min(TIME_UNITS, key=lambda u: abs(math.log(step * TIME_UNITS[u] / host_period)))
    return "ms" if np.all(times == np.round(times)) else "s"


class LayoutOptions(Protocol):
    """What :func:`decide_layout` reads of a ``text://`` URL's options."""

    @property
    def port(self) -> str: ...
    @property
    def columns(self) -> tuple[str, ...] | None: ...
    @property
    def accel_unit(self) -> str | None: ...
    @property
    def gyro_unit(self) -> str | None: ...
    @property
    def time_unit(self) -> str | None: ...
    @property
    def time_col(self) -> str | None: ...


def decide_layout(
    lines: list[Line], arrivals: list[float], options: LayoutOptions
) -> Layout | None:
    """Layout and units from the lines seen while connecting (None: nothing usable)."""
    numeric = [(ln, t) for ln, t in zip(lines, arrivals) if ln.kind == "numbers"]
    labelled = [ln for ln in lines if ln.kind == "labelled"
                and any(k[0] in "ag" for k in ln.values if k != "temp")]
    headers = [ln for ln in lines if ln.kind == "header"]
    hints: dict[str, str] = {}
    if options.columns or headers or (numeric and len(numeric) >= len(labelled)):
        names = list(options.columns) if options.columns else headers[-1].names if headers else None
        if names is not None:
            columns, hints = columns_from_names(names, options.time_col)
            n = len(names)
        else:
            n = Counter(len(ln.numbers) for ln, _ in numeric).most_common(1)[0][0]
            rows = np.array([ln.numbers for ln, _ in numeric if len(ln.numbers) == n])
            found = default_columns(n, rows)
            if found is None:
                raise DeviceOpenError(
                    f"{options.port}: lines hold {n} numbers, and no header says which is "
                    "which; add columns=... to the URL (e.g. columns=t,ax,ay,az,gx,gy,gz,_)"
                )
            columns = found
        if not any(c in columns for c in ("ax", "ay", "az")):
            raise DeviceOpenError(
                f"{options.port}: no accelerometer column among {names}; name them with "
                "columns=... (e.g. columns=ax,ay,az,gx,gy,gz)"
            )
        rows_n = [(ln.numbers, t) for ln, t in numeric if len(ln.numbers) == n]
        if not rows_n:
            return None
        values = np.array([r for r, _ in rows_n])
        row_times = np.array([t for _, t in rows_n])
        has_gyro = any(c in columns for c in ("gx", "gy", "gz"))
        layout = Layout("columns", n, columns, has_gyro=has_gyro)
        accel = values[:, [columns[c] for c in ("ax", "ay", "az") if c in columns]]
        gyro = values[:, [columns[c] for c in ("gx", "gy", "gz") if c in columns]]
        field = (values[:, [columns[c] for c in MAG_CHANNELS]]
                 if all(c in columns for c in MAG_CHANNELS) else None)
        time_values = values[:, columns["t"]] if "t" in columns else None
    elif labelled:
        datalog = any(ln.datalog for ln in labelled)
        accel_rows = [[ln.values[k] for k in ("ax", "ay", "az")] for ln in labelled
                      if all(k in ln.values for k in ("ax", "ay", "az"))]
        gyro_rows = [[ln.values[k] for k in ("gx", "gy", "gz")] for ln in labelled
                     if all(k in ln.values for k in ("gx", "gy", "gz"))]
        if not accel_rows:
            return None
        accel = np.array(accel_rows)
        gyro = np.array(gyro_rows) if gyro_rows else np.zeros((1, 3))
        mag_rows = [[ln.values[k] for k in MAG_CHANNELS] for ln in lines
                    if ln.kind == "labelled" and all(k in ln.values for k in MAG_CHANNELS)]
        field = np.array(mag_rows) if mag_rows else None
        for ln in lines:
            if ln.kind != "labelled":
                continue
            if ln.accel_unit:
                hints.setdefault("a", ln.accel_unit)
            if ln.gyro_unit:
                hints.setdefault("g", ln.gyro_unit)
            if ln.mag_unit:
                hints.setdefault("m", ln.mag_unit)
        if datalog:
            hints.setdefault("a", "mg")
            hints.setdefault("g", "mdps")
            hints.setdefault("m", "mgauss")
        layout = Layout("labelled", has_gyro=bool(gyro_rows))
        time_values = None
        row_times = np.array(arrivals)
    else:
        return None

    accel_unit = options.accel_unit or hints.get("a") or _guess_accel_unit(
        float(np.median(np.linalg.norm(accel, axis=1)))
    )
    gyro_unit = options.gyro_unit or hints.get("g") or _guess_gyro_unit(
        accel_unit, float(np.median(np.linalg.norm(gyro, axis=1)))
    )
    time_unit = "host"
    if time_values is not None and options.time_unit != "host":
        time_unit = options.time_unit or hints.get("t") or _guess_time_unit(time_values, row_times)
    mag_unit = None
    if field is not None and len(field):
        mag_unit = hints.get("m") or _guess_mag_unit(
            float(np.median(np.linalg.norm(field, axis=1))))
    columns = dict(layout.columns)
    if time_unit == "host":
        columns.pop("t", None)
    return replace(layout, columns=columns, accel_unit=accel_unit, gyro_unit=gyro_unit,
                   time_unit=time_unit, mag_unit=mag_unit)
