"""``evaluate-faults``: the thesis's NDR / FDI / false-alarm sweep over simulator scenarios and
recordings (runs simulated devices, reads recordings; the measures are
:mod:`app.core.faults.evaluation`).

Each source is read clean once: a simulator URL for ``clean_seconds`` (the false alarms) of
which the first ``seconds`` take the injected noise, a recording whole for both. The noise is
added to those samples (:class:`~app.core.faults.injection.FaultInjector`), one channel and one
sigma at a time; the simulator's are rounded to the chip's LSB again. Sources are grouped for
the tables: ``simulator`` for ``sim://`` URLs, a recording's folder name otherwise (``broad``).
"""

from __future__ import annotations

import glob
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.core.calibration import MagnetometerCalibration
from app.core.faults import SensorSpec
from app.core.faults.detector import FaultDetector
from app.core.faults.evaluation import (
    DEADLINES_S,
    MOTION_FAULTS,
    NOISE_MULTIPLES,
    THETAS,
    GroupSummary,
    MotionRun,
    SourceSweep,
    clean_events,
    evaluation_json,
    field_trusting,
    motion_runs,
    sample_rows,
    summarize_group,
    sweep_samples,
)
from app.core.faults.events import CHANNELS, FaultEvent
from app.core.faults.recording import recorded_field_calibration
from app.core.recording.format import KEY_MAGNETOMETER
from app.core.recording.reader import read_recording
from app.core.samples import SampleBlock
from app.services.acquisition import Acquisition, Until
from app.services.connection import Connection
from app.services.diagnosis import recording_spec

SIMULATOR_GROUP = "simulator"
DEFAULT_SEED = 1
"""The simulated unit of ``scenarios`` (``sim://NAME?seed=1``)."""
NOT_SWEPT = ("interactive",)
"""Scenarios that need a user (they stand still without one)."""
GLOB_CHARACTERS = "*?["


@dataclass(slots=True)
class FaultEvaluationSettings:
    """How long, where and what to inject (see ``inclinometer evaluate-faults --help``)."""

    seconds: float = 60.0
    """Simulator streams the noise is injected into (recordings: whole)."""
    onset_s: float = 10.0
    """Noise from this many seconds after the first sample to the end."""
    clean_seconds: float = 600.0
    """Clean simulator streams for the false-alarm rate (at least ``seconds``)."""
    multiples: tuple[float, ...] = NOISE_MULTIPLES
    channels: tuple[str, ...] = CHANNELS
    thetas: tuple[int, ...] = THETAS
    seed: int = 0
    """Picks the injected noise."""

    def check(self) -> None:
        """Raises ValueError with the reason for settings that cannot run."""
        if not self.seconds > 0:
            raise ValueError("--seconds must be positive")
        if not 0 <= self.onset_s < self.seconds:
            raise ValueError(f"--onset must be at least 0 and below --seconds ({self.seconds:g})")
        if not self.multiples or any(not m > 0 for m in self.multiples):
            raise ValueError("the sigma multiples must be positive numbers")
        if not self.thetas or any(th < 1 for th in self.thetas):
            raise ValueError("theta must be whole numbers >= 1")
        unknown = [c for c in self.channels if c not in CHANNELS]
        if unknown or not self.channels:
            raise ValueError(f"unknown channel {unknown[0] if unknown else ''!r}; use some of "
                             f"{', '.join(CHANNELS)}")

    def as_dict(self) -> dict[str, Any]:
        return {"seconds": self.seconds, "onset_s": self.onset_s,
                "clean_seconds": max(self.clean_seconds, self.seconds),
                "sigma_multiples": list(self.multiples), "channels": list(self.channels),
                "thetas": list(self.thetas), "seed": self.seed}


@dataclass(slots=True)
class CleanStream:
    """A source read clean: what takes the noise, the longer stream for false alarms."""

    sweep: SampleBlock
    clean: SampleBlock
    spec: SensorSpec
    lsb: np.ndarray | None
    field_calibrated: bool = False
    """The field comes free of the sensor's own iron (a recording's without a calibration of
    its own, as BROAD's, calibrated by its authors): the gyro bias test may carry it."""
    field_calibration: MagnetometerCalibration | None = None
    """A recording's own magnetometer calibration (applied while it was recorded)."""

    def detector_for(self, make: Callable[[SensorSpec], FaultDetector] = FaultDetector
                     ) -> Callable[[SensorSpec], FaultDetector]:
        """How to make a detector for this stream: ``make``, told what to trust of the field
        (a simulator's raw field holds its board's hard iron: gravity alone)."""
        if self.field_calibration is None and not self.field_calibrated:
            return make
        return field_trusting(make, self.field_calibration)


