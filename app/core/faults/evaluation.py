"""The thesis's measures of a fault detector, over arrays: NDR, FDI and the false-alarm rate.

The founding thesis evaluated its self-testing system by injecting white Gaussian noise of
growing standard deviation sigma into one input channel at a time and measuring:

- **NDR(channel, sigma)**, the fraction of samples the detector flags faulty (0..1) from the
  onset of the injected noise on. Measured on every channel, not only the injected one: the
  clean channels should stay near 0 (:attr:`InjectionRun.ndr` is the whole row).
- **FDI(channel, sigma, theta)**, the number of samples from the onset until a fault is
  declared, a fault being declared when the cumulative count of samples flagged on the
  injected channel reaches the threshold theta (:func:`fdi`).

Here "flagged" is :attr:`FaultDetector.flags`, any bit on the channel (stuck, dead, spike,
saturation or, while the noise test holds, noise). On clean data the false-alarm rate is the
detector's events (not samples) per hour; ``link`` events (lost samples, true events) do not
count.

sigma is given as multiples of the channel's own white noise per sample (:func:`own_noise`):
the datasheet's when the sensor is known, else estimated from the quiet parts of the clean
data (:func:`estimate_noise_sigma`). :func:`sweep_samples` does one source,
:func:`summarize_group` pools sources. Everything here is arrays in, numbers out; reading the
simulator and recordings is :mod:`app.services.fault_evaluation`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.core.calibration import MagnetometerCalibration
from app.core.faults.detector import D4_GAIN, FaultDetector
from app.core.faults.events import CHANNELS, FaultEvent
from app.core.faults.injection import FaultInjector, FaultSpec
from app.core.faults.spec import SensorSpec
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock

NOISE_MULTIPLES: tuple[float, ...] = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
"""Injected sigma in multiples of the channel's own noise per sample (the default sweep)."""
THETAS: tuple[int, ...] = (1, 10, 100)
"""Detection thresholds on the cumulative count of flagged samples (the default FDI)."""
BLOCK_S = 0.1
"""Blocks fed to the detector, as a live stream would (the results do not depend on it)."""
NOISE_WINDOW_S = 0.25
NOISE_QUIET_PERCENTILE = 10.0
NOISE_QUIET_SPAN = 2.5
"""The own noise of unknown sensors: the mean white-noise level of the quiet 0.25 s windows,
those within 2.5x the 10th percentile of all (motion only ever adds to the 4th difference; the
percentile alone would read white noise ~30 % low, as a window's level scatters ~25 %; this
reads it within 1 %)."""


# -- measures ----------------------------------------------------------------------------------
def ndr(flags: np.ndarray, start: int = 0) -> np.ndarray:
    """Fraction of samples flagged (any bit) per channel from row ``start`` on; (6,) in 0..1."""
    part = np.asarray(flags)[start:]
    if len(part) == 0:
        return np.zeros(part.shape[1] if part.ndim == 2 else len(CHANNELS))
    return np.count_nonzero(part, axis=0) / float(len(part))


def fdi(flagged: np.ndarray, thetas: Sequence[int] = THETAS) -> dict[int, int | None]:
    """Samples until the cumulative count of ``flagged`` (bool per sample, from the onset)
    reaches each theta: ``k + 1`` where sample ``k`` is the theta-th flagged one; None never."""
    where = np.flatnonzero(np.asarray(flagged, dtype=bool))
    return {int(theta): (int(where[theta - 1]) + 1 if len(where) >= theta else None)
            for theta in thetas}


def counted_events(events: Sequence[FaultEvent]) -> list[FaultEvent]:
    """The events that are alarms about the sensor (``link`` events are lost samples)."""
    return [event for event in events if event.channel != "link"]


def per_hour(count: int, seconds: float) -> float:
    """Events per hour (NaN without any time)."""
    return count / (seconds / 3600.0) if seconds > 0 else math.nan


