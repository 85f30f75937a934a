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

from app.core.recording.format import (
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
KEY_ARM = "arm"
REFERENCE_SOURCE = "the simulator's true orientation"


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
    if seconds <= 0.0 or not math.isfinite(seconds):
        raise ValueError(f"the duration must be a positive number of seconds, not {seconds!r}")
    if parse_sim_url(url).scenario != Arm.name:
        raise ValueError(f"{url}: not a measuring arm; use sim://arm?links=N&...")
    first = _arm_url(url, 0)
    assert isinstance(first.scenario, Arm)
    links = first.scenario.links
    paths = [out_dir / f"{stem}{k}.csv" for k in range(links)]
    existing = [p for p in paths if p.exists()]
    if existing and not overwrite:
        raise ValueError(f"{existing[0]} exists; choose another directory or allow overwriting")
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for sensor, path in enumerate(paths):
        device = first if sensor == 0 else _arm_url(url, sensor)
        written.append(_record_sensor(device, sensor, seconds, path, overwrite))
    return written


def _true_axes(scenario: Arm, sensor: int) -> dict[str, list[float]]:
    axes = {}
    for joint in (sensor, sensor + 1):
        if 1 <= joint < scenario.links:
            key = f"joint_{joint}_in_sensor_{sensor}"
            axes[key] = [float(v) for v in scenario.axis_in_sensor(joint, sensor)]
    return axes


def _record_sensor(device: SimulatedDevice, sensor: int, seconds: float,
                   path: Path, overwrite: bool = False) -> ArmRecording:
    session = Acquisition(Connection(), detect_faults=False, check_lookalike=False)
    info = session.attach(device)
    scenario = device.scenario
    assert isinstance(scenario, Arm)
    wanted = math.ceil(seconds * device.odr_hz)
    try:
        blocks = [block.uncalibrated for block in session.stream(Until(samples=wanted), 1.0)]
    finally:
        session.close()
    if session.ended.error is not None:
        raise session.ended.error
    t = np.concatenate([b.t_s for b in blocks])[:wanted]
    accel = np.concatenate([b.accel_m_s2 for b in blocks])[:wanted]
    gyro = np.concatenate([b.gyro_rad_s for b in blocks])[:wanted]
    temp = np.concatenate([b.temp_degc for b in blocks])[:wanted]
    ref = np.concatenate([b.reference_quat for b in blocks])[:wanted]
    block_start = np.zeros(wanted)
    block_start[0] = 1.0
    columns = [t, *accel.T, *gyro.T, temp, np.zeros(wanted), block_start, *ref.T]
    names = [*BASE_COLUMNS, "qw", "qx", "qy", "qz"]
    if sensor >= 1:
        t_true = np.arange(wanted) / device.true_odr_hz
        columns.append(scenario.joint_angles_deg(t_true)[:, sensor - 1])
        names.append(JOINT_REFERENCE_COLUMN)
    axes = _true_axes(scenario, sensor)
    arm = {"url": device.url, "links": scenario.links, "sensor": sensor, "true_axes": axes,
           "joint_reference": (f"{JOINT_REFERENCE_COLUMN}: the true angle of hinge {sensor} "
                               f"(between sensors {sensor - 1} and {sensor}), degrees")
           if sensor >= 1 else None}
    metadata = recording_metadata(
        device=info, reference_source=REFERENCE_SOURCE,
        extra={**simulator_metadata(device), KEY_ARM: arm},
    )
    text = metadata_text(metadata) + ",".join(names) + "\n" + format_table(columns)
    write_output(path, text, overwrite=overwrite)  # atomic; never a file not allowed
    return ArmRecording(path, sensor, wanted, axes)
