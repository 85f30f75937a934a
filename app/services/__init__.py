"""Application services: what runs devices and sources, between the drivers and the views.

- :mod:`~app.services.session` / :mod:`~app.services.worker`: a device session on its own
  thread (QtCore), wiring the parts below;
- :mod:`~app.services.connection`, :mod:`~app.services.acquisition`,
  :mod:`~app.services.recording_control`, :mod:`~app.services.replay_control`,
  :mod:`~app.services.calibration_state`, :mod:`~app.services.stream_status`: those parts,
  without Qt;
- :mod:`~app.services.board_health`: a board's own counters (STATUS) and the messages a rise
  brings;
- :mod:`~app.services.devices`: what the views may ask about devices and the simulator;
- :mod:`~app.services.recorder`: the headless recording loop (``inclinometer record``);
- :mod:`~app.services.simulation`: simulator streams for scoring filters.

Services may import ``app.core`` and ``drivers``; only the GUI and the command line import
them (the contracts are in pyproject.toml's ``[tool.importlinter]``).
"""
