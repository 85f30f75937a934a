"""The orientation-filter protocol and its parameter schema.

A filter consumes :class:`~app.core.samples.SampleBlock` s and returns one sensor-to-earth
quaternion per sample. It keeps its state between blocks, so a stream may be cut into blocks
anywhere. Parameters are described by :class:`ParameterSpec` s, from which the GUI builds its
controls; changing one mid-stream keeps the state continuous.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from app.core.orientation import TiltAngles, angles_from_quaternion
from app.core.samples import SampleBlock
from app.core.words import flag_word

MAX_STEP_S = 0.5
"""A time step longer than this (or a marked gap) restarts integration from the accelerometer."""


def restart_flags(dt: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """True where integration restarts: a marked gap, or a step ``dt`` (s, the time since the
    previous sample) that is not finite, not positive or longer than :data:`MAX_STEP_S`."""
    return ~np.isfinite(dt) | (dt <= 0.0) | (dt > MAX_STEP_S) | gap


@dataclass(frozen=True, slots=True)
class ParameterSpec:
    """Schema of one filter parameter.

    ``kind`` is ``"float"``, ``"int"`` or ``"bool"``. ``log_scale`` hints the GUI to use a
    logarithmic control. ``presets`` are named values shown next to the control.
    """

    name: str
    label: str
    unit: str
    default: float
    minimum: float
    maximum: float
    help: str
    kind: str = "float"
    log_scale: bool = False
    presets: tuple[tuple[str, float], ...] = ()

    def validate(self, value: Any) -> float | int | bool:
        """Return ``value`` converted to this parameter's type; raise ValueError when invalid."""
        if self.kind == "bool":
            if isinstance(value, str):  # "false" from a settings file or a command line
                flag = flag_word(value) if value.strip() else False
                if flag is not None:
                    return flag
                raise ValueError(f"{self.label}: {value!r} is not true or false")
            return bool(value)
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{self.label}: {value!r} is not a number") from None
        if not np.isfinite(number) or not self.minimum <= number <= self.maximum:
            raise ValueError(
                f"{self.label}: {value!r} is outside {self.minimum:g}..{self.maximum:g} {self.unit}"
            )
        return round(number) if self.kind == "int" else number


MAGNETOMETER_PARAMETER = ParameterSpec(
    "magnetometer", "Magnetometer heading", "", True, 0, 1,
    "Take heading from the magnetometer when the source has one (earth frame ENU, y toward "
    "magnetic north). Off: heading is carried by the gyroscope alone, from an arbitrary start.",
    kind="bool",
)
"""The switch every 9-axis filter (``uses_magnetometer``) declares among its parameters."""


@dataclass(slots=True)
class OrientationBlock:
    """Per-sample filter output: quaternions (N, 4) and the tilt-meter angles."""

    quat: np.ndarray
    angles: TiltAngles


