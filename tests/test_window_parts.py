"""The window's parts that need no device: the menu builder and the settings gateway."""

from __future__ import annotations

from PySide6.QtCore import QObject, QSettings, Signal
from PySide6.QtGui import QKeySequence
from PySide6.QtWidgets import QMainWindow

from app.core.filters import FILTERS, ONLINE_FILTERS
from app.gui.actions import ActionSpec, Generated, Separator, Submenu, build_menus
from app.gui.user_settings import SettingsSections
from app.gui.window_menus import menu_table
from app.gui.window_settings import WindowSettings


class _Requests(QObject):
    ping = Signal()


class _Window(QMainWindow):
    def __init__(self) -> None:
        super().__init__()
        self.calls: list[tuple] = []
        self.requests = _Requests()

    def open(self, *args) -> None:
        self.calls.append(("open", *args))

    def toggled(self, checked: bool) -> None:
        self.calls.append(("toggled", checked))

    def extra(self) -> list:
        from PySide6.QtGui import QAction

        return [QAction("Generated one", self)]


def _titles(menu) -> list[str]:
    return [action.text() or "---" for action in menu.actions()]


def test_the_builder_makes_menus_in_table_order_and_connects_callbacks(qtbot) -> None:
    window = _Window()
    qtbot.addWidget(window)
    pings = []
    window.requests.ping.connect(lambda: pings.append(1))
    actions = build_menus(window, [
        ActionSpec("a", "&Open", "&File", "open", "Ctrl+O"),
        Submenu("&File/&Samples"),
        ActionSpec("s", "one", "&File/&Samples", "open", args=("one.csv",)),
        Separator("&File"),
        ActionSpec("t", "&Toggle", "&File", "toggled", "F11", checkable=True, on_toggle=True,
                   window_wide=True),
        ActionSpec("p", "&Ping", "&Edit", "requests.ping", enabled=False),
        Generated("&Edit", "extra"),
        ActionSpec("x", "X", "&Edit/&Pick", "open", args=("x",), checkable=True, group="g"),
        ActionSpec("y", "Y", "&Edit/&Pick", "open", args=("y",), checkable=True, group="g"),
    ])
    bar = window.menuBar()
    assert _titles(bar) == ["&File", "&Edit"]
    file_menu, edit_menu = (action.menu() for action in bar.actions())
    assert _titles(file_menu) == ["&Open", "&Samples", "---", "&Toggle"]
    assert _titles(edit_menu) == ["&Ping", "Generated one", "&Pick"]
    assert actions["a"].shortcut() == QKeySequence("Ctrl+O")
    assert window.actions() == [actions["t"]]  # only the window-wide one
    actions["a"].trigger()
    actions["s"].trigger()
    actions["t"].trigger()
    assert window.calls == [("open",), ("open", "one.csv"), ("toggled", True)]
    assert not actions["p"].isEnabled()
    actions["p"].setEnabled(True)
    actions["p"].trigger()
    assert pings == [1]
    actions["x"].trigger()
    actions["y"].trigger()
    assert actions["y"].isChecked() and not actions["x"].isChecked()


def test_the_window_table_has_unique_ids_and_shortcuts() -> None:
    specs = [entry for entry in menu_table() if isinstance(entry, ActionSpec)]
    ids = [spec.id for spec in specs]
    assert len(ids) == len(set(ids))
    keys = [QKeySequence(spec.shortcut).toString() for spec in specs if spec.shortcut]
    assert len(keys) == len(set(keys))
    assert {"Ctrl+R", "Ctrl+T", "F11", "H", "Space", "Esc"} <= set(keys)


def test_window_settings_use_the_keys_they_always_had(tmp_path) -> None:
    settings = QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat)
    reports: list[str] = []
    remembered = WindowSettings(SettingsSections(settings, reports.append))
    name = ONLINE_FILTERS[-1]
    known = FILTERS[name].parameters[0].name if FILTERS[name].parameters else None
    remembered.save_filter(name, {"not-a-parameter": 1.0, **({known: 2.0} if known else {})})
    remembered.save_comparisons([ONLINE_FILTERS[0]])
    remembered.save_display({"unit": "percent", "averaging_s": 2.0, "range_deg": 10.0})
    remembered.save_plot_window_s(30)
    remembered.save_device_url("sim://static")
    settings.sync()
    text = (tmp_path / "s.ini").read_text()
    for key in ("filter=", "comparisons=", "unit=percent", "averaging_s=2", "range_deg=10",
                "plot_window_s=30", "device_url=", "filter_parameters"):
        assert key in text, key
    # Shown, not chosen: the source's default, whichever the source is (None).
    assert remembered.filter() is None and remembered.filter(name) == name
    remembered.save_filter_chosen(True)
    settings.sync()
    assert "filter_chosen=true" in (tmp_path / "s.ini").read_text()
    assert remembered.filter() == name
    assert remembered.filter(None) == name and remembered.filter("no-such") is None
    assert remembered.filter_parameters(name) == ({known: 2.0} if known else {})
    assert remembered.comparisons() == [ONLINE_FILTERS[0]]
    assert remembered.plot_window_s() == 30
    assert remembered.device_url() == "sim://static"
    assert remembered.device_url("sim://wobble") == "sim://wobble"
    settings.setValue("plot_window_s", "many")
    assert remembered.plot_window_s() == 10  # not a number: the default
    assert reports == []
