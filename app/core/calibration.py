"""The calibration stage: sensor-error correction applied to every block.

``a_cal = A (a_raw - b_a)`` and ``w_cal = G (w_raw - b_g)``, with biases in SI units and
3x3 matrices that hold scale and misalignment. The identity calibration leaves data unchanged.
The calibration wizard (a later stage of the project) fills these from measurements.

Optional temperature compensation (:class:`TemperatureCompensation`) makes both biases
functions of the die temperature of each sample::

    b(T) = b0 + k1 (T - T0) + k2 (T - T0)^2

with ``b0`` the calibration's bias (valid at ``T0``). A sample whose temperature is unknown
(NaN) gets ``b0``. The correction is elementwise per sample, so the result does not depend on
how a stream is cut into blocks: a replay reproduces the live run bit for bit.
:func:`temperature_to_json` and :func:`temperature_from_json` give the optional JSON keys
that profiles, recordings and ``inclinometer calibrate-temperature`` share.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from app.core.samples import SampleBlock


def _zeros3() -> np.ndarray:
    return np.zeros(3)


def _eye3() -> np.ndarray:
    return np.eye(3)


# The optional JSON keys of the temperature terms (flat, beside the binding bias/matrix keys).
KEY_TEMP_REFERENCE = "temperature_reference_degc"
TEMPERATURE_KEYS: dict[str, str] = {
    "accel_k1": "accel_bias_tc1_m_s2_per_degc",
    "accel_k2": "accel_bias_tc2_m_s2_per_degc2",
    "gyro_k1": "gyro_bias_tc1_rad_s_per_degc",
    "gyro_k2": "gyro_bias_tc2_rad_s_per_degc2",
}
"""Attribute of :class:`TemperatureCompensation` -> its JSON key ([3] numbers each)."""


@dataclass(frozen=True)
class TemperatureCompensation:
    """Bias against die temperature: ``b(T) = b0 + k1 (T - T0) + k2 (T - T0)^2`` per axis.

    ``reference_temp_degc`` is ``T0``; the ``k`` vectors are (3,), per sensor axis, in
    m/s^2/degC and m/s^2/degC^2 (accelerometer) or rad/s/degC and rad/s/degC^2 (gyroscope).
    """

    reference_temp_degc: float
    accel_k1: np.ndarray = field(default_factory=_zeros3)
    accel_k2: np.ndarray = field(default_factory=_zeros3)
    gyro_k1: np.ndarray = field(default_factory=_zeros3)
    gyro_k2: np.ndarray = field(default_factory=_zeros3)

    @property
    def is_zero(self) -> bool:
        return not any(np.any(getattr(self, name)) for name in TEMPERATURE_KEYS)

    def offsets(self, temp_degc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(accel, gyro)`` bias changes (N, 3) at temperatures (N,); zero where NaN."""
        delta = np.asarray(temp_degc, dtype=np.float64).reshape(-1, 1) - self.reference_temp_degc
        delta = np.where(np.isfinite(delta), delta, 0.0)
        square = delta * delta
        accel = delta * self.accel_k1 + square * self.accel_k2
        gyro = delta * self.gyro_k1 + square * self.gyro_k2
        return accel, gyro

    def recentred(self, reference_temp_degc: float) -> TemperatureCompensation:
        """The same curve's shape about another ``T0`` (its value at the new ``T0`` is 0).

        ``k1' = k1 + 2 k2 (T0' - T0)``, ``k2' = k2``: only the bias *change* is kept, so a
        bias measured at ``T0'`` (e.g. a six-position calibration's) can take the place of b0.
        """
        shift = float(reference_temp_degc) - self.reference_temp_degc
        return TemperatureCompensation(
            reference_temp_degc=float(reference_temp_degc),
            accel_k1=self.accel_k1 + 2.0 * shift * self.accel_k2, accel_k2=self.accel_k2.copy(),
            gyro_k1=self.gyro_k1 + 2.0 * shift * self.gyro_k2, gyro_k2=self.gyro_k2.copy(),
        )


def temperature_to_json(model: TemperatureCompensation | None) -> dict[str, Any]:
    """The optional keys (empty without a model): ``temperature_reference_degc`` and the
    four ``[3]`` coefficient vectors of :data:`TEMPERATURE_KEYS`."""
    if model is None:
        return {}
    out: dict[str, Any] = {KEY_TEMP_REFERENCE: float(model.reference_temp_degc)}
    for attribute, key in TEMPERATURE_KEYS.items():
        out[key] = np.asarray(getattr(model, attribute), float).tolist()
    return out


