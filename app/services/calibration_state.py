"""The session's calibration profile and level reference (tare), kept with the pipeline (no Qt).

On connect the device's stored profile is applied (a replay applies the calibration it was
recorded with instead), unless the user disabled it ("Run uncalibrated", remembered in the
profile store across reconnects and restarts); the wizard or an import applies and stores a
new one, which enables it again. A profile can also be deleted (it moves to the store's
history). A tare takes the current attitude as level. Every method returns what the user must
be told; the caller emits the changes.
"""

from __future__ import annotations

from app.core.calibration import IDENTITY_CALIBRATION
from app.core.calibration_procedures import (
    CalibrationProfile,
    ProfileError,
    ProfileStore,
    SensorSettings,
    TareReference,
    make_profile,
)
from app.core.devices import DeviceInfo
from app.core.pipeline import Pipeline
from drivers.base import Device


def sensor_settings(info: DeviceInfo) -> SensorSettings:
    """The settings a profile is made with, as the connected device reports them."""
    return SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps, info.sensor)


class CalibrationState:
    """The active :class:`CalibrationProfile` (None: uncalibrated) and the pipeline's tare."""

    def __init__(self, pipeline: Pipeline, store: ProfileStore) -> None:
        self.pipeline = pipeline
        self.store = store
        self.profile: CalibrationProfile | None = None
        self.unique_id: str | None = None
        """The connected device whose stored profile disable / enable / delete act on (None
        for a replay, which runs with its recorded calibration)."""
        self.notes: list[str] = []
        """What the last :meth:`load_for` has to say that is not a problem (a disabled profile)."""

    @property
    def tare_reference(self) -> TareReference | None:
        return self.pipeline.level_reference

    def load_for(self, info: DeviceInfo, device: Device | None) -> list[str]:
        """Apply the profile for a newly connected device and clear the tare.

        A replay (a device with ``recorded_calibration``) reproduces its recording: the
        calibration it was made with, not the device's current profile. Returns the problems
        to report (a bad profile file, other sensor settings); none of them is fatal.
        """
        problems: list[str] = []
        self.notes = []
        recorded = None if device is None else device.recorded_calibration
        self.unique_id = None if recorded is not None else info.unique_id
        if recorded is not None:
            profile = None if recorded.is_identity else make_profile(
                info.unique_id, recorded, sensor_settings(info), method="recorded",
            )
        elif self.store.is_disabled(info.unique_id):
            profile = None
            self.notes.append(
                f"Running uncalibrated: the calibration profile of {info.unique_id} is disabled "
                "(Calibration ▸ Use the stored profile enables it)")
        else:
            profile = None
            try:
                profile = self.store.load_for_device(info.unique_id)
            except ProfileError as exc:
                problems.append(f"Calibration profile not loaded: {exc}")
            if profile is not None:
                differences = profile.settings.differences(sensor_settings(info))
                if differences:
                    problems.append(
                        f"The calibration profile of {info.unique_id} was made with other "
                        f"sensor settings ({'; '.join(differences)}); it is applied all the same"
                    )
        self.apply(profile)
        self.pipeline.set_level_reference(None)
        return problems

    def apply(self, profile: CalibrationProfile | None) -> None:
        """Run with ``profile`` (None: uncalibrated) from now on; the stored one is kept."""
        self.profile = profile
        self.pipeline.set_calibration(
            IDENTITY_CALIBRATION if profile is None else profile.calibration
        )

    def use(self, profile: CalibrationProfile) -> str:
        """Apply a new profile and store it for its device; returns a save error, or ""."""
        problem = ""
        try:
            self.store.save(profile)
        except (OSError, ProfileError) as exc:
            problem = f"The calibration is applied but could not be saved: {exc}"
        self.apply(profile)
        return problem

    def disable(self) -> str:
        """Run uncalibrated, now and on every later connection of this device; says so."""
        self.apply(None)
        if self.unique_id is None:
            return "Running uncalibrated (for this session)"
        try:
            self.store.set_disabled(self.unique_id, True)
        except OSError as exc:
            return f"Running uncalibrated, but this could not be remembered: {exc}"
        return (f"Running uncalibrated: the profile of {self.unique_id} stays disabled across "
                "reconnects and restarts (Calibration ▸ Use the stored profile enables it)")

    def enable(self) -> str:
        """Apply the device's stored profile again (clears the disabled mark); returns a problem."""
        if self.unique_id is None:
            return "No connected device to load a calibration profile for"
        try:
            self.store.set_disabled(self.unique_id, False)
            profile = self.store.load_for_device(self.unique_id)
        except (OSError, ProfileError) as exc:
            return f"Calibration profile not loaded: {exc}"
        if profile is None:
            return f"No calibration profile is stored for {self.unique_id}: run the wizard"
        self.apply(profile)
        return ""

    def delete(self) -> str:
        """Delete the device's stored profile (it moves to history) and run uncalibrated."""
        self.apply(None)
        if self.unique_id is None:
            return "No connected device whose calibration profile could be deleted"
        try:
            kept = self.store.delete(self.unique_id)
        except OSError as exc:
            return f"The calibration profile could not be deleted: {exc}"
        if kept is None:
            return f"No calibration profile was stored for {self.unique_id}; running uncalibrated"
        return (f"Calibration profile of {self.unique_id} deleted (kept as {kept}; Import "
                "profile brings it back); running uncalibrated")

    def tare(self) -> TareReference:
        """Take the current attitude as level; ValueError before any data has arrived."""
        if self.pipeline.counters.samples == 0:
            raise ValueError("Nothing to tare yet: no data has arrived")
        reference = TareReference.from_quaternion(self.pipeline.filter.quaternion)
        self.pipeline.set_level_reference(reference)
        return reference

    def set_tare(self, reference: TareReference | None) -> TareReference | None:
        """Use a given level reference (from the reversal procedure, say); returns it."""
        self.pipeline.set_level_reference(reference)
        return self.pipeline.level_reference
