"""Processes that start together compile each of viform's numba kernels once, not once each.

numba keeps a compiled kernel in its on-disk cache (``cache=True``), but two processes that need the
same kernel before either has saved it both compile it: the workers of a sweep, of a dataset, or of
the test suite each spend the same minutes on the same machine code. :func:`share_compiles` makes a
process take a per-kernel file lock (beside the kernel's cache index) around numba's
``Dispatcher.compile``: the first process compiles and saves, the others wait for the lock, then load
the saved kernel from the cache — the same machine code numba would have loaded on the next run.

Set ``VIFORM_SHARE_COMPILES=1`` in the environment of processes started together (parallel jobs
on one machine; the test suite sets it for the commands its tests start) and importing viform calls
:func:`share_compiles`.

Only viform's own kernels with an on-disk cache are locked; every other numba function compiles as
numba does it. The lock is taken inside numba's process-wide compiler lock, so threads of one process
never wait on each other's file locks, and a kernel's lock is taken once per process even when its
compile nests (a kernel inlines another's, which is compiled first). Locks follow the call graph
(a kernel waits only for the kernels it calls), so two processes cannot deadlock; a process that dies
releases its locks (``flock``). Where ``fcntl`` or numba's internals are missing, nothing changes.
"""

from __future__ import annotations

import functools
import os

#: Module prefixes whose kernels are locked.
PACKAGES = ("viform.",)
_HELD: set[str] = set()


def _lock_path(dispatcher) -> str | None:
    """The lock file of a viform kernel with an on-disk cache, or None (not ours, or no cache)."""
    module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
    if not module.startswith(PACKAGES):
        return None
    cache = getattr(dispatcher, "_cache", None)
    folder = getattr(cache, "_cache_path", None)
    base = getattr(getattr(cache, "_impl", None), "filename_base", None)
    if not folder or not base:
        return None  # numba's NullCache: cache=False
    return os.path.join(folder, base + ".compile-lock")


def share_compiles() -> bool:
    """Make this process compile each viform kernel under its file lock (idempotent).

    Returns whether the locks are in place (False where ``fcntl`` or numba's internals are missing).
    """
    try:
        import fcntl

        from numba.core import dispatcher as numba_dispatcher
        from numba.core import sigutils
        from numba.core.compiler_lock import global_compiler_lock
    except ImportError:
        return False
    original = numba_dispatcher.Dispatcher.compile
    if getattr(original, "_viform_shared", False):
        return True

    def compile(self, sig):  # noqa: A001 -- numba's method name
        path = _lock_path(self)
        if path is None:
            return original(self, sig)
        with global_compiler_lock:
            args, _ = sigutils.normalize_signature(sig)
            if path in _HELD or tuple(args) in self.overloads:
                return original(self, sig)
            try:
                os.makedirs(os.path.dirname(path), exist_ok=True)
                handle = open(path, "a+b")  # noqa: SIM115 -- held across the compile
            except OSError:
                return original(self, sig)  # a read-only cache folder: numba compiles in memory
            with handle:
                fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
                _HELD.add(path)
                try:
                    return original(self, sig)
                finally:
                    _HELD.discard(path)
                    fcntl.flock(handle.fileno(), fcntl.LOCK_UN)

    functools.update_wrapper(compile, original)  # (its doc, and the marks of other wrappers)
    compile._viform_shared = True
    numba_dispatcher.Dispatcher.compile = compile
    return True

