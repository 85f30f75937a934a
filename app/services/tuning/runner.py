"""Where the runs of a study (or of ``evaluate``) go: this process, worker processes, or an
existing Dask cluster. No scheduling of our own: a process pool (``concurrent.futures``) or
``dask.distributed`` hands the tasks out; results come back in the order of the calls,
whichever finished first.

- :class:`SerialRunner`: here, one call after the other (``--jobs 1``);
- :class:`ProcessRunner`: ``jobs`` worker processes (forkserver where there is one, else
  spawn: never a fork of a process that may hold threads). Each worker loads the filters'
  compiled kernels once from numba's on-disk cache when it starts, and stays for every task;
- :class:`DaskRunner`: a client of the scheduler at ``tcp://HOST:PORT``. The workers read
  the recordings from the path given (a shared file system), or with ``scatter`` the client
  reads each recording once and sends it to every worker once (``client.scatter``); tasks then
  carry a reference to it, never the samples.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import Any

from app.core.version import __version__
from app.services.tuning import trials
from app.services.tuning.trials import SourceSpec

Progress = Callable[[int], None]
"""Called with the weight of each call as it finishes (runs done so far grow by it)."""
CONNECT_TIMEOUT_S = 10.0


class RunnerError(Exception):
    """The runner cannot start (no scheduler at the address, dask missing, workers of another
    version): one line for the user."""


def local_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


class Runner:
    """Runs calls ``fn(*args)``; :meth:`run` returns their results in the order given."""

    workers = 1
    description = "1 process (serial)"

    def source(self, spec: SourceSpec) -> Any:
        """What a task gets for a recording: its spec (the worker reads it) by default."""
        return spec

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple[Any, ...]],
            weights: Sequence[int] | None = None, progress: Progress | None = None) -> list[Any]:
        results = []
        for i, args in enumerate(calls):
            results.append(fn(*args))
            if progress is not None:
                progress(weights[i] if weights is not None else 1)
        return results

    def close(self) -> None:
        """Release the workers (or the connection)."""

    def __enter__(self) -> Runner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SerialRunner(Runner):
    """Every call in this process, in order."""


def _pool_context() -> multiprocessing.context.BaseContext:
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["app.services.tuning.trials"])  # imported once
        return context
    return multiprocessing.get_context("spawn")


class ProcessRunner(Runner):
    """``jobs`` worker processes on this machine, kept for every call."""

    def __init__(self, jobs: int, filters: Sequence[str] = ()) -> None:
        self.workers = jobs
        self.description = f"{jobs} worker processes"
        trials.warm_up(tuple(filters))  # a cold numba cache is filled here once, not per worker
        self._pool = ProcessPoolExecutor(max_workers=jobs, mp_context=_pool_context(),
                                         initializer=trials.warm_up,
                                         initargs=(tuple(filters),))

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple[Any, ...]],
            weights: Sequence[int] | None = None, progress: Progress | None = None) -> list[Any]:
        futures: dict[Future[Any], int] = {self._pool.submit(fn, *args): i
                                           for i, args in enumerate(calls)}
        return _gather(futures, as_completed(futures), len(calls), weights, progress)

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


def _gather(futures: dict[Any, int], completed: Any, count: int,
            weights: Sequence[int] | None, progress: Progress | None) -> list[Any]:
    """Results by call index as the futures complete (the first failure is raised)."""
    results: list[Any] = [None] * count
    for future in completed:
        index = futures[future]
        results[index] = future.result()
        if progress is not None:
            progress(weights[index] if weights is not None else 1)
    return results


def _worker_version() -> str:
    return __version__


class DaskRunner(Runner):
    """A client of an existing Dask cluster (``dask.distributed``)."""

    def __init__(self, address: str, filters: Sequence[str] = (), scatter: bool = False,
                 timeout_s: float = CONNECT_TIMEOUT_S) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise RunnerError("--scheduler needs dask.distributed: pip install "
                              "'inclinometer[cluster]' (or 'dask[distributed]')") from None
        try:
            self._client = Client(address, timeout=timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise RunnerError(f"--scheduler {address}: cannot reach the Dask scheduler "
                              f"({exc})") from None
        try:
            self._check_workers(address, filters)
        except BaseException:
            self._client.close()
            raise
        self._scatter = scatter
        self._scattered: dict[SourceSpec, Any] = {}
        self.description = f"Dask cluster {address}, {self.workers} workers"

    def _check_workers(self, address: str, filters: Sequence[str]) -> None:
        workers = self._client.scheduler_info().get("workers", {})
        if not workers:
            raise RunnerError(f"--scheduler {address}: the cluster has no workers")
        self.workers = sum(int(w.get("nthreads", 1)) for w in workers.values())
        try:
            versions = self._client.run(_worker_version)
        except ModuleNotFoundError as exc:
            raise RunnerError(f"--scheduler {address}: the workers cannot import the "
                              f"inclinometer package ({exc}); install it on them") from None
        other = sorted({v for v in versions.values() if v != __version__})
        if other:
            raise RunnerError(f"--scheduler {address}: workers run inclinometer "
                              f"{', '.join(other)}, this is {__version__}: results would "
                              "not be comparable")
        if filters:
            self._client.run(trials.warm_up, tuple(filters))

    def source(self, spec: SourceSpec) -> Any:
        if not self._scatter:
            return spec
        if spec not in self._scattered:  # read here once, sent to every worker once
            self._scattered[spec] = self._client.scatter(trials.prepare(spec), broadcast=True,
                                                         hash=False)
        return self._scattered[spec]

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple[Any, ...]],
            weights: Sequence[int] | None = None, progress: Progress | None = None) -> list[Any]:
        from distributed import as_completed as dask_completed

        futures = {self._client.submit(fn, *args, pure=False): i
                   for i, args in enumerate(calls)}
        try:
            return _gather(futures, dask_completed(list(futures), loop=self._client.loop),
                           len(calls), weights,
                           progress)
        finally:
            for future in futures:
                future.release()

    def close(self) -> None:
        self._scattered.clear()
        self._client.close()


def make_runner(jobs: int | None, scheduler: str | None, filters: Sequence[str] = (),
                scatter: bool = False) -> Runner:
    """The runner ``--jobs`` / ``--scheduler`` ask for (``jobs`` None: every local core)."""
    if scheduler:
        return DaskRunner(scheduler, filters, scatter=scatter)
    jobs = local_cores() if jobs is None else jobs
    return SerialRunner() if jobs <= 1 else ProcessRunner(jobs, filters)
