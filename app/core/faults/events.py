"""Fault events: what the detector reports, in the binding ``diagnose --json`` form.

One event is one line of ``inclinometer diagnose --json``::

    {"t": 12.5, "channel": "gx", "kind": "stuck", "severity": "fault", "message": "..."}

``t`` is seconds on the device clock at the moment of detection (not of onset).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from typing import Any, Literal

CHANNELS: tuple[str, ...] = ("ax", "ay", "az", "gx", "gy", "gz")
"""The six measurement channels, in the column order of a :class:`SampleBlock`."""
GROUP_CHANNELS: tuple[str, ...] = ("accel", "gyro", "link")
"""Events about a whole sensor or the link rather than one axis."""

KINDS: tuple[str, ...] = (
    "stuck", "dead", "spike", "noise", "saturation", "bias", "gravity", "consistency", "gap",
)
"""Every ``kind`` the detector emits (see docs/fault-detection.md)."""

Severity = Literal["info", "warning", "fault"]
SEVERITIES: tuple[str, ...] = ("info", "warning", "fault")
"""Ordered from least to most serious. ``fault``: the reading cannot be trusted."""


@dataclass(frozen=True, slots=True)
class FaultEvent:
    """One detected fault (or link event).

    Attributes
    ----------
    t : seconds on the device clock when it was detected.
    channel : ``"ax"`` .. ``"gz"``, or ``"accel"`` / ``"gyro"`` (the sensor as a whole) or
        ``"link"`` (lost samples); with a magnetometer also ``"mx"`` .. ``"mz"`` and ``"mag"``
        (the chip as a whole).
    kind : one of :data:`KINDS`.
    severity : one of :data:`SEVERITIES`.
    message : one line for the user.
    """

    t: float
    channel: str
    kind: str
    severity: str
    message: str

    def as_dict(self) -> dict[str, Any]:
        """The binding JSON object (keys t, channel, kind, severity, message)."""
        return asdict(self)

    def to_json(self) -> str:
        """One line of ``diagnose --json``."""
        return json.dumps(self.as_dict())

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FaultEvent:
        """The inverse of :meth:`as_dict` (e.g. from a recording's metadata)."""
        return cls(float(data["t"]), str(data["channel"]), str(data["kind"]),
                   str(data["severity"]), str(data["message"]))


def severity_rank(severity: str) -> int:
    """0 info, 1 warning, 2 fault (-1 for anything else)."""
    return SEVERITIES.index(severity) if severity in SEVERITIES else -1
