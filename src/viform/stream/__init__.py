"""Spike-stream (viform) data: container, .dat files, zarr stores, events view.

* :class:`SpikeStream` holds spikes in memory (bit-packed); :class:`SpikeSource` is what every reader
  gives (a stream, a memory-mapped ``.dat``, an ``.npz``, a zarr store), read block by block.
* :func:`open_spikes` / :func:`save_spikes` / :func:`verify_spikes` read, write and check any of the
  :data:`FORMATS` by its suffix; the format's own functions are :func:`read_dat` / :func:`write_dat`
  (:func:`pack_frames`), :func:`read_npz` / :func:`write_npz` and :func:`write_zarr`
  (:class:`ZarrSpikeStore`).
* The JSON sidecar beside a ``.dat`` (size, clock, threshold, provenance, checksums):
  :func:`sidecar_path`, :func:`read_sidecar`, :func:`write_sidecar`, :func:`provenance`.

The names are imported on first use (:mod:`viform._lazy`): ``import viform.stream`` costs nothing.
"""

from viform import _lazy

__all__ = [
    "SpikeStream", "SpikeSource",
    "FORMATS", "open_spikes", "save_spikes", "verify_spikes",
    "read_dat", "write_dat", "pack_frames", "read_npz", "write_npz", "write_zarr", "ZarrSpikeStore",
    "sidecar_path", "read_sidecar", "write_sidecar", "provenance",
]

__getattr__, __dir__ = _lazy.attach(__name__, __all__, {
    "container": ["SpikeStream", "SpikeSource"],
    "io": ["FORMATS", "open_spikes", "save_spikes", "verify_spikes"],
    "dat": ["read_dat", "write_dat", "pack_frames"],
    "npz": ["read_npz", "write_npz"],
    "zarr_store": ["write_zarr", "ZarrSpikeStore"],
    "sidecar": ["sidecar_path", "read_sidecar", "write_sidecar", "provenance"],
})
