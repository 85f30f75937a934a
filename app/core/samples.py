"""Sample blocks: the data model that flows from a device through the pipeline.

Sensor frame and axis conventions (written down once, used everywhere)
----------------------------------------------------------------------
- The sensor frame is the LSM6DSOX's own right-handed x, y, z frame as printed on the chip.
- Acceleration is *specific force* in m/s^2: a sensor lying still with +z up reads
  ``(0, 0, +9.80665)``. The accelerometer therefore measures the "up" direction at rest.
- Angular rate is in rad/s, right-handed about each sensor axis.
- Time is in seconds on the device clock (float64), starting near 0 at connection. It is
  monotonic within a connection; lost samples leave a hole in time and set ``gap``.
- Temperature is in degrees Celsius, one value per sample.
- The magnetic field, when a source has a magnetometer, is in microtesla (uT) in the
  magnetometer's own axes as the driver maps them onto the sensor frame (before calibration:
  the calibration turns them into the accelerometer's frame). A magnetometer runs slower than
  the accelerometer: a row holds a field sample only where a new one arrived, NaN elsewhere.
- A reference orientation, when a source knows one (the simulator, a recording with reference
  columns), is a unit quaternion ``(w, x, y, z)`` rotating sensor-frame vectors into the earth
  frame, earth z up. See :mod:`app.core.orientation` for angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STANDARD_GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True, slots=True)
class ScaleFactors:
    """How a device's raw numbers become SI units (``si = raw * scale + offset``)."""

    accel_m_s2_per_lsb: float
    gyro_rad_s_per_lsb: float
    temp_degc_per_lsb: float = 1.0
    temp_offset_degc: float = 0.0
    mag_ut_per_lsb: float = 1.0


@dataclass(slots=True)
class RawBlock:
    """A block of samples as a device delivers them, before unit conversion.

    Attributes
    ----------
    t_s : (N,) float64, device clock in seconds (already unwrapped by the driver).
    accel_raw, gyro_raw : (N, 3), raw device units (LSB counts for the LSM6DSOX).
    temp_raw : (N,), raw temperature units.
    scale : how to convert the raw arrays to SI.
    gap : (N,) bool, True on the first sample after lost data.
    lost_samples : number of samples known to be lost just before this block.
    reference_quat : (N, 4) sensor-to-earth reference orientation, or None when unknown.
    mag_raw : (N, 3) raw magnetometer units, NaN on rows without a new field sample; None
        when the source has no magnetometer.
    """

    t_s: np.ndarray
    accel_raw: np.ndarray
    gyro_raw: np.ndarray
    temp_raw: np.ndarray
    scale: ScaleFactors
    gap: np.ndarray | None = None
    lost_samples: int = 0
    reference_quat: np.ndarray | None = None
    mag_raw: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def merge_raw_blocks(blocks: list[RawBlock]) -> list[RawBlock]:
    """Join consecutive blocks that share their scale and reference columns into one block each
    (a link that sends a packet per FIFO poll delivers one or two samples a packet; the
    pipeline's cost is mostly per block). What was lost stays marked: a joined block's loss
    before it becomes a ``gap`` on its first sample and adds to ``lost_samples``."""
    merged: list[RawBlock] = []
    run: list[RawBlock] = []

    def flush() -> None:
        if len(run) == 1:
            merged.append(run[0])
        elif run:
            merged.append(_join(run))
        run.clear()

    for block in blocks:
        if not len(block):
            continue
        if run and (block.scale != run[0].scale
                    or (block.reference_quat is None) != (run[0].reference_quat is None)
                    or (block.mag_raw is None) != (run[0].mag_raw is None)):
            flush()
        run.append(block)
    flush()
    return merged


def _join(run: list[RawBlock]) -> RawBlock:
    gaps = []
    for index, block in enumerate(run):
        gap = np.zeros(len(block), dtype=bool) if block.gap is None else np.array(
            block.gap, dtype=bool)
        if index and block.lost_samples:
            gap[0] = True
        gaps.append(gap)
    gap = np.concatenate(gaps)
    return RawBlock(
        t_s=np.concatenate([b.t_s for b in run]),
        accel_raw=np.concatenate([b.accel_raw for b in run]),
        gyro_raw=np.concatenate([b.gyro_raw for b in run]),
        temp_raw=np.concatenate([b.temp_raw for b in run]),
        scale=run[0].scale,
        gap=gap if gap.any() else (None if run[0].gap is None else gap),
        lost_samples=sum(b.lost_samples for b in run),
        reference_quat=None if run[0].reference_quat is None else np.concatenate(
            [b.reference_quat for b in run]),
        mag_raw=None if run[0].mag_raw is None else np.concatenate([b.mag_raw for b in run]),
    )


@dataclass(slots=True)
class SampleBlock:
    """A block of samples in SI units (see the module docstring for conventions).

    Attributes
    ----------
    t_s : (N,) float64 seconds, device clock.
    accel_m_s2 : (N, 3) float64 specific force.
    gyro_rad_s : (N, 3) float64 angular rate.
    temp_degc : (N,) float64.
    gap : (N,) bool, True on the first sample after lost data.
    reference_quat : (N, 4) or None, sensor-to-earth reference orientation.
    mag_ut : (N, 3) float64 magnetic field in uT, NaN on rows without a new field sample;
        None when the source has no magnetometer.
    """

    t_s: np.ndarray
    accel_m_s2: np.ndarray
    gyro_rad_s: np.ndarray
    temp_degc: np.ndarray
    gap: np.ndarray
    reference_quat: np.ndarray | None = None
    mag_ut: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def convert_raw_block(raw: RawBlock) -> SampleBlock:
    """Convert a device block to SI units (the pipeline's first stage)."""
    n = len(raw)
    scale = raw.scale
    accel = np.asarray(raw.accel_raw, dtype=np.float64) * scale.accel_m_s2_per_lsb
    gyro = np.asarray(raw.gyro_raw, dtype=np.float64) * scale.gyro_rad_s_per_lsb
    temp = np.asarray(raw.temp_raw, dtype=np.float64) * scale.temp_degc_per_lsb
    temp += scale.temp_offset_degc
    gap = np.zeros(n, dtype=bool) if raw.gap is None else np.asarray(raw.gap, dtype=bool)
    ref = None if raw.reference_quat is None else np.asarray(raw.reference_quat, np.float64)
    mag = None if raw.mag_raw is None else (
        np.asarray(raw.mag_raw, dtype=np.float64) * scale.mag_ut_per_lsb).reshape(n, 3)
    return SampleBlock(
        t_s=np.asarray(raw.t_s, dtype=np.float64),
        accel_m_s2=accel.reshape(n, 3),
        gyro_rad_s=gyro.reshape(n, 3),
        temp_degc=temp.reshape(n),
        gap=gap,
        reference_quat=ref,
        mag_ut=mag,
    )


def slice_block(block: SampleBlock, start: int, stop: int) -> SampleBlock:
    """Rows ``[start, stop)`` of ``block`` with every column it carries (views, not copies)."""
    if start == 0 and stop >= len(block):
        return block
    ref, mag = block.reference_quat, block.mag_ut
    return SampleBlock(
        block.t_s[start:stop], block.accel_m_s2[start:stop], block.gyro_rad_s[start:stop],
        block.temp_degc[start:stop], block.gap[start:stop],
        None if ref is None else ref[start:stop],
        None if mag is None else mag[start:stop],
    )

