"""Allan deviation of a static record, and the sensor noise figures read from it.

The deviation itself is ``allantools.oadev`` (overlapping Allan deviation; a maintained
library, not hand-written code). On top of it this module fits the classic noise model per
axis (IEEE Std 952, Annex C) to the Allan *variance*::

    AVAR(tau) = N^2 / (2 tau)  +  (0.664 B)^2  +  K^2 tau / 3

- ``N``, the **noise density** (white noise), in the datasheet's one-sided convention: one
  sample at rate ``fs`` scatters by ``N sqrt(fs / 2)``, as in the simulator and the EKF's
  ``gyro_noise`` (so ``adev(1 s) = N / sqrt(2)`` on the -1/2 slope);
- ``B``, the **bias instability**: the flicker floor ``0.664 B``. It is reported as the
  minimum of the fitted curve divided by 0.664 (the usual read-off of the plot's bottom), so
  it is meaningful also when the floor is only where white noise meets the random walk;
- ``K``, the **random walk** of the bias (rate random walk for the gyroscope): the bias
  moves by ``K sqrt(t)`` in ``t`` seconds, as the simulator's ``bias_walk_..._per_sqrt_s`` and
  the EKF's ``bias_drift``.

The fit is a weighted linear least squares in the three non-negative coefficients (every
subset of terms is tried and the best non-negative one kept); each point's weight is the
square root of its number of independent clusters over its (modelled) variance, so that long,
poorly known taus count less; the weights come from the previous pass's model rather than from
the measured points, which would favour the points that happen to lie low.

A warming board drifts with temperature far more than its bias walks (0.01 dps/degC against
a few deg/h): :func:`remove_temperature_trend` subtracts, per axis, the part of the signal that
is a quadratic function of the temperature before the deviation is computed.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

FLICKER_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
"""0.664: Allan deviation of flicker (bias instability) noise per unit of B."""
POINTS_PER_DECADE = 10
MIN_CLUSTERS = 3
"""The longest tau keeps at least this many non-overlapping clusters (T / tau)."""
TEMPERATURE_WINDOW_S = 10.0
"""Window of the means whose differences give the temperature slopes."""
MIN_TEMPERATURE_SPAN_DEGC = 0.2
"""A temperature that moves less than this is not regressed out."""
AXES = "xyz"
FIT_ITERATIONS = 4
"""Reweighting passes of the fit (weights from the model, not from the noisy points)."""


@dataclass(frozen=True)
class AxisNoise:
    """Noise figures of one axis and its Allan deviation.

    Units are the signal's (rad/s or m/s^2): ``noise_density`` per sqrt(Hz),
    ``bias_instability`` plain, ``random_walk`` per sqrt(s).
    """

    noise_density: float
    bias_instability: float
    random_walk: float
    tau_s: np.ndarray
    adev: np.ndarray
    clusters: np.ndarray
    coefficients: np.ndarray
    """(3,) fitted ``N^2/2``, ``(0.664 B)^2``, ``K^2/3``: AVAR = c0/tau + c1 + c2 tau."""

    def model_adev(self, tau_s: np.ndarray) -> np.ndarray:
        tau = np.asarray(tau_s, dtype=np.float64)
        c = self.coefficients
        return np.sqrt(c[0] / tau + c[1] + c[2] * tau)

    def white_line(self, tau_s: np.ndarray) -> np.ndarray:
        """The -1/2 slope line of the noise density."""
        return self.noise_density / np.sqrt(2.0 * np.asarray(tau_s, dtype=np.float64))

    def walk_line(self, tau_s: np.ndarray) -> np.ndarray:
        """The +1/2 slope line of the random walk."""
        return self.random_walk * np.sqrt(np.asarray(tau_s, dtype=np.float64) / 3.0)

    def floor_line(self, tau_s: np.ndarray) -> np.ndarray:
        """The flat line at ``0.664 B``."""
        return np.full(np.shape(tau_s), FLICKER_FACTOR * self.bias_instability)


@dataclass(frozen=True)
class SensorNoiseFigures:
    """Three axes of one sensor (gyroscope in rad/s, accelerometer in m/s^2)."""

    axes: tuple[AxisNoise, AxisNoise, AxisNoise]

    @property
    def noise_density(self) -> np.ndarray:
        return np.array([a.noise_density for a in self.axes])

    @property
    def bias_instability(self) -> np.ndarray:
        return np.array([a.bias_instability for a in self.axes])

    @property
    def random_walk(self) -> np.ndarray:
        return np.array([a.random_walk for a in self.axes])

    @property
    def tau_s(self) -> np.ndarray:
        return self.axes[0].tau_s

    def to_json(self) -> dict[str, Any]:
        """The binding form: figures [3], ``tau_s`` [...], ``adev`` [[...] x 3]."""
        return {
            "noise_density": self.noise_density.tolist(),
            "bias_instability": self.bias_instability.tolist(),
            "random_walk": self.random_walk.tolist(),
            "tau_s": self.tau_s.tolist(),
            "adev": [a.adev.tolist() for a in self.axes],
        }


@dataclass(frozen=True)
class AllanResult:
    """The Allan analysis of a static record."""

    gyro: SensorNoiseFigures
    accel: SensorNoiseFigures
    rate_hz: float
    duration_s: float
    samples: int
    temperature_span_degc: float
    temperature_removed: bool
    gyro_slopes_per_degc: np.ndarray
    """(3,) the temperature slopes removed (zeros when none were)."""
    accel_slopes_per_degc: np.ndarray

    def to_json(self) -> dict[str, Any]:
        return {
            "gyro": self.gyro.to_json(),
            "accel": self.accel.to_json(),
            "rate_hz": self.rate_hz,
            "duration_s": self.duration_s,
            "samples": self.samples,
            "temperature_span_degc": (self.temperature_span_degc
                                      if math.isfinite(self.temperature_span_degc) else None),
            "temperature_removed": self.temperature_removed,
            "gyro_temperature_slope_rad_s_per_degc": self.gyro_slopes_per_degc.tolist(),
            "accel_temperature_slope_m_s2_per_degc": self.accel_slopes_per_degc.tolist(),
        }


def tau_grid(n: int, rate_hz: float, points_per_decade: int = POINTS_PER_DECADE) -> np.ndarray:
    """Log-spaced averaging times from one sample to ``n / MIN_CLUSTERS`` samples (distinct)."""
    longest = max(1, n // MIN_CLUSTERS)
    decades = math.log10(longest)
    m = np.unique(np.round(np.logspace(0.0, decades, max(2, round(decades * points_per_decade)
                                                          + 1))).astype(np.int64))
    return m / rate_hz


def allan_deviation(x: np.ndarray, rate_hz: float, taus: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(tau_s, adev, clusters)`` of a rate signal ``x`` (N,) by ``allantools.oadev``.

    ``clusters`` is ``T / tau``, the number of independent averages behind each point.
    """
    import allantools

    x = np.asarray(x, dtype=np.float64)
    if taus is None:
        taus = tau_grid(len(x), rate_hz)
    tau, adev, _, _ = allantools.oadev(x, rate=rate_hz, data_type="freq", taus=taus)
    tau = np.asarray(tau, dtype=np.float64)
    clusters = len(x) / rate_hz / tau
    return tau, np.asarray(adev, dtype=np.float64), clusters


