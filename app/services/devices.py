"""What the views may ask about devices, without importing a driver.

The driver registry (:mod:`drivers.registry`) stays the one place that knows URL schemes;
this module answers the GUI's questions with it: which devices are there, is a URL a replay,
which URL replays a file, and what the simulator offers (its sensor settings, and the full
scales each motion needs).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlencode

from app.core.devices import DeviceDescriptor
from drivers import lsm6dsox
from drivers.errors import DeviceError, DeviceUrlError
from drivers.registry import DEFAULT_DEVICE_URL, driver_for, driver_options
from drivers.registry import available_devices as _available_devices
from drivers.replay import replay_url as _replay_url
from drivers.sim.options import SimOptions, parse_sim_url
from drivers.url_options import format_options, option_rows

__all__ = [
    "DEFAULT_DEVICE_URL", "SENSOR_CHOICES", "SensorChoices", "SimulatorSettings",
    "available_devices", "device_options", "device_options_table", "is_replay_url",
    "knows_truth_url",
    "option_hints", "replay_url",
]


def available_devices() -> list[DeviceDescriptor]:
    """Everything that could be connected now (simulator scenarios, ports, ...)."""
    return _available_devices()


def device_options(name: str) -> list[dict[str, object]]:
    """A driver's URL options as plain data (name, type, default, limits, unit, help, repeatable),
    of a scheme (``sim``) or a URL (``sim://static``: with that scenario's). Raises the
    driver's error (a :class:`~drivers.errors.DeviceError`) for an unknown scheme."""
    return option_rows(driver_options(name))


def device_options_table(name: str) -> str:
    """:func:`device_options` as a text table (``inclinometer devices --options SCHEME``)."""
    return format_options(driver_options(name))


def option_hints(url: str) -> list[dict[str, object]]:
    """:func:`device_options` of a URL being typed: empty while its scheme names no driver."""
    try:
        return device_options(url)
    except DeviceError:
        return []


def is_replay_url(url: str) -> bool:
    """True when ``url`` names a recording to replay (``replay://`` or a bare ``.csv`` path)."""
    try:
        return driver_for(url).replayable
    except DeviceError:
        return False


def knows_truth_url(url: str) -> bool:
    """True when ``url``'s driver delivers a reference orientation (drivers.base
    ``knows_truth``: a recording then carries the reference columns)."""
    try:
        return driver_for(url).knows_truth
    except DeviceError:
        return False


def has_simulator_controls(url: str) -> bool:
    """True when ``url``'s driver takes live controls (the simulator panel: drivers.base
    ``steerable``); whether this device can be tilted now is ``Device.is_steerable``."""
    try:
        return driver_for(url).steerable
    except DeviceError:
        return False


def replay_url(path: str | Path) -> str:
    """The device URL that replays the recording at ``path``."""
    return _replay_url(path)


@dataclass(frozen=True, slots=True)
class SensorChoices:
    """The LSM6DSOX settings a user can pick (data rates, full scales)."""

    odr_hz: tuple[float, ...]
    accel_fs_g: tuple[int, ...]
    gyro_fs_dps: tuple[int, ...]


SENSOR_CHOICES = SensorChoices(
    odr_hz=tuple(lsm6dsox.ODR_LABELS_HZ.values()),  # labels, for people
    accel_fs_g=tuple(sorted(lsm6dsox.ACCEL_MG_PER_LSB)),
    gyro_fs_dps=tuple(sorted(lsm6dsox.GYRO_MDPS_PER_LSB)),
)


@dataclass(frozen=True, slots=True)
class SimulatorSettings:
    """The settings a ``sim://`` URL carries that the simulator panel shows."""

    scenario: str
    odr_hz: float
    accel_fs_g: int
    gyro_fs_dps: int
    seed: int
    roll_deg: float = 0.0
    pitch_deg: float = 0.0

    @classmethod
    def defaults(cls, scenario: str) -> SimulatorSettings:
        """The simulator's defaults for ``scenario``, with the full scales its motion needs
        (a hand-held motion turns faster than the default ±250 dps)."""
        return cls._of(parse_sim_url(f"sim://{scenario}"))

    @classmethod
    def from_url(cls, url: str) -> SimulatorSettings | None:
        """The settings of a ``sim://`` URL; None when it is not a valid one."""
        try:
            return cls._of(parse_sim_url(url))
        except DeviceUrlError:
            return None

    @classmethod
    def _of(cls, options: SimOptions) -> SimulatorSettings:
        params = options.scenario_params
        return cls(options.scenario, options.odr_nominal_hz, options.accel_fs_g,
                   options.gyro_fs_dps, options.seed, float(params.get("roll", 0.0)),
                   float(params.get("pitch", 0.0)))

    def url(self) -> str:
        """The ``sim://`` URL for these settings (roll and pitch only for ``interactive``)."""
        options: dict[str, object] = {
            "odr": f"{self.odr_hz:g}", "accel_fs": self.accel_fs_g,
            "gyro_fs": self.gyro_fs_dps, "seed": self.seed,
        }
        if self.scenario == "interactive":
            options["roll"] = f"{self.roll_deg:g}"
            options["pitch"] = f"{self.pitch_deg:g}"
        return f"sim://{self.scenario}?{urlencode(options)}"