# -- noise ---------------------------------------------------------------------------------------
def estimate_noise_sigma(values: np.ndarray, odr_hz: float) -> np.ndarray:
    """White-noise sigma per channel of (N, C) ``values`` sampled at ``odr_hz``.

    The mean absolute 4th difference (``sqrt(70) sigma sqrt(2/pi)`` for white noise, smooth
    motion suppressed by ``(2 pi f / ODR)^4``) per 0.25 s window; the mean over the quiet
    windows (:data:`NOISE_QUIET_SPAN`): what the detector learns at rest.
    """
    x = np.asarray(values, dtype=np.float64)
    if len(x) < 5:
        return np.full(x.shape[1], math.nan)
    d4 = np.abs(np.diff(x, n=4, axis=0))
    window = max(8, round(NOISE_WINDOW_S * odr_hz))
    whole = len(d4) // window
    if whole == 0:
        return d4.mean(axis=0) / D4_GAIN
    levels = d4[: whole * window].reshape(whole, window, -1).mean(axis=1)
    low = np.percentile(levels, NOISE_QUIET_PERCENTILE, axis=0)
    sigma = np.empty(levels.shape[1])
    for c in range(levels.shape[1]):
        quiet = levels[:, c][levels[:, c] <= NOISE_QUIET_SPAN * low[c]]
        sigma[c] = float(np.mean(quiet)) / D4_GAIN
    return sigma


def own_noise(samples: SampleBlock, spec: SensorSpec) -> tuple[np.ndarray, str]:
    """Each channel's own white noise per sample (SI, (6,)) and where it comes from.

    The datasheet's (through ``spec``) when the sensor is known, else
    :func:`estimate_noise_sigma` over ``samples``.
    """
    if spec.accel_noise_rms_m_s2 is not None and spec.gyro_noise_rms_rad_s is not None:
        sigma = np.array([spec.accel_noise_rms_m_s2] * 3 + [spec.gyro_noise_rms_rad_s] * 3)
        return sigma, "datasheet"
    return estimate_noise_sigma(_values(samples), spec.odr_hz), "estimated at rest"


def to_user_units(channel: int, value_si: float) -> float:
    """m/s^2 -> g on ax..az, rad/s -> dps on gx..gz (FaultSpec's SIZE units)."""
    return value_si / STANDARD_GRAVITY_M_S2 if channel < 3 else math.degrees(value_si)


def unit_of(channel: int) -> str:
    """``"g"`` or ``"dps"``."""
    return "g" if channel < 3 else "dps"


# -- running the detector --------------------------------------------------------------------------
@dataclass(slots=True)
class DetectorRun:
    """The detector over one stream: per-sample flags (N, 6) and the events."""

    flags: np.ndarray
    events: list[FaultEvent]


def run_detector(samples: SampleBlock, spec: SensorSpec, block_s: float = BLOCK_S,
                 detector_for: Callable[[SensorSpec], FaultDetector] = FaultDetector,
                 ) -> DetectorRun:
    """A fresh detector (``detector_for``: how to make one) over ``samples`` in blocks of
    ``block_s``."""
    detector = detector_for(spec)
    n = len(samples)
    size = max(1, round(block_s * spec.odr_hz))
    flags = np.zeros((n, len(CHANNELS)), dtype=np.uint8)
    events: list[FaultEvent] = []
    for start in range(0, n, size):
        stop = min(n, start + size)
        events += detector.update(sample_rows(samples, start, stop))
        flags[start:stop] = detector.flags
    return DetectorRun(flags, events)


def field_trusting(make: Callable[[SensorSpec], FaultDetector] = FaultDetector,
                   calibration: MagnetometerCalibration | None = None,
                   ) -> Callable[[SensorSpec], FaultDetector]:
    """``make``, its detectors told to carry the field as the earth's in the gyro bias test:
    as it comes (a recording's, such as BROAD's, calibrated by its authors), or through
    ``calibration`` (a recording's own). A simulator's raw field holds the board's hard iron
    and must not be given to them."""
    def made(spec: SensorSpec) -> FaultDetector:
        detector = make(spec)
        if calibration is None:
            detector.field_calibrated = True
        else:
            detector.field_calibration = calibration
        return detector
    return made


