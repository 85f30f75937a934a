"""``lsm6dsox://`` devices: the register-level driver on a named I2C bus.

URLs
----
- ``lsm6dsox://emulated?odr=104`` - the emulated chip of
  :mod:`~drivers.lsm6dsox_direct.emulated_chip` on a virtual bus, paced by the wall clock: the
  whole register path (configuration, FIFO bursts, tag decoding, timestamps) with the
  simulator's physics, no hardware needed.
- ``lsm6dsox://mcp2221?address=0x6a&odr=104`` - a real chip on an MCP2221A USB-I2C bridge
  (:mod:`~drivers.lsm6dsox_direct.mcp2221`; needs the optional EasyMCP2221 package).

Options for every bus: ``odr`` Hz (snapped to the nearest LSM6DSOX rate, default 104),
``accel_fs`` 2/4/8/16 g (default 4), ``gyro_fs`` 125/250/500/1000/2000 dps (default 250),
``address`` 0x6a (SA0 low, default) or 0x6b.

``mcp2221`` options: ``serial`` (the adapter's USB serial number) or ``index`` (enumeration
order, default 0), ``speed`` I2C clock in Hz (default 400000), ``force=1`` to allow an ODR above
:data:`~drivers.lsm6dsox_direct.mcp2221.MAX_ODR_HZ`.

``emulated`` options: ``scenario`` (a simulator scenario, default slow-tilt) and its options,
``seed``, ``errors``, ``noise`` as for ``sim://``; fault injection: ``who_am_i=0x6b`` (another
part answers), ``selftest_fault=1`` (the self-test changes nothing), ``fail_after`` seconds
(the adapter is pulled), ``part=lsm6dso32`` (a look-alike answering 0x6C whose accelerometer
ranges are double: it reads half the acceleration).

The magnetometer on the same bus (issue 31): ``mag=lis3mdl|lis2mdl|none`` on ``emulated`` puts
that emulated chip beside the LSM6DSOX (default none), with the simulator's ``place``, ``date``
and ``magdist`` and ``mag_fail_after`` seconds (the chip stops acknowledging); on ``mcp2221``
the driver probes for an LIS3MDL (0x1C, 0x1E) or LIS2MDL (0x1E) (``mag=auto``, the default)
unless ``mag=none``. A chip found is configured (:mod:`~drivers.lsm6dsox_direct.mag_driver`),
polled on every FIFO poll, and its samples land as ``RawBlock.mag_raw`` on the first
accelerometer row at or after their read time on the LSM6DSOX's clock (its TIMESTAMP
registers, read right after the magnetometer), NaN rows between. If it stops answering, a
warning says so and the rows stay NaN while the accelerometer streams on.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field, replace
from typing import ClassVar
from urllib.parse import parse_qsl, urlsplit

import numpy as np

from app.core.devices import DeviceMessage, MagnetometerInfo
from app.core.samples import RawBlock, ScaleFactors
from drivers import lsm6dsox
from drivers.base import Device, DeviceDescriptor, DeviceInfo
from drivers.errors import (
    DeviceClosedError,
    DeviceError,
    DeviceIOError,
    DeviceOpenError,
    DeviceUrlError,
)
from drivers.lsm6dsox_direct import mcp2221
from drivers.lsm6dsox_direct import registers as reg
from drivers.lsm6dsox_direct.bus import I2CBus
from drivers.lsm6dsox_direct.driver import Lsm6dsoxDriver, SelfTestResult, StreamSettings
from drivers.lsm6dsox_direct.fifo import DecodedSamples
from drivers.lsm6dsox_direct.mag_driver import MagnetometerDriver
from drivers.sim.error_model import unique_id_for_seed
from drivers.sim.options import SimOptions, parse_sim_url
from drivers.sim.options import options_for_url as sim_options_for_url
from drivers.url_options import Option, parse_options, url_error

BUSES = ("emulated", "mcp2221")
DEFAULT_ODR_HZ = 104.0
DEFAULT_ACCEL_FS_G = 4
DEFAULT_GYRO_FS_DPS = 250
DEFAULT_ADDRESS = 0x6A
DEFAULT_EMULATED_SCENARIO = "slow-tilt"
_SIM_ONLY = ("realtime", "block")


def _address_problem(address: int) -> str | None:
    return None if address in (0x6A, 0x6B) else "is not an LSM6DSOX address (0x6a or 0x6b)"


def _part(text: str) -> str:
    from drivers.lsm6dsox_direct.emulated_chip import PART_ACCEL_RANGE_FACTOR

    part = text.upper()
    if part not in PART_ACCEL_RANGE_FACTOR:
        raise ValueError(f"use one of {', '.join(p.lower() for p in PART_ACCEL_RANGE_FACTOR)}")
    return part


COMMON_OPTIONS: tuple[Option, ...] = (
    replace(lsm6dsox.ODR_OPTION, default=DEFAULT_ODR_HZ),
    replace(lsm6dsox.ACCEL_FS_OPTION, default=DEFAULT_ACCEL_FS_G),
    replace(lsm6dsox.GYRO_FS_OPTION, default=DEFAULT_GYRO_FS_DPS),
    Option("address", "integer", DEFAULT_ADDRESS, minimum=0, maximum=0x7F,
           check=_address_problem, help="I2C address: 0x6a (SA0 low) or 0x6b (107)"),
)
"""Options of every bus."""
MCP2221_OPTIONS: tuple[Option, ...] = (
    Option("serial", "text", None, help="mcp2221: the adapter's USB serial number"),
    Option("index", "integer", 0, minimum=0, maximum=255,
           help="mcp2221: which adapter, in enumeration order"),
    Option("speed", "integer", mcp2221.DEFAULT_SPEED_HZ, unit="Hz", minimum=47_000,
           maximum=400_000, field="speed_hz", help="mcp2221: I2C clock"),
    Option("force", "flag", False,
           help=f"mcp2221: 1 allows an odr above {mcp2221.MAX_ODR_HZ:g} Hz (expect gaps)"),
    Option("mag", "choice", "auto", choices=("auto", "none"),
           help="mcp2221: auto probes the bus for an LIS3MDL (0x1C, 0x1E) or an LIS2MDL (0x1E) "
                "and streams it; none leaves the bus alone"),
)
"""Options of ``lsm6dsox://mcp2221``."""
EMULATED_OWN_OPTIONS: tuple[Option, ...] = (
    Option("scenario", "text", DEFAULT_EMULATED_SCENARIO,
           help="emulated: the simulator scenario (its options and seed, errors, noise, ... "
                "as for sim://)"),
    Option("who_am_i", "integer", lsm6dsox.WHO_AM_I_VALUE, minimum=0, maximum=0xFF,
           help="emulated: the WHO_AM_I the chip answers (another part)"),
    Option("selftest_fault", "flag", False, help="emulated: 1: the self-test changes nothing"),
    Option("fail_after", "number", None, unit="s", positive=True, field="fail_after_s",
           help="emulated: seconds after which the adapter is pulled"),
    Option("part", "choice", "LSM6DSOX", choices=("lsm6dsox", "lsm6dso32"), parse=_part,
           help="emulated: lsm6dso32 is a look-alike answering 0x6C whose accelerometer ranges "
                "are double"),
    Option("mag_fail_after", "number", None, unit="s", positive=True, field="mag_fail_after_s",
           help="emulated: seconds after which the magnetometer stops acknowledging"),
)
"""Options of ``lsm6dsox://emulated`` beside the simulator's."""


