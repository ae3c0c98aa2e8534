"""Execution of independent jobs: local worker processes or a Dask cluster, retries, progress."""

from __future__ import annotations

import math
import os
import sys
import uuid
from collections.abc import Hashable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._extras import require
from ..scenario import set_value
from .objectives import Objective

JOB_RETRIES = 2
"""Resubmissions of a failed job (its worker process died, or an error of the machine such as
OSError or MemoryError) before it is reported as failed: each job is tried at most
``1 + JOB_RETRIES`` times on the local pool. Errors of the job itself
(:data:`DETERMINISTIC_ERRORS`) would only repeat, so they are reported at once."""

DETERMINISTIC_ERRORS: tuple[type[BaseException], ...] = (ValueError, TypeError, KeyError, IndexError,
                                                          ArithmeticError, NotImplementedError)
"""Errors that the same job raises again on every try (a bad scenario value, a missing
target): never retried. On a Dask cluster the scheduler retries every error (``retries=``)."""


def evaluate(
    scenario: Mapping[str, Any],
    overrides: Mapping[str, Any],
    seed: int,
    objective: Objective,
) -> dict[str, Any]:
    """One job: the scenario with ``overrides`` (dotted key -> value) set, prepared by the
    objective, simulated with ``seed`` on one engine thread for ``objective.duration_s`` (or
    the scenario's duration), and measured. Top level and pure (same arguments, same numbers),
    so it can run in any process."""
    from ..simulate import simulate

    s = dict(scenario)
    for key, value in overrides.items():
        s = set_value(s, key, value)
    s = objective.prepare(s)
    result = simulate(s, duration_s=objective.duration_s, seed=int(seed), num_threads=1)
    values = objective.evaluate(result)
    # A metric is a number, or an array of them (the statistics vector of the fit's chi-square).
    return {m: values[m] if isinstance(values[m], np.ndarray) else float(values[m]) for m in objective.metrics}


@dataclass(frozen=True)
class _Context:
    """What every job of one search or sweep shares (shipped once per worker)."""

    scenario: dict[str, Any]
    objective: Objective
    token: str = field(default_factory=lambda: uuid.uuid4().hex)


@dataclass(frozen=True)
class _Job:
    key: Hashable
    overrides: dict[str, Any]
    seed: int


@dataclass
class JobFailure:
    """A job that failed every attempt: its key, overrides, seed and last error."""

    key: Hashable
    overrides: dict[str, Any]
    seed: int
    attempts: int
    error: str


def _run_context_job(ctx: _Context, overrides: dict[str, Any], seed: int) -> dict[str, float]:
    return evaluate(ctx.scenario, overrides, seed, ctx.objective)


_WORKER_CONTEXT: _Context | None = None


def _install_context(ctx: _Context) -> None:
    from .._signals import ignore_sigint

    global _WORKER_CONTEXT
    _WORKER_CONTEXT = ctx
    ignore_sigint()  # the parent stops the workers on Ctrl-C (kill)


def _run_installed_job(overrides: dict[str, Any], seed: int) -> dict[str, float]:
    if _WORKER_CONTEXT is None:  # pragma: no cover - the initializer always ran
        raise RuntimeError("worker has no job context")
    return _run_context_job(_WORKER_CONTEXT, overrides, seed)


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _failure(job: _Job, attempts: int, error: str) -> JobFailure:
    """The record of ``job`` given up after ``attempts`` tries, with the last one's error."""
    return JobFailure(job.key, job.overrides, job.seed, attempts, error)


def _submit(pool: Any, job: _Job) -> Any:
    """``pool.submit`` of one job; a worker it starts never sees a terminal's Ctrl-C."""
    from .._signals import children_without_sigint

    with children_without_sigint():
        return pool.submit(_run_installed_job, job.overrides, job.seed)


