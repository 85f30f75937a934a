"""A simulated LSM6DSOX: a seed-picked chip with realistic errors, moved by a scenario.

URL: ``sim://SCENARIO?key=value&...``, for example ``sim://wobble?odr=416&seed=7``.

Scenarios (:data:`SCENARIOS`): static, slow-tilt, wobble, vibration, translation, handheld,
strokes, arm (a measuring arm: one stream per ``sensor=K``), tour,
interactive. Options every scenario accepts:

- ``odr`` Hz, snapped to the nearest LSM6DSOX rate 12.5 ... 6667 (default 104); the chip runs
  at 6666.67 Hz / ODR_Coeff, so "12.5" delivers 13.02 Hz and "104" 104.17 Hz (times the trim)
- ``accel_fs`` 2/4/8/16 g (default 4), ``gyro_fs`` 125/250/500/1000/2000 dps (default 250)
- ``seed`` integer >= 0 (default 1): picks the simulated *unit*, its unique id and errors
- ``realtime`` 1 (default): paced by the wall clock; 0: each read returns ``block`` samples
  (default 256) at once
- ``errors`` 0: an ideal chip; ``noise`` 0: no white noise (quantisation stays)
- ``settling`` 1: the first samples are the chip's turn-on transient (:mod:`drivers.sim.transient`),
  as a reader that does not discard them would see; 0 (default): already discarded
- ``fail_after`` seconds of device time, after which reads raise ``DeviceIOError`` as if the
  cable had been unplugged
- ``warmup=RISE[:TAU]``: the die warms by RISE degC with time constant TAU s (default 300)
  after power-up instead of the unit's own 1.5-4 degC (a temperature-compensation run)
- ``clock_offset`` s and ``clock_ppm``: the timestamps start at the offset and run that many
  ppm fast (a device clock of its own, for tests of the time alignment of several devices)
- ``fault=KIND:CHANNEL[:SIZE]@START[-END]``, repeatable: an injected sensor fault
  (:mod:`app.core.faults.injection`, :mod:`drivers.sim.faults`), e.g. ``fault=stuck:gx@10``;
  with a magnetometer also on ``mx``..``mz`` (SIZE in uT)
- ``mag=lis3mdl|lis2mdl|none``: a magnetometer beside the chip (default none; ``magtour``:
  lis3mdl), with ``mag_odr`` (its rate), ``place=LAT,LON[,ALT_M]``, ``date=YYYY-MM-DD`` (the
  World Magnetic Model's field there and then) and ``magdist=...`` (disturbances); see
  :mod:`drivers.sim.magnetometer`

plus the scenario's own options (``SCENARIOS[name].parameters``), such as ``roll``/``pitch``.

Time: the chip's oscillator runs at the nominal rate times its trim (``odr_hz`` in the
:class:`DeviceInfo`, what the chip reports) times a small untrimmed residual (``true_odr_hz``).
``t_s`` counts samples in trimmed periods, as the device's own timestamps would; the scenario
is evaluated at true time (sample index / ``true_odr_hz``), which in realtime mode is the wall
clock since :meth:`open`.

The sensors of one ``sim://arm`` (same seed and arm options, any ``sensor``) opened in realtime
at the same time are one arm on one board: the second one opened joins the first one's clock
(its first sample is the arm's current one, not sample 0), and :class:`DeviceInfo`'s
``extra["clock_domain"]`` names that shared clock (including ``clock_offset``/``clock_ppm``, so
a sensor with a clock of its own is in a domain of its own).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from app.core import quaternion as quat
from app.core.devices import SIMULATOR_REFERENCE
from app.core.earth_field import DEFAULT_PLACE, EarthField, earth_field
from app.core.orientation import quaternion_from_roll_pitch
from app.core.samples import RawBlock, ScaleFactors
from app.core.version import __version__
from drivers import lsm6dsox
from drivers.base import Device, DeviceDescriptor, DeviceInfo, read_block_s
from drivers.errors import DeviceError, DeviceIOError, DeviceUrlError
from drivers.sim.error_model import (
    REFERENCE_TEMP_DEGC,
    STREAM_SCENARIO,
    MagnetometerErrors,
    MeasurementModel,
    UnitErrors,
    unique_id_for_seed,
)
from drivers.sim.faults import SimulatedFaults
from drivers.sim.magnetometer import MAG_CHIPS, MagChip, MagneticWorld, SimulatedMagnetometer
from drivers.sim.options import GENERAL_OPTIONS, SimOptions, options_for_url, parse_sim_url
from drivers.sim.scenarios import SCENARIOS, Interactive, Scenario
from drivers.sim.transient import apply_turn_on_transient
from drivers.url_options import Option

"""What a simulator's reference orientation is (a recording's ``reference`` metadata)."""

__all__ = ["SCENARIOS", "SimulatedDevice"]

FIFO_SPAN_S = 1.0
"""A reader more than this far behind loses the excess (the chip's FIFO would overflow)."""
GENERATION_CHUNK = 1024
"""Samples computed at a time inside one block."""
_GRAVITY_EARTH = np.array([0.0, 0.0, lsm6dsox.STANDARD_GRAVITY_M_S2])
_SHARED_EPOCHS: dict[tuple[object, ...], list[float]] = {}
"""Open arms' shared start: key -> [start wall time, open sensors]."""
_SHARED_LOCK = threading.Lock()


class SimulatedDevice(Device):
    """The simulator behind ``sim://`` URLs (see the module docstring for the options).

    Parameters
    ----------
    url : ``sim://SCENARIO?options``.
    clock : wall clock in seconds for realtime pacing (tests may pass a fake one).
    **overrides : URL options given as Python values (``realtime=False``, ``odr=416``); they win
        over the URL's query.

    Attributes
    ----------
    options : the validated URL options.
    unit_errors : the true errors of this unit (ideal when ``errors=0``): what a calibration
        should find; ``unit_errors.magnetometer`` the magnetometer's, with ``mag=``.
    scenario : the true motion; ``scenario.motion(t)`` gives it at true times ``t``.
    mag_chip : the simulated magnetometer (``mag=``), None without one.
    earth_field : the World Magnetic Model's field for ``place`` and ``date``, None without a
        magnetometer; in the simulator's earth frame (ENU, y to magnetic north) it is
        ``earth_field.enu_magnetic_ut()``.
    """

    scheme: ClassVar[str] = "sim"
    steerable: ClassVar[bool] = True
    knows_truth: ClassVar[bool] = True
    url_options: ClassVar[tuple[Option, ...]] = GENERAL_OPTIONS

    @classmethod
    def options_for(cls, url: str = "") -> tuple[Option, ...]:
        """The general options and those of the URL's scenario."""
        return options_for_url(url)

    def __init__(
        self, url: str, *, clock: Callable[[], float] = time.monotonic, **overrides: object
    ) -> None:
        super().__init__(url)
        self.options: SimOptions = parse_sim_url(url, overrides)
        try:
            self.scenario: Scenario = self._new_scenario()
        except ValueError as exc:  # parameters that contradict each other
            raise DeviceUrlError(f"{url}: {exc}") from None
        unit = self.scenario.unit_errors(self.options.seed)
        self.mag_chip: MagChip | None = MAG_CHIPS[self.options.mag] if self.options.mag else None
        if self.mag_chip is not None and self.options.mag_odr_hz is not None:
            self.mag_chip = self.mag_chip.at_rate(self.options.mag_odr_hz)
        self.earth_field: EarthField | None = None
        if self.mag_chip is not None:
            unit = replace(unit, magnetometer=MagnetometerErrors.draw(unit.seed))
            try:
                self.earth_field = earth_field(self.options.place or DEFAULT_PLACE,
                                               self.options.date)
            except ValueError as exc:  # a date outside the model's span
                raise DeviceUrlError(f"{url}: {exc}") from None
        if self.options.warmup is not None:
            rise, tau = self.options.warmup
            unit = replace(unit, self_heating_degc=rise, self_heating_time_constant_s=tau)
        self.unit_errors: UnitErrors = unit if self.options.errors else unit.without_errors()
        self.unique_id = unique_id_for_seed(unit.seed)
        self._clock = clock
        self._stop = threading.Event()
        self._generation_lock = threading.Lock()
        self._opened_before = False
        self._start_wall_s = 0.0
        self._next_index = 0
        self._measurement = self._new_measurement()
        self.scale = ScaleFactors(
            accel_m_s2_per_lsb=self._measurement.accel_lsb_m_s2,
            gyro_rad_s_per_lsb=self._measurement.gyro_lsb_rad_s,
            temp_degc_per_lsb=1.0 / lsm6dsox.TEMP_LSB_PER_DEGC,
            temp_offset_degc=lsm6dsox.TEMP_OFFSET_DEGC,
            **({"mag_ut_per_lsb": self.mag_chip.ut_per_lsb} if self.mag_chip else {}),
        )
        self._magnetometer = self._new_magnetometer()
        self._faults = self._new_faults()

    # -- what the GUI and tests use ------------------------------------------------------------
    @property
    def odr_hz(self) -> float:
        """The trimmed output data rate the chip reports: its real rate (6666.67 Hz / ODR_Coeff,
        "12.5 Hz" is 13.02 Hz) x trim; ``odr_nominal_hz`` is the datasheet label."""
        real = lsm6dsox.real_odr_hz(self.options.odr_nominal_hz)
        return real * self.unit_errors.clock_trim_factor

    @property
    def true_odr_hz(self) -> float:
        """The real sample rate: the trimmed rate with the untrimmed residual."""
        return self.odr_hz * (1.0 + self.unit_errors.clock_residual)

    @property
    def measurement(self) -> MeasurementModel:
        """Noise levels, LSB sizes and the current bias random-walk state."""
        return self._measurement

    @property
    def magnetometer(self) -> SimulatedMagnetometer | None:
        """The simulated magnetometer (its chip, errors and the true field), None without one."""
        return self._magnetometer

    def device_time(self, t_true_s: np.ndarray) -> np.ndarray:
        """Device-clock timestamps of true times (as the rows' ``t_s`` are made)."""
        t_s = np.asarray(t_true_s, dtype=np.float64) * (self.true_odr_hz / self.odr_hz)
        if self.options.clock_ppm or self.options.clock_offset_s:
            t_s = t_s * (1.0 + 1e-6 * self.options.clock_ppm) + self.options.clock_offset_s
        return t_s

    @property
    def simulator_truth(self) -> dict[str, Any]:
        """What the simulator's metadata adds beyond ``unit_errors``: with a magnetometer the
        earth's field (``earth_field``: place, year, ENU vector, strength, dip, declination;
        ``earth_frame``) and the disturbances' truth (``mag_disturbances``)."""
        if self.earth_field is None or self._magnetometer is None:
            return {}
        field_ = self.earth_field
        place = field_.place
        return {
            "earth_frame": "ENU, y to magnetic north (x magnetic east, z up)",
            "earth_field": {
                "place": [place.latitude_deg, place.longitude_deg, place.altitude_m],
                "year": field_.year,
                "enu_ut": field_.enu_magnetic_ut().tolist(),
                "total_ut": field_.total_ut, "dip_deg": field_.dip_deg,
                "declination_deg": field_.declination_deg,
            },
            "mag_disturbances": self._magnetometer.world.truth(),
        }

    def truth_metadata(self) -> dict[str, Any]:
        """The unit's true errors and rate, the injected faults and :attr:`simulator_truth`:
        what a calibration or a fault detector run on a recording of it should find."""
        truth: dict[str, Any] = {"unit_errors": self.unit_errors.as_dict(),
                                 "true_odr_hz": self.true_odr_hz}
        faults = self.injected_faults
        if faults:
            truth["faults"] = list(faults)
        truth.update(self.simulator_truth)
        return truth

    @property
    def injected_faults(self) -> list[dict[str, object]]:
        """The faults of the URL's ``fault=`` options, as a recording's metadata lists them."""
        return self._faults.as_metadata()

    @property
    def is_interactive(self) -> bool:
        """True when :meth:`set_target_attitude` can move the sensor."""
        return isinstance(self.scenario, Interactive)

    @property
    def is_steerable(self) -> bool:
        """The interactive scenario follows :meth:`set_target_attitude` (drivers.base)."""
        return self.is_interactive

    @property
    def reference_source(self) -> str:
        return SIMULATOR_REFERENCE

    @classmethod
    def unpaced_url(cls, url: str) -> str:
        """``url`` with ``realtime=0`` unless it says how to pace."""
        if "realtime" in url:
            return url
        return url + ("&" if "?" in url else "?") + "realtime=0"

    def set_target_attitude(self, roll_deg: float, pitch_deg: float, yaw_deg: float = 0.0) -> float:
        """Tilt the virtual sensor (``sim://interactive`` only). Thread-safe.

        The true attitude glides from where it is now to the target, so the gyroscope and the
        accelerometer stay consistent. Returns the glide time in seconds.
        """
        if not self.is_interactive:
            raise DeviceError(f"{self.url}: only sim://interactive can be tilted from the program")
        target = quaternion_from_roll_pitch(roll_deg, pitch_deg, yaw_deg)
        with self._generation_lock:
            scenario = self.scenario
            assert isinstance(scenario, Interactive)
            t_start = self._next_index / self.true_odr_hz
            if self.options.realtime and self.is_open:
                t_start = max(t_start, self._clock() - self._start_wall_s)
            return scenario.set_target(t_start, target)

    @classmethod
    def discover(cls) -> list[DeviceDescriptor]:
        """One entry per scenario (the simulator is always available), and the interactive one
        with a magnetometer."""
        def label(scenario: type[Scenario]) -> str:
            chip = scenario.magnetometer
            return "Simulated LSM6DSOX" + (f" + {MAG_CHIPS[chip].name}" if chip else "")

        found = [
            DeviceDescriptor(f"sim://{name}", f"{label(sc)}: {sc.description}", "simulator")
            for name, sc in SCENARIOS.items()
        ]
        found.append(DeviceDescriptor(
            "sim://interactive?mag=lis3mdl",
            f"Simulated LSM6DSOX + LIS3MDL: {Interactive.description}", "simulator"))
        return found

    # -- Device template -----------------------------------------------------------------------
    def _open(self) -> DeviceInfo:
        with self._generation_lock:
            if self._opened_before:
                self.scenario = self._new_scenario()
                self._measurement = self._new_measurement()
                self._magnetometer = self._new_magnetometer()
                self._faults = self._new_faults()
            self._opened_before = True
            self._next_index = 0
            self._stop.clear()
            self._start_wall_s = self._clock()
            self._join_shared_epoch()
        opts = self.options
        chip = self.mag_chip
        return DeviceInfo(
            url=self.url,
            name=f"Simulated LSM6DSOX{f' + {chip.name}' if chip else ''} ({opts.scenario})",
            unique_id=self.unique_id,
            sensor="LSM6DSOX",
            odr_hz=self.odr_hz,
            odr_nominal_hz=opts.odr_nominal_hz,
            accel_fs_g=opts.accel_fs_g,
            gyro_fs_dps=opts.gyro_fs_dps,
            firmware=f"simulator {__version__}",
            reference=SIMULATOR_REFERENCE,
            extra={
                "scenario": opts.scenario,
                "scenario_params": dict(self.scenario.params),
                "seed": opts.seed,
                "errors": opts.errors,
                "noise": opts.noise,
                "realtime": opts.realtime,
                **({"clock_domain": self._clock_domain()} if self._epoch_key() else {}),
                **({"faults": self.injected_faults} if opts.faults else {}),
            },
            magnetometer=None if chip is None else chip.info(),
        )

    def _read(self, timeout_s: float) -> RawBlock | None:
        if self._stop.is_set():
            return None
        limit = self._sample_limit()
        if self._next_index >= limit:
            raise DeviceIOError(
                f"{self.url}: simulated cable unplugged after {self.options.fail_after_s:g} s "
                "of device time (fail_after option)"
            )
        if not self.options.realtime:
            return self._generate(min(self.options.block, limit - self._next_index), 0)
        due = self._wait_for_samples(timeout_s)
        if due <= 0:
            return None
        due = min(due, limit - self._next_index)
        capacity = max(1, round(FIFO_SPAN_S * self.true_odr_hz * self.options.speed))
        lost = max(0, due - capacity)
        return self._generate(due - lost, lost)

    def _close(self) -> None:
        self._stop.set()
        key = self._epoch_key()
        with _SHARED_LOCK:
            entry = _SHARED_EPOCHS.get(key) if key else None
            if entry is not None:
                entry[1] -= 1
                if entry[1] <= 0:
                    del _SHARED_EPOCHS[key]  # type: ignore[arg-type]

    def _epoch_key(self) -> tuple[object, ...] | None:
        """What makes two realtime arm sensors one arm (None for other scenarios)."""
        opts = self.options
        if opts.scenario != "arm" or not opts.realtime:
            return None
        params = tuple(sorted((k, v) for k, v in opts.scenario_params.items() if k != "sensor"))
        return (id(self._clock), opts.seed, opts.odr_nominal_hz, opts.speed, opts.errors, params)

    def _clock_domain(self) -> str:
        key = self._epoch_key()
        return (f"sim-arm:{hash(key) & 0xFFFFFFFF:08x}:{self.options.clock_offset_s:g}:"
                f"{self.options.clock_ppm:g}")

    def _join_shared_epoch(self) -> None:
        """Start on an open sibling's clock (one arm, one board); under the generation lock."""
        key = self._epoch_key()
        if key is None:
            return
        with _SHARED_LOCK:
            entry = _SHARED_EPOCHS.get(key)
            if entry is None:
                _SHARED_EPOCHS[key] = [self._start_wall_s, 1]
                return
            entry[1] += 1
            self._start_wall_s = entry[0]
        self._next_index = max(0, self._due() - 1)

    # -- internals ---------------------------------------------------------------------------
    def _new_scenario(self) -> Scenario:
        rng = np.random.default_rng([self.options.seed, STREAM_SCENARIO])
        return SCENARIOS[self.options.scenario](rng, **self.options.scenario_params)

    def _new_measurement(self) -> MeasurementModel:
        return MeasurementModel(
            self.unit_errors,
            self.options.accel_fs_g,
            self.options.gyro_fs_dps,
            self.odr_hz,
            white_noise=self.options.noise,
        )

    def _new_faults(self) -> SimulatedFaults:
        return SimulatedFaults(self.options.faults, self.options.seed,
                               self._measurement.accel_lsb_m_s2, self._measurement.gyro_lsb_rad_s,
                               self.scale.mag_ut_per_lsb)

    def _new_magnetometer(self) -> SimulatedMagnetometer | None:
        errors = self.unit_errors.magnetometer
        if self.mag_chip is None or self.earth_field is None or errors is None:
            return None
        # The room's disturbances from the URL's seed (one room for every sensor of an arm),
        # the chip's noise from its unit's.
        world = MagneticWorld.build(self.earth_field.enu_magnetic_ut(),
                                    self.options.mag_disturbances, self.options.seed)
        return SimulatedMagnetometer(self.mag_chip, errors, world, self.unit_errors.seed,
                                     white_noise=self.options.noise)

    def _sample_limit(self) -> int:
        """Index of the first sample never delivered (fail_after), or a huge number."""
        if self.options.fail_after_s is None:
            return np.iinfo(np.int64).max
        return math.ceil(self.options.fail_after_s * self.odr_hz)

    def _due(self) -> int:
        """Samples whose true time has come and that were not generated yet."""
        elapsed = (self._clock() - self._start_wall_s) * self.options.speed
        return math.floor(elapsed * self.true_odr_hz + 1e-9) + 1 - self._next_index

    def _wait_for_samples(self, timeout_s: float) -> int:
        due = self._due()
        # Realtime reads wait for drivers.base.read_block_s of data, like a host reading a
        # board (and at least one sample); at the rate samples arrive on the host's clock.
        arriving_hz = self.true_odr_hz * self.options.speed
        wanted = max(1, math.ceil(read_block_s(arriving_hz) * arriving_hz))
        if due < wanted:
            ready_at = self._start_wall_s + (self._next_index + wanted - 1) / (
                self.true_odr_hz * self.options.speed
            )
            wait_s = min(max(0.0, timeout_s), ready_at - self._clock())
            if wait_s > 0.0 and self._stop.wait(wait_s):
                return 0
            due = self._due()
        return due

    def _generate(self, n: int, lost: int) -> RawBlock:
        accel_raw = np.empty((n, 3), dtype=np.int16)
        gyro_raw = np.empty((n, 3), dtype=np.int16)
        temp_degc = np.empty(n)
        reference = np.empty((n, 4))
        with self._generation_lock:
            self._next_index += lost
            first = self._next_index
            self._next_index += n
            # Chunks keep numpy's temporaries small (cache-resident, no page faults).
            for start in range(0, n, GENERATION_CHUNK):
                stop = min(n, start + GENERATION_CHUNK)
                t_true = np.arange(first + start, first + stop) / self.true_odr_hz
                motion = self.scenario.motion(t_true)
                temp_degc[start:stop] = self.unit_errors.temperature_degc(t_true)
                specific_force = quat.rotate_inverse(
                    motion.orientation_quat, motion.linear_accel_m_s2 + _GRAVITY_EARTH
                )
                accel_raw[start:stop], gyro_raw[start:stop] = self._measurement.measure(
                    first + start, specific_force, motion.angular_rate_rad_s, temp_degc[start:stop]
                )
                reference[start:stop] = motion.orientation_quat
            mag_raw = None
            if self._magnetometer is not None:
                mag_raw = self._magnetometer.block(first, n, self.true_odr_hz,
                                                   self.scenario.orientation, self.device_time)
        if self.options.settling:  # sample k of the stream is the (k+1)th after the ODR write
            accel_raw, gyro_raw = apply_turn_on_transient(
                np.arange(first + 1, first + n + 1), accel_raw, gyro_raw,
                lsm6dsox.odr_code_for(self.options.odr_nominal_hz), self.options.gyro_fs_dps)
        temp_raw = np.rint((temp_degc - REFERENCE_TEMP_DEGC) * lsm6dsox.TEMP_LSB_PER_DEGC)
        t_s = np.arange(first, first + n) / self.odr_hz
        if self.options.clock_ppm or self.options.clock_offset_s:
            t_s = t_s * (1.0 + 1e-6 * self.options.clock_ppm) + self.options.clock_offset_s
        accel_raw, gyro_raw = self._faults.apply(t_s, accel_raw, gyro_raw)
        if mag_raw is not None:
            rows = ~np.isnan(mag_raw[:, 0])
            mag_raw[rows] = self._faults.apply_mag(t_s[rows], mag_raw[rows])
        gap = np.zeros(n, dtype=bool)
        gap[0] = lost > 0
        return RawBlock(
            t_s=t_s,
            accel_raw=accel_raw,
            gyro_raw=gyro_raw,
            temp_raw=temp_raw.astype(np.int16),
            scale=self.scale,
            gap=gap,
            lost_samples=lost,
            reference_quat=reference,
            mag_raw=mag_raw,
        )
