"""Atomic file output: write to a temporary file beside the target, then rename.

A failure or Ctrl-C part-way leaves no half-written file under the target's name.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import sys
import tempfile
import threading
from pathlib import Path

#: Marker in the names of temporary outputs: ``.NAME.viform-tmp-PID-XXXX`` (being written) and
#: ``.NAME.viform-old-PID-XXXX`` (a replaced folder store awaiting deletion). A later write to
#: the same NAME removes those whose process is gone (see :func:`clean_stale`).
TMP_MARK = ".viform-tmp-"
OLD_MARK = ".viform-old-"


_deferred_sections = 0
_pending_interrupt: BaseException | None = None
#: Outputs completed (renamed in) since :func:`begin_outputs`, in order: what an interrupted command kept.
_completed: list[Path] = []


def begin_outputs() -> None:
    """Start a new record of completed outputs (the CLI calls it when a command starts)."""
    _completed.clear()


def completed_outputs() -> list[Path]:
    """Outputs written whole (renamed in) since :func:`begin_outputs` that are still there."""
    seen, kept = set(), []
    for path in _completed:
        if path not in seen and os.path.lexists(path):
            seen.add(path)
            kept.append(path)
    return kept


@contextlib.contextmanager
def interrupts_deferred():
    """Hold Ctrl-C and SIGTERM while a library call that must not be cut runs; raise them after it.

    zarr does its I/O on an event-loop thread and waits for it: an interrupt raised in the middle
    of such a call can leave that thread waiting forever (the process then hangs at exit) or the
    library in a broken state. The CLI's signal handlers call :func:`raise_or_defer`, which raises
    at once outside these sections and at the end of the outermost one inside.
    """
    global _deferred_sections, _pending_interrupt
    _deferred_sections += 1
    try:
        yield
    finally:
        _deferred_sections -= 1
        if _deferred_sections == 0 and _pending_interrupt is not None:
            interrupt, _pending_interrupt = _pending_interrupt, None
            raise interrupt


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
    """Wrap ``module.Dispatcher.compile`` (numba's) in :func:`interrupts_deferred` (main thread only).

    The file lock of :func:`viform._numba_cache.share_compiles` stays outside the deferral, whichever was
    installed first: waiting for another process's compile remains interruptible.
    """
    current = module.Dispatcher.compile
    if getattr(current, "_viform_defers", False):
        return
    shared = getattr(current, "_viform_shared", False)
    original = current.__wrapped__ if shared else current  # numba's own: the lock is put back around it below

    def compile(self, sig):  # noqa: A001 -- numba's method name
        if threading.current_thread() is not threading.main_thread():
            return original(self, sig)  # (signal handlers run in the main thread only)
        with interrupts_deferred():
            return original(self, sig)

    functools.update_wrapper(compile, original)  # (its doc, and the marks of other wrappers)
    compile._viform_defers = True
    module.Dispatcher.compile = compile
    if shared:
        from viform._numba_cache import share_compiles

        share_compiles()


class _PatchAfterExec:
    """The loader of numba's dispatcher module alone, which patches it (:func:`_defer_in`) once it has run;
    everything else is the real loader's (which may serve other modules too)."""

    def __init__(self, loader):
        self._loader = loader

    def __getattr__(self, name):
        return getattr(self._loader, name)

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        self._loader.exec_module(module)
        _defer_in(module)


class _PatchDispatcherOnImport:
    """An import hook that finds numba's dispatcher module as the other finders do, and patches it
    (:func:`_defer_in`) once it has run; it removes itself on first use. A loader of the old protocol
    (no ``exec_module``) is left as it is: the compiles are then not deferred."""

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
        if callable(getattr(spec.loader, "exec_module", None)):
            spec.loader = _PatchAfterExec(spec.loader)
        return spec


def import_uninterrupted(module: str):
    """Import ``module`` with interrupts held: an interrupt in the middle of a big library's first
    import leaves it half-initialised (dataclass fields that raise RuntimeError, event-loop threads
    that never finish)."""
    import importlib

    with interrupts_deferred():
        return importlib.import_module(module)


def raise_or_defer(interrupt: BaseException) -> None:
    """Raise ``interrupt`` now, or when the current :func:`interrupts_deferred` section ends."""
    global _pending_interrupt
    if _deferred_sections:
        if _pending_interrupt is None:
            _pending_interrupt = interrupt
        return
    raise interrupt


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # another user's process (or not ours to judge): leave its files alone
    return True


def _leftover_pid(name: str, prefix: str) -> int | None:
    """The writer's process id in a leftover name ``prefix + PID-...``, or None."""
    if not name.startswith(prefix):
        return None
    digits = name[len(prefix):].split("-", 1)[0]
    return int(digits) if digits.isdigit() and len(digits) < 10 else None


def _remove(path: Path) -> None:
    import shutil

    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def clean_stale(path) -> list[Path]:
    """Remove what killed writers left beside ``path``; returns what was removed or restored.

    A temporary ``.NAME.viform-tmp-PID-*`` of a dead process is deleted. A folder store
    ``.NAME.viform-old-PID-*`` set aside by a dead process is deleted when ``path`` exists (the
    new store made it in) and renamed back onto ``path`` when it does not (the writer died
    between the two renames: the old store is whole again).
    """
    path = Path(path)
    parent = path.parent
    done: list[Path] = []
    tmp_prefix = f".{path.name}{TMP_MARK}"
    old_prefix = f".{path.name}{OLD_MARK}"
    try:
        entries = [e for e in parent.iterdir() if e.name.startswith((tmp_prefix, old_prefix))]
    except OSError:
        return done
    for entry in sorted(entries, key=lambda e: e.name):
        is_tmp = entry.name.startswith(tmp_prefix)
        pid = _leftover_pid(entry.name, tmp_prefix if is_tmp else old_prefix)
        if pid is None or _pid_alive(pid):
            continue
        if not is_tmp and not os.path.lexists(path):
            with contextlib.suppress(OSError):
                os.rename(entry, path)
                done.append(entry)
                continue
        _remove(entry)
        done.append(entry)
    return done


def store_set_aside(path) -> Path | None:
    """The old folder store a live writer has renamed aside from ``path`` while it renames its new
    one in (the moment between the two renames of :func:`atomic_path`), or None.

    A reader that finds ``path`` missing reads this one: the old store is whole until the writer,
    once its new store is in, deletes it (a read then fails on a missing chunk, never on wrong bits).
    """
    path = Path(path)
    prefix = f".{path.name}{OLD_MARK}"
    try:
        entries = sorted(e for e in path.parent.iterdir() if e.name.startswith(prefix) and e.is_dir())
    except OSError:
        return None
    for entry in entries:
        pid = _leftover_pid(entry.name, prefix)
        if pid is not None and _pid_alive(pid):
            return entry
    return None


def folder_writable(folder) -> bool:
    """Whether a file can be created in the existing ``folder``, tried by creating (and removing) one.

    ``os.access`` is not enough: for root it says yes to read-only mounts and to ``/proc``.
    """
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".viform-probe-"):
            pass
    except OSError:
        return False
    return True


