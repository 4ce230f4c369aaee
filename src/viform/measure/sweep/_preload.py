"""Imported once by the fork server that a sweep's local dask workers are forked from (see
:data:`viform.measure.sweep.run.WORKER_START`): the modules a point needs, and numba's CPU
target registries (its first compile or cache load would otherwise import them, scipy.linalg with
them, in every worker). Nothing here starts a thread: numba's thread pool is not safe to fork."""

from numba.core.registry import cpu_target

import viform.measure.sweep.run  # noqa: F401 -- a point's modules, imported once for every worker

cpu_target.target_context.refresh()
