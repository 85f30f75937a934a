"""Calibration profiles on disk: round trip, atomic writes, and clear errors that lose nothing.

Every test uses ``tmp_path``; none touches the real user data directory.
"""

from __future__ import annotations

import json
import os
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pytest

from app import __version__
from app.core.calibration import SensorCalibration
from app.core.calibration_procedures import (
    CalibrationProfile,
    ProfileCorruptError,
    ProfileDeviceMismatchError,
    ProfileError,
    ProfileNotFoundError,
    ProfileStore,
    ProfileVersionError,
    SensorSettings,
    TareReference,
    make_profile,
)
from app.core.calibration_procedures import profiles as profiles_module

UID = "SIM-C2F5490A546C10CF485CAAE8"
OTHER_UID = "SIM-0123456789ABCDEF01234567"
SETTINGS = SensorSettings(odr_hz=104.0, accel_fs_g=4, gyro_fs_dps=250)


def a_profile(uid: str = UID, created: str = "2026-05-09T07:35:25Z", bias: float = 0.05):
    calibration = SensorCalibration(
        accel_bias_m_s2=np.array([bias, -0.1, 0.07]),
        accel_matrix=np.array([[1.01, 0.002, -0.001], [0.0, 0.99, 0.003], [0.001, 0.0, 1.005]]),
        gyro_bias_rad_s=np.array([0.004, -0.015, 0.016]),
        name="six-position 2026-05-09",
    )
    return make_profile(
        uid, calibration, SETTINGS, method="six-position", temperature_degc=26.9,
        residuals={"residual_norm_rms_mg": 0.014, "bias_std_mg": np.array([0.01, 0.01, 0.01]),
                   "nan_becomes_null": float("nan")},
        tare=TareReference.from_angles(1.0, -0.5), created_utc=created,
    )


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_save_and_load_round_trip(tmp_path):
    store = ProfileStore(tmp_path)
    profile = a_profile()
    path = store.save(profile)
    assert path == tmp_path / f"{UID}.json" and store.exists(UID)
    loaded = store.load(UID)
    cal, want = loaded.calibration, profile.calibration
    np.testing.assert_array_equal(cal.accel_bias_m_s2, want.accel_bias_m_s2)
    np.testing.assert_array_equal(cal.accel_matrix, want.accel_matrix)
    np.testing.assert_array_equal(cal.gyro_bias_rad_s, want.gyro_bias_rad_s)
    np.testing.assert_array_equal(cal.gyro_matrix, np.eye(3))
    assert cal.name == "six-position 2026-05-09"
    assert loaded.settings == SETTINGS
    assert loaded.temperature_degc == 26.9 and loaded.method == "six-position"
    assert loaded.app_version == __version__ and loaded.format_version == 1
    assert loaded.residuals["bias_std_mg"] == [0.01, 0.01, 0.01]
    assert loaded.residuals["nan_becomes_null"] is None
    np.testing.assert_allclose(loaded.tare.quaternion, profile.tare.quaternion)
    assert loaded.created == datetime(2026, 5, 9, 7, 35, 25, tzinfo=UTC)
    assert loaded.age(datetime(2026, 5, 10, 7, 35, 25, tzinfo=UTC)) == timedelta(days=1)
    data = json.loads(path.read_text())
    assert data["format_version"] == 1 and data["device_unique_id"] == UID
    assert data["sensor_settings"] == {
        "sensor": "LSM6DSOX", "odr_hz": 104.0, "accel_fs_g": 4, "gyro_fs_dps": 250,
    }
    assert store.load_for_device(OTHER_UID) is None


def test_creation_time_is_utc_iso_8601(tmp_path):
    profile = make_profile(UID, SensorCalibration(), SETTINGS)
    assert profile.created_utc.endswith("Z")
    assert abs(profile.age()) < timedelta(minutes=1)


def test_saving_again_keeps_the_previous_profile_in_history(tmp_path):
    store = ProfileStore(tmp_path)
    store.save(a_profile(bias=0.01))
    store.save(a_profile(created="2026-06-01T00:00:00Z", bias=0.02))
    assert store.load(UID).calibration.accel_bias_m_s2[0] == 0.02
    history = store.history(UID)
    assert [p.name for p in history] == [f"{UID}-20260509T073525Z.json"]
    old = profiles_module.read_profile_file(history[0])
    assert old.calibration.accel_bias_m_s2[0] == 0.01
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*"))


def test_a_corrupt_file_gets_a_clear_error_and_nothing_is_lost(tmp_path):
    store = ProfileStore(tmp_path)
    store.save(a_profile(uid=OTHER_UID))
    path = store.path_for(UID)
    path.write_text('{"format": "inclinometer-calibration-profile", "format_ver')
    before = snapshot(tmp_path)
    with pytest.raises(ProfileCorruptError, match="not valid JSON") as info:
        store.load(UID)
    assert str(path) in str(info.value) and info.value.path == path
    assert snapshot(tmp_path) == before  # nothing deleted, moved or rewritten
    assert store.load(OTHER_UID).device_unique_id == OTHER_UID  # the other profile still loads
    listing = store.list()
    assert [p.device_unique_id for _, p in listing.profiles] == [OTHER_UID]
    assert [p for p, _ in listing.problems] == [path]
    # Saving a good profile over the corrupt one keeps the corrupt bytes in history.
    store.save(a_profile())
    kept = [p for p in store.history(UID) if p.read_bytes() == before[path.name]]
    assert len(kept) == 1


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("parameters"), "'parameters' is missing"),
        (lambda d: d["parameters"].update(accel_bias_m_s2=[1, 2]), "shape"),
        (lambda d: d["parameters"].update(accel_matrix=[[0] * 3] * 3), "singular"),
        (lambda d: d["sensor_settings"].update(accel_fs_g="4"), "whole number"),
        (lambda d: d.update(created_utc="yesterday"), "ISO 8601"),
        (lambda d: d.update(format="something else"), "'format'"),
        (lambda d: d.update(tare_quaternion=[1, 0]), "tare_quaternion"),
    ],
)
def test_invalid_fields_are_named(tmp_path, edit, message):
    store = ProfileStore(tmp_path)
    path = store.save(a_profile())
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    before = path.read_bytes()
    with pytest.raises(ProfileCorruptError, match=message):
        store.load(UID)
    assert path.read_bytes() == before


