"""Self-describing chunked storage of long viforms (zarr).

The store is one zarr array of shape (T, H, ceil(W/8)) holding the spike bits packed
along the row (LSB first, upright rows), chunked along time, with the stream's metadata
(resolution, clock, Q, start time, sensor parameters) in its attributes under ``viform``.
Streams are written block by block (bounded memory) into a temporary folder that is
renamed into place at the end, so an interrupted write leaves nothing under the name.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from viform._io import atomic_path
from viform._validate import ViformError, check_int
from viform.stream.container import SpikeSource

FORMAT_NAME = "viform-spikes"
FORMAT_VERSION = 1


def _jsonable(metadata: dict) -> dict:
    from viform._io import _jsonable as convert

    return json.loads(json.dumps(metadata, default=convert))


class ZarrSpikeStore(SpikeSource):
    """A viform stored as zarr, read lazily by time chunk."""

    def __init__(self, path):
        import zarr

        path = Path(path)
        try:
            self._array = zarr.open_array(store=str(path), mode="r")
            header = dict(self._array.attrs["viform"])
        except Exception as exc:
            raise ViformError(f"{str(path)!r} is not a viform zarr store: {exc}") from None
        if header.get("format") != FORMAT_NAME:
            raise ViformError(f"{str(path)!r} is not a viform zarr store (format={header.get('format')!r})")
        self.path = path
        self.height, self.width = int(header["height"]), int(header["width"])
        self.n_ticks = int(self._array.shape[0])
        self.clock_hz = float(header["clock_hz"])
        q = header.get("threshold_electrons")
        self.threshold_electrons = None if q is None else float(q)
        self.start_time_s = float(header.get("start_time_s", 0.0))
        self.metadata = dict(header.get("metadata", {}))

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        packed = np.asarray(self._array[max(0, start):min(stop, self.n_ticks)])
        bits = np.unpackbits(packed, axis=-1, bitorder="little", count=self.width)
        return bits.view(bool)


def write_zarr(path, source: SpikeSource, *, block_ticks: int = 1024) -> Path:
    """Write ``source`` to a zarr store block by block, atomically (temporary folder + rename)."""
    import zarr

    block_ticks = check_int("block_ticks", block_ticks, 1)
    path = Path(path)
    packed_width = (source.width + 7) // 8
    header = {
        "format": FORMAT_NAME, "version": FORMAT_VERSION,
        "height": source.height, "width": source.width, "clock_hz": source.clock_hz,
        "threshold_electrons": source.threshold_electrons, "start_time_s": source.start_time_s,
        "bit_order": "little", "rows": "upright",
        "metadata": _jsonable(source.metadata),
    }
    with atomic_path(path, suffix=".zarr") as tmp:
        tmp.unlink()
        array = zarr.create_array(store=str(tmp), shape=(0, source.height, packed_width),
                                  chunks=(block_ticks, source.height, packed_width), dtype="uint8")
        array.attrs["viform"] = header
        for _, block in source.iter_blocks(block_ticks):
            array.append(np.packbits(block, axis=-1, bitorder="little"), axis=0)
    return path