def inject(samples: SampleBlock, specs: Sequence[FaultSpec], seed: int = 0,
           lsb: np.ndarray | None = None) -> SampleBlock:
    """``samples`` with the faults of ``specs`` applied (:class:`FaultInjector`, one pass).

    ``lsb`` (6,) SI, when known: the result is rounded to it again, as the chip's output
    stage would (0 or NaN on a channel: left as is).
    """
    values = FaultInjector(specs, seed).apply(samples.t_s, _values(samples))
    if lsb is not None:
        q = np.asarray(lsb, dtype=np.float64)
        ok = np.isfinite(q) & (q > 0)
        values[:, ok] = np.rint(values[:, ok] / q[ok]) * q[ok]
    return SampleBlock(samples.t_s, np.ascontiguousarray(values[:, :3]),
                       np.ascontiguousarray(values[:, 3:]), samples.temp_degc, samples.gap,
                       samples.reference_quat, samples.mag_ut)


# -- one source ------------------------------------------------------------------------------------
@dataclass(slots=True)
class InjectionRun:
    """Noise of ``sigma_si`` on channel ``channel`` (0..5) from the onset on."""

    channel: int
    multiple: float
    sigma_si: float
    ndr: np.ndarray
    """(6,) fraction flagged on every channel, from the onset on."""
    fdi: dict[int, int | None]
    """theta -> samples from the onset until declared (None: never)."""
    first_event_s: float | None
    """Seconds from the onset to the first event on the injected channel (None: none)."""

    def as_dict(self) -> dict[str, Any]:
        return {
            "channel": CHANNELS[self.channel], "multiple": self.multiple,
            "sigma": to_user_units(self.channel, self.sigma_si), "unit": unit_of(self.channel),
            "ndr": dict(zip(CHANNELS, (float(v) for v in self.ndr), strict=True)),
            "fdi": {str(k): v for k, v in self.fdi.items()},
            "first_event_s": self.first_event_s,
        }


@dataclass(slots=True)
class SourceSweep:
    """Every measure on one source (see the module docstring)."""

    label: str
    group: str
    rate_hz: float
    samples: int
    duration_s: float
    onset_s: float
    injected_samples: int
    """Samples from the onset to the end (NDR's denominator)."""
    noise_si: np.ndarray
    """(6,) the channels' own white noise per sample, SI."""
    noise_basis: str
    clean_seconds: float
    clean_events: list[FaultEvent]
    clean_ndr: np.ndarray
    """(6,) fraction of clean samples flagged, over the whole clean stream."""
    runs: list[InjectionRun] = field(default_factory=list)

    @property
    def false_alarms(self) -> int:
        return len(counted_events(self.clean_events))

    def run(self, channel: int, multiple: float) -> InjectionRun | None:
        return next((r for r in self.runs if r.channel == channel and r.multiple == multiple),
                    None)

    def as_dict(self) -> dict[str, Any]:
        return {
            "label": self.label, "group": self.group, "rate_hz": self.rate_hz,
            "samples": self.samples, "duration_s": self.duration_s, "onset_s": self.onset_s,
            "injected_samples": self.injected_samples,
            "own_noise": {name: to_user_units(c, float(self.noise_si[c]))
                          for c, name in enumerate(CHANNELS)},
            "own_noise_units": {name: unit_of(c) for c, name in enumerate(CHANNELS)},
            "own_noise_basis": self.noise_basis,
            "clean": {
                "seconds": self.clean_seconds, "false_alarms": self.false_alarms,
                "per_hour": _finite(per_hour(self.false_alarms, self.clean_seconds)),
                "events": [e.as_dict() for e in self.clean_events],
                "ndr": dict(zip(CHANNELS, (float(v) for v in self.clean_ndr), strict=True)),
            },
            "injections": [r.as_dict() for r in self.runs],
        }


