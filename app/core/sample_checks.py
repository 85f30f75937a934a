"""Rows no sensor can have produced: NaN, infinite or absurdly large samples.

An LSM6DSOX reads at most 16 g and 2000 dps, in counts: a sample that is not a finite number,
or is a million times beyond that, comes from a damaged or forged file. Analyses that sum
squares (Allan variance, the fault detector's statistics) would turn it into NaN or an
overflow, so they refuse such rows with a message naming how many and where.
"""

from __future__ import annotations

import numpy as np

IMPLAUSIBLE_ABS = 1e6
"""No accelerometer (m/s^2), gyroscope (rad/s) or temperature (degC) sample reaches this."""


def implausible_rows(*columns: np.ndarray) -> np.ndarray:
    """(N,) True where any of the (N,) or (N, k) ``columns`` is NaN, infinite or beyond
    :data:`IMPLAUSIBLE_ABS` in size."""
    bad: np.ndarray | None = None
    for column in columns:
        values = np.asarray(column, dtype=float)
        rows = ~(np.abs(values) < IMPLAUSIBLE_ABS)  # NaN compares False: it counts as bad
        rows = rows.reshape(len(values), -1).any(axis=1)
        bad = rows if bad is None else bad | rows
    return np.zeros(0, dtype=bool) if bad is None else bad


def implausible_message(t_s: np.ndarray, bad: np.ndarray, what: str) -> str | None:
    """The message for rows ``bad`` (None when there are none)."""
    count = int(np.count_nonzero(bad))
    if count == 0:
        return None
    first = int(np.argmax(bad))
    at = f"t = {float(t_s[first]):.6g} s" if first < len(t_s) else f"row {first}"
    return (f"{count} sample(s) of {what} are not finite numbers or are beyond "
            f"{IMPLAUSIBLE_ABS:g} (first at {at}): not sensor readings, the file is damaged")