@dataclass(slots=True)
class FaultSource:
    """A source named on the command line, checked but not read yet."""

    label: str
    group: str
    load: Callable[[FaultEvaluationSettings], CleanStream]
    path: Path | None = None


@dataclass(slots=True)
class FaultEvaluation:
    """The sweeps of every source and their group summaries."""

    settings: FaultEvaluationSettings
    sweeps: list[SourceSweep] = field(default_factory=list)
    groups: list[GroupSummary] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        """The ``--json`` document."""
        return evaluation_json(self.groups, self.sweeps, self.settings.as_dict())


# -- sources ---------------------------------------------------------------------------------------
def scenario_urls(seed: int = DEFAULT_SEED) -> list[str]:
    """Every simulator scenario but the interactive one, as ``sim://NAME?seed=SEED``."""
    from drivers.sim.scenarios import SCENARIOS

    return [f"sim://{name}?seed={seed}" for name in SCENARIOS if name not in NOT_SWEPT]


def resolve_fault_sources(items: Sequence[str]) -> list[FaultSource]:
    """``scenarios``, ``sim://`` URLs, recordings and globs of them, in order (each file once).

    Raises
    ------
    ValueError
        For a URL that is not a simulator (a live device cannot be made clean at will), a bad
        simulator URL, a missing file or a glob that matches nothing.
    """
    from drivers.errors import DeviceError, DeviceUrlError
    from drivers.registry import driver_for
    from drivers.sim.options import parse_sim_url

    sources: list[FaultSource] = []
    seen: set[Path] = set()

    def add_file(path: Path) -> None:
        if not path.is_file():
            raise ValueError(f"{path}: no such file")
        key = path.resolve()
        if key not in seen:
            seen.add(key)
            sources.append(FaultSource(path.stem, key.parent.name or "recordings",
                                       lambda settings, path=path: _recording_stream(path),  # type: ignore[misc]
                                       path))

    for item in items:
        if item == "scenarios":
            items_here = scenario_urls()
        elif "://" in item:
            items_here = [item]
        elif any(c in item for c in GLOB_CHARACTERS) and not Path(item).exists():
            matches = sorted(glob.glob(os.path.expanduser(item)))
            if not matches:
                raise ValueError(f"{item}: no file matches")
            for match in matches:
                add_file(Path(match))
            continue
        else:
            add_file(Path(item))
            continue
        for url in items_here:
            try:
                simulated = driver_for(url).knows_truth
            except DeviceError:
                simulated = False
            if not simulated:
                raise ValueError(f"{url}: only simulator URLs (sim://...) and recordings can be "
                                 "swept; a live device cannot be made clean at will")
            try:
                parse_sim_url(url)
            except DeviceUrlError as exc:
                raise ValueError(str(exc)) from None
            sources.append(FaultSource(url.removeprefix("sim://"), SIMULATOR_GROUP,
                                       lambda settings, url=url: _simulator_stream(url, settings)))  # type: ignore[misc]
    return sources


def _simulator_stream(url: str, settings: FaultEvaluationSettings) -> CleanStream:
    """The scenario's raw samples (no calibration: the detector sees what the chip says)."""
    from drivers.errors import DeviceIOError
    from drivers.sim.device import SimulatedDevice

    device = SimulatedDevice(url, realtime=False, block=65536)
    session = Acquisition(Connection(), detect_faults=False, check_lookalike=False)
    info = session.attach(device)
    blocks: list[SampleBlock] = []
    scale = device.scale
    wanted = max(1, round(max(settings.clean_seconds, settings.seconds) * device.odr_hz))
    try:
        for block in session.stream(Until(samples=wanted), 1.0):
            scale = block.raw.scale or scale
            blocks.append(block.uncalibrated)
    finally:
        session.close()
    error = session.ended.error
    if error is not None and not isinstance(error, DeviceIOError):  # fail_after: the end
        raise error
    clean = _join(blocks)
    clean = sample_rows(clean, 0, min(len(clean), wanted))
    sweep_n = min(len(clean), max(1, round(settings.seconds * device.odr_hz)))
    spec = SensorSpec.from_device_info(info, scale)
    lsb = np.array([scale.accel_m_s2_per_lsb] * 3 + [scale.gyro_rad_s_per_lsb] * 3)
    return CleanStream(sample_rows(clean, 0, sweep_n), clean, spec, lsb)


def _recording_stream(path: Path) -> CleanStream:
    recording = read_recording(path)
    samples = recording.sample_block(None)
    calibration = recorded_field_calibration(recording.metadata.get(KEY_MAGNETOMETER))
    return CleanStream(samples, samples, recording_spec(recording), None,
                       field_calibrated=calibration is None, field_calibration=calibration)