def sweep_samples(
    samples: SampleBlock, spec: SensorSpec, *, label: str, group: str, onset_s: float,
    channels: Sequence[int] = tuple(range(6)), multiples: Sequence[float] = NOISE_MULTIPLES,
    thetas: Sequence[int] = THETAS, seed: int = 0, lsb: np.ndarray | None = None,
    clean: SampleBlock | None = None, progress: Callable[[str], None] | None = None,
    detector: Callable[[SensorSpec], FaultDetector] = FaultDetector,
) -> SourceSweep:
    """NDR, FDI and false alarms of one source.

    ``samples`` are the clean stream the noise is injected into (from ``onset_s`` seconds
    after its first sample to its end); ``clean`` a longer clean stream beginning with the
    same samples for the false alarms (default: ``samples``). ``lsb`` re-quantises what is
    injected (a simulated chip). ``progress`` gets a line per channel; ``detector``: how to
    make a detector for the source (:func:`field_trusting`).
    """
    if len(samples) == 0:
        raise ValueError(f"{label}: no samples")
    t0 = float(samples.t_s[0])
    onset = t0 + onset_s
    start = int(np.searchsorted(samples.t_s, onset, side="left"))
    if start >= len(samples):
        raise ValueError(f"{label}: the onset ({onset_s:g} s) is after the end "
                         f"({float(samples.t_s[-1]) - t0:.1f} s)")
    clean = samples if clean is None else clean
    clean_run = run_detector(clean, spec, detector_for=detector)
    noise, basis = own_noise(clean, spec)
    clean_s = _duration(clean, spec.odr_hz)
    sweep = SourceSweep(label, group, spec.odr_hz, len(samples), _duration(samples, spec.odr_hz),
                        onset_s, len(samples) - start, noise, basis, clean_s, clean_run.events,
                        ndr(clean_run.flags))
    for c in channels:
        if progress is not None:
            progress(f"{label}: noise on {CHANNELS[c]}")
        for multiple in multiples:
            sigma = float(multiple * noise[c])
            if not (math.isfinite(sigma) and sigma > 0):
                continue
            fault = FaultSpec("noise", CHANNELS[c], to_user_units(c, sigma), onset)
            result = run_detector(inject(samples, [fault], seed, lsb), spec,
                                  detector_for=detector)
            first = next((e.t - onset for e in result.events
                          if e.channel == CHANNELS[c] and e.t >= onset), None)
            sweep.runs.append(InjectionRun(
                c, float(multiple), sigma, ndr(result.flags, start),
                fdi(result.flags[start:, c] != 0, thetas),
                None if first is None else round(float(first), 6)))
    return sweep


# -- several sources -------------------------------------------------------------------------------
@dataclass(slots=True)
class GroupSummary:
    """Sources of one kind pooled (the simulator's scenarios, a folder of recordings).

    ``ndr[c][k]`` is the row (6,) of NDR on every channel with noise on channel ``c`` at
    ``multiples[k]``, pooled over the sources (flagged samples over samples); ``fdi[theta][c][k]``
    the median over the sources where the fault was declared (None: in none) and
    ``detected[theta][c][k]`` in how many of them it was.
    """

    name: str
    sources: list[str]
    multiples: list[float]
    channels: list[int]
    thetas: list[int]
    ndr: dict[int, list[np.ndarray]]
    fdi: dict[int, dict[int, list[float | None]]]
    detected: dict[int, dict[int, list[int]]]
    clean_ndr: np.ndarray
    clean_seconds: float
    false_alarms: int
    rates_hz: list[float]

    @property
    def false_alarms_per_hour(self) -> float:
        return per_hour(self.false_alarms, self.clean_seconds)

    def ndr_injected(self, c: int) -> list[float]:
        """NDR on the injected channel per multiple."""
        return [float(row[c]) for row in self.ndr[c]]

    def ndr_others_max(self, c: int) -> list[float]:
        """The largest NDR on the other five channels per multiple."""
        return [float(np.max(np.delete(row, c))) for row in self.ndr[c]]

    def as_dict(self) -> dict[str, Any]:
        names = [CHANNELS[c] for c in self.channels]
        return {
            "sources": self.sources, "sigma_multiples": self.multiples, "channels": names,
            "thetas": self.thetas, "rates_hz": sorted(set(self.rates_hz)),
            "ndr": {CHANNELS[c]: [dict(zip(CHANNELS, map(float, row), strict=True))
                                  for row in self.ndr[c]] for c in self.channels},
            "ndr_injected": {CHANNELS[c]: self.ndr_injected(c) for c in self.channels},
            "ndr_others_max": {CHANNELS[c]: self.ndr_others_max(c) for c in self.channels},
            "fdi_samples": {str(th): {CHANNELS[c]: self.fdi[th][c] for c in self.channels}
                            for th in self.thetas},
            "fdi_detected": {str(th): {CHANNELS[c]: self.detected[th][c]
                                       for c in self.channels} for th in self.thetas},
            "clean": {
                "hours": self.clean_seconds / 3600.0, "false_alarms": self.false_alarms,
                "per_hour": _finite(self.false_alarms_per_hour),
                "ndr": dict(zip(CHANNELS, map(float, self.clean_ndr), strict=True)),
            },
        }


