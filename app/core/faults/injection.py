"""Fault injection: ``KIND:CHANNEL[:SIZE]@START[-END]`` specs applied to samples in SI units.

Used by the simulator (``sim://...?fault=...``, through :mod:`drivers.sim.faults`) and by
``inclinometer evaluate-faults`` on recordings. Kinds (SIZE in g on ax..az, dps on gx..gz, uT
on the magnetometer's mx..mz, which only a simulator with a magnetometer accepts):

- ``noise:CH:SIGMA`` added white Gaussian noise of standard deviation SIGMA;
- ``stuck:CH`` the output freezes at its last value before START;
- ``dead:CH`` the output reads exactly 0;
- ``spike:CH:SIZE`` one sample offset by SIZE at START, and once a second until END if given;
- ``bias:CH:SIZE`` a constant offset (a bias step at START);
- ``scale:CH:FACTOR`` the output multiplied by FACTOR.

START and END are seconds on the device clock; the fault holds for START <= t < END (to the
end without END). The noise is drawn from ``numpy.random.default_rng([seed, 6, index])``, so a
seed gives the same faults every time.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.core.faults.events import CHANNELS
from app.core.samples import STANDARD_GRAVITY_M_S2

FAULT_KINDS: dict[str, str] = {
    "noise": "added Gaussian noise, SIZE = sigma (g or dps)",
    "stuck": "output frozen at its last value (no SIZE)",
    "dead": "output reads 0 (no SIZE)",
    "spike": "one-sample spikes of SIZE (g or dps), at START and every second until END",
    "bias": "offset of SIZE (g or dps)",
    "scale": "output multiplied by SIZE (a factor)",
}
"""Every injectable kind with a line of help."""
_NEEDS_SIZE = {"noise", "spike", "bias", "scale"}
MAG_CHANNELS: tuple[str, ...] = ("mx", "my", "mz")
FAULT_CHANNELS: tuple[str, ...] = (*CHANNELS, *MAG_CHANNELS)
"""Every channel a fault can be injected into; :attr:`FaultSpec.axis` indexes it."""
STREAM_FAULTS = 6
"""Random stream (after the simulator's own 0..5) for injected noise."""


@dataclass(frozen=True, slots=True)
class FaultSpec:
    """One injected fault (see the module docstring)."""

    kind: str
    channel: str
    size: float | None
    start_s: float
    end_s: float | None = None

    @property
    def axis(self) -> int:
        """Column 0..5 (ax..gz), 6..8 for the magnetometer's mx..mz."""
        return FAULT_CHANNELS.index(self.channel)

    def text(self) -> str:
        """The spec as written in a URL (``bias:gx:5@10-20``)."""
        size = "" if self.size is None else f":{self.size:g}"
        end = "" if self.end_s is None else f"-{self.end_s:g}"
        return f"{self.kind}:{self.channel}{size}@{self.start_s:g}{end}"

    def as_dict(self) -> dict[str, Any]:
        """For a recording's metadata: ``{"spec", "kind", "channel", "size", "unit", ...}``."""
        unit = "factor" if self.kind == "scale" else (
            "g" if self.axis < 3 else "dps" if self.axis < 6 else "uT")
        return {"spec": self.text(), "kind": self.kind, "channel": self.channel,
                "size": self.size, "unit": None if self.size is None else unit,
                "start_s": self.start_s, "end_s": self.end_s}

    def si_size(self) -> float:
        """SIZE in m/s^2, rad/s or uT (the factor itself for ``scale``; 0 without SIZE)."""
        if self.size is None:
            return 0.0
        if self.kind == "scale" or self.axis >= 6:
            return self.size
        return self.size * STANDARD_GRAVITY_M_S2 if self.axis < 3 else math.radians(self.size)


def parse_fault_spec(text: str, channels: tuple[str, ...] = CHANNELS) -> FaultSpec:
    """Parse ``KIND:CHANNEL[:SIZE]@START[-END]``, CHANNEL one of ``channels``.

    Raises
    ------
    ValueError
        With a message that says what is wrong and what is allowed.
    """
    form = "KIND:CHANNEL[:SIZE]@START[-END]"
    spec = text.strip()
    if "@" not in spec:
        raise ValueError(f"fault {text!r}: missing '@START' (expected {form}, e.g. "
                         "stuck:gx@10 or noise:az:0.01@5-15)")
    head, when = spec.rsplit("@", 1)
    parts = [p.strip().lower() for p in head.split(":")]
    if len(parts) not in (2, 3):
        raise ValueError(f"fault {text!r}: expected {form}")
    kind, channel = parts[0], parts[1]
    if kind not in FAULT_KINDS:
        raise ValueError(f"fault {text!r}: unknown kind {kind!r}; use one of "
                         f"{', '.join(FAULT_KINDS)}")
    if channel not in channels:
        hint = (" (mx..mz need a magnetometer: mag=lis3mdl)"
                if channel in MAG_CHANNELS and channel not in channels else "")
        raise ValueError(f"fault {text!r}: unknown channel {channel!r}; use one of "
                         f"{', '.join(channels)}{hint}")
    size: float | None = None
    if len(parts) == 3:
        if kind not in _NEEDS_SIZE:
            raise ValueError(f"fault {text!r}: {kind} takes no SIZE")
        size = _finite(text, "SIZE", parts[2])
    elif kind in _NEEDS_SIZE:
        raise ValueError(f"fault {text!r}: {kind} needs a SIZE ({FAULT_KINDS[kind]})")
    if kind == "noise" and size is not None and size <= 0:
        raise ValueError(f"fault {text!r}: the noise sigma must be positive")
    start_text, _, end_text = when.partition("-") if not when.startswith("-") else ("", "", "")
    if not start_text:
        raise ValueError(f"fault {text!r}: START must be a time >= 0 in seconds")
    start = _finite(text, "START", start_text)
    if start < 0:
        raise ValueError(f"fault {text!r}: START must be >= 0 s")
    end = None
    if end_text:
        end = _finite(text, "END", end_text)
        if end <= start:
            raise ValueError(f"fault {text!r}: END ({end:g} s) must be after START "
                             f"({start:g} s)")
    return FaultSpec(kind, channel, size, start, end)


def _finite(text: str, name: str, value: str) -> float:
    try:
        number = float(value)
    except ValueError:
        raise ValueError(f"fault {text!r}: {name} {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ValueError(f"fault {text!r}: {name} {value!r} is not a finite number")
    return number


class FaultInjector:
    """Applies fault specs to a stream of SI samples, block by block (state carries over).

    Parameters
    ----------
    specs : the faults, applied in order.
    seed : picks the injected noise.
    """

    def __init__(self, specs: Sequence[FaultSpec], seed: int = 0) -> None:
        self.specs = tuple(specs)
        self._rngs = [np.random.default_rng([seed, STREAM_FAULTS, i]) for i in range(len(specs))]
        self._held: list[float | None] = [None] * len(specs)
        self._next_spike = [s.start_s for s in specs]
        self._last_value = np.zeros(len(FAULT_CHANNELS))

    def apply(self, t_s: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Faulty copy of ``values`` (N, 6: ax..gz in m/s^2 and rad/s; N, 9 with mx..mz in uT)
        at times ``t_s``."""
        out = np.array(values, dtype=np.float64, copy=True)
        n = len(t_s)
        if n == 0:
            return out
        t = np.asarray(t_s, dtype=np.float64)
        for i, spec in enumerate(self.specs):
            end = math.inf if spec.end_s is None else spec.end_s
            active = (t >= spec.start_s) & (t < end)
            c = spec.axis
            if spec.kind == "spike":
                self._spikes(i, spec, t, out[:, c], end)
                continue
            if not active.any():
                continue
            if spec.kind == "noise":
                out[active, c] += self._rngs[i].standard_normal(int(active.sum())) * spec.si_size()
            elif spec.kind == "bias":
                out[active, c] += spec.si_size()
            elif spec.kind == "scale":
                out[active, c] *= spec.si_size()
            elif spec.kind == "dead":
                out[active, c] = 0.0
            elif spec.kind == "stuck":
                first = int(np.argmax(active))
                if self._held[i] is None:
                    self._held[i] = float(out[first - 1, c] if first > 0 else
                                          (self._last_value[c] if t[0] > spec.start_s
                                           else out[first, c]))
                out[active, c] = self._held[i]
        last = np.asarray(values, dtype=np.float64)[-1]
        self._last_value[: last.shape[0]] = last
        return out

    def _spikes(self, i: int, spec: FaultSpec, t: np.ndarray, column: np.ndarray,
                end: float) -> None:
        while self._next_spike[i] < end and self._next_spike[i] <= t[-1]:
            k = int(np.searchsorted(t, self._next_spike[i]))
            if k < len(t) and t[k] < end:
                column[k] += spec.si_size()
            self._next_spike[i] = (self._next_spike[i] + 1.0 if spec.end_s is not None
                                   else math.inf)
            if k < len(t):
                while self._next_spike[i] <= t[k]:
                    self._next_spike[i] += 1.0


KEY_INJECTED_FAULTS = "injected_faults"
"""Metadata key of a recording copied with faults injected (:func:`inject_recording`)."""
_INJECT_BLOCK = 4096


def inject_recording(source: str | os.PathLike[str], target: str | os.PathLike[str],
                     specs: Sequence[FaultSpec], seed: int = 0) -> int:
    """Copy a plain-text recording with ``specs`` applied to its ax..gz (and mx..mz) columns,
    START/END seconds from its first sample; every other byte of the header and the rows is
    kept, and the faults are listed under ``injected_faults`` in its metadata. Returns the
    rows copied.

    Raises
    ------
    ValueError
        A compressed recording, or one without a column a spec names.
    """
    from app.core.recording.edit import rewrite_metadata

    path = Path(source)
    with open(path, "rb") as probe:
        if probe.read(2) == b"\x1f\x8b":
            raise ValueError(f"{path}: a compressed recording; decompress it first")
    with open(path, encoding="utf-8", newline="") as handle:
        lines = handle.readlines()
    head = 0
    while head < len(lines) and lines[head].startswith("#"):
        head += 1
    if head >= len(lines):
        raise ValueError(f"{path}: no column header")
    names = [name.strip() for name in lines[head].strip().split(",")]
    wanted = [c for c in FAULT_CHANNELS if c in names]
    missing = [s.channel for s in specs if s.channel not in names]
    if missing or "t" not in names:
        raise ValueError(f"{path}: no column {(missing or ['t'])[0]!r}")
    index = [names.index(c) for c in wanted]
    time_index = names.index("t")
    rows = [line.rstrip("\r\n").split(",") for line in lines[head + 1:] if line.strip()]
    t = np.array([float(r[time_index]) for r in rows])
    t0 = float(t[0]) if len(t) else 0.0
    shifted = [FaultSpec(s.kind, s.channel, s.size, s.start_s + t0,
                         None if s.end_s is None else s.end_s + t0) for s in specs]
    injector = FaultInjector(shifted, seed)
    values = np.full((len(rows), len(FAULT_CHANNELS)), np.nan)
    for k, c in zip(index, wanted, strict=True):
        values[:, FAULT_CHANNELS.index(c)] = [float(r[k]) if r[k] else np.nan for r in rows]
    out = np.empty_like(values)
    for start in range(0, len(rows), _INJECT_BLOCK):
        stop = min(len(rows), start + _INJECT_BLOCK)
        out[start:stop] = injector.apply(t[start:stop], values[start:stop])
    with open(target, "w", encoding="utf-8", newline="") as handle:
        handle.writelines(lines[: head + 1])
        for i, row in enumerate(rows):
            for k, c in zip(index, wanted, strict=True):
                if row[k]:
                    row[k] = f"{out[i, FAULT_CHANNELS.index(c)]:.9g}"
            handle.write(",".join(row) + "\n")
    rewrite_metadata(target, {KEY_INJECTED_FAULTS: [s.as_dict() for s in specs]})
    return len(rows)
