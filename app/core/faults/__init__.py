"""Sensor fault detection and isolation (issue 15): see docs/fault-detection.md.

- :class:`FaultDetector` per block -> :class:`FaultEvent` s (the ``diagnose --json`` lines).
- :class:`SensorSpec`: what the detector knows about the sensor.
- :mod:`app.core.faults.injection`: fault specs (``KIND:CHANNEL[:SIZE]@START[-END]``) and
  their application to samples.
"""

from app.core.faults.detector import FaultDetector
from app.core.faults.events import CHANNELS, KINDS, SEVERITIES, FaultEvent
from app.core.faults.spec import SensorSpec

__all__ = ["CHANNELS", "KINDS", "SEVERITIES", "FaultDetector", "FaultEvent", "SensorSpec"]