def summarize_group(name: str, sweeps: Sequence[SourceSweep]) -> GroupSummary:
    """Pool the sweeps of one group (see :class:`GroupSummary`)."""
    if not sweeps:
        raise ValueError(f"group {name!r} has no sources")
    multiples = sorted({r.multiple for s in sweeps for r in s.runs})
    channels = sorted({r.channel for s in sweeps for r in s.runs})
    thetas = sorted({th for s in sweeps for r in s.runs for th in r.fdi})
    table: dict[int, list[np.ndarray]] = {}
    fdi_median: dict[int, dict[int, list[float | None]]] = {th: {} for th in thetas}
    detected: dict[int, dict[int, list[int]]] = {th: {} for th in thetas}
    for c in channels:
        rows = []
        for th in thetas:
            fdi_median[th][c] = []
            detected[th][c] = []
        for m in multiples:
            flagged = np.zeros(len(CHANNELS))
            counted = 0
            per_theta: dict[int, list[float]] = {th: [] for th in thetas}
            for sweep in sweeps:
                run = sweep.run(c, m)
                if run is None:
                    continue
                after = sweep.injected_samples
                flagged += run.ndr * after
                counted += after
                for th in thetas:
                    value = run.fdi.get(th)
                    per_theta[th].append(math.inf if value is None else float(value))
            rows.append(flagged / counted if counted else np.full(len(CHANNELS), math.nan))
            for th in thetas:
                declared = [v for v in per_theta[th] if math.isfinite(v)]
                fdi_median[th][c].append(float(np.median(declared)) if declared else None)
                detected[th][c].append(len(declared))
        table[c] = rows
    weights = np.array([s.clean_seconds for s in sweeps])
    clean_ndr = (np.sum([s.clean_ndr * w for s, w in zip(sweeps, weights, strict=True)], axis=0)
                 / max(float(weights.sum()), 1e-300))
    return GroupSummary(
        name, [s.label for s in sweeps], multiples, channels, thetas, table, fdi_median,
        detected, clean_ndr, float(weights.sum()), sum(s.false_alarms for s in sweeps),
        [s.rate_hz for s in sweeps])


def evaluation_json(groups: Sequence[GroupSummary], sweeps: Sequence[SourceSweep],
                    settings: dict[str, Any]) -> dict[str, Any]:
    """The whole evaluation as one JSON document (``evaluate-faults --json``)."""
    return {
        "measure": {
            "ndr": "fraction of samples flagged faulty from the onset of the injected noise "
                   "on, per injected channel (rows) and flagged channel",
            "fdi": "samples from the onset until the cumulative count of samples flagged on "
                   "the injected channel reaches theta; median over the sources where it is "
                   "reached (fdi_detected: how many), null when none",
            "false_alarms": "detector events (link events excluded) on the clean sources, "
                            "per hour",
            "sigma": "multiples of each channel's own white noise per sample",
        },
        "settings": settings,
        "groups": {g.name: g.as_dict() for g in groups},
        "sources": [s.as_dict() for s in sweeps],
    }


