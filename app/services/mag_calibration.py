"""The magnetometer's calibration from a recorded tour (``inclinometer calibrate-mag``).

Reads a recording with ``mx,my,mz`` (and the accelerometer and gyroscope), fits it with
:func:`app.core.magnetometer.fit.fit_magnetometer` against the local WMM field when the place
is known, and stores the result in the device's calibration profile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from datetime import date, datetime
from pathlib import Path
from typing import Any

from app.core.calibration import MAG_KEY, SensorCalibration
from app.core.calibration_procedures.profiles import (
    CalibrationProfile,
    ProfileStore,
    SensorSettings,
    make_profile,
)
from app.core.earth_field import EarthField, Place, earth_field
from app.core.magnetometer.fit import MagFitResult, fit_magnetometer
from app.core.recording.format import KEY_START_TIME
from app.core.recording.reader import read_recording

DEFAULT_ACCEL_FS_G = 4
DEFAULT_GYRO_FS_DPS = 250


@dataclass(frozen=True)
class MagCalibrationRun:
    """A fitted tour and what it was compared with."""

    result: MagFitResult
    source: str
    device: dict[str, Any]
    settings: SensorSettings
    expected: EarthField | None = None
    when: date | None = None
    notes: tuple[str, ...] = field(default=())

    @property
    def unique_id(self) -> str:
        return str(self.device.get("unique_id") or "")

    def document(self) -> dict[str, Any]:
        """The binding JSON: ``{"magnetometer": {"hard_iron_uT", "soft_iron", "field_uT",
        "dip_deg", "fitness_uT", "coverage", "alignment_deg", "method", "verdict", "reasons",
        ...}}``; ``wmm`` holds the reference it was judged against (when the place was
        known)."""
        body = self.result.to_json()
        body["source"] = self.source
        if self.expected is not None:
            body["wmm"] = {
                "field_uT": self.expected.total_ut, "dip_deg": self.expected.dip_deg,
                "declination_deg": self.expected.declination_deg,
                "latitude_deg": self.expected.place.latitude_deg,
                "longitude_deg": self.expected.place.longitude_deg,
                "date": None if self.when is None else self.when.isoformat(),
            }
        return {MAG_KEY: body}


def recording_date(metadata: dict[str, Any]) -> date | None:
    """The day a recording started (its ``start_time``), None when it does not say."""
    value = metadata.get(KEY_START_TIME)
    if not isinstance(value, str):
        return None
    try:
        return datetime.fromisoformat(value.replace("Z", "+00:00")).date()
    except ValueError:
        return None


def _settings(device: dict[str, Any], rate_hz: float) -> SensorSettings:
    odr = device.get("odr_hz")
    accel_fs = device.get("accel_fs_g")
    gyro_fs = device.get("gyro_fs_dps")
    if not isinstance(odr, int | float) or isinstance(odr, bool) or not odr > 0:
        odr = rate_hz if math.isfinite(rate_hz) and rate_hz > 0 else 1.0
    if not isinstance(accel_fs, int) or not isinstance(gyro_fs, int):
        accel_fs, gyro_fs = DEFAULT_ACCEL_FS_G, DEFAULT_GYRO_FS_DPS
    return SensorSettings(float(odr), accel_fs, gyro_fs, str(device.get("sensor") or "LSM6DSOX"))


def calibrate_recording(path: str | Path, place: Place | None = None,
                        when: date | None = None) -> MagCalibrationRun:
    """Fit the magnetometer on the recording at ``path``.

    ``place`` (optional) brings the local WMM field into the verdict, on ``when`` (default:
    the day the recording started). Raises ``RecordingError``/``OSError`` for a file that
    cannot be read and ValueError (with the reason) for one without field samples, a date
    outside the WMM's span or a tour that cannot be fitted.
    """
    recording = read_recording(Path(path))
    if not recording.has_magnetometer:
        raise ValueError(f"{path}: the recording has no magnetometer columns (mx, my, mz)")
    notes = []
    calibration = recording.calibration
    inertial = None
    if calibration is not None and not calibration.is_identity:
        # The field is fitted raw; the accelerometer's own calibration gives better gravity.
        inertial = replace(calibration, magnetometer=None)
        if not inertial.is_identity:
            notes.append(f"the accelerometer and gyroscope were corrected with the recording's "
                         f"calibration {calibration.name!r}; the field is fitted raw")
        else:
            inertial = None
    if inertial is None:
        notes.append("the recording carries no accelerometer/gyroscope calibration: their own "
                     "axis errors (a few tenths of a degree) enter the turn; calibrate them "
                     "first for the best result")
    block = recording.sample_block(inertial)
    expected = None
    day = when if when is not None else recording_date(recording.metadata)
    if place is not None:
        if day is None:
            raise ValueError("the recording does not say when it was made: give --date "
                             "YYYY-MM-DD for the WMM")
        expected = earth_field(place, day)
    else:
        notes.append("no place given: the field and dip were not compared with the WMM "
                     "(give --place LAT,LON)")
    result = fit_magnetometer(block.mag_ut, block.accel_m_s2, t_s=block.t_s,
                              gyro_rad_s=block.gyro_rad_s, expected=expected)
    return MagCalibrationRun(result, str(path), dict(recording.device),
                             _settings(recording.device, recording.rate_hz), expected, day,
                             tuple(notes))


def save_to_profile(run: MagCalibrationRun, store: ProfileStore,
                    created_utc: str | None = None) -> tuple[Path, CalibrationProfile]:
    """Put the run's magnetometer terms into the device's profile (the accelerometer's and
    gyroscope's terms stay as they were; a device without a profile gets a new one with
    only the magnetometer's). Raises ValueError without a unique id, ``ProfileError`` when
    the existing profile cannot be read."""
    if not run.unique_id:
        raise ValueError(f"{run.source}: the device has no unique id, so its profile cannot "
                         "be named; use --json OUT")
    existing = store.load_for_device(run.unique_id)
    magnetometer = run.result.calibration
    residuals = {"magnetometer_fit": {
        "fitness_uT": magnetometer.fitness_ut, "coverage": magnetometer.coverage,
        "alignment_deg": magnetometer.extra.get("alignment_deg"),
        "verdict": run.result.verdict}}
    note = f"inclinometer calibrate-mag {run.source}"
    if existing is not None:
        profile = replace(
            existing, calibration=existing.calibration.with_magnetometer(magnetometer),
            method=existing.method if "magnetometer" in existing.method
            else f"{existing.method} + magnetometer".strip(" +"),
            residuals={**existing.residuals, **residuals},
            notes=f"{existing.notes}; {note}".strip("; "),
            **({"created_utc": created_utc} if created_utc else {}))
    else:
        profile = make_profile(
            run.unique_id, SensorCalibration(name="magnetometer", magnetometer=magnetometer),
            run.settings, method="magnetometer", residuals=residuals,
            created_utc=created_utc, notes=note)
    return store.save(profile), profile
