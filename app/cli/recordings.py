"""What the commands that read recordings share: refuse an unusable recorded calibration."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from app.cli.errors import CommandError
from app.core.recording.format import recorded_calibration_problem


def check_recorded_calibration(metadata: dict[str, Any], path: Path) -> None:
    """CommandError when the recording's ``calibration`` is there but cannot be used: the
    samples would silently go uncalibrated (``--raw`` says so on purpose)."""
    problem = recorded_calibration_problem(metadata)
    if problem is not None:
        raise CommandError(f"{path}: the recorded calibration is invalid ({problem}); give "
                           "--raw to use the samples uncalibrated")
