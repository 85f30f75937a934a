"""The simulated magnetometer beside the LSM6DSOX (``sim://SCENARIO?mag=lis3mdl|lis2mdl``).

Frames: the simulator's earth frame is ENU with **y toward magnetic north** (x magnetic east,
z up), the frame of :meth:`app.core.earth_field.EarthField.enu_magnetic_ut`. A scenario's
reference quaternion maps sensor-frame vectors into it, so a sensor at ``yaw=0`` (``q =
Rz(yaw) Ry(-pitch) Rx(roll)``) points its x axis to magnetic east and its y axis to magnetic
north, and ``yaw`` turns it counter-clockwise seen from above (toward north from east):
the x axis's compass heading is ``90 - yaw`` degrees (magnetic).

The true field at a sample is the World Magnetic Model's for the URL's ``place`` and ``date``
plus the disturbances (:class:`Disturbance`, ``magdist=``), all fixed in the room (the earth
frame), turned into the sensor frame by the true orientation. The chip then measures it with its
unit's errors (:class:`~drivers.sim.error_model.MagnetometerErrors`), its datasheet noise, and
its LSB (:data:`MAG_CHIPS`).

Timing: the chip runs on its own oscillator at its output rate (its nominal rate times ``1 +
odr_error``), sample ``k`` at true time ``(k + phase) / rate``. A sample lands on the first
accelerometer row at or after its time; rows between hold NaN. When the chip is faster than
the accelerometer, a row carries the newest of the samples that landed on it (the data
registers hold only the last).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from app.core import quaternion as quat
from app.core.devices import MagnetometerInfo
from drivers.sim.error_model import (
    INT16_MAX,
    INT16_MIN,
    STREAM_MAG_DISTURBANCE,
    STREAM_MAG_NOISE,
    MagnetometerErrors,
)

UT_PER_GAUSS = 100.0


@dataclass(frozen=True, slots=True)
class MagChip:
    """A magnetometer chip as the simulator runs it: its best low-noise setting."""

    name: str
    odr_hz: float
    """Output rate in the simulated mode."""
    range_ut: float
    """Full scale, +-uT."""
    ut_per_lsb: float
    noise_ut: tuple[float, float, float]
    """White-noise RMS per axis in the simulated mode (datasheet), uT."""
    address: int
    mode: str
    who_am_i: int
    rates_hz: tuple[float, ...] = ()
    """Every output rate of the simulated mode (``mag_odr=``); ``odr_hz`` is the default."""

    def at_rate(self, odr_hz: float) -> MagChip:
        """This chip set to ``odr_hz`` (one of :attr:`rates_hz`; same mode and noise)."""
        if odr_hz not in self.rates_hz:
            raise ValueError(f"the {self.name} has no rate {odr_hz:g} Hz in its "
                             f"{self.mode} mode; use one of "
                             f"{', '.join(f'{r:g}' for r in self.rates_hz)}")
        mode = self.mode + (", FAST_ODR" if self.name == "LIS3MDL" and odr_hz > 80.0 else "")
        return replace(self, odr_hz=float(odr_hz), mode=mode)

    def info(self) -> MagnetometerInfo:
        """The :class:`~app.core.devices.MagnetometerInfo` of this chip, simulated."""
        return MagnetometerInfo(chip=self.name, odr_hz=self.odr_hz, range_ut=self.range_ut,
                                ut_per_lsb=self.ut_per_lsb, address=self.address,
                                mode=self.mode, path="simulated")


LIS3MDL = MagChip(
    # Datasheet DocID024204: +-4 gauss full scale, 6842 LSB/gauss; ultra-high-performance
    # mode on x/y and z (OM = ZOM = 11) at DO = 80 Hz (the fastest rate without FAST_ODR);
    # RMS noise in that mode 3.2 mgauss (x, y) and 4.1 mgauss (z); I2C address 0x1C (SA1 low,
    # as on Adafruit's LSM6DSOX + LIS3MDL board), WHO_AM_I 0x3D. Its rates in this mode: DO =
    # 0.625 ... 80 Hz, and 155 Hz with FAST_ODR.
    name="LIS3MDL", odr_hz=80.0, range_ut=4.0 * UT_PER_GAUSS,
    ut_per_lsb=UT_PER_GAUSS / 6842.0, noise_ut=(0.32, 0.32, 0.41), address=0x1C,
    mode="ultra-high-performance", who_am_i=0x3D,
    rates_hz=(0.625, 1.25, 2.5, 5.0, 10.0, 20.0, 40.0, 80.0, 155.0),
)
LIS2MDL = MagChip(
    # Datasheet DocID 027847: 1.5 mgauss/LSB, +-49.152 gauss (16 bits x 1.5 mgauss);
    # continuous mode at 100 Hz (the fastest), high-resolution (LP = 0) with the low-pass
    # filter on (LPF = 1): RMS noise 3 mgauss; I2C address 0x1E, WHO_AM_I 0x40 in 0x4F.
    name="LIS2MDL", odr_hz=100.0, range_ut=32768 * 0.15, ut_per_lsb=0.15,
    noise_ut=(0.3, 0.3, 0.3), address=0x1E,
    mode="continuous, high-resolution, low-pass filter", who_am_i=0x40,
    rates_hz=(10.0, 20.0, 50.0, 100.0),
)
MAG_CHIPS: dict[str, MagChip] = {"lis3mdl": LIS3MDL, "lis2mdl": LIS2MDL}
"""``mag=`` URL value -> chip."""

_MU0_OVER_4PI = 1e-7  # T m / A
_RAMP_S = 1.0
"""The desk's field comes and goes over this long (the board is put down and picked up)."""