@dataclass(frozen=True, slots=True)
class DirectOptions:
    """A validated ``lsm6dsox://`` URL."""

    bus: str
    odr_nominal_hz: float = DEFAULT_ODR_HZ
    accel_fs_g: int = DEFAULT_ACCEL_FS_G
    gyro_fs_dps: int = DEFAULT_GYRO_FS_DPS
    address: int = DEFAULT_ADDRESS
    serial: str | None = None
    index: int = 0
    speed_hz: int = mcp2221.DEFAULT_SPEED_HZ
    force: bool = False
    sim: SimOptions = field(default_factory=lambda: SimOptions(DEFAULT_EMULATED_SCENARIO))
    who_am_i: int = lsm6dsox.WHO_AM_I_VALUE
    selftest_fault: bool = False
    fail_after_s: float | None = None
    part: str = "LSM6DSOX"
    """The emulated part (``EmulatedLsm6dsox.PART_ACCEL_RANGE_FACTOR``)."""
    mag: str = "auto"
    """The magnetometer: ``none``, ``auto`` (probe; mcp2221), ``lis3mdl`` or ``lis2mdl``
    (emulated)."""
    mag_fail_after_s: float | None = None
    """Emulated: the magnetometer stops acknowledging after this many seconds."""


def parse_lsm6dsox_url(url: str, overrides: dict[str, object] | None = None) -> DirectOptions:
    """Validate an ``lsm6dsox://BUS?options`` URL (``overrides`` win over the query)."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "lsm6dsox" or "://" not in url:
        raise url_error(url, "not an lsm6dsox:// URL")
    bus = (parts.netloc + parts.path).strip("/").lower()
    if bus not in BUSES:
        raise url_error(url, f"unknown bus {bus!r}; use lsm6dsox://emulated or "
                             "lsm6dsox://mcp2221")
    if bus == "mcp2221":
        values = parse_options(url, parts.query, COMMON_OPTIONS + MCP2221_OPTIONS,
                               overrides=overrides).values
        odr = float(values.get("odr_nominal_hz", DEFAULT_ODR_HZ))  # type: ignore[arg-type]
        if odr > mcp2221.MAX_ODR_HZ and not values.get("force"):
            raise url_error(
                url,
                f"odr={odr:g} Hz is more than an MCP2221A can read (about 400 samples/s; "
                f"use {mcp2221.MAX_ODR_HZ:g} Hz or less, or force=1 to try and see gaps)",
            )
        return DirectOptions(bus, **values)  # type: ignore[arg-type]

    parsed = parse_options(url, parts.query, COMMON_OPTIONS + EMULATED_OWN_OPTIONS,
                           overrides=overrides, keep_other=True)
    sim_options = dict(parsed.other)  # the simulator's, checked by its own parser
    for key in _SIM_ONLY:
        if key in sim_options:
            raise url_error(url, f"option {key!r} is for sim:// only; the emulated chip is "
                                 "paced by the clock")
    if "mag_odr" in sim_options:
        raise url_error(url, "mag_odr is for sim:// only; the direct driver picks the "
                             "magnetometer's rate from what the bus can poll")
    # The emulated magnetometer on the bus: only when the URL asks (a scenario's own chip,
    # sim://magtour's, stays off the bus unless mag= says so).
    sim_options.setdefault("mag", "none")
    values = parsed.values
    scenario = values.pop("scenario", DEFAULT_EMULATED_SCENARIO)
    try:
        values["sim"] = parse_sim_url(f"sim://{scenario}", sim_options)
    except DeviceUrlError as exc:
        accepted = ", ".join(o.name for o in COMMON_OPTIONS + EMULATED_OWN_OPTIONS)
        raise url_error(url, f"{exc} (lsm6dsox://emulated also accepts {accepted})") from None
    values["mag"] = values["sim"].mag or "none"  # type: ignore[attr-defined]
    if values.get("mag_fail_after_s") is not None and values["mag"] == "none":
        raise url_error(url, "mag_fail_after needs an emulated magnetometer (mag=lis3mdl or "
                             "lis2mdl on lsm6dsox://emulated)")
    return DirectOptions(bus, **values)  # type: ignore[arg-type]


class Lsm6dsoxDirectDevice(Device):
    """An LSM6DSOX driven register by register (see the module docstring for the URLs).

    Parameters
    ----------
    url : ``lsm6dsox://BUS?options``.
    bus : an already made bus to use instead of the one the URL names (tests pass an
        :class:`~drivers.lsm6dsox_direct.emulated_chip.EmulatedLsm6dsox` on virtual time); the
        device never closes a bus it was given.
    **overrides : URL options as Python values; they win over the query.
    """

    scheme: ClassVar[str] = "lsm6dsox"
    url_options: ClassVar[tuple[Option, ...]] = (
        COMMON_OPTIONS + MCP2221_OPTIONS + EMULATED_OWN_OPTIONS
    )

    @classmethod
    def options_for(cls, url: str = "") -> tuple[Option, ...]:
        """A bus's options (the emulated chip's with its scenario's), or every bus's."""
        parts = urlsplit(url)
        bus = (parts.netloc + parts.path).strip("/").lower()
        if bus == "mcp2221":
            return COMMON_OPTIONS + MCP2221_OPTIONS
        if bus != "emulated":
            return cls.url_options
        scenario = dict(parse_qsl(parts.query)).get("scenario", DEFAULT_EMULATED_SCENARIO)
        own = COMMON_OPTIONS + EMULATED_OWN_OPTIONS
        names = {option.name for option in own} | set(_SIM_ONLY)
        return own + tuple(o for o in sim_options_for_url(f"sim://{scenario}")
                           if o.name not in names)

    def __init__(self, url: str, *, bus: I2CBus | None = None, **overrides: object) -> None:
        super().__init__(url)
        self.options = parse_lsm6dsox_url(url, overrides)
        self._given_bus = bus
        self._bus: I2CBus | None = None
        self._driver: Lsm6dsoxDriver | None = None
        self._mag: MagnetometerDriver | None = None
        self._mag_pending: list[tuple[float, np.ndarray]] = []
        self._messages: list[DeviceMessage] = []
        self._scale = ScaleFactors(
            accel_m_s2_per_lsb=lsm6dsox.accel_m_s2_per_lsb(self.options.accel_fs_g),
            gyro_rad_s_per_lsb=lsm6dsox.gyro_rad_s_per_lsb(self.options.gyro_fs_dps),
            temp_degc_per_lsb=1.0 / lsm6dsox.TEMP_LSB_PER_DEGC,
            temp_offset_degc=lsm6dsox.TEMP_OFFSET_DEGC,
        )
        self._reset_timeline()

    # -- public ---------------------------------------------------------------------------------
    @property
    def driver(self) -> Lsm6dsoxDriver | None:
        """The register-level driver while open."""
        return self._driver

    @property
    def bus(self) -> I2CBus | None:
        """The I2C bus while open."""
        return self._bus

    @property
    def magnetometer(self) -> MagnetometerDriver | None:
        """The magnetometer's driver while open and found (None after it failed)."""
        return self._mag

    def take_messages(self) -> list[DeviceMessage]:
        messages, self._messages = self._messages, []
        return messages

    @property
    def settings(self) -> StreamSettings | None:
        """What the chip was configured with, and its clock trim."""
        return None if self._driver is None else self._driver.settings

    @property
    def supports_self_test(self) -> bool:
        return True

    def self_test(self) -> SelfTestResult:
        """Run the chip's self-test (about 0.5 s), then stream again; the pause is a gap."""
        driver, bus = self._driver, self._bus
        if driver is None or bus is None or self.info is None:
            raise DeviceClosedError(f"{self.url} is not open")
        try:
            try:
                result = driver.self_test()
            finally:
                self._restart_stream(driver, bus)
        except DeviceIOError as exc:
            raise DeviceIOError(f"{self.url}: {exc}") from exc
        return result

    @classmethod
    def discover(cls) -> list[DeviceDescriptor]:
        """The emulated chip, and every MCP2221A adapter when EasyMCP2221 is installed."""
        found = [
            DeviceDescriptor(
                "lsm6dsox://emulated?odr=104",
                "Emulated LSM6DSOX on a virtual I2C bus (register-level driver)",
                "emulated",
            )
        ]
        for adapter in mcp2221.list_adapters():
            serial = adapter["serial"]
            which = f"serial={serial}" if serial else f"index={adapter['index']}"
            found.append(
                DeviceDescriptor(
                    f"lsm6dsox://mcp2221?{which}&odr=104",
                    f"LSM6DSOX on an MCP2221A USB-I2C bridge ({which}, USB 04D8:00DD)",
                    "i2c-bridge",
                )
            )
        return found

    # -- Device template --------------------------------------------------------------------------
    def _open(self) -> DeviceInfo:
        opts = self.options
        bus = self._given_bus if self._given_bus is not None else self._make_bus()
        driver = Lsm6dsoxDriver(bus, opts.address, label=self.url)
        try:
            driver.check_who_am_i()
            settings = driver.configure(opts.odr_nominal_hz, opts.accel_fs_g, opts.gyro_fs_dps)
        except DeviceError as exc:
            if bus is not self._given_bus:
                bus.close()
            if isinstance(exc, DeviceOpenError):
                raise
            raise DeviceOpenError(f"{self.url}: {exc}") from exc
        self._bus, self._driver = bus, driver
        self._reset_timeline()
        self._poll_interval_s = max(bus.min_poll_interval_s, min(0.05, 32.0 / settings.odr_hz))
        mag_info = self._open_magnetometer(bus)
        return DeviceInfo(
            url=self.url,
            name=self._name(bus),
            unique_id=self._unique_id(bus),
            sensor="LSM6DSOX",
            odr_hz=settings.odr_hz,
            odr_nominal_hz=settings.odr_nominal_hz,
            accel_fs_g=settings.accel_fs_g,
            gyro_fs_dps=settings.gyro_fs_dps,
            firmware="",
            extra={
                "bus": bus.description,
                "address": opts.address,
                "freq_fine": settings.freq_fine,
                "tick_s": settings.tick_s,
                "configuration": [[r, v] for r, v in settings.sequence],
                **({"mag_configuration": [[r, v] for r, v in self._mag.settings.sequence]}
                   if self._mag is not None and self._mag.settings is not None else {}),
            },
            magnetometer=mag_info,
        )

    def _open_magnetometer(self, bus: I2CBus) -> MagnetometerInfo | None:
        """Probe for a magnetometer (unless ``mag=none``) and set it up at the fastest rate at
        or below half the poll rate; None when none answers (the stream has no mag columns)."""
        self._mag = None
        self._mag_pending = []
        self._scale = replace(self._scale, mag_ut_per_lsb=1.0)
        if self.options.mag == "none":
            return None
        mag = MagnetometerDriver.probe(bus, label=self.url)
        if mag is None:
            return None
        try:
            # At most half the poll rate: at least two polls per field sample, so none is
            # overwritten unread (ZYXOR) when the chip's own clock runs a little fast.
            settings = mag.configure(0.5 / self._poll_interval_s)
        except DeviceIOError as exc:
            self._messages.append(DeviceMessage(2, f"{exc}; streaming without it"))
            return None
        self._mag = mag
        self._scale = replace(self._scale, mag_ut_per_lsb=settings.ut_per_lsb)
        return settings.info()

    def _read(self, timeout_s: float) -> RawBlock | None:
        driver, bus = self._driver, self._bus
        assert driver is not None and bus is not None
        try:
            deadline = bus.monotonic() + max(0.0, timeout_s)
            while True:
                self._poll_magnetometer(driver)
                decoded = driver.poll()
                if decoded is not None:
                    return self._block(decoded, driver, bus)
                now = bus.monotonic()
                if now >= deadline:
                    return None
                bus.delay(min(self._poll_interval_s, deadline - now))
        except DeviceIOError as exc:
            raise DeviceIOError(f"{self.url}: {exc}") from exc

    def _close(self) -> None:
        driver, bus = self._driver, self._bus
        self._driver = self._bus = None
        if driver is None or bus is None:
            return
        with contextlib.suppress(DeviceError):  # unplugged: nothing left to switch off
            driver.stop()
        mag, self._mag = self._mag, None
        if mag is not None:
            with contextlib.suppress(DeviceError):
                mag.stop()
        if bus is not self._given_bus:
            bus.close()

    # -- internals --------------------------------------------------------------------------------
    def _make_bus(self) -> I2CBus:
        opts = self.options
        if opts.bus == "mcp2221":
            return mcp2221.Mcp2221Bus(serial=opts.serial, index=opts.index, speed_hz=opts.speed_hz)
        from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox

        chip = EmulatedLsm6dsox(
            opts.sim, address=opts.address, who_am_i=opts.who_am_i,
            self_test_working=not opts.selftest_fault, fail_after_s=opts.fail_after_s,
            part=opts.part,
        )
        if opts.mag == "none":
            return chip
        from drivers.lsm6dsox_direct.emulated_mag import make_emulated_bus

        return make_emulated_bus(chip, opts.mag.upper(), fail_after_s=opts.mag_fail_after_s)

    def _name(self, bus: I2CBus) -> str:
        if self.options.bus == "emulated":
            sim = getattr(bus, "sim", self.options.sim)
            mag = getattr(bus, "magnetometer", None)
            chips = "LSM6DSOX" + (f" + {mag.part}" if mag is not None else "")
            return f"Emulated {chips}, register level ({sim.scenario})"
        return f"LSM6DSOX at 0x{self.options.address:02X} on {bus.description}"

    def _unique_id(self, bus: I2CBus) -> str:
        if self.options.bus == "emulated":
            sim = getattr(bus, "sim", self.options.sim)
            return "EMU-" + unique_id_for_seed(sim.seed)[4:]
        serial = getattr(bus, "serial", "") or f"index{self.options.index}"
        return f"MCP2221A-{serial}-0x{self.options.address:02X}"

    def _poll_magnetometer(self, driver: Lsm6dsoxDriver) -> None:
        """Read a new field sample, if the chip has one, and the LSM6DSOX's timestamp right
        after it: the sample waits in ``_mag_pending`` for the first row at or after that time.
        A magnetometer that stops answering is reported once and dropped; the accelerometer
        streams on (its rows' field is NaN)."""
        mag = self._mag
        if mag is None or driver.decoder is None:
            return
        try:
            counts = mag.poll()
        except DeviceIOError as exc:
            self._mag = None
            self._messages.append(DeviceMessage(
                2, f"the magnetometer stopped answering ({exc}); the field is NaN from here "
                   "while the accelerometer streams on"))
            return
        if counts is None:
            return
        raw_ticks = int.from_bytes(driver.read(reg.TIMESTAMP0, 4), "little")
        self._mag_pending.append((driver.decoder.unwrap_ticks(raw_ticks), counts))

    def _place_magnetometer(self, ticks: np.ndarray) -> np.ndarray | None:
        """(N, 3) ``mag_raw`` for rows at ``ticks``: each pending sample on the first row at
        or after its read time (the newest wins a row), NaN elsewhere; later ones wait."""
        if self.info is None or self.info.magnetometer is None:
            return None
        out = np.full((len(ticks), 3), np.nan)
        waiting = []
        for read_ticks, counts in self._mag_pending:
            row = int(np.searchsorted(ticks, read_ticks, side="left"))
            if row < len(ticks):
                out[row] = counts
            else:
                waiting.append((read_ticks, counts))
        self._mag_pending = waiting
        return out

    def _reset_timeline(self) -> None:
        self._origin_ticks: float | None = None
        self._time_offset_s = 0.0
        self._last_t_s: float | None = None
        self._last_block_clock_s = 0.0
        self._pending_lost = 0

    def _restart_stream(self, driver: Lsm6dsoxDriver, bus: I2CBus) -> None:
        """Configure again after a pause; the time axis keeps real time across it."""
        opts = self.options
        settings = driver.configure(opts.odr_nominal_hz, opts.accel_fs_g, opts.gyro_fs_dps)
        if self._last_t_s is not None:
            paused_s = max(0.0, bus.monotonic() - self._last_block_clock_s)
            # The first sample kept comes after the turn-on transient the driver drops.
            settling = driver.settling_left
            self._time_offset_s = self._last_t_s + paused_s + settling / settings.odr_hz
            self._pending_lost = max(0, round(paused_s * settings.odr_hz) - 1) + settling
            self._origin_ticks = None
        self._mag_pending = []  # their ticks were on the clock the reset restarted

    def _block(self, decoded: DecodedSamples, driver: Lsm6dsoxDriver, bus: I2CBus) -> RawBlock:
        settings = driver.settings
        assert settings is not None
        if self._origin_ticks is None:
            self._origin_ticks = float(decoded.ticks[0])
        t_s = self._time_offset_s + (decoded.ticks - self._origin_ticks) * settings.tick_s
        lost = decoded.lost_before.copy()
        lost[0] += self._pending_lost
        self._pending_lost = 0
        self._last_t_s = float(t_s[-1])
        self._last_block_clock_s = bus.monotonic()
        return RawBlock(
            t_s=t_s,
            accel_raw=decoded.accel_raw,
            gyro_raw=decoded.gyro_raw,
            temp_raw=decoded.temp_raw,
            scale=self._scale,
            gap=lost > 0,
            lost_samples=int(np.sum(lost)),
            mag_raw=self._place_magnetometer(decoded.ticks),
        )