def _check_target(path: Path, directory: bool) -> None:
    from viform._validate import ViformError

    if path.is_dir() and not directory:
        raise ViformError(f"{str(path)!r} is an existing folder; a file was expected there")
    if directory and path.exists() and not path.is_dir():
        raise ViformError(f"{str(path)!r} is an existing file; a folder store was expected there")
    existing = path.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ViformError(f"{str(path)!r} cannot be written: {str(existing)!r} is not a folder")
    if not folder_writable(existing):
        raise ViformError(f"{str(path)!r} cannot be written: the folder {str(existing)!r} is not writable")


def check_output_path(option: str, path, *, directory: bool = False) -> None:
    """Refuse, before any work, an output ``path`` that cannot be written as a file (or a folder).

    ``option`` (the flag the user typed, e.g. ``--out``) leads the message.
    """
    from viform._validate import ViformError

    try:
        _check_target(Path(path), directory)
    except ViformError as exc:
        raise ViformError(f"{option}: {exc}") from None


def _rename(src: Path, dst: Path) -> None:
    """The renames of :func:`atomic_path` (one function, so that tests can stop a writer at each)."""
    os.replace(src, dst)


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None, *, directory: bool = False, output: bool = True):
    """Yield a temporary path in the target's folder; move it onto ``path`` on success.

    ``suffix`` defaults to the target's own suffix (libraries that pick a format from
    the name see the right one). With ``directory=False`` an empty temporary file is
    created; with ``directory=True`` nothing is created and the caller makes a folder there
    (e.g. a zarr store). On any exception (Ctrl-C and SIGTERM included) the temporary is
    removed and the target is untouched; an interrupt that arrives while the output is being
    renamed in waits until it is (the command line's handlers, :func:`interrupts_deferred`), so the
    output is then whole under its name and listed by :func:`completed_outputs` (unless
    ``output=False``: a cache file the command keeps for later runs, not one of its outputs).

    A folder replaces an existing one in three steps: the old store is renamed aside, the
    new one renamed in, the old one deleted; a crash at any point leaves the old or the new
    store whole under ``path``, and the next write to ``path`` finishes the job
    (:func:`clean_stale`). Temporary names carry the writer's process id so that a later run
    recognises those of killed writers.
    """
    import shutil

    from viform._validate import ViformError

    path = Path(path)
    suffix = path.suffix if suffix is None else suffix
    pid = os.getpid()
    tmp = None
    try:
        _check_target(path, directory)
        path.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(path)
        with interrupts_deferred():  # an interrupt between creating the temporary and the try below would leak it
            if directory:
                tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}{TMP_MARK}{pid}-", suffix=suffix, dir=path.parent))
                tmp.rmdir()  # the caller creates it (libraries refuse an existing folder)
            else:
                fd, name = tempfile.mkstemp(prefix=f".{path.name}{TMP_MARK}{pid}-", suffix=suffix, dir=path.parent)
                os.close(fd)
                tmp = Path(name)
                try:  # mkstemp creates 0600; give the result the permissions a plain open() would
                    umask = os.umask(0)
                    os.umask(umask)
                    os.chmod(tmp, 0o666 & ~umask)
                except OSError:
                    _remove(tmp)
                    raise
    except OSError as exc:  # name the file the user asked for, not the temporary one
        raise ViformError(f"{str(path)!r} cannot be written: {exc.strerror or exc}") from None
    except BaseException:  # an interrupt held while the temporary was made is raised here
        if tmp is not None:
            _remove(tmp)
        raise
    old = None
    try:
        yield tmp
        # Ctrl-C/SIGTERM wait for the renames, the record of them and the old store's removal (raised after:
        # the output is then whole under its name, and reported as kept)
        with interrupts_deferred():
            if tmp.is_dir() and os.path.lexists(path):
                old = Path(tempfile.mkdtemp(prefix=f".{path.name}{OLD_MARK}{pid}-", dir=path.parent))
                old.rmdir()
                _rename(path, old)
                try:
                    _rename(tmp, path)
                except BaseException:
                    _rename(old, path)  # put the old store back
                    old = None
                    raise
            else:
                _rename(tmp, path)
            if output:
                _completed.append(path)
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        _remove(tmp)
        raise


