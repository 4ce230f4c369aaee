"""The dask.distributed set-up shared by the commands that run tasks on workers (datasets, sweeps).

A run goes on an existing scheduler (its address) or on a new ``LocalCluster`` of single-threaded
worker processes; :func:`parse_memory` reads the per-worker memory limit such a cluster gets.

Faults: a worker that dies is replaced (a local cluster restarts it) and its task is run again by
dask; :func:`completed` yields the tasks as they finish and raises :class:`SchedulerLost` when the
connection to the scheduler is lost, or when it has had no worker for the connection timeout, so
that the caller can stop with one line saying what is done (a command run again resumes).
"""

from __future__ import annotations

import logging
import time

from viform._validate import ViformError, one_line

#: Seconds a client keeps trying to reach its scheduler (at the start, and after losing it).
DEFAULT_CONNECT_TIMEOUT_S = 20.0
#: Seconds between checks of the scheduler while waiting for tasks.
POLL_S = 1.0


class SchedulerLost(ViformError):  # noqa: N818 -- one line for the user, like every ViformError
    """The scheduler was lost (or has had no workers for the timeout) while tasks were pending."""


def parse_memory(memory_limit, name: str = "memory_limit") -> str | int:
    """Per-worker memory limit: ``"auto"`` (or None) or a size such as ``"2GiB"``, in bytes (≥ 64 MiB);
    errors begin with ``name``."""
    if memory_limit in (None, "auto"):
        return "auto"
    from dask.utils import parse_bytes

    try:
        value = parse_bytes(str(memory_limit))
    except (ValueError, TypeError):
        raise ViformError(f"{name} = {memory_limit!r} is not allowed: give a size such as 2GiB, "
                          "or auto") from None
    if value < 64 << 20:
        raise ViformError(f"{name} = {memory_limit!r} is not allowed: at least 64MiB per worker")
    return value


def one_line_warnings(fn):
    """``fn`` for ``client.submit``: warnings raised while it runs on a worker print one line each, as
    the command's own do (a local cluster's workers write to the command's stderr)."""
    import functools

    return functools.partial(_run_with_one_line_warnings, fn)


def _run_with_one_line_warnings(fn, *args, **kwargs):
    import warnings

    from viform._numba_cache import share_compiles
    from viform._validate import show_warning

    warnings.showwarning = show_warning  # this worker process shows every warning so from now on
    share_compiles()  # workers that start together compile each kernel once between them
    return fn(*args, **kwargs)


def check_connect_timeout(timeout_s) -> float:
    """The seconds a client keeps trying to reach its scheduler: a number in [0.1, 3600]."""
    if isinstance(timeout_s, bool) or not isinstance(timeout_s, (int, float)) or not 0.1 <= timeout_s <= 3600:
        raise ViformError(f"connect_timeout_s = {timeout_s!r} is not allowed: give seconds in [0.1, 3600]")
    return float(timeout_s)


#: dask settings of the local clusters viform starts (sweeps, datasets). No statistical profiler in the
#: workers: it samples the running task's stack every 10 ms, and with dask's ``MALLOC_TRIM_THRESHOLD_`` its
#: frees trim the heap that a task's arrays then grow again — 12–15 % more CPU per sweep point than in this
#: process, measured point by point alternately (0.95–0.99× without). The workers' environment keeps dask's
#: one-thread BLAS/OpenMP settings but not ``MALLOC_TRIM_THRESHOLD_`` (setting it also switches off glibc's
#: adaptive mmap threshold, so every large temporary array is mapped and unmapped anew: 5× the page faults;
#: the workers live for one command). No work stealing: the tasks are independent and queued at the
#: scheduler, which hands each to the next free worker. The event loops' latency tick every 1 s (not
#: 20 ms) and the system monitor every 5 s (not 0.5 s): an idle 2-worker cluster then costs 0.75 CPU-s per
#: 20 s instead of 2.8 (this process and its children, measured), CPU taken from the tasks on a 2-core
#: machine. The workers' memory monitor (which enforces the memory limit) keeps its own interval.
LOCAL_CLUSTER_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.scheduler.work-stealing": False,
                        "distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1,
                                                                "OPENBLAS_NUM_THREADS": 1},
                        "distributed.admin.tick.interval": "1s", "distributed.admin.system-monitor.interval": "5s"}

