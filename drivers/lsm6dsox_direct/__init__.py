"""The LSM6DSOX driven register by register over an I2C bus (``lsm6dsox://`` URLs).

- :mod:`~drivers.lsm6dsox_direct.registers`: register map and the configuration sequence table.
- :mod:`~drivers.lsm6dsox_direct.bus`: the :class:`I2CBus` interface.
- :mod:`~drivers.lsm6dsox_direct.fifo`: vectorised decoding of tagged FIFO words.
- :mod:`~drivers.lsm6dsox_direct.driver`: probe, configure, FIFO bursts, self-test.
- :mod:`~drivers.lsm6dsox_direct.device`: :class:`Lsm6dsoxDirectDevice` and its URLs.
- :mod:`~drivers.lsm6dsox_direct.emulated_chip`: the emulated chip (simulator physics).
- :mod:`~drivers.lsm6dsox_direct.mcp2221`: the MCP2221A USB-I2C bridge (EasyMCP2221, lazy).
"""

from drivers.lsm6dsox_direct.bus import I2CBus
from drivers.lsm6dsox_direct.device import Lsm6dsoxDirectDevice
from drivers.lsm6dsox_direct.driver import Lsm6dsoxDriver, SelfTestResult
from drivers.lsm6dsox_direct.registers import configuration_sequence

__all__ = [
    "I2CBus",
    "Lsm6dsoxDirectDevice",
    "Lsm6dsoxDriver",
    "SelfTestResult",
    "configuration_sequence",
]
