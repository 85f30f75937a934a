"""Inclinometer: an LSM6DSOX tilt meter and IMU workbench.

Layers, lowest first (imports only point downwards):

- ``app.core``: numpy-only data model, orientation maths, filters, calibration, ring buffers
  and the processing pipeline. No Qt.
- ``drivers``: device I/O (simulator, serial, replay). May use ``app.core``; no Qt.
- ``app.worker``: the QtCore worker that moves a device and a pipeline onto a thread.
- ``app.gui``: widgets. They display what the core computed and never do maths themselves.
"""

from app.core.version import __version__

__all__ = ["__version__"]
