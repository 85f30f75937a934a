"""Offline filters (smoothers) never run on a live stream: not in the pipeline, the worker,
the filter panel, the saved settings, nor ``record``; they are listed greyed out instead."""

from __future__ import annotations

import os

import pytest
from PySide6.QtCore import QSettings, Qt

from app.cli import main
from app.core.filters import DEFAULT_FILTER, FILTERS, ONLINE_FILTERS
from app.core.pipeline import Pipeline
from app.gui import theme
from app.gui.filter_panel import FilterPanel
from app.services.worker import DeviceWorker

OFFLINE = [name for name, cls in FILTERS.items() if cls.offline]
TIMEOUT_MS = 15_000


def test_there_are_offline_filters_and_they_are_not_online():
    assert set(OFFLINE) == {"ekf-smoother", "vqf-offline"}
    assert not set(OFFLINE) & set(ONLINE_FILTERS)


@pytest.mark.parametrize("name", OFFLINE)
def test_the_pipeline_refuses_an_offline_filter_and_changes_nothing(name):
    pipeline = Pipeline(odr_hz=104.0, filter_name="accel")
    pipeline.set_comparisons(["complementary"])
    running = pipeline.comparisons
    with pytest.raises(ValueError, match=rf"offline filter.*whole recording.*--filter {name}"):
        pipeline.set_filter(name)
    with pytest.raises(ValueError, match="offline filter"):
        pipeline.set_comparisons(["madgwick", name])
    with pytest.raises(ValueError, match="offline filter"):
        Pipeline(odr_hz=104.0, filter_name=name)
    assert pipeline.filter.name == "accel"
    assert pipeline.comparisons is running and list(running) == ["complementary"]
    # Unknown names are still a KeyError listing the known ones.
    with pytest.raises(KeyError):
        pipeline.set_filter("nonsense")


def test_the_worker_reports_an_offline_filter_as_an_error(qtbot):
    worker = DeviceWorker(Pipeline(odr_hz=104.0))
    with qtbot.waitSignal(worker.error, timeout=1000) as blocker:
        worker.set_filter("ekf-smoother")
    assert "offline filter" in blocker.args[0]
    assert worker.pipeline.filter.name == DEFAULT_FILTER
    with qtbot.waitSignal(worker.comparisonsChanged, timeout=1000) as blocker:
        worker.set_comparisons(["accel", "vqf-offline"])
    assert blocker.args[0] == []


def _compare_item(panel: FilterPanel, name: str):
    return next(panel.compare_list.item(r) for r in range(panel.compare_list.count())
                if panel.compare_list.item(r).data(Qt.ItemDataRole.UserRole) == name)


def test_the_filter_panel_lists_offline_filters_greyed_out(qtbot, qapp, artifacts_dir):
    theme.apply_theme(qapp)
    panel = FilterPanel()
    qtbot.addWidget(panel)
    panel.show_filter(DEFAULT_FILTER, FILTERS[DEFAULT_FILTER]().parameter_values())
    model = panel.combo.model()
    for name, cls in FILTERS.items():
        index = panel.combo.findData(name)
        text = panel.combo.itemText(index)
        tooltip = panel.combo.itemData(index, Qt.ItemDataRole.ToolTipRole)
        item = _compare_item(panel, name)
        enabled_in_combo = model.item(index).isEnabled()
        enabled_in_list = bool(item.flags() & Qt.ItemFlag.ItemIsEnabled)
        checkable = bool(item.flags() & Qt.ItemFlag.ItemIsUserCheckable)
        if cls.offline:
            assert text == item.text() and text.endswith("(offline)")
            assert text.count("(offline)") == 1
            for tip in (tooltip, item.toolTip()):
                assert tip.startswith("offline: needs the whole recording")
                assert f"inclinometer replay IN.csv --filter {name}" in tip
            assert not enabled_in_combo and not enabled_in_list and not checkable
        else:
            assert "(offline)" not in text
            assert enabled_in_combo and checkable
            assert enabled_in_list == (name != DEFAULT_FILTER)
    # Switching the main filter re-enables the others, never an offline one.
    panel.show_filter("accel", {})
    assert bool(_compare_item(panel, DEFAULT_FILTER).flags() & Qt.ItemFlag.ItemIsEnabled)
    for name in OFFLINE:
        assert not _compare_item(panel, name).flags() & Qt.ItemFlag.ItemIsEnabled
    # Even if activated programmatically, an offline entry is not requested, and the combo
    # returns to the running filter; a reported comparison list naming one ticks nothing.
    requested: list[str] = []
    panel.filterRequested.connect(requested.append)
    for name in OFFLINE:
        panel.combo.setCurrentIndex(panel.combo.findData(name))
        panel.combo.activated.emit(panel.combo.findData(name))
    assert requested == [] and panel.combo.currentData() == "accel"
    panel.show_comparisons(["madgwick", *OFFLINE])
    assert panel.compared_filters() == ["madgwick"]
    panel.resize(420, 760)
    panel.show()
    assert panel.grab().save(os.path.join(artifacts_dir, "offline_filters.png"))


def test_saved_offline_settings_fall_back_to_the_default(qtbot, qapp, tmp_path):
    from app.gui.main_window import MainWindow
    from app.services.session import DeviceSession

    theme.apply_theme(qapp)
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    settings.setValue("filter", "ekf-smoother")
    settings.setValue("comparisons", "vqf-offline,accel,ekf-smoother")
    settings.sync()
    session = DeviceSession()
    window = MainWindow(session, settings, "sim://static?odr=52&seed=1")
    qtbot.addWidget(window)
    errors: list[str] = []
    session.error.connect(errors.append)
    try:
        qtbot.waitUntil(lambda: window.filter_panel.current_filter == DEFAULT_FILTER,
                        timeout=TIMEOUT_MS)
        qtbot.waitUntil(lambda: window.filter_panel.compared_filters() == ["accel"],
                        timeout=TIMEOUT_MS)
        assert session.pipeline.filter.name == DEFAULT_FILTER
        assert list(session.pipeline.comparisons) == ["accel"]
        assert not any("offline" in message for message in errors)
    finally:
        window.close()


def test_record_refuses_an_offline_filter(tmp_path, capsys):
    out = tmp_path / "x.csv"
    assert main(["record", "--device", "sim://static?realtime=0", "--filter", "ekf-smoother",
                 "--duration", "1", str(out)]) == 2
    assert "offline filter" in capsys.readouterr().err
    assert main(["record", "--device", "sim://static?realtime=0", "--compare",
                 "accel,vqf-offline", "--duration", "1", str(out)]) == 2
    assert "'vqf-offline' is an offline filter" in capsys.readouterr().err
    assert not out.exists()