@contextlib.contextmanager
def atomic_open(path, mode: str = "wb", *, output: bool = True):
    """Open a temporary file for writing; it replaces ``path`` only when the block succeeds
    (``output``: as for :func:`atomic_path`)."""
    with atomic_path(path, output=output) as tmp, open(tmp, mode) as f:
        yield f


def check_output_folder(option: str, folder) -> None:
    """Refuse, before any work, an output folder that cannot be created or written.

    ``option`` names the command-line option or parameter in the error message.
    """
    from viform._validate import ViformError

    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ViformError(f"{option}: {existing} is not a folder, so {folder} cannot be created")
    if not folder_writable(existing):
        raise ViformError(f"{option}: the folder {existing} is not writable")


#: What every command's ``--json-file`` does with folders (the CLI shows it in each command's help).
JSON_FILE_HELP = ("Also write the JSON that --json prints to this file. Missing folders are created (as for an "
                  "output folder); an existing file is replaced.")


def check_json_file(path, option: str = "--json-file") -> None:
    """Refuse, before any work, a JSON output ``path`` that cannot be written; None passes.

    The one rule for every command's ``--json-file`` (applied centrally by the CLI): like
    ``--out``, missing folders are created when the file is written (by :func:`write_json`);
    refused are an existing folder or a FIFO/device at ``path``, a path under a regular file,
    and a folder that is not writable. ``option`` (the flag the user typed) leads the message.
    """
    from viform._validate import ViformError

    if path is None:
        return
    path = Path(path)
    if path.is_dir():
        raise ViformError(f"{option} = {str(path)!r} is an existing folder; give a file name for the JSON")
    if path.exists() and not path.is_file():
        raise ViformError(f"{option} = {str(path)!r} is not a regular file (a FIFO or device cannot hold the JSON)")
    try:
        _check_target(path, directory=False)
    except ViformError as exc:
        raise ViformError(f"{option} = {exc}") from None


def write_json(path, data) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_open(path, "w") as f:
        json.dump(data, f, indent=2, default=_jsonable)
        f.write("\n")


def save_image(path, image) -> None:
    """Write an image (PNG, …) atomically with imageio."""
    import imageio.v3 as iio

    with atomic_path(path) as tmp:
        iio.imwrite(tmp, image, extension=Path(path).suffix)


def save_figure(path, figure, dpi: int = 110) -> None:
    """Save a matplotlib figure atomically and close it."""
    import matplotlib.pyplot as plt

    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=dpi, format=Path(path).suffix.lstrip(".") or "png")
    plt.close(figure)


def _jsonable(value):
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")