# -- helpers ---------------------------------------------------------------------------------------
def _values(samples: SampleBlock) -> np.ndarray:
    return np.hstack([samples.accel_m_s2, samples.gyro_rad_s]).astype(np.float64)


def sample_rows(samples: SampleBlock, start: int, stop: int) -> SampleBlock:
    """Rows ``start:stop`` of ``samples`` (views), the field's too when there is one."""
    ref, mag = samples.reference_quat, samples.mag_ut
    return SampleBlock(samples.t_s[start:stop], samples.accel_m_s2[start:stop],
                       samples.gyro_rad_s[start:stop], samples.temp_degc[start:stop],
                       samples.gap[start:stop], None if ref is None else ref[start:stop],
                       None if mag is None else mag[start:stop])


def _duration(samples: SampleBlock, odr_hz: float) -> float:
    """Seconds covered, one sample period per sample."""
    if len(samples) == 0:
        return 0.0
    return float(samples.t_s[-1] - samples.t_s[0]) + 1.0 / odr_hz


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


# -- faults injected while the sensor moves (issue 33) -------------------------------------------
MOTION_FAULTS: tuple[tuple[str, str, float], ...] = (
    *(("noise", ch, size) for size in (1.0, 2.9) for ch in ("gx", "gy", "gz")),
    *(("noise", ch, size) for size in (0.2 / STANDARD_GRAVITY_M_S2, 0.5 / STANDARD_GRAVITY_M_S2)
      for ch in ("ax", "ay", "az")),
    *(("bias", ch, 2.0) for ch in ("gx", "gy", "gz")),
)
"""The default faults of ``evaluate-faults --in-motion``: noise of 1 and 2.9 dps on each gyro
axis, 0.2 and 0.5 m/s^2 on each accelerometer axis, a 2 dps bias step on each gyro axis
(FaultSpec units: g and dps)."""
DEADLINES_S: dict[str, float] = {"noise": 2.0, "bias": 10.0, "stuck": 2.0, "dead": 2.0,
                                 "spike": 2.0, "scale": 10.0}
"""Seconds from the onset within which a fault counts as found (issue 33's goal)."""
MOTION_MARGIN_S = 2.0
"""Samples read past the deadline (the detector runs only to there: the rest is not needed)."""


@dataclass(slots=True)
class MotionRun:
    """One fault injected at ``onset_s`` (seconds after the first sample) of one source."""

    source: str
    spec: FaultSpec
    deadline_s: float
    delay_s: float | None
    """Seconds from the onset to the first event (any channel, link excluded); None: none."""
    first_channel: str | None
    first_kind: str | None

    @property
    def detected(self) -> bool:
        return self.delay_s is not None and self.delay_s <= self.deadline_s

    @property
    def isolated(self) -> bool:
        """Found in time, and the first event names the injected channel."""
        return self.detected and self.first_channel == self.spec.channel

    def label(self) -> str:
        return motion_label(self.spec)

    def as_dict(self) -> dict[str, Any]:
        return {"source": self.source, "fault": self.spec.text(), "label": self.label(),
                "deadline_s": self.deadline_s, "delay_s": self.delay_s,
                "first_channel": self.first_channel, "first_kind": self.first_kind,
                "detected": self.detected, "isolated": self.isolated}


def motion_label(spec: FaultSpec) -> str:
    """``"gy noise 1 dps"``, ``"ax noise 0.2 m/s^2"``: the size in the units of the goal."""
    size = spec.size or 0.0
    if spec.kind in ("noise", "bias", "spike") and spec.axis < 3:
        text = f"{size * STANDARD_GRAVITY_M_S2:.2g} m/s^2"
    elif spec.kind in ("noise", "bias", "spike"):
        text = f"{size:g} dps"
    else:
        text = "" if spec.size is None else f"{size:g}"
    return f"{spec.channel} {spec.kind} {text}".strip()


