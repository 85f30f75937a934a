"""Calibration profiles: one JSON file per device unique id, under the user data directory.

Layout (``base`` defaults to ``platformdirs.user_data_dir("Inclinometer") / "profiles"``)::

    base/<unique id>.json                  the device's current profile
    base/history/<unique id>-<stamp>.json  every profile a save replaced (never deleted)

A profile holds the calibration parameters, its creation time (UTC, ISO 8601), the die
temperature, the sensor settings (ODR, full scales), the fit residuals, an optional tare, the
app version and a format version. The ``parameters`` may also hold temperature terms
(``temperature_reference_degc`` and four coefficient vectors, see
:func:`app.core.calibration.temperature_to_json`) and the magnetometer's terms (key
``magnetometer``: ``calibrate-mag``'s JSON, :class:`app.core.calibration.MagnetometerCalibration`):
optional keys within format 1, so profiles without them read as before and an older reader
ignores them. Safety rules:

- writes are atomic: a temporary file in the same directory, flushed and fsynced, then
  ``os.replace`` (a crash leaves the old file or the new one, never half a file);
- saving over an existing profile first copies the old file (even an unreadable one) into
  ``history/``;
- reading never modifies, moves or deletes anything; a bad file raises a typed
  :class:`ProfileError` that names the file and the problem: :class:`ProfileCorruptError`
  (not JSON, missing or invalid fields), :class:`ProfileVersionError` (another format
  version), :class:`ProfileDeviceMismatchError` (made for another device),
  :class:`ProfileNotFoundError`.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

from app.core.bounded_input import InputTooLargeError, JsonInputError, loads_json, read_bounded
from app.core.calibration import (
    MAG_KEY,
    MagnetometerCalibration,
    SensorCalibration,
    temperature_from_json,
    temperature_to_json,
)
from app.core.calibration_procedures.level_reference import TareReference
from app.core.version import __version__

APP_NAME = "Inclinometer"
MAX_PROFILE_BYTES = 16 << 20
"""Larger files are refused unread (a profile, history included, takes a few kB)."""
FORMAT_TAG = "inclinometer-calibration-profile"
FORMAT_VERSION = 1
HISTORY_DIR = "history"


class ProfileError(Exception):
    """A profile could not be used; ``path`` is the file concerned (if any)."""

    def __init__(self, message: str, path: Path | None = None) -> None:
        super().__init__(message)
        self.path = path


class ProfileNotFoundError(ProfileError):
    """No profile exists for the device."""


class ProfileCorruptError(ProfileError):
    """The file is not a readable profile (not JSON, fields missing or invalid)."""


class ProfileVersionError(ProfileError):
    """The file has a format version this program does not read."""


class ProfileDeviceMismatchError(ProfileError):
    """The profile belongs to another device."""


def default_profile_dir() -> Path:
    """``<user data dir>/profiles`` for this platform (not created here)."""
    import platformdirs

    return Path(platformdirs.user_data_dir(APP_NAME, appauthor=False)) / "profiles"


def utc_now_iso() -> str:
    """The current UTC time as ISO 8601 with a ``Z`` (second resolution)."""
    return datetime.now(UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def parse_utc(text: str) -> datetime:
    """Parse an ISO 8601 time (``Z`` or an offset); naive times are taken as UTC."""
    value = datetime.fromisoformat(text.replace("Z", "+00:00"))
    return value if value.tzinfo is not None else value.replace(tzinfo=UTC)


@dataclass(frozen=True)
class SensorSettings:
    """The sensor configuration a profile was made with."""

    odr_hz: float
    accel_fs_g: int
    gyro_fs_dps: int
    sensor: str = "LSM6DSOX"

    def differences(self, other: SensorSettings) -> list[str]:
        """Human-readable differences from ``other`` (empty when they match)."""
        out = []
        if self.sensor != other.sensor:
            out.append(f"sensor {self.sensor} vs {other.sensor}")
        if not math.isclose(self.odr_hz, other.odr_hz, rel_tol=0.05):
            out.append(f"ODR {self.odr_hz:g} Hz vs {other.odr_hz:g} Hz")
        if self.accel_fs_g != other.accel_fs_g:
            out.append(f"accelerometer range +-{self.accel_fs_g} g vs +-{other.accel_fs_g} g")
        if self.gyro_fs_dps != other.gyro_fs_dps:
            out.append(f"gyroscope range +-{self.gyro_fs_dps} dps vs +-{other.gyro_fs_dps} dps")
        return out


@dataclass(frozen=True)
class CalibrationProfile:
    """A device's calibration with its provenance (see the module docstring).

    ``residuals`` holds plain JSON numbers (e.g. ``AccelFit.summary()`` and the gyro bias
    uncertainty); ``method`` says how it was made (``"six-position"``, ``"ellipsoid"``, ...).
    """

    device_unique_id: str
    calibration: SensorCalibration
    settings: SensorSettings
    created_utc: str = field(default_factory=utc_now_iso)
    temperature_degc: float | None = None
    method: str = ""
    residuals: Mapping[str, Any] = field(default_factory=dict)
    tare: TareReference | None = None
    app_version: str = __version__
    format_version: int = FORMAT_VERSION
    notes: str = ""

    @property
    def created(self) -> datetime:
        return parse_utc(self.created_utc)

    def age(self, now: datetime | None = None) -> timedelta:
        """Time since the profile was made."""
        return (now or datetime.now(UTC)) - self.created

    # -- JSON ---------------------------------------------------------------------------------
    def to_json_dict(self) -> dict[str, Any]:
        cal = self.calibration
        return {
            "format": FORMAT_TAG,
            "format_version": self.format_version,
            "device_unique_id": self.device_unique_id,
            "name": cal.name,
            "created_utc": self.created_utc,
            "app_version": self.app_version,
            "method": self.method,
            "temperature_degc": self.temperature_degc,
            "sensor_settings": {
                "sensor": self.settings.sensor,
                "odr_hz": self.settings.odr_hz,
                "accel_fs_g": self.settings.accel_fs_g,
                "gyro_fs_dps": self.settings.gyro_fs_dps,
            },
            "parameters": {
                "accel_bias_m_s2": np.asarray(cal.accel_bias_m_s2, float).tolist(),
                "accel_matrix": np.asarray(cal.accel_matrix, float).tolist(),
                "gyro_bias_rad_s": np.asarray(cal.gyro_bias_rad_s, float).tolist(),
                "gyro_matrix": np.asarray(cal.gyro_matrix, float).tolist(),
                # Optional, within format 1: the temperature terms when there are some.
                **temperature_to_json(cal.temperature),
                # Optional, within format 1: the magnetometer's terms (calibrate-mag's JSON).
                **({MAG_KEY: cal.magnetometer.to_json()} if cal.magnetometer is not None
                   else {}),
            },
            "tare_quaternion": None if self.tare is None else self.tare.to_list(),
            "residuals": _jsonable(self.residuals),
            "notes": self.notes,
        }

    @classmethod
    def from_json_dict(cls, data: Any, path: Path | None = None) -> CalibrationProfile:
        """Validate and build a profile; raises :class:`ProfileError` subclasses."""
        where = f"{path}: " if path is not None else ""

        def corrupt(problem: str) -> ProfileCorruptError:
            return ProfileCorruptError(f"{where}not a valid calibration profile: {problem}", path)

        if not isinstance(data, dict):
            raise corrupt("the file does not hold a JSON object")
        if data.get("format") != FORMAT_TAG:
            raise corrupt(f"'format' is {data.get('format')!r}, expected {FORMAT_TAG!r}")
        version = data.get("format_version")
        if not isinstance(version, int) or isinstance(version, bool):
            raise corrupt(f"'format_version' is {version!r}, expected a whole number")
        if version != FORMAT_VERSION:
            newer = "a newer" if version > FORMAT_VERSION else "an older"
            raise ProfileVersionError(
                f"{where}profile format version {version} was written by {newer} version of "
                f"{APP_NAME}; this version ({__version__}) reads format {FORMAT_VERSION}. "
                "The file was left untouched.",
                path,
            )
        try:
            uid = data["device_unique_id"]
            if not isinstance(uid, str) or not uid:
                raise corrupt("'device_unique_id' must be a non-empty string")
            params = data["parameters"]
            if not isinstance(params, dict):
                raise corrupt("'parameters' must be an object")
            accel_bias = _array(params["accel_bias_m_s2"], (3,), "accel_bias_m_s2", corrupt)
            accel_matrix = _array(params["accel_matrix"], (3, 3), "accel_matrix", corrupt)
            gyro_bias = _array(params["gyro_bias_rad_s"], (3,), "gyro_bias_rad_s", corrupt)
            gyro_matrix = _array(params["gyro_matrix"], (3, 3), "gyro_matrix", corrupt)
            try:
                temperature_terms = temperature_from_json(params)
            except ValueError as exc:
                raise corrupt(f"the temperature terms: {exc}") from None
            magnetometer = None
            if params.get(MAG_KEY) is not None:
                try:
                    magnetometer = MagnetometerCalibration.from_json(params[MAG_KEY])
                except ValueError as exc:
                    raise corrupt(f"the magnetometer terms: {exc}") from None
            for name, matrix in (("accel_matrix", accel_matrix), ("gyro_matrix", gyro_matrix)):
                if abs(np.linalg.det(matrix)) < 1e-6:
                    raise corrupt(f"'{name}' is singular")
            settings_data = data["sensor_settings"]
            if not isinstance(settings_data, dict):
                raise corrupt("'sensor_settings' must be an object")
            settings = SensorSettings(
                odr_hz=_number(settings_data["odr_hz"], "odr_hz", corrupt),
                accel_fs_g=_whole(settings_data["accel_fs_g"], "accel_fs_g", corrupt),
                gyro_fs_dps=_whole(settings_data["gyro_fs_dps"], "gyro_fs_dps", corrupt),
                sensor=str(settings_data.get("sensor", "LSM6DSOX")),
            )
            created = data["created_utc"]
            if not isinstance(created, str):
                raise corrupt("'created_utc' must be a string")
            try:
                parse_utc(created)
            except ValueError:
                raise corrupt(f"'created_utc' {created!r} is not an ISO 8601 time") from None
            temperature = data.get("temperature_degc")
            if temperature is not None:
                temperature = _number(temperature, "temperature_degc", corrupt)
            tare_data = data.get("tare_quaternion")
            try:
                tare = None if tare_data is None else TareReference.from_list(tare_data)
            except (TypeError, ValueError) as exc:
                raise corrupt(f"'tare_quaternion': {exc}") from None
            residuals = data.get("residuals", {})
            if not isinstance(residuals, dict):
                raise corrupt("'residuals' must be an object")
            name = data.get("name", "calibrated")
            return cls(
                device_unique_id=uid,
                calibration=SensorCalibration(
                    accel_bias_m_s2=accel_bias,
                    accel_matrix=accel_matrix,
                    gyro_bias_rad_s=gyro_bias,
                    gyro_matrix=gyro_matrix,
                    name=str(name),
                    temperature=temperature_terms,
                    magnetometer=magnetometer,
                ),
                settings=settings,
                created_utc=created,
                temperature_degc=temperature,
                method=str(data.get("method", "")),
                residuals=residuals,
                tare=tare,
                app_version=str(data.get("app_version", "")),
                format_version=version,
                notes=str(data.get("notes", "")),
            )
        except KeyError as exc:
            raise corrupt(f"the field {exc.args[0]!r} is missing") from None


def _jsonable(value: Any) -> Any:
    """Plain JSON types (arrays to lists, numpy scalars to floats, NaN/inf to None)."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    return str(value)


