"""``inclinometer import``: x-IMU3's logged CSV, EuRoC/Kalibr imu0.csv and a mapped generic CSV
become format v1 recordings with their origin in the header (issue 34, items 3 and 5)."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from app import cli
from app.core.interop.importing import detect_format, read_any
from app.core.recording.reader import read_recording
from app.core.recording.samples import sample_recording
from app.core.samples import STANDARD_GRAVITY_M_S2

XIMU3_SERIAL = "65577B49"
T0_US = 34290905  # x-IMU3 timestamps: the device's microseconds since it started
EUROC_T0_NS = 1403636579758555392  # EuRoC MH_01's first IMU timestamp: beyond float64's 2^53


def write_ximu3(root: Path, *, rows: int = 400, bad_line: str | None = None) -> Path:
    """A data logger folder as the x-IMU3 GUI writes it: one device folder with Command.json,
    Inertial.csv (400 Hz), Magnetometer.csv (20 Hz, a.u.) and Temperature.csv (1 Hz)."""
    device = root / f"x-IMU3 - {XIMU3_SERIAL} (USB)"
    device.mkdir(parents=True)
    (device / "Command.json").write_text(
        '[\n    {"ping":{"interface":"USB","name":"x-IMU3","sn":"' + XIMU3_SERIAL + '"}},\n'
        '    {"time":"2026-11-27 08:00:00"}\n]')
    lines = ["Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),"
             "Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)"]
    for i in range(rows):  # ~2500 us apart with the jitter of a real log
        lines.append(f"{T0_US + i * 2500 + (i * 7) % 5},{0.212382 - i * 1e-4:.6f},-0.027105,"
                     f"{45 * math.sin(i / 40):.6f},0.000092,0.031777,{1.007784 - i * 1e-6:.6f}")
    if bad_line is not None:
        lines.insert(6, bad_line)
    (device / "Inertial.csv").write_text("\n".join(lines) + "\n")
    mag = ["Timestamp (us),X Axis (a.u.),Y Axis (a.u.),Z Axis (a.u.)"]
    for i in range(rows // 20):
        mag.append(f"{T0_US - 8714 + i * 50000},0.367{i % 7},-0.472{i % 3},-0.8012")
    (device / "Magnetometer.csv").write_text("\n".join(mag) + "\n")
    temp = ["Timestamp (us),Temperature (degC)"]
    temp += [f"{T0_US + 7492 + i * 498808},{41.125 + 0.025 * i:.6f}" for i in range(2)]
    (device / "Temperature.csv").write_text("\n".join(temp) + "\n")
    return root


EUROC_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
"""EuRoC MAV's header."""
EXPORT_HEADER = ("timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y,w_RS_S_z,a_RS_S_x [m s^-2],"
                 "a_RS_S_y,a_RS_S_z")
"""The header `inclinometer export --format euroc` writes (no '#', units on the first of each
sensor's columns), with timestamps zero-padded to ten digits."""


def write_euroc(path: Path, t_ns: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
                header: str = EUROC_HEADER, digits: int = 0) -> Path:
    """An imu0.csv as EuRoC's datasets and Kalibr's tools have it (floats written with repr)."""
    lines = [header]
    for stamp, w, a in zip(t_ns.tolist(), gyro.tolist(), accel.tolist()):
        lines.append(",".join([f"{stamp:0{digits}d}", *map(repr, w), *map(repr, a)]))
    path.write_text("\n".join(lines) + "\n")
    return path


def no_temporaries(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if p.name.startswith(".")]


