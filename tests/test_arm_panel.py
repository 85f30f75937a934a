"""The Arm dock: entered lengths and angles give R and Z; placements give the statistics."""

from __future__ import annotations

import csv
import os

import numpy as np
import pytest

from app.core.arm import ArmLayout, jamris_layout
from app.core.orientation import quaternion_from_roll_pitch
from app.gui import theme
from app.gui.arm_panel import COL_ANGLE, COL_LENGTH, ArmPanel


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def panel(qtbot, qapp):
    theme.apply_theme(qapp)
    clock = Clock()
    panel = ArmPanel(clock=clock)
    panel.clock = clock
    qtbot.addWidget(panel)
    panel.resize(460, 820)
    panel.show()
    return panel


def number(label) -> float:
    return float(label.text().split()[0])


def test_entered_lengths_and_angles_give_r_and_z(panel):
    for row, length in enumerate((150.0, 320.0, 275.0)):
        panel.table.cellWidget(row, COL_LENGTH).setValue(length)
    for row, angle in enumerate((30.0, 90.0, -90.0)):  # upper arm straight up, forearm level
        panel.table.cellWidget(row, COL_ANGLE).setValue(angle)
    assert number(panel.values["R"]) == pytest.approx(275.0, abs=0.05)
    assert number(panel.values["Z"]) == pytest.approx(150.0 + 320.0, abs=0.05)
    assert number(panel.values["x"]) == pytest.approx(275.0 * np.cos(np.radians(30)), abs=0.05)
    assert number(panel.values["y"]) == pytest.approx(275.0 * np.sin(np.radians(30)), abs=0.05)
    assert panel.values["R"].text().endswith("mm")


def test_link_orientations_drive_the_hinges_and_the_column_keeps_its_entered_angle(panel):
    panel.table.cellWidget(0, COL_ANGLE).setValue(90.0)
    upper = quaternion_from_roll_pitch(0.0, 40.0, 12.0)  # heading is not seen by gravity
    fore = quaternion_from_roll_pitch(0.0, -20.0, -70.0)
    panel.set_link_orientations([None, upper, fore])
    assert panel.pose.joint_angles_deg == pytest.approx([90.0, 40.0, -60.0], abs=1e-9)
    assert panel.sensor_links == (1, 2)
    r = 300 * np.cos(np.radians(40)) + 300 * np.cos(np.radians(-20))
    assert number(panel.values["R"]) == pytest.approx(r, abs=0.05)
    assert panel.pose.end[1] == pytest.approx(r)  # the column turned the arm to +y
    assert "(sensor)" in panel.pose_note.text()


def test_bad_input_leaves_the_pose_and_says_why(panel, tmp_path):
    panel.set_joint_angles([0.0, 10.0, 20.0])
    pose = panel.pose
    panel.set_joint_angles([1.0, 2.0])
    assert panel.pose is pose
    assert "2 joint angles for 3" in panel.message.text()
    bad = tmp_path / "bad.json"
    bad.write_text('{"links": [{"name": "a", "length": -5}]}')
    assert not panel.load_layout(str(bad))
    assert "length must be >= 0" in panel.message.text()
    assert panel.arm.n_joints == 3


def test_layout_saves_and_loads(panel, tmp_path):
    panel.add_link()
    panel.table.cellWidget(3, COL_LENGTH).setValue(42.0)
    path = tmp_path / "arm.json"
    assert panel.save_layout(str(path))
    saved = ArmLayout.from_json(path.read_text())
    assert saved.n_joints == 4 and saved.links[3].length == 42.0
    assert panel.load_layout(str(path)) and panel.arm == saved
    jamris = tmp_path / "jamris.json"
    jamris.write_text(jamris_layout(1.0, 2.0, 3.0).to_json())
    assert panel.load_layout(str(jamris))
    assert panel.table.rowCount() == 3
    assert panel.table.cellWidget(2, COL_LENGTH).value() == 3.0


def test_captured_placements_give_the_statistics_and_export(panel, qapp, tmp_path, artifacts_dir):
    rng = np.random.default_rng(7)
    pitches = (30.0, 30.2, 29.9, 30.1, 29.8)
    for pitch in pitches:
        panel.clock.t += 10.0  # a new placement: the old one's end points leave the window
        for _ in range(20):
            panel.clock.t += 0.04
            panel.set_device_orientation(
                quaternion_from_roll_pitch(0.0, pitch + rng.normal(0.0, 0.02))
            )
        assert panel.capture()
    stats = panel.placements.statistics()
    assert stats["Z"].n == 5
    # Each placement averages its window: Z follows 200 + 600 sin(pitch) (forearm in line).
    expected_z = [200 + 600 * np.sin(np.radians(p)) for p in pitches]
    assert stats["Z"].sd == pytest.approx(np.std(expected_z, ddof=1), rel=0.05)
    assert stats["Z"].max - stats["Z"].min == pytest.approx(np.ptp(expected_z), rel=0.05)
    sd_cell = panel.stats_table.item(1, 1).text()  # row SD, column Z
    assert float(sd_cell) == pytest.approx(stats["Z"].sd, abs=0.006)
    assert "5 placements" in panel.count_label.text()
    path = tmp_path / "repeat.csv"
    assert panel.export_csv(str(path))
    rows = list(csv.reader(line for line in path.read_text().splitlines()
                           if not line.startswith("#")))
    assert rows[0][:3] == ["placement", "samples", "x"]
    assert [row[0] for row in rows[1:]] == ["1", "2", "3", "4", "5",
                                            "mean", "sd", "min", "max", "range"]
    qapp.processEvents()  # the layout takes the message's new height
    assert panel.grab().save(os.path.join(artifacts_dir, "arm_panel_stats.png"))
    panel.undo_capture()
    assert len(panel.placements) == 4


def test_capture_without_data_says_so(panel):
    panel.clock.t += 1000.0
    assert not panel.capture()
    assert "Nothing to capture" in panel.message.text()
    assert len(panel.placements) == 0