def _array(value: Any, shape: tuple[int, ...], name: str, corrupt: Any) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise corrupt(f"'{name}' must be numbers of shape {shape}") from None
    if array.shape != shape:
        raise corrupt(f"'{name}' has shape {array.shape}, expected {shape}")
    if not np.all(np.isfinite(array)):
        raise corrupt(f"'{name}' holds a non-finite number")
    return array


def _number(value: Any, name: str, corrupt: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise corrupt(f"'{name}' must be a finite number, not {value!r}")
    return float(value)


def _whole(value: Any, name: str, corrupt: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise corrupt(f"'{name}' must be a whole number, not {value!r}")
    return value


# -- files ----------------------------------------------------------------------------------------
def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temp file in the same folder + ``os.replace``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp_name, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp_name)
        raise


def write_profile_file(path: Path, profile: CalibrationProfile) -> None:
    """Write one profile as JSON, atomically."""
    text = json.dumps(profile.to_json_dict(), indent=2, allow_nan=False) + "\n"
    write_bytes_atomic(Path(path), text.encode("utf-8"))


def read_profile_file(path: Path, expected_unique_id: str | None = None) -> CalibrationProfile:
    """Read and validate a profile file (never modifies it).

    Raises :class:`ProfileNotFoundError`, :class:`ProfileCorruptError`,
    :class:`ProfileVersionError`, or :class:`ProfileDeviceMismatchError` when
    ``expected_unique_id`` is given and differs from the file's.
    """
    path = Path(path)
    try:
        raw = read_bounded(path, MAX_PROFILE_BYTES)
    except FileNotFoundError:
        raise ProfileNotFoundError(f"{path}: no such profile file", path) from None
    except InputTooLargeError:
        raise ProfileCorruptError(
            f"{path}: not a calibration profile: the file is too large (more than "
            f"{MAX_PROFILE_BYTES} bytes; a profile takes a few kB). The file was left "
            "untouched.", path) from None
    except OSError as exc:  # also a FIFO or a device: refused, never waited on
        raise ProfileError(f"{path}: cannot read the profile: {exc.strerror or exc}", path) from exc
    try:
        data = loads_json(raw, max_bytes=MAX_PROFILE_BYTES)
    except JsonInputError as exc:
        raise ProfileCorruptError(
            f"{path}: not a valid calibration profile: {exc}. The file was left untouched.",
            path,
        ) from None
    profile = CalibrationProfile.from_json_dict(data, path)
    if expected_unique_id is not None and profile.device_unique_id != expected_unique_id:
        raise ProfileDeviceMismatchError(
            f"{path}: this profile belongs to device {profile.device_unique_id!r}, not to the "
            f"connected device {expected_unique_id!r}; it was not applied.",
            path,
        )
    return profile


def file_stem_for(unique_id: str) -> str:
    """A safe file name stem for a device id (a hash suffix when characters were replaced)."""
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", unique_id).lstrip(".")
    if safe != unique_id or not safe:
        digest = hashlib.blake2b(unique_id.encode("utf-8"), digest_size=4).hexdigest()
        safe = f"{safe or 'device'}-{digest}"
    return safe


@dataclass(frozen=True)
class ProfileListing:
    """The readable profiles in a store and the files that could not be read."""

    profiles: list[tuple[Path, CalibrationProfile]]
    problems: list[tuple[Path, str]]


class ProfileStore:
    """Profiles on disk, one per device (see the module docstring).

    Parameters
    ----------
    base_dir : folder of the profiles; defaults to :func:`default_profile_dir`. Tests pass a
        temporary folder.
    """

    def __init__(self, base_dir: Path | str | None = None) -> None:
        self.base_dir = Path(base_dir) if base_dir is not None else default_profile_dir()

    @property
    def history_dir(self) -> Path:
        return self.base_dir / HISTORY_DIR

    def path_for(self, unique_id: str) -> Path:
        return self.base_dir / f"{file_stem_for(unique_id)}.json"

    def exists(self, unique_id: str) -> bool:
        return self.path_for(unique_id).is_file()

    def load(self, unique_id: str) -> CalibrationProfile:
        """The device's profile; raises a :class:`ProfileError` subclass (nothing is changed)."""
        path = self.path_for(unique_id)
        if not path.is_file():
            raise ProfileNotFoundError(f"no calibration profile for device {unique_id!r}", path)
        return read_profile_file(path, expected_unique_id=unique_id)

    def load_for_device(self, unique_id: str) -> CalibrationProfile | None:
        """What to apply on connect: the profile, None when there is none; raises if broken."""
        try:
            return self.load(unique_id)
        except ProfileNotFoundError:
            return None

    def save(self, profile: CalibrationProfile) -> Path:
        """Store ``profile`` as its device's current one; the replaced file goes to history.

        A new profile is meant to be used: it clears the device's *disabled* mark.
        """
        path = self.path_for(profile.device_unique_id)
        if path.exists():
            self._keep_in_history(path)
        write_profile_file(path, profile)
        self.set_disabled(profile.device_unique_id, False)
        return path

    def disabled_path(self, unique_id: str) -> Path:
        """The mark that keeps the device's profile stored but unused (``STEM.disabled``)."""
        return self.base_dir / f"{file_stem_for(unique_id)}.disabled"

    def is_disabled(self, unique_id: str) -> bool:
        """True when the user chose to run this device uncalibrated (kept across restarts)."""
        return self.disabled_path(unique_id).is_file()

    def set_disabled(self, unique_id: str, disabled: bool) -> None:
        """Mark the device's profile as not to be applied on connect (or clear the mark)."""
        path = self.disabled_path(unique_id)
        if disabled:
            write_bytes_atomic(path, f"disabled {utc_now_iso()}\n".encode())
        else:
            path.unlink(missing_ok=True)

    def delete(self, unique_id: str) -> Path | None:
        """Remove the device's profile; the file moves to history (recoverable by import).

        Returns where it went, None when there was none; the disabled mark goes too.
        """
        path = self.path_for(unique_id)
        kept = None
        if path.exists():
            kept = self._keep_in_history(path)
            path.unlink()
        self.set_disabled(unique_id, False)
        return kept

    def history(self, unique_id: str) -> list[Path]:
        """Earlier profiles of the device, oldest first (by name)."""
        stem = file_stem_for(unique_id)
        if not self.history_dir.is_dir():
            return []
        return sorted(self.history_dir.glob(f"{glob_escape(stem)}-*.json"))

    def list(self) -> ProfileListing:
        """Every current profile, and every file that failed to read (with the reason)."""
        profiles, problems = [], []
        if self.base_dir.is_dir():
            for path in sorted(self.base_dir.glob("*.json")):
                try:
                    profile = read_profile_file(path)
                except ProfileError as exc:
                    problems.append((path, str(exc)))
                    continue
                if self.path_for(profile.device_unique_id) != path:
                    problems.append(
                        (path, f"{path}: holds the profile of device "
                               f"{profile.device_unique_id!r} under another device's name")
                    )
                    continue
                profiles.append((path, profile))
        return ProfileListing(profiles, problems)

    def export(self, unique_id: str, destination: Path | str, overwrite: bool = False) -> Path:
        """Copy the device's (validated) profile to ``destination``."""
        profile = self.load(unique_id)
        destination = Path(destination)
        if destination.exists() and not overwrite:
            raise FileExistsError(f"{destination} exists; choose another name")
        write_profile_file(destination, profile)
        return destination

    def import_file(
        self, source: Path | str, expected_unique_id: str | None = None
    ) -> CalibrationProfile:
        """Validate a profile file and store it as its device's current profile.

        ``expected_unique_id`` (the connected device) rejects a profile of another device with
        :class:`ProfileDeviceMismatchError`; the store is not touched when anything fails.
        """
        profile = read_profile_file(Path(source), expected_unique_id)
        self.save(profile)
        return profile

    def _keep_in_history(self, path: Path) -> Path:
        """Copy an existing file into history (readable or not) before it is replaced."""
        data = path.read_bytes()
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S%fZ")
        with contextlib.suppress(ProfileError, ValueError):
            stamp = parse_utc(read_profile_file(path).created_utc).strftime("%Y%m%dT%H%M%SZ")
        target = self.history_dir / f"{path.stem}-{stamp}.json"
        counter = 1
        while target.exists():
            if target.read_bytes() == data:
                return target
            counter += 1
            target = self.history_dir / f"{path.stem}-{stamp}-{counter}.json"
        write_bytes_atomic(target, data)
        return target


def glob_escape(text: str) -> str:
    """Escape glob metacharacters (file stems only contain ``[A-Za-z0-9._-]``, but be safe)."""
    return re.sub(r"([*?\[])", r"[\1]", text)


def make_profile(
    device_unique_id: str,
    calibration: SensorCalibration,
    settings: SensorSettings,
    method: str = "",
    temperature_degc: float | None = None,
    residuals: Mapping[str, Any] | None = None,
    tare: TareReference | None = None,
    created_utc: str | None = None,
    notes: str = "",
) -> CalibrationProfile:
    """Convenience constructor (the wizard's last page)."""
    if temperature_degc is not None and not math.isfinite(temperature_degc):
        temperature_degc = None
    return CalibrationProfile(
        device_unique_id=device_unique_id,
        calibration=calibration,
        settings=settings,
        created_utc=created_utc or utc_now_iso(),
        temperature_degc=temperature_degc,
        method=method,
        residuals=dict(residuals or {}),
        tare=tare,
        notes=notes,
    )
