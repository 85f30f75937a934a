"""Parse and validate ``sim://SCENARIO?key=value&...`` URLs (see :mod:`drivers.sim.device`)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from urllib.parse import urlsplit

from app.core.earth_field import WMM_VALID_YEARS, Place
from app.core.faults.injection import FAULT_CHANNELS, MAG_CHANNELS, FaultSpec, parse_fault_spec
from drivers import lsm6dsox
from drivers.sim.magnetometer import DISTURBANCE_KINDS, MAG_CHIPS, DisturbanceSpec
from drivers.sim.magnetometer import parse_disturbances as _parse_disturbances
from drivers.sim.scenarios import SCENARIOS, Param
from drivers.url_options import Option, parse_options, url_error

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


def _warmup(text: str) -> tuple[float, float]:
    rise_text, _, tau_text = text.partition(":")
    try:
        rise = float(rise_text)
        tau = float(tau_text) if tau_text else DEFAULT_WARMUP_TAU_S
    except ValueError:
        raise ValueError("expected RISE[:TAU] in numbers") from None
    if not 0.0 <= rise <= 60.0 or not 1.0 <= tau <= 36000.0:  # also NaN
        raise ValueError("expected RISE[:TAU], RISE 0 ... 60 degC, TAU 1 ... 36000 s")
    return rise, tau


def _mag_chip(text: str) -> str | None:
    word = text.strip().lower()
    if word not in (*MAG_CHIPS, "none"):
        raise ValueError(f"is not a magnetometer the simulator has; use one of "
                         f"{', '.join(MAG_CHIPS)} or none")
    return None if word == "none" else word


def _place(text: str) -> Place:
    parts = text.split(",")
    if len(parts) not in (2, 3):
        raise ValueError("expected LAT,LON or LAT,LON,ALT_M (degrees, metres)")
    values = []
    for part in parts:
        try:
            values.append(float(part))
        except ValueError:
            raise ValueError(f"{part.strip()!r} is not a number") from None
    return Place(*values)


def _date(text: str) -> dt.date:
    try:
        day = dt.date.fromisoformat(text)
    except ValueError:
        raise ValueError("expected YYYY-MM-DD") from None
    low, high = WMM_VALID_YEARS
    if not low <= day.year < high:
        raise ValueError(f"the World Magnetic Model in use covers {low:.0f} to {high:.0f}")
    return day


GENERAL_OPTIONS: tuple[Option, ...] = (
    replace(lsm6dsox.ODR_OPTION, default=DEFAULT_ODR_HZ),
    replace(lsm6dsox.ACCEL_FS_OPTION, default=DEFAULT_ACCEL_FS_G,
            help="accelerometer full scale (default 4, or what the scenario's motion needs)"),
    replace(lsm6dsox.GYRO_FS_OPTION, default=DEFAULT_GYRO_FS_DPS,
            help="gyroscope full scale (default 250, or what the scenario's motion needs)"),
    Option("seed", "integer", DEFAULT_SEED, minimum=0, maximum=2**63 - 1,
           help="picks the simulated unit (its id and its errors)"),
    Option("realtime", "flag", True, help="1: paced by the wall clock; 0: blocks as fast as "
                                          "possible"),
    Option("speed", "number", 1.0, minimum=0.1, maximum=100.0,
           help="time-lapse factor for realtime pacing (1 = real time)"),
    Option("block", "integer", DEFAULT_BLOCK, minimum=1, maximum=MAX_BLOCK,
           help="samples per read when realtime=0"),
    Option("errors", "flag", True,
           help="0: an ideal chip (no bias, scale, cross-axis, drift or clock error)"),
    Option("noise", "flag", True, help="0: no white noise (quantisation stays)"),
    Option("settling", "flag", False,
           help="1: the first samples after open (a configure) are the chip's turn-on "
                "transient, as a board that does not discard them would send"),
    Option("fail_after", "number", None, unit="s", positive=True, field="fail_after_s",
           help="seconds of device time after which reads fail like an unplugged cable"),
    Option("warmup", "text", None, parse=_warmup, metavar="RISE[:TAU]",
           help="RISE[:TAU]: the die warms by RISE degC (0 ... 60) with time constant TAU s "
                "(1 ... 36000, default 300) after power-up, instead of the unit's own "
                "1.5-4 degC"),
    Option("clock_offset", "number", 0.0, unit="s", minimum=-MAX_CLOCK_OFFSET_S,
           maximum=MAX_CLOCK_OFFSET_S, field="clock_offset_s",
           help="seconds added to every timestamp (a device clock started elsewhere; beyond "
                "the range the timestamps lose the resolution of a sample period)"),
    Option("clock_ppm", "number", 0.0, unit="ppm", minimum=-10000.0, maximum=10000.0,
           help="parts per million the timestamps run fast (a drifting device clock, on top "
                "of the unit's own)"),
    Option("fault", "text", None, parse=lambda text: parse_fault_spec(text, FAULT_CHANNELS),
           repeatable=True, field="faults", metavar="KIND:CHANNEL[:SIZE]@START",
           help="inject a fault, KIND:CHANNEL[:SIZE]@START[-END] (repeatable), KIND one of "
                "noise, stuck, dead, spike, bias, scale; SIZE in g (ax..az), dps (gx..gz) or "
                "uT (mx..mz, with a magnetometer)"),
    # -- the magnetometer (issue 31) --
    Option("mag", "choice", None, choices=(*MAG_CHIPS, "none"), parse=_mag_chip,
           help="the magnetometer beside the LSM6DSOX: lis3mdl (80 Hz, +-4 gauss, ultra-high-"
                "performance), lis2mdl (100 Hz, +-49 gauss) or none (default; sim://magtour: "
                "lis3mdl)"),
    Option("mag_odr", "number", None, unit="Hz", positive=True, field="mag_odr_hz",
           help="the magnetometer's output rate: LIS3MDL 0.625, 1.25, 2.5, 5, 10, 20, 40, 80 "
                "(default) or 155 (FAST_ODR); LIS2MDL 10, 20, 50 or 100 (default)"),
    Option("place", "text", None, parse=_place, metavar="LAT,LON[,ALT_M]",
           help="where the earth's field is taken (World Magnetic Model; default "
                "52.5125,13.3269,50: TU Berlin)"),
    Option("date", "text", None, parse=_date, metavar="YYYY-MM-DD",
           help="the date the earth's field is taken for (default today; the model covers "
                f"{WMM_VALID_YEARS[0]:.0f}-{WMM_VALID_YEARS[1]:.0f})"),
    Option("magdist", "text", (), parse=_parse_disturbances, field="mag_disturbances",
           metavar="KIND[:SIZE[:FREQ]][@START[-END]],...",
           help="magnetic disturbances, ITEM,ITEM... (device-clock seconds): " + "; ".join(
               f"{kind}: {text}" for kind, text in DISTURBANCE_KINDS.items())),
)
"""Options every scenario accepts."""
MAG_OPTION_FIELDS = {"mag_odr_hz": "mag_odr", "place": "place", "date": "date",
                     "mag_disturbances": "magdist"}
"""The magnetometer's options that need one (field -> option name)."""