def calibration_to_json(calibration: SensorCalibration) -> dict[str, Any]:
    """The calibration's binding JSON keys, the one place they are written (recordings,
    profiles, ``calibrate --out``, ``calibrate-temperature --out``): ``accel_bias_m_s2``,
    ``accel_matrix``, ``gyro_bias_rad_s``, ``gyro_matrix`` and, only when there are some, the
    temperature terms of :func:`temperature_to_json` and the magnetometer's
    (:data:`MAG_KEY`: calibrate-mag's object)."""
    return {
        "accel_bias_m_s2": np.asarray(calibration.accel_bias_m_s2, float).tolist(),
        "accel_matrix": np.asarray(calibration.accel_matrix, float).tolist(),
        "gyro_bias_rad_s": np.asarray(calibration.gyro_bias_rad_s, float).tolist(),
        "gyro_matrix": np.asarray(calibration.gyro_matrix, float).tolist(),
        **temperature_to_json(calibration.temperature),
        **({MAG_KEY: calibration.magnetometer.to_json()}
           if calibration.magnetometer is not None else {}),
    }


def calibration_json_text(document: Mapping[str, Any]) -> str:
    """A calibration document (a profile, a ``calibrate --out`` file) as the JSON text
    written to disk: indented, no NaN (a NaN raises ValueError), a final newline."""
    return json.dumps(document, indent=2, allow_nan=False) + "\n"


def temperature_from_json(value: Mapping[str, Any]) -> TemperatureCompensation | None:
    """The model from the keys of :func:`temperature_to_json` (None when there is no
    ``temperature_reference_degc``; a missing coefficient vector is zero).

    Raises ValueError, naming the key, for a malformed value.
    """
    reference = value.get(KEY_TEMP_REFERENCE)
    if reference is None:
        return None
    if (isinstance(reference, bool) or not isinstance(reference, int | float)
            or not math.isfinite(reference)):
        raise ValueError(f"{KEY_TEMP_REFERENCE!r} must be a finite number, not {reference!r}")
    vectors = {}
    for attribute, key in TEMPERATURE_KEYS.items():
        raw = value.get(key)
        if raw is None:
            vectors[attribute] = np.zeros(3)
            continue
        try:
            array = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{key!r} is not numbers") from None
        if array.shape != (3,) or not np.all(np.isfinite(array)):
            raise ValueError(f"{key!r} is not 3 finite numbers")
        vectors[attribute] = array
    return TemperatureCompensation(float(reference), **vectors)


MAG_KEY = "magnetometer"
"""The JSON key of the magnetometer's calibration (binding: ``calibrate-mag --json``)."""


