"""The dask.distributed set-up shared by the commands that run tasks on workers (datasets, sweeps).

A run goes on an existing scheduler (its address) or on a new ``LocalCluster`` of single-threaded
worker processes; :func:`parse_memory` reads the per-worker memory limit such a cluster gets.
"""

from __future__ import annotations

import logging

from viform._validate import ViformError, one_line


def parse_memory(memory_limit) -> str | int:
    """Per-worker memory limit: ``"auto"`` (or None) or a size such as ``"2GiB"``, in bytes (≥ 64 MiB)."""
    if memory_limit in (None, "auto"):
        return "auto"
    from dask.utils import parse_bytes

    try:
        value = parse_bytes(str(memory_limit))
    except (ValueError, TypeError):
        raise ViformError(f"--worker-memory = {memory_limit!r} is not allowed: give a size such as 2GiB, "
                          "or auto") from None
    if value < 64 << 20:
        raise ViformError(f"--worker-memory = {memory_limit!r} is not allowed: at least 64MiB per worker")
    return value


def open_client(workers: int, scheduler: str | None, memory_limit):
    """(client, cluster): a client of the scheduler at ``scheduler`` (cluster None), or of a new
    LocalCluster of ``workers`` processes with one thread each and ``memory_limit`` per worker."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as exc:
            raise ViformError(f"--scheduler {scheduler!r}: could not connect ({one_line(exc)})") from None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, memory_limit=memory_limit,
                           dashboard_address=":0", silence_logs=logging.ERROR)
    return Client(cluster), cluster