# -- disturbances ----------------------------------------------------------------------------
DISTURBANCE_KINDS: dict[str, str] = {
    "magnet": "a magnet carried past, closest at the window's middle, its field up to SIZE "
              "uT (default 150), at most 1/25 of that at the window's edges; needs @START, END "
              "default START + 4 s",
    "desk": "a steel desk: the field distorted (about 15 %) and SIZE uT (default 30) added, "
            "fixed in the room; without @ the whole time; ramps over 1 s at either end",
    "motor": "a running motor nearby: SIZE uT (default 5) at FREQ Hz (default 50) plus a "
             "steady SIZE uT, fixed in the room; without @ the whole time",
}
"""``magdist=`` kinds, with a line of help each."""
_DEFAULT_SIZE = {"magnet": 150.0, "desk": 30.0, "motor": 5.0}
_MAGNET_DEFAULT_S = 4.0
_MAGNET_DISTANCE_M = 0.1
_MAGNET_EDGE_DISTANCES = math.sqrt(50.0 ** (2.0 / 3.0) - 1.0)
"""The magnet's path: at the window's edges it is this many closest distances along its path
from the closest point, 3.68 times as far as at its closest, so its field there is at most 1/25
of the peak (1/50 of the closest point's in the same direction, and a dipole's field varies by
at most 2 with direction), falling as 1/r^3 beyond."""


@dataclass(frozen=True, slots=True)
class DisturbanceSpec:
    """One ``magdist=`` item: ``KIND[:SIZE[:FREQ]][@START[-END]]`` (times on the device clock)."""

    kind: str
    size: float
    start_s: float = 0.0
    end_s: float | None = None
    frequency_hz: float | None = None

    def text(self) -> str:
        freq = "" if self.frequency_hz is None else f":{self.frequency_hz:g}"
        end = "" if self.end_s is None else f"-{self.end_s:g}"
        return f"{self.kind}:{self.size:g}{freq}@{self.start_s:g}{end}"