@dataclass(frozen=True)
class MagnetometerCalibration:
    """The magnetometer's correction: ``m = soft_iron (raw - hard_iron)``, in uT.

    The result is in the accelerometer's frame: ``soft_iron`` holds the soft-iron distortion's
    inverse *and* the turn between the magnetometer chip's axes and the accelerometer's.
    ``field_ut`` and ``dip_deg`` are the local field's strength and its dip below the
    horizontal found by the fit; ``fitness_uT`` the fit's RMS residual, ``coverage`` the
    fraction of directions the tour covered (0..1). Rows that carry no field sample (NaN)
    stay NaN.
    """

    hard_iron_ut: np.ndarray = field(default_factory=_zeros3)
    soft_iron: np.ndarray = field(default_factory=_eye3)
    field_ut: float = math.nan
    dip_deg: float = math.nan
    fitness_ut: float = math.nan
    coverage: float = math.nan
    extra: dict[str, Any] = field(default_factory=dict)
    """Further JSON keys the fit reported (kept through a round trip)."""

    @property
    def is_identity(self) -> bool:
        return not np.any(self.hard_iron_ut) and np.array_equal(self.soft_iron, np.eye(3))

    def apply(self, mag_ut: np.ndarray) -> np.ndarray:
        """(N, 3) measured field -> (N, 3) calibrated field in the accelerometer's frame."""
        return (np.asarray(mag_ut, dtype=np.float64) - self.hard_iron_ut) @ self.soft_iron.T

    def to_json(self) -> dict[str, Any]:
        """``{"hard_iron_uT": [3], "soft_iron": [[3]x3], "field_uT", "dip_deg", ...}``."""
        def number(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        return {
            **self.extra,
            "hard_iron_uT": np.asarray(self.hard_iron_ut, float).tolist(),
            "soft_iron": np.asarray(self.soft_iron, float).tolist(),
            "field_uT": number(self.field_ut),
            "dip_deg": number(self.dip_deg),
            "fitness_uT": number(self.fitness_ut),
            "coverage": number(self.coverage),
        }

    @classmethod
    def from_json(cls, value: Any) -> MagnetometerCalibration:
        """Inverse of :meth:`to_json`; raises ValueError naming what is wrong."""
        if not isinstance(value, Mapping):
            raise ValueError("the magnetometer calibration is not a JSON object")

        def array(name: str, shape: tuple[int, ...]) -> np.ndarray:
            if name not in value:
                raise ValueError(f"the magnetometer calibration lacks {name!r}")
            try:
                result = np.asarray(value[name], dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(
                    f"the magnetometer calibration's {name!r} is not numbers") from None
            if result.shape != shape or not np.all(np.isfinite(result)):
                raise ValueError(
                    f"the magnetometer calibration's {name!r} is not {shape} finite numbers")
            return result

        def number(name: str) -> float:
            item = value.get(name)
            if item is None:
                return math.nan
            if isinstance(item, bool) or not isinstance(item, int | float):
                raise ValueError(f"the magnetometer calibration's {name!r} is not a number")
            return float(item)

        soft = array("soft_iron", (3, 3))
        if abs(np.linalg.det(soft)) < 1e-6:
            raise ValueError("the magnetometer calibration's 'soft_iron' is singular")
        known = {"hard_iron_uT", "soft_iron", "field_uT", "dip_deg", "fitness_uT", "coverage"}
        return cls(
            hard_iron_ut=array("hard_iron_uT", (3,)), soft_iron=soft,
            field_ut=number("field_uT"), dip_deg=number("dip_deg"),
            fitness_ut=number("fitness_uT"), coverage=number("coverage"),
            extra={k: v for k, v in value.items() if k not in known},
        )


@dataclass(frozen=True)
class SensorCalibration:
    """Accelerometer and gyroscope correction; ``name`` labels the active profile.

    ``temperature`` (optional) makes the biases follow the die temperature; the biases here
    are then their values at its ``reference_temp_degc``.
    """

    accel_bias_m_s2: np.ndarray = field(default_factory=_zeros3)
    accel_matrix: np.ndarray = field(default_factory=_eye3)
    gyro_bias_rad_s: np.ndarray = field(default_factory=_zeros3)
    gyro_matrix: np.ndarray = field(default_factory=_eye3)
    name: str = "uncalibrated"
    temperature: TemperatureCompensation | None = None
    magnetometer: MagnetometerCalibration | None = None
    """The magnetometer's correction, when the profile has one (applied to ``mag_ut``)."""

    @property
    def is_identity(self) -> bool:
        return (
            not np.any(self.accel_bias_m_s2)
            and not np.any(self.gyro_bias_rad_s)
            and np.array_equal(self.accel_matrix, np.eye(3))
            and np.array_equal(self.gyro_matrix, np.eye(3))
            and (self.temperature is None or self.temperature.is_zero)
            and (self.magnetometer is None or self.magnetometer.is_identity)
        )

    def biases_at(self, temp_degc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(accel, gyro)`` biases (N, 3) at temperatures (N,) (b0 without a model or at NaN)."""
        n = np.asarray(temp_degc).reshape(-1).shape[0]
        if self.temperature is None:
            return (np.broadcast_to(self.accel_bias_m_s2, (n, 3)),
                    np.broadcast_to(self.gyro_bias_rad_s, (n, 3)))
        accel, gyro = self.temperature.offsets(temp_degc)
        accel += self.accel_bias_m_s2
        gyro += self.gyro_bias_rad_s
        return accel, gyro

    def apply(self, block: SampleBlock) -> SampleBlock:
        """A calibrated copy of ``block`` (the block itself when this is the identity)."""
        if self.is_identity:
            return block
        if self.temperature is None or self.temperature.is_zero:
            accel_bias, gyro_bias = self.accel_bias_m_s2, self.gyro_bias_rad_s
        else:
            accel_bias, gyro_bias = self.biases_at(block.temp_degc)
        accel = (block.accel_m_s2 - accel_bias) @ self.accel_matrix.T
        gyro = (block.gyro_rad_s - gyro_bias) @ self.gyro_matrix.T
        mag = block.mag_ut
        if mag is not None and self.magnetometer is not None:
            mag = self.magnetometer.apply(mag)
        return replace(block, accel_m_s2=accel, gyro_rad_s=gyro, mag_ut=mag)

    def with_temperature(self, model: TemperatureCompensation | None) -> SensorCalibration:
        """This calibration with ``model`` as its temperature terms (None removes them)."""
        return replace(self, temperature=model)

    def with_magnetometer(self, model: MagnetometerCalibration | None) -> SensorCalibration:
        """This calibration with ``model`` as its magnetometer terms (None removes them)."""
        return replace(self, magnetometer=model)


IDENTITY_CALIBRATION = SensorCalibration()