def test_a_foreign_profile_is_refused(tmp_path):
    store = ProfileStore(tmp_path / "store")
    foreign = a_profile(uid=OTHER_UID)
    # Someone copied another device's file under this device's name.
    profiles_module.write_profile_file(store.path_for(UID), foreign)
    before = snapshot(store.base_dir)
    with pytest.raises(ProfileDeviceMismatchError, match="belongs to device") as info:
        store.load(UID)
    assert OTHER_UID in str(info.value) and UID in str(info.value)
    assert snapshot(store.base_dir) == before
    # Importing a foreign file for the connected device is refused before the store changes.
    outside = tmp_path / "exported-elsewhere.json"
    profiles_module.write_profile_file(outside, foreign)
    with pytest.raises(ProfileDeviceMismatchError):
        store.import_file(outside, expected_unique_id=UID)
    assert snapshot(store.base_dir) == before
    assert "another device's name" in store.list().problems[0][1]


def test_another_format_version_is_refused(tmp_path):
    store = ProfileStore(tmp_path)
    path = store.save(a_profile())
    data = json.loads(path.read_text())
    data["format_version"] = 2
    path.write_text(json.dumps(data))
    before = snapshot(tmp_path)
    with pytest.raises(ProfileVersionError, match="format version 2 was written by a newer"):
        store.load(UID)
    assert snapshot(tmp_path) == before
    data["format_version"] = "1"
    path.write_text(json.dumps(data))
    with pytest.raises(ProfileCorruptError, match="format_version"):
        store.load(UID)


def test_missing_profile(tmp_path):
    store = ProfileStore(tmp_path / "not-created-yet")
    with pytest.raises(ProfileNotFoundError, match="no calibration profile"):
        store.load(UID)
    assert store.list().profiles == [] and store.history(UID) == []
    assert not (tmp_path / "not-created-yet").exists()  # reading creates nothing
    assert issubclass(ProfileNotFoundError, ProfileError)


def test_export_and_import(tmp_path):
    store = ProfileStore(tmp_path / "a")
    store.save(a_profile())
    exported = store.export(UID, tmp_path / "exported.json")
    with pytest.raises(FileExistsError):
        store.export(UID, exported)
    other = ProfileStore(tmp_path / "b")
    imported = other.import_file(exported, expected_unique_id=UID)
    assert imported.device_unique_id == UID
    assert other.load(UID).to_json_dict() == store.load(UID).to_json_dict()


def test_writes_are_atomic(tmp_path, monkeypatch):
    store = ProfileStore(tmp_path)
    path = store.save(a_profile(bias=0.01))
    before = path.read_bytes()

    real_replace = os.replace

    def crash_on_the_profile(src, dst):
        if Path(dst) == path:
            raise OSError("disk full")
        real_replace(src, dst)

    monkeypatch.setattr(profiles_module.os, "replace", crash_on_the_profile)
    with pytest.raises(OSError, match="disk full"):
        store.save(a_profile(created="2026-06-01T00:00:00Z", bias=0.02))
    monkeypatch.undo()
    assert path.read_bytes() == before  # the old profile is intact
    assert [p.read_bytes() for p in store.history(UID)] == [before]
    leftovers = [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]
    assert leftovers == []


def test_unsafe_device_ids_get_safe_distinct_file_names(tmp_path):
    store = ProfileStore(tmp_path)
    a = store.path_for("usb:1/2")
    b = store.path_for("usb:1_2")
    assert a != b and a.parent == tmp_path and b.parent == tmp_path
    assert store.path_for("../../etc/passwd").parent == tmp_path
    store.save(a_profile(uid="usb:1/2"))
    assert store.load("usb:1/2").device_unique_id == "usb:1/2"


def test_default_directory_is_the_platform_user_data_dir(monkeypatch, tmp_path):
    import platformdirs

    calls = []

    def fake_user_data_dir(appname, appauthor=None, *args, **kwargs):
        calls.append((appname, appauthor))
        return str(tmp_path / "user-data")

    monkeypatch.setattr(platformdirs, "user_data_dir", fake_user_data_dir)
    store = ProfileStore()
    assert store.base_dir == tmp_path / "user-data" / "profiles"
    assert calls == [("Inclinometer", False)]
    assert not store.base_dir.exists()


def test_profile_json_dict_round_trip_without_disk():
    profile = a_profile()
    again = CalibrationProfile.from_json_dict(profile.to_json_dict())
    assert again.to_json_dict() == profile.to_json_dict()
    assert os.sep not in profiles_module.file_stem_for("a/b")
    assert SETTINGS.differences(SensorSettings(104.0, 8, 250)) == [
        "accelerometer range +-4 g vs +-8 g"
    ]
