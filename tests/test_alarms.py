"""Alarm logic (app/core/alarms/): limits, hysteresis, delay, clearing, the text form."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.alarms import (
    AlarmConfig,
    AlarmEvent,
    AlarmLimit,
    AlarmMonitor,
    default_alarm_config,
    parse_alarm,
    recorded_alarm_events,
    save_alarm_events,
)
from app.core.recording import read_recording

RATE_HZ = 100.0


def run(monitor: AlarmMonitor, values, *, quantity: str = "tilt", start_t: float = 0.0,
        block: int = 7) -> list[AlarmEvent]:
    """Feed ``values`` (one per sample at 100 Hz) in blocks of ``block``; all events."""
    values = np.asarray(values, dtype=float)
    t = start_t + np.arange(len(values)) / RATE_HZ
    events = []
    for i in range(0, len(values), block):
        angles = {name: np.zeros(len(t[i:i + block])) for name in ("roll", "pitch", "tilt")}
        angles[quantity] = values[i:i + block]
        events += monitor.update(t[i:i + block], angles)
    return events


def monitor_of(*specs: str) -> AlarmMonitor:
    return AlarmMonitor(AlarmConfig(tuple(parse_alarm(s) for s in specs)))


def test_raises_only_after_the_delay_and_clears_after_hysteresis_and_delay():
    monitor = monitor_of("tilt>2,hyst=0.2,delay=0.5")
    # 1 s level, 1 s at 2.5 (beyond), 1 s at 1.9 (inside, but not by the hysteresis),
    # 1 s at 1.7 (inside by more than the hysteresis).
    values = [1.0] * 100 + [2.5] * 100 + [1.9] * 100 + [1.7] * 100
    events = run(monitor, values)
    assert [(e.state, e.quantity) for e in events] == [("raised", "tilt"), ("cleared", "tilt")]
    raised, cleared = events
    assert raised.t == pytest.approx(1.5)  # 0.5 s after the first sample beyond
    assert raised.value == 2.5 and raised.limit == 2.0
    assert cleared.t == pytest.approx(3.5)  # 0.5 s after the value came inside by 0.2
    assert cleared.value == pytest.approx(1.7) and cleared.limit == 2.0
    assert monitor.active() == ()


def test_a_short_excursion_shorter_than_the_delay_raises_nothing():
    monitor = monitor_of("tilt>2,delay=0.5")
    # 0.4 s beyond, back for one sample, 0.4 s beyond again: never 0.5 s without a break.
    values = [1.0] * 50 + [3.0] * 40 + [1.0] + [3.0] * 40 + [1.0] * 50
    assert run(monitor, values) == []
    assert monitor.active() == ()


def test_a_pending_delay_carries_over_block_boundaries():
    monitor = monitor_of("roll>1,delay=0.25")
    values = [0.0] * 10 + [1.5] * 30
    events = run(monitor, values, quantity="roll", block=3)
    assert len(events) == 1 and events[0].t == pytest.approx(0.35)
    assert [limit.quantity for limit in monitor.active()] == ["roll"]
    assert monitor.active_readouts() == ("roll",)


def test_chatter_at_the_limit_is_held_by_the_hysteresis():
    monitor = monitor_of("pitch>1,hyst=0.3,delay=0")
    noise = 1.0 + 0.2 * np.sin(np.arange(400) * 1.3)  # wanders across 1.0 by +-0.2
    events = run(monitor, np.concatenate([[0.0] * 10, noise, [0.0] * 5]), quantity="pitch")
    # One raise on the first sample beyond 1, no clear until the value falls to 0.7 or less.
    assert [e.state for e in events] == ["raised", "cleared"]
    assert events[1].t == pytest.approx((10 + 400) / RATE_HZ)


def test_lower_limit_and_both_sides():
    monitor = monitor_of("|roll|>2,hyst=0.5,delay=0.1")
    values = [0.0] * 20 + [-2.5] * 20 + [-1.0] * 20 + [2.2] * 20 + [0.0] * 20
    events = run(monitor, values, quantity="roll")
    assert [(e.state, e.limit) for e in events] == [
        ("raised", -2.0), ("cleared", -2.0), ("raised", 2.0), ("cleared", 2.0)]
    assert "below -2°" in events[0].message() and "above 2°" in events[2].message()


def test_out_of_level_watches_the_tilt_and_unwatched_quantities_are_ignored():
    monitor = monitor_of("level>0.5,delay=0")
    assert run(monitor, [3.0] * 20, quantity="roll") == []  # roll does not matter to it
    events = run(monitor, [0.6] * 5, quantity="tilt", start_t=1.0)
    assert [e.state for e in events] == ["raised"]
    assert monitor.active_readouts() == ("tilt",)


def test_time_running_backwards_starts_afresh_without_events():
    monitor = monitor_of("tilt>1,delay=0")
    assert [e.state for e in run(monitor, [2.0] * 5, start_t=10.0)] == ["raised"]
    assert run(monitor, [0.0] * 5, start_t=0.0) == []  # a replay sought back
    assert monitor.active() == ()


def test_nan_neither_raises_nor_clears():
    monitor = monitor_of("tilt>1,delay=0")
    assert run(monitor, [np.nan] * 10) == []
    assert [e.state for e in run(monitor, [2.0] + [np.nan] * 10, start_t=1.0)] == ["raised"]
    assert [limit.quantity for limit in monitor.active()] == ["tilt"]


def test_switching_an_alarm_off_while_raised_clears_it_and_unchanged_alarms_keep_state():
    monitor = monitor_of("tilt>1,delay=0", "roll>1,delay=0")
    run(monitor, [2.0] * 3)
    assert [limit.quantity for limit in monitor.active()] == ["tilt"]
    events = monitor.configure(AlarmConfig((parse_alarm("roll>1,delay=0"),)))
    assert [(e.quantity, e.state) for e in events] == [("tilt", "cleared")]
    assert "switched off" in events[0].message()
    stored = events[0].as_dict()
    assert stored["value"] is None  # JSON has no NaN
    assert AlarmEvent.from_dict(stored).message() == events[0].message()
    kept = monitor_of("tilt>1,delay=0")
    run(kept, [2.0] * 3)
    assert kept.configure(AlarmConfig((parse_alarm("tilt>1,delay=0"),))) == []
    assert len(kept.active()) == 1


def test_the_text_form_reads_and_writes_back():
    alarm = parse_alarm("tilt>2.0,hyst=0.2,delay=0.5")
    assert alarm == AlarmLimit("tilt", upper=2.0, hysteresis=0.2, delay_s=0.5)
    assert parse_alarm(alarm.spec()) == alarm
    both = parse_alarm("roll>2, roll<-1, delay=1s")
    assert (both.upper, both.lower, both.delay_s) == (2.0, -1.0, 1.0)
    assert parse_alarm(both.spec()) == both
    assert parse_alarm("|pitch|>1.5").spec() == "|pitch|>1.5,hyst=0.1,delay=0.5"
    assert parse_alarm("|pitch|>1.5").describe() == "pitch outside -1.5° to 1.5°"
    assert parse_alarm("roll<-1").describe() == "roll below -1°"
    assert alarm.describe() == "tilt above 2°"
    assert parse_alarm("level>0.5").describe() == "out of level (tilt beyond 0.5°)"
    for bad, words in (("tilt", "cannot read"), ("yaw>2", "no quantity 'yaw'"),
                       ("tilt>2,roll<1", "one quantity"), ("tilt>2,speed=3", "unknown option"),
                       ("roll>1,roll<2", "must be below"), ("level<1", "tolerance"),
                       ("tilt>2,delay=-1", "delay"), ("tilt>2,hyst=x", "not a number"),
                       ("hyst=1", "no limit")):
        with pytest.raises(ValueError, match=words):
            parse_alarm(bad)


def test_the_configuration_round_trips_through_plain_json_and_refuses_garbage():
    config = AlarmConfig((*default_alarm_config().limits, parse_alarm("|roll|>3")), sound=True)
    assert AlarmConfig.from_dict(config.to_dict()) == config
    for bad in ([], {"limits": {}}, {"sound": "loud"}, {"limits": [{"quantity": "yaw"}]},
                {"limits": [{"quantity": "tilt", "upper": "2"}]},
                {"limits": [{"quantity": "tilt", "upper": 2, "enabled": "yes"}]}):
        with pytest.raises(ValueError):
            AlarmConfig.from_dict(bad)


def test_crossings_are_stored_in_a_recording_and_read_back(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("# inclinometer-recording 1\n# note: \"x\"\nt,ax,ay,az,gx,gy,gz\n"
                    "0,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0,0\n")
    monitor = monitor_of("tilt>1,delay=0")
    monitor.begin_recording()
    run(monitor, [0.0, 2.0, 2.0, 0.0])
    events = monitor.end_recording()
    save_alarm_events(path, events, monitor.config)
    recording = read_recording(path)
    assert recorded_alarm_events(recording.metadata) == events
    assert recording.metadata["alarms"] == ["tilt>1,hyst=0.1,delay=0"]
    assert recording.note == "x" and len(recording) == 2
    assert recorded_alarm_events({"alarm_events": [{"t": 1}, "junk"]}) == []


def reference_crossings(limit: AlarmLimit, t, values) -> list[tuple[float, str]]:
    """The definition, sample by sample: what the vectorised monitor must reproduce."""
    active, since, out = False, None, []
    for time_s, value in zip(t, values, strict=True):
        if active:
            holds = (value <= (limit.upper if limit.upper is not None else np.inf)
                     - limit.hysteresis and value >= (limit.lower if limit.lower is not None
                                                      else -np.inf) + limit.hysteresis)
        else:
            holds = ((limit.upper is not None and value > limit.upper)
                     or (limit.lower is not None and value < limit.lower))
        if not holds:
            since = None
            continue
        since = time_s if since is None else since
        if time_s - since >= limit.delay_s:
            active = not active
            out.append((time_s, "raised" if active else "cleared"))
            since = None
    return out


@pytest.mark.parametrize("seed", range(6))
def test_the_monitor_agrees_with_the_sample_by_sample_definition(seed):
    rng = np.random.default_rng(seed)
    n = 3000
    t = np.cumsum(rng.uniform(0.005, 0.015, n))  # an uneven clock
    values = np.sin(2 * np.pi * t / 3.0) + rng.standard_normal(n) * 0.08
    limit = AlarmLimit("roll", upper=0.4, lower=-0.6, hysteresis=float(rng.uniform(0, 0.2)),
                       delay_s=float(rng.choice([0.0, 0.02, 0.1])))
    monitor = AlarmMonitor(AlarmConfig((limit,)))
    got, i = [], 0
    while i < n:
        size = int(rng.integers(1, 200))
        block = slice(i, i + size)
        angles = {"roll": values[block], "pitch": values[block], "tilt": values[block]}
        got += [(e.t, e.state) for e in monitor.update(t[block], angles)]
        i += size
    expected = reference_crossings(limit, t, values)
    assert len(expected) > 4  # the signal does cross, often
    assert got == expected
