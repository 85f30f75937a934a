"""Streams from the simulator, for scoring filters and measuring motion (runs a device).

:func:`simulator_blocks` reads a ``sim://`` URL as fast as it computes (no pacing), with the
unit's static errors compensated by their true values; :func:`simulator_source` wraps it as an
:class:`~app.core.evaluation.StreamSource` and :func:`standard_sources` is the set of scenarios
``inclinometer evaluate scenarios`` scores. The scoring itself is :mod:`app.core.evaluation`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

from app.core.calibration import SensorCalibration
from app.core.evaluation import (
    StreamSource,
    calibration_from_unit_errors,
    concatenate_blocks,
    with_gap,
)
from app.core.motion_stats import MotionStats, block_stats
from app.core.samples import SampleBlock
from app.services.acquisition import Acquisition, Until
from app.services.connection import Connection
from drivers.errors import DeviceError, DeviceIOError
from drivers.sim.device import SimulatedDevice
from drivers.sim.options import parse_sim_url


def simulator_blocks(
    url: str, seconds: float, *, compensate: bool = True, block: int = 65536
) -> Iterator[SampleBlock]:
    """The first ``seconds`` of a ``sim://`` URL as SampleBlocks (not paced: realtime off).

    A ``fail_after`` option in the URL ends the stream early.

    With ``compensate`` (the default) the unit's static errors (scale, cross-axis, bias) are
    removed with its true values (:func:`calibration_from_unit_errors`), so the scores show the
    filters rather than an uncalibrated sensor.
    """
    device = SimulatedDevice(url, realtime=False, block=block)
    calibration = (
        calibration_from_unit_errors(device.unit_errors) if compensate else SensorCalibration()
    )
    session = Acquisition(Connection(), calibration=calibration, detect_faults=False,
                          check_lookalike=False)
    session.attach(device)
    try:
        for samples in session.stream(Until(samples=max(1, round(seconds * device.odr_hz))),
                                      1.0):
            yield samples.samples
    finally:
        session.close()
    _raise_unless_cut(session.ended.error)


def _raise_unless_cut(error: DeviceError | None) -> None:
    """A simulator's ``fail_after`` (DeviceIOError) ends its stream, as a recording would
    end; any other failure is raised."""
    if error is not None and not isinstance(error, DeviceIOError):
        raise error


def simulator_source(
    url: str, seconds: float, *, compensate: bool = True, gap: tuple[float, float] | None = None,
    label: str | None = None, description: str = "",
) -> StreamSource:
    """A :class:`StreamSource` for a simulator URL; ``gap`` = (start s, length s) drops samples.

    Raises :class:`drivers.errors.DeviceUrlError` at once for a bad URL.
    """
    parse_sim_url(url)

    def blocks() -> Iterable[SampleBlock]:
        stream = simulator_blocks(url, seconds, compensate=compensate)
        if gap is None:
            return stream
        return [with_gap(concatenate_blocks(stream), *gap)]

    return StreamSource(label or url, blocks, description)


# -- the standard set ------------------------------------------------------------------------
MOTION_SCENARIOS = (
    "static", "slow-tilt", "wobble", "vibration", "translation", "handheld", "strokes", "tour",
)
"""Simulator scenarios with a scripted motion (``interactive`` waits for the user)."""
SCENARIO_ODR_HZ = 208
LONG_REST_S = 3600.0


def standard_sources(
    seconds: float = 60.0, *, compensate: bool = True, seed: int = 1
) -> list[StreamSource]:
    """Every motion scenario for ``seconds``, plus the hard cases.

    Hard cases: an hour at rest at 26 Hz (always an hour: slow drifts show there), a hand-held
    wobble around 90 degrees of pitch, one upside down, and the six-face tour with 2.5 s of
    samples lost over its half turn from +x up to -x up (the filter must find the new attitude
    after the gap).
    """
    def url(name: str, odr: float = SCENARIO_ODR_HZ, **params: float) -> str:
        query = "&".join([f"odr={odr:g}", f"seed={seed}", *(f"{k}={v:g}" for k, v in
                                                            params.items())])
        return f"sim://{name}?{query}"

    sources = [simulator_source(url(name), seconds, compensate=compensate)
               for name in MOTION_SCENARIOS]
    sources += [
        simulator_source(url("static", 26), LONG_REST_S, compensate=compensate,
                         description="an hour at rest"),
        simulator_source(url("wobble", pitch=90, roll=0), seconds, compensate=compensate,
                         description="hand-held at 90 degrees of pitch"),
        simulator_source(url("wobble", roll=180, pitch=0), seconds, compensate=compensate,
                         description="hand-held upside down"),
        simulator_source(url("tour"), max(seconds, 30.0), compensate=compensate,
                         gap=(21.5, 2.5), label=url("tour") + " + gap 21.5-24 s",
                         description="2.5 s of samples lost during a half turn"),
    ]
    return sources


def simulator_stats(url: str, seconds: float) -> MotionStats:
    """The figures of the first ``seconds`` of a ``sim://`` stream, its true orientation as the
    reference and the unit's static errors compensated (as ``inclinometer evaluate`` does).

    No movement flag: the moving samples are those not at rest.
    """
    return block_stats(concatenate_blocks(simulator_blocks(url, seconds)))
