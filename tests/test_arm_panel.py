"""The Arm dock: entered lengths and angles give R and Z; placements give the statistics."""

from __future__ import annotations

import csv
import os

import numpy as np
import pytest

from app.core.arm import ArmLayout, jamris_layout
from app.core.orientation import quaternion_from_roll_pitch
from app.gui import theme
from app.gui.arm_panel import COL_ANGLE, COL_LENGTH, SHOWN_COORDINATES, ArmPanel


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
    sd_cell = panel.stats_table.item(1, SHOWN_COORDINATES.index("Z")).text()  # row SD
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


# -- theta from the magnetometers (#32) ---------------------------------------------------------
class SimArmWindows:
    """The two sensors of sim://arm?column=1 with magnetometers as a capture source: the
    newest seconds before ``self.t`` (true seconds), the field corrected with each unit's
    exact calibration (as after calibrate-mag)."""

    URL = ("sim://arm?column=1&mag=lis3mdl&date=2026-06-01&seed=3&spots=4&hold=1.2"
           "&transition=0.8&realtime=0&block=4096")

    def __init__(self, seconds: float) -> None:
        from app.core.calibration import MagnetometerCalibration
        from app.core.samples import convert_raw_block
        from drivers.sim.device import SimulatedDevice
        self.devices = [SimulatedDevice(self.URL, sensor=k) for k in (0, 1)]
        self.scenario = self.devices[0].scenario
        self.accel, self.mag = [], []
        for device in self.devices:
            device.open()
            blocks = []
            while sum(len(b) for b in blocks) < seconds * device.odr_hz:
                raw = device.read(1.0)
                if raw is not None:
                    blocks.append(convert_raw_block(raw))
            device.close()
            correction = MagnetometerCalibration.from_json(
                device.unit_errors.magnetometer.calibration_json())
            self.accel.append(np.concatenate([b.accel_m_s2 for b in blocks]))
            self.mag.append(correction.apply(np.concatenate([b.mag_ut for b in blocks])))
        self.t = 0.0

    def __call__(self, seconds: float):
        from app.services.group_attitudes import SensorWindow
        rate = self.devices[0].true_odr_hz
        rows = slice(int((self.t - seconds) * rate), int(self.t * rate))
        return [SensorWindow(link, accel[rows], mag[rows])
                for link, accel, mag in zip((1, 2), self.accel, self.mag)]

    def quaternions(self):
        from app.core import quaternion as quat
        return [None, *(quat.normalize(d.scenario.orientation(np.array([self.t]))[0])
                        for d in self.devices)]


def test_theta_is_measured_live_and_per_capture_from_the_magnetometers(panel):
    from app.core.arm import COLUMN_AZIMUTH
    from app.services.arm_recordings import arm_layout_of
    source = SimArmWindows(9.0)
    panel.set_layout(arm_layout_of(source.scenario))
    panel.set_capture_source(source)
    windows = source.scenario.placement_windows(4)
    truths = []
    for k, (_start, end) in enumerate(windows):
        source.t = end - 0.05
        panel.clock.t += 1.0
        if k == 0:
            assert panel.set_theta_zero()
        panel.set_link_orientations(source.quaternions())
        assert "θ measured by the magnetometers" in panel.theta_label.text()
        assert panel.capture(), panel.message.text()
        truths.append(source.scenario.column_angles_deg(np.array([source.t]))[0, 0])
    expected = (np.array(truths) - truths[0] + 180.0) % 360.0 - 180.0
    table = panel.placements.table()
    np.testing.assert_allclose(table[:, 5], expected, atol=1.0)  # theta, degrees
    assert panel.placements.theta_sources == ("measured",) * 4
    # The live readout follows the last placement (also theta).
    assert number(panel.values["azimuth_deg"]) == pytest.approx(expected[-1], abs=1.0)
    column = SHOWN_COORDINATES.index("azimuth_deg")
    assert panel.stats_table.horizontalHeaderItem(column).text() == "θ °"
    stats = panel.placements.statistics()
    assert float(panel.stats_table.item(4, column).text()) == pytest.approx(
        stats["azimuth_deg"].range, abs=0.006)
    assert COLUMN_AZIMUTH in stats
    # Moving between placements: refused, with the reason, and nothing added.
    source.t = windows[1][1] + 0.5
    panel.clock.t += 1.0
    assert not panel.capture()
    assert "Placement refused" in panel.message.text()
    assert "not steady" in panel.message.text()
    assert len(panel.placements) == 4
    # The zero stays while there are placements measured from it.
    source.t = windows[1][1] - 0.05
    zero = panel.theta_zero
    assert not panel.set_theta_zero()
    assert "Clear them first" in panel.message.text() and panel.theta_zero == zero
    panel.clear_captures()
    assert panel.set_theta_zero() and panel.theta_zero != zero