class LocalExecutor:
    """Jobs in local worker processes (one engine thread each); ``workers=0`` runs them in
    the calling process (debugging, profiling). The shared context reaches each worker once,
    through the pool's initializer. Start method: forkserver where available (no fork of a
    process that runs threads), else spawn."""

    def __init__(self, workers: int | None = None) -> None:
        if workers is None:
            workers = (
                len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
            )
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
            raise ValueError(f"workers must be an integer >= 0; got {workers!r}")
        self.workers = workers
        self._pool: Any = None
        self._children_before: set[Any] = set()
        self._token: str | None = None

    @property
    def description(self) -> str:
        return "in-process" if self.workers == 0 else f"local pool of {self.workers} process(es)"

    def _new_pool(self, ctx: _Context) -> Any:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        from .._signals import children_without_sigint

        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        self.close()
        self._children_before = set(multiprocessing.active_children())
        with children_without_sigint():  # and the workers started at the submits (_submit)
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=multiprocessing.get_context(method),
                initializer=_install_context,
                initargs=(ctx,),
            )
        self._token = ctx.token
        return self._pool

    def run(
        self, ctx: _Context, jobs: Sequence[_Job]
    ) -> Iterator[tuple[_Job, dict[str, float] | JobFailure]]:
        """Yield (job, numbers or JobFailure) as jobs finish, in completion order."""
        if self.workers == 0:
            for job in jobs:
                yield job, self._run_inline(ctx, job)
            return
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        pool = self._pool if self._token == ctx.token and self._pool is not None else self._new_pool(ctx)
        attempts = {i: 0 for i in range(len(jobs))}
        futures: dict[Any, int] = {}
        ok = False
        try:
            # Submitted inside the try: the first submits spawn the workers (seconds on a loaded
            # machine), and a Ctrl-C landing then must stop them too, not leave the interpreter
            # waiting at exit for jobs of a minute or more.
            for i, j in enumerate(jobs):
                futures[_submit(pool, j)] = i
            while futures:
                done, _ = wait(list(futures), return_when=FIRST_COMPLETED)
                retry: list[int] = []
                broken = False
                for fut in done:
                    i = futures.pop(fut)
                    try:
                        values = fut.result()
                    except BrokenProcessPool as exc:
                        broken = True
                        attempts[i] += 1
                        if attempts[i] > JOB_RETRIES:
                            yield jobs[i], _failure(jobs[i], attempts[i], f"worker process died: {_error_text(exc)}")
                        else:
                            retry.append(i)
                    except Exception as exc:  # noqa: BLE001 - any job error is retried, then reported
                        attempts[i] += 1
                        if attempts[i] > JOB_RETRIES or isinstance(exc, DETERMINISTIC_ERRORS):
                            yield jobs[i], _failure(jobs[i], attempts[i], _error_text(exc))
                        else:
                            retry.append(i)
                    else:
                        yield jobs[i], values
                if broken:
                    # Every job still queued on the dead pool fails with it: take them all back
                    # (without charging them an attempt) and go on with a new pool.
                    retry.extend(futures.values())
                    futures.clear()
                    pool = self._new_pool(ctx)
                for i in retry:
                    futures[_submit(pool, jobs[i])] = i
            ok = True
        finally:
            if not ok:  # Ctrl-C, or the caller stopped early: no worker may outlive us
                # Not cancelled first: Python 3.11's pool manager, finding the workers dead,
                # sets BrokenProcessPool on every pending future and dies with
                # InvalidStateError on a cancelled one, part-way through its cleanup.
                self.kill()

    def kill(self) -> None:
        """Stop now: terminate the worker processes (their jobs are lost) and drop the pool.
        SIGINT that reaches only this process would otherwise leave the workers finishing
        their jobs, and the interpreter waiting for them at exit."""
        from ..simulate import stop_workers

        if self._pool is None:
            return
        stop_workers(self._pool, self._children_before)
        self._pool = None
        self._token = None

    def _run_inline(self, ctx: _Context, job: _Job) -> dict[str, float] | JobFailure:
        error = ""
        for attempt in range(1, JOB_RETRIES + 2):
            try:
                return _run_context_job(ctx, job.overrides, job.seed)
            except DETERMINISTIC_ERRORS as exc:
                return _failure(job, attempt, _error_text(exc))
            except Exception as exc:  # noqa: BLE001
                error = _error_text(exc)
        return _failure(job, JOB_RETRIES + 1, error)

    def close(self, wait: bool = True) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=wait, cancel_futures=True)
        self._pool = None
        self._token = None


