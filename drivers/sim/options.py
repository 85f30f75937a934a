"""Parse and validate ``sim://SCENARIO?key=value&...`` URLs (see :mod:`drivers.sim.device`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from urllib.parse import urlsplit

from app.core.faults.injection import FaultSpec, parse_fault_spec
from drivers import lsm6dsox
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
    Option("fault", "text", None, parse=parse_fault_spec, repeatable=True, field="faults",
           metavar="KIND:CHANNEL[:SIZE]@START",
           help="inject a fault, KIND:CHANNEL[:SIZE]@START[-END] (repeatable), KIND one of "
                "noise, stuck, dead, spike, bias, scale; SIZE in g (ax..az) or dps (gx..gz)"),
)
"""Options every scenario accepts."""


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
    return SimOptions(name, scenario_params=params, faults=faults, **values)  # type: ignore[arg-type]
