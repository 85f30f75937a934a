"""What a recording costs in disk space, before it starts (``record`` and the record dialog).

Row sizes are those of format v1 as the recorder writes it, measured on simulated motion
(``benchmarks/long_sessions.py`` prints the real figures): a row holds about 140 bytes, 220
with the reference columns. Compressed (``.csv.gz``, zlib level 1) a moving sensor's rows take
about 45 % of that, a still one's far less; the estimate takes the moving case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

ROW_BYTES = 140.0
"""A row without reference columns (t, six axes, temperature, gap, block_start)."""
REFERENCE_ROW_BYTES = 220.0
"""A row with the reference quaternion (qw, qx, qy, qz)."""
COMPRESSED_FRACTION = 0.45
"""Compressed size over plain size for a sensor in motion (at rest: about 0.16)."""


@dataclass(frozen=True, slots=True)
class DataRate:
    """The estimated growth of a recording and how long a disk lasts at that rate."""

    bytes_per_s: float
    free_bytes: float | None = None

    @property
    def mb_per_minute(self) -> float:
        return self.bytes_per_s * 60.0 / 1e6

    @property
    def lasts_s(self) -> float:
        """Seconds of recording the free space holds (inf when unknown or no data)."""
        if self.free_bytes is None or self.bytes_per_s <= 0:
            return math.inf
        return self.free_bytes / self.bytes_per_s

    def text(self) -> str:
        """``about 1.9 MB/min; the 71 GB free last about 26 days``."""
        rate = f"about {self.mb_per_minute:.3g} MB/min"
        if self.free_bytes is None or not math.isfinite(self.lasts_s):
            return rate
        return f"{rate}; the {self.free_bytes / 1e9:.3g} GB free last about " \
               f"{duration_text(self.lasts_s)}"


def data_rate(odr_hz: float, *, reference: bool = False, compressed: bool = False,
              free_bytes: float | None = None) -> DataRate:
    """The estimated data rate of a recording at ``odr_hz``."""
    row = REFERENCE_ROW_BYTES if reference else ROW_BYTES
    if compressed:
        row *= COMPRESSED_FRACTION
    return DataRate(max(odr_hz, 0.0) * row, free_bytes)


def duration_text(seconds: float) -> str:
    """A duration in the largest unit that reads well: ``45 s``, ``12 min``, ``5.2 h``,
    ``26 days``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.0f} days"
