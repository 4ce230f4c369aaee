"""Per-block checksums of spike data: every read checks exactly the bytes it uses, at bounded cost.

viform writes, beside the data of a ``.dat`` (in its sidecar) and of a ``.npz`` (in its header
member), the CRC-32 of each block of :func:`block_bytes_for` bytes of the stored data. A reader
that needs ticks [a, b) reads the blocks holding them, checks their CRC-32 and only then
decodes them: a partial read (``reconstruct --at``) costs one or two blocks, never a pass over
the file, and no result is ever computed from bytes that failed their check. (zarr stores do
the same per chunk: :mod:`viform.stream.zarr_store`.)
"""

from __future__ import annotations

import zlib
from collections import OrderedDict
from collections.abc import Callable

from viform._validate import ViformError

#: Smallest block of stored bytes with its own CRC-32 (1 MiB: CRC-32 of a block takes < 1 ms).
MIN_BLOCK_BYTES = 1 << 20
#: Most blocks in a manifest (so it stays under 0.4 MB of JSON, 1.6 MB as the UTF-32 string of an
#: .npz header member, whatever the file size: a 100 GB file has 4 MiB blocks).
MAX_BLOCKS = 1 << 15
#: Blocks kept in memory after their check (sequential reads that straddle a block reuse it).
CACHED_BLOCKS = 2


def block_bytes_for(total_bytes: int) -> int:
    """Block size for ``total_bytes`` of data: 1 MiB, doubled until at most :data:`MAX_BLOCKS` blocks."""
    size = MIN_BLOCK_BYTES
    while -(-int(total_bytes) // size) > MAX_BLOCKS:
        size *= 2
    return size


class BlockCrcs:
    """Running CRC-32 of consecutive blocks of ``block_bytes`` bytes (for writers)."""

    def __init__(self, block_bytes: int):
        self.block_bytes = int(block_bytes)
        self.crcs: list[int] = []
        self._crc = 0
        self._filled = 0

    def update(self, data) -> None:
        view = memoryview(data).cast("B")
        while len(view):
            take = min(len(view), self.block_bytes - self._filled)
            self._crc = zlib.crc32(view[:take], self._crc)
            self._filled += take
            view = view[take:]
            if self._filled == self.block_bytes:
                self.crcs.append(self._crc)
                self._crc, self._filled = 0, 0

    def finish(self) -> list[int]:
        """The CRC-32 list (the last, short block included)."""
        if self._filled:
            self.crcs.append(self._crc)
            self._crc, self._filled = 0, 0
        return self.crcs


def check_manifest(crcs, block_bytes, total_bytes: int, where: str, fields=("block_crc32", "block_bytes")) -> list:
    """Validate a manifest read from a file (types, block size, count); returns the CRC list."""
    crc_name, size_name = fields
    if isinstance(block_bytes, bool) or not isinstance(block_bytes, int) \
            or not MIN_BLOCK_BYTES <= block_bytes <= (1 << 40) or block_bytes & (block_bytes - 1):
        raise ViformError(f"{where}: field {size_name!r} = {block_bytes!r} is not allowed: it must be a power of "
                          f"two ≥ {MIN_BLOCK_BYTES}")
    if not isinstance(crcs, list) or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c < 2**32
                                             for c in crcs):
        raise ViformError(f"{where}: field {crc_name!r} must be a list of CRC-32 values")
    expected = -(-int(total_bytes) // block_bytes)
    if len(crcs) != expected:
        raise ViformError(f"{where}: field {crc_name!r} lists {len(crcs)} blocks but {total_bytes} bytes in blocks "
                          f"of {block_bytes} make {expected}: the file is damaged or was edited")
    return crcs


class BlockReader:
    """Reads byte ranges of stored data, block by block, each block checked against its CRC-32.

    Parameters
    ----------
    crcs : list of int
        CRC-32 of each block.
    block_bytes : int
        Block size, bytes.
    total_bytes : int
        Bytes the manifest covers.
    read_raw : callable (offset, count) -> bytes
        Reads stored bytes (may return fewer at the end of a cut file).
    where : str
        The file, for messages (``'clip.dat'``).
    """

    def __init__(self, crcs: list[int], block_bytes: int, total_bytes: int,
                 read_raw: Callable[[int, int], bytes], where: str):
        self.crcs, self.block_bytes, self.total_bytes = crcs, int(block_bytes), int(total_bytes)
        self._read_raw, self.where = read_raw, where
        self._cache: OrderedDict[int, bytes] = OrderedDict()

    def read(self, offset: int, count: int) -> bytes | bytearray:
        """``count`` bytes from ``offset``, from blocks whose CRC-32 matched."""
        if count <= 0:
            return b""
        if offset < 0 or offset + count > self.total_bytes:
            raise ViformError(f"{self.where}: bytes {offset}–{offset + count - 1} lie outside the "
                              f"{self.total_bytes} bytes its checksums cover")
        size = self.block_bytes
        first, last = offset // size, (offset + count - 1) // size
        start = offset - first * size
        if first == last:
            return self._block(first)[start:start + count]
        out = bytearray(count)  # one copy of the checked blocks into the result
        filled = 0
        for piece in self.pieces(offset, count):
            out[filled:filled + len(piece)] = piece
            filled += len(piece)
        return out

    def pieces(self, offset: int, count: int):
        """``count`` bytes from ``offset`` as consecutive views of checked blocks (no copy), in order."""
        if count <= 0:
            return
        if offset < 0 or offset + count > self.total_bytes:
            raise ViformError(f"{self.where}: bytes {offset}–{offset + count - 1} lie outside the "
                              f"{self.total_bytes} bytes its checksums cover")
        size = self.block_bytes
        first, last = offset // size, (offset + count - 1) // size
        start, done = offset - first * size, 0
        for i in range(first, last + 1):
            block = memoryview(self._block(i))
            a = start if i == first else 0
            b = min(len(block), a + count - done)
            yield block[a:b]
            done += b - a

    def _block(self, index: int) -> bytes:
        if index in self._cache:
            self._cache.move_to_end(index)
            return self._cache[index]
        a = index * self.block_bytes
        n = min(self.block_bytes, self.total_bytes - a)
        data = self._read_raw(a, n)
        if len(data) != n:
            raise ViformError(f"{self.where} is damaged: it ends inside block {index} (bytes {a}–{a + n - 1}), "
                              f"{n - len(data)} bytes short of what its checksums cover")
        if zlib.crc32(data) != self.crcs[index]:
            raise ViformError(f"{self.where} is damaged: block {index} (bytes {a}–{a + n - 1}) differs from its "
                              "CRC-32 checksum")
        self._cache[index] = data
        while len(self._cache) > CACHED_BLOCKS:
            self._cache.popitem(last=False)
        return data


def header_digest(header: dict) -> str:
    """BLAKE2b (16 bytes, hex) of a JSON header without its ``header_blake2b`` field (sorted keys)."""
    import hashlib
    import json

    body = {k: v for k, v in header.items() if k != "header_blake2b"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()
