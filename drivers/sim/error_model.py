"""The simulated chip's own errors, and how they turn the truth into LSB counts.

A seed picks one simulated *unit*: its turn-on biases, scale and cross-axis errors, temperature
coefficients, bias random walks, temperature profile and clock trim. The same seed always gives
the same unit (numpy ``Generator`` on a seed-derived stream that nothing else uses).

Figures come from the project's HARDWARE.md. Where it says "typical +-X" the value is drawn
uniformly within +-X. "(assumed)" marks modelling choices no datasheet confirmed.

Measurement model per channel (accelerometer in m/s^2, gyroscope in rad/s), with ``dT = T - 25``::

    measured = (1 + scale_tc * dT) * (M @ true) + bias + bias_tc * dT + walk(t) + white_noise
    raw = clip(rint(measured / lsb), -32768, 32767)          # int16 LSB, saturates

with ``M = (I + diag(scale_error)) @ (I + cross_axis)``.

A magnetometer beside the accelerometer (``sim://...?mag=lis3mdl``, :mod:`drivers.sim.magnetometer`)
has errors of its own, :class:`MagnetometerErrors`, on a stream of their own
(:data:`STREAM_MAG_UNIT`), so adding one never changes the accelerometer's unit::

    m_chip = soft_iron @ alignment @ b + hard_iron + white_noise      # uT, chip axes
    raw = clip(rint(m_chip / lsb), -32768, 32767)

where ``b`` is the true field in the accelerometer's (sensor) frame.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from drivers import lsm6dsox

G = lsm6dsox.STANDARD_GRAVITY_M_S2
REFERENCE_TEMP_DEGC = 25.0
"""Temperature at which biases and scale errors are specified (and where raw temperature is 0)."""

# Independent random streams derived from one seed, so that e.g. a longer noise record never
# changes the unit's errors.
STREAM_UNIT = 0
STREAM_SCENARIO = 1
STREAM_ACCEL_NOISE = 2
STREAM_GYRO_NOISE = 3
STREAM_ACCEL_WALK = 4
STREAM_GYRO_WALK = 5
# 6 is app.core.faults.injection.STREAM_FAULTS.
STREAM_MAG_UNIT = 7
STREAM_MAG_NOISE = 8
STREAM_MAG_DISTURBANCE = 9

ACCEL_BIAS_LIMIT_M_S2 = 20e-3 * G  # zero-g level, typical +-20 mg
ACCEL_SCALE_LIMIT = 0.01  # sensitivity tolerance +-1 %
ACCEL_CROSS_AXIS_LIMIT = 0.01  # about 1 % (assumed)
ACCEL_BIAS_TC_LIMIT_M_S2_PER_DEGC = 0.1e-3 * G  # +-0.1 mg/degC (assumed, sibling parts)
GYRO_BIAS_LIMIT_RAD_S = math.radians(1.0)  # zero-rate level, typical +-1 dps
GYRO_SCALE_LIMIT = 0.01  # +-1 %
GYRO_CROSS_AXIS_LIMIT = 0.01  # about 1 % (assumed)
GYRO_BIAS_TC_LIMIT_RAD_S_PER_DEGC = math.radians(0.01)  # +-0.01 dps/degC (assumed, siblings)
SCALE_TC_LIMIT_PER_DEGC = 0.01e-2  # sensitivity +-0.01 %/degC (assumed, sibling parts)
# Bias random walks, expressed as the 1-sigma drift after one hour (assumed: a gyro bias
# instability of a few deg/h; accelerometer drift a small fraction of a mg).
GYRO_BIAS_DRIFT_DEG_S_PER_HOUR = (2.0 / 3600.0, 5.0 / 3600.0)
ACCEL_BIAS_DRIFT_M_S2_PER_HOUR = (0.05e-3 * G, 0.2e-3 * G)
# Temperature profile: room ambient plus self-heating after power-up (assumed).
AMBIENT_DEGC = (20.0, 28.0)
SELF_HEATING_DEGC = (1.5, 4.0)
SELF_HEATING_TIME_CONSTANT_S = (120.0, 480.0)
# Clock: INTERNAL_FREQ_FINE-like trim in 0.15 % steps, +-20 steps = +-3 % (assumed spread),
# and what the trim does not capture (assumed +-0.02 %).
FREQ_FINE_LIMIT = 20
CLOCK_RESIDUAL_LIMIT = 2e-4

# The magnetometer's unit (assumed figures, typical of a small board): hard iron from the board's
# parts, tens of uT; soft iron a few % of scale with cross terms; the magnetometer chip turned
# against the accelerometer chip by 1-2 degrees (two packages soldered separately); its own
# oscillator a little off nominal.
MAG_HARD_IRON_LIMIT_UT = 40.0
MAG_SOFT_SCALE_LIMIT = 0.05
MAG_SOFT_CROSS_LIMIT = 0.03
MAG_ALIGNMENT_DEG = (1.0, 2.0)
MAG_ODR_ERROR_LIMIT = 0.02

INT16_MIN = -32768
INT16_MAX = 32767


def unique_id_for_seed(seed: int) -> str:
    """The simulated unit's unique id: ``"SIM-"`` and 24 hex digits (96 bits), stable per seed."""
    digest = hashlib.blake2b(f"sim-lsm6dsox:{seed}".encode(), digest_size=12).hexdigest()
    return "SIM-" + digest.upper()