def parse_disturbances(text: str) -> tuple[DisturbanceSpec, ...]:
    """Parse ``magdist=ITEM,ITEM...``; raises ValueError saying what is wrong."""
    form = "KIND[:SIZE[:FREQ]][@START[-END]]"
    specs = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            raise ValueError(f"magdist={text!r}: an empty item (expected {form}, ...)")
        head, at, when = item.partition("@")
        parts = [p.strip().lower() for p in head.split(":")]
        kind = parts[0]
        if kind not in DISTURBANCE_KINDS:
            raise ValueError(f"magdist item {item!r}: unknown kind {kind!r}; use one of "
                             f"{', '.join(DISTURBANCE_KINDS)}")
        most = 3 if kind == "motor" else 2
        if len(parts) > most:
            raise ValueError(f"magdist item {item!r}: too many ':' parts (expected {form}; "
                             "only motor takes FREQ)")
        size = _positive(item, "SIZE", parts[1]) if len(parts) > 1 else _DEFAULT_SIZE[kind]
        freq = None
        if kind == "motor":
            freq = _positive(item, "FREQ", parts[2]) if len(parts) > 2 else 50.0
        start, end = 0.0, None
        if at:
            start_text, dash, end_text = when.partition("-")
            start = _number(item, "START", start_text)
            if start < 0:
                raise ValueError(f"magdist item {item!r}: START must be >= 0 s")
            if dash:
                end = _number(item, "END", end_text)
                if end <= start:
                    raise ValueError(f"magdist item {item!r}: END ({end:g} s) must be after "
                                     f"START ({start:g} s)")
        elif kind == "magnet":
            raise ValueError(f"magdist item {item!r}: a magnet passes at a time: give "
                             "@START[-END] (e.g. magnet@10-14)")
        if kind == "magnet" and end is None:
            end = start + _MAGNET_DEFAULT_S
        specs.append(DisturbanceSpec(kind, size, start, end, freq))
    return tuple(specs)


