"""The BROAD trials in ``../shared/datasets/broad`` (real motion with optical ground truth).

Laidig, Caruso, Cereatti, Seel (2021), "BROAD - A Benchmark for Robust Inertial Orientation
Estimation", Data 6(7):72, CC BY 4.0. Tests that need them skip, with this reason, only when
the shared folder is absent (CI has it).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

from app.core.orientation import inclination_error_deg
from app.core.recording.reader import read_recording
from app.core.samples import SampleBlock

BROAD_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "broad"
MISSING_REASON = f"the shared BROAD trials are not at {BROAD_DIR} (../shared beside the project)"


def trial_path(stem: str) -> Path:
    """The path of one trial (by file stem); skips the test when the folder is absent."""
    if not BROAD_DIR.is_dir():
        pytest.skip(MISSING_REASON)
    return BROAD_DIR / f"{stem}.csv"


@cache
def load_trial(stem: str) -> tuple[SampleBlock, np.ndarray]:
    """A trial's samples (with the reference) and its score mask (movement = 1, reference)."""
    recording = read_recording(trial_path(stem))
    samples = recording.sample_block(None)
    movement = np.asarray(recording.unknown_columns["movement"]) > 0.5
    mask = movement & np.all(np.isfinite(samples.reference_quat), axis=1)
    return samples, mask


def broad_rmse(quat: np.ndarray, stem: str) -> float:
    """BROAD's metric: inclination-error RMSE (degrees) over the scored samples."""
    samples, mask = load_trial(stem)
    errors = inclination_error_deg(quat[mask], samples.reference_quat[mask])
    return float(np.sqrt(np.mean(errors**2)))
