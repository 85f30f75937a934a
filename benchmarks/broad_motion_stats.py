"""How the BROAD trials move, and how the simulator's scenarios move, by the same figures.

Per trial, over its movement phase (``movement == 1``; see :mod:`app.core.motion_stats` for
every definition): ``|a|-g`` RMS and peak (m/s^2 and g); the earth-frame linear acceleration's
RMS and spectrum (dominant and median frequency, bands holding the middle 50 % and 90 % of the
power); the rate's RMS, peak and dominant frequency (dps, Hz); the tilt (5th percentile,
median, 95th percentile and largest, degrees), the rotation from the mean orientation (RMS
about its x, y, z, degrees); and, over the span from the first to the last
moving sample, the fraction of time at rest and the rest breaks.

``--sim URL`` computes the same figures for a simulator stream (its true orientation is the
reference; the unit's static errors are compensated as in ``inclinometer evaluate``); the
moving samples are then those not at rest.

    .venv/bin/python benchmarks/broad_motion_stats.py [TRIAL.csv ...]
    .venv/bin/python benchmarks/broad_motion_stats.py --seconds 130 \
        --sim "sim://translation?odr=208&level=0" --sim "sim://translation?odr=208" \
        --sim "sim://translation?odr=208&level=1" --sim "sim://handheld?odr=208&level=0" \
        --sim "sim://handheld?odr=208" --sim "sim://handheld?odr=208&level=1"
"""

from __future__ import annotations

import argparse
import glob
import math
import sys
from pathlib import Path

from app.core.motion_stats import G, MotionStats, motion_stats
from app.services.simulation import simulator_stats

REPO = Path(__file__).resolve().parent.parent
DEFAULT_GLOB = str(REPO.parent / "shared" / "datasets" / "broad" / "*.csv")


def trial_stats(path: str | Path) -> MotionStats:
    """The figures of one recording over its ``movement`` phase (all of it without the column)."""
    from app.core.recording.reader import read_recording

    recording = read_recording(path)
    flag = recording.columns.get("movement")
    movement = None if flag is None else (flag > 0)
    return motion_stats(
        recording.t_s, recording.accel_m_s2, recording.gyro_rad_s,
        recording.reference_quat, movement,
    )


COLUMNS = (
    ("|a|-g rms", "m/s2 (g)"),
    ("|a|-g peak", "m/s2 (g)"),
    ("lin rms", "m/s2"),
    ("lin dom", "Hz"),
    ("lin med", "Hz"),
    ("lin 50%", "Hz"),
    ("lin 90%", "Hz"),
    ("gyro rms", "dps"),
    ("gyro peak", "dps"),
    ("gyro dom", "Hz"),
    ("tilt p5/p50/p95 max", "deg"),
    ("rot rms x/y/z", "deg"),
    ("rest", "% (breaks x s)"),
)


def row(s: MotionStats) -> list[str]:
    lin, gyr = s.linear_spectrum, s.gyro_spectrum
    return [
        f"{s.excess_rms_m_s2:.2f} ({s.excess_rms_g:.2f})",
        f"{s.excess_peak_m_s2:.1f} ({s.excess_peak_g:.1f})",
        f"{s.linear_rms_m_s2:.2f}",
        f"{lin.dominant_hz:.2f}",
        f"{lin.median_hz:.2f}",
        f"{lin.band50_hz[0]:.2f}-{lin.band50_hz[1]:.2f}",
        f"{lin.band90_hz[0]:.2f}-{lin.band90_hz[1]:.2f}",
        f"{s.gyro_rms_dps:.0f}",
        f"{s.gyro_peak_dps:.0f}",
        f"{gyr.dominant_hz:.2f}",
        "/".join(f"{v:.0f}" for v in s.tilt_deg) + f" {s.tilt_max_deg:.0f}",
        "/".join(f"{v:.0f}" for v in s.rotation_rms_deg),
        f"{100 * s.rest_fraction:.0f} ({s.rest_breaks} x {s.rest_break_mean_s:.0f})",
    ]


def print_table(rows: list[tuple[str, MotionStats]], markdown: bool) -> None:
    header = ["source"] + [f"{name} {unit}" for name, unit in COLUMNS]
    cells = [[label, *row(s)] for label, s in rows]
    if markdown:
        print("| " + " | ".join(header) + " |")
        print("|" + "---|" * len(header))
        for line in cells:
            print("| " + " | ".join(line) + " |")
        return
    widths = [max(len(c[i]) for c in [header, *cells]) for i in range(len(header))]
    for line in [header, *cells]:
        print("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                        for i, (c, w) in enumerate(zip(line, widths, strict=True))))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="*", help=f"recordings (default: {DEFAULT_GLOB})")
    parser.add_argument("--sim", action="append", default=[], metavar="URL",
                        help="a simulator URL to describe (repeatable); trials are then "
                             "read only when named")
    parser.add_argument("--seconds", type=float, default=120.0,
                        help="seconds of each simulator stream (default 120)")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    args = parser.parse_args(argv)

    paths = args.trials or ([] if args.sim else sorted(glob.glob(DEFAULT_GLOB)))
    if not paths and not args.sim:
        print(f"no trials found at {DEFAULT_GLOB}", file=sys.stderr)
        return 1
    rows = [(Path(p).stem, trial_stats(p)) for p in paths]
    rows += [(url, simulator_stats(url, args.seconds)) for url in args.sim]
    print(f"g = {G} m/s^2; spectra: Welch, 8 s Hann segments; moving samples only")
    print_table(rows, args.markdown)
    if any(not math.isclose(s.reference_fraction, 1.0) for _, s in rows):
        print("reference known on " + ", ".join(
            f"{label[:2]} {100 * s.reference_fraction:.1f}%" for label, s in rows
            if not math.isclose(s.reference_fraction, 1.0)) + " of the moving samples")
    return 0


if __name__ == "__main__":
    sys.exit(main())