def _number(item: str, name: str, value: str) -> float:
    try:
        number = float(value)
    except ValueError:
        raise ValueError(f"magdist item {item!r}: {name} {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ValueError(f"magdist item {item!r}: {name} {value!r} is not a finite number")
    return number


def _positive(item: str, name: str, value: str) -> float:
    number = _number(item, name, value)
    if not 0.0 < number <= 10000.0:
        raise ValueError(f"magdist item {item!r}: {name} must be above 0 and at most 10000")
    return number


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


class Disturbance:
    """One disturbance's field in the earth frame (uT) at device times, from its spec and a
    geometry drawn from the seed."""

    def __init__(self, spec: DisturbanceSpec, rng: np.random.Generator,
                 earth_ut: np.ndarray) -> None:
        self.spec = spec
        self.truth: dict[str, Any] = {
            "kind": spec.kind, "spec": spec.text(), "start_s": spec.start_s, "end_s": spec.end_s,
        }
        if spec.kind == "magnet":
            assert spec.end_s is not None
            self.t_mid = 0.5 * (spec.start_s + spec.end_s)
            half = 0.5 * (spec.end_s - spec.start_s)
            self.closest = _unit(rng) * _MAGNET_DISTANCE_M
            along = _unit(rng)
            along -= self.closest * (along @ self.closest) / _MAGNET_DISTANCE_M ** 2
            self.velocity = along / np.linalg.norm(along) * (
                _MAGNET_DISTANCE_M * _MAGNET_EDGE_DISTANCES / half)
            moment = _unit(rng)
            # Scaled so that the strongest field along the whole path is SIZE (a dipole's field
            # need not be strongest at the closest point: it depends on the direction too).
            path = self._offsets(np.linspace(-3.0 * half, 3.0 * half, 2001) + self.t_mid)
            peak = np.max(np.linalg.norm(self._dipole(path, moment), axis=1))
            self.moment = moment * (spec.size / peak)
            self.truth.update(peak_ut=spec.size, closest_s=self.t_mid,
                              closest_m=self.closest.tolist(),
                              velocity_m_s=self.velocity.tolist(),
                              moment_a_m2=self.moment.tolist())
        elif spec.kind == "desk":
            cross = np.triu(rng.uniform(-0.1, 0.1, (3, 3)), 1)
            self.distortion = np.diag(rng.uniform(-0.15, 0.15, 3)) + cross + cross.T
            self.offset = _unit(rng) * spec.size
            self.extra = self.distortion @ earth_ut + self.offset
            self.truth.update(field_ut=spec.size, distortion=self.distortion.tolist(),
                              offset_ut=self.offset.tolist(), extra_ut=self.extra.tolist())
        else:  # motor
            assert spec.frequency_hz is not None
            self.direction = _unit(rng)
            self.offset = _unit(rng) * spec.size
            self.phase = float(rng.uniform(0.0, 2.0 * math.pi))
            self.truth.update(amplitude_ut=spec.size, frequency_hz=spec.frequency_hz,
                              direction=self.direction.tolist(), offset_ut=self.offset.tolist(),
                              phase_rad=self.phase)

    @staticmethod
    def _dipole(r_m: np.ndarray, moment: np.ndarray) -> np.ndarray:
        """Field in uT (N, 3) of a dipole ``moment`` (A m^2) at offsets ``r_m`` (N, 3) from it."""
        r = np.linalg.norm(r_m, axis=1, keepdims=True)
        r_hat = r_m / r
        b_t = _MU0_OVER_4PI * (3.0 * r_hat * (r_hat @ moment)[:, None] - moment) / r ** 3
        return b_t * 1e6

    def _offsets(self, t_s: np.ndarray) -> np.ndarray:
        """(N, 3) from the magnet to the sensor: the magnet is at ``closest + v (t - t_mid)``
        from the sensor."""
        return -(self.closest + (t_s - self.t_mid)[:, None] * self.velocity)

    def active(self, t_s: np.ndarray) -> np.ndarray:
        """(N,) True inside the spec's window."""
        end = math.inf if self.spec.end_s is None else self.spec.end_s
        return (t_s >= self.spec.start_s) & (t_s < end)

    def field_ut(self, t_s: np.ndarray) -> np.ndarray:
        """(N, 3) extra field in the earth frame at device times ``t_s``: the magnet's dipole
        ``mu0/4pi (3 r^(m.r^) - m) / r^3`` as it passes (``truth``: its closest point, velocity
        and moment), the desk's ``distortion @ earth + offset`` ramped in and out, the motor's
        ``offset + amplitude sin(2 pi f t + phase) direction`` inside its window."""
        t_s = np.asarray(t_s, dtype=np.float64)
        spec = self.spec
        if spec.kind == "magnet":
            return self._dipole(self._offsets(t_s), self.moment)
        end = math.inf if spec.end_s is None else spec.end_s
        if spec.kind == "desk":
            ramp = min(_RAMP_S, 0.5 * (end - spec.start_s))
            weight = _smoothstep((t_s - spec.start_s) / ramp) * _smoothstep((end - t_s) / ramp)
            if spec.start_s == 0.0:  # on the desk from the start
                weight = np.where(t_s < ramp, _smoothstep((end - t_s) / ramp), weight)
            return weight[:, None] * self.extra
        assert spec.frequency_hz is not None
        on = self.active(t_s)
        wave = np.sin(2.0 * math.pi * spec.frequency_hz * t_s + self.phase)
        return on[:, None] * (self.offset + wave[:, None] * (spec.size * self.direction))


# -- the chip --------------------------------------------------------------------------------
@dataclass
class MagneticWorld:
    """Everything outside the chip: the earth's field (earth frame, uT) and the disturbances."""

    earth_ut: np.ndarray
    disturbances: list[Disturbance] = field(default_factory=list)

    @classmethod
    def build(cls, earth_ut: np.ndarray, specs: tuple[DisturbanceSpec, ...],
              seed: int) -> MagneticWorld:
        """The world of a URL's ``magdist`` specs, geometry from ``seed``."""
        rng = np.random.default_rng([seed, STREAM_MAG_DISTURBANCE])
        earth = np.asarray(earth_ut, dtype=np.float64)
        return cls(earth, [Disturbance(spec, rng, earth) for spec in specs])

    def field_ut(self, t_device_s: np.ndarray) -> np.ndarray:
        """(N, 3) true field in the earth frame at device times."""
        total = np.broadcast_to(self.earth_ut, (len(t_device_s), 3)).copy()
        for disturbance in self.disturbances:
            total += disturbance.field_ut(t_device_s)
        return total

    def truth(self) -> list[dict[str, Any]]:
        """The disturbances as the simulator's metadata lists them."""
        return [d.truth for d in self.disturbances]


class SimulatedMagnetometer:
    """The chip: which of its samples land on which accelerometer rows, and their raw counts.

    Parameters
    ----------
    chip : the simulated part.
    errors : its unit errors (ideal ones for ``errors=0``).
    world : the true field.
    seed : the unit's seed (its noise stream).
    white_noise : False switches the datasheet noise off (quantisation stays).
    """

    def __init__(self, chip: MagChip, errors: MagnetometerErrors, world: MagneticWorld,
                 seed: int, *, white_noise: bool = True) -> None:
        self.chip = chip
        self.errors = errors
        self.world = world
        self.true_odr_hz = chip.odr_hz * (1.0 + errors.odr_error)
        self.noise_ut = np.asarray(chip.noise_ut) if white_noise else np.zeros(3)
        self._noise_rng = np.random.default_rng([seed, STREAM_MAG_NOISE])

    def samples_for_rows(self, first: int, n: int, row_rate_hz: float
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Chip samples landing on rows ``first ... first + n - 1`` (rows at true times
        ``i / row_rate_hz``): their true times (M,) and row offsets within the block (M,), one
        per row at most (the newest)."""
        if n <= 0:
            return np.zeros(0), np.zeros(0, dtype=np.int64)
        rate, phase = self.true_odr_hz, self.errors.phase
        k_low = max(0, math.floor((first - 1) / row_rate_hz * rate - phase) - 1)
        k_high = math.ceil((first + n) / row_rate_hz * rate - phase) + 1
        k = np.arange(k_low, k_high + 1, dtype=np.float64)
        t_true = (k + phase) / rate
        rows = np.ceil(t_true * row_rate_hz - 1e-9).astype(np.int64)
        inside = (rows >= first) & (rows < first + n)
        t_true, rows = t_true[inside], rows[inside]
        newest = np.r_[rows[1:] != rows[:-1], True] if len(rows) else np.zeros(0, bool)
        return t_true[newest], rows[newest] - first

    def true_field_sensor_ut(self, t_device_s: np.ndarray, orientation: np.ndarray
                             ) -> np.ndarray:
        """(M, 3) true field in the sensor (accelerometer) frame."""
        return quat.rotate_inverse(orientation, self.world.field_ut(t_device_s))

    def measure(self, field_sensor_ut: np.ndarray) -> np.ndarray:
        """(M, 3) raw counts (float, whole numbers, int16 range) of true sensor-frame fields."""
        value = self.errors.apply(field_sensor_ut)
        if np.any(self.noise_ut) and len(value):
            value += self._noise_rng.standard_normal(value.shape) * self.noise_ut
        value *= 1.0 / self.chip.ut_per_lsb
        np.rint(value, out=value)
        np.clip(value, INT16_MIN, INT16_MAX, out=value)
        return value

    def block(self, first: int, n: int, row_rate_hz: float,
              orientation_at: Callable[[np.ndarray], np.ndarray],
              device_time: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """(n, 3) ``mag_raw`` for rows ``first ...``: counts where a sample landed, NaN elsewhere.

        ``orientation_at(t_true)`` gives the true sensor-to-earth quaternions, ``device_time``
        maps true times to the device clock (where the disturbances' windows are given).
        """
        out = np.full((n, 3), np.nan)
        t_true, rows = self.samples_for_rows(first, n, row_rate_hz)
        if len(rows):
            field_ut = self.true_field_sensor_ut(device_time(t_true), orientation_at(t_true))
            out[rows] = self.measure(field_ut)
        return out
