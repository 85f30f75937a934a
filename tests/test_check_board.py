"""``inclinometer check-board``: the bring-up check, against the firmware's own core on a pty and
against an emulated board that loses packets."""

from __future__ import annotations

import argparse
import io
import sys
from dataclasses import replace

import numpy as np
import pytest
from fwcore import FirmwareCore, PtyBoard

from app.cli import build_parser
from app.cli.check_board import check_board, check_command, clock_ppm_of
from drivers import lsm6dsox
from drivers.emulated_nucleo import EmulatedNucleo, NucleoFaults
from drivers.link import protocol as p
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox
from drivers.sim.options import SimOptions

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals")


def test_the_firmware_core_passes_and_says_which_rates_it_refuses(firmware_lib) -> None:
    board = PtyBoard(lambda: FirmwareCore(
        firmware_lib, EmulatedLsm6dsox(SimOptions("static", seed=9)), unique_id=bytes(12)))
    out = io.StringIO()
    try:
        passed = check_board(board.port, [104.0, 1667.0, 3333.0], 0.5, True, out)
    finally:
        board.close()
    report = out.getvalue()
    assert passed, report
    assert "board     NUCLEO-F746ZG, firmware 1.2.0, unique id 000000000000000000000000" in report
    assert "WHO_AM_I 0x6C" in report and "ping      20 round trips" in report
    lines = {line.split()[0]: line for line in report.splitlines() if line.strip()}
    assert lines["104"].endswith("ok") and lines["1667"].endswith("ok")
    assert "refused by the board" in lines["3333"] and "highest ODR 1667 Hz" in lines["3333"]
    assert "self-test accelerometer pass" in report
    # The firmware's own counters, and that nothing was lost on the board.
    assert "health    started by power-on, up " in report
    overruns = next(line for line in report.splitlines() if "Sensor FIFO overruns" in line)
    assert overruns.split()[3:] == ["0", "(+0", "during", "the", "check)"]
    sent = next(line for line in report.splitlines() if "Samples sent" in line)
    assert int(sent.split()[3].strip("(+").replace(",", "")) > 0.5 * (104 + 1667)
    assert report.rstrip().endswith("PASS: the board works.")


def test_a_two_sensor_board_passes_1667_hz_with_sensor_1_paused() -> None:
    """An IKS01A3 with an adapter: the second chip costs no rate; the board says it paused it."""
    board = EmulatedNucleo("static", seed=3, sensors=2, sensor_bus_hz=400_000)
    out = io.StringIO()
    try:
        passed = check_board(board.port, [1667.0, 3333.0], 0.5, False, out)
    finally:
        board.close()
    report = out.getvalue()
    assert passed, report
    rows = report.splitlines()
    lines = {line.split()[0]: line for line in rows if line.strip()}
    assert lines["1667"].endswith("ok")
    notes = [line.strip() for line in rows if line.strip().startswith("note:")]
    assert notes == ["note: sensor 1 (0x6B) paused: 1667 Hz does not fit two sensors on I2C "
                     "400 kHz (highest 833 Hz)"]
    assert rows.index("         " + notes[0]) == rows.index(lines["1667"]) + 1
    assert "refused by the board" in lines["3333"] and "sensors" not in lines["3333"]


def test_lost_packets_fail_the_check() -> None:
    board = EmulatedNucleo("static", seed=3, faults=NucleoFaults(drop_seqs=frozenset({20, 21})))
    out = io.StringIO()
    try:
        passed = check_board(board.port, [833.0], 1.0, False, out)
    finally:
        board.close()
    report = out.getvalue()
    assert not passed
    row = next(line for line in report.splitlines() if line.strip().startswith("833"))
    lost, gaps = (int(value) for value in row.split()[2:4])
    assert lost > 0 and gaps == 1 and row.endswith("FAIL")
    assert report.rstrip().endswith("FAIL: see the lines marked FAIL.")


def test_a_port_without_a_board_fails_at_open(tmp_path) -> None:
    out = io.StringIO()
    assert not check_board(str(tmp_path / "ttyNONE"), [104.0], 0.5, False, out)
    assert out.getvalue().startswith("FAIL  open:")


