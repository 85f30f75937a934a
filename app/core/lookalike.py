"""Look-alike parts: an accelerometer whose 1 g at rest reads 0.5 g or 2 g.

WHO_AM_I 0x6C answers for the LSM6DSOX and also for the LSM6DSO and the LSM6DSO32(X). The
LSM6DSO reads like an LSM6DSOX; the LSM6DSO32's accelerometer ranges are double (its "+-4 g"
setting is +-8 g), so with the LSM6DSOX's sensitivities it reads half the acceleration: 0.5 g
at rest. Nothing on the bus tells them apart, so the check is physical: after bring-up, while
the sensor lies still, the mean |a| must be near 1 g. Near 0.5 g or 2 g it is a range off by a
factor of two; the caller shows :meth:`LookAlikeCheck.update`'s message as a device message.
"""

from __future__ import annotations

import numpy as np

from app.core.samples import SampleBlock

STANDARD_GRAVITY_M_S2 = 9.80665
REST_SECONDS = 0.5
"""At rest for this long (and at least :data:`MIN_SAMPLES` samples) before judging."""
MIN_SAMPLES = 8
GIVE_UP_SECONDS = 30.0
"""Never at rest this long after bring-up: no verdict (a hand-held sensor)."""
REST_GYRO_DPS = 5.0
"""At rest: every gyroscope axis within this, and |a| steady (below)."""
REST_ACCEL_SPREAD = 0.05
"""At rest: |a| within this share of its mean."""
HALF_G = (0.35, 0.7)
DOUBLE_G = (1.5, 2.8)


def lookalike_message(accel_g: float) -> str | None:
    """The warning for a mean |a| at rest of ``accel_g``, or None when it is not a factor of 2."""
    if HALF_G[0] <= accel_g <= HALF_G[1]:
        return (f"accelerometer reads {accel_g:.2f} g at rest: this may be an LSM6DSO32, whose "
                "ranges are double (+-4 g configured is +-8 g; it answers WHO_AM_I 0x6C too). "
                "Its accelerations read half: calibrate, or use an LSM6DSOX")
    if DOUBLE_G[0] <= accel_g <= DOUBLE_G[1]:
        return (f"accelerometer reads {accel_g:.2f} g at rest: its range may be half the one "
                "configured (another part answering WHO_AM_I 0x6C?); accelerations read double")
    return None


class LookAlikeCheck:
    """Judges |a| once, on the first stretch at rest after a device is opened."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """A new device: judge again."""
        self.done = False
        self.accel_g: float | None = None
        """Mean |a| at rest in g, once judged."""
        self._norms: list[np.ndarray] = []
        self._stretch_start_s: float | None = None
        """Time of the first sample of the stretch at rest (None: no stretch)."""
        self._start_s: float | None = None

    def update(self, block: SampleBlock) -> str | None:
        """Feed a block (SI, before calibration); the warning once judged and wrong, else None."""
        if self.done or not len(block):
            return None
        if self._start_s is None:
            self._start_s = float(block.t_s[0])
        still = np.all(np.abs(np.degrees(block.gyro_rad_s)) < REST_GYRO_DPS, axis=1)
        norms = np.linalg.norm(block.accel_m_s2, axis=1) / STANDARD_GRAVITY_M_S2
        if not np.all(still) or np.any(block.gap):
            self._norms = []  # moved (or data lost): start the stretch again
        else:
            if not self._norms:
                self._stretch_start_s = float(block.t_s[0])
            self._norms.append(norms)
        if float(block.t_s[-1]) - self._start_s > GIVE_UP_SECONDS:
            self.done = True
            return None
        if not self._norms:
            return None
        stretch = np.concatenate(self._norms)
        mean = float(np.mean(stretch))
        if mean <= 0.0 or np.ptp(stretch) > 2 * REST_ACCEL_SPREAD * mean:
            self._norms = [norms]  # not steady: the stretch starts again with this block
            self._stretch_start_s = float(block.t_s[0])
            return None
        if len(stretch) < MIN_SAMPLES or not self._long_enough(stretch, block):
            return None
        self.done = True
        self.accel_g = mean
        return lookalike_message(mean)

    def _long_enough(self, stretch: np.ndarray, block: SampleBlock) -> bool:
        """The stretch covers :data:`REST_SECONDS` (its time span plus one sample period),
        whatever the size of the blocks it came in (a link may deliver one sample a block)."""
        if self._stretch_start_s is None or len(stretch) < 2:
            return False
        span = float(block.t_s[-1]) - self._stretch_start_s
        return span * len(stretch) / (len(stretch) - 1) >= REST_SECONDS