def scenario_name(url: str) -> str:
    """The scenario a ``sim://`` URL names, normalised (``Slow_Tilt`` -> ``slow-tilt``);
    ``sim://`` alone names the interactive simulator, as the app starts with."""
    parts = urlsplit(url)
    return (parts.netloc + parts.path).strip("/").lower().replace("_", "-") or DEFAULT_SCENARIO


def options_for_url(url: str) -> tuple[Option, ...]:
    """The options of a ``sim://`` URL's scenario (the general ones for no URL or an unknown
    scenario)."""
    name = scenario_name(url) if "://" in url else ""
    return scenario_options(name) if name in SCENARIOS else GENERAL_OPTIONS


def scenario_options(scenario: str) -> tuple[Option, ...]:
    """The options of ``sim://SCENARIO``: :data:`GENERAL_OPTIONS` and the scenario's own."""
    return GENERAL_OPTIONS + tuple(
        _param_option(key, spec) for key, spec in SCENARIOS[scenario].parameters.items()
    )


def _param_option(name: str, spec: Param) -> Option:
    """A scenario parameter as an option (its default's type is the option's)."""
    if isinstance(spec.default, bool):
        return Option(name, "flag", spec.default, help=spec.doc)
    kind = "integer" if isinstance(spec.default, int) else "number"
    return Option(name, kind, spec.default, minimum=spec.minimum, maximum=spec.maximum,
                  help=spec.doc)


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
    # The magnetometer (issue 31).
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


def parse_sim_url(url: str, overrides: Mapping[str, object] | None = None) -> SimOptions:
    """Validate a ``sim://`` URL; ``overrides`` (option name -> value) win over the query.

    Raises
    ------
    DeviceUrlError
        For an unknown scenario or option, or a bad value; the message names the allowed ones.
    """
    parts = urlsplit(url)
    if parts.scheme.lower() != "sim" or "://" not in url:
        raise url_error(url, "not a simulator URL; expected sim://SCENARIO?option=value&...")
    name = scenario_name(url)
    if name not in SCENARIOS:
        names = ", ".join(SCENARIOS)
        raise url_error(url, f"unknown simulator scenario {name!r}; choose one of: {names}")
    scenario = SCENARIOS[name]
    parsed = parse_options(url, parts.query, scenario_options(name), overrides=overrides,
                           context=f" for sim://{name}")
    values = parsed.values
    params = {key: values.pop(key) for key in scenario.parameters if key in values}
    if "accel_fs_g" not in values and scenario.accel_fs_g is not None:  # what the motion needs
        values["accel_fs_g"] = scenario.accel_fs_g
    if "gyro_fs_dps" not in values and scenario.gyro_fs_dps is not None:
        values["gyro_fs_dps"] = scenario.gyro_fs_dps
    faults = tuple(parsed.repeated.get("faults", ()))
    _check_magnetometer(url, scenario.magnetometer, values, faults)  # type: ignore[arg-type]
    return SimOptions(name, scenario_params=params, faults=faults, **values)  # type: ignore[arg-type]


def _check_magnetometer(url: str, default_chip: str | None, values: dict[str, object],
                        faults: tuple[FaultSpec, ...]) -> None:
    """The scenario's own chip unless ``mag=`` says otherwise; options and faults that need a
    magnetometer are refused without one; the chip's rate is one it has."""
    if "mag" not in values:
        values["mag"] = default_chip
    chip = values["mag"]
    if chip is None:
        given = [name for key, name in MAG_OPTION_FIELDS.items() if key in values]
        if given:
            raise url_error(url, f"option {given[0]!r} needs a magnetometer (mag=lis3mdl or "
                                 "lis2mdl)")
        on_field = [f for f in faults if f.channel in MAG_CHANNELS]
        if on_field:
            raise url_error(url, f"fault {on_field[0].text()!r}: mx..mz need a magnetometer "
                                 "(mag=lis3mdl or lis2mdl)")
        return
    rate = values.get("mag_odr_hz")
    if rate is not None:
        try:
            MAG_CHIPS[str(chip)].at_rate(float(rate))  # type: ignore[arg-type]
        except ValueError as exc:
            raise url_error(url, f"mag_odr={rate:g}: {exc}") from None
