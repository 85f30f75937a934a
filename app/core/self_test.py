"""A sensor self-test's outcome as the app reports it, whichever device ran it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class SelfTestReport:
    """Pass or fail per sensor, and the output change the test force caused, per axis.

    The windows the changes are judged by belong to the device (they depend on the full scale
    its procedure uses), so the verdicts come from the device too.
    """

    accel_pass: bool
    gyro_pass: bool
    accel_delta_mg: tuple[float, float, float]
    gyro_delta_dps: tuple[float, float, float]

    @classmethod
    def from_result(cls, result: Any) -> SelfTestReport:
        """From a driver's result (link protocol SELFTEST or the register-level driver's)."""
        return cls(
            bool(result.accel_pass), bool(result.gyro_pass),
            tuple(float(v) for v in result.accel_delta_mg),  # type: ignore[arg-type]
            tuple(float(v) for v in result.gyro_delta_dps),  # type: ignore[arg-type]
        )

    @property
    def passed(self) -> bool:
        return self.accel_pass and self.gyro_pass

    def lines(self) -> list[str]:
        """The verdict, then one line per sensor with its output change per axis."""
        def axes(values: tuple[float, float, float]) -> str:
            return " / ".join(f"{v:.0f}" for v in values)

        return [
            f"Self-test {'passed' if self.passed else 'FAILED'}",
            f"accelerometer {'pass' if self.accel_pass else 'FAIL'}: change "
            f"{axes(self.accel_delta_mg)} mg",
            f"gyroscope {'pass' if self.gyro_pass else 'FAIL'}: change "
            f"{axes(self.gyro_delta_dps)} °/s",
        ]

    def summary(self) -> str:
        """One line for the user."""
        verdict, *sensors = self.lines()
        return f"{verdict}: {', '.join(sensors)}"
