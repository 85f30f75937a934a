"""Record a simulated measuring arm (``sim://arm``): one v1 file per sensor, with the truth.

:func:`record_arm` runs ``sim://arm?...&sensor=K`` for every link ``K`` of one arm (one seed,
so one consistent arm), as fast as possible, and writes ``DIR/sensorK.csv`` each: the standard
columns (raw samples, temperature, gap, block_start, the true orientation ``qw..qz``) and, from
sensor 1 on, ``joint_ref_deg``: the true angle of the hinge between sensor K-1 and sensor K
(an extension within v1, see docs/recording-format.md). The ``arm`` metadata key holds the
true hinge axes in both sensors' frames, for scoring an axis estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.arm import (
    COLUMN_AZIMUTH,
    ArmLayout,
    Link,
    LinkCapture,
    Placements,
    ThetaZero,
    capture_link,
    forward,
    placement_pose,
)
from app.core.arm.layout import ALONG_X, PITCH_UP, VERTICAL
from app.core.calibration import MagnetometerCalibration
from app.core.devices import DeviceInfo
from app.core.earth_field import DEFAULT_PLACE
from app.core.field_check import wmm_reference
from app.core.recording.format import (
    MAG_COLUMNS,
    metadata_text,
    recording_metadata,
    simulator_metadata,
)
from app.core.recording.writer import BASE_COLUMNS, format_table
from app.core.safe_output import write_output
from app.services.acquisition import Acquisition, Until
from app.services.connection import Connection
from drivers.sim.device import SimulatedDevice
from drivers.sim.options import parse_sim_url
from drivers.sim.scenarios import Arm

JOINT_REFERENCE_COLUMN = "joint_ref_deg"
THETA_REFERENCE_COLUMN = "theta_ref_deg"
KEY_ARM = "arm"
REFERENCE_SOURCE = "the simulator's true orientation"
CAPTURE_S = 1.0
"""Seconds of each hold a placement averages (the middle of the hold), as the panel's Capture."""
SHOULDER_HEIGHT_MM = 200.0
"""The layout's column length: the simulator's arm has its upper arm's hinge at the grip, so
any height will do; it only shifts Z."""


@dataclass(frozen=True)
class ArmRecording:
    """One written sensor file of an arm and what the benchmark scores against."""

    path: Path
    sensor: int
    samples: int
    true_axes: dict[str, list[float]]
    """``"joint_K_in_sensor_S"`` -> the true hinge axis (3,) in that sensor's frame."""


def _arm_url(url: str, sensor: int) -> SimulatedDevice:
    return SimulatedDevice(url, realtime=False, sensor=sensor, block=4096)


def record_arm(
    url: str, seconds: float, out_dir: Path, *, stem: str = "sensor", overwrite: bool = False
) -> list[ArmRecording]:
    """Write one recording per sensor of the arm ``url`` (``sim://arm?...``) into ``out_dir``.

    Raises ValueError for a URL that is not ``sim://arm``, a non-positive duration or a file
    that exists (unless ``overwrite``); DeviceError for a bad option.
    """
    return record_arm_placements(url, seconds, out_dir, stem=stem, overwrite=overwrite)[0]


def record_arm_placements(
    url: str, seconds: float, out_dir: Path, *, stem: str = "sensor", overwrite: bool = False,
    placements: int = 0, capture_s: float = CAPTURE_S,
) -> tuple[list[ArmRecording], ArmPlacements | None]:
    """:func:`record_arm`, and with ``placements`` > 0 (``sim://arm?column=1`` with a
    magnetometer) the first ``placements`` placements measured (:func:`measure_placements`);
    the recording then lasts at least until the last one's hold ends."""
    if seconds <= 0.0 or not math.isfinite(seconds):
        raise ValueError(f"the duration must be a positive number of seconds, not {seconds!r}")
    if parse_sim_url(url).scenario != Arm.name:
        raise ValueError(f"{url}: not a measuring arm; use sim://arm?links=N&...")
    first = _arm_url(url, 0)
    assert isinstance(first.scenario, Arm)
    if placements:
        if not first.scenario.column:
            raise ValueError(f"{url}: placements are measured on a column arm; add column=1")
        if first.mag_chip is None:
            raise ValueError(f"{url}: theta is measured with the magnetometers; add "
                             "mag=lis3mdl or mag=lis2mdl")
        windows = first.scenario.placement_windows(placements)
        seconds = max(seconds, windows[-1][1] + 0.1)
    links = first.scenario.links
    paths = [out_dir / f"{stem}{k}.csv" for k in range(links)]
    existing = [p for p in paths if p.exists()]
    if existing and not overwrite:
        raise ValueError(f"{existing[0]} exists; choose another directory or allow overwriting")
    out_dir.mkdir(parents=True, exist_ok=True)
    written, streams, devices = [], [], []
    for sensor, path in enumerate(paths):
        device = first if sensor == 0 else _arm_url(url, sensor)
        stream = _stream_sensor(device, math.ceil(seconds * device.odr_hz))
        written.append(_record_sensor(device, sensor, seconds, path, overwrite, stream))
        streams.append(stream)
        devices.append(device)
    measured = (measure_placements(streams, devices, placements, capture_s)
                if placements else None)
    return written, measured