#: How a local cluster's workers start: "forkserver" forks them from one server process that has imported
#: distributed, the caller's task modules (``preload`` of :func:`open_client`) and numba's CPU target
#: registries once (:mod:`viform._worker_preload`; nothing that starts a thread, numba's kernels are loaded
#: by each worker); "spawn" (dask's default) starts each as a fresh interpreter that imports them all again
#: (≈ 1.1 CPU-s a worker, taken from the tasks on a 2-core machine). Measured on the 32-point benchmark
#: sweep, 2 workers, one sweep per fresh process, alternately: CPU beyond the points' own 2.3 CPU-s
#: against 3.7–4.5 with "spawn". The server lives as long as this process and is started, with the
#: workers' environment of ``distributed.nanny.pre-spawn-environ``, by the first local cluster: a later
#: cluster forks from it at once, and its workers import what the server did not. Its workers also get
#: the server's environment variables, those of this process when the first local cluster started: a
#: variable changed later in the same process (a notebook, a test) reaches them only through a new process.
WORKER_START = "forkserver"


def open_client(workers: int, scheduler: str | None, memory_limit,
                connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S, preload: tuple[str, ...] = ()):
    """(client, cluster): a client of the scheduler at ``scheduler`` (cluster None), or of a new
    LocalCluster of ``workers`` processes with one thread each and ``memory_limit`` per worker, with
    :data:`LOCAL_CLUSTER_CONFIG`, its workers started as :data:`WORKER_START` says (``preload``: the
    modules their tasks need, imported once by the fork server).

    ``connect_timeout_s`` bounds the wait for the scheduler, at the start and after a lost
    connection (then :func:`completed` stops the run). The client's own log lines, and the local
    cluster's, are kept quiet: failures reach the caller as exceptions, said in one line (a worker's
    heartbeat that meets the scheduler already closed, on a loaded machine, would otherwise print a
    traceback after a run that succeeded).
    """
    from distributed import Client, LocalCluster

    connect_timeout_s = check_connect_timeout(connect_timeout_s)
    for name in ("distributed.client", "distributed.core", "distributed.comm", "distributed.batched"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    if scheduler:
        try:
            return Client(scheduler, timeout=connect_timeout_s), None
        except (OSError, TimeoutError) as exc:
            raise ViformError(f"scheduler = {scheduler!r}: could not connect within connect_timeout_s = "
                              f"{connect_timeout_s:g} s ({one_line(exc)}); nothing was written") from None
    import dask

    # the settings hold while the cluster and its client start; this process's own are left as they were
    with dask.config.set(dict(LOCAL_CLUSTER_CONFIG, **{"distributed.worker.multiprocessing-method": WORKER_START})):
        if WORKER_START == "forkserver":
            from distributed.utils import get_mp_context

            # read when the server starts (by the first local cluster of this process)
            get_mp_context().set_forkserver_preload(["distributed", "viform._worker_preload", *preload])
        try:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   memory_limit=memory_limit, dashboard_address=":0",
                                   silence_logs=logging.CRITICAL)
        except Exception as exc:  # a worker process that died while starting (killed, out of memory)
            raise ViformError(f"could not start {workers} local dask worker process(es) ({one_line(exc)}); "
                              "nothing was written: run the command again") from None
        try:
            return Client(cluster, timeout=connect_timeout_s), cluster
        except BaseException:
            cluster.close()
            raise


def _lost(client, exc: BaseException | None = None) -> bool:
    """Whether the client has lost its scheduler (``exc``: an error a wait or a result raised)."""
    from concurrent.futures import CancelledError

    if client.status not in ("running", "connecting"):
        return True
    return isinstance(exc, CancelledError) or (exc is not None and "connection-lost" in str(exc))


def completed(client, futures, connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S):
    """Yield ``(future, result)`` as each finishes (any order); a task's own exception is yielded
    as its result, to be reported by the caller.

    Raises :class:`SchedulerLost` when the connection to the scheduler is lost (dask cancels every
    pending task then) or when the scheduler has had no worker for ``connect_timeout_s`` (a run
    would otherwise wait for ever); a worker that dies is not a fault here (dask runs its task
    again on another worker, up to its ``allowed-failures``).
    """
    from distributed import wait

    pending = set(futures)
    idle_since = None
    while pending:
        try:
            done, pending = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        except Exception as exc:
            if _lost(client, exc):
                raise SchedulerLost("lost the connection to the dask scheduler") from None
            raise
        for fut in done:
            try:
                result = fut.result()
            except Exception as exc:
                if _lost(client, exc):
                    raise SchedulerLost("lost the connection to the dask scheduler") from None
                result = exc
            yield fut, result
        if done or not pending:
            idle_since = None
            continue
        if _lost(client):
            raise SchedulerLost("lost the connection to the dask scheduler")
        try:
            workers = len(client.nthreads())
        except Exception as exc:
            raise SchedulerLost(f"lost the connection to the dask scheduler ({one_line(exc)})") from None
        if workers:
            idle_since = None
        elif idle_since is None:
            idle_since = time.monotonic()
        elif time.monotonic() - idle_since > connect_timeout_s:
            raise SchedulerLost(f"the dask scheduler has had no worker for {connect_timeout_s:g} s")
