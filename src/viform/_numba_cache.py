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

The command line also holds its Ctrl-C and SIGTERM while numba compiles in the main thread
(:func:`defer_interrupts_in_compiles`): the command stops when that kernel is compiled, neither
lost inside LLVM's callbacks nor with a half-made kernel.
"""

from __future__ import annotations

import functools
import os
import sys
import threading

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


def defer_interrupts_in_compiles() -> None:
    """Hold the command line's Ctrl-C and SIGTERM while numba compiles a kernel (or loads it from its
    cache) in the main thread, and raise them when it returns (:func:`viform._io.interrupts_deferred`).

    Raised in the middle of numba's compile, an interrupt can be lost: raised inside a callback that
    LLVM calls through ctypes, which drops exceptions, so the command runs on as if never told to stop.
    It can also leave a compiled library half made, so that the command fails with "no compiled object
    yet" instead of stopping. numba is imported by the first command that needs a kernel, after the
    handlers are in place: its dispatcher is patched as it is imported (an import hook, removed once
    used), so a command that never compiles does not import numba for this. Idempotent.
    """
    module = sys.modules.get("numba.core.dispatcher")
    if module is not None:
        _defer_in(module)
    elif not any(isinstance(finder, _PatchDispatcherOnImport) for finder in sys.meta_path):
        sys.meta_path.insert(0, _PatchDispatcherOnImport())


def _defer_in(module) -> None:
    """Wrap ``module.Dispatcher.compile`` (numba's) in :func:`viform._io.interrupts_deferred` (main thread)."""
    original = module.Dispatcher.compile
    if getattr(original, "_viform_defers", False):
        return

    def compile(self, sig):  # noqa: A001 -- numba's method name
        if threading.current_thread() is not threading.main_thread():
            return original(self, sig)  # (signal handlers run in the main thread only)
        from viform._io import interrupts_deferred

        with interrupts_deferred():
            return original(self, sig)

    functools.update_wrapper(compile, original)  # (its doc, and the marks of other wrappers)
    compile._viform_defers = True
    module.Dispatcher.compile = compile


class _PatchDispatcherOnImport:
    """An import hook that finds numba's dispatcher module as the other finders do, and patches it
    (:func:`_defer_in`) once it has run; it removes itself on first use."""

    def find_spec(self, name, path, target=None):
        if name != "numba.core.dispatcher":
            return None
        sys.meta_path.remove(self)
        for finder in sys.meta_path:
            find = getattr(finder, "find_spec", None)
            spec = find(name, path, target) if find is not None else None
            if spec is not None:
                break
        else:
            return None
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            _defer_in(module)

        spec.loader.exec_module = exec_module
        return spec
