"""Heading alarms: a sector or a set heading, wrapping round north; the pipeline's heading
column they watch; and the recording's ``heading`` metadata key from ``record``."""

from __future__ import annotations

import numpy as np
import pytest

from app.cli import main
from app.core.alarms import (
    RAISED,
    AlarmConfig,
    AlarmLimit,
    AlarmMonitor,
    default_alarm_config,
    parse_alarm,
)
from app.core.earth_field import Place, earth_field
from app.core.filters import FILTERS
from app.core.filters.base import MAGNETOMETER_PARAMETER, OrientationFilter
from app.core.heading import Declination, magnetic_heading_deg
from app.core.pipeline import Pipeline
from app.core.recording import read_recording


def run(spec: str, headings: np.ndarray, rate_hz: float = 10.0):
    monitor = AlarmMonitor(AlarmConfig((parse_alarm(spec),)))
    t = np.arange(len(headings)) / rate_hz
    return monitor.update(t, {"heading": headings, "roll": 0 * t, "pitch": 0 * t,
                              "tilt": 0 * t})


def test_a_sector_across_north_raises_outside_and_never_inside() -> None:
    inside = np.array([350.5, 355.0, 359.9, 0.0, 3.0, 9.5] * 5)
    assert run("heading:350..10,delay=0.2", inside) == []
    events = run("heading:350..10,delay=0.2", np.r_[np.full(5, 0.0), np.full(10, 15.0)])
    assert [e.state for e in events] == [RAISED]
    assert events[0].value == pytest.approx(15.0) and events[0].limit == 10.0
    # 345 is 15 degrees anticlockwise of north: beyond the lower limit, not "above 10".
    events = run("heading:350..10,delay=0.2", np.r_[np.full(5, 0.0), np.full(10, 345.0)])
    assert [e.state for e in events] == [RAISED]
    assert events[0].value == pytest.approx(-15.0) and events[0].limit == -10.0


def test_deviation_from_a_set_heading_wraps_and_clears_with_hysteresis() -> None:
    # Set heading 358: 3 reads as +5 clockwise, 352 as -6.
    headings = np.r_[np.full(5, 358.0), np.full(10, 4.0), np.full(10, 2.5), np.full(10, 0.0)]
    events = run("|heading-358|>5,hyst=1,delay=0.2", headings)
    assert [e.state for e in events] == ["raised", "cleared"]
    assert events[0].value == pytest.approx(6.0)
    assert events[1].t == pytest.approx(2.7)  # 2.5 is 4.5 off: not back by the hysteresis
    one_sided = run("heading-90>20,delay=0", np.array([95.0, 60.0, 200.0]))
    assert [e.value for e in one_sided] == [pytest.approx(110.0)]


def test_no_heading_neither_raises_nor_clears() -> None:
    assert run("|heading-0|>5,delay=0", np.full(20, np.nan)) == []


def test_heading_alarm_texts_and_settings_round_trip() -> None:
    for spec in ("heading:350..10", "|heading-45|>5,hyst=1", "heading-90>20",
                 "heading-90<-20", "heading-90>20,heading-90<-30,delay=2"):
        limit = parse_alarm(spec)
        assert parse_alarm(limit.spec()) == limit
        assert AlarmLimit.from_dict(limit.to_dict()) == limit
    assert parse_alarm("heading:350..10").describe() == \
        "magnetic heading outside 350° to 10° (clockwise)"
    for bad in ("heading>5", "heading:10..10", "heading-x>5", "heading-1>5,heading-2<-5"):
        with pytest.raises(ValueError):
            parse_alarm(bad)
    with pytest.raises(ValueError, match="set heading"):
        AlarmLimit("tilt", upper=1.0, centre=10.0)
    config = default_alarm_config()
    assert AlarmConfig.from_dict(config.to_dict()) == config
    assert "heading" in {limit.quantity for limit in config.limits}


class _TruthFilter(OrientationFilter):
    """A stand-in 9-axis filter for this test: the simulator's true orientation (ENU, y
    magnetic north), as a 9-axis filter's output is defined."""

    name = "test-truth"
    uses_magnetometer = True
    parameters = (MAGNETOMETER_PARAMETER,)

    def _process(self, block):
        return block.reference_quat


def test_the_pipeline_heading_column_only_from_a_field_filter(monkeypatch) -> None:
    from drivers.registry import create_device

    monkeypatch.setitem(FILTERS, "test-truth", _TruthFilter)
    device = create_device("sim://handheld?realtime=0&block=64&mag=lis3mdl&seed=4")
    info = device.open()
    try:
        pipeline = Pipeline(info.odr_hz, "complementary")  # 6-axis: arbitrary heading
        pipeline.process(device.read(1.0))
        assert pipeline.has_field and not pipeline.takes_heading_from_field()
        assert np.all(np.isnan(pipeline.orientation.latest(64, ["heading"])["heading"]))
        pipeline.set_filter("test-truth")
        assert pipeline.takes_heading_from_field()
        block = pipeline.process(device.read(1.0))
        rows = pipeline.orientation.latest(len(block), ["heading", "quat"])
        expected = magnetic_heading_deg(block.reference_quat)
        assert np.isfinite(expected).all()
        np.testing.assert_allclose(rows["heading"], expected)
        monitor = AlarmMonitor(AlarmConfig((parse_alarm(
            f"|heading-{(expected[0] + 180.0) % 360.0:.1f}|>1,delay=0"),)))
        events = monitor.update_from_buffer(pipeline.orientation, len(block))
        assert [e.state for e in events] == [RAISED]  # 180 degrees off the set heading
        pipeline.set_filter_parameter("magnetometer", False)
        assert not pipeline.takes_heading_from_field()
    finally:
        device.close()


def test_record_stores_the_declination_typed_or_from_wmm(tmp_path, capsys) -> None:
    typed = tmp_path / "typed.csv"
    assert main(["record", "--device", "sim://static?realtime=0&odr=104", "--duration", "0.2",
                 "--declination", "-3.5", "--quiet", str(typed)]) == 0
    stored = read_recording(typed).metadata["heading"]
    assert Declination.from_dict(stored) == Declination(-3.5, "typed")
    assert stored["frame"] == "ENU, y magnetic north"
    placed = tmp_path / "wmm.csv"
    assert main(["record", "--device", "sim://static?realtime=0&odr=104", "--duration", "0.2",
                 "--place=-33.9,151.2,40", "--quiet", str(placed)]) == 0
    stored = read_recording(placed).metadata["heading"]
    declination = Declination.from_dict(stored)
    assert declination.source == "wmm" and declination.place == Place(-33.9, 151.2, 40.0)
    assert declination.declination_deg == pytest.approx(
        earth_field(declination.place, declination.when).declination_deg)
    plain = tmp_path / "plain.csv"
    assert main(["record", "--device", "sim://static?realtime=0&odr=104", "--duration", "0.2",
                 "--quiet", str(plain)]) == 0
    assert "heading" not in read_recording(plain).metadata
    capsys.readouterr()
    for bad in (["--declination", "east"], ["--declination", "200"], ["--place", "95,0"],
                ["--place", "1,2,3,4"]):
        code = main(["record", "--device", "sim://static?realtime=0", "--duration", "0.2",
                     *bad, str(tmp_path / "bad.csv")])
        assert code == 2, bad
        assert not (tmp_path / "bad.csv").exists()
        assert "--declination" in capsys.readouterr().err or bad[0] == "--place"
