"""What the window shows when the device session reports: connected, lost, its stream's
status, the filter, the board's own messages, the self-test and the fault detector."""

from __future__ import annotations

from typing import Any

from app.core.devices import DeviceInfo, is_measured_reference
from app.core.filters import FILTERS
from app.core.self_test import SelfTestReport
from app.services.devices import has_simulator_controls, is_replay_url
from app.services.replay_control import replay_caption
from app.services.stream_status import StreamStatus

MainWindow = Any
"""The window this part works for (not imported: the parts sit below
:mod:`app.gui.main_window`, which assembles them)."""

DEVICE_MESSAGE_WARNING = 2
DEVICE_MESSAGE_ERROR = 3
"""Levels of a device's own messages (the link protocol's LOG levels)."""


class DeviceEvents:
    """Shows the session's events in ``window``'s device bar, docks, status bar and banner."""

    def __init__(self, window: MainWindow) -> None:
        self.window = window
        self.awaiting_board = False
        """The cable was pulled: the session waits for the board."""
        self.fault_shown = ""

    def on_connected(self, info: DeviceInfo) -> None:
        window = self.window
        if self.awaiting_board:  # the board is back: the unplug warning is over
            self.awaiting_board = False
            window.banner.hide()
        window.device_bar.select_url(info.url)
        window.device_bar.set_state("streaming", "Streaming")
        window.device_panel.show_info(info)
        window.plots.name_reference(is_measured_reference(info))
        window.status_device.setText(
            f"{replay_caption(info) or info.name}  ·  {info.odr_hz:.1f} Hz")
        window.replay_bar.setVisible(is_replay_url(info.url))
        if has_simulator_controls(info.url):
            window.simulator_panel.show_url(info.url)
            params = info.extra.get("scenario_params", {})
            if "roll" in params and "pitch" in params:
                window.simulator_panel.set_target(float(params["roll"]), float(params["pitch"]))
        else:
            window.simulator_panel.set_interactive(False)
        window.window_settings.save_device_url(info.url)
        window.log(f"Connected to {info.name} ({info.url}), id {info.unique_id}")

    def on_disconnected(self, reason: str) -> None:
        window = self.window
        if reason:
            window.device_bar.set_state("error", "Disconnected: error")
        else:
            window.device_bar.set_state("disconnected", "Disconnected")
        window.status_view.show_disconnected()
        self.show_health(None, "")
        window.simulator_panel.set_interactive(False)
        window.log("Disconnected" + (f": {reason}" if reason else ""))

    def on_reconnecting(self, message: str) -> None:
        self.awaiting_board = True
        window = self.window
        window.device_bar.set_state("stalled", "Unplugged — waiting for the board…")
        window.banner.show_message(message)
        window.log(message, error=True)

    def on_status(self, status: StreamStatus) -> None:
        window = self.window
        window.plots_dock.on_status()
        if status.replay is not None:
            window.replay_bar.show_position(*status.replay)
        self.show_health(status.health, status.fault)
        if status.overview is not None:
            window.replay_bar.show_overview(status.overview, status.gaps_s or ())
        stalled = status.measured_rate_hz <= 0.0 and status.samples > 0
        lost = f"  ·  lost {status.lost_samples:,}" if status.lost_samples else ""
        text = f"{status.measured_rate_hz:.1f} Hz{lost}"
        if status.replay is not None and not status.replay.playing:  # not stalled: paused
            stalled, text = False, "Replay ended" if status.replay.ended else "Replay paused"
        window.device_bar.set_state("stalled" if stalled else "streaming", text)
        window.status_rate.setText(
            f"{status.samples:,} samples  ·  lost {status.lost_samples:,}  ·  "
            f"pipeline {100 * status.pipeline_load:.1f} %"
        )
        window.device_panel.show_status(status)

    def show_health(self, health: dict[str, str] | None, fault: str) -> None:
        """Lights, and the banner while the reading cannot be trusted."""
        window = self.window
        window.health_lights.show_health(health)
        if fault and fault != self.fault_shown and not self.awaiting_board:
            window.banner.show_message(f"The reading cannot be trusted: {fault}. Click the "
                                       "channel lights in the status bar to reset latched "
                                       "faults.")
        elif not fault and self.fault_shown and not self.awaiting_board:
            window.banner.hide()
        self.fault_shown = fault

    def reset_health(self) -> None:
        self.window.session.requestHealthReset.emit()
        self.window.log("Fault detection reset: latched faults cleared, noise levels learnt "
                        "afresh")

    def on_filter_changed(self, name: str, values: dict) -> None:
        window = self.window
        window.filter_panel.show_filter(name, values)
        window.status_filter.setText(f"Filter: {FILTERS[name].title}")
        window.window_settings.save_filter(name, values)

    def on_comparisons_changed(self, names: list) -> None:
        window = self.window
        window.filter_panel.show_comparisons(names)
        window.plots.set_comparisons([(name, FILTERS[name].title) for name in names])
        window.window_settings.save_comparisons(names)

    def on_self_test_finished(self, report: SelfTestReport | None, error: str) -> None:
        window = self.window
        window.device_panel.show_self_test(report, error)
        if report is None:
            window.show_error(f"Self-test not run: {error}")
        else:
            window.log(report.summary(), error=not report.passed)

    def on_device_message(self, level: int, text: str) -> None:
        """A message from the device itself (the board's firmware): errors also on the banner."""
        window = self.window
        info = window.session.device_info
        source = info.name if info is not None else "device"
        if level >= DEVICE_MESSAGE_ERROR:
            window.show_error(f"{source}: {text}")
        else:
            prefix = "warning: " if level == DEVICE_MESSAGE_WARNING else ""
            window.log(f"{source}: {prefix}{text}")

    def on_fault_events(self, events: list) -> None:
        """The detector's events go to Messages (faults in red)."""
        for event in events:
            self.window.log(
                f"sensor {event.channel} {event.kind} at {event.t:.2f} s: {event.message}",
                error=event.severity == "fault")
