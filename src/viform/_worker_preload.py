"""Imported once by the fork server that viform's local dask workers are forked from (see
:data:`viform._parallel.WORKER_START`): distributed's and numba's CPU target registries (a worker's first
compile or cache load would otherwise import them, scipy.linalg with them, in every worker). The modules
a command's tasks need are preloaded beside it. Nothing here starts a thread: numba's thread pool is not
safe to fork."""

from numba.core.registry import cpu_target

cpu_target.target_context.refresh()