def _join(blocks: list[SampleBlock]) -> SampleBlock:
    if not blocks:
        raise ValueError("the simulator gave no samples")
    return SampleBlock(
        np.concatenate([b.t_s for b in blocks]), np.concatenate([b.accel_m_s2 for b in blocks]),
        np.concatenate([b.gyro_rad_s for b in blocks]),
        np.concatenate([b.temp_degc for b in blocks]), np.concatenate([b.gap for b in blocks]),
        mag_ut=(np.concatenate([b.mag_ut for b in blocks])
                if all(b.mag_ut is not None for b in blocks) else None))


# -- the run ---------------------------------------------------------------------------------------
def run_fault_evaluation(
    sources: Sequence[FaultSource], settings: FaultEvaluationSettings,
    progress: Callable[[str], None] | None = None,
) -> FaultEvaluation:
    """Sweep every source (one at a time, memory stays one source) and pool them per group.

    Raises
    ------
    ValueError, RecordingError, DeviceError
        When a source cannot be read or is shorter than the onset.
    """
    settings.check()
    result = FaultEvaluation(settings)
    channels = [CHANNELS.index(c) for c in settings.channels]
    for source in sources:
        started = time.perf_counter()
        stream = source.load(settings)
        sweep = sweep_samples(
            stream.sweep, stream.spec, label=source.label, group=source.group,
            onset_s=settings.onset_s, channels=channels, multiples=settings.multiples,
            thetas=settings.thetas, seed=settings.seed, lsb=stream.lsb, clean=stream.clean,
            detector=stream.detector_for())
        result.sweeps.append(sweep)
        if progress is not None:
            progress(f"{source.group}/{source.label}: {sweep.duration_s:.0f} s swept, "
                     f"{sweep.clean_seconds:.0f} s clean, {len(sweep.runs)} injections, "
                     f"{sweep.false_alarms} false alarm(s), "
                     f"{time.perf_counter() - started:.1f} s")
    groups: dict[str, list[SourceSweep]] = {}
    for sweep in result.sweeps:
        groups.setdefault(sweep.group, []).append(sweep)
    result.groups = [summarize_group(name, members) for name, members in groups.items()]
    return result


# -- faults while the sensor moves (issue 33) ------------------------------------------------------
@dataclass(slots=True)
class MotionSource:
    """One source of the in-motion evaluation: its runs and its clean alarms."""

    label: str
    group: str
    onset_s: float
    moving_at_onset: bool | None
    """The recording's ``movement`` column at the onset (None: the source has none)."""
    clean_seconds: float
    clean_events: list[FaultEvent]
    runs: list[MotionRun]


def run_motion_evaluation(
    sources: Sequence[FaultSource], onset_s: float,
    faults: Sequence[tuple[str, str, float | None]] = MOTION_FAULTS, seed: int = 0,
    clean_seconds: float = 600.0, detector: Callable[[SensorSpec], FaultDetector] = FaultDetector,
    progress: Callable[[str], None] | None = None,
) -> list[MotionSource]:
    """Every fault of ``faults`` injected alone at ``onset_s`` into each source (a recording
    whole, a simulator stream of ``onset_s`` + 14 s), and the clean alarms (a recording
    whole, ``clean_seconds`` of a simulator).

    Raises
    ------
    ValueError, RecordingError, DeviceError
        When a source cannot be read or ends before the onset.
    """
    settings = FaultEvaluationSettings(seconds=onset_s + max(DEADLINES_S.values()) + 4.0,
                                       onset_s=onset_s, clean_seconds=clean_seconds)
    results = []
    for source in sources:
        started = time.perf_counter()
        stream = source.load(settings)
        moving = None
        if source.group != SIMULATOR_GROUP:
            moving = _moving_at(source, onset_s)
        made = stream.detector_for(detector)
        runs = motion_runs(stream.sweep, stream.spec, source=source.label, onset_s=onset_s,
                           faults=faults, seed=seed, lsb=stream.lsb, detector=made)
        clean = clean_events(stream.clean, stream.spec, made)
        seconds = float(stream.clean.t_s[-1] - stream.clean.t_s[0]) if len(stream.clean) else 0.0
        results.append(MotionSource(source.label, source.group, onset_s, moving, seconds, clean,
                                    runs))
        if progress is not None:
            found = sum(r.isolated for r in runs)
            progress(f"{source.group}/{source.label}: {found} of {len(runs)} faults found on "
                     f"their channel in time, {len(clean)} false alarm(s), "
                     f"{time.perf_counter() - started:.1f} s")
    return results


def _moving_at(source: FaultSource, onset_s: float) -> bool | None:
    path = getattr(source, "path", None)
    if path is None:
        return None
    recording = read_recording(path)
    column = recording.unknown_columns.get("movement")
    if column is None or not len(recording):
        return None
    index = int(np.searchsorted(recording.t_s, recording.t_s[0] + onset_s))
    return bool(np.asarray(column)[min(index, len(recording) - 1)] > 0.5)
