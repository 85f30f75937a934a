"""Device URL options declared as data (drivers/url_options.py): the one parser, the drivers'
tables, ``inclinometer devices --options`` and the GUI's device field."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from app.cli import main
from app.core.words import FALSE_WORDS, TRUE_WORDS, flag_word
from app.services.devices import device_options, option_hints
from drivers.errors import DeviceUrlError
from drivers.lsm6dsox_direct.device import (
    COMMON_OPTIONS,
    EMULATED_OWN_OPTIONS,
    MCP2221_OPTIONS,
    DirectOptions,
)
from drivers.registry import driver_options
from drivers.replay import OPTIONS as REPLAY_OPTIONS
from drivers.replay import ReplayOptions, parse_replay_url
from drivers.serial_link import OPTIONS as LINK_OPTIONS
from drivers.serial_link import LinkOptions
from drivers.sim.options import GENERAL_OPTIONS, SimOptions, parse_sim_url
from drivers.text_lines import OPTIONS as TEXT_OPTIONS
from drivers.text_lines import TextOptions
from drivers.url_options import Option, format_options, parse_options

TABLE = (
    Option("rate", "number", 1.0, unit="Hz", positive=True, maximum=100.0),
    Option("count", "integer", 3, minimum=1, maximum=10),
    Option("on", "flag", False),
    Option("mode", "choice", "a", choices=("a", "b"), aliases={"alpha": "a"}),
    Option("size", "choice", 4, choices=(2, 4, 8), unit="g", field="size_g"),
    Option("tag", "text", None, repeatable=True, metavar="NAME"),
)


def parse(query: str, **kwargs: object) -> dict[str, object]:
    return parse_options("x://y", query, TABLE, **kwargs).values  # type: ignore[arg-type]


@pytest.mark.parametrize(("table", "record", "fixed"), [
    (GENERAL_OPTIONS, SimOptions, {"scenario": "static"}),
    (LINK_OPTIONS, LinkOptions, {"port": "/dev/x"}),
    (TEXT_OPTIONS, TextOptions, {"port": "/dev/x"}),
    (COMMON_OPTIONS + MCP2221_OPTIONS + EMULATED_OWN_OPTIONS, DirectOptions, {"bus": "emulated"}),
    (REPLAY_OPTIONS, ReplayOptions, {"path": "x.csv"}),
])
def test_each_table_names_its_records_fields_and_defaults(table, record, fixed):
    """The table is what a listing shows: its defaults must be the options record's."""
    defaults = record(**fixed)
    fields = {f.name for f in dataclasses.fields(record)}
    for option in table:
        if option.key in ("scenario", "port", "faults"):  # the URL's path, or a list
            continue
        assert option.key in fields, option.name
        actual = getattr(defaults, option.key)
        expected = option.default
        if option.name == "part":  # listed as the user writes it, kept as the chip's name
            expected = str(expected).upper()
        assert actual == expected, (option.name, actual, expected)


def test_values_are_typed_and_checked():
    assert parse("rate=2.5&count=0x4&on=YES&mode=Alpha&size=8.0&tag=a&tag=b") == {
        "rate": 2.5, "count": 4, "on": True, "mode": "a", "size_g": 8}
    assert parse_options("x://y", "tag=a&tag=b", TABLE).repeated == {"tag": ["a", "b"]}
    assert parse("count=1e1") == {"count": 10}
    for query, words in [
        ("rate=fast", ["rate='fast' is not a positive number"]),
        ("rate=0", ["must be a positive number (Hz)"]),
        ("rate=inf", ["not a finite number"]),
        ("rate=" + "9" * 400, ["(400 chars) is not a finite number"]),
        ("rate=101", ["out of range (0, 100] Hz"]),
        ("count=2.5", ["whole number in [1, 10]"]),
        ("count=11", ["count='11' is out of range [1, 10]"]),
        ("on=maybe", ["use 1 or 0 (also true/false, yes/no, on/off)"]),
        ("mode=c", ["is not supported; use one of a, b"]),
        ("size=3", ["use one of 2, 4, 8 (g)"]),
        ("colour=red", ["unknown option 'colour'; allowed: rate, count, on, mode, size, tag"]),
        ("Rate=1&rate=2", ["option 'rate' is given twice"]),
        ("rate=", ["option 'rate' needs a value (rate=...)"]),
        ("tag=", ["option 'tag' needs a value (tag=NAME)"]),
    ]:
        with pytest.raises(DeviceUrlError) as caught:
            parse(query)
        message = str(caught.value)
        assert message.startswith("x://y: ") and "\n" not in message
        for word in words:
            assert word in message, (query, message)


