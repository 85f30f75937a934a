"""Motion scenarios of the simulated sensor: the truth the simulated chip measures.

Each scenario is evaluated vectorised over an array of true times ``t`` (seconds since the
device opened) and returns a :class:`Motion`. Conventions are those of
:mod:`app.core.orientation`: ``q`` rotates sensor-frame vectors into the earth frame, earth z up.
The angular rate is in the sensor (body) frame and is exactly the derivative of ``q``,
``omega = 2 vec(conj(q) dq/dt)`` (analytic here; :meth:`Scenario.numerical_angular_rate` checks
it). Linear acceleration is in the earth frame and excludes gravity; the sensor sits at the
centre of rotation, so rotations alone cause none.

:data:`SCENARIOS` maps each URL name (``sim://NAME``) to its class; ``cls.description`` is a line
for the user and ``cls.parameters`` lists the URL options of that scenario.
"""

from __future__ import annotations

import hashlib
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from app.core import quaternion as quat
from app.core.orientation import quaternion_from_roll_pitch
from app.core.samples import STANDARD_GRAVITY_M_S2
from drivers.sim.error_model import GYRO_BIAS_LIMIT_RAD_S, UnitErrors

_GOLDEN_ANGLE_RAD = math.pi * (3.0 - math.sqrt(5.0))
_TWO_PI = 2.0 * math.pi
_G = STANDARD_GRAVITY_M_S2


@dataclass(frozen=True, slots=True)
class Param:
    """A scenario option: its default (whose type, bool/int/float, is the option's type), range."""

    default: float | int | bool
    minimum: float = -math.inf
    maximum: float = math.inf
    doc: str = ""


@dataclass(slots=True)
class Motion:
    """The true motion at N instants.

    Attributes
    ----------
    orientation_quat : (N, 4) sensor-to-earth unit quaternions (w, x, y, z).
    angular_rate_rad_s : (N, 3) angular rate in the sensor frame.
    linear_accel_m_s2 : (N, 3) acceleration of the sensor in the earth frame, gravity excluded.
    """

    orientation_quat: np.ndarray
    angular_rate_rad_s: np.ndarray
    linear_accel_m_s2: np.ndarray


# -- building blocks ---------------------------------------------------------------------------
def smoothstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``s = 3x^2 - 2x^3`` on x clipped to [0, 1], and ``ds/dx`` (zero outside)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x)


def smootherstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``s = 6x^5 - 15x^4 + 10x^3`` on x clipped to [0, 1], ``ds/dx`` and ``d2s/dx2``.

    Both derivatives are zero at the ends, so a path ramped by it keeps a continuous
    acceleration.
    """
    x = np.clip(x, 0.0, 1.0)
    x2 = x * x
    return x2 * x * (x * (6.0 * x - 15.0) + 10.0), 30.0 * x2 * (x - 1.0) ** 2, (
        60.0 * x * (x - 1.0) * (2.0 * x - 1.0)
    )


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (twice as fast as ``np.cross`` for these)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def rate_of_rotation_vector(phi: np.ndarray, phi_dot: np.ndarray) -> np.ndarray:
    """Body rate of ``q = q0 * exp(phi(t))`` (q0 fixed): the right Jacobian of phi times phi_dot."""
    theta2 = np.sum(phi * phi, axis=-1, keepdims=True)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    c1 = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    c2 = np.where(small, 1.0 / 6.0 - theta2 / 120.0, (safe - np.sin(safe)) / safe**3)
    phi_x_v = _cross(phi, phi_dot)
    return phi_dot - c1 * phi_x_v + c2 * _cross(phi, phi_x_v)


def compose(
    q_a: np.ndarray, rate_a: np.ndarray, q_b: np.ndarray, rate_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Orientation ``q_a * q_b`` and its body rate, from the parts' orientations and rates."""
    return quat.multiply(q_a, q_b), quat.rotate_inverse(q_b, rate_a) + rate_b


