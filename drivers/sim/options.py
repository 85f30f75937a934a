"""Parse and validate ``sim://SCENARIO?key=value&...`` URLs (see :mod:`drivers.sim.device`)."""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, urlsplit

from app.core.earth_field import WMM_VALID_YEARS, Place
from app.core.faults.injection import FAULT_CHANNELS, FaultSpec, parse_fault_spec
from drivers import lsm6dsox
from drivers.errors import DeviceUrlError
from drivers.sim.magnetometer import DISTURBANCE_KINDS, MAG_CHIPS, DisturbanceSpec
from drivers.sim.magnetometer import parse_disturbances as _parse_disturbances
from drivers.sim.scenarios import SCENARIOS, Param

DEFAULT_SCENARIO = "interactive"
"""The scenario of a URL that names none (``sim://``, ``sim://?odr=52``)."""
DEFAULT_ODR_HZ = 104.0
DEFAULT_ACCEL_FS_G = 4
DEFAULT_GYRO_FS_DPS = 250
DEFAULT_SEED = 1
DEFAULT_BLOCK = 256
DEFAULT_WARMUP_TAU_S = 300.0
MAX_BLOCK = 1_000_000
MAX_CLOCK_OFFSET_S = 1e9
"""31 years: a float64 timestamp still resolves 0.1 us."""

GENERAL_OPTIONS: dict[str, str] = {
    "odr": "Hz, snapped to the nearest LSM6DSOX rate (12.5 ... 6667; 12.5 runs at 13.02)",
    "accel_fs": "accelerometer full scale: 2, 4, 8 or 16 g (default 4, or what the motion needs)",
    "gyro_fs": "gyroscope full scale: 125, 250, 500, 1000 or 2000 dps (default 250, or what the "
               "motion needs)",
    "seed": "integer >= 0 picking the simulated unit (its id and its errors)",
    "realtime": "1: paced by the wall clock; 0: blocks as fast as possible",
    "speed": "time-lapse factor for realtime pacing (0.1 ... 100; 1 = real time)",
    "block": "samples per read when realtime=0",
    "errors": "0: an ideal chip (no bias, scale, cross-axis, drift or clock error)",
    "noise": "0: no white noise (quantisation stays)",
    "settling": "1: the first samples after open (a configure) are the chip's turn-on transient, "
                "as a board that does not discard them would send (default 0: discarded)",
    "fail_after": "seconds of device time after which reads fail like an unplugged cable",
    "warmup": "RISE[:TAU]: the die warms by RISE degC (0 ... 60) with time constant TAU s "
              "(1 ... 36000, default 300) after power-up, instead of the unit's own 1.5-4 degC",
    "clock_offset": "seconds added to every timestamp (a device clock started elsewhere)",
    "clock_ppm": "parts per million the timestamps run fast (-10000 ... 10000; a drifting "
                 "device clock, on top of the unit's own)",
    "fault": "inject a fault, KIND:CHANNEL[:SIZE]@START[-END] (repeatable), KIND one of "
             "noise, stuck, dead, spike, bias, scale; SIZE in g (ax..az), dps (gx..gz) or "
             "uT (mx..mz, with a magnetometer)",
}
"""Options every scenario accepts, with a line of help each."""

# -- the magnetometer's options (issue 31; one block, parsed by _magnetometer_options) --------
MAG_OPTIONS: dict[str, str] = {
    "mag": "the magnetometer beside the LSM6DSOX: lis3mdl (80 Hz, +-4 gauss, ultra-high-"
           "performance), lis2mdl (100 Hz, +-49 gauss) or none (default; sim://magtour: "
           "lis3mdl)",
    "mag_odr": "the magnetometer's output rate, Hz: LIS3MDL 0.625, 1.25, 2.5, 5, 10, 20, 40, "
               "80 (default) or 155 (FAST_ODR); LIS2MDL 10, 20, 50 or 100 (default)",
    "place": "LAT,LON[,ALT_M] where the earth's field is taken (World Magnetic Model; default "
             "52.5125,13.3269,50: TU Berlin)",
    "date": "YYYY-MM-DD the earth's field is taken for (default today; the model covers "
            f"{WMM_VALID_YEARS[0]:.0f}-{WMM_VALID_YEARS[1]:.0f})",
    "magdist": "magnetic disturbances, ITEM,ITEM... each KIND[:SIZE[:FREQ]][@START[-END]] "
               "(device-clock seconds): " + "; ".join(
                   f"{kind}: {text}" for kind, text in DISTURBANCE_KINDS.items()),
}
"""The magnetometer's URL options, with a line of help each (accepted by every scenario)."""

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