# -- x-IMU3 -----------------------------------------------------------------------------------
def test_ximu3_log_becomes_a_recording_in_si_units_with_its_origin(tmp_path, capsys):
    root = write_ximu3(tmp_path / "log")
    out = tmp_path / "x.csv"
    assert cli.main(["import", str(root), str(out), "--mag-au-ut", "48.5"]) == 0
    assert "imported 400 samples" in capsys.readouterr().out
    rec = read_recording(out)
    inertial = np.loadtxt(next(root.iterdir()) / "Inertial.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(rec.t_s, (inertial[:, 0] - T0_US) / 1e6)
    np.testing.assert_allclose(rec.gyro_rad_s, np.radians(inertial[:, 1:4]), rtol=1e-15)
    np.testing.assert_allclose(rec.accel_m_s2, inertial[:, 4:7] * STANDARD_GRAVITY_M_S2,
                               rtol=1e-15)
    # 20 Hz field samples: each on the first inertial row at or after it, in uT.
    mag = np.loadtxt(next(root.iterdir()) / "Magnetometer.csv", delimiter=",", skiprows=1)
    rows = np.flatnonzero(~np.isnan(rec.mag_ut[:, 0]))
    assert len(rows) == len(mag)
    np.testing.assert_allclose(rec.mag_ut[rows], mag[:, 1:4] * 48.5, rtol=1e-15)
    assert np.all(rec.t_s[rows] >= (mag[:, 0] - T0_US) / 1e6)
    # The temperature is held from its first sample on, unknown before it.
    temp = rec.columns["temp"]
    assert np.isnan(temp[rec.t_s < 0.007492]).all()
    assert temp[-1] == pytest.approx(41.15)
    origin = rec.metadata["imported_from"]
    assert origin["format"] == "x-imu3-csv" and origin["file"] == "Inertial.csv"
    digest = hashlib.sha256((next(root.iterdir()) / "Inertial.csv").read_bytes()).hexdigest()
    assert origin["sha256"] == digest
    assert "ximu3csv" in origin["tool"] and origin["time_origin"] == {"value": T0_US,
                                                                       "unit": "us"}
    assert rec.metadata["device"]["unique_id"] == XIMU3_SERIAL
    assert rec.metadata["magnetometer"]["ut_per_unit"] == 48.5
    # Device blocks of ten samples (25 ms at 400 Hz), as a live device delivers them: a replay
    # hands them on at that pace instead of waiting for the whole file.
    starts = np.flatnonzero(rec.columns["block_start"] == 1)
    assert starts[0] == 0 and set(np.diff(starts)) == {10}


def test_ximu3_magnetometer_in_arbitrary_units_is_left_out_without_its_scale(tmp_path, capsys):
    root = write_ximu3(tmp_path / "log")
    out = tmp_path / "x.csv"
    assert cli.main(["import", str(next(root.iterdir()) / "Inertial.csv"), str(out)]) == 0
    assert "--mag-au-ut" in capsys.readouterr().err
    rec = read_recording(out)
    assert "mx" not in rec.header and "magnetometer" not in rec.metadata


def test_ximu3_bad_row_names_its_line_and_writes_nothing(tmp_path, capsys):
    root = write_ximu3(tmp_path / "log", bad_line="34303405,0.1,abc,0.2,0.0,0.0,1.0")
    out = tmp_path / "x.csv"
    assert cli.main(["import", str(root), str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "Inertial.csv: line 7, column 'Gyroscope Y (deg/s)': 'abc' is not a number" in err
    assert not out.exists() and no_temporaries(tmp_path)


def test_ximu3_time_going_back_is_refused_with_its_line(tmp_path, capsys):
    root = write_ximu3(tmp_path / "log", bad_line="34290000,0.1,0.1,0.2,0.0,0.0,1.0")
    assert cli.main(["import", str(root), str(tmp_path / "x.csv")]) == 2
    assert "Inertial.csv: line 7: the timestamp does not increase" in capsys.readouterr().err


# -- EuRoC / Kalibr ---------------------------------------------------------------------------
def test_euroc_imu0_keeps_nanosecond_timestamps_exactly(tmp_path):
    n = 600
    rng = np.random.default_rng(3)
    t_ns = EUROC_T0_NS + np.arange(n, dtype=np.int64) * 5_000_000 + rng.integers(0, 3, n)
    gyro = rng.normal(0, 0.1, (n, 3))
    accel = rng.normal([0, 0, 9.81], 0.05, (n, 3))
    src = write_euroc(tmp_path / "imu0.csv", t_ns, gyro, accel)
    assert detect_format(src) == "euroc"
    out = tmp_path / "e.csv"
    assert cli.main(["import", str(src), str(out)]) == 0
    rec = read_recording(out)
    origin = rec.metadata["imported_from"]
    assert origin["time_origin"] == {"value": int(t_ns[0]), "unit": "ns"}
    back = origin["time_origin"]["value"] + np.round(rec.t_s * 1e9).astype(np.int64)
    np.testing.assert_array_equal(back, t_ns)
    np.testing.assert_array_equal(rec.gyro_rad_s, gyro)
    np.testing.assert_array_equal(rec.accel_m_s2, accel)


def test_euroc_bad_field_and_wrong_units_are_one_line(tmp_path, capsys):
    src = tmp_path / "imu0.csv"
    write_euroc(src, np.array([10, 20, 30]), np.zeros((3, 3)), np.ones((3, 3)))
    text = src.read_text().splitlines()
    text[2] = "20,0.0,0.0,nan,1.0,1.0,1.0"
    src.write_text("\n".join(text) + "\n")
    assert cli.main(["import", str(src), str(tmp_path / "e.csv")]) == 2
    assert ("imu0.csv: line 3, column 'w_RS_S_z [rad s^-1]': 'nan' is not a finite number"
            in capsys.readouterr().err)
    text[0] = text[0].replace("[m s^-2]", "[g]", 1)
    text[2] = "20,0.0,0.0,0.0,1.0,1.0,1.0"
    src.write_text("\n".join(text) + "\n")
    assert cli.main(["import", str(src), str(tmp_path / "e.csv")]) == 2
    assert "unit [g], expected [m s^-2]" in capsys.readouterr().err
    assert not (tmp_path / "e.csv").exists()


# -- generic CSV ------------------------------------------------------------------------------
def test_generic_csv_through_a_mapping_converts_units_and_signs(tmp_path):
    src = tmp_path / "phone.csv"
    src.write_text("time_ms,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z,bx,by,bz\n"
                   "1000,0.0,0.5,0.8,10,0,-20,0.2,0.1,-0.4\n"
                   "1010,0.1,0.5,0.8,10,5,-20,0.2,0.1,-0.4\n\n"
                   "1020,0.2,0.5,0.8,10,5,-25,0.2,0.1,-0.4\n")
    assert detect_format(src) is None
    spec = ("t=time_ms:ms,ax=acc_x:g,ay=-acc_y:g,az=#4:g,gx=gyro_x:dps,gy=gyro_y:dps,"
            "gz=gyro_z:deg/s,mx=bx:G,my=by:G,mz=bz:G")
    out = tmp_path / "g.csv"
    assert cli.main(["import", str(src), str(out), "--map", spec]) == 0
    rec = read_recording(out)
    np.testing.assert_allclose(rec.t_s, [0.0, 0.01, 0.02], atol=1e-15)
    np.testing.assert_allclose(rec.accel_m_s2[2], np.array([0.2, -0.5, 0.8]) * 9.80665)
    np.testing.assert_allclose(rec.gyro_rad_s[2], np.radians([10, 5, -25]))
    np.testing.assert_allclose(rec.mag_ut[0], [20.0, 10.0, -40.0])
    assert rec.metadata["imported_from"]["mapping"]["ay"] == {"column": "acc_y", "unit": "g",
                                                               "sign": -1}


@pytest.mark.parametrize(("spec", "message"), [
    ("t=time_ms:ms,ax=acc_x:g", "--map lacks ay, az, gx, gy, gz"),
    ("t=time_ms:fortnights,ax=a:g", "unit 'fortnights' for t"),
    ("t=time_ms:ms,ax=nope:g,ay=acc_y:g,az=acc_z:g,gx=gx:dps,gy=gx:dps,gz=gx:dps",
     "no column 'nope' in the header on line 1"),
])
def test_generic_csv_mapping_mistakes_are_one_line(tmp_path, capsys, spec, message):
    src = tmp_path / "phone.csv"
    src.write_text("time_ms,acc_x,acc_y,acc_z,gx\n1,0,0,1,0\n2,0,0,1,0\n")
    assert cli.main(["import", str(src), str(tmp_path / "g.csv"), "--map", spec]) == 2
    err = capsys.readouterr().err
    assert message in err and err.strip().count("\n") == 0


def test_unknown_csv_without_a_mapping_is_refused(tmp_path, capsys):
    src = tmp_path / "other.csv"
    src.write_text("a,b\n1,2\n")
    assert cli.main(["import", str(src), str(tmp_path / "o.csv")]) == 2
    assert "give the columns with --map" in capsys.readouterr().err


# -- output safety ----------------------------------------------------------------------------
def test_existing_output_is_kept_unless_overwrite(tmp_path, capsys):
    root = write_ximu3(tmp_path / "log")
    out = tmp_path / "x.csv"
    out.write_text("precious\n")
    assert cli.main(["import", str(root), str(out)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert out.read_text() == "precious\n"
    assert cli.main(["import", str(root), str(out), "--force"]) == 0
    assert len(read_recording(out)) == 400 and no_temporaries(tmp_path)


# -- round trip (item 5) ----------------------------------------------------------------------
@pytest.mark.parametrize(("header", "digits"), [(EUROC_HEADER, 0), (EXPORT_HEADER, 10)])
def test_recording_to_euroc_and_back_gives_the_same_samples(tmp_path, header, digits):
    """A recording written as EuRoC (integer ns, repr floats; EuRoC's header, and the one
    `export --format euroc` writes, zero-padded from t = 0) and imported again: the same
    samples, time to the nanosecond the format holds. (The lead links the export writer here
    once both are merged.)"""
    original = read_recording(sample_recording("wobble-104hz.csv"))
    t_ns = np.round(original.t_s * 1e9).astype(np.int64)
    src = write_euroc(tmp_path / "imu0.csv", t_ns, original.gyro_rad_s, original.accel_m_s2,
                      header, digits)
    assert detect_format(src) == "euroc"
    out = tmp_path / "back.csv"
    assert cli.main(["import", str(src), str(out)]) == 0
    back = read_recording(out)
    t0 = back.metadata["imported_from"]["time_origin"]["value"]
    np.testing.assert_array_equal(t0 + np.round(back.t_s * 1e9).astype(np.int64), t_ns)
    np.testing.assert_allclose(back.t_s + t0 / 1e9, original.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(back.gyro_rad_s, original.gyro_rad_s)
    np.testing.assert_array_equal(back.accel_m_s2, original.accel_m_s2)


def test_detection_by_content(tmp_path):
    root = write_ximu3(tmp_path / "log")
    device = next(root.iterdir())
    renamed = tmp_path / "inertial_copy.csv"
    renamed.write_bytes((device / "Inertial.csv").read_bytes())
    assert [detect_format(p) for p in (root, device, device / "Inertial.csv", renamed)] == [
        "x-imu3"] * 4
    assert detect_format(sample_recording("wobble-104hz.csv")) == "recording"
    data = read_any(renamed)
    assert len(data) == 400 and json.dumps(data.origin)


@pytest.mark.parametrize(("name", "content", "message"), [
    ("empty.csv", "", "the file is empty"),
    ("missing.csv", None, "no such file or folder"),
    ("Inertial.csv", "Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z "
     "(deg/s),Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n",
     "Inertial.csv: no data rows below the header (line 1)"),
])
def test_hostile_inputs_are_one_line_and_write_nothing(tmp_path, capsys, name, content,
                                                       message):
    src = tmp_path / name
    if content is not None:
        src.write_text(content)
    assert cli.main(["import", str(src), str(tmp_path / "out.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(message) and "\n" not in err
    assert not (tmp_path / "out.csv").exists()


def test_ximu3_older_gui_spelling_of_the_device_is_read(tmp_path):
    """The x-IMU3 GUI's older logs name the device deviceName/serialNumber (ximu3csv reads
    name/sn) and the magnetometer columns 'X Axis (a.u.)'."""
    root = write_ximu3(tmp_path / "log", rows=40)
    device = next(root.iterdir())
    (device / "Command.json").write_text(
        '[\n    {"ping":{"deviceName":"x-IMU3","interface":"USB",'
        '"serialNumber":"F7E4-5410-EC7B-D7E7"}},\n    {"time":"2022-08-11 12:03:39"}\n]')
    data = read_any(root, mag_au_ut=50.0)
    assert data.device["unique_id"] == "F7E4-5410-EC7B-D7E7" and data.device["name"] == "x-IMU3"
    assert data.mag_ut is not None
