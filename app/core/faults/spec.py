"""What the fault detector needs to know about a sensor: rate, LSB sizes, full scales, noise.

The LSM6DSOX figures are the datasheet's (DS12814, the project's HARDWARE.md); they are repeated
here because the core imports no driver (``tests/test_fault_detector.py`` checks that they
match :mod:`drivers.lsm6dsox`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from app.core.devices import DeviceInfo
from app.core.samples import STANDARD_GRAVITY_M_S2, ScaleFactors

LSM6DSOX_ACCEL_MG_PER_LSB: dict[int, float] = {2: 0.061, 4: 0.122, 8: 0.244, 16: 0.488}
LSM6DSOX_GYRO_MDPS_PER_LSB: dict[int, float] = {
    125: 4.375, 250: 8.75, 500: 17.5, 1000: 35.0, 2000: 70.0,
}
LSM6DSOX_GYRO_NOISE_DPS_PER_SQRT_HZ = 3.8e-3
LSM6DSOX_ACCEL_NOISE_G_PER_SQRT_HZ = 70e-6
LSM6DSOX_ACCEL_NOISE_G_PER_SQRT_HZ_16G = 110e-6


@dataclass(frozen=True, slots=True)
class SensorSpec:
    """A sensor as the detector sees it. ``None`` means unknown (the test learns or is off).

    Attributes
    ----------
    odr_hz : sample rate (the windows and the time limits are converted with it).
    accel_lsb_m_s2, gyro_lsb_rad_s : output resolution; sets the stuck-run length.
    accel_fs_g, gyro_fs_dps : full scale; saturation is tested only when known.
    accel_noise_rms_m_s2, gyro_noise_rms_rad_s : datasheet white noise per sample (density x
        sqrt(ODR / 2)); only a starting point, the detector learns the real level at rest.
    mag_range_ut, mag_ut_per_lsb, mag_odr_hz : the magnetometer's full scale (+-uT), count
        size and own rate, when there is one and they are known.
    """

    odr_hz: float
    accel_lsb_m_s2: float | None = None
    gyro_lsb_rad_s: float | None = None
    accel_fs_g: float | None = None
    gyro_fs_dps: float | None = None
    accel_noise_rms_m_s2: float | None = None
    gyro_noise_rms_rad_s: float | None = None
    mag_range_ut: float | None = None
    mag_ut_per_lsb: float | None = None
    mag_odr_hz: float | None = None

    def with_magnetometer(self, info: Any) -> SensorSpec:
        """This spec with a magnetometer's figures (a :class:`MagnetometerInfo` or its
        metadata dict with ``range_ut``, ``odr_hz`` and ``ut_per_lsb``); None: unchanged."""
        if info is None:
            return self

        def figure(name: str) -> float | None:
            value = info.get(name) if isinstance(info, dict) else getattr(info, name, None)
            if isinstance(value, bool) or not isinstance(value, int | float):
                return None
            return float(value) if math.isfinite(value) and value > 0 else None

        return replace(self, mag_range_ut=figure("range_ut"),
                       mag_ut_per_lsb=figure("ut_per_lsb"), mag_odr_hz=figure("odr_hz"))

    @classmethod
    def lsm6dsox(cls, odr_hz: float, accel_fs_g: int, gyro_fs_dps: int) -> SensorSpec:
        """An LSM6DSOX at these settings, with the datasheet's LSB sizes and noise densities."""
        density = (LSM6DSOX_ACCEL_NOISE_G_PER_SQRT_HZ_16G if accel_fs_g == 16
                   else LSM6DSOX_ACCEL_NOISE_G_PER_SQRT_HZ)
        half_band = math.sqrt(odr_hz / 2.0)
        accel_lsb = LSM6DSOX_ACCEL_MG_PER_LSB.get(int(accel_fs_g))
        gyro_lsb = LSM6DSOX_GYRO_MDPS_PER_LSB.get(int(gyro_fs_dps))
        return cls(
            odr_hz=odr_hz,
            accel_lsb_m_s2=None if accel_lsb is None else accel_lsb * 1e-3 * STANDARD_GRAVITY_M_S2,
            gyro_lsb_rad_s=None if gyro_lsb is None else math.radians(gyro_lsb * 1e-3),
            accel_fs_g=float(accel_fs_g),
            gyro_fs_dps=float(gyro_fs_dps),
            accel_noise_rms_m_s2=density * STANDARD_GRAVITY_M_S2 * half_band,
            gyro_noise_rms_rad_s=math.radians(LSM6DSOX_GYRO_NOISE_DPS_PER_SQRT_HZ) * half_band,
        )

    @classmethod
    def from_device_info(cls, info: DeviceInfo, scale: ScaleFactors | None = None) -> SensorSpec:
        """From what an open device says about itself (and its raw scale factors, if known)."""
        return cls.from_device_dict(
            {"sensor": info.sensor, "odr_hz": info.odr_hz, "accel_fs_g": info.accel_fs_g,
             "gyro_fs_dps": info.gyro_fs_dps}, info.odr_hz, scale
        ).with_magnetometer(info.magnetometer)

    @classmethod
    def from_device_dict(
        cls, device: dict[str, Any], odr_hz: float, scale: ScaleFactors | None = None
    ) -> SensorSpec:
        """From a recording's ``device`` metadata (possibly empty) and its measured rate."""
        odr = float(device.get("odr_hz") or odr_hz)
        accel_fs = device.get("accel_fs_g")
        gyro_fs = device.get("gyro_fs_dps")
        if str(device.get("sensor", "")).upper() == "LSM6DSOX" and accel_fs and gyro_fs:
            spec = cls.lsm6dsox(odr, int(accel_fs), int(gyro_fs))
        else:
            spec = cls(odr_hz=odr,
                       accel_fs_g=float(accel_fs) if accel_fs else None,
                       gyro_fs_dps=float(gyro_fs) if gyro_fs else None)
        if scale is not None:
            spec = cls(spec.odr_hz, scale.accel_m_s2_per_lsb, scale.gyro_rad_s_per_lsb,
                       spec.accel_fs_g, spec.gyro_fs_dps, spec.accel_noise_rms_m_s2,
                       spec.gyro_noise_rms_rad_s)
        return spec