def test_overrides_win_and_others_are_kept_when_asked():
    assert parse("rate=2&on=1", overrides={"rate": 5, "on": False, "count": None}) == {
        "rate": 5.0, "on": False}
    found = parse_options("x://y", "rate=2&file=t.txt&raw", TABLE, keep_other=True)
    assert found.values == {"rate": 2.0} and found.other == [("file", "t.txt"), ("raw", "")]
    with pytest.raises(DeviceUrlError, match="unknown option 'nope' for x://y"):
        parse_options("x://y", "", TABLE, overrides={"nope": 1}, context=" for x://y")


def test_one_set_of_yes_no_words():
    assert {flag_word(w) for w in TRUE_WORDS} == {True}
    assert {flag_word(w.upper()) for w in FALSE_WORDS} == {False}
    assert flag_word("maybe") is None
    assert parse_sim_url("sim://static?realtime=Off&errors=yes").realtime is False
    assert parse_replay_url("replay://x.csv?loop=on&exact=no") == ReplayOptions(
        parse_replay_url("replay://x.csv").path, loop=True, exact=False)


def test_urls_that_worked_keep_their_values():
    sim = parse_sim_url("sim://Slow_Tilt?ODR=208&accel_fs=8&seed=1e3&fault=stuck:gz@2",
                        {"realtime": False})
    assert (sim.scenario, sim.odr_nominal_hz, sim.accel_fs_g, sim.seed, sim.realtime) == (
        "slow-tilt", 208.0, 8, 1000, False)
    assert [f.channel for f in sim.faults] == ["gz"]
    assert parse_sim_url("sim://handheld").gyro_fs_dps == 2000  # what the motion needs
    assert math.isinf(parse_replay_url("replay://x.csv?speed=max").speed)


def test_the_listing_covers_every_scheme():
    for scheme in ("sim", "serial", "port", "text", "lsm6dsox", "replay"):
        names = [option.name for option in driver_options(scheme)]
        assert names and len(names) == len(set(names)), scheme
    static = [option.name for option in driver_options("sim://static")]
    assert static[-3:] == ["roll", "pitch", "yaw"]
    emulated = [option.name for option in driver_options("lsm6dsox://emulated?scenario=static")]
    assert "roll" in emulated and "realtime" not in emulated and "index" not in emulated
    text = format_options(driver_options("replay"))
    assert text.splitlines()[0].split() == ["option", "type", "default", "range", "/",
                                            "choices", "help"]
    assert "[1, 65536]" in text
    assert option_hints("nosuch://x?") == [] and option_hints("sim://static?")


def test_devices_options_command(capsys):
    assert main(["devices", "--options", "serial"]) == 0
    out = capsys.readouterr().out
    assert "timeout" in out and "(0, 3600] s" in out
    assert main(["devices", "--options", "sim://static", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows == device_options("sim://static")
    roll = next(row for row in rows if row["name"] == "roll")
    assert (roll["minimum"], roll["maximum"], roll["type"]) == (-180, 180, "number")
    assert main(["devices", "--options", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no driver for nosuch://" in err


def test_device_field_offers_the_options_of_the_typed_url(qtbot):
    from PySide6.QtCore import Qt

    from app.gui.device_bar import TOOLTIP_ROLE, DeviceBar

    bar = DeviceBar()
    qtbot.addWidget(bar)
    bar.show()
    bar.activateWindow()
    asked: list[str] = []
    bar.connectRequested.connect(asked.append)
    edit = bar.device_combo.lineEdit()
    edit.clear()
    edit.setFocus()  # as while typing: the line edit inserts what its completer chose
    qtbot.waitUntil(edit.hasFocus)
    qtbot.keyClicks(edit, "sim://static?")
    completer = bar.option_completer
    assert edit.completer() is completer
    model = completer.model()
    names = [model.index(row, 0).data() for row in range(model.rowCount())]
    assert names[:2] == ["odr=", "accel_fs="] and names[-3:] == ["roll=", "pitch=", "yaw="]
    qtbot.waitUntil(completer.popup().isVisible)
    qtbot.keyClicks(edit, "odr=104&ro")
    assert completer.currentCompletion() == "sim://static?odr=104&roll="
    index = completer.currentIndex()
    assert "[-180, 180]" in index.data(TOOLTIP_ROLE) and "roll angle" in index.data(TOOLTIP_ROLE)
    qtbot.waitUntil(completer.popup().isVisible)
    completer.popup().setCurrentIndex(completer.completionModel().index(0, 0))
    qtbot.keyClick(completer.popup(), Qt.Key.Key_Return)
    assert edit.text() == "sim://static?odr=104&roll="
    assert asked == []  # choosing an option does not connect
    edit.clear()
    qtbot.keyClicks(edit, "nosuch://x?")
    assert edit.completer() is bar._url_completer  # back to the devices' URLs
