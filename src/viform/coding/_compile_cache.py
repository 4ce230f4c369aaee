"""Is numba's on-disk cache of the coding kernels warm? (So the CLI can announce a cold compile.)

The first ``viform encode``/``decode`` compiles the coding kernels (about a minute, several
under load) and caches them next to the modules; later runs load them in a fraction of a
second. numba invalidates a cache entry when its source file changes, so a stale ``.nbi``
file does not count as warm: the index itself is loaded and checked.
"""

from __future__ import annotations

import importlib

#: (module, kernel) pairs that each direction compiles at its top level.
_KERNELS = {
    "encode": (("first_spike", "_encode_block"), ("context_model", "encode_segment"),
               ("interval_model", "encode_segment")),
    "decode": (("first_spike", "_decode_block"), ("context_model", "decode_segment"),
               ("interval_model", "decode_segment")),
}

COMPILING_NOTICE = "compiling the coding kernels (first run only, about a minute; cached afterwards)"


def kernels_cached(direction: str = "encode") -> bool:
    """True when every top-level ``direction`` kernel has at least one valid cache entry.

    Uses numba's cache index (an internal API); if it cannot be read, says ``True`` so that
    at worst the notice is not shown.
    """
    try:
        for module, name in _KERNELS[direction]:
            dispatcher = getattr(importlib.import_module(f"viform.coding.{module}"), name)
            cache = getattr(dispatcher, "_cache", None)
            if cache is None or not cache._cache_file._load_index():
                return False
        return True
    except Exception:  # noqa: BLE001 -- an internal numba API changed: stay quiet rather than fail
        return True
