"""Record from the GUI, then replay the file as a device with the transport controls."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PySide6.QtCore import QSettings

from app.core.recording import read_recording
from app.gui import theme
from app.gui.main_window import MainWindow
from app.services.replay_control import SEEK_LEAD_IN_S
from app.services.session import DeviceSession

TIMEOUT_MS = 30_000


@pytest.fixture
def window(qtbot, qapp, tmp_path):
    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(DeviceSession(), settings, "sim://wobble?odr=208&speed=10")
    qtbot.addWidget(window)
    window.resize(1280, 860)
    window.show()
    qtbot.waitUntil(lambda: window.session.device_info is not None, timeout=TIMEOUT_MS)
    yield window
    window.close()


def test_record_then_replay_through_the_same_pipeline(qtbot, window, tmp_path, artifacts_dir):
    session = window.session
    path = tmp_path / "session.csv"
    statuses = []
    session.recordingChanged.connect(statuses.append)
    with qtbot.waitSignal(session.recordingChanged, timeout=TIMEOUT_MS):
        window.start_recording(str(path), "a test recording")
    qtbot.waitUntil(lambda: window.record_action.isChecked(), timeout=TIMEOUT_MS)
    # The writer reports each flush (at most 1 s apart).
    qtbot.waitUntil(
        lambda: statuses[-1] is not None and statuses[-1].rows_synced > 1500, timeout=TIMEOUT_MS
    )
    assert "REC" in window.status_recording.text()
    window.record_action.trigger()  # stop
    qtbot.waitUntil(lambda: statuses[-1] is None, timeout=TIMEOUT_MS)
    assert not window.record_action.isChecked()
    assert window.status_recording.text() == ""

    recording = read_recording(path)
    assert recording.metadata["note"] == "a test recording"
    assert recording.has_reference
    t = recording.columns["t"]
    assert len(t) > 1500 and np.all(np.diff(t) > 0)

    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        window.open_recording(str(path))
    assert window.replay_bar.isVisible()
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 200, timeout=TIMEOUT_MS)
    # The replayed reference is the recorded truth, so the error table fills in.
    qtbot.waitUntil(lambda: window.truth_label.text().startswith("Simulator truth")
                    or window.truth_label.text() != "", timeout=TIMEOUT_MS)
    window.grab().save(os.path.join(artifacts_dir, "replay.png"))

    stream = []
    session.status.connect(stream.append)
    window.replay_bar.play_button.setChecked(False)  # pause
    qtbot.waitUntil(
        lambda: bool(stream) and stream[-1].replay is not None and not stream[-1].replay[2],
        timeout=TIMEOUT_MS,
    )
    before = session.pipeline.counters
    window.replay_bar.control.emit("seek", 1.0)  # s from the start of the recording
    window.replay_bar.play_button.setChecked(True)
    # A seek starts the views afresh (time must not run backwards): the pipeline is configured
    # anew, with new counters (watching the count fall below its old value missed it on a busy
    # machine, where the lead-in and the play refilled it between two polls); then data flows
    # again, the lead-in before the new position first (here from the recording's start).
    qtbot.waitUntil(lambda: session.pipeline.counters is not before, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 100, timeout=TIMEOUT_MS)
    first_t = session.pipeline.samples.latest(len(session.pipeline.samples))["t"][0]
    assert first_t == pytest.approx(t[0] + max(0.0, 1.0 - SEEK_LEAD_IN_S), abs=0.05)


def test_sample_recordings_are_offered_and_open(qtbot, window):
    file_menu = window.menuBar().actions()[0].menu()
    samples = next(a.menu() for a in file_menu.actions() if a.menu() is not None)
    names = [action.text() for action in samples.actions()]
    assert any("wobble" in name for name in names)
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS) as blocker:
        samples.actions()[0].trigger()
    assert blocker.args[0].url.startswith("replay://")
    qtbot.waitUntil(lambda: window.session.pipeline.counters.samples > 50, timeout=TIMEOUT_MS)


def test_lost_data_shows_as_a_break_in_the_plots(qtbot, window, tmp_path):
    from app.core.recording import RecordingWriter, recording_metadata
    from app.core.samples import RawBlock, ScaleFactors

    path = tmp_path / "gap.csv"
    n = 2000
    t = np.arange(n) / 200.0
    t[1000:] += 3.0  # three seconds lost
    gap = np.zeros(n, bool)
    gap[1000] = True
    accel = np.tile([0.0, 0.0, 9.80665], (n, 1))
    block = RawBlock(t, accel, np.zeros((n, 3)), np.full(n, 25.0), ScaleFactors(1.0, 1.0),
                     gap=gap)
    with RecordingWriter(path, recording_metadata(note="gap")) as writer:
        writer.write(block)
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device(f"replay://{path}?speed=max")
    qtbot.waitUntil(lambda: window.session.pipeline.counters.samples == n, timeout=TIMEOUT_MS)
    curve = window.plots.accel_curves[2]

    def has_break() -> bool:
        connect = curve.opts.get("connect")
        return isinstance(connect, np.ndarray) and not connect.all()

    qtbot.waitUntil(has_break, timeout=TIMEOUT_MS)
    assert window.session.pipeline.counters.gaps == 1


def test_plots_export_to_png_and_svg(qtbot, window, tmp_path):
    qtbot.waitUntil(lambda: window.session.pipeline.counters.samples > 300, timeout=TIMEOUT_MS)
    png, svg = tmp_path / "plots.png", tmp_path / "plots.svg"
    window.export_plots(str(png))
    window.export_plots(str(svg))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "<svg" in svg.read_text()
    window.export_plots(str(tmp_path / "plots.bmp"))
    assert "Plots not exported" in window.banner.label.text()


def test_typed_seek_and_bookmarks_in_a_sample_recording(qtbot, window):
    from app.core.recording import sample_recording
    from drivers.replay import replay_url

    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device(replay_url(sample_recording("tour-104hz"), speed=5))
    session = window.session
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 50, timeout=TIMEOUT_MS)
    stream = []
    session.status.connect(stream.append)

    window.replay_bar.goto_spin.setValue(30.0)
    window.replay_bar.goto_spin.lineEdit().returnPressed.emit()
    qtbot.waitUntil(lambda: bool(stream) and stream[-1].replay[0] >= 30.0, timeout=TIMEOUT_MS)
    assert stream[-1].replay[0] < 40.0

    window.replay_bar.bookmark_button.click()
    position = stream[-1].replay[0]
    qtbot.waitUntil(lambda: stream[-1].replay[0] != position, timeout=TIMEOUT_MS)
    assert stream[-1].replay[0] > position


def test_compare_view_error_over_time_and_range_statistics(qtbot, window, artifacts_dir):
    from app.core.recording import sample_recording
    from drivers.replay import replay_url

    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device(replay_url(sample_recording("translation-208hz"), speed=8))
    window.session.requestComparisons.emit(["vqf"])
    session = window.session
    qtbot.waitUntil(lambda: session.pipeline.counters.samples > 1500, timeout=TIMEOUT_MS)
    # The recording has reference columns: the error plot appears with a curve per filter.
    qtbot.waitUntil(lambda: window.plots.error_visible, timeout=TIMEOUT_MS)
    qtbot.waitUntil(
        lambda: curve_points(window.plots.error_curve) > 10
        and "vqf" in window.plots.comparison_error_curves
        and curve_points(window.plots.comparison_error_curves["vqf"]) > 10,
        timeout=TIMEOUT_MS,
    )
    window.range_box.setChecked(True)
    window.plots.region.setRegion((-2.0, -1.0))
    window.plots.region.sigRegionChangeFinished.emit(window.plots.region)
    text = window.range_label.text()
    assert "roll mean" in text and "pitch mean" in text and "spread" in text
    duration = float(text.split(" s,")[0])
    assert duration == pytest.approx(1.0, abs=0.05)
    window.grab().save(os.path.join(artifacts_dir, "compare_view.png"))


def curve_points(curve) -> int:
    return 0 if curve.xData is None else len(curve.xData)


def test_a_replay_restores_the_recorded_filter_and_parameters(qtbot, window, tmp_path):
    session = window.session
    with qtbot.waitSignal(session.filterChanged, timeout=TIMEOUT_MS):
        session.requestFilter.emit("complementary")
    with qtbot.waitSignal(session.filterChanged, timeout=TIMEOUT_MS):
        session.requestFilterParameter.emit("tau_s", 2.5)
    path = tmp_path / "complementary.csv"
    statuses = []
    session.recordingChanged.connect(statuses.append)
    window.start_recording(str(path))
    qtbot.waitUntil(
        lambda: bool(statuses) and statuses[-1] is not None and statuses[-1].rows_synced > 200,
        timeout=TIMEOUT_MS,
    )
    window.record_action.trigger()
    qtbot.waitUntil(lambda: statuses[-1] is None, timeout=TIMEOUT_MS)
    with qtbot.waitSignal(session.filterChanged, timeout=TIMEOUT_MS):
        session.requestFilter.emit("madgwick")
    with qtbot.waitSignal(session.connected, timeout=TIMEOUT_MS):
        window.open_recording(str(path))
    assert session.pipeline.filter.name == "complementary"
    assert session.pipeline.filter.get_parameter("tau_s") == 2.5
    qtbot.waitUntil(lambda: window.filter_panel.current_filter == "complementary",
                    timeout=TIMEOUT_MS)


def test_a_recordings_own_reference_is_named_not_called_the_simulators_truth(
        qtbot, window, tmp_path):
    from tests.broad_trials import trial_path

    lines = trial_path("01_undisturbed_slow_rotation_A").read_text().splitlines()
    comments = [line for line in lines if line.startswith("#")]
    path = tmp_path / "broad_01_slice.csv"  # 3 s of the real trial, its metadata as it is
    path.write_text("\n".join(lines[:len(comments) + 1 + 300]) + "\n")
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.open_recording(str(path))
    assert "optical motion capture" in window.session.device_info.reference
    qtbot.waitUntil(lambda: window.truth_label.text().startswith("Reference ("),
                    timeout=TIMEOUT_MS)
    assert "Simulator" not in window.truth_label.text()
    assert "The reference: optical motion capture (BROAD)" in window.truth_label.toolTip()
    # The angle plot's dashed traces are named as measured, not as the simulator's truth.
    plots = window.plots
    assert plots.legend_entries(plots.angle_plot)[2:] == ["reference roll", "reference pitch"]
    assert "reference roll" in plots.angle_plot.titleLabel.text
    assert "true roll" not in plots.angle_plot.titleLabel.text
    # A simulator again: its truth is called truth again.
    with qtbot.waitSignal(window.session.connected, timeout=TIMEOUT_MS):
        window.connect_device("sim://static?seed=2")
    assert plots.legend_entries(plots.angle_plot)[2:] == ["true roll", "true pitch"]