def accel_noise_rms_m_s2(accel_fs_g: int, odr_hz: float) -> float:
    """White-noise RMS per accelerometer axis: density x sqrt(ODR / 2)."""
    return lsm6dsox.accel_noise_g_per_sqrt_hz(accel_fs_g) * G * math.sqrt(odr_hz / 2.0)


def gyro_noise_rms_rad_s(odr_hz: float) -> float:
    """White-noise RMS per gyroscope axis: density x sqrt(ODR / 2)."""
    return math.radians(lsm6dsox.GYRO_NOISE_DPS_PER_SQRT_HZ) * math.sqrt(odr_hz / 2.0)


@dataclass(frozen=True, eq=False)
class MagnetometerErrors:
    """A simulated magnetometer's own errors against the accelerometer (the calibration's truth).

    The chip measures ``soft_iron @ alignment @ b + hard_iron`` (uT) of the true field ``b`` in
    the accelerometer's frame: ``alignment`` (a rotation, accelerometer axes -> magnetometer
    chip axes) is the turn between the two chips, ``soft_iron`` (symmetric) the distortion of
    the board's soft iron and the chip's own scale, ``hard_iron`` the board's permanent field.
    """

    hard_iron_ut: np.ndarray
    soft_iron: np.ndarray
    alignment: np.ndarray
    alignment_deg: float
    odr_error: float
    """Fractional error of the chip's own output rate (its oscillator)."""
    phase: float
    """Where in its first period the chip's first sample falls (0 ... 1)."""

    @classmethod
    def draw(cls, seed: int) -> MagnetometerErrors:
        """The magnetometer of unit ``seed`` (its own random stream)."""
        rng = np.random.default_rng([seed, STREAM_MAG_UNIT])
        hard = rng.uniform(-MAG_HARD_IRON_LIMIT_UT, MAG_HARD_IRON_LIMIT_UT, size=3)
        cross = np.triu(rng.uniform(-MAG_SOFT_CROSS_LIMIT, MAG_SOFT_CROSS_LIMIT, (3, 3)), 1)
        soft = np.eye(3) + np.diag(rng.uniform(-MAG_SOFT_SCALE_LIMIT, MAG_SOFT_SCALE_LIMIT, 3))
        soft = soft + cross + cross.T
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = float(rng.uniform(*MAG_ALIGNMENT_DEG))
        return cls(
            hard_iron_ut=hard, soft_iron=soft,
            alignment=rotation_matrix(axis * math.radians(angle)), alignment_deg=angle,
            odr_error=float(rng.uniform(-MAG_ODR_ERROR_LIMIT, MAG_ODR_ERROR_LIMIT)),
            phase=float(rng.uniform(0.0, 1.0)),
        )

    def without_errors(self) -> MagnetometerErrors:
        """An ideal magnetometer: no hard or soft iron, aligned, exact rate (same phase)."""
        return replace(self, hard_iron_ut=np.zeros(3), soft_iron=np.eye(3),
                       alignment=np.eye(3), alignment_deg=0.0, odr_error=0.0)

    @property
    def matrix(self) -> np.ndarray:
        """``soft_iron @ alignment``: accelerometer-frame field -> chip reading (less hard iron)."""
        return self.soft_iron @ self.alignment

    def apply(self, field_ut: np.ndarray) -> np.ndarray:
        """(N, 3) chip readings in uT (no noise, no quantisation) of true fields (N, 3) in the
        accelerometer's frame."""
        return np.asarray(field_ut, dtype=np.float64) @ self.matrix.T + self.hard_iron_ut

    def calibration_json(self) -> dict[str, Any]:
        """The exact correction in the binding ``calibrate-mag`` form, ``m = soft_iron (raw -
        hard_iron)`` (accelerometer frame): what a perfect calibration finds."""
        return {"hard_iron_uT": self.hard_iron_ut.tolist(),
                "soft_iron": np.linalg.inv(self.matrix).tolist()}

    def as_dict(self) -> dict[str, Any]:
        """The ``mag_*`` keys of :meth:`UnitErrors.as_dict`."""
        return {
            "mag_hard_iron_ut": self.hard_iron_ut.tolist(),
            "mag_soft_iron": self.soft_iron.tolist(),
            "mag_alignment": self.alignment.tolist(),
            "mag_alignment_deg": self.alignment_deg,
            "mag_odr_error": self.odr_error,
            "mag_phase": self.phase,
            "mag_calibration": self.calibration_json(),
        }


