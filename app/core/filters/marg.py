"""Shared pieces of the MARG (magnetic, angular rate, gravity) forms of Madgwick and Mahony.

Earth frame: ENU, y toward magnetic north, z up. The measured field ``m`` (sensor frame) is
rotated into the earth frame, ``h = R(q) m``; its reference direction is ``b = (0, |h_xy|, h_z)``:
the same dip as the measurement, horizontal part toward +y. (Madgwick's report and the ``ahrs``
package put it on +x, ``(|h_xy|, 0, h_z)``: an x-north frame; only the horizontal axis differs.)

A magnetometer is slower than the accelerometer: a row without a new field sample (NaN) uses
the last one, *carried along by the gyroscope* (a vector fixed in the earth frame turns by
``-w dt`` in the sensor frame), so the correction keeps the rate the gains were designed for and
a held sample does not lag a turning sensor. A restart forgets the held sample (the sensor may
have turned during the gap), and the heading is then taken at once from the next field sample:
the rotation about the vertical that puts the field's horizontal part on +y.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from app.core.samples import SampleBlock


@njit(cache=True)
def carry_field(hx, hy, hz, gx, gy, gz, dt):  # pragma: no cover - compiled
    """The held field (sensor frame) after the sensor turned at rate (gx, gy, gz) for ``dt``:
    ``h - dt (w x h)``, rescaled to its norm (first order in ``w dt``, exact in length)."""
    if not gx * gx + gy * gy + gz * gz < math.inf:
        return hx, hy, hz
    norm = math.sqrt(hx * hx + hy * hy + hz * hz)
    nx = hx - dt * (gy * hz - gz * hy)
    ny = hy - dt * (gz * hx - gx * hz)
    nz = hz - dt * (gx * hy - gy * hx)
    scale = norm / math.sqrt(nx * nx + ny * ny + nz * nz)
    return nx * scale, ny * scale, nz * scale


@njit(cache=True)
def field_in_earth(qw, qx, qy, qz, mx, my, mz):  # pragma: no cover - compiled
    """``R(q) m``: a sensor-frame vector in the earth frame."""
    ex = (1.0 - 2.0 * (qy * qy + qz * qz)) * mx + 2.0 * (qx * qy - qw * qz) * my \
        + 2.0 * (qx * qz + qw * qy) * mz
    ey = 2.0 * (qx * qy + qw * qz) * mx + (1.0 - 2.0 * (qx * qx + qz * qz)) * my \
        + 2.0 * (qy * qz - qw * qx) * mz
    ez = 2.0 * (qx * qz - qw * qy) * mx + 2.0 * (qy * qz + qw * qx) * my \
        + (1.0 - 2.0 * (qx * qx + qy * qy)) * mz
    return ex, ey, ez


@njit(cache=True)
def heading_from_field(qw, qx, qy, qz, mx, my, mz):  # pragma: no cover - compiled
    """``q`` turned about the earth's vertical so that the field's horizontal part points to +y
    (magnetic north); ``q`` unchanged when the field is vertical."""
    ex, ey, _ = field_in_earth(qw, qx, qy, qz, mx, my, mz)
    if not ex * ex + ey * ey > 0.0:
        return qw, qx, qy, qz
    half = 0.5 * math.atan2(ex, ey)
    c = math.cos(half)
    s = math.sin(half)
    # (c, 0, 0, s) (x) q
    return (c * qw - s * qz, c * qx - s * qy, c * qy + s * qx, c * qz + s * qw)


@njit(cache=True)
def step_field(field, i, held, gx, gy, gz, dt):  # pragma: no cover - compiled
    """Row ``i``'s field: a new sample (stored in ``held``), else the held one carried by the
    gyro. Returns (mx, my, mz, usable)."""
    mx, my, mz = field[i, 0], field[i, 1], field[i, 2]
    n2 = mx * mx + my * my + mz * mz
    if n2 > 0.0 and n2 < math.inf:
        held[0], held[1], held[2] = mx, my, mz
        return mx, my, mz, True
    hx, hy, hz = held[0], held[1], held[2]
    n2 = hx * hx + hy * hy + hz * hz
    if not (n2 > 0.0 and n2 < math.inf):
        return 0.0, 0.0, 0.0, False
    if dt > 0.0:
        hx, hy, hz = carry_field(hx, hy, hz, gx, gy, gz, dt)
        held[0], held[1], held[2] = hx, hy, hz
    return hx, hy, hz, True


def warm_up_block() -> SampleBlock:
    """A few made-up samples with a field on some rows, to compile a MARG kernel before the
    first real block (the base class's warm-up block has no field)."""
    n = 4
    field = np.tile([0.0, 20.0, -40.0], (n, 1))
    field[1::2] = np.nan
    return SampleBlock(np.arange(n) * 0.01, np.tile([0.0, 0.0, 9.81], (n, 1)), np.zeros((n, 3)),
                       np.zeros(n), np.zeros(n, dtype=bool), None, field)


def no_field() -> np.ndarray:
    """A held field that is not there yet (NaN)."""
    return np.full(3, np.nan)
