"""Inclinometer: an LSM6DSOX tilt meter and IMU workbench.

Layers, lowest first (imports only point downwards; ``lint-imports`` checks it):

- ``app.core``: numpy-only data model, orientation maths, filters, calibration, ring buffers,
  the processing pipeline and the recording format. No Qt, no drivers.
- ``drivers``: device I/O (simulator, serial, replay). May use ``app.core``; no Qt.
- ``app.services``: what runs devices: the session and its worker thread (QtCore), the
  headless recorder, simulator streams for scoring.
- ``app.gui`` and the command line (``app.cli*``): widgets and commands. The GUI reaches
  devices only through ``app.services``.
"""

from app.core.version import __version__

__all__ = ["__version__"]