@dataclass(frozen=True, slots=True)
class SimOptions:
    """A validated simulator URL."""

    scenario: str
    odr_nominal_hz: float = DEFAULT_ODR_HZ
    accel_fs_g: int = DEFAULT_ACCEL_FS_G
    gyro_fs_dps: int = DEFAULT_GYRO_FS_DPS
    seed: int = DEFAULT_SEED
    realtime: bool = True
    speed: float = 1.0
    block: int = DEFAULT_BLOCK
    errors: bool = True
    noise: bool = True
    fail_after_s: float | None = None
    settling: bool = False
    """Model the turn-on transient on the first samples (drivers.sim.transient)."""
    scenario_params: dict[str, float | int | bool] = field(default_factory=dict)
    faults: tuple[FaultSpec, ...] = ()
    """Injected faults (``fault=...``, repeatable), in URL order."""
    warmup: tuple[float, float] | None = None
    """``warmup=RISE[:TAU]``: self-heating rise (degC) and time constant (s), None: the unit's."""
    clock_offset_s: float = 0.0
    """Added to every timestamp (``clock_offset``)."""
    clock_ppm: float = 0.0
    """The timestamps run this many ppm fast (``clock_ppm``)."""
    # The magnetometer (MAG_OPTIONS).
    mag: str | None = None
    """Key of :data:`drivers.sim.magnetometer.MAG_CHIPS`, None without a magnetometer."""
    mag_odr_hz: float | None = None
    """The magnetometer's output rate (None: the chip's default)."""
    place: Place | None = None
    """Where the earth's field is taken (None: :data:`app.core.earth_field.DEFAULT_PLACE`)."""
    date: dt.date | None = None
    """The date the earth's field is taken for (None: today)."""
    mag_disturbances: tuple[DisturbanceSpec, ...] = ()
    """``magdist=`` items, in URL order."""


def _fail(url: str, message: str) -> DeviceUrlError:
    return DeviceUrlError(f"{_shown(url, 120)}: {message}")


