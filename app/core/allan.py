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

**How N and K are estimated** (``method``): by default (``"likelihood"``) from the time series
itself, not from the Allan curve: :func:`fit_white_and_walk` evaluates the exact Gaussian
likelihood of the state-space model white noise + random walk (+ the temperature's residual
slope) on bin means of about 0.4 s, and takes ``K`` as the posterior median under the Jeffreys
prior. A 30-minute record holds only a few independent stretches of a walk that crosses the
white noise after 200-500 s (the gyroscope's), so the Allan fit, which weighs a handful of long
clusters, scatters by far more than the Cramer-Rao bound (:func:`random_walk_bound`); the
likelihood uses every sample and reaches it. The flicker floor ``0.664 B`` is then fitted to
the Allan points with ``N`` and ``K`` held. ``"allan-fit"`` is the older estimator: all three
from the Allan curve, as follows.

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

from app.core.sample_checks import IMPLAUSIBLE_ABS, implausible_rows

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
METHODS = ("likelihood", "allan-fit")
"""How N and K are estimated: the time-domain likelihood (default) or the Allan-curve fit."""
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
    method: str = "allan-fit"
    random_walk_log_sd: float = math.nan
    """About the relative 1-sigma uncertainty of ``random_walk`` (likelihood method only)."""

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

    @property
    def random_walk_log_sd(self) -> np.ndarray:
        return np.array([a.random_walk_log_sd for a in self.axes])

    def to_json(self) -> dict[str, Any]:
        """The binding form: figures [3], ``tau_s`` [...], ``adev`` [[...] x 3]."""
        return {
            "noise_density": self.noise_density.tolist(),
            "bias_instability": self.bias_instability.tolist(),
            "random_walk": self.random_walk.tolist(),
            "tau_s": self.tau_s.tolist(),
            "adev": [a.adev.tolist() for a in self.axes],
            # Optional (not in the binding format): the walk's relative 1-sigma uncertainty.
            "random_walk_log_sd": [v if math.isfinite(v) else None
                                   for v in self.random_walk_log_sd.tolist()],
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
    method: str = "allan-fit"

    def to_json(self) -> dict[str, Any]:
        return {
            "gyro": self.gyro.to_json(),
            "accel": self.accel.to_json(),
            "method": self.method,
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


def fit_floor(tau_s: np.ndarray, adev: np.ndarray, clusters: np.ndarray, white: float,
              walk: float) -> float:
    """The flicker coefficient ``c1 >= 0`` of the Allan variance with ``c0``, ``c2`` held.

    Weighted as :func:`fit_noise_model` (clusters over the model's variance, squared).
    """
    tau = np.asarray(tau_s, dtype=np.float64)
    avar = np.asarray(adev, dtype=np.float64) ** 2
    good = np.isfinite(avar) & (avar > 0)
    tau, avar, n = tau[good], avar[good], np.asarray(clusters, dtype=np.float64)[good]
    floor = 0.0
    for _ in range(FIT_ITERATIONS):
        model = white / tau + floor + walk * tau
        weight = np.maximum(n, 1.0) / np.maximum(model, np.finfo(float).tiny) ** 2
        floor = max(0.0, float(weight @ (avar - white / tau - walk * tau) / weight.sum()))
    return floor


def axis_noise(x: np.ndarray, rate_hz: float, taus: np.ndarray | None = None,
               method: str = "likelihood", regressor: np.ndarray | None = None) -> AxisNoise:
    """Allan deviation and noise figures of one axis (see the module docstring).

    ``regressor`` (the likelihood method only): a signal, such as the temperature, whose
    coefficient is fitted jointly with the noise.
    """
    if method not in METHODS:
        raise ValueError(f"method {method!r}: one of {', '.join(METHODS)}")
    tau, adev, clusters = allan_deviation(x, rate_hz, taus)
    log_sd = math.nan
    if method == "likelihood":
        fit = fit_white_and_walk(x, rate_hz, regressor)
        white, walk = fit.noise_density**2 / 2.0, fit.random_walk**2 / 3.0
        c = np.array([white, fit_floor(tau, adev, clusters, white, walk), walk])
        log_sd = fit.random_walk_log_sd
    else:
        c = fit_noise_model(tau, adev, clusters)
    dense = np.logspace(math.log10(tau[0]), math.log10(tau[-1]), 200)
    model = np.sqrt(c[0] / dense + c[1] + c[2] * dense)
    return AxisNoise(
        noise_density=math.sqrt(2.0 * c[0]),
        bias_instability=float(model.min()) / FLICKER_FACTOR,
        random_walk=math.sqrt(3.0 * c[2]),
        tau_s=tau, adev=adev, clusters=clusters, coefficients=c,
        method=method, random_walk_log_sd=log_sd,
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
    method: str = "likelihood",
) -> AllanResult:
    """The Allan analysis of a static record (N, 3) + (N, 3) sampled at ``rate_hz``.

    With the temperature removed, the likelihood method also fits what is left of its slope.
    """
    gyro = np.asarray(gyro_rad_s, dtype=np.float64).reshape(-1, 3)
    accel = np.asarray(accel_m_s2, dtype=np.float64).reshape(-1, 3)
    n = len(gyro)
    if n < 100 or not math.isfinite(rate_hz) or rate_hz <= 0:
        raise ValueError(f"{n} samples: record at least a few minutes at rest")
    if method not in METHODS:
        raise ValueError(f"method {method!r}: one of {', '.join(METHODS)}")
    if np.any(implausible_rows(gyro, accel)):  # NaN, inf, 1e308: NaN figures or overflow
        raise ValueError("the samples hold values that are not finite or beyond "
                         f"{IMPLAUSIBLE_ABS:g}: not sensor readings")
    span = math.nan
    regressor = None
    gyro_slopes = accel_slopes = np.zeros(3)
    if temp_degc is not None:
        temp = np.asarray(temp_degc, dtype=np.float64)
        if np.all(np.isfinite(temp)):
            span = float(np.ptp(temp))
            if remove_temperature and span >= MIN_TEMPERATURE_SPAN_DEGC:
                gyro, gyro_slopes = remove_temperature_trend(gyro, temp, rate_hz)
                accel, accel_slopes = remove_temperature_trend(accel, temp, rate_hz)
                regressor = temp
    removed = regressor is not None
    taus = tau_grid(n, rate_hz)

    def figures(data: np.ndarray) -> SensorNoiseFigures:
        axes = tuple(axis_noise(data[:, k], rate_hz, taus, method, regressor)
                     for k in range(3))
        return SensorNoiseFigures(axes)  # type: ignore[arg-type]

    return AllanResult(
        gyro=figures(gyro), accel=figures(accel), rate_hz=float(rate_hz),
        duration_s=n / rate_hz, samples=n, temperature_span_degc=span,
        temperature_removed=removed, gyro_slopes_per_degc=gyro_slopes,
        accel_slopes_per_degc=accel_slopes, method=method,
    )


# -- likelihood fit of noise density and random walk --------------------------------------------
ML_BINS = 4096
"""The time-domain fit averages the record into about this many bins (0.44 s for 30 minutes at
104 Hz): enough for a noise density to about 1 %, and no walk information is lost (the walk
lives at averaging times of tens to hundreds of seconds; the walk inside a bin is modelled)."""
ML_GRID_STEP = 0.05
"""Spacing of the grid over ``ln(q / r)`` on which the likelihood is evaluated."""
ML_LONGEST_CROSSING = 1000.0
"""The grid reaches walks whose crossing time ``N / K`` is this many record lengths."""
ML_LARGEST_RATIO = 100.0
"""... and walks whose step per sample is this many times the white noise's variance."""


@dataclass(frozen=True)
class WalkFit:
    """The time-domain likelihood fit of white noise plus a bias random walk."""

    noise_density: float
    """``N`` per sqrt(Hz), the one-sided density (sample scatter ``N sqrt(fs / 2)``)."""
    random_walk: float
    """``K`` per sqrt(s): the posterior median under the Jeffreys prior (see
    :func:`fit_white_and_walk`)."""
    random_walk_log_sd: float
    """Half the width of the central 68 % posterior interval of ``ln K``: about the relative
    1-sigma uncertainty of ``K``."""
    random_walk_ml: float
    """``K`` at the likelihood's maximum (0 when that lies at the grid's small end)."""
    bin_samples: int
    bins: int
    regressor_slope: float
    """The regressor's coefficient at the estimate (0 without a regressor)."""


def _dst1(x: np.ndarray) -> np.ndarray:
    """Orthonormal type-I discrete sine transform along the last axis (numpy FFT).

    ``X_k = sqrt(2 / (n + 1)) sum_j x_j sin(pi j k / (n + 1))``, j, k = 1..n: the eigenvectors
    of every symmetric tridiagonal Toeplitz matrix.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    zero = np.zeros((*x.shape[:-1], 1))
    odd = np.concatenate([zero, x, zero, -x[..., ::-1]], axis=-1)
    return -np.fft.rfft(odd, axis=-1).imag[..., 1:n + 1] * math.sqrt(0.5 / (n + 1))


def binned_difference_spectra(n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues ``(a, b)`` (n,) of the covariance of ``n`` differences of bin means.

    Bins hold ``m`` samples. ``a``: white noise of unit variance per sample (the bin means'
    differences have autocovariance ``2/m, -1/m``); ``b``: a random walk of unit increment
    variance per sample, with the walk inside each bin accounted for (autocovariance
    ``(2 m^2 + 1) / (3 m), (m^2 - 1) / (6 m)``). Both are tridiagonal Toeplitz, so both are
    diagonal in the type-I sine basis with eigenvalues ``g0 + 2 g1 cos(pi k / (n + 1))``.
    """
    cos = np.cos(np.pi * np.arange(1, n + 1) / (n + 1))
    a = (2.0 - 2.0 * cos) / m
    b = (2.0 * m * m + 1.0) / (3.0 * m) + 2.0 * (m * m - 1.0) / (6.0 * m) * cos
    return a, b


def _profile_deviance(rho: np.ndarray, a: np.ndarray, b: np.ndarray, z: np.ndarray,
                      zt: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``-2 ln L`` (up to a constant) at walk-to-white ratios ``rho`` (G,), with the white
    variance ``r`` maximised out; also ``r`` and the regressor's coefficient.

    With a regressor this is the restricted (REML) likelihood, that of the data's part the
    regressor cannot explain: a warm-up curve looks like a stretch of walk, and plain maximum
    likelihood would hand it a share of the walk without counting the degree of freedom spent.
    """
    rho = np.atleast_1d(np.asarray(rho, dtype=np.float64))
    n = len(z)
    deviance = np.empty(len(rho))
    r = np.empty(len(rho))
    beta = np.zeros(len(rho))
    chunk = max(1, 2_000_000 // max(n, 1))
    for lo in range(0, len(rho), chunk):
        lam = a[None, :] + rho[lo:lo + chunk, None] * b[None, :]
        w = 1.0 / lam
        quad = w @ (z * z)
        if zt is not None:
            wtt = w @ (zt * zt)
            wzt = w @ (z * zt)
            safe = np.where(wtt > 0, wtt, 1.0)
            beta[lo:lo + chunk] = np.where(wtt > 0, wzt / safe, 0.0)
            quad = quad - np.where(wtt > 0, wzt * wzt / safe, 0.0)
            dof = n - 1
        else:
            dof = n
        r_hat = np.maximum(quad / dof, np.finfo(np.float64).tiny)
        r[lo:lo + chunk] = r_hat
        deviance[lo:lo + chunk] = dof * np.log(r_hat) + np.log(lam).sum(axis=1)
        if zt is not None:  # restricted likelihood: the coefficient's own uncertainty
            deviance[lo:lo + chunk] += np.log(np.where(wtt > 0, wtt, 1.0))
    return deviance, r, beta


def walk_information(rho: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(G, 2, 2) expected Fisher information on ``(ln r, ln q)`` at ratios ``rho`` (G,).

    Exact for the Gaussian model (``1/2 sum_k d ln(lambda_k) d ln(lambda_k)``); a regressor's
    coefficient is orthogonal to both and does not enter.
    """
    rho = np.atleast_1d(np.asarray(rho, dtype=np.float64))
    lam = a[None, :] + rho[:, None] * b[None, :]
    da, db = a[None, :] / lam, rho[:, None] * b[None, :] / lam
    out = np.empty((len(rho), 2, 2))
    out[:, 0, 0] = 0.5 * np.sum(da * da, axis=1)
    out[:, 0, 1] = out[:, 1, 0] = 0.5 * np.sum(da * db, axis=1)
    out[:, 1, 1] = 0.5 * np.sum(db * db, axis=1)
    return out


def random_walk_bound(noise_density: float, random_walk: float, rate_hz: float,
                      duration_s: float) -> float:
    """Cramer-Rao bound on the standard deviation of ``ln K`` from ``duration_s`` of data.

    The least scatter any unbiased estimator of the random walk ``K`` can reach with white noise
    of density ``N`` over the record (with ``N`` unknown too); about the relative 1-sigma
    error of ``K``.
    """
    count = round(duration_s * rate_hz)
    m = max(1, count // ML_BINS)
    a, b = binned_difference_spectra(count // m - 1, m)
    rho = 2.0 * random_walk**2 / (noise_density * rate_hz) ** 2
    information = walk_information(np.array([rho]), a, b)[0]
    return 0.5 * math.sqrt(float(np.linalg.inv(information)[1, 1]))


def fit_white_and_walk(x: np.ndarray, rate_hz: float, regressor: np.ndarray | None = None
                       ) -> WalkFit:
    """Noise density and bias random walk of ``x`` (N,) from its exact Gaussian likelihood.

    The model is the state-space model ``x_k = b_k + w_k``, ``b_k = b_(k-1) + v_k`` (white
    ``w`` of density ``N``, walk steps ``v`` of variance ``K^2 / fs``), plus ``beta *
    regressor_k`` when a regressor (the temperature) is given. The data are averaged into
    about :data:`ML_BINS` bins (the walk inside a bin is modelled exactly) and differenced,
    which removes the unknown turn-on bias as a diffuse initial state of a Kalman filter does.
    Both terms of the differences' covariance are tridiagonal Toeplitz, so the sine transform
    diagonalises it: the likelihood, the same number a scalar Kalman filter's innovations
    give, costs O(n) per evaluation after one O(n log n) transform. The white variance and
    ``beta`` are maximised out in closed form; the walk-to-white ratio ``rho = q / r`` runs over
    a fine logarithmic grid.

    Thirty minutes hold only a few independent stretches of a walk that crosses the white noise
    after minutes: the likelihood of ``K`` is then wide and skewed, and its maximum falls on
    ``K = 0`` for a good share of records. ``K`` is therefore the median of the posterior under
    the Jeffreys prior (``sqrt(det I)``, invariant to the units and vanishing where the walk
    cannot be told apart), which is median-unbiased and never 0; the maximum is kept as
    ``random_walk_ml``, and the posterior's width as ``random_walk_log_sd``.
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    count = len(x)
    m = max(1, count // ML_BINS)
    bins = count // m
    if bins < 8:
        raise ValueError(f"{count} samples: too few for the noise fit (record longer)")

    def differenced(values: np.ndarray) -> np.ndarray:
        return _dst1(np.diff(values[: bins * m].reshape(bins, m).mean(axis=1)))

    z = differenced(x)
    zt = None
    if regressor is not None:
        values = np.asarray(regressor, dtype=np.float64).ravel()
        zt = differenced(values - values.mean())
        if not np.any(zt):
            zt = None
    a, b = binned_difference_spectra(bins - 1, m)
    duration = count / rate_hz
    # rho = q / r = 2 K^2 / (N fs)^2
    lowest = 2.0 / (ML_LONGEST_CROSSING * duration * rate_hz) ** 2
    grid = np.arange(math.log(lowest), math.log(ML_LARGEST_RATIO), ML_GRID_STEP)
    rho = np.exp(grid)
    deviance, white_var, beta = _profile_deviance(rho, a, b, z, zt)
    information = walk_information(rho, a, b)
    log_prior = 0.5 * np.log(np.maximum(np.linalg.det(information), np.finfo(float).tiny))
    log_post = -0.5 * deviance + log_prior
    weight = np.exp(log_post - log_post.max())
    log_k = 0.5 * np.log(np.maximum(rho * white_var * rate_hz, np.finfo(float).tiny))
    order = np.argsort(log_k)
    cumulative = np.cumsum(weight[order])
    cumulative /= cumulative[-1]
    quantiles = np.interp([0.16, 0.5, 0.84], cumulative, log_k[order])
    at = int(np.argmin(np.abs(log_k - quantiles[1])))
    best = int(np.argmin(deviance))
    return WalkFit(
        noise_density=math.sqrt(2.0 * float(white_var[at]) / rate_hz),
        random_walk=math.exp(float(quantiles[1])),
        random_walk_log_sd=0.5 * float(quantiles[2] - quantiles[0]),
        random_walk_ml=0.0 if best == 0 else math.exp(float(log_k[best])),
        bin_samples=m, bins=bins,
        regressor_slope=float(beta[at]) if zt is not None else 0.0,
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
