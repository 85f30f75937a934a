"""``inclinometer joint A.csv B.csv --out J.csv [--axis auto|AX,AY,AZ:BX,BY,BZ]``.

The angle of the hinge between the sensor of recording A and that of recording B
(:mod:`app.core.joint`), one row per row of A. Output: ``# inclinometer-joint 1``, ``# key:
<JSON>`` lines (sources, axes, how well the motion determined them, alignment), then ``t``
(A's clock, s) and ``joint_deg`` (empty where B has no sample or before the angle is known).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from app.cli.errors import CommandError, one_line
from app.cli.recordings import check_recorded_calibration
from app.core.joint.alignment import align_to
from app.core.joint.offline import joint_angle_offline
from app.core.recording.errors import RecordingError
from app.core.recording.reader import read_recording
from app.core.recording.session import load_session, session_joint_files
from app.core.recording.writer import format_table
from app.core.safe_output import OutputRefused, check_output, write_error_message, write_output
from app.core.samples import SampleBlock

EXIT_USAGE = 2
MAGIC = "# inclinometer-joint 1"
AXIS_SPREAD_LIMIT_DEG = 2.0
"""An axis whose quarter-by-quarter estimates differ more than this is reported as poor."""


def add_arguments(joint: argparse.ArgumentParser) -> None:
    """The options of ``joint``; it runs :func:`joint_command`."""
    joint.set_defaults(handler=joint_command)
    joint.description = (
            "Estimate the angle of a hinge joint between the sensors of two recordings "
            "(format v1, e.g. sim://arm's). Each link's 6D orientation (VQF), the hinge "
            "axis from the gyroscopes (or --axis), the heading offset between the two "
            "orientations from the hinge, fused with the gyroscopes' rate about the axis. "
            "Writes t and joint_deg, one row per row of A; B is interpolated to A's times "
            "when their rows differ."
    )
    joint.add_argument("first", metavar="A.csv", help="the recording of the sensor on link 1, "
                       "or a session manifest (NAME.session.json) instead of A and B")
    joint.add_argument("second", metavar="B.csv", nargs="?",
                       help="the recording of the sensor on link 2")
    joint.add_argument("--out", required=True, metavar="J.csv", help="the file to write")
    joint.add_argument(
        "--axis", default="auto", metavar="auto|AX,AY,AZ:BX,BY,BZ",
        help="the hinge axis in A's and B's sensor frames (any length, same direction in "
        "space); 'auto' (default): estimated from the motion",
    )
    joint.add_argument("--overwrite", "--force", dest="force", action="store_true",
                       help="replace --out if it exists (never an input)")
    joint.add_argument("--allow-outside-paths", action="store_true",
                       help="let a session manifest name files outside its folder (absolute "
                            "or ../ paths); by default they are refused")


def parse_axes(text: str) -> tuple[np.ndarray, np.ndarray] | None:
    """None for ``auto``, else the two axes of ``AX,AY,AZ:BX,BY,BZ``; ValueError if malformed."""
    if text.strip().lower() == "auto":
        return None
    parts = text.split(":")
    if len(parts) != 2:
        raise ValueError(f"--axis {text!r}: write auto or AX,AY,AZ:BX,BY,BZ")
    axes = []
    for part in parts:
        try:
            values = [float(v) for v in part.split(",")]
        except ValueError:
            raise ValueError(f"--axis {text!r}: {part!r} is not three numbers") from None
        vector = np.array(values)
        if len(values) != 3 or not np.all(np.isfinite(vector)) or np.linalg.norm(vector) == 0:
            raise ValueError(f"--axis {text!r}: {part!r} is not a non-zero 3-vector")
        axes.append(vector / np.linalg.norm(vector))
    return axes[0], axes[1]


def _fail(message: str) -> CommandError:
    """Input ``joint`` cannot use: ``inclinometer joint: MESSAGE``, exit 2."""
    return CommandError(message, EXIT_USAGE, command="joint")


def _vector(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:+.4f}" for x in v) + ")"


def joint_command(args: argparse.Namespace, out: TextIO | None = None) -> int:
    out = sys.stdout if out is None else out
    manifest, time_map = _from_manifest(args)
    try:
        axes = parse_axes(args.axis)
    except ValueError as exc:
        raise _fail(str(exc)) from None
    target = Path(args.out)
    inputs = [args.first, args.second, manifest]
    try:
        check_output(target, inputs=inputs, overwrite=args.force, option="--out")
    except OutputRefused as exc:
        raise _fail(str(exc)) from None
    blocks = [_calibrated_samples(name) for name in (args.first, args.second)]
    if time_map is not None:  # B's clock onto A's, as the manifest maps them
        blocks[1].t_s = time_map(blocks[1].t_s)
    first, other = blocks
    second, covered, how = align_to(first, other)
    rows = np.flatnonzero(covered)
    if len(rows) < 2:
        raise _fail("the two recordings do not overlap in time")
    part1 = _take(first, rows)
    part2 = _take(second, rows)
    try:
        result = joint_angle_offline(part1, part2, axes)
    except ValueError as exc:
        raise _fail(str(exc)) from None
    angle = np.full(len(first), np.nan)
    angle[rows] = result.angles.angle_deg
    info: dict[str, Any] = {
        "sources": [str(args.first), str(args.second)],
        "alignment": how,
        "axis_in_first": result.j1.tolist(),
        "axis_in_second": result.j2.tolist(),
        "axis_source": "given" if axes is not None else "estimated from the gyroscopes",
        "units": {"t": "s", "joint_deg": "deg"},
        "convention": "angle of the second link about the axis (right hand, the axis as in "
                      "the first sensor's frame); zero at an arbitrary fixed pose",
    }
    estimate = result.axis_estimate
    if estimate is not None:
        info["axis_quality"] = {
            "smallest_singular_value_rad_s": estimate.smallest_singular,
            "uncertainty_deg": estimate.uncertainty_deg.tolist(),
            "residual_rms_dps": math.degrees(estimate.residual_rms_rad_s),
            "spread_over_quarters_deg": result.axis_spread_deg,
            "samples": estimate.samples,
        }
    head = MAGIC + "\n" + "".join(f"# {k}: {json.dumps(v)}\n" for k, v in info.items())
    text = head + "t,joint_deg\n" + format_table([first.t_s, angle])
    try:
        write_output(target, text, inputs=inputs, overwrite=args.force, option="--out")
    except OSError as exc:
        raise _fail(write_error_message(exc, target, "--out")) from None
    print(f"axis in A: {_vector(result.j1)}   axis in B: {_vector(result.j2)}"
          f"   ({info['axis_source']})", file=out)
    if estimate is not None:
        spread = result.axis_spread_deg
        good = estimate.well_determined and spread < AXIS_SPREAD_LIMIT_DEG  # NaN: not good
        verdict = "well determined" if good else "POORLY determined"
        residual = info["axis_quality"]["residual_rms_dps"]
        print(f"axis fit: {estimate.samples} samples, residual {residual:.3f} dps, smallest "
              f"singular value {estimate.smallest_singular:.3f} rad/s (0: motion that cannot "
              f"show the axis), spread over the quarters {spread:.3f} deg, 1-sigma from "
              f"the residuals {max(estimate.uncertainty_deg):.3f} deg: {verdict}", file=out)
    known = np.isfinite(angle)
    print(f"{target}: {len(angle)} rows ({int(known.sum())} with an angle), alignment: {how}",
          file=out)
    return 0


def _from_manifest(args: argparse.Namespace) -> tuple[str | None, Any]:
    """(the session manifest, the map of B's clock onto A's), both None for two recordings; a
    manifest names A and B (``args.first``, ``args.second``) and may give the axes."""
    if not str(args.first).lower().endswith(".json"):
        if args.second is None:
            raise _fail("give two recordings (A.csv B.csv) or a session manifest "
                        "(.session.json)")
        return None, None
    if args.second is not None:
        raise _fail("give a session manifest alone, or two recordings A.csv B.csv")
    try:
        session = load_session(args.first, allow_outside=args.allow_outside_paths)
        first, second, config, time_map = session_joint_files(session)
    except RecordingError as exc:
        raise _fail(str(exc)) from None
    except RecursionError:
        raise _fail(f"{args.first}: not a session manifest (its JSON is nested too "
                    "deeply)") from None
    except ValueError as exc:  # an integer of thousands of digits, a NUL in the name
        raise _fail(f"{args.first}: not a session manifest ({one_line(exc)})") from None
    manifest, args.first, args.second = args.first, str(first), str(second)
    if config.axes is not None and args.axis.strip().lower() == "auto":
        args.axis = ":".join(",".join(repr(v) for v in a) for a in config.axes)
    return manifest, time_map


def _calibrated_samples(name: str) -> Any:
    """A recording's samples with its recorded calibration applied."""
    try:
        recording = read_recording(name)
    except RecordingError as exc:
        raise _fail(str(exc)) from None
    except OSError as exc:
        raise _fail(f"{name}: cannot read the recording: {exc.strerror or exc}") from None
    if len(recording) < 2:
        raise _fail(f"{name}: fewer than two samples")
    check_recorded_calibration(recording.metadata, Path(name))
    return recording.sample_block(recording.calibration)


def _take(block: Any, rows: np.ndarray) -> Any:
    return SampleBlock(block.t_s[rows], block.accel_m_s2[rows], block.gyro_rad_s[rows],
                       block.temp_degc[rows], block.gap[rows])