def _true_axes(scenario: Arm, sensor: int) -> dict[str, list[float]]:
    axes = {}
    for joint in (sensor, sensor + 1):
        if 1 <= joint < scenario.links:
            key = f"joint_{joint}_in_sensor_{sensor}"
            axes[key] = [float(v) for v in scenario.axis_in_sensor(joint, sensor)]
    return axes


@dataclass(frozen=True)
class _Stream:
    """One sensor's samples (uncalibrated SI units) as the acquisition delivered them."""

    info: DeviceInfo
    t: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray
    temp: np.ndarray
    ref: np.ndarray
    mag: np.ndarray | None


def _stream_sensor(device: SimulatedDevice, wanted: int) -> _Stream:
    session = Acquisition(Connection(), detect_faults=False, check_lookalike=False)
    info = session.attach(device)
    try:
        blocks = [block.uncalibrated for block in session.stream(Until(samples=wanted), 1.0)]
    finally:
        session.close()
    if session.ended.error is not None:
        raise session.ended.error
    mag = (None if blocks[0].mag_ut is None
           else np.concatenate([b.mag_ut for b in blocks])[:wanted])  # type: ignore[misc]
    t, accel, gyro, temp, ref = (np.concatenate([getattr(b, name) for b in blocks])[:wanted]
                                 for name in ("t_s", "accel_m_s2", "gyro_rad_s", "temp_degc",
                                              "reference_quat"))
    return _Stream(info, t, accel, gyro, temp, ref, mag)


def _record_sensor(device: SimulatedDevice, sensor: int, seconds: float,
                   path: Path, overwrite: bool = False,
                   stream: _Stream | None = None) -> ArmRecording:
    scenario = device.scenario
    assert isinstance(scenario, Arm)
    wanted = math.ceil(seconds * device.odr_hz)
    if stream is None:
        stream = _stream_sensor(device, wanted)
    info, t, accel, gyro, temp, ref = (stream.info, stream.t, stream.accel, stream.gyro,
                                       stream.temp, stream.ref)
    wanted = len(t)
    block_start = np.zeros(wanted)
    block_start[0] = 1.0
    columns = [t, *accel.T, *gyro.T, temp, np.zeros(wanted), block_start]
    names = [*BASE_COLUMNS]
    if stream.mag is not None:  # the metadata names the magnetometer: its columns go along
        columns += [*stream.mag.T]
        names += list(MAG_COLUMNS)
    columns += [*ref.T]
    names += ["qw", "qx", "qy", "qz"]
    t_true = np.arange(wanted) / device.true_odr_hz
    if sensor >= 1:
        columns.append(scenario.joint_angles_deg(t_true)[:, sensor - 1])
        names.append(JOINT_REFERENCE_COLUMN)
    if scenario.column:
        columns.append(scenario.column_angles_deg(t_true)[:, 0])
        names.append(THETA_REFERENCE_COLUMN)
    axes = _true_axes(scenario, sensor)
    arm = {"url": device.url, "links": scenario.links, "sensor": sensor, "true_axes": axes,
           "joint_reference": (f"{JOINT_REFERENCE_COLUMN}: the true angle of hinge {sensor} "
                               f"(between sensors {sensor - 1} and {sensor}), degrees")
           if sensor >= 1 else None}
    if scenario.column:
        arm["column"] = {
            "theta_reference": (f"{THETA_REFERENCE_COLUMN}: the column's true angle from the "
                                "base's x axis, counter-clockwise seen from above, degrees"),
            "base_azimuth_deg": scenario.base_azimuth_deg,
            "link_lengths_m": [float(v) for v in scenario.link_lengths_m],
            "hinge_axis": list(Arm.COLUMN_HINGE_AXIS),
            "hold_s": float(scenario.params["hold"]),
            "transition_s": float(scenario.params["transition"]),
        }
    metadata = recording_metadata(
        device=info, reference_source=REFERENCE_SOURCE,
        extra={**simulator_metadata(device), KEY_ARM: arm},
    )
    text = metadata_text(metadata) + ",".join(names) + "\n" + format_table(columns)
    write_output(path, text, overwrite=overwrite)  # atomic; never a file not allowed
    return ArmRecording(path, sensor, wanted, axes)


# -- placements of a column arm (sim://arm?column=1): R, theta and Z, measured ----------------


@dataclass(frozen=True)
class PlacementRow:
    """One placement: what was measured and what the simulator knows."""

    index: int
    t_s: tuple[float, float]
    """The capture's window, true seconds."""
    measured: dict[str, float] | None
    """R, azimuth_deg (theta), Z, column_azimuth_deg, or None when refused."""
    truth: dict[str, float]
    refused: str = ""


