"""The simulated LSM6DSOX behind ``sim://`` URLs: a product feature, not a test mock.

- :mod:`~drivers.sim.scenarios`: true motions (static, slow-tilt, wobble, vibration, translation,
  tour, interactive) and the :data:`~drivers.sim.scenarios.SCENARIOS` registry.
- :mod:`~drivers.sim.error_model`: a seed-picked unit's errors and the measurement model.
- :mod:`~drivers.sim.options`: ``sim://`` URL parsing and validation.
- :mod:`~drivers.sim.device`: :class:`~drivers.sim.device.SimulatedDevice`, pacing and blocks.
"""

from drivers.sim.device import SimulatedDevice
from drivers.sim.scenarios import SCENARIOS

__all__ = ["SCENARIOS", "SimulatedDevice"]
