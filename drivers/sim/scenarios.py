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

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from app.core import quaternion as quat
from app.core.orientation import quaternion_from_roll_pitch
from app.core.samples import STANDARD_GRAVITY_M_S2

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


def _sin_cos(arg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 sine and cosine of float64 angles, reduced exactly to [-pi, pi] first.

    Four times faster than float64 trigonometry; the relative error, about 1e-7, is far
    below what the sensor resolves. ``arg`` is overwritten.
    """
    turns = np.rint(arg * (1.0 / _TWO_PI))
    turns *= _TWO_PI
    arg -= turns
    arg32 = arg.astype(np.float32)
    return np.sin(arg32), np.cos(arg32)


class MultiSine:
    """Per axis a sum of sines, ``v_i(t) = sum_k a_ik sin(2 pi f_ik t + p_ik)``, arrays (3, K)."""

    def __init__(self, amplitudes: np.ndarray, freqs_hz: np.ndarray, phases_rad: np.ndarray):
        amplitudes = np.asarray(amplitudes, dtype=np.float64)
        omegas = 2.0 * np.pi * np.asarray(freqs_hz, dtype=np.float64)
        self.amplitudes = amplitudes
        self.omegas = omegas
        self.phases = np.asarray(phases_rad, dtype=np.float64)
        # Terms laid out as (3K, N) so numpy's inner loops run along time, and summed per axis
        # by a (3, 3K) block-diagonal matrix product.
        self._omega_col = omegas.reshape(-1, 1)
        self._phase_col = self.phases.reshape(-1, 1)
        mask = np.repeat(np.eye(3), amplitudes.shape[1], axis=1)
        self._value_sum = (mask * amplitudes.reshape(1, -1)).astype(np.float32)
        self._rate_sum = (mask * (amplitudes * omegas).reshape(1, -1)).astype(np.float32)

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
        sin, _ = _sin_cos(self._angles(t))
        return self._per_axis(self._value_sum, sin)

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (N, 3) and their time derivatives (N, 3) at times ``t`` (N,)."""
        sin, cos = _sin_cos(self._angles(t))
        return self._per_axis(self._value_sum, sin), self._per_axis(self._rate_sum, cos)


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


def _tilt(roll: float, pitch: float, yaw: float | None = None) -> dict[str, Param]:
    params = {
        "roll": Param(roll, -180.0, 180.0, "roll angle, degrees"),
        "pitch": Param(pitch, -90.0, 90.0, "pitch angle, degrees"),
    }
    if yaw is not None:
        params["yaw"] = Param(yaw, -180.0, 180.0, "heading, degrees")
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


class Translation(Scenario):
    """Bursts of fast back-and-forth strokes along horizontal directions, at a fixed tilt.

    Each stroke accelerates with ``+A sin`` over its first half (moving out and stopping) and
    ``-A sin`` over its second half (moving back), so the sensor returns to where it started.
    Successive bursts turn by the golden angle.
    """

    name = "translation"
    description = "fast back-and-forth shaking at a fixed tilt"
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
    cls.name: cls for cls in (Static, SlowTilt, Wobble, Vibration, Translation, Tour, Interactive)
}
"""URL name -> scenario class (``cls.description``: one line for the user), in display order."""
