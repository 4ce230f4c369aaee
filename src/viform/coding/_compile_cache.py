"""numba's on-disk cache for the coding kernels: kept fresh, and a compile announced when it really happens.

Two things numba does not do on its own:

* **Freshness across modules.** numba keys a kernel's cache entry on its own source file only, but
  the coding kernels inline code from the other modules of this package (the range coder of
  :mod:`~viform.coding._range_coder` sits inside every model's coding loop): after an edit of the
  coder alone, the models would load machine code built from the old coder. The cache locators
  registered here (:func:`install_locators`, run by ``viform/coding/__init__.py`` before any kernel
  is defined) stamp every kernel of this package with a hash of all its source files that define
  kernels.
* **Saying when it compiles.** The first ``viform encode``/``decode`` on a machine compiles the
  kernels it needs (about a minute, several under load); later runs load them from the cache.
  :func:`announce_compiles` registers a numba compile listener that calls back once, at the first
  compile of a coding kernel — so the notice appears exactly when a compile happens, never on a
  run that only loads the cache (predicting it from the cache index named kernels a given file
  never uses, and announced a compile on every run).
"""

from __future__ import annotations

import hashlib
import threading
from pathlib import Path

COMPILING_NOTICE = "compiling the coding kernels (first run only, about a minute; cached afterwards)"

_HERE = Path(__file__).resolve().parent
_STAMP: str | None = None


def sources_stamp(folder: Path = _HERE) -> str:
    """A hash of every ``*.py`` file in ``folder`` that defines numba kernels (names and contents).

    Only those can be inlined into a kernel: an edit of a file without kernels (the container, a
    version's payload layout) leaves the compiled kernels valid.
    """
    h = hashlib.sha256()
    for path in sorted(folder.glob("*.py")):
        text = path.read_bytes()
        if b"njit" in text:
            h.update(path.name.encode() + b"\0" + text + b"\0")
    return h.hexdigest()


def _package_stamp() -> str:
    global _STAMP
    if _STAMP is None:
        _STAMP = sources_stamp()
    return _STAMP


def _in_package(py_file) -> bool:
    try:
        return Path(py_file).resolve().parent == _HERE
    except OSError:
        return False


def _coding_locator(base):
    """``base`` (a numba source-file locator) for this package's kernels, stamped by every source file."""

    class Locator(base):
        @classmethod
        def from_function(cls, py_func, py_file):
            if not _in_package(py_file):
                return None
            return super().from_function(py_func, py_file)

        def get_source_stamp(self):
            return ("viform.coding", _package_stamp())

    Locator.__name__ = Locator.__qualname__ = f"Coding{base.__name__}"
    return Locator


def install_locators() -> None:
    """Put the package-stamped locators in front of numba's own (idempotent; quiet if numba changed)."""
    try:
        from numba.core import caching

        impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
        classes = impl._locator_classes
        if any(getattr(c, "_viform_coding", False) for c in classes):
            return
        out = []
        for base in classes:
            if base.__name__.lstrip("_") in ("UserProvidedCacheLocator", "InTreeCacheLocator",
                                             "UserWideCacheLocator"):
                ours = _coding_locator(base)
                ours._viform_coding = True
                out.append(ours)
            out.append(base)
        impl._locator_classes = out
    except Exception:  # noqa: BLE001 -- an internal numba API changed: numba's own locators still work
        return


_LOCK = threading.Lock()
_CALLBACK = None
_ANNOUNCED = False
_LISTENING = False


def announce_compiles(callback) -> None:
    """Call ``callback()`` once, at the first compile (not cache load) of a coding kernel in this process."""
    global _CALLBACK, _LISTENING
    from numba.core import event

    with _LOCK:
        _CALLBACK = callback
        if _LISTENING:
            return

        class _Listener(event.Listener):
            def on_start(self, ev):
                global _ANNOUNCED
                dispatcher = (ev.data or {}).get("dispatcher")
                module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
                if not module.startswith("viform.coding"):
                    return
                with _LOCK:
                    if _ANNOUNCED or _CALLBACK is None:
                        return
                    _ANNOUNCED = True
                    cb = _CALLBACK
                cb()

            def on_end(self, ev):
                pass

        event.register("numba:compile", _Listener())
        _LISTENING = True


def coding_dispatchers() -> list:
    """Every numba dispatcher of the coding modules that are imported (for cache statistics)."""
    import sys

    out = []
    for name, module in list(sys.modules.items()):
        if not name.startswith("viform.coding") or module is None:
            continue
        for value in vars(module).values():
            if hasattr(value, "stats") and hasattr(value, "py_func") and \
                    getattr(value.py_func, "__module__", "") == name:
                out.append(value)
    return out
