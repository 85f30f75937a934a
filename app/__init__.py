"""Inclinometer: an LSM6DSOX tilt meter and IMU workbench.

Layers, lowest first (imports only point downwards; ``lint-imports`` checks it):

- ``app.core``: numpy-only data model, orientation maths, filters, calibration, ring buffers,
  the processing pipeline and the recording format. No Qt, no drivers.
- ``drivers``: device I/O (simulator, serial, replay). May use ``app.core``; no Qt.
- ``app.services``: what runs devices: the session and its worker thread (QtCore), the
  headless recorder, simulator streams for scoring.
- ``app.documents``: the calibration report and the fault curves, painted with QtGui.
- ``app.gui``, the command line (``app.cli``, one module per sub-command) and
  ``app.launcher`` (the ``inclinometer`` entry point: the window or a sub-command): widgets
  and commands. The GUI reaches devices only through ``app.services``; the command line
  never imports the GUI.
"""

from app.core.version import __version__

__all__ = ["__version__"]
