"""The measurement log model (app/core/measurement_log.py): readings, the file, bad files."""

from __future__ import annotations

import csv
import io
import json
import math
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from app.core.measurement_log import COLUMNS, MeasurementLog, measure
from app.core.orientation import quaternion_from_roll_pitch

WHEN = datetime(2026, 5, 9, 7, 35, 25, tzinfo=timezone(timedelta(hours=2)))


def noisy_quaternions(roll: float, pitch: float, spread: float, n: int = 400,
                      seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rolls = roll + spread * rng.standard_normal(n)
    pitches = pitch + spread * rng.standard_normal(n)
    return quaternion_from_roll_pitch(rolls, pitches)


def test_a_reading_is_the_mean_and_spread_of_the_window_in_the_unit():
    quat = noisy_quaternions(2.0, -1.0, 0.05)
    reading = measure(quat, "deg", 0.5, label="A", filter_name="ekf",
                      calibration="bench", device="sim", when=WHEN)
    assert reading.roll == pytest.approx(2.0, abs=0.01)
    assert reading.pitch == pytest.approx(-1.0, abs=0.01)
    assert reading.roll_std == pytest.approx(0.05, rel=0.15)
    assert reading.tilt == pytest.approx(math.hypot(2.0, 1.0), abs=0.01)
    assert reading.samples == 400 and reading.window_s == 0.5
    assert reading.time == "2026-05-09T07:35:25+02:00"
    assert (reading.label, reading.filter, reading.calibration) == ("A", "ekf", "bench")
    in_mm = measure(quat, "mm/m", 0.5, when=WHEN)
    assert in_mm.roll == pytest.approx(1000 * math.tan(math.radians(reading.roll)))
    assert in_mm.roll_std == pytest.approx(reading.roll_std * 1000 * math.pi / 180, rel=0.01)
    assert measure(np.full((5, 4), np.nan), "deg", 0.5) is None


def test_the_spread_of_a_roll_near_180_degrees_does_not_wrap():
    quat = noisy_quaternions(179.98, 0.0, 0.02)
    reading = measure(quat, "deg", 1.0)
    assert abs(reading.roll) > 179.9 and reading.roll_std < 0.05


def test_the_log_saves_every_change_and_reads_back(tmp_path):
    path = tmp_path / "sub" / "measurements.json"
    log = MeasurementLog(path)
    first = measure(noisy_quaternions(1.0, 0.5, 0.01), "deg", 0.5, label="a", when=WHEN)
    second = measure(noisy_quaternions(0.0, 0.0, 0.0), "percent", 2.0, label="b", when=WHEN)
    log.add(first)
    log.add(second)  # std 0 of identical samples, NaN-free
    log.set_label(1, "b, with a comma")
    again, message = MeasurementLog.load(path)
    assert message == "" and [e.label for e in again.entries] == ["a", "b, with a comma"]
    assert again.entries[0] == first
    again.remove([0])
    assert [e.label for e in MeasurementLog.load(path)[0].entries] == ["b, with a comma"]
    assert not list(path.parent.glob("*.tmp"))  # written through a renamed temporary file


def test_csv_and_clipboard_text(tmp_path):
    log = MeasurementLog(None)
    for label in ("north", "south\tcorner"):
        log.add(measure(noisy_quaternions(1.0, 0.5, 0.01), "deg", 0.5, label=label, when=WHEN))
    rows = list(csv.reader(io.StringIO(log.csv_text())))
    assert tuple(rows[0]) == COLUMNS and len(rows) == 3
    assert rows[1][COLUMNS.index("roll")] == f"{log.entries[0].roll:.6g}"
    tabbed = list(csv.reader(io.StringIO(log.csv_text("\t", rows=[1])), delimiter="\t"))
    assert len(tabbed) == 2 and tabbed[1][1] == "south\tcorner"  # quoted, not split
    target = tmp_path / "out.csv"
    log.export_csv(target)
    assert target.read_text() == log.csv_text()


@pytest.mark.parametrize("content", [
    "not json at all", '{"format": "something else"}',
    '{"format": "inclinometer-measurement-log", "version": 99, "entries": []}',
    '{"format": "inclinometer-measurement-log", "version": 1, "entries": [{"label": 3}]}',
    '{"format": "inclinometer-measurement-log", "version": 1, "entries": [[]]}',
])
def test_a_damaged_file_is_moved_aside_and_the_log_starts_empty(tmp_path, content):
    path = tmp_path / "measurements.json"
    path.write_text(content)
    log, message = MeasurementLog.load(path)
    assert len(log) == 0 and "damaged" in message
    aside = list(tmp_path.glob("measurements.json.corrupt-*"))
    assert len(aside) == 1 and aside[0].read_text() == content and str(aside[0]) in message
    log.add(measure(noisy_quaternions(1.0, 0.0, 0.01), "deg", 0.5, when=WHEN))
    assert json.loads(path.read_text())["entries"][0]["roll"] == pytest.approx(1.0, abs=0.01)
    # A second damaged file does not replace the first one kept aside.
    path.write_text(content)
    MeasurementLog.load(path)
    assert len(list(tmp_path.glob("measurements.json.corrupt-*"))) == 2


def test_an_unreadable_file_is_left_alone_and_not_saved_over(tmp_path):
    path = tmp_path / "measurements.json"
    path.mkdir()  # cannot be read as a file (as root too, unlike permissions)
    (path / "inside").write_text("keep")
    log, message = MeasurementLog.load(path)
    assert "cannot be read" in message and log.path is None
    log.add(measure(noisy_quaternions(1.0, 0.0, 0.01), "deg", 0.5))
    assert len(log) == 1 and (path / "inside").read_text() == "keep"