@dataclass(frozen=True)
class ArmPlacements:
    """The placements of one arm run: every row, the repeatability of the accepted ones."""

    layout: ArmLayout
    rows: list[PlacementRow]
    placements: Placements
    zero: ThetaZero
    calibration: str

    def to_dict(self) -> dict:
        return {
            "layout": self.layout.to_dict(),
            "theta_zero": {"psi_deg": self.zero.psi_deg, "source": self.zero.source},
            "magnetometer_calibration": self.calibration,
            "rows": [{"index": r.index, "t_s": list(r.t_s), "measured": r.measured,
                      "truth": r.truth, "refused": r.refused or None} for r in self.rows],
            "repeatability": self.placements.to_dict(),
        }


def arm_layout_of(scenario: Arm) -> ArmLayout:
    """The app's layout of a ``column=1`` arm: the column, then one hinge per simulated link
    (lengths in mm, the simulator's)."""
    links = [Link("column", SHOULDER_HEIGHT_MM, axis=VERTICAL, direction=VERTICAL)]
    names = ["upper arm", "forearm"] if scenario.links == 2 else [
        f"link {k + 1}" for k in range(scenario.links)]
    links += [Link(name, float(length) * 1000.0, axis=PITCH_UP, direction=ALONG_X)
              for name, length in zip(names, scenario.link_lengths_m)]
    return ArmLayout(tuple(links), "mm", "sim://arm column")


def _true_angles(scenario: Arm, t_s: float) -> np.ndarray:
    """The layout's joint angles at true time ``t_s``: theta from the base's x, then hinges."""
    return scenario.column_angles_deg(np.array([t_s]))[0]


def measure_placements(streams: list[_Stream], devices: list[SimulatedDevice], count: int,
                       capture_s: float = CAPTURE_S) -> ArmPlacements:
    """Capture ``count`` placements of a column arm from every sensor's stream, as the panel
    does: each link's accelerometer and field averaged over the middle ``capture_s`` of each
    hold, theta from the field with its zero at the first accepted placement.

    The field is corrected with each unit's exact ``calibrate-mag`` correction (the
    simulator's truth), and checked against the WMM field of the URL's place and date.
    """
    scenario = devices[0].scenario
    assert isinstance(scenario, Arm) and scenario.column
    layout = arm_layout_of(scenario)
    first = devices[0]
    reference = wmm_reference(first.options.place or DEFAULT_PLACE, first.options.date)
    corrections = [MagnetometerCalibration.from_json(d.unit_errors.magnetometer.calibration_json())
                   if d.unit_errors.magnetometer is not None else None for d in devices]
    placements = Placements(layout.base_position, layout.unit)
    zero: ThetaZero | None = None
    zero_psi_true = math.nan
    rows = []
    hold = float(scenario.params["hold"])
    if not 0.0 < capture_s <= hold:
        raise ValueError(f"the capture ({capture_s:g} s) must fit in a hold ({hold:g} s)")
    for index, (start, end) in enumerate(scenario.placement_windows(count)):
        middle = 0.5 * (start + end)
        window = (middle - 0.5 * capture_s, middle + 0.5 * capture_s)
        captures: list[LinkCapture | None] = [None]
        for sensor, (stream, device, correction) in enumerate(
                zip(streams, devices, corrections), start=1):
            rows_in = slice(math.ceil(window[0] * device.true_odr_hz),
                            math.floor(window[1] * device.true_odr_hz))
            mag = None
            if stream.mag is not None and correction is not None:
                mag = correction.apply(stream.mag[rows_in])
            captures.append(capture_link(sensor, stream.accel[rows_in], mag, reference,
                                         layout.links[sensor].name))
        truth_angles = _true_angles(scenario, middle)
        truth_psi = scenario.base_yaw_deg + float(truth_angles[0])
        if zero is None:
            result = placement_pose(layout, captures)
            if result.pose is not None and result.theta is not None:
                zero = ThetaZero(result.theta.psi_deg, f"placement {index + 1}")
                zero_psi_true = truth_psi
                result = placement_pose(layout, captures, zero)
        else:
            result = placement_pose(layout, captures, zero)
        # The truth in the frame the measurement uses: x where the column pointed at the zero
        # (magnetic north before one is set).
        in_frame = truth_angles.copy()
        in_frame[0] = ThetaZero(90.0 if zero is None else zero_psi_true).theta(truth_psi)
        coordinates = forward(layout, in_frame).coordinates()
        truth = {"R": coordinates["R"], "azimuth_deg": coordinates["azimuth_deg"],
                 "Z": coordinates["Z"], COLUMN_AZIMUTH: float((90.0 - truth_psi) % 360.0),
                 "theta_deg": float(in_frame[0])}
        if result.pose is None:
            rows.append(PlacementRow(index, window, None, truth, result.refused))
            continue
        placements.capture(result.pose.end[None, :], result.theta_source,
                           result.column_azimuth_deg)
        measured = result.pose.coordinates()
        rows.append(PlacementRow(index, window, {
            "R": measured["R"], "azimuth_deg": measured["azimuth_deg"], "Z": measured["Z"],
            COLUMN_AZIMUTH: result.column_azimuth_deg,
            "theta_deg": float(result.pose.joint_angles_deg[0])}, truth))
    calibration = "each unit's exact calibrate-mag correction (the simulator's truth)"
    return ArmPlacements(layout, rows, placements, zero or ThetaZero(), calibration)
