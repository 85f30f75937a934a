"""Allan deviation of a static record, and the sensor noise figures read from it.

The deviation itself is ``allantools.oadev`` (overlapping Allan deviation; a maintained
library, not hand-written code). On top of it this module fits the classic noise model per
axis (IEEE Std 952, Annex C) to the Allan *variance*::

    AVAR(tau) = N^2 / (2 tau)  +  (0.664 B)^2  +  K^2 tau / 3

- ``N``, the **noise density** (white noise), in the datasheet's one-sided convention: one
  sample at rate ``fs`` scatters by ``N sqrt(fs / 2)``, as in the simulator and the EKF's
  ``gyro_noise`` (so ``adev(1 s) = N / sqrt(2)`` on the -1/2 slope). Kalibr, allan_variance_ros
  and IEEE Std 952 read the density off the Allan curve at tau = 1 s instead (continuous-time
  white noise of strength ``N_c``: one sample scatters by ``N_c sqrt(fs)``), so
  ``N_c = N / sqrt(2)``; both are reported (:data:`CONVENTIONS`);
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
ONE_SIDED_PER_ALLAN = math.sqrt(2.0)
"""The datasheet's one-sided density over the Allan/Kalibr one, for the same white noise."""
CONVENTIONS = {
    "noise_density": "the datasheet's one-sided density N: one sample at rate fs scatters by "
                     "N*sqrt(fs/2) (kept under this key; the same as noise_density_one_sided)",
    "noise_density_one_sided": "the datasheet's one-sided density N: one sample at rate fs "
                               "scatters by N*sqrt(fs/2); compare with ST's datasheet figures",
    "noise_density_allan": "the Allan/Kalibr/IEEE Std 952 density N_c = N/sqrt(2), the Allan "
                           "deviation at tau = 1 s: one sample at rate fs scatters by "
                           "N_c*sqrt(fs); Kalibr's *_noise_density",
    "random_walk": "K: the bias moves by K*sqrt(t) in t seconds; the same in both conventions "
                   "(Kalibr's *_random_walk)",
}
"""What each density and walk of the JSON means (its ``convention`` object)."""


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
    def noise_density_one_sided(self) -> np.ndarray:
        """The datasheet's one-sided density: a sample scatters by ``N sqrt(fs / 2)``."""
        return self.noise_density

    @property
    def noise_density_allan(self) -> np.ndarray:
        """The Allan/Kalibr density (adev at tau = 1 s): a sample scatters by ``N sqrt(fs)``."""
        return self.noise_density / ONE_SIDED_PER_ALLAN

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
            "noise_density_one_sided": self.noise_density_one_sided.tolist(),
            "noise_density_allan": self.noise_density_allan.tolist(),
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
            "convention": dict(CONVENTIONS),
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


# -- is the record still, and what does it support ----------------------------------------------
STILL_WINDOW_S = 1.0
"""Windows in which the record is checked for motion."""
MOTION_TILT_DEG = 0.25
"""A window whose mean gravity direction is this far from the record's is moved. A warm-up
shifts the accelerometer's offset by about 0.1 mg/degC (0.06 deg over 10 degC), while a change
of attitude of 0.25 deg is a 4 mg step: a hundred times the bias instability the curve reads."""
MOTION_RATE_DPS = 0.5
"""A window whose mean rate departs this far from the record's median is turning (a warm-up
moves the gyro's bias by about 0.01 dps/degC; a 130 deg turn in 10 s is 13 dps)."""
MOTION_SD_RATIO = 3.0
"""A window whose gyro scatter exceeds the record's typical (median) scatter this many times is
shaken: at rest the scatter is the white noise, the same in every window (within ~20 %)."""
MOTION_SD_FLOOR_DPS = 0.1
"""The scatter test's threshold is never below this: a few LSB at the widest range (70 mdps
at +-2000 dps), where a quantised record at rest scatters by 0 or 1 LSB from window to window."""
MOTION_GYRO_SD_DPS = 1.0
"""Gyro scatter within a window above this is motion whatever the rest of the record does (a
MEMS gyro at rest scatters by 0.03 dps at 104 Hz, 0.2 dps at 6.7 kHz; a hand's tremor by
several)."""
MIN_STATIC_RECORD_S = 30.0
"""The noise density comes from the short taus: 30 s gives it within a few percent."""
MIN_FLOOR_CLUSTERS = 9
"""The bias instability is read at the curve's minimum; the minimum must have at least this many
clusters (T / tau, the deviation then within about 25 %), else the curve has not reached its
floor in the record (it still falls at the longest taus) and the figure is not reported."""


@dataclass(frozen=True)
class StillnessCheck:
    """Whether a record was at rest throughout (:func:`check_still`)."""

    moving_s: float
    """Seconds of windows in which the sensor moved."""
    first_motion_s: float
    """Start of the first such window, seconds from the record's start (NaN: none)."""
    largest_tilt_deg: float
    largest_rate_dps: float
    reason: str
    """A sentence for the user ("" when still)."""

    @property
    def still(self) -> bool:
        return not self.reason