class DaskExecutor:
    """Jobs on a Dask distributed cluster: ``scheduler`` is an address, a
    ``distributed.Client``, or ``"local"`` (an in-process ``LocalCluster`` of ``workers``
    (default 2) single-threaded worker processes on 127.0.0.1, its HTTP endpoints on a free
    loopback port). The shared
    context is scattered to every worker once; each job is submitted with
    ``retries=JOB_RETRIES`` (a job whose worker dies is rescheduled by the scheduler)."""

    def __init__(self, scheduler: Any, workers: int | None = None) -> None:
        Client = require("distributed").Client

        self._cluster: Any = None
        self._own_client = True
        if isinstance(scheduler, Client):
            self.client = scheduler
            self._own_client = False
        elif scheduler == "local":
            LocalCluster = require("distributed").LocalCluster

            n = 2 if workers is None else workers
            if isinstance(n, bool) or not isinstance(n, int) or n < 1:
                raise ValueError(f"workers must be an integer >= 1 for --scheduler local; got {workers!r}")
            self._cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address="127.0.0.1:0",
            )
            self.client = Client(self._cluster)
        elif isinstance(scheduler, str) and scheduler:
            try:
                self.client = Client(scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise ValueError(f"--scheduler {scheduler!r}: cannot connect ({exc})") from None
        else:
            raise ValueError(
                f"scheduler must be a Dask address, a distributed.Client or 'local'; got {scheduler!r}"
            )
        self._scattered: dict[str, Any] = {}

    @property
    def description(self) -> str:
        n = (
            len(self.client.scheduler_info(n_workers=-1).get("workers", {}))
            if hasattr(self.client, "scheduler_info")
            else 0
        )
        return f"Dask cluster at {self.client.scheduler.address} ({n} worker(s))"

    def run(
        self, ctx: _Context, jobs: Sequence[_Job]
    ) -> Iterator[tuple[_Job, dict[str, float] | JobFailure]]:
        as_completed = require("distributed").as_completed

        if ctx.token not in self._scattered:
            self._scattered = {ctx.token: self.client.scatter(ctx, broadcast=True, hash=False)}
        shared = self._scattered[ctx.token]
        futures = {}
        for i, j in enumerate(jobs):
            fut = self.client.submit(
                _run_context_job,
                shared,
                j.overrides,
                j.seed,
                retries=JOB_RETRIES,
                pure=False,
                key=f"evstwin-job-{ctx.token[:8]}-{uuid.uuid4().hex}",
            )
            futures[fut] = i
        ok = False
        try:
            for fut in as_completed(list(futures)):
                i = futures[fut]
                try:
                    values = fut.result()
                except Exception as exc:  # noqa: BLE001 - failed after the scheduler's retries
                    yield jobs[i], _failure(jobs[i], JOB_RETRIES + 1, _error_text(exc))
                else:
                    yield jobs[i], values
            ok = True
        finally:
            if not ok:
                self.client.cancel(list(futures))

    def close(self, wait: bool = True) -> None:
        self._scattered = {}
        if self._own_client:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


Executor = LocalExecutor | DaskExecutor


def make_executor(scheduler: Any = None, workers: int | None = None) -> Executor:
    """A local process pool (``scheduler`` None), or Dask (an address, a Client, "local")."""
    if scheduler is None or scheduler == "":
        return LocalExecutor(workers)
    return DaskExecutor(scheduler, workers)


UPDATES_PER_S_PER_WORKER = 15e6
"""Pixel-updates a worker gets through per second end to end (scene, sub-sampling, engine),
for the estimate printed before a run: a 3 s ``mcreynolds`` on one thread of the 2-core
development machine did 67.5 M base-rate updates in 4.5 s. A rough figure, said to be one."""


def announce(what: str, n_jobs: int, scene: Any, executor: Any, job_seconds: float | None = None) -> str:
    """One paragraph saying what a run will do and about how long it should take: from
    ``job_seconds`` (one job timed by the caller) if given, else from the pixel-updates."""
    updates = scene.width * scene.height * scene.rate_hz * scene.duration_s
    workers = max(1, getattr(executor, "workers", None) or 1) if executor is not None else 1
    if isinstance(executor, DaskExecutor):
        info = executor.client.scheduler_info() if hasattr(executor.client, "scheduler_info") else {}
        workers = max(1, len(info.get("workers", {})))
    per_job_s = updates / UPDATES_PER_S_PER_WORKER if job_seconds is None else float(job_seconds)
    total_s = per_job_s * math.ceil(n_jobs / workers)
    where = executor.description if executor is not None else "nothing to run"
    basis = (f"from {UPDATES_PER_S_PER_WORKER / 1e6:g} M pixel-updates/s per worker; sub-sampled moving targets take "
             "longer" if job_seconds is None else "from one job timed here; each worker also pays its start-up, imports and PSF tables")
    return (f"{what}: {n_jobs} job(s) of {scene.width}x{scene.height} px for {scene.duration_s:g} s of sensor "
            f"time at {scene.rate_hz:g} Hz on {where}; estimate ~{per_job_s:.1f} s a job, "
            f"~{_duration_text(total_s)} in all ({basis})")


def _duration_text(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _bar(total: int, desc: str, progress: bool, initial: int = 0, unit: str = "job") -> Any:
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True)