def motion_runs(samples: SampleBlock, spec: SensorSpec, *, source: str, onset_s: float,
                faults: Sequence[tuple[str, str, float | None]] = MOTION_FAULTS, seed: int = 0,
                lsb: np.ndarray | None = None,
                detector: Callable[[SensorSpec], FaultDetector] = FaultDetector,
                ) -> list[MotionRun]:
    """Each fault of ``faults`` (kind, channel, FaultSpec size) injected alone from
    ``onset_s`` seconds after the first sample to the end; the detector (``detector``: how to
    make one) runs from the start to the fault's deadline plus :data:`MOTION_MARGIN_S`."""
    t0 = float(samples.t_s[0])
    onset = t0 + onset_s
    if onset >= float(samples.t_s[-1]):
        raise ValueError(f"{source}: the onset ({onset_s:g} s) is after the end")
    runs = []
    for kind, channel, size in faults:
        fault = FaultSpec(kind, channel, size, onset)
        deadline = DEADLINES_S.get(kind, 10.0)
        stop = int(np.searchsorted(samples.t_s, onset + deadline + MOTION_MARGIN_S))
        part = sample_rows(samples, 0, stop)
        events = _events_of(inject(part, [fault], seed, lsb), spec, detector)
        first = next((e for e in counted_events(events) if e.t >= onset), None)
        runs.append(MotionRun(source, fault, deadline,
                              None if first is None else round(first.t - onset, 6),
                              None if first is None else first.channel,
                              None if first is None else first.kind))
    return runs


def clean_events(samples: SampleBlock, spec: SensorSpec,
                 detector: Callable[[SensorSpec], FaultDetector] = FaultDetector
                 ) -> list[FaultEvent]:
    """The alarms (link events excluded) of a fresh detector over a clean stream."""
    return counted_events(_events_of(samples, spec, detector))


def _events_of(samples: SampleBlock, spec: SensorSpec,
               detector: Callable[[SensorSpec], FaultDetector]) -> list[FaultEvent]:
    made = detector(spec)
    size = max(1, round(BLOCK_S * spec.odr_hz))
    events: list[FaultEvent] = []
    for start in range(0, len(samples), size):
        events += made.update(sample_rows(samples, start, min(len(samples), start + size)))
    return events


@dataclass(slots=True)
class MotionRow:
    """One fault (label) pooled over sources: NDR, FDI, delays."""

    label: str
    runs: list[MotionRun]

    @property
    def ndr(self) -> float:
        """Share of the injections found within the deadline (on any channel)."""
        return sum(r.detected for r in self.runs) / len(self.runs)

    @property
    def fdi(self) -> float:
        """Share of the injections found within the deadline on the injected channel."""
        return sum(r.isolated for r in self.runs) / len(self.runs)

    def delays(self) -> list[float]:
        return sorted(r.delay_s for r in self.runs if r.detected and r.delay_s is not None)

    def as_dict(self) -> dict[str, Any]:
        delays = self.delays()
        return {"fault": self.label, "injections": len(self.runs), "ndr": self.ndr,
                "fdi": self.fdi, "delay_median_s": float(np.median(delays)) if delays else None,
                "delay_max_s": delays[-1] if delays else None,
                "missed": [r.source for r in self.runs if not r.detected],
                "wrong_channel": [f"{r.source}: {r.first_channel} {r.first_kind}"
                                  for r in self.runs if r.detected and not r.isolated]}


def motion_table(runs: Sequence[MotionRun]) -> list[MotionRow]:
    """The runs pooled per fault label, in the order first seen."""
    rows: dict[str, list[MotionRun]] = {}
    for run in runs:
        rows.setdefault(run.label(), []).append(run)
    return [MotionRow(label, members) for label, members in rows.items()]