def fit_noise_model(tau_s: np.ndarray, adev: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """Non-negative ``(c0, c1, c2)`` of ``AVAR = c0/tau + c1 + c2 tau`` (see module doc)."""
    tau = np.asarray(tau_s, dtype=np.float64)
    avar = np.asarray(adev, dtype=np.float64) ** 2
    good = np.isfinite(avar) & (avar > 0)
    tau, avar, n = tau[good], avar[good], np.asarray(clusters, dtype=np.float64)[good]
    if len(tau) < 3:
        raise ValueError("too few Allan deviation points for a fit (record longer)")
    scale = np.sqrt(np.maximum(n, 1.0))
    expected = avar  # the first pass weighs by the measured values, later ones by the model
    best = np.zeros(3)
    for _ in range(FIT_ITERATIONS):
        weight = scale / expected
        design = np.column_stack([1.0 / tau, np.ones_like(tau), tau]) * weight[:, None]
        target = avar * weight
        best, best_cost = np.zeros(3), math.inf
        for size in (3, 2, 1):
            for terms in itertools.combinations(range(3), size):
                cols = list(terms)
                solution, *_ = np.linalg.lstsq(design[:, cols], target, rcond=None)
                if np.any(solution < 0.0):
                    continue
                coefficients = np.zeros(3)
                coefficients[cols] = solution
                cost = float(np.sum((design @ coefficients - target) ** 2))
                if cost < best_cost:
                    best, best_cost = coefficients, cost
        model = best[0] / tau + best[1] + best[2] * tau
        if not np.all(model > 0):
            break
        expected = model
    return best


def axis_noise(x: np.ndarray, rate_hz: float, taus: np.ndarray | None = None) -> AxisNoise:
    """Allan deviation and noise figures of one axis (see the module docstring)."""
    tau, adev, clusters = allan_deviation(x, rate_hz, taus)
    c = fit_noise_model(tau, adev, clusters)
    dense = np.logspace(math.log10(tau[0]), math.log10(tau[-1]), 200)
    model = np.sqrt(c[0] / dense + c[1] + c[2] * dense)
    return AxisNoise(
        noise_density=math.sqrt(2.0 * c[0]),
        bias_instability=float(model.min()) / FLICKER_FACTOR,
        random_walk=math.sqrt(3.0 * c[2]),
        tau_s=tau, adev=adev, clusters=clusters, coefficients=c,
    )


def temperature_slopes(x: np.ndarray, temp_degc: np.ndarray, rate_hz: float,
                       window_s: float = TEMPERATURE_WINDOW_S) -> np.ndarray:
    """(k,) ``d x / d T`` per column of ``x`` (N, k), from differences of window means.

    Differencing first makes the estimate blind to a random walk (its increments are white),
    so removing ``slope (T - mean T)`` leaves the walk for the Allan fit; a plain regression
    of ``x`` on ``T`` would take the walk's share along a monotone warm-up with it.
    """
    x = np.asarray(x, dtype=np.float64).reshape(len(temp_degc), -1)
    t = np.asarray(temp_degc, dtype=np.float64)
    size = max(1, round(window_s * rate_hz))
    count = len(t) // size
    if count < 3:
        return np.zeros(x.shape[1])
    x_means = x[: count * size].reshape(count, size, -1).mean(axis=1)
    t_means = t[: count * size].reshape(count, size).mean(axis=1)
    dt = np.diff(t_means)
    dx = np.diff(x_means, axis=0)
    denominator = float(dt @ dt)
    if denominator <= 0.0:
        return np.zeros(x.shape[1])
    return (dt @ dx) / denominator


def remove_temperature_trend(x: np.ndarray, temp_degc: np.ndarray, rate_hz: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """``x`` (N, k) minus ``slope (T - mean T)`` per column, and the slopes (k,)."""
    x = np.asarray(x, dtype=np.float64)
    t = np.asarray(temp_degc, dtype=np.float64)
    slopes = temperature_slopes(x, t, rate_hz)
    return x - np.outer(t - t.mean(), slopes), slopes


def analyse_static(
    gyro_rad_s: np.ndarray,
    accel_m_s2: np.ndarray,
    rate_hz: float,
    temp_degc: np.ndarray | None = None,
    remove_temperature: bool = True,
) -> AllanResult:
    """The Allan analysis of a static record (N, 3) + (N, 3) sampled at ``rate_hz``."""
    gyro = np.asarray(gyro_rad_s, dtype=np.float64).reshape(-1, 3)
    accel = np.asarray(accel_m_s2, dtype=np.float64).reshape(-1, 3)
    n = len(gyro)
    if n < 100 or not math.isfinite(rate_hz) or rate_hz <= 0:
        raise ValueError(f"{n} samples: record at least a few minutes at rest")
    span = math.nan
    removed = False
    gyro_slopes = accel_slopes = np.zeros(3)
    if temp_degc is not None:
        temp = np.asarray(temp_degc, dtype=np.float64)
        if np.all(np.isfinite(temp)):
            span = float(np.ptp(temp))
            if remove_temperature and span >= MIN_TEMPERATURE_SPAN_DEGC:
                gyro, gyro_slopes = remove_temperature_trend(gyro, temp, rate_hz)
                accel, accel_slopes = remove_temperature_trend(accel, temp, rate_hz)
                removed = True
    taus = tau_grid(n, rate_hz)

    def figures(data: np.ndarray) -> SensorNoiseFigures:
        axes = tuple(axis_noise(data[:, k], rate_hz, taus) for k in range(3))
        return SensorNoiseFigures(axes)  # type: ignore[arg-type]

    return AllanResult(
        gyro=figures(gyro), accel=figures(accel), rate_hz=float(rate_hz),
        duration_s=n / rate_hz, samples=n, temperature_span_degc=span,
        temperature_removed=removed, gyro_slopes_per_degc=gyro_slopes,
        accel_slopes_per_degc=accel_slopes,
    )


# -- filter tuning ---------------------------------------------------------------------------------
NOISE_PARAMETERS: dict[str, tuple[str, str, float]] = {
    "gyro_noise": ("gyro", "noise_density", math.degrees(1.0) * 1e3),  # rad/s/rtHz -> mdps/rtHz
    "bias_drift": ("gyro", "random_walk", math.degrees(1.0) * 1e3),  # rad/s/rts -> mdps/rts
    "accel_noise": ("accel", "noise_density", 1e6 / 9.80665),  # m/s^2/rtHz -> ug/rtHz
}
"""Filter parameters that are sensor noise figures: name -> (sensor, figure, SI-to-unit)."""


MIN_WALK_RECORD_S = 1800.0
"""A random walk from a shorter record is too rough to set a filter's bias drift."""


def filter_noise_parameters(result: AllanResult, filters: dict[str, Any]
                            ) -> dict[str, dict[str, float]]:
    """``{filter: {parameter: value}}`` for every filter that has a noise-figure parameter.

    Each value is the axes' mean (the filters take one figure for all three axes), in the
    parameter's unit, clamped to its range. A figure the data could not resolve (a random walk
    of zero, or from under :data:`MIN_WALK_RECORD_S`) is left out, keeping the filter's value.
    """
    out: dict[str, dict[str, float]] = {}
    for name, cls in filters.items():
        for spec in getattr(cls, "parameters", ()):
            mapping = NOISE_PARAMETERS.get(spec.name)
            if mapping is None:
                continue
            sensor, figure, factor = mapping
            if figure == "random_walk" and result.duration_s < MIN_WALK_RECORD_S:
                continue
            value = float(np.mean(getattr(getattr(result, sensor), figure))) * factor
            if not math.isfinite(value) or value <= 0.0:
                continue
            out.setdefault(name, {})[spec.name] = min(max(value, spec.minimum), spec.maximum)
    return out
