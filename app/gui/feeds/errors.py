"""The Filter dock's error table (each filter's error against the simulator's truth)."""

from __future__ import annotations

import numpy as np

from app.core.comparison import summarize_errors
from app.core.filters import FILTERS
from app.gui.feeds.frame import Frame
from app.gui.feeds.screen import ScreenPresence
from app.gui.filter_panel import FilterPanel

ERROR_TABLE_INTERVAL_S = 0.5


class ErrorTableFeed:
    """Refreshes the table at a low rate while it can be seen and its input changed."""

    def __init__(self, panel: FilterPanel, session, plots) -> None:
        self.panel = panel
        self.session = session
        self.plots = plots
        self.shown = ScreenPresence(panel)
        self.key: tuple | None = None
        self.last_update = -np.inf

    def frame(self, frame: Frame, total: int) -> None:
        pipeline = self.session.pipeline
        key = (total, self.plots.window_s, tuple(pipeline.comparison_buffers))
        if key == self.key or not self.shown(frame.now):
            return
        if frame.now - self.last_update >= ERROR_TABLE_INTERVAL_S:
            self.last_update = frame.now
            self.key = key
            self.update()
        else:
            frame.defer(self.last_update + ERROR_TABLE_INTERVAL_S, pending=False)

    def update(self) -> None:
        """Refresh the filter panel's error table."""
        pipeline = self.session.pipeline
        window = self.plots.window_s
        rows = [summarize_errors(pipeline.orientation, pipeline.filter.title, window)]
        for name, ring in pipeline.comparison_buffers.items():
            rows.append(summarize_errors(ring, FILTERS[name].title, window))
        self.panel.show_errors([(r.name, r.rms_deg, r.max_deg) for r in rows])
