"""The processing pipeline: device block -> units -> calibration -> filter -> ring buffers.

A :class:`Pipeline` is plain Python, driven by one thread (the worker) and read by another
(the GUI) only through its ring buffers, which lock. Nothing here knows about Qt.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.core.calibration import IDENTITY_CALIBRATION, SensorCalibration
from app.core.calibration_procedures.level_reference import TareReference
from app.core.field_check import FieldMonitor, FieldReference
from app.core.filters import FILTERS, OrientationFilter, create_filter, default_filter_for
from app.core.filters.base import MAGNETOMETER_PARAMETER
from app.core.heading import magnetic_heading_deg
from app.core.orientation import angles_from_quaternion, inclination_error_deg
from app.core.ring_buffer import RingBuffer
from app.core.samples import RawBlock, SampleBlock, convert_raw_block

MAX_WINDOW_S = 60.0
"""The longest time window the views may ask for."""

SAMPLE_COLUMNS = {
    "t": 1, "accel": 3, "gyro": 3, "temp": 1, "gap": 1, "ref_quat": 4,
    # Before calibration (SI units): what calibration procedures and recordings need.
    "raw_accel": 3, "raw_gyro": 3,
}
ORIENTATION_COLUMNS = {
    "t": 1, "quat": 4, "roll": 1, "pitch": 1, "tilt": 1, "direction": 1, "gap": 1,
    # The magnetic heading of +x (app.core.heading) where the filter takes it from a field in
    # the block; NaN otherwise (another filter's heading is arbitrary) and near vertical.
    "heading": 1,
    # From the reference orientation when the source knows it (NaN otherwise):
    "ref_roll": 1, "ref_pitch": 1, "ref_tilt": 1, "incl_error": 1,
}


FIELD_COLUMNS = {
    "t": 1, "mag": 3, "raw_mag": 3, "accel": 3, "norm": 1, "dip": 1, "gap": 1,
}
"""One row per field sample (a magnetometer runs slower than the accelerometer): the
calibrated field ``mag`` (uT, the accelerometer's frame) and before calibration ``raw_mag``,
the calibrated accelerometer at the same row, ``|m|`` and the dip against gravity (degrees,
positive down; NaN where the sensor was not steady, :mod:`app.core.field_check`), and ``gap``
(lost data since the previous field sample)."""


REFERENCE_COLUMNS = ("ref_roll", "ref_pitch", "ref_tilt", "incl_error")
COMPARISON_COLUMNS = {"t": 1, "roll": 1, "pitch": 1, "tilt": 1, "incl_error": 1}


def require_online(name: str) -> None:
    """Raise ValueError when ``name`` is an offline filter (a smoother): it needs the whole
    recording in one ``process`` call and must never be fed a live stream block by block.

    Unknown names pass (``create_filter`` reports them with the list of known ones).
    """
    cls = FILTERS.get(name)
    if cls is not None and cls.offline:
        raise ValueError(
            f"{cls.title or name} ({name!r}) is an offline filter: it needs the whole recording "
            f"at once and cannot run on a live stream; run it over a recording instead "
            f"(inclinometer replay IN.csv --filter {name} --out ANGLES.csv)"
        )


def capacity_for(odr_hz: float, window_s: float = MAX_WINDOW_S) -> int:
    """Ring rows needed to hold ``window_s`` at ``odr_hz`` with a 10 % margin."""
    return max(1024, math.ceil(odr_hz * window_s * 1.1))


@dataclass(slots=True)
class PipelineCounters:
    """Running totals since the pipeline was (re)configured."""

    samples: int = 0
    blocks: int = 0
    lost_samples: int = 0
    gaps: int = 0
    filter_cpu_s: float = 0.0
    """Thread CPU time spent in conversion, calibration, filtering and buffering."""


class Pipeline:
    """Turns raw device blocks into buffered samples and orientation.

    Parameters
    ----------
    odr_hz : expected sample rate, used to size the ring buffers.
    filter_name : the initial filter (see :data:`app.core.filters.FILTERS`); None: the default
        for the source (:func:`app.core.filters.default_filter_for` ``has_magnetometer``),
        which then follows each new source (:meth:`adopt_source`) until a filter is chosen.
    """

    def __init__(self, odr_hz: float = 104.0, filter_name: str | None = None,
                 has_magnetometer: bool = False) -> None:
        self.calibration: SensorCalibration = IDENTITY_CALIBRATION
        self.level_reference: TareReference | None = None
        self.follows_source = filter_name is None
        """The filter is the source's default (none was chosen): a new source with or without
        a magnetometer brings its own default (:meth:`adopt_source`)."""
        filter_name = filter_name or default_filter_for(has_magnetometer)
        require_online(filter_name)
        self.filter: OrientationFilter = create_filter(filter_name)
        self.counters = PipelineCounters()
        self.samples = RingBuffer(1024, SAMPLE_COLUMNS)
        self.orientation = RingBuffer(1024, ORIENTATION_COLUMNS)
        self.comparisons: dict[str, OrientationFilter] = {}
        """Filters run side by side with the main one, on the same calibrated samples."""
        self.comparison_buffers: dict[str, RingBuffer] = {}
        self.field = RingBuffer(1024, FIELD_COLUMNS)
        """Field samples, for a source with a magnetometer (empty otherwise)."""
        self.field_monitor = FieldMonitor()
        self.field_reference: FieldReference | None = None
        """The World Magnetic Model's field where the sensor is, handed to every filter
        (:meth:`set_field_reference`); None: not known."""
        self._field_gap = False
        self.uncalibrated: SampleBlock | None = None
        """The last block in SI units before calibration (for monitors of the sensor itself,
        such as the fault detector, so they need not convert it again)."""
        self._capacity = 1024
        self.configure(odr_hz)

    def configure(self, odr_hz: float) -> None:
        """Size the buffers for a sample rate and start afresh (a new device connected)."""
        capacity = capacity_for(odr_hz)
        self._capacity = capacity
        self.samples = RingBuffer(capacity, SAMPLE_COLUMNS)
        self.orientation = RingBuffer(capacity, ORIENTATION_COLUMNS)
        # A magnetometer runs at most as fast as the accelerometer: the same rows suffice.
        self.field = RingBuffer(capacity, FIELD_COLUMNS)
        self.field_monitor.reset()
        self._field_gap = False
        self.comparison_buffers = {
            name: RingBuffer(capacity, COMPARISON_COLUMNS) for name in self.comparisons
        }
        self.counters = PipelineCounters()
        self.filter.reset()
        for comparison in self.comparisons.values():
            comparison.reset()

    # -- configuration ----------------------------------------------------------------------
    def set_filter(self, name: str, **values: Any) -> OrientationFilter:
        """Switch to the filter the user chose, mid-stream: it stays for every source; it
        starts from the current orientation.

        Raises ValueError for an offline filter (see :func:`require_online`).
        """
        new_filter = self.set_source_filter(name, **values)
        self.follows_source = False
        return new_filter

    def set_source_filter(self, name: str, **values: Any) -> OrientationFilter:
        """Switch to the filter the source asks for (a recording's own), as
        :meth:`set_filter` does, without making it the user's choice."""
        require_online(name)
        new_filter = create_filter(name, **values)
        new_filter.warm_up()
        if self.counters.samples:
            new_filter.reset(self.filter.quaternion, self.filter.last_time_s)
        new_filter.set_field_reference(self.field_reference)
        self.filter = new_filter
        return new_filter

    def set_field_reference(self, reference: FieldReference | None) -> None:
        """The World Magnetic Model's field at the user's place (the Field dock's place and
        date): the 9-axis filters accept a field reference they learn at rest only when it
        agrees with it. Kept for every filter to come."""
        self.field_reference = reference
        for orientation_filter in (self.filter, *self.comparisons.values()):
            orientation_filter.set_field_reference(reference)

    def follow_source(self, has_magnetometer: bool) -> bool:
        """Let the source choose the filter again: its default from now on, for this
        source (with or without a magnetometer) and each new one. Returns whether the
        filter changed."""
        self.follows_source = True
        return self.adopt_source(has_magnetometer)

    def adopt_source(self, has_magnetometer: bool) -> bool:
        """A new source: a filter that follows the source becomes the source's default
        (:func:`app.core.filters.default_filter_for`); a chosen one stays. Returns whether
        the filter changed."""
        name = default_filter_for(has_magnetometer)
        if not self.follows_source or self.filter.name == name:
            return False
        self.set_source_filter(name)
        return True

    def set_filter_parameter(self, name: str, value: Any) -> None:
        self.filter.set_parameter(name, value)

    def set_comparisons(self, names: list[str]) -> list[str]:
        """Run these filters side by side with the main one (by registry name).

        Filters already running keep their state; new ones start on their own from the next
        sample. Returns the names now running. Raises ValueError, changing nothing, when any
        name is an offline filter (see :func:`require_online`).
        """
        for name in names:
            require_online(name)
        running = {}
        buffers = {}
        for name in dict.fromkeys(names):
            if name in self.comparisons:
                running[name] = self.comparisons[name]
                buffers[name] = self.comparison_buffers[name]
                continue
            new_filter = create_filter(name)
            new_filter.warm_up()
            new_filter.set_field_reference(self.field_reference)
            # It starts on its own (from the accelerometer at the next sample): inheriting the
            # main filter's estimate would also inherit its current error.
            running[name] = new_filter
            buffers[name] = RingBuffer(self._capacity, COMPARISON_COLUMNS)
        # Replace whole dicts: a reader in another thread sees either the old or the new one.
        self.comparison_buffers = buffers
        self.comparisons = running
        return list(running)

    def set_calibration(self, calibration: SensorCalibration) -> None:
        self.calibration = calibration

    def set_level_reference(self, reference: TareReference | None) -> None:
        """Report angles relative to a tared attitude (None: relative to true vertical)."""
        self.level_reference = None if reference is None or reference.is_identity else reference

    # -- processing -------------------------------------------------------------------------
    def process(self, raw: RawBlock) -> SampleBlock:
        """Run one device block through every stage and into the ring buffers."""
        cpu_start = time.thread_time()
        uncalibrated = convert_raw_block(raw)
        self.uncalibrated = uncalibrated
        block = self.calibration.apply(uncalibrated)
        n = len(block)
        if n == 0:
            return block
        if raw.lost_samples:
            self.counters.lost_samples += raw.lost_samples
        self.counters.gaps += int(np.count_nonzero(block.gap))
        orientation = self.filter.process(block)
        shown_quat = orientation.quat
        angles = orientation.angles
        if self.level_reference is not None:
            # The tare changes what is shown, not what the filter tracks nor the error
            # against the (absolute) reference.
            shown_quat = self.level_reference.apply_quaternion(orientation.quat)
            angles = angles_from_quaternion(shown_quat)
        if block.reference_quat is not None:
            ref = block.reference_quat
            ref_angles = angles_from_quaternion(ref)
            ref_columns = {
                "ref_roll": ref_angles.roll_deg, "ref_pitch": ref_angles.pitch_deg,
                "ref_tilt": ref_angles.tilt_deg,
                "incl_error": inclination_error_deg(orientation.quat, ref),
            }
        else:
            ref = np.full((n, 4), np.nan)
            unknown = np.full(n, np.nan)
            ref_columns = dict.fromkeys(REFERENCE_COLUMNS, unknown)
        self.samples.write(
            {
                "t": block.t_s, "accel": block.accel_m_s2, "gyro": block.gyro_rad_s,
                "temp": block.temp_degc, "gap": block.gap, "ref_quat": ref,
                "raw_accel": uncalibrated.accel_m_s2, "raw_gyro": uncalibrated.gyro_rad_s,
            }
        )
        self.orientation.write(
            {
                "t": block.t_s, "quat": shown_quat, "roll": angles.roll_deg,
                "pitch": angles.pitch_deg, "tilt": angles.tilt_deg,
                "direction": angles.direction_deg, "gap": block.gap,
                "heading": self._heading(block, shown_quat), **ref_columns,
            }
        )
        if block.mag_ut is not None:
            self._write_field(block, uncalibrated)
        for name, comparison in self.comparisons.items():
            output = comparison.process(block)
            error = (
                ref_columns["incl_error"] if block.reference_quat is None
                else inclination_error_deg(output.quat, block.reference_quat)
            )
            self.comparison_buffers[name].write(
                {
                    "t": block.t_s, "roll": output.angles.roll_deg,
                    "pitch": output.angles.pitch_deg, "tilt": output.angles.tilt_deg,
                    "incl_error": error,
                }
            )
        self.counters.samples += n
        self.counters.blocks += 1
        self.counters.filter_cpu_s += time.thread_time() - cpu_start
        return block

    def takes_heading_from_field(self) -> bool:
        """Whether the filter takes heading from the magnetometer now (a 9-axis filter with
        its magnetometer switch on)."""
        running = self.filter
        if not running.uses_magnetometer:
            return False
        if any(spec.name == MAGNETOMETER_PARAMETER.name for spec in running.parameters):
            return bool(running.get_parameter(MAGNETOMETER_PARAMETER.name))
        return True

    def _heading(self, block: SampleBlock, quat: np.ndarray) -> np.ndarray:
        """The magnetic heading column of a block: NaN unless its heading comes from a field."""
        if block.mag_ut is None or not self.takes_heading_from_field():
            return np.full(len(block), np.nan)
        return magnetic_heading_deg(quat)

    @property
    def has_field(self) -> bool:
        """Whether field samples arrived since the pipeline was configured."""
        return self.field.total_written > 0

    def _write_field(self, block: SampleBlock, uncalibrated: SampleBlock) -> None:
        """The block's field samples (rows with a finite field) into :attr:`field`."""
        assert block.mag_ut is not None and uncalibrated.mag_ut is not None  # a field block
        rows = self.field_monitor.update(block.t_s, block.accel_m_s2, block.mag_ut)
        # A field sample after lost data starts a new line, also when the rows lost lay
        # between two field samples (or in an earlier block without one).
        lost = np.cumsum(block.gap)
        if not len(rows):
            self._field_gap |= bool(lost[-1] > 0)
            return
        at = lost[rows.rows]
        gap = at > np.concatenate([[0], at[:-1]])
        gap[0] |= self._field_gap
        self._field_gap = bool(lost[-1] > at[-1])
        self.field.write({
            "t": rows.t_s, "mag": rows.mag_ut, "raw_mag": uncalibrated.mag_ut[rows.rows],
            "accel": rows.accel_m_s2, "norm": rows.norm_ut, "dip": rows.dip_deg, "gap": gap,
        })

