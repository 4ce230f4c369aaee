"""Self-describing chunked storage of long spike streams (zarr), checked on every read.

The store is one zarr array of shape (T, H, ceil(W/8)) holding the spike bits packed
along the row (LSB first), chunked along time, with the stream's header (resolution, clock,
Q, start time, row order, sensor description, provenance: :mod:`viform.stream.sidecar`) in
its attributes under ``viform``.

Integrity (format version 2): every chunk is stored (none is left implicit), zstd frames
carry their own checksum, and the header holds a manifest of the CRC-32 of each time
chunk's packed bytes plus a BLAKE2b of the header itself. A reader checks the header when
it opens the store and each chunk's CRC when it reads it: a missing, damaged or swapped
chunk is a one-line error naming the store and the chunk, never zeros or wrong bits.
Stores are written block by block (bounded memory) into a temporary folder that replaces
the old store only when complete (:func:`viform._io.atomic_path`).
"""

from __future__ import annotations

import hashlib
import json
import math
import zlib
from pathlib import Path

import numpy as np

from viform._io import atomic_path, import_uninterrupted, interrupts_deferred
from viform._validate import ViformError, check_int
from viform.stream.container import SpikeSource
from viform.stream.sidecar import HEADER_FIELDS, check_consistent, source_metadata, stream_header, validate_header

FORMAT_NAME = "viform-spikes"
FORMAT_VERSION = 2
#: Fields only version 2 writes (their presence in a "version 1" header means an edit).
_MANIFEST_FIELDS = ("chunks", "chunk_ticks", "header_blake2b", "n_ticks", "viform_version", "utc_date",
                    "command_line")
#: Every field of a version 2 header (others are refused).
_HEADER_FIELDS = HEADER_FIELDS + ("format", "version", "chunk_ticks", "chunks", "header_blake2b")
#: Bytes of packed bits per stored chunk at most (a chunk is read whole to check its CRC).
CHUNK_BUDGET_BYTES = 4 << 20


def _jsonable(metadata: dict) -> dict:
    from viform._io import _jsonable as convert

    return json.loads(json.dumps(metadata, default=convert))


