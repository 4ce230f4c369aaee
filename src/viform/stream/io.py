"""Open and save spike streams by file type: ``.dat`` (spike camera), ``.npz`` (arrays), zarr.

Every format carries the same header (:mod:`viform.stream.sidecar`): ``.dat`` in a JSON
sidecar beside it, ``.npz`` in a member, zarr in its attributes. Readers validate it at open
and keep memory bounded whatever the file length or declared size.
"""

from __future__ import annotations

import numbers
from pathlib import Path

from viform._validate import ViformError, size_text
from viform.stream.container import SpikeSource
from viform.stream.dat import DatFile, write_dat
from viform.stream.npz import NpzSpikes, read_npz, write_npz
from viform.stream.zarr_store import ZarrSpikeStore, write_zarr

#: File types :func:`open_spikes` and :func:`save_spikes` know.
FORMATS = (".dat", ".npz", ".zarr")

__all__ = ["FORMATS", "open_spikes", "save_spikes", "read_npz", "verify_spikes"]


def open_spikes(path, height: int | None = None, width: int | None = None, *,
                clock_hz: float | None = None, flip: bool | None = None, allow_partial: bool = False,
                threshold_electrons: float | None = None, key: str | None = None,
                axes: str | None = None) -> SpikeSource:
    """Open a spike stream by its file type.

    ``.dat`` takes height, width, clock, Q and row order from its sidecar when there is one
    (``height``/``width`` are then optional; a contradiction is refused); without a sidecar
    ``height`` and ``width`` are required. ``clock_hz`` and ``threshold_electrons`` override what
    the file records. ``key`` and ``axes`` choose the array of a ``.npz`` and its axis order
    (see :class:`~viform.stream.npz.NpzSpikes`).

    Parameters
    ----------
    path : str or Path
        A ``.dat`` (with or without sidecar), ``.npz``, ``.zarr`` or ``.vfc`` file.
    height, width : int, optional
        Size of a ``.dat`` without sidecar, pixels.
    clock_hz : float, optional
        Tick rate, Hz, overriding the file's.
    flip : bool, optional
        Whether a ``.dat``'s rows are stored bottom-up (default: its sidecar's, else True).
    allow_partial : bool
        Accept a ``.dat`` whose size is not a whole number of frames (the trailing bytes are ignored).
    threshold_electrons : float, optional
        Spike threshold Q, e⁻, overriding the file's.
    key : str, optional
        Name of the spike array of a ``.npz``.
    axes : str, optional
        Axis order of that array (``"thw"``, ``"hwt"`` ...).

    Returns
    -------
    SpikeSource
        The stream, read block by block (a ``.dat`` is memory-mapped).
    """
    from viform._io import clean_stale, store_set_aside

    _check_overrides(clock_hz, threshold_electrons)
    path = Path(path)
    suffix = path.suffix.lower()
    if not path.exists():
        clean_stale(path)  # a writer killed between its two renames set the old store aside
        if not path.exists():
            aside = store_set_aside(path)  # a live writer between its two renames: the old store is whole
            if aside is None:
                raise ViformError(f"spike file {str(path)!r} does not exist")
            path = aside
    if not (path.is_file() or path.is_dir()):  # a FIFO or device would block the reader
        raise ViformError(f"{str(path)!r} is not a regular file or folder")
    if suffix in (".dat", ".npz") and path.is_dir():
        raise ViformError(f"{str(path)!r} is a folder, not a {suffix} file")
    if suffix == ".dat":
        source = DatFile(path, height, width, flip=flip, allow_partial=allow_partial,
                         clock_hz=clock_hz, threshold_electrons=threshold_electrons)
    elif suffix == ".npz":
        source = NpzSpikes(path, clock_hz, key, axes)
        if threshold_electrons is not None:
            source.threshold_electrons = threshold_electrons
    elif suffix == ".zarr" or (path.is_dir() and (path / "zarr.json").exists()):
        source = ZarrSpikeStore(path)
        if clock_hz is not None:
            source.clock_hz = clock_hz
        if threshold_electrons is not None:
            source.threshold_electrons = threshold_electrons
    else:
        raise ViformError(f"unknown spike file type {suffix!r} for {str(path)!r}: use one of {', '.join(FORMATS)}")
    if source.n_ticks == 0:  # an empty stream has no instant, duration or rate: every command says so here
        raise ViformError(f"{str(path)!r} holds an empty stream (0 ticks of {size_text(source.height, source.width)} "
                          "pixels): there is nothing to read")
    return source


def _check_overrides(clock_hz, threshold_electrons) -> None:
    """A clock or Q given by the caller passes the bounds a file's header must pass."""
    from viform.stream.sidecar import (
        MAX_CLOCK_HZ,
        MAX_THRESHOLD_ELECTRONS,
        MIN_CLOCK_HZ,
        MIN_THRESHOLD_ELECTRONS,
    )

    for name, value, low, high, unit in (("clock_hz", clock_hz, MIN_CLOCK_HZ, MAX_CLOCK_HZ, "Hz"),
                                         ("threshold_electrons", threshold_electrons, MIN_THRESHOLD_ELECTRONS,
                                          MAX_THRESHOLD_ELECTRONS, "e⁻")):
        if value is None:
            continue
        ok = not isinstance(value, bool) and isinstance(value, numbers.Real) and low <= value <= high
        if not ok:
            raise ViformError(f"{name} = {value!r} is not allowed: it must be a number in [{low:g}, {high:g}] {unit}")


def verify_spikes(path, **kwargs) -> dict:
    """Open ``path`` and check everything it holds against its checksums and header.

    Returns ``{"file", "format", "verified", "checks", ...summary}``; a damaged file raises
    :class:`ViformError` naming the file and what is wrong.

    Parameters
    ----------
    path : str or Path
        The spike file.
    **kwargs
        Passed to :func:`open_spikes` (``height``, ``width``, ``key`` ...).

    Returns
    -------
    dict
        ``file``, ``format``, ``verified``, ``checks`` and the stream's summary.
    """
    source = open_spikes(path, **kwargs)
    result = source.verify() if hasattr(source, "verify") else {"verified": False, "checks": ["no checks"]}
    return {"file": str(path), "format": source.metadata.get("format"), **result}


def save_spikes(path, source: SpikeSource, *, flip: bool = True, block_ticks: int = 1024) -> Path:
    """Save a spike stream; the format follows the suffix (.dat + sidecar, .npz, .zarr). Atomic.

    Memory stays bounded for every format (blocks of at most a few tens of MB).

    Parameters
    ----------
    path : str or Path
        The file to write; its suffix chooses the format (:data:`FORMATS`).
    source : SpikeSource
        The spikes (a :class:`SpikeStream` or any opened file).
    flip : bool
        Store a ``.dat``'s rows bottom-up, as the cameras do.
    block_ticks : int
        Ticks written per block (memory bound).

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".dat":
        return write_dat(path, source, flip=flip, block_ticks=block_ticks)
    if suffix == ".zarr":
        return write_zarr(path, source, block_ticks=block_ticks)
    if suffix == ".npz":
        return write_npz(path, source, block_ticks=block_ticks)
    raise ViformError(f"unknown spike file type {suffix!r} for {str(path)!r}: use one of {', '.join(FORMATS)}")
