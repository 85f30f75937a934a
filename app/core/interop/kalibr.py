"""Kalibr's IMU noise file (``imu.yaml``) from an Allan analysis, in Kalibr's convention.

Kalibr (its wiki page "IMU-Noise-Model") models each axis as continuous-time white noise of
strength ``sigma`` plus a bias that is a random walk of strength ``sigma_b``; at the sampling
time ``dt`` one sample scatters by ``sigma / sqrt(dt)`` and the bias moves by
``sigma_b sqrt(dt)`` per sample. ``sigma`` is the Allan deviation at tau = 1 s: the datasheet's
one-sided density divided by sqrt(2) (:attr:`SensorNoiseFigures.noise_density_allan`);
``sigma_b`` is this program's random walk ``K`` unchanged.
"""

from __future__ import annotations

import math

import numpy as np

from app.core.allan import MIN_WALK_RECORD_S, AllanResult, SensorNoiseFigures

KALIBR_KEYS = ("accelerometer_noise_density", "accelerometer_random_walk",
               "gyroscope_noise_density", "gyroscope_random_walk", "rostopic", "update_rate")
"""The keys of Kalibr's IMU file, in the order written."""
DEFAULT_ROSTOPIC = "/imu0"


class KalibrRefused(ValueError):
    """The analysis cannot give every figure Kalibr's file needs (says why, in one line)."""


def kalibr_figures(result: AllanResult) -> dict[str, float]:
    """Kalibr's four noise figures (the mean of the three axes), SI units.

    Raises :class:`KalibrRefused` when a random walk is not supported by the record's length
    or a figure is not a positive number (Kalibr would then weigh the IMU wrongly).
    """
    if result.duration_s < MIN_WALK_RECORD_S:
        raise KalibrRefused(
            f"--kalibr needs the random walks, which need {MIN_WALK_RECORD_S / 60:.0f} min of "
            f"data or more; this record has {result.duration_s / 60:.1f} min")
    figures: dict[str, float] = {}
    for prefix, sensor in (("accelerometer", result.accel), ("gyroscope", result.gyro)):
        for key, values in (("noise_density", sensor.noise_density_allan),
                            ("random_walk", sensor.random_walk)):
            value = float(np.mean(values))
            if not (math.isfinite(value) and value > 0.0):
                raise KalibrRefused(f"--kalibr: the {prefix}'s {key.replace('_', ' ')} came out "
                                    f"as {value:g}; Kalibr needs a positive figure")
            figures[f"{prefix}_{key}"] = value
    return figures


def _axes(sensor: SensorNoiseFigures) -> str:
    density = ", ".join(f"{v:.4g}" for v in sensor.noise_density_allan)
    walk = ", ".join(f"{v:.4g}" for v in sensor.random_walk)
    return f"density [{density}], random walk [{walk}]"


def kalibr_yaml(result: AllanResult, source: str, rostopic: str = DEFAULT_ROSTOPIC) -> str:
    """The text of Kalibr's IMU file for ``result`` (see :func:`kalibr_figures`)."""
    figures = kalibr_figures(result)
    temperature = ("regressed out" if result.temperature_removed else "kept") if math.isfinite(
        result.temperature_span_degc) else "not recorded"
    lines = [
        "# Kalibr IMU noise file (its wiki: IMU-Noise-Model), written by inclinometer allan",
        f"# from {source}: {result.duration_s / 60:.1f} min at rest, {result.samples} samples "
        f"at {result.rate_hz:.6g} Hz; noise density and random walk by the {result.method} "
        f"estimator; temperature {temperature}.",
        "# Kalibr's continuous-time convention: *_noise_density is the white noise's strength,",
        "# the Allan deviation at tau = 1 s (one sample at update_rate scatters by",
        "# density * sqrt(update_rate)) = the datasheet's one-sided density / sqrt(2);",
        "# *_random_walk: the bias moves by random_walk * sqrt(t). Each is the mean of the x, y, z",
        f"# axes: gyroscope {_axes(result.gyro)};",
        f"# accelerometer {_axes(result.accel)}.",
        "# These are the MEASURED values, not inflated. Kalibr's users usually inflate them to",
        "# cover what the model leaves out (temperature, vibration, axis misalignment): commonly",
        "# the random walks by about 10x and the noise densities by a few times. Not applied here.",
        f"accelerometer_noise_density: {figures['accelerometer_noise_density']:.6e}"
        "  # m/s^2/sqrt(Hz)",
        f"accelerometer_random_walk: {figures['accelerometer_random_walk']:.6e}"
        "  # m/s^3/sqrt(Hz)",
        f"gyroscope_noise_density: {figures['gyroscope_noise_density']:.6e}  # rad/s/sqrt(Hz)",
        f"gyroscope_random_walk: {figures['gyroscope_random_walk']:.6e}  # rad/s^2/sqrt(Hz)",
        f"rostopic: {rostopic}",
        f"update_rate: {result.rate_hz:.6g}  # Hz",
    ]
    return "\n".join(lines) + "\n"
