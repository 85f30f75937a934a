"""How `inclinometer tune` scales (issue 35): a 100-point EKF grid over the twelve BROAD trials
(1200 filter runs of about 56 000 samples each, plus the sensitivity runs) on one process, on
two worker processes and on a two-worker Dask LocalCluster (worker processes, one thread each),
with the wall time of each, the load of the machine meanwhile, and whether the results are the
same to the bit.

    .venv/bin/python benchmarks/tune_scaling.py [--modes serial processes dask] [TRIAL.csv ...]

The goal is under 2 minutes for the grid on this 2-core machine. Each mode's time includes
starting its workers (processes: forkserver, the filters' kernels from numba's cache; the
LocalCluster's start is timed apart). The load average is the machine's: other work counts.
"""

from __future__ import annotations

import argparse
import glob
import os
import time
from pathlib import Path
from typing import Any

from app.core.filters import FILTERS
from app.services.tuning.grid import Axis, grid_points
from app.services.tuning.runner import DaskRunner, ProcessRunner, Runner, SerialRunner
from app.services.tuning.study import StudyRequest, run_study
from app.services.tuning.trials import SourceSpec

DEFAULT_GLOB = str(Path(__file__).resolve().parents[2] / "shared" / "datasets" / "broad" / "*.csv")
GRID = {"lp_tau": (1.0, 1.5, 2.0, 3.0, 4.0), "motion_frequency": (0.5, 0.75, 1.0, 1.5, 2.0),
        "gyro_scale_error": (0.1, 0.3, 0.6, 1.2)}
"""5 x 5 x 4 = 100 points of the EKF."""
ENVIRON = "distributed.nanny.pre-spawn-environ"
WORKER_MALLOC = {"MALLOC_MMAP_THRESHOLD_": 32 << 20}
"""Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which fixes glibc's mmap
threshold at 128 KB: every array of a run is then mapped and unmapped afresh, about 35 % more
CPU per run here. A 32 MB mmap threshold gives that back (start real workers with it too)."""
COMPARED = ("results", "best", "cross_validation", "cross_validated_rmse_deg", "sensitivity")


def request(paths: list[str]) -> StudyRequest:
    cls = FILTERS["ekf"]
    axes = [Axis("ekf", cls.parameter_spec(name), values=values) for name, values in GRID.items()]
    sources = [SourceSpec(str(Path(p).resolve()), Path(p).stem) for p in paths]
    return StudyRequest("ekf", axes, grid_points(axes), sources, groups=True)


def timed(runner: Runner, study: StudyRequest) -> tuple[dict[str, Any], float, float, float]:
    """The study's document, its wall time (workers' start included), the mean 1-minute load
    average over the run and this process's CPU seconds (all of the work when serial)."""
    start, load, cpu = time.perf_counter(), os.getloadavg()[0], time.process_time()
    with runner:
        document = run_study(study, runner)
    return (document, time.perf_counter() - start, (load + os.getloadavg()[0]) / 2,
            time.process_time() - cpu)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="*", help=f"recordings (default {DEFAULT_GLOB})")
    parser.add_argument("--modes", nargs="+", default=["serial", "processes", "dask"],
                        choices=["serial", "processes", "dask"])
    args = parser.parse_args()
    paths = args.trials or sorted(glob.glob(DEFAULT_GLOB))
    study = request(paths)
    runs = len(study.points) * len(paths)
    print(f"{len(study.points)}-point EKF grid x {len(paths)} recordings = {runs} runs "
          f"(+ sensitivity); {os.cpu_count()} cores; load average now "
          f"{os.getloadavg()[0]:.1f}")
    documents: dict[str, dict[str, Any]] = {}
    for mode in args.modes:
        if mode == "serial":
            document, wall, load, cpu = timed(SerialRunner(), study)
            print(f"  (serial: {cpu:.1f} CPU seconds, so two idle cores would need about "
                  f"{cpu / 2:.0f} s)")
        elif mode == "processes":
            document, wall, load, _ = timed(ProcessRunner(2, ["ekf"]), study)
        else:
            import dask.config
            from distributed import LocalCluster

            begin = time.perf_counter()
            with dask.config.set({ENVIRON: {**dask.config.get(ENVIRON), **WORKER_MALLOC}}), \
                    LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster:
                started = time.perf_counter() - begin
                document, wall, load, _ = timed(
                    DaskRunner(cluster.scheduler_address, ["ekf"]), study)
            print(f"  (LocalCluster started in {started:.1f} s)")
        documents[mode] = {key: document[key] for key in COMPARED}
        print(f"{mode:>10}: {wall:7.1f} s wall, {runs / wall:6.1f} runs/s, load average "
              f"{load:.1f}, cross-validated {document['cross_validated_rmse_deg']:.4f} deg, "
              f"best {document['best']['rmse_deg']:.4f} deg")
    first = next(iter(documents.values()))
    same = all(d == first for d in documents.values())
    print(f"results identical to the bit across {', '.join(documents)}: {same}")


if __name__ == "__main__":
    main()
