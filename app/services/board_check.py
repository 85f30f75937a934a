"""The streaming parts of ``check-board``, through the acquisition session (no Qt).

:func:`timed_blocks` streams a rate and keeps each block's times with the moment it arrived (the
clock comparison); :func:`at_rest_verdict` runs the look-alike check on a board lying still.
The report itself is the command's (``app/cli_check.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.services.acquisition import Acquisition, Block, Subscriber, Until
from app.services.connection import Connection
from drivers.base import Device


@dataclass
class TimedBlocks(Subscriber):
    """Each block's sample times and (device time of its last sample, host time it arrived)."""

    times: list[np.ndarray] = field(default_factory=list)
    arrivals: list[tuple[float, float]] = field(default_factory=list)
    samples: int = 0

    def on_block(self, block: Block) -> None:
        self.arrivals.append((float(block.raw.t_s[-1]), block.received_s))
        self.times.append(block.raw.t_s)
        self.samples += len(block)


def timed_blocks(device: Device, samples: float, wall_s: float,
                 timeout_s: float = 0.2) -> TimedBlocks:
    """Stream ``device`` (open) in whole blocks until ``samples`` arrived or ``wall_s`` of
    host time passed. Whole blocks: a block's arrival places its last sample on the host's
    clock. Raises the device's DeviceError."""
    seen = TimedBlocks()
    session = Acquisition(Connection(), detect_faults=False, check_lookalike=False,
                          subscribers=[seen])
    session.attach(device)
    end = session.run(Until(when=lambda: seen.samples >= samples, wall_s=wall_s), timeout_s)
    if end.error is not None:
        raise end.error
    return seen


@dataclass(frozen=True, slots=True)
class AtRest:
    """The look-alike check's verdict: a warning, or |a| at rest (None: it moved)."""

    warning: str | None
    accel_g: float | None


def at_rest_verdict(device: Device, wall_s: float, timeout_s: float = 0.2) -> AtRest:
    """Stream ``device`` (open) until the look-alike check decides or ``wall_s`` passed."""
    warnings: list[str] = []

    class Warnings(Subscriber):
        def on_message(self, level: int, text: str) -> None:
            if text.startswith("sensor: "):
                warnings.append(text.removeprefix("sensor: "))

    session = Acquisition(Connection(), detect_faults=False, subscribers=[Warnings()])
    session.attach(device)
    end = session.run(Until(when=lambda: session.lookalike.done, wall_s=wall_s), timeout_s)
    if end.error is not None:
        raise end.error
    return AtRest(warnings[-1] if warnings else None, session.lookalike.accel_g)