def test_rates_are_checked_before_anything_is_opened(capsys) -> None:
    args = build_parser().parse_args(["check-board", "/dev/null", "--rates", "104,100"])
    assert check_command(args) == 2
    assert "100 Hz is not an LSM6DSOX rate" in capsys.readouterr().err
    bad = argparse.Namespace(port="/dev/null", rates="fast", seconds=1.0, no_self_test=True)
    assert check_command(bad) == 2


class LabelRateBoard(EmulatedNucleo):
    """A board whose firmware reports the datasheet label as its rate (earlier builds: CONFIG
    said 104 Hz while the chip ran at 104.17 Hz); its samples come at the real rate."""

    @property
    def config(self) -> p.Config:
        real = super().config
        label = lsm6dsox.ODR_LABELS_HZ[self._settings[0]]
        return replace(real, odr_mhz=round(label * 1000 * 25_000 / real.tick_ns))


def test_a_board_reporting_the_label_as_its_rate_fails_the_rate_check() -> None:
    board = LabelRateBoard("static", seed=3)
    out = io.StringIO()
    try:
        passed = check_board(board.port, [104.0], 1.5, False, out)
    finally:
        board.close()
    report = out.getvalue()
    assert not passed, report
    row = next(line for line in report.splitlines() if line.strip().startswith("104 "))
    assert row.endswith("FAIL")
    measured_hz = float(row.split()[6])
    assert measured_hz == pytest.approx(104.167 * board._sim.unit_errors.clock_trim_factor,
                                        rel=5e-4)  # the samples come at the real rate
    assert "rate: the chip should run at" in report and "the board reports 10" in report


def test_the_emulated_board_runs_and_reports_the_real_rate() -> None:
    board = EmulatedNucleo("static", seed=3)
    out = io.StringIO()
    try:
        passed = check_board(board.port, [104.0], 1.5, False, out)
    finally:
        board.close()
    report = out.getvalue()
    row = next(line for line in report.splitlines() if line.strip().startswith("104 "))
    assert passed and row.endswith("ok"), report
    assert abs(float(row.split()[7])) < 1_000  # rate ppm against 104.17 Hz x trim


def test_the_clock_fit_sees_a_slow_board_through_uneven_blocks_and_latency() -> None:
    # A board clock 2 % slow, read in blocks of 1 to 10 samples that arrive 1-40 ms after their
    # last sample: the first and last reads alone would be off by the latency difference.
    rng = np.random.default_rng(5)
    ends = np.cumsum(rng.integers(1, 11, 40)) / 104.0
    arrivals = [(float(t), float(t / 0.98 + rng.uniform(0.001, 0.040))) for t in ends]
    assert clock_ppm_of(arrivals) == pytest.approx(-20_000, abs=4_000)
    assert clock_ppm_of(arrivals[:2]) == 0.0  # too few reads to say


def test_the_emulated_board_drops_the_turn_on_transient() -> None:
    from drivers.serial_link import SerialLinkDevice

    board = EmulatedNucleo("static", seed=3, odr_hz=833, errors=False, noise=False)
    device = SerialLinkDevice(f"serial://{board.port}")
    try:
        device.open()
        block = None
        while block is None or not len(block):
            block = device.read(1.0)
    finally:
        device.close()
        board.close()
    assert board.stats.settling_discarded == lsm6dsox.turn_on_discard(833)
    # The first sample streamed is a settled one: 1 g at rest, no rate (the chip's first 70 read
    # up to 20 dps and a fraction of 1 g).
    accel_g = np.linalg.norm(block.accel_raw[0]) * lsm6dsox.ACCEL_MG_PER_LSB[4] / 1e3
    assert accel_g == pytest.approx(1.0, abs=0.01)
    assert np.abs(block.gyro_raw[0]).max() * lsm6dsox.GYRO_MDPS_PER_LSB[250] / 1e3 < 0.1


def test_a_look_alike_lsm6dso32_is_named_but_not_failed(firmware_lib) -> None:
    board = PtyBoard(lambda: FirmwareCore(
        firmware_lib, EmulatedLsm6dsox(SimOptions("static", seed=9), part="LSM6DSO32"),
        unique_id=bytes(12)))
    out = io.StringIO()
    try:
        passed = check_board(board.port, [104.0], 0.5, False, out)
    finally:
        board.close()
    report = out.getvalue()
    line = next(line for line in report.splitlines() if line.startswith("WARN"))
    assert "sensor: accelerometer reads 0.5" in line and "LSM6DSO32" in line
    assert passed, report  # a warning: the link and the rates work