def rotation_matrix(rotvec: np.ndarray) -> np.ndarray:
    """The 3x3 matrix of a rotation vector (axis times angle, rad): Rodrigues' formula."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    angle = float(np.linalg.norm(rotvec))
    if angle == 0.0:
        return np.eye(3)
    k = rotvec / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


@dataclass(frozen=True, eq=False)
class UnitErrors:
    """Every per-unit error of one simulated chip, in SI units (the truth a calibration seeks).

    Attributes ending in ``_tc_..._per_degc`` multiply ``T - 25 degC``. Vectors are (3,), per
    sensor axis x, y, z; cross-axis matrices are (3, 3) with a zero diagonal.
    """

    seed: int
    accel_scale_error: np.ndarray
    accel_cross_axis: np.ndarray
    accel_bias_m_s2: np.ndarray
    accel_bias_tc_m_s2_per_degc: np.ndarray
    accel_scale_tc_per_degc: np.ndarray
    accel_bias_walk_m_s2_per_sqrt_s: float
    gyro_scale_error: np.ndarray
    gyro_cross_axis: np.ndarray
    gyro_bias_rad_s: np.ndarray
    gyro_bias_tc_rad_s_per_degc: np.ndarray
    gyro_scale_tc_per_degc: np.ndarray
    gyro_bias_walk_rad_s_per_sqrt_s: float
    ambient_degc: float
    self_heating_degc: float
    self_heating_time_constant_s: float
    freq_fine: int
    """Clock trim in INTERNAL_FREQ_FINE steps of 0.15 % (what the chip reports)."""
    clock_residual: float
    """Fractional clock error the trim does not capture: true rate = trimmed rate x (1 + this)."""
    magnetometer: MagnetometerErrors | None = None
    """The magnetometer beside the chip (``mag=`` URL option), None without one."""

    @classmethod
    def draw(cls, seed: int) -> UnitErrors:
        """The unit picked by ``seed`` (depends on nothing else)."""
        rng = np.random.default_rng([seed, STREAM_UNIT])

        def sym(limit: float, shape: tuple[int, ...] = (3,)) -> np.ndarray:
            return rng.uniform(-limit, limit, size=shape)

        def cross(limit: float) -> np.ndarray:
            return sym(limit, (3, 3)) * (1.0 - np.eye(3))

        def per_sqrt_s(bounds: tuple[float, float]) -> float:
            return float(rng.uniform(*bounds)) / math.sqrt(3600.0)

        return cls(
            seed=seed,
            accel_scale_error=sym(ACCEL_SCALE_LIMIT),
            accel_cross_axis=cross(ACCEL_CROSS_AXIS_LIMIT),
            accel_bias_m_s2=sym(ACCEL_BIAS_LIMIT_M_S2),
            accel_bias_tc_m_s2_per_degc=sym(ACCEL_BIAS_TC_LIMIT_M_S2_PER_DEGC),
            accel_scale_tc_per_degc=sym(SCALE_TC_LIMIT_PER_DEGC),
            accel_bias_walk_m_s2_per_sqrt_s=per_sqrt_s(ACCEL_BIAS_DRIFT_M_S2_PER_HOUR),
            gyro_scale_error=sym(GYRO_SCALE_LIMIT),
            gyro_cross_axis=cross(GYRO_CROSS_AXIS_LIMIT),
            gyro_bias_rad_s=sym(GYRO_BIAS_LIMIT_RAD_S),
            gyro_bias_tc_rad_s_per_degc=sym(GYRO_BIAS_TC_LIMIT_RAD_S_PER_DEGC),
            gyro_scale_tc_per_degc=sym(SCALE_TC_LIMIT_PER_DEGC),
            gyro_bias_walk_rad_s_per_sqrt_s=math.radians(
                per_sqrt_s(GYRO_BIAS_DRIFT_DEG_S_PER_HOUR)
            ),
            ambient_degc=float(rng.uniform(*AMBIENT_DEGC)),
            self_heating_degc=float(rng.uniform(*SELF_HEATING_DEGC)),
            self_heating_time_constant_s=float(rng.uniform(*SELF_HEATING_TIME_CONSTANT_S)),
            freq_fine=int(rng.integers(-FREQ_FINE_LIMIT, FREQ_FINE_LIMIT + 1)),
            clock_residual=float(rng.uniform(-CLOCK_RESIDUAL_LIMIT, CLOCK_RESIDUAL_LIMIT)),
        )

    def without_errors(self) -> UnitErrors:
        """An ideal chip (exact clock, no bias, scale or drift) in the same temperature profile."""
        zero = np.zeros(3)
        return replace(
            self,
            accel_scale_error=zero,
            accel_cross_axis=np.zeros((3, 3)),
            accel_bias_m_s2=zero,
            accel_bias_tc_m_s2_per_degc=zero,
            accel_scale_tc_per_degc=zero,
            accel_bias_walk_m_s2_per_sqrt_s=0.0,
            gyro_scale_error=zero,
            gyro_cross_axis=np.zeros((3, 3)),
            gyro_bias_rad_s=zero,
            gyro_bias_tc_rad_s_per_degc=zero,
            gyro_scale_tc_per_degc=zero,
            gyro_bias_walk_rad_s_per_sqrt_s=0.0,
            freq_fine=0,
            clock_residual=0.0,
            magnetometer=None if self.magnetometer is None else self.magnetometer.without_errors(),
        )

    @property
    def accel_matrix(self) -> np.ndarray:
        """``M = (I + diag(scale)) @ (I + cross_axis)`` at 25 degC."""
        return (np.eye(3) + np.diag(self.accel_scale_error)) @ (np.eye(3) + self.accel_cross_axis)

    @property
    def gyro_matrix(self) -> np.ndarray:
        """``M = (I + diag(scale)) @ (I + cross_axis)`` at 25 degC."""
        return (np.eye(3) + np.diag(self.gyro_scale_error)) @ (np.eye(3) + self.gyro_cross_axis)

    @property
    def clock_trim_factor(self) -> float:
        """Trimmed ODR over nominal ODR: ``1 + 0.0015 * freq_fine``."""
        return 1.0 + lsm6dsox.FREQ_FINE_STEP * self.freq_fine

    def temperature_degc(self, t_s: np.ndarray) -> np.ndarray:
        """Die temperature at true times ``t_s`` (s since power-up): ambient plus self-heating."""
        t_s = np.asarray(t_s, dtype=np.float64)
        heating = -np.expm1(-t_s / self.self_heating_time_constant_s)
        return self.ambient_degc + self.self_heating_degc * heating

    def as_dict(self) -> dict[str, Any]:
        """Plain Python values (lists for arrays), e.g. for a recording's metadata; with a
        magnetometer also its ``mag_*`` keys (:meth:`MagnetometerErrors.as_dict`)."""
        values = {
            key: value.tolist() if isinstance(value, np.ndarray) else value
            for key, value in asdict(self).items() if key != "magnetometer"
        }
        if self.magnetometer is not None:
            values.update(self.magnetometer.as_dict())
        return values


class RandomWalk:
    """A triaxial bias random walk, indexed by sample number.

    Drawn at knots every ``KNOT`` samples and interpolated linearly between them: the right
    statistics at all but the shortest time scales, where white noise dominates by far, at a
    fraction of the cost of one random draw per sample. Values depend on the sample index only
    (to rounding), not on how the stream is cut into blocks; a jump ahead (lost samples) takes
    one step of the combined variance.

    Parameters
    ----------
    sigma_per_sample : standard deviation of the per-sample increment, per axis.
    rng : the walk's own random stream.
    """

    KNOT = 64

    def __init__(self, sigma_per_sample: float, rng: np.random.Generator) -> None:
        self.knot_sigma = sigma_per_sample * math.sqrt(self.KNOT)
        self.rng = rng
        self._first_knot = 0
        self._knots = np.zeros((1, 3))

    def values(self, start: int, n: int) -> np.ndarray:
        """Walk values (n, 3) at samples ``start ... start + n - 1`` (start never decreases)."""
        first = start // self.KNOT
        last = (start + n - 1) // self.KNOT + 1
        have = self._first_knot + len(self._knots) - 1
        if first > have:
            jump = self.rng.standard_normal((1, 3)) * (self.knot_sigma * math.sqrt(first - have))
            self._knots = self._knots[-1:] + jump
            self._first_knot = have = first
        else:
            self._knots = self._knots[first - self._first_knot :]
            self._first_knot = first
        if last > have:
            steps = self.rng.standard_normal((last - have, 3)) * self.knot_sigma
            self._knots = np.vstack([self._knots, self._knots[-1] + np.cumsum(steps, axis=0)])
        samples = np.arange(start, start + n, dtype=np.float64)
        knot_samples = np.arange(first, first + len(self._knots), dtype=np.float64) * self.KNOT
        out = np.empty((n, 3))
        for axis in range(3):
            out[:, axis] = np.interp(samples, knot_samples, self._knots[:, axis])
        return out

    @property
    def current(self) -> np.ndarray:
        """The most recent knot value (3,)."""
        return self._knots[-1].copy()


class _Channel:
    """One triaxial sensor: errors, noise and random walk, and the int16 quantiser."""

    def __init__(
        self,
        matrix: np.ndarray,
        bias: np.ndarray,
        bias_tc: np.ndarray,
        scale_tc: np.ndarray,
        walk: RandomWalk | None,
        noise_rms: float,
        lsb: float,
        noise_rng: np.random.Generator,
    ) -> None:
        self.matrix_t = np.ascontiguousarray(matrix.T)
        self.bias = bias
        self.bias_tc = bias_tc if np.any(bias_tc) else None
        self.scale_tc = scale_tc if np.any(scale_tc) else None
        self.walk = walk
        self.noise_rms = noise_rms
        self.lsb = lsb
        self.noise_rng = noise_rng

    def measure(self, start: int, true: np.ndarray, temp_delta: np.ndarray) -> np.ndarray:
        """Raw int16 counts (N, 3) of true values (N, 3) from sample ``start``, at T - 25 degC."""
        value = true @ self.matrix_t
        if self.scale_tc is not None:
            value *= 1.0 + temp_delta[:, None] * self.scale_tc
        value += self.bias
        if self.bias_tc is not None:
            value += temp_delta[:, None] * self.bias_tc
        if self.walk is not None:
            value += self.walk.values(start, len(value))
        if self.noise_rms:
            noise = self.noise_rng.standard_normal(value.shape)
            noise *= self.noise_rms
            value += noise
        value *= 1.0 / self.lsb
        np.rint(value, out=value)
        np.clip(value, INT16_MIN, INT16_MAX, out=value)
        return value.astype(np.int16)


class MeasurementModel:
    """Turns true specific force and angular rate into the chip's raw LSB counts.

    Holds the random state (white noise and bias random walks), so one model produces one
    continuous stream: consecutive calls continue where the previous one stopped, and the
    output depends on the seed only, not on how the stream is cut into blocks.

    Parameters
    ----------
    unit : the unit's errors (use ``UnitErrors.without_errors()`` for an ideal sensor).
    accel_fs_g, gyro_fs_dps : full scales, which set the LSB sizes and the accelerometer noise.
    odr_hz : the sample rate that sets the noise bandwidth (ODR / 2) and the walk step.
    white_noise : False switches the white noise off (quantisation stays).
    """

    def __init__(
        self,
        unit: UnitErrors,
        accel_fs_g: int,
        gyro_fs_dps: int,
        odr_hz: float,
        *,
        white_noise: bool = True,
    ) -> None:
        self.unit = unit
        root = unit.seed
        dt_sqrt = math.sqrt(1.0 / odr_hz)

        def walk(sigma_per_sqrt_s: float, stream: int) -> RandomWalk | None:
            if sigma_per_sqrt_s == 0.0:
                return None
            return RandomWalk(sigma_per_sqrt_s * dt_sqrt, np.random.default_rng([root, stream]))

        self.accel_noise_rms_m_s2 = accel_noise_rms_m_s2(accel_fs_g, odr_hz) if white_noise else 0.0
        self.gyro_noise_rms_rad_s = gyro_noise_rms_rad_s(odr_hz) if white_noise else 0.0
        self.accel_lsb_m_s2 = lsm6dsox.accel_m_s2_per_lsb(accel_fs_g)
        self.gyro_lsb_rad_s = lsm6dsox.gyro_rad_s_per_lsb(gyro_fs_dps)
        self._accel = _Channel(
            unit.accel_matrix,
            unit.accel_bias_m_s2,
            unit.accel_bias_tc_m_s2_per_degc,
            unit.accel_scale_tc_per_degc,
            walk(unit.accel_bias_walk_m_s2_per_sqrt_s, STREAM_ACCEL_WALK),
            self.accel_noise_rms_m_s2,
            self.accel_lsb_m_s2,
            np.random.default_rng([root, STREAM_ACCEL_NOISE]),
        )
        self._gyro = _Channel(
            unit.gyro_matrix,
            unit.gyro_bias_rad_s,
            unit.gyro_bias_tc_rad_s_per_degc,
            unit.gyro_scale_tc_per_degc,
            walk(unit.gyro_bias_walk_rad_s_per_sqrt_s, STREAM_GYRO_WALK),
            self.gyro_noise_rms_rad_s,
            self.gyro_lsb_rad_s,
            np.random.default_rng([root, STREAM_GYRO_NOISE]),
        )

    @property
    def accel_walk(self) -> RandomWalk | None:
        """The accelerometer's bias random walk (m/s^2), None for an ideal chip."""
        return self._accel.walk

    @property
    def gyro_walk(self) -> RandomWalk | None:
        """The gyroscope's bias random walk (rad/s), None for an ideal chip."""
        return self._gyro.walk

    def measure(
        self,
        start: int,
        specific_force_m_s2: np.ndarray,
        angular_rate_rad_s: np.ndarray,
        temp_degc: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Raw ``(accel, gyro)`` int16 arrays (N, 3) of sensor-frame truths (N, 3).

        ``start`` is the index of the first sample (it places the random walks); the white
        noise continues its own stream.
        """
        temp_delta = np.asarray(temp_degc, dtype=np.float64) - REFERENCE_TEMP_DEGC
        accel = self._accel.measure(start, specific_force_m_s2, temp_delta)
        gyro = self._gyro.measure(start, angular_rate_rad_s, temp_delta)
        return accel, gyro
