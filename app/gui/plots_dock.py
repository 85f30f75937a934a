"""The Live plots dock: the plots under a bar with the time window and the range selection
(drag a time range on the angle plot for its statistics)."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QCheckBox, QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.gui.plots import LivePlots

PLOT_WINDOWS_S = (2, 5, 10, 20, 30, 60)


class PlotsDock(QWidget):
    """The plots and their bar; ``statistics(start, end)`` gives a range's statistics."""

    def __init__(self, plots: LivePlots, statistics: Callable[[float, float], object],
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.plots = plots
        self.statistics = statistics
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 0, 4, 4)
        bar = QHBoxLayout()
        bar.addWidget(QLabel("Window"))
        self.window_combo = QComboBox()
        for seconds in PLOT_WINDOWS_S:
            self.window_combo.addItem(f"{seconds} s", seconds)
        self.window_combo.setCurrentIndex(self.window_combo.findData(10))
        self.window_combo.currentIndexChanged.connect(
            lambda _index: plots.set_window(self.window_combo.currentData()))
        bar.addWidget(self.window_combo)
        self.range_box = QCheckBox("Select range")
        self.range_box.setToolTip("Drag a time range on the angle plot for its statistics")
        self.range_box.toggled.connect(self._on_range_toggled)
        bar.addWidget(self.range_box)
        self.range_label = QLabel()
        self.range_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        bar.addWidget(self.range_label, 1)
        bar.addStretch(1)
        layout.addLayout(bar)
        layout.addWidget(plots, 1)
        plots.rangeSelected.connect(self.show_range_statistics)

    def choose_window(self, seconds: int) -> None:
        """Show ``seconds`` if it is one of the windows offered."""
        index = self.window_combo.findData(seconds)
        if index >= 0:
            self.window_combo.setCurrentIndex(index)

    def _on_range_toggled(self, enabled: bool) -> None:
        self.plots.set_range_selection(enabled)
        if not enabled:
            self.range_label.setText("")

    def show_range_statistics(self, *_args: object) -> None:
        """Statistics per angle over the range selected on the angle plot."""
        selected = self.plots.selected_range()
        if selected is None:
            return
        result = self.statistics(*selected)
        if result is None:
            self.range_label.setText("No data in the selected range")
            return
        parts = [
            f"{name} mean {a.mean:+.3f}° std {a.std:.3f}° min {a.minimum:+.3f}° "
            f"max {a.maximum:+.3f}° spread {a.spread:.3f}°"
            for name, a in (("roll", result.roll), ("pitch", result.pitch))
        ]
        self.range_label.setText(
            f"{result.duration_s:.2f} s, {result.samples:,} samples · " + " · ".join(parts)
        )

    def on_status(self) -> None:
        """New data: a selected range's statistics follow them."""
        if self.range_box.isChecked():
            self.show_range_statistics()
