"""Open and save viforms by file type: ``.dat`` (spike camera), ``.npz`` (arrays), zarr."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from viform._io import atomic_path
from viform._validate import ViformError
from viform.stream.container import SpikeSource, SpikeStream
from viform.stream.dat import DEFAULT_DAT_CLOCK_HZ, read_dat, write_dat
from viform.stream.zarr_store import ZarrSpikeStore, write_zarr

#: File types :func:`open_spikes` and :func:`save_spikes` know.
FORMATS = (".dat", ".npz", ".zarr")


def read_npz(path, clock_hz: float = DEFAULT_DAT_CLOCK_HZ, key: str | None = None) -> SpikeStream:
    """A stream from a ``.npz`` holding a 0/1 array of shape (T, H, W).

    The array is taken from ``key``, else ``spk`` or ``spikes`` (the Spike-Zoo and viform
    names). Metadata arrays saved by :func:`save_spikes` (clock, Q, start) are used when present;
    other scalar entries (e.g. a label) go to the metadata.
    """
    if not zipfile.is_zipfile(path):
        raise ViformError(f"{str(path)!r} is not a .npz file (not a zip archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            names = list(data.keys())
            key = key or next((k for k in ("spikes", "spk") if k in names), None)
            if key is None:
                raise ViformError(f"{str(path)!r} has no 'spikes' or 'spk' array (it has {names})")
            spikes = data[key]
            extra = {k: data[k].item() for k in names if k != key and data[k].ndim == 0}
    except ViformError:
        raise
    except Exception as exc:
        raise ViformError(f"{str(path)!r} could not be read as .npz: {exc}") from None
    if spikes.ndim != 3:
        raise ViformError(f"{str(path)!r}: array {key!r} must have shape (T, H, W); got {spikes.shape}")
    clock = float(extra.pop("clock_hz", clock_hz))
    q = extra.pop("threshold_electrons", None)
    q = None if q is None or (isinstance(q, float) and np.isnan(q)) else float(q)
    start = float(extra.pop("start_time_s", 0.0))
    extra = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in extra.items()}
    return SpikeStream(spikes, clock, q, start, {"source": str(path), "format": "npz", **extra})


def open_spikes(path, height: int | None = None, width: int | None = None, *,
                clock_hz: float | None = None, flip: bool = True, allow_partial: bool = False,
                threshold_electrons: float | None = None) -> SpikeSource:
    """Open a viform by its file type (``.dat`` needs ``height`` and ``width``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if not path.exists():
        raise ViformError(f"spike file {str(path)!r} does not exist")
    # None means "not given"; 0 or a negative clock is refused by the readers, not replaced
    clock_hz = DEFAULT_DAT_CLOCK_HZ if clock_hz is None else clock_hz
    if suffix == ".dat":
        return read_dat(path, height, width, flip=flip, allow_partial=allow_partial,
                        clock_hz=clock_hz, threshold_electrons=threshold_electrons)
    if suffix == ".npz":
        stream = read_npz(path, clock_hz)
        if threshold_electrons is not None:
            stream.threshold_electrons = threshold_electrons
        return stream
    if suffix == ".zarr" or (path.is_dir() and (path / "zarr.json").exists()):
        return ZarrSpikeStore(path)
    raise ViformError(f"unknown spike file type {suffix!r} for {str(path)!r}: use one of {', '.join(FORMATS)}")


def save_spikes(path, source: SpikeSource, *, flip: bool = True, block_ticks: int = 1024) -> Path:
    """Save a viform; the format follows the suffix (.dat, .npz, .zarr). Atomic."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".dat":
        return write_dat(path, source, flip=flip, block_ticks=block_ticks)
    if suffix == ".zarr":
        return write_zarr(path, source, block_ticks=block_ticks)
    if suffix == ".npz":
        stream = source if isinstance(source, SpikeStream) else source.to_memory()
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(
                    f, spikes=stream.spikes.astype(np.uint8), clock_hz=stream.clock_hz,
                    threshold_electrons=np.nan if stream.threshold_electrons is None
                    else stream.threshold_electrons, start_time_s=stream.start_time_s)
        return path
    raise ViformError(f"unknown spike file type {suffix!r} for {str(path)!r}: use one of {', '.join(FORMATS)}")