class OrientationFilter(ABC):
    """Base class of every orientation filter (a template method: override ``_process``)."""

    name: ClassVar[str] = ""
    title: ClassVar[str] = ""
    description: ClassVar[str] = ""
    parameters: ClassVar[tuple[ParameterSpec, ...]] = ()
    offline: ClassVar[bool] = False
    """True for an acausal filter (a smoother): it needs the whole recording in one block, so it
    is offered for recorded sessions only, never for a live stream."""
    uses_magnetometer: ClassVar[bool] = False
    """True for a 9-axis filter: it takes heading from the magnetometer when the block carries a
    field (``SampleBlock.mag_ut``); its :data:`MAGNETOMETER_PARAMETER` turns that off. Its
    quaternion is then sensor-to-earth in ENU with y toward magnetic north."""
    reference_only: ClassVar[bool] = False
    """True for a filter kept as a faithful reference (the thesis's), not meant for measurement:
    labelled so in the filter list and left out of the default side-by-side set."""

    def __init__(self, **values: Any) -> None:
        self._values: dict[str, Any] = {spec.name: spec.default for spec in self.parameters}
        if self.parameters:
            for spec in self.parameters:
                if spec.kind == "int":
                    self._values[spec.name] = int(spec.default)
        for key, value in values.items():
            self.set_parameter(key, value)
        self._quat = np.array([1.0, 0.0, 0.0, 0.0])
        self._last_t: float | None = None
        self.reset()

    # -- parameters -------------------------------------------------------------------------
    @classmethod
    def parameter_spec(cls, name: str) -> ParameterSpec:
        for spec in cls.parameters:
            if spec.name == name:
                return spec
        known = ", ".join(s.name for s in cls.parameters) or "none"
        raise KeyError(f"{cls.title or cls.__name__} has no parameter {name!r} (has: {known})")

    def get_parameter(self, name: str) -> Any:
        self.parameter_spec(name)
        return self._values[name]

    def set_parameter(self, name: str, value: Any) -> None:
        """Validate and set a parameter; the filter state is kept."""
        self._values[name] = self.parameter_spec(name).validate(value)
        self._parameters_changed()

    def parameter_values(self) -> dict[str, Any]:
        return dict(self._values)

    def set_field_reference(self, reference: Any) -> None:  # noqa: B027 - an optional hook
        """The World Magnetic Model's field where the sensor is (a
        :class:`~app.core.field_check.FieldReference`, None: unknown), for filters that check
        the field reference they learn against it; the others have no use for it."""

    def _parameters_changed(self) -> None:  # noqa: B027 - an optional hook
        """Hook for filters that cache derived constants."""

    # -- state ------------------------------------------------------------------------------
    def reset(
        self, initial_quat: np.ndarray | None = None, last_time_s: float | None = None
    ) -> None:
        """Forget the state; start from ``initial_quat`` if given, else from the next sample.

        ``last_time_s`` is the time of the sample ``initial_quat`` belongs to, so that a filter
        taking over mid-stream integrates the very next step instead of restarting.
        """
        self._has_state = initial_quat is not None
        self._quat = (
            np.array([1.0, 0.0, 0.0, 0.0]) if initial_quat is None
            else np.asarray(initial_quat, dtype=np.float64).copy()
        )
        self._last_t = last_time_s if initial_quat is not None else None

    @property
    def last_time_s(self) -> float | None:
        """Time of the last processed sample, None before the first."""
        return self._last_t

    @property
    def quaternion(self) -> np.ndarray:
        """The latest estimate (sensor-to-earth)."""
        return self._quat.copy()

    # -- processing -------------------------------------------------------------------------
    def process(self, block: SampleBlock) -> OrientationBlock:
        """Run the filter over a block and return per-sample orientation."""
        if len(block) == 0:
            empty = np.empty((0, 4))
            return OrientationBlock(empty, angles_from_quaternion(empty))
        quat = self._process(block)
        self._quat = quat[-1].copy()
        self._has_state = True
        self._last_t = float(block.t_s[-1])
        return OrientationBlock(quat, angles_from_quaternion(quat))

    def time_steps(self, block: SampleBlock) -> np.ndarray:
        """Per-sample dt in seconds; 0 marks a restart (first sample, gap, bad or long step)."""
        previous = np.empty(len(block))
        previous[0] = np.nan if self._last_t is None else self._last_t
        previous[1:] = block.t_s[:-1]
        dt = block.t_s - previous
        restart = restart_flags(dt, block.gap)
        if not self._has_state:
            restart[0] = True
        return np.where(restart, 0.0, dt)

    @abstractmethod
    def _process(self, block: SampleBlock) -> np.ndarray:
        """Return (N, 4) quaternions for the block."""

    def warm_up(self) -> None:
        """Compile or prepare whatever the first block would (called off the GUI thread).

        Runs on a copy, so no state of this filter (averaging history, bias estimates...)
        sees the made-up samples.
        """
        t = np.arange(4) * 0.01
        block = SampleBlock(
            t, np.tile([0.0, 0.0, 9.81], (4, 1)), np.zeros((4, 3)), np.zeros(4),
            np.zeros(4, dtype=bool),
        )
        copy.deepcopy(self)._process(block)