def _header_digest(header: dict) -> str:
    body = {k: v for k, v in header.items() if k != "header_blake2b"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()


def chunk_ticks_for(height: int, width: int, block_ticks: int | None = None) -> int:
    """Ticks per stored chunk: ``block_ticks`` capped so a packed chunk is ≤ :data:`CHUNK_BUDGET_BYTES`."""
    packed = max(1, height * ((width + 7) // 8))
    cap = max(1, CHUNK_BUDGET_BYTES // packed)
    return cap if block_ticks is None else max(1, min(int(block_ticks), cap))


class ZarrSpikeStore(SpikeSource):
    """A spike stream stored as zarr, read lazily by time chunk and checked chunk by chunk.

    Parameters
    ----------
    path : path-like
        The store (a folder).
    verify : bool
        Check each chunk's CRC-32 as it is read (default True). Stores written before
        checksums existed (format version 1) are refused unless ``verify=False`` (then read
        unchecked; ``self.checked`` says which). A version 1 store holding any field of the
        version 2 manifest had its version edited down: it is refused as damaged.
    """

    def __init__(self, path, verify: bool = True):
        zarr = import_uninterrupted("zarr")

        path = Path(path)
        self.path = path
        if not path.is_dir():
            raise ViformError(f"{str(path)!r} is not a zarr store (not a folder)")
        try:
            with interrupts_deferred():
                self._array = zarr.open_array(store=str(path), mode="r")
                attrs = self._array.attrs.asdict()
        except Exception as exc:
            raise ViformError(f"{str(path)!r} is not a readable zarr store: {_short(exc)}") from None
        header = attrs.get("viform")
        if not isinstance(header, dict):
            raise ViformError(f"{str(path)!r} is not a viform zarr store: attribute 'viform' is missing")
        if header.get("format") != FORMAT_NAME:
            raise ViformError(f"{str(path)!r} is not a viform zarr store (format={header.get('format')!r})")
        version = header.get("version")
        if version not in (1, FORMAT_VERSION):
            raise ViformError(f"{str(path)!r}: field 'version' = {version!r} is not supported "
                              f"(this viform reads versions 1 and {FORMAT_VERSION})")
        if version == 1:
            edited = [k for k in _MANIFEST_FIELDS if k in header]
            if edited:
                raise ViformError(f"{str(path)!r}: field 'version' = 1 but the header holds the version "
                                  f"{FORMAT_VERSION} field {edited[0]!r}: the store is damaged or was edited")
            if verify:
                raise ViformError(f"{str(path)!r} was written without checksums (format version 1, an early "
                                  "viform): its data cannot be verified; write it again with viform, or read it "
                                  "unchecked from Python with ZarrSpikeStore(path, verify=False)")
        # version 2 stores are written whole by viform: every field must be there (null where unknown)
        validate_header(header, path, required=("height", "width", "clock_hz") if version == 1 else
                        ("height", "width", "clock_hz", "start_time_s", "rows", "bit_order"))
        if version >= 2 and "threshold_electrons" not in header:
            raise ViformError(f"{str(path)!r}: required field 'threshold_electrons' is missing from the header")
        self.header = header
        self.height, self.width = int(header["height"]), int(header["width"])
        packed_width = (self.width + 7) // 8
        shape = tuple(int(n) for n in self._array.shape)
        if len(shape) != 3 or shape[1:] != (self.height, packed_width) or self._array.dtype != np.uint8:
            raise ViformError(f"{str(path)!r}: the array has shape {shape} and dtype {self._array.dtype}, "
                              f"not (ticks, {self.height}, {packed_width}) uint8 as its header declares")
        self.n_ticks = shape[0]
        self.chunk_ticks = int(self._array.chunks[0])
        if tuple(self._array.chunks[1:]) != (self.height, packed_width):
            raise ViformError(f"{str(path)!r}: chunks {self._array.chunks} must span whole frames")
        self.clock_hz = float(header["clock_hz"])
        q = header.get("threshold_electrons")
        self.threshold_electrons = None if q is None else float(q)
        self.start_time_s = float(header.get("start_time_s") or 0.0)
        self.flip = header.get("rows") == "bottom-up"
        self.checked = version >= 2 and verify
        self._crcs = None
        if version >= 2:
            self._check_manifest(header)
            if verify:
                self._crcs = [int(c) for c in header["chunks"]]
        self.metadata = source_metadata(header)
        self.metadata.update({"source": str(path), "format": "zarr"})

    def _check_manifest(self, header: dict) -> None:
        path = self.path
        for key in ("n_ticks", "chunk_ticks", "chunks", "header_blake2b"):
            if key not in header:
                raise ViformError(f"{str(path)!r}: required field {key!r} is missing from the header")
        for key in ("n_ticks", "chunk_ticks"):
            v = header[key]
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ViformError(f"{str(path)!r}: field {key!r} = {v!r} must be a whole number ≥ 0")
        chunks = header["chunks"]
        if not isinstance(chunks, list) or not all(isinstance(c, int) and not isinstance(c, bool)
                                                   and 0 <= c < 2**32 for c in chunks):
            raise ViformError(f"{str(path)!r}: field 'chunks' must be a list of CRC-32 values")
        if _header_digest(header) != header["header_blake2b"]:
            raise ViformError(f"{str(path)!r}: the header is damaged or was edited (its BLAKE2b checksum differs)")
        check_consistent(header, repr(str(path)), known=_HEADER_FIELDS)
        if int(header["n_ticks"]) != self.n_ticks:
            raise ViformError(f"{str(path)!r}: the header declares {header['n_ticks']} ticks but the array holds "
                              f"{self.n_ticks}")
        if int(header["chunk_ticks"]) != self.chunk_ticks:
            raise ViformError(f"{str(path)!r}: field 'chunk_ticks' = {header['chunk_ticks']!r} differs from the "
                              f"array's {self.chunk_ticks}")
        n_chunks = math.ceil(self.n_ticks / self.chunk_ticks)
        chunks = header["chunks"]
        if not isinstance(chunks, list) or len(chunks) != n_chunks:
            raise ViformError(f"{str(path)!r}: the checksum manifest lists "
                              f"{len(chunks) if isinstance(chunks, list) else chunks!r} chunks, not {n_chunks}")
        for i in range(n_chunks):
            if not self._chunk_file(i).is_file():
                raise ViformError(f"{str(path)!r}: chunk {i} (ticks {i * self.chunk_ticks}–"
                                  f"{min((i + 1) * self.chunk_ticks, self.n_ticks) - 1}) is missing")

    def _chunk_file(self, index: int) -> Path:
        return self.path / "c" / str(index) / "0" / "0"

    def _read_packed(self, start: int, stop: int) -> np.ndarray:
        """Packed rows of ticks [start, stop), each chunk touched read whole and checked."""
        if self._crcs is None:
            return self._load(start, stop)
        ct = self.chunk_ticks
        first, last = start // ct, (stop - 1) // ct
        parts = []
        for i in range(first, last + 1):
            a, b = i * ct, min((i + 1) * ct, self.n_ticks)
            if not self._chunk_file(i).is_file():
                raise ViformError(f"{str(self.path)!r}: chunk {i} (ticks {a}–{b - 1}) is missing")
            chunk = self._load(a, b)
            if zlib.crc32(chunk.tobytes()) != self._crcs[i]:
                raise ViformError(f"{str(self.path)!r}: chunk {i} (ticks {a}–{b - 1}) is damaged "
                                  "(its CRC-32 differs from the manifest)")
            self._check_padding(chunk, i, a, b)
            parts.append(chunk[max(start, a) - a: min(stop, b) - a])
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def _check_padding(self, chunk: np.ndarray, index: int, a: int, b: int) -> None:
        """The bits past the declared width in each row's last byte are zero, as viform writes them:
        a non-zero one means the data is wider than the header says (the width was edited)."""
        spare = (-self.width) % 8
        if spare and chunk.size and np.any(chunk[..., -1] & np.uint8((0xFF << (8 - spare)) & 0xFF)):
            raise ViformError(f"{str(self.path)!r}: chunk {index} (ticks {a}–{b - 1}) holds spikes past the declared "
                              f"width of {self.width} columns (its padding bits are not zero): the header was edited "
                              "or the store is damaged")

    def _load(self, a: int, b: int) -> np.ndarray:
        try:
            with interrupts_deferred():
                return np.asarray(self._array[a:b])
        except Exception as exc:  # the codec's own error names neither the store nor the chunk
            raise ViformError(f"{str(self.path)!r}: ticks {a}–{b - 1} cannot be decoded (damaged chunk: "
                              f"{_short(exc)})") from None

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, start), min(stop, self.n_ticks)
        if stop <= start:
            return np.zeros((0, self.height, self.width), bool)
        if not self.checked:
            self._say_unverified(f"{str(self.path)!r} is read without its checksums (verify=False)")
        packed = self._read_packed(start, stop)
        bits = np.unpackbits(packed, axis=-1, bitorder="little", count=self.width).view(bool)
        return bits[:, ::-1, :] if self.flip else bits

    def verify(self) -> dict:
        """Read every chunk and check it; returns ``{"verified": bool, "checks": [...]}``."""
        if self._crcs is None:
            return {"verified": False, "checks": ["store written without checksums (format version 1)"]}
        for i in range(math.ceil(self.n_ticks / self.chunk_ticks)):
            self._read_packed(i * self.chunk_ticks, min((i + 1) * self.chunk_ticks, self.n_ticks))
        return {"verified": True, "checks": [f"header checksum and {len(self._crcs)} chunk CRC-32s match"]}


def _short(exc) -> str:
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return text[:200]


def write_zarr(path, source: SpikeSource, *, block_ticks: int = 1024) -> Path:
    """Write ``source`` to a zarr store block by block, atomically (temporary folder + renames).

    Chunks hold ``block_ticks`` ticks (capped at :data:`CHUNK_BUDGET_BYTES` of packed bits);
    each chunk's CRC-32 goes into the header's manifest.

    Parameters
    ----------
    path : str or Path
        The ``.zarr`` folder to write.
    source : SpikeSource
        The spikes.
    block_ticks : int
        Ticks per chunk.

    Returns
    -------
    Path
        The store written.
    """
    zarr = import_uninterrupted("zarr")

    block_ticks = chunk_ticks_for(source.height, source.width, check_int("block_ticks", block_ticks, 1))
    path = Path(path)
    packed_width = (source.width + 7) // 8
    with atomic_path(path, suffix=".zarr", directory=True) as tmp:
        with interrupts_deferred():  # zarr's calls are not cut by Ctrl-C/SIGTERM (raised right after)
            array = zarr.create_array(store=str(tmp), shape=(0, source.height, packed_width),
                                      chunks=(block_ticks, source.height, packed_width), dtype="uint8",
                                      compressors=zarr.codecs.ZstdCodec(level=3, checksum=True),
                                      config={"write_empty_chunks": True})
        crcs, pending, n_ticks = [], [], 0

        def flush(rows):
            with interrupts_deferred():
                array.append(rows, axis=0)
            crcs.append(zlib.crc32(rows.tobytes()))

        # re-block the source so each append fills exactly one chunk (its CRC is then the chunk's)
        buffered = 0
        for _, block in source.iter_blocks(block_ticks):
            packed = np.packbits(block, axis=-1, bitorder="little")
            n_ticks += packed.shape[0]
            pending.append(packed)
            buffered += packed.shape[0]
            while buffered >= block_ticks:
                rows = np.concatenate(pending) if len(pending) > 1 else pending[0]
                flush(np.ascontiguousarray(rows[:block_ticks]))
                rest = rows[block_ticks:]
                pending, buffered = ([rest] if rest.shape[0] else []), rest.shape[0]
        if buffered:
            flush(np.ascontiguousarray(np.concatenate(pending)))
        header = stream_header(source, rows="upright",
                               extra={"format": FORMAT_NAME, "version": FORMAT_VERSION, "n_ticks": n_ticks,
                                      "chunk_ticks": block_ticks, "chunks": crcs})
        header = _jsonable(header)
        header["header_blake2b"] = _header_digest(header)
        with interrupts_deferred():
            array.attrs["viform"] = header
    return path
