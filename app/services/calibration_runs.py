"""Streams for the calibration lab: seconds of a live device, or a recording, as one block.

``inclinometer calibrate --device URL --seconds N`` and ``inclinometer allan --device URL
--seconds N`` read a device here (the loop that runs a device belongs in app.services); the
maths is :mod:`app.core.calibration_procedures.offline` and :mod:`app.core.allan`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from app.core.calibration_procedures.profiles import SensorSettings
from app.core.evaluation import concatenate_blocks
from app.core.recording.format import to_json_value
from app.core.samples import SampleBlock
from app.services.acquisition import Acquisition, Block, Subscriber, Until
from app.services.connection import Connection
from drivers.registry import create_device

READ_TIMEOUT_S = 0.5


@dataclass
class CapturedStream:
    """Uncalibrated samples with what is known of their device.

    ``unit_errors`` is a simulated unit's truth (None for real hardware); ``note`` says how
    the capture ended when it ended early.
    """

    block: SampleBlock
    settings: SensorSettings
    device: dict[str, Any] = field(default_factory=dict)
    unit_errors: dict[str, Any] | None = None
    note: str = ""

    @property
    def unique_id(self) -> str:
        return str(self.device.get("unique_id") or "")


def capture_device(
    url: str,
    seconds: float,
    *,
    progress: Callable[[float], None] | None = None,
) -> CapturedStream:
    """Read ``seconds`` of device time from ``url`` (uncalibrated, as the wizard sees them).

    Raises :class:`drivers.errors.DeviceError` when the device cannot be opened; a device that
    fails later ends the capture early (``note`` says why).
    """
    if not math.isfinite(seconds) or seconds <= 0:
        raise ValueError("--seconds must be a positive number")
    device = create_device(url)
    blocks: list[SampleBlock] = []
    session = Acquisition(Connection(), detect_faults=False, check_lookalike=False,
                          subscribers=[_Capture(blocks, seconds, progress)])
    info = session.attach(device)
    try:
        end = session.run(Until(duration_s=seconds), READ_TIMEOUT_S)
    finally:
        session.close()
    note = ""
    if end.reason == "device":
        held = 0.0 if end.first_t_s is None or end.last_t_s is None else (
            end.last_t_s - end.first_t_s)
        note = f"the device failed after {held:.1f} s: {end.message}"
    elif end.reason == "end":
        note = "the source ended"
    elif end.reason == "interrupted":
        note = "interrupted (Ctrl-C): the samples read so far are used"
    device_json = to_json_value({name: getattr(info, name, None) for name in (
        "url", "name", "unique_id", "sensor", "odr_hz", "odr_nominal_hz", "accel_fs_g",
        "gyro_fs_dps", "firmware")})
    unit = device.unit_errors
    return CapturedStream(
        block=concatenate_blocks(blocks),
        settings=SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps,
                                info.sensor or "LSM6DSOX"),
        device=device_json,
        unit_errors=None if unit is None else unit.as_dict(),
        note=note,
    )


class _Capture(Subscriber):
    """Keeps the uncalibrated samples and reports how far the capture is."""

    def __init__(self, blocks: list[SampleBlock], seconds: float,
                 progress: Callable[[float], None] | None) -> None:
        self.blocks = blocks
        self.seconds = seconds
        self.progress = progress
        self.first: float | None = None

    def on_block(self, block: Block) -> None:
        samples = block.uncalibrated
        self.blocks.append(samples)
        if self.first is None:
            self.first = float(samples.t_s[0])
        if self.progress is not None:
            self.progress(min(1.0, (float(samples.t_s[-1]) - self.first) / self.seconds))