def _shown(text: str, limit: int = 40) -> str:
    """``text`` quoted for a message, cut to ``limit`` characters (a 400-digit number)."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} chars)"


def _number(url: str, key: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _fail(url, f"{key}={_shown(text)} is not a number") from None
    if not math.isfinite(value):
        raise _fail(url, f"{key}={_shown(text)} is not a finite number")
    return value


def _integer(url: str, key: str, text: str, minimum: float, maximum: float) -> int:
    value = _number(url, key, text)
    if value != int(value) or not minimum <= value <= maximum:
        raise _fail(url, f"{key}={text!r}: expected a whole number from {minimum:g} to {maximum:g}")
    return int(value)


def _choice(url: str, key: str, text: str, allowed: list[int], unit: str) -> int:
    value = _number(url, key, text)
    if value not in allowed:
        choices = ", ".join(str(a) for a in allowed)
        raise _fail(url, f"{key}={text!r} is not supported; use one of {choices} ({unit})")
    return int(value)


def _flag(url: str, key: str, text: str) -> bool:
    word = text.lower()
    if word in _TRUE:
        return True
    if word in _FALSE:
        return False
    raise _fail(url, f"{key}={text!r}: use 1 or 0 (also true/false, yes/no, on/off)")


def _param(url: str, key: str, text: str, spec: Param) -> float | int | bool:
    if isinstance(spec.default, bool):
        return _flag(url, key, text)
    if isinstance(spec.default, int):
        return _integer(url, key, text, spec.minimum, spec.maximum)
    value = _number(url, key, text)
    if not spec.minimum <= value <= spec.maximum:
        raise _fail(url, f"{key}={text!r} is out of range [{spec.minimum:g}, {spec.maximum:g}]")
    return value


def _warmup(url: str, text: str) -> tuple[float, float]:
    rise_text, _, tau_text = text.partition(":")
    rise = _number(url, "warmup", rise_text)
    tau = _number(url, "warmup", tau_text) if tau_text else DEFAULT_WARMUP_TAU_S
    if not 0.0 <= rise <= 60.0 or not 1.0 <= tau <= 36000.0:
        raise _fail(url, f"warmup={text!r}: expected RISE[:TAU], RISE 0 ... 60 degC, "
                         "TAU 1 ... 36000 s")
    return rise, tau


def _query(
    url: str, query: str, overrides: Mapping[str, object], faults: list[str]
) -> dict[str, str]:
    raw: dict[str, str] = {}
    for key, value in parse_qsl(query, keep_blank_values=True):
        key = key.strip().lower()
        if key == "fault":
            if not value.strip():
                raise _fail(url, "option 'fault' needs a value (fault=KIND:CHANNEL[:SIZE]@START)")
            faults.append(value.strip())
            continue
        if key in raw:
            raise _fail(url, f"option {key!r} is given twice")
        raw[key] = value.strip()
    for key, value in overrides.items():
        if value is None:
            raw.pop(key, None)
        else:
            raw[key] = str(int(value)) if isinstance(value, bool) else str(value)
    for key, value in raw.items():
        if value == "":
            raise _fail(url, f"option {key!r} needs a value ({key}=...)")
    return raw


def parse_sim_url(url: str, overrides: Mapping[str, object] | None = None) -> SimOptions:
    """Validate a ``sim://`` URL; ``overrides`` (option name -> value) win over the query.

    Raises
    ------
    DeviceUrlError
        For an unknown scenario or option, or a bad value; the message names the allowed ones.
    """
    parts = urlsplit(url)
    if parts.scheme.lower() != "sim" or "://" not in url:
        raise _fail(url, "not a simulator URL; expected sim://SCENARIO?option=value&...")
    name = (parts.netloc + parts.path).strip("/").lower().replace("_", "-")
    if not name:  # sim:// alone: the interactive simulator, as the app starts with
        name = DEFAULT_SCENARIO
    if name not in SCENARIOS:
        names = ", ".join(SCENARIOS)
        raise _fail(url, f"unknown simulator scenario {name!r}; choose one of: {names}")
    spec = SCENARIOS[name].parameters
    fault_texts: list[str] = []
    raw = _query(url, parts.query, overrides or {}, fault_texts)
    unknown = sorted(set(raw) - set(GENERAL_OPTIONS) - set(MAG_OPTIONS) - set(spec))
    if unknown:
        allowed = ", ".join([*GENERAL_OPTIONS, *MAG_OPTIONS, *spec])
        raise _fail(url, f"unknown option {unknown[0]!r} for sim://{name}; allowed: {allowed}")

    options: dict[str, object] = {"scenario": name}
    if "odr" in raw:
        odr = _number(url, "odr", raw["odr"])
        problem = lsm6dsox.odr_problem(odr)
        if problem is not None:
            raise _fail(url, f"odr={_shown(raw['odr'])} {problem}")
        options["odr_nominal_hz"] = lsm6dsox.odr_label_hz(odr)
    if "accel_fs" in raw:
        allowed = sorted(lsm6dsox.ACCEL_MG_PER_LSB)
        options["accel_fs_g"] = _choice(url, "accel_fs", raw["accel_fs"], allowed, "g")
    elif SCENARIOS[name].accel_fs_g is not None:  # what the scenario's motion needs
        options["accel_fs_g"] = SCENARIOS[name].accel_fs_g
    if "gyro_fs" in raw:
        allowed = sorted(lsm6dsox.GYRO_MDPS_PER_LSB)
        options["gyro_fs_dps"] = _choice(url, "gyro_fs", raw["gyro_fs"], allowed, "dps")
    elif SCENARIOS[name].gyro_fs_dps is not None:
        options["gyro_fs_dps"] = SCENARIOS[name].gyro_fs_dps
    if "seed" in raw:
        options["seed"] = _integer(url, "seed", raw["seed"], 0, 2**63 - 1)
    if "speed" in raw:
        speed = _number(url, "speed", raw["speed"])
        if not 0.1 <= speed <= 100.0:
            raise _fail(url, f"speed={raw['speed']!r} is out of range [0.1, 100]")
        options["speed"] = speed
    if "block" in raw:
        options["block"] = _integer(url, "block", raw["block"], 1, MAX_BLOCK)
    for key in ("realtime", "errors", "noise", "settling"):
        if key in raw:
            options[key] = _flag(url, key, raw[key])
    if "fail_after" in raw:
        seconds = _number(url, "fail_after", raw["fail_after"])
        if seconds <= 0.0:
            raise _fail(url, f"fail_after={raw['fail_after']!r} must be a positive time in s")
        options["fail_after_s"] = seconds
    if "warmup" in raw:
        options["warmup"] = _warmup(url, raw["warmup"])
    if "clock_offset" in raw:
        offset = _number(url, "clock_offset", raw["clock_offset"])
        if not -MAX_CLOCK_OFFSET_S <= offset <= MAX_CLOCK_OFFSET_S:
            raise _fail(url, f"clock_offset={_shown(raw['clock_offset'])} is out of range "
                             f"[-{MAX_CLOCK_OFFSET_S:g}, {MAX_CLOCK_OFFSET_S:g}] s (beyond it "
                             "the timestamps lose the resolution of a sample period)")
        options["clock_offset_s"] = offset
    if "clock_ppm" in raw:
        ppm = _number(url, "clock_ppm", raw["clock_ppm"])
        if not -10000.0 <= ppm <= 10000.0:
            raise _fail(url, f"clock_ppm={raw['clock_ppm']!r} is out of range [-10000, 10000]")
        options["clock_ppm"] = ppm
    options["scenario_params"] = {
        key: _param(url, key, raw[key], spec[key]) for key in spec if key in raw
    }
    options.update(_magnetometer_options(url, name, raw))
    channels = FAULT_CHANNELS if options["mag"] else FAULT_CHANNELS[:6]
    faults = []
    for text in fault_texts:
        try:
            faults.append(parse_fault_spec(text, channels))
        except ValueError as exc:
            raise _fail(url, str(exc)) from None
    options["faults"] = tuple(faults)
    return SimOptions(**options)  # type: ignore[arg-type]


# -- the magnetometer's options ------------------------------------------------------------------
def _magnetometer_options(url: str, name: str, raw: Mapping[str, str]) -> dict[str, object]:
    """``mag``, ``place``, ``date`` and ``magdist`` (:data:`MAG_OPTIONS`) as SimOptions fields."""
    chip = SCENARIOS[name].magnetometer
    if "mag" in raw:
        word = raw["mag"].lower()
        if word not in (*MAG_CHIPS, "none"):
            raise _fail(url, f"mag={_shown(raw['mag'])} is not a magnetometer the simulator "
                             f"has; use one of {', '.join(MAG_CHIPS)} or none")
        chip = None if word == "none" else word
    given = [key for key in ("mag_odr", "place", "date", "magdist") if key in raw]
    if given and chip is None:
        raise _fail(url, f"option {given[0]!r} needs a magnetometer (mag=lis3mdl or lis2mdl)")
    options: dict[str, object] = {"mag": chip}
    if "mag_odr" in raw and chip is not None:
        rate = _number(url, "mag_odr", raw["mag_odr"])
        try:
            MAG_CHIPS[chip].at_rate(rate)
        except ValueError as exc:
            raise _fail(url, f"mag_odr={_shown(raw['mag_odr'])}: {exc}") from None
        options["mag_odr_hz"] = rate
    if "place" in raw:
        options["place"] = _place(url, raw["place"])
    if "date" in raw:
        options["date"] = _date(url, raw["date"])
    if "magdist" in raw:
        try:
            options["mag_disturbances"] = _parse_disturbances(raw["magdist"])
        except ValueError as exc:
            raise _fail(url, str(exc)) from None
    return options


def _place(url: str, text: str) -> Place:
    parts = text.split(",")
    if len(parts) not in (2, 3):
        raise _fail(url, f"place={_shown(text)}: expected LAT,LON or LAT,LON,ALT_M (degrees, "
                         "metres)")
    values = [_number(url, "place", part) for part in parts]
    try:
        return Place(*values)
    except ValueError as exc:
        raise _fail(url, f"place={_shown(text)}: {exc}") from None


def _date(url: str, text: str) -> dt.date:
    try:
        day = dt.date.fromisoformat(text)
    except ValueError:
        raise _fail(url, f"date={_shown(text)}: expected YYYY-MM-DD") from None
    low, high = WMM_VALID_YEARS
    if not low <= day.year < high:
        raise _fail(url, f"date={_shown(text)}: the World Magnetic Model in use covers "
                         f"{low:.0f} to {high:.0f}")
    return day