def check_still(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, rate_hz: float
                ) -> StillnessCheck:
    """Find motion in a record meant to be at rest (see the ``MOTION_...`` constants).

    Checked per window of :data:`STILL_WINDOW_S`: the mean gravity direction against the
    record's, the mean rate against the record's median, and the gyro's scatter against the
    record's median scatter (never below :data:`MOTION_SD_FLOOR_DPS`) and an absolute limit.
    """
    gyro = np.asarray(gyro_rad_s, dtype=np.float64).reshape(-1, 3)
    accel = np.asarray(accel_m_s2, dtype=np.float64).reshape(-1, 3)
    size = max(4, round(STILL_WINDOW_S * rate_hz))
    count = len(gyro) // size
    if count == 0:
        return StillnessCheck(0.0, math.nan, 0.0, 0.0, "")
    g = gyro[: count * size].reshape(count, size, 3)
    a = accel[: count * size].reshape(count, size, 3)
    g_mean, g_sd = g.mean(axis=1), g.std(axis=1, ddof=1)
    a_mean = a.mean(axis=1)
    direction = np.median(a_mean, axis=0)
    cross = np.linalg.norm(np.cross(a_mean, direction), axis=1)
    tilt = np.degrees(np.arctan2(cross, a_mean @ direction))
    rate = np.degrees(np.linalg.norm(g_mean - np.median(g_mean, axis=0), axis=1))
    sd = np.degrees(g_sd)
    typical = np.maximum(MOTION_SD_RATIO * np.median(sd, axis=0), MOTION_SD_FLOOR_DPS)
    shaken = np.any((sd > typical) | (sd > MOTION_GYRO_SD_DPS), axis=1)
    moved = (tilt > MOTION_TILT_DEG) | (rate > MOTION_RATE_DPS) | shaken
    largest_tilt, largest_rate = float(tilt.max()), float(rate.max())
    if not moved.any():
        return StillnessCheck(0.0, math.nan, largest_tilt, largest_rate, "")
    window_s = size / rate_hz
    first = float(np.flatnonzero(moved)[0] * window_s)
    moving = float(moved.sum() * window_s)
    what = []
    if largest_tilt > MOTION_TILT_DEG:
        what.append(f"the gravity direction moved by up to {largest_tilt:.1f}°")
    if largest_rate > MOTION_RATE_DPS:
        what.append(f"it turned at up to {largest_rate:.1f} °/s")
    if shaken.any():
        what.append(f"it shook (gyro scatter up to {float(sd.max()):.2f} °/s)")
    reason = (f"not at rest: the sensor moved for {moving:.0f} s of {count * window_s:.0f} s, "
              f"first at {first:.0f} s ({'; '.join(what)}). The Allan analysis needs a "
              "recording of the sensor lying still throughout")
    return StillnessCheck(moving, first, largest_tilt, largest_rate, reason)


@dataclass(frozen=True)
class FigureSupport:
    """Which figures of an :class:`AllanResult` its record supports, per sensor and axis."""

    bias_instability: dict[str, np.ndarray]
    """{"gyro" | "accel": (3,) bool}"""
    random_walk: dict[str, np.ndarray]
    notes: tuple[str, ...]
    """One sentence per figure left out, saying what it would need."""

    def supported(self, sensor: str, figure: str) -> np.ndarray:
        """(3,) bool for "noise_density" (always), "bias_instability" or "random_walk"."""
        if figure == "noise_density":
            return np.ones(3, dtype=bool)
        return getattr(self, figure)[sensor]

    def to_json(self) -> dict[str, Any]:
        return {
            "bias_instability": {k: v.tolist() for k, v in self.bias_instability.items()},
            "random_walk": {k: v.tolist() for k, v in self.random_walk.items()},
            "notes": list(self.notes),
        }


def figure_support(result: AllanResult) -> FigureSupport:
    """What the record can tell: the bias instability only where the curve's minimum lies at a
    tau with :data:`MIN_FLOOR_CLUSTERS` clusters, the random walk only from
    :data:`MIN_WALK_RECORD_S` of data (the gyro's walk crosses its white noise after 200-500 s)."""
    duration = result.duration_s
    floors: dict[str, np.ndarray] = {}
    walks: dict[str, np.ndarray] = {}
    notes: list[str] = []
    for sensor in ("gyro", "accel"):
        figures: SensorNoiseFigures = getattr(result, sensor)
        ok = []
        for axis in figures.axes:
            finite = np.isfinite(axis.adev)
            if not finite.any():
                ok.append(False)
                continue
            best = int(np.nanargmin(np.where(finite, axis.adev, np.nan)))
            ok.append(duration / float(axis.tau_s[best]) >= MIN_FLOOR_CLUSTERS)
        floors[sensor] = np.array(ok)
        if not all(ok):
            missing = "/".join(a for a, good in zip(AXES, ok, strict=True) if not good)
            notes.append(
                f"{sensor} bias instability ({missing}) not reported: the Allan curve has not "
                f"reached its floor with {MIN_FLOOR_CLUSTERS} clusters in {duration / 60:.1f} "
                "min; record longer")
        walks[sensor] = np.full(3, duration >= MIN_WALK_RECORD_S)
        if duration < MIN_WALK_RECORD_S:
            notes.append(f"{sensor} random walk not reported: it needs "
                         f"{MIN_WALK_RECORD_S / 60:.0f} min of data or more, this record has "
                         f"{duration / 60:.1f} min")
    return FigureSupport(floors, walks, tuple(notes))


def static_record_problem(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, rate_hz: float) -> str:
    """Why a record cannot give noise figures ("" when it can): too short, or not at rest."""
    n = len(np.asarray(gyro_rad_s).reshape(-1, 3))
    duration = n / rate_hz if rate_hz > 0 else 0.0
    motion = check_still(gyro_rad_s, accel_m_s2, rate_hz).reason if duration > 0 else ""
    if motion:
        return motion
    if duration < MIN_STATIC_RECORD_S:
        return (f"{duration:.1f} s of data: record at least a few minutes at rest "
                f"({MIN_STATIC_RECORD_S:.0f} s for the noise density alone)")
    return ""
