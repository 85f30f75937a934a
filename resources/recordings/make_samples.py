"""Make the sample recordings in this folder from the simulator.

    python -m resources.recordings.make_samples          (from the repository root)

Each recording is what ``inclinometer record`` would write from a live simulator polled every
20 ms by the GUI's worker, made without waiting: the simulator runs in realtime mode on a fake
wall clock that this script advances. So the blocks, their sizes and the gap flags are those of a
live session, and the files are the same on every run (except their ``start_time``).

The calibration applied while recording is the one that undoes the simulated unit's true
static errors (:func:`app.core.evaluation.calibration_from_unit_errors`), so ``inclinometer
evaluate`` on a sample scores the filters, not an uncalibrated sensor; ``--raw`` shows the
uncalibrated case. The reference columns hold the simulator's true orientation.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from app.core.evaluation import calibration_from_unit_errors
from app.core.recording.recorder import record_device
from app.core.samples import RawBlock
from drivers.sim.device import SimulatedDevice
from drivers.sim.scenarios import Tour

POLL_S = 0.020
"""How often the fake worker reads the simulator (the GUI worker reads about this often)."""
FOLDER = Path(__file__).resolve().parent


class FakeClock:
    """A wall clock this script moves."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class PolledSimulator(SimulatedDevice):
    """The realtime simulator, with each read advancing a fake clock by one poll interval.

    ``stall`` = (device time s, length s): the reader stalls once for that long, as a busy
    computer would; beyond the chip's 1 s FIFO the excess samples are lost and the next one is
    marked as a gap.
    """

    def __init__(self, url: str, stall: tuple[float, float] | None = None) -> None:
        self.fake_clock = FakeClock()
        super().__init__(url, clock=self.fake_clock)
        self._stall = stall

    def _read(self, timeout_s: float) -> RawBlock | None:
        self.fake_clock.now += POLL_S
        if self._stall is not None and self.fake_clock.now >= self._stall[0]:
            self.fake_clock.now += self._stall[1]
            self._stall = None
        return super()._read(0.0)


@dataclass
class Sample:
    """One sample recording to make."""

    name: str
    url: str
    seconds: float
    note: str
    stall: tuple[float, float] | None = None
    bookmarks: Callable[[], list[dict[str, object]]] = field(default=lambda: [])


def tour_bookmarks() -> list[dict[str, object]]:
    """The start of each held face of the default tour (6 s held, 2 s turning)."""
    step = Tour.parameters["hold"].default + Tour.parameters["transition"].default
    faces = [*Tour.FACES, *Tour.FACES]
    return [{"t": k * step, "label": f"{face} up"} for k, face in enumerate(faces)
            if k * step < 60.0]


SAMPLES = (
    Sample("wobble-104hz", "sim://wobble?odr=104&seed=11", 30.0,
           "30 s hand-held wobble near level at 104 Hz (simulator, true orientation in qw..qz)"),
    Sample("translation-208hz", "sim://strokes?odr=208&seed=12", 30.0,
           "30 s of several g of linear acceleration at 208 Hz: the accelerometer alone is "
           "fooled (simulator, true orientation in qw..qz)"),
    Sample("tour-104hz", "sim://tour?odr=104&seed=13", 60.0,
           "60 s calibration tour of the six faces at 104 Hz, with a 1.5 s stall of the reader "
           "at 37 s that loses 0.5 s of samples (a gap) during a turn (simulator, true "
           "orientation in qw..qz)",
           stall=(37.0, 1.5), bookmarks=tour_bookmarks),
)


def make(sample: Sample, folder: Path = FOLDER) -> Path:
    """Write one sample recording; returns its path."""
    device = PolledSimulator(sample.url, sample.stall)
    calibration = calibration_from_unit_errors(device.unit_errors)
    path = folder / f"{sample.name}.csv"
    extra = {"bookmarks": sample.bookmarks()} if sample.bookmarks() else None
    outcome = record_device(
        device, path, duration_s=sample.seconds, note=sample.note, calibration=calibration,
        overwrite=True, extra_metadata=extra,
    )
    if outcome.reason != "duration":
        raise RuntimeError(f"{path}: recording ended early ({outcome.reason}: {outcome.message})")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--folder", type=Path, default=FOLDER, help="where to write them")
    args = parser.parse_args()
    args.folder.mkdir(parents=True, exist_ok=True)
    total = 0
    for sample in SAMPLES:
        path = make(sample, args.folder)
        size = path.stat().st_size
        total += size
        print(f"{path}: {size / 1e6:.2f} MB")
    print(f"total {total / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