def _sin_cos(arg: np.ndarray, precise: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """float32 sine and cosine of float64 angles, reduced exactly to [-pi, pi] first.

    Four times faster than float64 trigonometry; the relative error, about 1e-7, is far
    below what the sensor resolves. ``arg`` is overwritten. ``precise``: float64 throughout.
    """
    if precise:
        return np.sin(arg), np.cos(arg)
    turns = np.rint(arg * (1.0 / _TWO_PI))
    turns *= _TWO_PI
    arg -= turns
    arg32 = arg.astype(np.float32)
    return np.sin(arg32), np.cos(arg32)


class MultiSine:
    """Per axis a sum of sines, ``v_i(t) = sum_k a_ik sin(2 pi f_ik t + p_ik)``, arrays (3, K).

    Evaluated in float32 (see :func:`_sin_cos`) unless ``precise``: large rotations (radians)
    keep float64, so that their finite differences, as in
    :meth:`Scenario.numerical_angular_rate`, are not swamped by float32 rounding.
    """

    def __init__(
        self, amplitudes: np.ndarray, freqs_hz: np.ndarray, phases_rad: np.ndarray,
        precise: bool = False,
    ):
        amplitudes = np.asarray(amplitudes, dtype=np.float64)
        omegas = 2.0 * np.pi * np.asarray(freqs_hz, dtype=np.float64)
        self.amplitudes = amplitudes
        self.omegas = omegas
        self.phases = np.asarray(phases_rad, dtype=np.float64)
        self.precise = precise
        dtype = np.float64 if precise else np.float32
        # Terms laid out as (3K, N) so numpy's inner loops run along time, and summed per axis
        # by a (3, 3K) block-diagonal matrix product.
        self._omega_col = omegas.reshape(-1, 1)
        self._phase_col = self.phases.reshape(-1, 1)
        mask = np.repeat(np.eye(3), amplitudes.shape[1], axis=1)
        self._value_sum = (mask * amplitudes.reshape(1, -1)).astype(dtype)
        self._rate_sum = (mask * (amplitudes * omegas).reshape(1, -1)).astype(dtype)
        self._accel_sum = (mask * (-amplitudes * omegas**2).reshape(1, -1)).astype(dtype)

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        terms: int,
        f_min_hz: float,
        f_max_hz: float,
        rms: float,
        slope: float,
    ) -> MultiSine:
        """Log-uniform frequencies, random phases, amplitudes ~ f**-slope, ``rms`` per axis."""
        freqs = np.exp(rng.uniform(math.log(f_min_hz), math.log(f_max_hz), size=(3, terms)))
        phases = rng.uniform(0.0, 2.0 * np.pi, size=(3, terms))
        amps = freqs**-slope
        amps *= rms / np.sqrt(0.5 * np.sum(amps * amps, axis=1, keepdims=True))
        return cls(amps, freqs, phases)

    def _angles(self, t: np.ndarray) -> np.ndarray:
        arg = self._omega_col * t
        arg += self._phase_col
        return arg

    @staticmethod
    def _per_axis(weights: np.ndarray, terms: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray((weights @ terms).T, dtype=np.float64)

    def value(self, t: np.ndarray) -> np.ndarray:
        """Values (N, 3) at times ``t`` (N,)."""
        sin, _ = _sin_cos(self._angles(t), self.precise)
        return self._per_axis(self._value_sum, sin)

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (N, 3) and their time derivatives (N, 3) at times ``t`` (N,)."""
        sin, cos = _sin_cos(self._angles(t), self.precise)
        return self._per_axis(self._value_sum, sin), self._per_axis(self._rate_sum, cos)

    def evaluate2(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Values (N, 3) and their first and second time derivatives (N, 3) at times ``t``."""
        sin, cos = _sin_cos(self._angles(t), self.precise)
        return (
            self._per_axis(self._value_sum, sin),
            self._per_axis(self._rate_sum, cos),
            self._per_axis(self._accel_sum, sin),
        )

    def rms(self) -> np.ndarray:
        """(3,) RMS of each axis over a long time (frequencies distinct)."""
        return np.sqrt(0.5 * np.sum(self.amplitudes**2, axis=1))


class Tremor:
    """A hand's tremor: random-phase multi-sine rotation (0.5-8 Hz) and small hand translations.

    Parameters
    ----------
    rng : source of frequencies and phases.
    amplitude_deg : RMS tremor angle per axis. Amplitudes fall as f**-1.5, so the slow sway
        dominates the angle and the fast tremor the rate (a few dps RMS at 1.5 degrees).
    shake_m_s2 : RMS hand acceleration per earth axis (0.5-5 Hz, bounded displacement).
    """

    def __init__(self, rng: np.random.Generator, amplitude_deg: float, shake_m_s2: float):
        self.rotation = MultiSine.random(rng, 6, 0.5, 8.0, math.radians(amplitude_deg), 1.5)
        self.translation = MultiSine.random(rng, 4, 0.5, 5.0, shake_m_s2, 0.0)

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tremor rotation (N, 4), its body rate (N, 3) and hand acceleration (N, 3), earth."""
        phi, phi_dot = self.rotation.evaluate(t)
        accel = self.translation.value(t)
        return quat.from_rotation_vector(phi), rate_of_rotation_vector(phi, phi_dot), accel


class RestBreaks:
    """How much a hand moves, ``e(t)`` in [0, 1]: ``move_s`` of motion, then ``rest_s`` still.

    Each motion phase ramps in and out over ``ramp_s`` (a quintic smootherstep, so a path
    scaled by ``e`` keeps a continuous acceleration); the stream starts with a ramp from rest.
    ``rest_s = 0``: no breaks, ``e = 1`` throughout.
    """

    def __init__(self, move_s: float, rest_s: float, ramp_s: float = 1.5):
        self.move_s = move_s
        self.rest_s = rest_s
        self.ramp_s = min(ramp_s, 0.5 * move_s)

    def at_rest(self, t: np.ndarray) -> np.ndarray:
        """(N,) True where the hand is still (``e = 0``)."""
        if self.rest_s <= 0.0:
            return np.zeros(np.shape(t), dtype=bool)
        tau = np.mod(t, self.move_s + self.rest_s)
        return (tau >= self.move_s) | (tau <= 0.0)

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``e``, ``de/dt`` and ``d2e/dt2`` (N,) at times ``t``."""
        if self.rest_s <= 0.0:
            return np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
        ramp = self.ramp_s
        tau = np.mod(t, self.move_s + self.rest_s)
        up, d_up, dd_up = smootherstep(tau / ramp)
        down, d_down, dd_down = smootherstep((self.move_s - tau) / ramp)
        d_up /= ramp
        dd_up /= ramp * ramp
        d_down /= -ramp
        dd_down /= ramp * ramp
        return up * down, d_up * down + up * d_down, dd_up * down + 2.0 * d_up * d_down + (
            up * dd_down
        )


def _flat_band(
    rng: np.random.Generator, terms: int, band_hz: tuple[float, float], rms: np.ndarray,
    power: float, third: float = 0.0,
) -> MultiSine:
    """Per axis ``terms`` sines (precise), log-uniform in ``band_hz``, random phases, whose
    ``power``-th derivative has equal amplitudes and ``rms`` (3,) per axis (0: the value).

    ``third``: each sine also gets its third harmonic, ``third`` times as large in that
    derivative and phased so that their peaks add (``sin x - third sin 3x``): a stroke that
    reverses sharply, as a hand does, rather than a pure sine.
    """
    low, high = band_hz
    freqs = np.exp(rng.uniform(math.log(low), math.log(high), size=(3, terms)))
    phases = rng.uniform(0.0, _TWO_PI, size=(3, terms))
    derivative = np.sqrt(2.0 / (terms * (1.0 + third * third))) * np.broadcast_to(
        np.asarray(rms, float)[:, None], (3, terms)
    )
    if third:
        freqs = np.hstack([freqs, 3.0 * freqs])
        phases = np.hstack([phases, 3.0 * phases])
        derivative = np.hstack([derivative, -third * derivative])
    return MultiSine(derivative / (_TWO_PI * freqs) ** power, freqs, phases, precise=True)


def _stack(*parts: MultiSine) -> MultiSine:
    """One (precise) multi-sine holding every term of ``parts``."""
    return MultiSine(
        np.hstack([p.amplitudes for p in parts]),
        np.hstack([p.omegas for p in parts]) / _TWO_PI,
        np.hstack([p.phases for p in parts]),
        precise=True,
    )


class HandMotion:
    """A hand moving a sensor around a rest pose: bounded translation and rotation, breaks.

    - Translation: per earth axis a sum of sines in ``band_hz`` with equal acceleration
      amplitudes, ``accel_rms`` (3,) per axis. The position is that sum integrated twice
      (amplitudes ``A / omega^2``), so it stays within ``sum(A / omega^2)`` of the rest spot
      (:meth:`position_bound`): the hand never walks away.
    - Rotation: a rotation vector ``phi`` (body axes of the rest pose), per axis ``rotation``
      (3,) rad RMS, made of a part that follows the hand's displacement (``coupling`` of the
      variance: turning the wrist as the hand moves) and an independent part in
      ``rotation_band_hz``, plus a fast ``jitter`` (2-8 Hz, rad/s RMS of rate per axis).
    - Breaks: the displacement and ``phi`` are scaled by :class:`RestBreaks`' ``e(t)``, so the
      sensor returns to its rest spot and pose, keeps still, and sets off again.

    Everything is analytic: acceleration and body rate are the exact derivatives of the
    position and orientation (:func:`rate_of_rotation_vector`).
    """

    TERMS: ClassVar[int] = 8
    THIRD_HARMONIC: ClassVar[float] = 0.5
    """Third harmonic of each translation term, relative to it in acceleration."""
    VIGOUR: ClassVar[float] = 0.3
    VIGOUR_BAND_HZ: ClassVar[tuple[float, float]] = (0.03, 0.1)
    JITTER_BAND_HZ: ClassVar[tuple[float, float]] = (2.0, 8.0)

    def __init__(
        self,
        rng: np.random.Generator,
        *,
        band_hz: tuple[float, float],
        accel_rms: np.ndarray,
        rotation_band_hz: tuple[float, float],
        rotation: np.ndarray,
        coupling: float,
        jitter: np.ndarray,
        breaks: RestBreaks,
    ):
        rotation = np.asarray(rotation, dtype=np.float64)
        self.breaks = breaks
        self.translation = _flat_band(
            rng, self.TERMS, band_hz, np.asarray(accel_rms), 2, self.THIRD_HARMONIC
        )
        # Coupled part: phi_c = C p, C scaled per row to the coupled share of each axis's RMS.
        mixing = rng.normal(size=(3, 3))
        mixing /= np.linalg.norm(mixing, axis=1, keepdims=True)
        coupled_rms = math.sqrt(coupling) * rotation
        self.coupling = mixing * coupled_rms[:, None] / self.translation.rms()[None, :]
        own = _flat_band(rng, self.TERMS, rotation_band_hz, math.sqrt(1.0 - coupling) * rotation, 0)
        shake = _flat_band(rng, self.TERMS, self.JITTER_BAND_HZ, np.asarray(jitter), 1)
        self.rotation = _stack(own, shake)
        # Vigour: a slow gain on the whole motion, 1 +- VIGOUR RMS, never below 1 - 3 x that
        # (three sines); the RMS figures above hold on average.
        vigour = np.zeros((3, 3))
        vigour[0] = self.VIGOUR * math.sqrt(2.0 / 3.0)
        self.vigour = MultiSine(
            vigour,
            np.exp(rng.uniform(*np.log(self.VIGOUR_BAND_HZ), size=(3, 3))),  # type: ignore[call-overload]
            rng.uniform(0.0, _TWO_PI, size=(3, 3)),
            precise=True,
        )
        self.vigour_norm = 1.0 / math.sqrt(1.0 + self.VIGOUR**2)

    def position_bound(self) -> np.ndarray:
        """(3,) largest possible distance from the rest spot along each earth axis, m."""
        most = self.vigour_norm * (1.0 + np.sum(np.abs(self.vigour.amplitudes[0])))
        return most * np.sum(np.abs(self.translation.amplitudes), axis=1)

    def position(self, t: np.ndarray) -> np.ndarray:
        """(N, 3) displacement from the rest spot, earth frame, m."""
        return self._gain(t)[0] * self.translation.value(t)

    def _gain(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The breaks' envelope times the vigour, and its two derivatives, (N, 1) each."""
        e, de, dde = self.breaks.evaluate(t)
        v, dv, ddv = (x[:, :1] * self.vigour_norm for x in self.vigour.evaluate2(t))
        v = v + self.vigour_norm
        e, de, dde = e[:, None], de[:, None], dde[:, None]
        return e * v, de * v + e * dv, dde * v + 2.0 * de * dv + e * ddv

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rotation from the rest pose (N, 4), its body rate (N, 3) and the acceleration (N, 3),
        earth frame."""
        e, de, dde = self._gain(t)
        p, v, a = self.translation.evaluate2(t)
        r, dr = self.rotation.evaluate(t)
        accel = dde * p + 2.0 * de * v + e * a
        free = r + p @ self.coupling.T
        free_dot = dr + v @ self.coupling.T
        phi = e * free
        phi_dot = de * free + e * free_dot
        return quat.from_rotation_vector(phi), rate_of_rotation_vector(phi, phi_dot), accel


def _tilt(roll: float, pitch: float, yaw: float | None = None) -> dict[str, Param]:
    params = {
        "roll": Param(roll, -180.0, 180.0, "roll angle, degrees"),
        "pitch": Param(pitch, -90.0, 90.0, "pitch angle, degrees"),
    }
    if yaw is not None:
        params["yaw"] = Param(yaw, -180.0, 180.0, "turn about the vertical, degrees, counter-"
                               "clockwise seen from above; 0: x to magnetic east (the x "
                               "axis's magnetic compass heading is 90 - yaw)")
    return params


def _repeat(row: np.ndarray, n: int) -> np.ndarray:
    return np.broadcast_to(row, (n, row.shape[-1])).copy()


# -- scenarios ---------------------------------------------------------------------------------
class Scenario(ABC):
    """A true motion. Subclasses set ``name``, ``description``, ``parameters``, and ``motion``.

    Parameters
    ----------
    rng : random source for phases and the like (derived from the device seed).
    **params : values for ``parameters`` (missing ones take their defaults).
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    parameters: ClassVar[dict[str, Param]] = {}
    accel_fs_g: ClassVar[int | None] = None
    """Accelerometer full scale for a URL without ``accel_fs`` (None: the simulator's 4 g)."""
    gyro_fs_dps: ClassVar[int | None] = None
    """Gyroscope full scale for a URL without ``gyro_fs`` (None: the simulator's 250 dps)."""
    magnetometer: ClassVar[str | None] = None
    """Magnetometer for a URL without ``mag`` (None: none; see :mod:`drivers.sim.magnetometer`)."""

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        unknown = sorted(set(params) - set(self.parameters))
        if unknown:
            raise TypeError(f"{self.name}: unknown parameters {unknown}")
        self.params: dict[str, float] = {k: p.default for k, p in self.parameters.items()}
        self.params.update(params)
        self.rng = rng if rng is not None else np.random.default_rng(1)

    @abstractmethod
    def motion(self, t: np.ndarray) -> Motion:
        """The true motion at true times ``t`` (N,), seconds."""

    def unit_errors(self, seed: int) -> UnitErrors:
        """The simulated unit that measures this motion for the device seed ``seed``."""
        return UnitErrors.draw(seed)

    def orientation(self, t: np.ndarray) -> np.ndarray:
        """Sensor-to-earth quaternions (N, 4) at times ``t``."""
        return self.motion(np.asarray(t, dtype=np.float64)).orientation_quat

    def angular_rate(self, t: np.ndarray) -> np.ndarray:
        """Body-frame angular rates (N, 3), rad/s."""
        return self.motion(np.asarray(t, dtype=np.float64)).angular_rate_rad_s

    def linear_acceleration(self, t: np.ndarray) -> np.ndarray:
        """Earth-frame accelerations (N, 3), m/s^2, gravity excluded."""
        return self.motion(np.asarray(t, dtype=np.float64)).linear_accel_m_s2

    def numerical_angular_rate(self, t: np.ndarray, h: float = 1e-4) -> np.ndarray:
        """``2 vec(conj(q) (q(t+h) - q(t-h)) / 2h)``: a check of the analytic rate."""
        t = np.asarray(t, dtype=np.float64)
        q = self.orientation(t)
        q_plus = self.orientation(t + h)
        q_minus = self.orientation(t - h)
        # q and -q are one rotation: align signs before differencing.
        q_plus *= np.sign(np.sum(q * q_plus, axis=-1, keepdims=True))
        q_minus *= np.sign(np.sum(q * q_minus, axis=-1, keepdims=True))
        dq = (q_plus - q_minus) / (2.0 * h)
        return 2.0 * quat.multiply(quat.conjugate(q), dq)[:, 1:]


class Static(Scenario):
    """Lying still at a fixed attitude."""

    name = "static"
    description = "lying still at a fixed tilt"
    parameters: ClassVar[dict[str, Param]] = _tilt(0.0, 0.0, yaw=0.0)

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        p = self.params
        self.quat = quaternion_from_roll_pitch(p["roll"], p["pitch"], p["yaw"])

    def motion(self, t: np.ndarray) -> Motion:
        n = len(t)
        return Motion(_repeat(self.quat, n), np.zeros((n, 3)), np.zeros((n, 3)))


class SlowTilt(Scenario):
    """Roll and pitch swing sinusoidally with different periods (a Lissajous of tilts)."""

    name = "slow-tilt"
    description = "slow tilting through +-30 degrees"
    parameters: ClassVar[dict[str, Param]] = {
        "amplitude": Param(30.0, 0.0, 80.0, "peak roll and pitch, degrees"),
        "roll_period": Param(20.0, 0.5, 3600.0, "seconds"),
        "pitch_period": Param(27.0, 0.5, 3600.0, "seconds"),
    }

    def motion(self, t: np.ndarray) -> Motion:
        p = self.params
        amp = math.radians(p["amplitude"])
        w_roll = 2.0 * np.pi / p["roll_period"]
        w_pitch = 2.0 * np.pi / p["pitch_period"]
        roll = amp * np.sin(w_roll * t)
        pitch = amp * np.sin(w_pitch * t)
        roll_rate = amp * w_roll * np.cos(w_roll * t)
        pitch_rate = amp * w_pitch * np.cos(w_pitch * t)
        # q = Ry(-pitch) Rx(roll), as quaternion_from_roll_pitch, multiplied out; body rate =
        # (roll_rate, 0, 0) + Rx(roll)^-1 (0, -pitch_rate, 0).
        cr, sr = np.cos(0.5 * roll), np.sin(0.5 * roll)
        cp, sp = np.cos(0.5 * pitch), np.sin(0.5 * pitch)
        q = np.stack([cp * cr, cp * sr, -sp * cr, sp * sr], axis=-1)
        rate = np.stack([roll_rate, -pitch_rate * np.cos(roll), pitch_rate * np.sin(roll)], axis=-1)
        return Motion(q, rate, np.zeros((len(t), 3)))


class Wobble(Scenario):
    """Held in a hand: tremor and small translations around a base tilt."""

    name = "wobble"
    description = "hand-held wobble"
    parameters: ClassVar[dict[str, Param]] = {
        **_tilt(5.0, -3.0),
        "amplitude": Param(1.5, 0.0, 20.0, "RMS tremor angle per axis, degrees"),
        "shake": Param(0.3, 0.0, 20.0, "RMS hand acceleration per axis, m/s^2"),
    }

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        p = self.params
        self.base_quat = quaternion_from_roll_pitch(p["roll"], p["pitch"])
        self.tremor = Tremor(self.rng, p["amplitude"], p["shake"])

    def motion(self, t: np.ndarray) -> Motion:
        q_tremor, rate, accel = self.tremor.evaluate(t)
        return Motion(quat.multiply(self.base_quat, q_tremor), rate, accel)


class Vibration(Scenario):
    """Bolted to a running machine: strong linear vibration, a little rocking."""

    name = "vibration"
    description = "on a running machine (strong vibration)"
    parameters: ClassVar[dict[str, Param]] = {
        **_tilt(2.0, -1.0),
        "g": Param(1.0, 0.0, 16.0, "peak linear vibration at the fundamental, g"),
        "freq": Param(30.0, 0.1, 1000.0, "fundamental frequency, Hz"),
        "angular": Param(0.05, 0.0, 5.0, "peak rocking angle, degrees"),
    }
    HARMONICS: ClassVar[tuple[float, ...]] = (1.0, 0.3, 0.1)
    """Relative amplitudes of the fundamental and its harmonics."""

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        p = self.params
        self.base_quat = quaternion_from_roll_pitch(p["roll"], p["pitch"])
        n = len(self.HARMONICS)
        # Each harmonic shakes along its own direction, mostly vertical.
        dirs = self.rng.normal(size=(n, 3)) * np.array([0.5, 0.5, 1.0])
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        amps = (p["g"] * _G * np.asarray(self.HARMONICS))[:, None] * dirs
        orders = np.arange(1, n + 1) * p["freq"]
        phases = self.rng.uniform(0.0, 2.0 * np.pi, size=n)
        self.linear = MultiSine(amps.T, np.tile(orders, (3, 1)), np.tile(phases, (3, 1)))
        axis = self.rng.normal(size=3)
        self.rocking = MultiSine(
            (math.radians(p["angular"]) * axis / np.linalg.norm(axis))[:, None],
            np.full((3, 1), p["freq"]),
            self.rng.uniform(0.0, 2.0 * np.pi, size=(3, 1)),
        )

    def motion(self, t: np.ndarray) -> Motion:
        accel = self.linear.value(t)
        phi, phi_dot = self.rocking.evaluate(t)
        q = quat.multiply(self.base_quat, quat.from_rotation_vector(phi))
        return Motion(q, rate_of_rotation_vector(phi, phi_dot), accel)


class Strokes(Scenario):
    """Bursts of fast back-and-forth strokes along horizontal directions, at a fixed tilt.

    Each stroke accelerates with ``+A sin`` over its first half (moving out and stopping) and
    ``-A sin`` over its second half (moving back), so the sensor returns to where it started.
    Successive bursts turn by the golden angle.

    A stress test, not a hand: 3 g strokes of 0.4 s (power near 2.5-7 Hz, ``|a|-g`` 9.4 m/s^2
    RMS) with no rotation at all, closer to a shaker or a vibrating machine. Hand-held
    translation as measured is :class:`Translation` (this scenario was ``translation`` until
    that one replaced it).
    """

    name = "strokes"
    description = "stress test: 3 g back-and-forth strokes at a fixed tilt, no rotation"
    parameters: ClassVar[dict[str, Param]] = {
        **_tilt(3.0, 2.0),
        "g": Param(3.0, 0.0, 32.0, "peak acceleration, g"),
        "stroke": Param(0.4, 0.02, 60.0, "duration of one out-and-back stroke, seconds"),
        "strokes": Param(3, 1, 1000, "strokes per burst"),
        "pause": Param(1.5, 0.0, 3600.0, "rest between bursts, seconds"),
    }

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        self.base_quat = quaternion_from_roll_pitch(self.params["roll"], self.params["pitch"])

    def motion(self, t: np.ndarray) -> Motion:
        p = self.params
        stroke = p["stroke"]
        burst = int(p["strokes"]) * stroke
        cycle = burst + p["pause"]
        index = np.floor(t / cycle)
        tau = t - index * cycle
        u = np.mod(tau, stroke) / stroke
        accel = p["g"] * _G * np.sin(4.0 * np.pi * u) * np.where(u < 0.5, 1.0, -1.0)
        accel = np.where(tau < burst, accel, 0.0)
        heading = index * _GOLDEN_ANGLE_RAD
        lin = np.stack([accel * np.cos(heading), accel * np.sin(heading), np.zeros_like(t)], -1)
        n = len(t)
        return Motion(_repeat(self.base_quat, n), np.zeros((n, 3)), lin)


def _between(slow: npt.ArrayLike, fast: npt.ArrayLike, level: float) -> np.ndarray:
    """Geometric interpolation: ``slow`` at level 0, ``fast`` at level 1."""
    slow = np.asarray(slow, dtype=np.float64)
    return slow * (np.asarray(fast, dtype=np.float64) / slow) ** level


class _HandScenario(Scenario):
    """A :class:`HandMotion` about a rest pose; subclasses give its figures at levels 0 and 1.

    Each (level 0, level 1) pair below is interpolated geometrically by the ``level`` option.
    """

    BAND_HZ: ClassVar[tuple[tuple[float, float], tuple[float, float]]]
    """Translation band (low, high) at level 0 and at level 1."""
    ACCEL_RMS: ClassVar[tuple[float, float]]
    """Linear acceleration RMS (3-D magnitude, while moving), m/s^2, level 0 and 1."""
    ROTATION_BAND_HZ: ClassVar[tuple[tuple[float, float], tuple[float, float]]]
    ROTATION_DEG: ClassVar[tuple[tuple[float, float, float], tuple[float, float, float]]]
    """RMS rotation about the rest pose's x, y, z, degrees, level 0 and 1."""
    COUPLING: ClassVar[float]
    JITTER_DPS: ClassVar[tuple[float, float]]
    """RMS rate of the 2-8 Hz jitter per axis, dps, level 0 and 1."""

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        p = self.params
        level = float(p["level"])
        self.base_quat = quaternion_from_roll_pitch(p["roll"], p["pitch"])
        band = _between(self.BAND_HZ[0], self.BAND_HZ[1], level)
        rotation_band = _between(self.ROTATION_BAND_HZ[0], self.ROTATION_BAND_HZ[1], level)
        accel = float(_between(*self.ACCEL_RMS, level)) / math.sqrt(3.0)
        self.hand = HandMotion(
            self.rng,
            band_hz=(float(band[0]), float(band[1])),
            accel_rms=np.full(3, accel),
            rotation_band_hz=(float(rotation_band[0]), float(rotation_band[1])),
            rotation=np.radians(_between(*self.ROTATION_DEG, level)),
            coupling=self.COUPLING,
            jitter=np.full(3, math.radians(float(_between(*self.JITTER_DPS, level)))),
            breaks=RestBreaks(p["move"], p["rest"]),
        )

    def position(self, t: np.ndarray) -> np.ndarray:
        """(N, 3) the sensor's displacement from its rest spot, earth frame, m."""
        return self.hand.position(np.asarray(t, dtype=np.float64))

    def at_rest(self, t: np.ndarray) -> np.ndarray:
        """(N,) True during the rest breaks."""
        return self.hand.breaks.at_rest(np.asarray(t, dtype=np.float64))

    def motion(self, t: np.ndarray) -> Motion:
        q_hand, rate, accel = self.hand.evaluate(t)
        return Motion(quat.multiply(self.base_quat, q_hand), rate, accel)


def _hand_params(roll: float, pitch: float, rest: float) -> dict[str, Param]:
    return {
        **_tilt(roll, pitch),
        "level": Param(0.5, 0.0, 1.0, "0: like BROAD's slow trials, 1: like its fast ones"),
        "move": Param(30.0, 3.0, 3600.0, "seconds of motion between rest breaks"),
        "rest": Param(rest, 0.0, 3600.0, "seconds of each rest break (0: no breaks)"),
    }


class Translation(_HandScenario):
    """Moved about by hand, mostly translation: as BROAD's translation trials measure.

    A :class:`HandMotion` about a near-level rest pose: linear acceleration of equal power on
    the three earth axes, in a band around 0.5-1.1 Hz with third harmonics (sharp reversals) and
    a slowly varying vigour (the occasional hard stroke), the hand turning with it (mostly
    about the vertical, as a wrist does) plus a 2-8 Hz jitter, and breaks of ``rest`` s after
    every ``move`` s (BROAD's trial 14 has three 10 s breaks; 10 and 15 none). ``level`` 0 is
    the slow trials, 1 the fast one, geometrically between (band, acceleration, rotation).

    Measured with :mod:`app.core.motion_stats` over the moving samples
    (``.venv/bin/python benchmarks/broad_motion_stats.py`` for the real trials; ``--sim URL
    --seconds 130`` for these, seed 1, 208 Hz, full scales as below). ``|a|-g`` and its peak in
    m/s^2; the linear acceleration's dominant and median frequency and the bands holding 50 %
    and 90 % of its power in Hz; rate RMS and peak in dps and its dominant frequency in Hz;
    tilt 5th/50th/95th percentile in degrees; rest, % of the span::

        source              |a|-g  peak   dom/med      50 %      90 % rate peak  dom   tilt rest
        real 10 slow         1.61   7.2 0.62/0.67 0.55-1.08 0.39-7.98   48  222 0.62 1/5/10    0
        real 14 slow+breaks  1.20   6.7 0.50/0.62 0.47-0.89 0.32-6.47   34  100 0.37 1/5/13   24
        real 15 fast         9.36  43.7 1.12/1.18 1.07-1.51 0.92-4.35  151  437 1.12 2/7/21    0
        sim level=0          1.64   5.8 0.50/0.71 0.52-0.92 0.35-2.25   44  139 0.62 2/5/11   24
        sim (level 0.5)      3.48  12.9 0.62/0.89 0.69-1.16 0.52-3.03   78  241 0.87 2/6/15   23
        sim level=1          8.74  30.4 0.87/1.21 0.94-1.54 0.76-4.11  152  512 1.37 2/8/21   23

    (The real trials' 90 % band reaches higher: sensor noise and knocks above 4 Hz that the
    simulation leaves out. Other seeds move the simulated figures by about 10 %.) The
    displacement never exceeds :meth:`HandMotion.position_bound` (2 m per axis at most, at
    level 1); in practice it stays within +-0.8 m, 0.1-0.17 m RMS per axis. The motion reaches
    5 g and 700 dps on an axis at level 1, so without ``accel_fs`` / ``gyro_fs`` in the URL this
    scenario reads at 8 g and 1000 dps.
    """

    name = "translation"
    description = "moved about by hand, as measured: ~1 Hz, 0.35 g RMS, turning with it, breaks"
    parameters: ClassVar[dict[str, Param]] = _hand_params(3.0, 2.0, 10.0)
    accel_fs_g = 8
    gyro_fs_dps = 1000
    # Level 0 / 1 are BROAD's trials 10 / 15 (benchmarks/broad_motion_stats.py): linear
    # acceleration RMS 2.70 / 14.06 m/s^2, rotation from the mean orientation 3/4/10 and 6/9/18
    # degrees RMS about x/y/z (simulated, seed 1: 3/4/10 and 6/9/17). The bands and the jitter
    # (the real rate's power above 2 Hz) were chosen to give the figures above.
    BAND_HZ = ((0.4, 0.9), (0.8, 1.6))
    ACCEL_RMS = (2.7, 14.06)
    ROTATION_BAND_HZ = ((0.3, 0.9), (0.7, 1.9))
    ROTATION_DEG = ((3.0, 4.0, 10.0), (6.0, 9.0, 18.0))
    COUPLING = 0.5
    JITTER_DPS = (15.0, 30.0)


class Handheld(_HandScenario):
    """Turned and moved in a hand, tilted by tens of degrees: BROAD's rotation and combined trials.

    A :class:`HandMotion` about a level rest pose: large rotations (about 65, 40 and 45
    degrees RMS about x, y, z, in a band of 0.1-0.4 Hz at ``level`` 0 up to 0.3-1.3 Hz at
    level 1) with a 2-8 Hz jitter, independent hand translation (0.4-1.2 Hz up to 0.8-2.5 Hz),
    a slowly varying vigour, and breaks of ``rest`` s after every ``move`` s, back at the rest
    pose (BROAD's trials 04, 08 and 30 put the sensor down two or three times for about 10 s).

    Measured as in :class:`Translation` (same script and columns; the linear-acceleration
    spectrum is left out for the rotation trials, where it is mostly the reference's error and
    the sensor's lever arm, above 3 Hz, and for tapping and vibration)::

        source                  |a|-g  peak   dom/med      50 % rate peak  dom     tilt rest
        real 01 slow rotation    0.72   6.2                       95  328 0.12 4/81/163    0
        real 04 slow+breaks      0.77  19.7                       95  469 0.25 3/73/161   26
        real 06 fast rotation    2.10  15.8                      298  935 1.37  3/32/92    0
        real 08 fast+breaks      2.63  15.5                      405 1360 0.62 2/77/162   22
        real 24 tapping          4.00 148.6                      183  523 0.37 2/56/165    0
        real 26 phone buzzing    2.62   9.0                      191  505 0.25 1/86/168    0
        real 28 combined         5.51  26.5 1.25/1.25 0.90-1.88  347  797 0.62 3/72/156    0
        real 30 combined+breaks  8.01  29.2 1.87/1.89 1.66-2.46  419  835 0.87 2/55/130   15
        real 32 combined slower  1.32   7.1 0.50/0.71 0.49-1.16  132  373 0.37  3/44/77    0
        sim level=0              0.88   3.6 0.50/0.75 0.51-1.07  115  295 0.25 7/52/115   22
        sim (level 0.5)          1.99   8.7 0.62/1.06 0.73-1.58  206  554 0.50 8/52/129   23
        sim level=1              4.53  20.3 0.87/1.54 1.05-2.37  363  875 0.87 6/53/130   22

    The sensor sits at the centre of rotation, so rotation adds no acceleration here (the real
    rotation trials' 0.7-2.6 m/s^2 of ``|a|-g`` come from the hand's lever arm), and the taps
    and the phone's 40 Hz buzz of trials 24 and 26 are not simulated. The rate reaches 1300 dps
    on an axis at level 1 (600 dps at the default level), so without ``accel_fs`` / ``gyro_fs``
    in the URL this scenario reads at 8 g and 2000 dps.
    """

    name = "handheld"
    description = "turned and moved in a hand, as measured: tilts of tens of degrees, breaks"
    parameters: ClassVar[dict[str, Param]] = _hand_params(0.0, 0.0, 10.0)
    accel_fs_g = 8
    gyro_fs_dps = 2000
    # Rotation from the mean orientation in BROAD's rotation and combined trials: 43-90, 19-46
    # and 30-81 degrees RMS about x, y, z (simulated, seed 1: 57-61, 37-39, 43-46). Level 0 / 1
    # aim at trials 01 and 32 / 08, 28 and 30; bands and accelerations were chosen to give the
    # figures above.
    BAND_HZ = ((0.4, 1.2), (0.8, 2.5))
    ACCEL_RMS = (1.5, 8.0)
    ROTATION_BAND_HZ = ((0.1, 0.4), (0.3, 1.3))
    ROTATION_DEG = ((65.0, 40.0, 45.0), (65.0, 40.0, 45.0))
    COUPLING = 0.0
    JITTER_DPS = (5.0, 15.0)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random unit quaternion (w >= 0)."""
    return quat.normalize(rng.normal(size=4))


def _random_unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


class Arm(Scenario):
    """A hand-held chain of ``links`` links joined by hinges, one sensor on each link.

    The base link is moved like :class:`Handheld` (tilts of tens of degrees, hand translation,
    rest breaks; ``base`` scales its rotation, ``level`` its speed). Each hinge ``k`` (between
    links ``k-1`` and ``k``) turns about a random axis fixed in link ``k-1``, through a smooth
    random angle in [``joint_min``, ``joint_max``] (``mid + half * tanh(s(t))``, ``s`` a sum of
    sines up to ``joint_band`` Hz). Each sensor is mounted on its link in a random orientation,
    so the hinge axis is unknown in every sensor's frame. Sensors sit away from the hinges
    (links 0.2-0.35 m long), so they feel the centripetal and tangential accelerations of the
    joints as well as the hand's.

    ``sensor`` picks which link's sensor this stream is. The arm itself (motion, axes,
    mountings) depends on the seed only, so streams of one seed with different ``sensor`` are
    one consistent arm. Each sensor is its own simulated unit (:meth:`unit_errors`: its own
    biases, noise and id), but all share the arm's sample clock, as one board reading every
    chip on one trigger would. Gyroscope turn-on biases are drawn within +-``bias`` dps; with
    ``calibrated`` (the default) the units have no scale or cross-axis errors and a residual
    accelerometer bias of at most 2 mg, as after the app's six-face calibration (the
    bias, its drift and temperature dependence, noise and quantisation stay).

    ``column=1`` is the JAMRIS measuring arm instead, standing on a table: a column turning
    about the vertical by theta (the base's x axis points ``base_azimuth_deg`` from magnetic
    north), link 0 (the upper arm) raised from the column's top by a hinge about the
    horizontal, every further link by a parallel hinge (:data:`COLUMN_HINGE_AXIS`), each
    sensor mounted with x along its link and z up when its joints are at zero (as the app's
    arm layout assumes). The arm is *placed*: placement ``p`` is held still for ``hold`` s,
    then it moves to the next over ``transition`` s. The placements visit ``spots`` targets in
    turn (1: the same spot every time, a repeatability test), each joint ``scatter`` degrees
    (SD) off its target, as a hand puts a tip on a mark. :meth:`column_angles_deg` is the truth
    (theta, the upper arm's and every hinge's angle), :meth:`placement_windows` the holds.
    """

    name = "arm"
    description = "sensors on a hand-held chain of links joined by hinges (measuring arm)"
    parameters: ClassVar[dict[str, Param]] = {
        "links": Param(2, 2, 6, "number of links, each carrying one sensor"),
        "sensor": Param(0, 0, 5, "which link's sensor this stream is (0: the base)"),
        "level": Param(0.5, 0.0, 1.0, "speed of the hand: 0 like BROAD's slow trials, 1 fast"),
        "base": Param(1.0, 0.0, 1.0, "scale of the base's rotation (small: poorly excited axes)"),
        "joint_min": Param(10.0, 0.0, 180.0, "smallest joint angle, degrees"),
        "joint_max": Param(130.0, 0.0, 180.0, "largest joint angle, degrees"),
        "joint_band": Param(0.5, 0.02, 3.0, "highest frequency of the joint motion, Hz"),
        "bias": Param(0.5, 0.0, 5.0, "largest gyroscope turn-on bias per axis, dps"),
        "calibrated": Param(True, doc="1: units as after a six-face calibration (no scale or "
                            "cross-axis errors, accelerometer bias within +-2 mg); 0: raw units "
                            "(1 % scale and cross-axis errors, +-20 mg)"),
        "move": Param(30.0, 3.0, 3600.0, "seconds of base motion between rest breaks"),
        "rest": Param(10.0, 0.0, 3600.0, "seconds of each rest break of the base"),
        "column": Param(False, doc="1: the JAMRIS measuring arm on a table instead (a column "
                        "turning about the vertical, links raised by horizontal hinges, "
                        "sensors with x along their link), placed in turn and held still"),
        "spots": Param(3, 1, 100, "column=1: targets the placements visit in turn (1: the "
                       "same spot every time)"),
        "hold": Param(3.0, 0.2, 3600.0, "column=1: seconds each placement is held still"),
        "transition": Param(2.0, 0.2, 600.0, "column=1: seconds moving between placements"),
        "scatter": Param(0.2, 0.0, 10.0, "column=1: SD of each joint's placement about its "
                         "target, degrees"),
    }
    accel_fs_g = 8
    gyro_fs_dps = 2000
    LINK_LENGTH_M: ClassVar[tuple[float, float]] = (0.2, 0.35)
    CALIBRATED_ACCEL_BIAS: ClassVar[float] = 0.1
    """Accelerometer bias left by a calibration, as a fraction of the raw unit's (2 of 20 mg)."""
    LEVER_STEP_S: ClassVar[float] = 5e-4
    """Step of the central difference that gives the lever arms' acceleration."""
    COLUMN_ONLY: ClassVar[tuple[str, ...]] = ("spots", "hold", "transition", "scatter")
    COLUMN_HINGE_AXIS: ClassVar[tuple[float, float, float]] = (0.0, -1.0, 0.0)
    """``column=1``: every hinge's axis in the previous link's frame (positive raises a link
    running along +x; the app's :data:`app.core.arm.layout.PITCH_UP`)."""
    COLUMN_TARGETS_DEG: ClassVar[tuple[tuple[float, float], ...]] = (
        (-180.0, 180.0), (10.0, 60.0), (-110.0, -20.0))
    """``column=1``: ranges of the targets' theta, upper-arm angle and further hinges' angles."""

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        p = self.params
        links = int(p["links"])
        if not 0 <= int(p["sensor"]) < links:
            raise ValueError(f"arm: sensor={p['sensor']} but the arm has links 0 to {links - 1}")
        if not p["joint_min"] < p["joint_max"]:
            raise ValueError("arm: joint_min must be below joint_max")
        placing = sorted(set(params) & set(self.COLUMN_ONLY))
        if placing and not p["column"]:
            raise ValueError(f"arm: {', '.join(placing)} place a column arm: add column=1")
        rng = self.rng
        level = float(p["level"])
        rotation = np.radians(_between(*Handheld.ROTATION_DEG, level)) * float(p["base"])
        band = _between(Handheld.BAND_HZ[0], Handheld.BAND_HZ[1], level)
        rotation_band = _between(Handheld.ROTATION_BAND_HZ[0], Handheld.ROTATION_BAND_HZ[1], level)
        self.hand = HandMotion(
            rng,
            band_hz=(float(band[0]), float(band[1])),
            accel_rms=np.full(3, float(_between(*Handheld.ACCEL_RMS, level)) / math.sqrt(3.0)),
            rotation_band_hz=(float(rotation_band[0]), float(rotation_band[1])),
            rotation=np.maximum(rotation, 1e-6),
            coupling=0.0,
            jitter=np.full(3, math.radians(float(_between(*Handheld.JITTER_DPS, level)))),
            breaks=RestBreaks(p["move"], p["rest"]),
        )
        self.base_yaw_deg = float(rng.uniform(-180.0, 180.0))
        """The base's x axis, counter-clockwise from magnetic east (the earth frame's x)."""
        self.base_quat = quaternion_from_roll_pitch(0.0, 0.0, self.base_yaw_deg)
        self.links = links
        self.sensor = int(p["sensor"])
        self.axes = np.array([_random_unit(rng) for _ in range(links - 1)])
        """(links-1, 3) hinge k's axis in the frame of link k-1 (and of link k)."""
        self.mountings = np.array([_random_rotation(rng) for _ in range(links)])
        """(links, 4) sensor k's frame in link k's frame (sensor-to-link quaternions)."""
        lengths = rng.uniform(*self.LINK_LENGTH_M, size=links)
        self.hinge_offsets = np.array([_random_unit(rng) * length for length in lengths])
        """(links, 3) from joint k (the grip for k = 0) to joint k+1, link k's frame, m."""
        self.sensor_offsets = np.array(
            [o * rng.uniform(0.3, 0.7) + 0.02 * rng.normal(size=3) for o in self.hinge_offsets]
        )
        self._joint_mid = math.radians(0.5 * (p["joint_min"] + p["joint_max"]))
        self._joint_half = math.radians(0.5 * (p["joint_max"] - p["joint_min"]))
        self._joint_sines = [
            _flat_band(rng, 6, (0.03, float(p["joint_band"])), np.full(3, 0.9), 0)
            for _ in range(links - 1)
        ]
        self._joint_offsets = rng.normal(scale=0.4, size=links - 1)
        self.column = bool(p["column"])
        if self.column:
            self._setup_column(rng, lengths)

    # -- column=1: the JAMRIS arm, placed -------------------------------------------------------
    def _setup_column(self, rng: np.random.Generator, lengths: np.ndarray) -> None:
        p = self.params
        self.axes = np.tile(np.array(self.COLUMN_HINGE_AXIS), (self.links - 1, 1))
        self.mountings = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (self.links, 1))
        self.hinge_offsets = np.column_stack([lengths, np.zeros((self.links, 2))])
        self.sensor_offsets = self.hinge_offsets * 0.5
        self.link_lengths_m = lengths
        spots = int(p["spots"])
        self._targets = np.column_stack([
            rng.uniform(*self.COLUMN_TARGETS_DEG[0], size=spots),
            rng.uniform(*self.COLUMN_TARGETS_DEG[1], size=spots),
            *(rng.uniform(*self.COLUMN_TARGETS_DEG[2], size=spots)
              for _ in range(self.links - 1)),
        ])
        """(spots, links + 1) theta, the upper arm's and each hinge's target angle, degrees."""
        self._scatter_key = int(rng.integers(2**62))

    @property
    def base_azimuth_deg(self) -> float:
        """The base's x axis as a compass reads it: clockwise from magnetic north, 0-360."""
        return float((90.0 - self.base_yaw_deg) % 360.0)

    def placement_deg(self, index: int) -> np.ndarray:
        """(links + 1,) placement ``index``'s angles: theta, upper arm, every hinge (degrees)."""
        target = self._targets[index % len(self._targets)]
        scatter = float(self.params["scatter"])
        noise = np.random.default_rng([self._scatter_key, index]).normal(size=len(target))
        return target + scatter * noise

    def placement_windows(self, count: int) -> list[tuple[float, float]]:
        """The first ``count`` placements' holds, (start, end) in true seconds."""
        step = float(self.params["hold"] + self.params["transition"])
        return [(k * step, k * step + float(self.params["hold"])) for k in range(count)]

    def _column_angles(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, links + 1) theta, upper arm, hinges (rad) and their rates at true times ``t``."""
        hold = float(self.params["hold"])
        step = hold + float(self.params["transition"])
        index = np.maximum(np.floor(t / step), 0.0).astype(np.int64)
        s, ds, _ = smootherstep((np.maximum(t, 0.0) - index * step - hold) / (step - hold))
        angles = np.empty((len(t), self.links + 1))
        rates = np.empty_like(angles)
        for k in np.unique(index):
            rows = index == k
            a = np.radians(self.placement_deg(int(k)))
            b = np.radians(self.placement_deg(int(k) + 1))
            angles[rows] = a + (b - a) * s[rows, None]
            rates[rows] = (b - a) * (ds[rows, None] / (step - hold))
        return angles, rates

    def column_angles_deg(self, t: np.ndarray) -> np.ndarray:
        """``column=1``: (N, links + 1) true theta (the column's turn, counter-clockwise seen
        from above, from the base's x axis), the upper arm's and every hinge's angle, degrees."""
        return np.degrees(self._column_angles(np.asarray(t, dtype=np.float64))[0])

    # -- the truth a joint-angle estimator seeks ------------------------------------------------
    def joint_angles(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, links-1) true joint angles (rad) and their rates (rad/s) at times ``t``."""
        t = np.asarray(t, dtype=np.float64)
        if self.column:
            angles_all, rates_all = self._column_angles(t)
            return angles_all[:, 2:], rates_all[:, 2:]
        angles = np.empty((len(t), self.links - 1))
        rates = np.empty_like(angles)
        for k, sines in enumerate(self._joint_sines):
            s, s_dot = sines.evaluate(t)
            th = np.tanh(s[:, 0] + self._joint_offsets[k])
            angles[:, k] = self._joint_mid + self._joint_half * th
            rates[:, k] = self._joint_half * (1.0 - th * th) * s_dot[:, 0]
        return angles, rates

    def joint_angles_deg(self, t: np.ndarray) -> np.ndarray:
        """(N, links-1) true joint angles in degrees."""
        return np.degrees(self.joint_angles(t)[0])

    def axis_in_sensor(self, joint: int, sensor: int) -> np.ndarray:
        """Hinge ``joint``'s axis (1 ... links-1) in sensor ``sensor``'s frame."""
        if sensor not in (joint - 1, joint):
            raise ValueError(f"hinge {joint} joins sensors {joint - 1} and {joint}, not {sensor}")
        return quat.rotate_inverse(self.mountings[sensor], self.axes[joint - 1])

    def unit_errors(self, seed: int) -> UnitErrors:
        """Sensor ``sensor``'s own unit (biases within +-``bias`` dps) on the arm's clock."""
        digest = hashlib.blake2b(f"arm:{seed}:{self.sensor}".encode(), digest_size=7).digest()
        unit = UnitErrors.draw(int.from_bytes(digest, "big"))
        clock = UnitErrors.draw(seed)
        scale = math.radians(float(self.params["bias"])) / GYRO_BIAS_LIMIT_RAD_S
        unit = replace(
            unit, gyro_bias_rad_s=unit.gyro_bias_rad_s * scale,
            freq_fine=clock.freq_fine, clock_residual=clock.clock_residual,
        )
        if not self.params["calibrated"]:
            return unit
        zero, none = np.zeros(3), np.zeros((3, 3))
        return replace(
            unit, accel_scale_error=zero, accel_cross_axis=none, gyro_scale_error=zero,
            gyro_cross_axis=none, accel_scale_tc_per_degc=zero, gyro_scale_tc_per_degc=zero,
            accel_bias_m_s2=unit.accel_bias_m_s2 * self.CALIBRATED_ACCEL_BIAS,
        )

    # -- motion ---------------------------------------------------------------------------------
    def _chain(
        self, t: np.ndarray, with_rate: bool
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """The sensor's link's orientation (N, 4), body rate (N, 3) or None, and the lever from
        the grip to the sensor (N, 3, earth frame)."""
        if self.column:  # the base stands; the column turns, the upper arm is raised
            column, column_rates = self._column_angles(t)
            q = np.broadcast_to(self.base_quat, (len(t), 4))
            rate = np.zeros((len(t), 3))
            for k, axis in ((0, np.array([0.0, 0.0, 1.0])),
                            (1, np.array(self.COLUMN_HINGE_AXIS))):
                q_turn = quat.from_axis_angle(axis, column[:, k])
                if with_rate:
                    q, rate = compose(q, rate, q_turn, column_rates[:, k, None] * axis)
                else:
                    q = quat.multiply(q, q_turn)
        else:
            q_hand, rate, _ = self.hand.evaluate(t)
            q = quat.multiply(self.base_quat, q_hand)
        angles, angle_rates = self.joint_angles(t)
        lever = np.zeros((len(t), 3))
        for k in range(self.sensor):
            lever += quat.rotate(q, self.hinge_offsets[k])
            axis = self.axes[k]
            q_joint = quat.from_axis_angle(axis, angles[:, k])
            if with_rate:
                q, rate = compose(q, rate, q_joint, angle_rates[:, k, None] * axis)
            else:
                q = quat.multiply(q, q_joint)
        lever += quat.rotate(q, self.sensor_offsets[self.sensor])
        return q, (rate if with_rate else None), lever

    def motion(self, t: np.ndarray) -> Motion:
        t = np.asarray(t, dtype=np.float64)
        q_link, rate, lever = self._chain(t, True)
        h = self.LEVER_STEP_S
        lever_plus = self._chain(t + h, False)[2]
        lever_minus = self._chain(t - h, False)[2]
        accel = (lever_plus - 2.0 * lever + lever_minus) / (h * h)
        if not self.column:
            accel += self.hand.evaluate(t)[2]
        mounting = self.mountings[self.sensor]
        assert rate is not None
        q_sensor, rate_sensor = compose(q_link, rate, np.broadcast_to(mounting, q_link.shape),
                                        np.zeros_like(rate))
        return Motion(q_sensor, rate_sensor, accel)


class Tour(Scenario):
    """The six calibration orientations in turn, each held still, with smooth turns between."""

    name = "tour"
    description = "tour of the six calibration orientations"
    parameters: ClassVar[dict[str, Param]] = {
        "hold": Param(6.0, 0.0, 3600.0, "time held still in each orientation, seconds"),
        "transition": Param(2.0, 0.05, 60.0, "time to turn to the next orientation, seconds"),
    }
    FACES: ClassVar[tuple[str, ...]] = ("+z", "-z", "+x", "-x", "+y", "-y")
    """Which sensor axis points up in each held orientation, in tour order."""
    _FACE_ROLL_PITCH: ClassVar[tuple[tuple[float, float], ...]] = (
        (0.0, 0.0),
        (180.0, 0.0),
        (0.0, 90.0),
        (0.0, -90.0),
        (90.0, 0.0),
        (-90.0, 0.0),
    )

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        roll, pitch = np.array(self._FACE_ROLL_PITCH).T
        self.face_quats = quaternion_from_roll_pitch(roll, pitch)
        following = np.roll(self.face_quats, -1, axis=0)
        self._turns = quat.to_rotation_vector(
            quat.multiply(quat.conjugate(self.face_quats), following)
        )

    def _phase(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        step = self.params["hold"] + self.params["transition"]
        k = np.floor(t / step)
        return k.astype(np.int64) % len(self.FACES), t - k * step

    def face_at(self, t: np.ndarray) -> np.ndarray:
        """Index into :attr:`FACES` of the orientation held at each time, -1 while turning."""
        face, within = self._phase(np.asarray(t, dtype=np.float64))
        return np.where(within < self.params["hold"], face, -1)

    def motion(self, t: np.ndarray) -> Motion:
        face, within = self._phase(t)
        duration = self.params["transition"]
        s, ds_dx = smoothstep((within - self.params["hold"]) / duration)
        turn = self._turns[face]
        q = quat.multiply(self.face_quats[face], quat.from_rotation_vector(turn * s[:, None]))
        # Slerp about a fixed axis: the body rate is the turn vector times ds/dt.
        rate = turn * (ds_dx / duration)[:, None]
        return Motion(q, rate, np.zeros((len(t), 3)))


class MagTour(Scenario):
    """A magnetometer calibration tour: the board turned through every direction.

    ``turns`` orientations picked from random ones (the seed's, or ``path``'s) so that every
    earth-fixed direction (the field, gravity) spreads over the sensor's sphere, each held for
    ``hold`` s, reached by smooth turns about a fixed axis (as :class:`Tour`), then the same
    again: the field's direction in the sensor frame covers all of it, and the board lies at
    every tilt, for a calibration that uses gravity too.
    """

    name = "magtour"
    description = "magnetometer calibration tour: turned through every direction"
    parameters: ClassVar[dict[str, Param]] = {
        "turns": Param(40, 4, 1000, "orientations in one round of the tour"),
        "hold": Param(0.3, 0.0, 3600.0, "time held still in each orientation, seconds"),
        "transition": Param(2.0, 0.2, 60.0, "time to turn to the next orientation, seconds"),
        "path": Param(0, 0, 2**31 - 1, "which tour: 0 one picked by the seed, others a tour "
                      "of their own (the same unit on another tour: data a fit never saw)"),
    }
    magnetometer = "lis3mdl"
    STREAM_PATH: ClassVar[int] = 31
    POOL: ClassVar[int] = 3000
    """Random orientations the tour's are picked from."""

    @staticmethod
    def _spread(pool: np.ndarray, count: int) -> np.ndarray:
        """``count`` of ``pool``'s orientations, each next one the farthest from those picked:
        farthest in the sensor frame for all three earth axes at once (the least of the three
        distances), so any earth-fixed direction, the field's at any dip, spreads over the
        sensor's sphere (16-27 degrees at most from every direction on seeds 1-8, instead of
        22-34 for the random ones)."""
        images = [quat.rotate_inverse(pool, axis) for axis in np.eye(3)]
        nearest = np.full((3, len(pool)), 4.0)
        picked = [0]
        for _ in range(count - 1):
            for axis, image in enumerate(images):
                np.minimum(nearest[axis], 1.0 - image @ image[picked[-1]], out=nearest[axis])
            picked.append(int(np.argmax(nearest.min(axis=0))))
        return pool[picked]

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        count = int(self.params["turns"])
        path = int(self.params["path"])
        draw = self.rng if path == 0 else np.random.default_rng([path, self.STREAM_PATH])
        self.orientations = self._spread(quat.normalize(draw.normal(size=(self.POOL, 4))), count)
        """(turns, 4) the held orientations (sensor to earth), in tour order."""
        following = np.roll(self.orientations, -1, axis=0)
        self._turns = quat.to_rotation_vector(
            quat.multiply(quat.conjugate(self.orientations), following))

    @property
    def round_s(self) -> float:
        """Duration of one round through every orientation, seconds."""
        return len(self.orientations) * (self.params["hold"] + self.params["transition"])

    def _phase(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        step = self.params["hold"] + self.params["transition"]
        k = np.floor(t / step)
        return k.astype(np.int64) % len(self.orientations), t - k * step

    def motion(self, t: np.ndarray) -> Motion:
        index, within = self._phase(t)
        duration = self.params["transition"]
        s, ds_dx = smoothstep((within - self.params["hold"]) / duration)
        turn = self._turns[index]
        q = quat.multiply(self.orientations[index], quat.from_rotation_vector(turn * s[:, None]))
        rate = turn * (ds_dx / duration)[:, None]
        return Motion(q, rate, np.zeros((len(t), 3)))


class Interactive(Scenario):
    """Tilted from the GUI: the attitude glides smoothly to each new target.

    A glide from ``q0`` to a target ``q1 = q0 exp(turn)`` follows ``q0 exp(phi(x))``, with
    ``x`` = elapsed / duration in [0, 1] and the cubic Hermite curve
    ``phi = turn (3x^2 - 2x^3) + duration * rate0 (x^3 - 2x^2 + x)``: with no motion at the
    start (``rate0 = 0``) this is a slerp with a smoothstep; a new target that arrives during a
    glide keeps the current angular rate ``rate0``, so the rate never jumps (rapid targets, as
    from a dragged slider, give a smooth, slightly underdamped follow). The glide time grows
    with the angle, from 0.3 s to 1.5 s for a half turn.

    Not thread-safe by itself: :class:`drivers.sim.device.SimulatedDevice` serialises
    :meth:`set_target` with sample generation.
    """

    name = "interactive"
    description = "tilt it yourself from the GUI"
    parameters: ClassVar[dict[str, Param]] = {
        **_tilt(1.5, -0.8, yaw=0.0),
        "jitter": Param(False, doc="add the hand-held tremor of sim://wobble"),
    }
    MIN_GLIDE_S: ClassVar[float] = 0.3
    MAX_GLIDE_S: ClassVar[float] = 1.5
    MAX_SEGMENTS: ClassVar[int] = 64

    def __init__(self, rng: np.random.Generator | None = None, **params: float) -> None:
        super().__init__(rng, **params)
        p = self.params
        start = quaternion_from_roll_pitch(p["roll"], p["pitch"], p["yaw"])
        self.target_quat = start
        # Glide segments sorted by start time (s): from-quaternion, turn and start rate
        # (rotation vectors, rad and rad/s) and duration (s).
        self._starts = np.zeros(1)
        self._froms = start[None, :].copy()
        self._turns = np.zeros((1, 3))
        self._rates = np.zeros((1, 3))
        self._durations = np.ones(1)
        wobble = Wobble.parameters
        self.tremor = (
            Tremor(self.rng, wobble["amplitude"].default, wobble["shake"].default)
            if p["jitter"]
            else None
        )

    @classmethod
    def glide_duration_s(cls, angle_rad: float) -> float:
        """How long a turn by ``angle_rad`` takes: 0.3 s growing to 1.5 s for a half turn."""
        fraction = min(abs(angle_rad) / math.pi, 1.0)
        return cls.MIN_GLIDE_S + (cls.MAX_GLIDE_S - cls.MIN_GLIDE_S) * fraction

    def set_target(self, t_start: float, target_quat: np.ndarray) -> float:
        """Glide from the state at ``t_start`` to ``target_quat``; returns the glide time (s).

        ``t_start`` must not precede samples already generated.
        """
        q_now, rate_now = self._path(np.array([float(t_start)]))
        target = np.asarray(target_quat, dtype=np.float64)
        turn = quat.to_rotation_vector(quat.multiply(quat.conjugate(q_now[0]), target))
        duration = self.glide_duration_s(float(np.linalg.norm(turn)))
        keep = self._starts < t_start
        keep[: max(0, int(keep.sum()) - self.MAX_SEGMENTS)] = False
        self._starts = np.append(self._starts[keep], float(t_start))
        self._froms = np.vstack([self._froms[keep], q_now])
        self._turns = np.vstack([self._turns[keep], turn])
        self._rates = np.vstack([self._rates[keep], rate_now])
        self._durations = np.append(self._durations[keep], duration)
        self.target_quat = target
        return duration

    def _path(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        seg = np.clip(np.searchsorted(self._starts, t, side="right") - 1, 0, None)
        duration = self._durations[seg][:, None]
        x = np.clip((t[:, None] - self._starts[seg][:, None]) / duration, 0.0, 1.0)
        turn = self._turns[seg]
        rate0 = self._rates[seg]
        phi = turn * (x * x * (3.0 - 2.0 * x)) + rate0 * (duration * x * (x - 1.0) ** 2)
        phi_dot = turn * (6.0 * x * (1.0 - x) / duration) + rate0 * ((3.0 * x - 1.0) * (x - 1.0))
        q = quat.multiply(self._froms[seg], quat.from_rotation_vector(phi))
        return q, rate_of_rotation_vector(phi, phi_dot)

    def motion(self, t: np.ndarray) -> Motion:
        q, rate = self._path(t)
        if self.tremor is None:
            return Motion(q, rate, np.zeros((len(t), 3)))
        q_tremor, rate_tremor, accel = self.tremor.evaluate(t)
        q, rate = compose(q, rate, q_tremor, rate_tremor)
        return Motion(q, rate, accel)


SCENARIOS: dict[str, type[Scenario]] = {
    cls.name: cls
    for cls in (
        Static, SlowTilt, Wobble, Vibration, Translation, Handheld, Strokes, Arm, Tour,
        MagTour, Interactive,
    )
}
"""URL name -> scenario class (``cls.description``: one line for the user), in display order."""
