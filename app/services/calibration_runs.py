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
from app.core.samples import SampleBlock, convert_raw_block
from drivers.errors import DeviceError
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
    info = device.open()
    blocks: list[SampleBlock] = []
    note = ""
    try:
        first: float | None = None
        t_last = math.nan
        while True:
            try:
                raw = device.read(READ_TIMEOUT_S)
            except DeviceError as exc:
                held = 0.0 if first is None else t_last - first
                note = f"the device failed after {held:.1f} s: {exc}"
                break
            if raw is None or len(raw) == 0:
                if getattr(device, "at_end", False):
                    note = "the source ended"
                    break
                continue
            block = convert_raw_block(raw)
            if first is None:
                first = float(block.t_s[0])
            inside = int((block.t_s < first + seconds).sum())
            if inside < len(block):
                blocks.append(_head(block, inside))
                break
            blocks.append(block)
            t_last = float(block.t_s[-1])
            if progress is not None:
                progress(min(1.0, (t_last - first) / seconds))
    except KeyboardInterrupt:
        note = "interrupted (Ctrl-C): the samples read so far are used"
    finally:
        device.close()
    device_json = to_json_value({name: getattr(info, name, None) for name in (
        "url", "name", "unique_id", "sensor", "odr_hz", "odr_nominal_hz", "accel_fs_g",
        "gyro_fs_dps", "firmware")})
    unit = getattr(device, "unit_errors", None)
    return CapturedStream(
        block=concatenate_blocks(blocks),
        settings=SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps,
                                getattr(info, "sensor", "LSM6DSOX") or "LSM6DSOX"),
        device=device_json,
        unit_errors=unit.as_dict() if unit is not None and hasattr(unit, "as_dict") else None,
        note=note,
    )


def _head(block: SampleBlock, count: int) -> SampleBlock:
    ref = block.reference_quat
    return SampleBlock(
        t_s=block.t_s[:count], accel_m_s2=block.accel_m_s2[:count],
        gyro_rad_s=block.gyro_rad_s[:count], temp_degc=block.temp_degc[:count],
        gap=block.gap[:count], reference_quat=None if ref is None else ref[:count],
    )

