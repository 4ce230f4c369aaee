"""Pieces the ``.vfc`` format versions share (see :mod:`viform.coding.aer_file` for the container).

The payload head every segment starts with, the zstd stage of the record columns, the data bound
of an interval-coded segment, and for the banded versions (4, 5) the bands of rows, the coding
threads and the decoded form of a segment (its spike ticks).
"""

from __future__ import annotations

import os
import struct
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import zstandard

from viform._validate import ViformError
from viform.coding import interval_model
from viform.coding.first_spike import Segment

#: zstd level of the last stage (versions 1 and 2, and the lossy modes of later versions).
ZSTD_LEVEL = 19
#: every segment payload starts with: u64 start tick, u32 ticks, u32 records, u8 flags, u64 spikes
_PAYLOAD_HEAD = struct.Struct("<QIIBQ")


class _Zstd:
    def __init__(self, level: int = ZSTD_LEVEL):
        self.c = zstandard.ZstdCompressor(level=level, write_checksum=True)
        self.d = zstandard.ZstdDecompressor()

    def compress(self, b: bytes) -> bytes:
        return self.c.compress(b)

    def decompress(self, b: bytes, limit: int, what: str) -> bytes:
        """Decompress one whole frame of at most ``limit`` bytes (nothing before or after it).

        The frame's stated content size is checked against ``limit`` *before* decompressing:
        zstd allocates what a frame states (``max_output_size`` only applies to frames that do
        not state it), and a few kB of run-length blocks can state gigabytes.
        """
        try:
            size = zstandard.get_frame_parameters(b).content_size
            if size == zstandard.CONTENTSIZE_UNKNOWN:
                raise ViformError(f"column {what!r} is damaged (its zstd frame does not state its size)")
            if size > limit:
                raise ViformError(f"column {what!r} states {size} bytes, more than the {limit} it may hold")
            dobj = self.d.decompressobj()
            out = dobj.decompress(b)
        except zstandard.ZstdError as exc:
            raise ViformError(f"column {what!r} is damaged (zstd: {exc})") from None
        if not dobj.eof or dobj.unused_data or len(out) != size:
            raise ViformError(f"column {what!r} is damaged (cut short, or bytes after its zstd frame)")
        return out



def _interval_data_limit(n_spikes: int, n_pixels: int) -> int:
    """Most bytes an interval-coded segment of ``n_spikes`` spikes may hold (reader and writer agree).

    A spike costs at most a stop decision, a residual (sign, ≤ 2·31 + 2 Elias-gamma bits) —
    under 9 bytes — and a pixel's first spike a few more.
    """
    return 9 * n_spikes + 16 * n_pixels + 4096


#: Largest segment a strict version-4 writer holds in memory (pixel-ticks: one byte each, while it is coded).
MAX_SEGMENT_PIXEL_TICKS = 1 << 28
#: Default pixel-ticks of a strict version-4 segment (the segment length shrinks for large sensors).
DEFAULT_SEGMENT_PIXEL_TICKS = 1 << 25
_POOL: ThreadPoolExecutor | None = None
_POOL_PID = -1


def _check_band_totals(payload, band_bytes_end: int, band_spikes: int, spikes: int) -> None:
    """The band table must account for the whole payload and every spike of the segment header."""
    if band_bytes_end != len(payload):
        raise ViformError(f"segment payload holds {len(payload)} bytes, its band table says {band_bytes_end}")
    if band_spikes != spikes:
        raise ViformError(f"bands hold {band_spikes} spikes, the segment header says {spikes}")


def coding_threads() -> int:
    """Threads that code bands at once (``VIFORM_THREADS``, else the CPU count, at most 8).

    The coded bytes never depend on it: the bands are fixed by the file's ``band_rows``.
    """
    env = os.environ.get("VIFORM_THREADS", "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            raise ViformError(f"VIFORM_THREADS = {env!r} is not allowed: give a whole number ≥ 1") from None
        if n < 1:
            raise ViformError(f"VIFORM_THREADS = {env!r} is not allowed: give a whole number ≥ 1")
        return min(n, 64)
    return max(1, min(os.cpu_count() or 1, 8))


def _pool() -> ThreadPoolExecutor:
    global _POOL, _POOL_PID
    n = coding_threads()
    # a forked child inherits the pool object but not its threads: make its own
    if _POOL is None or _POOL._max_workers != n or _POOL_PID != os.getpid():
        _POOL = ThreadPoolExecutor(max_workers=n, thread_name_prefix="viform-coding")
        _POOL_PID = os.getpid()
    return _POOL


def _map(fn, n: int) -> list:
    """``fn(0..n-1)`` on the coding threads (in order); one band runs inline."""
    if n == 1 or coding_threads() == 1:
        return [fn(i) for i in range(n)]
    return list(_pool().map(fn, range(n)))


def default_band_rows(height: int) -> int:
    """Rows per independently coded band: one band below 96 rows, else an even number (≤ 8) of ≥ 48 rows.

    Each band learns its probabilities on its own (smaller bands cost more: 32-row bands ≈ 1 % of
    the size, 16-row ≈ 2 %); an even count keeps two threads equally busy.
    """
    n_bands = 1 if height < 96 else min(8, 2 * (height // 96))
    return -(-height // n_bands)


def default_segment_ticks(n_pixels: int) -> int:
    """Segment length of a strict version-4 file: 4,096 ticks, fewer for large sensors (bounded memory)."""
    from viform.coding.first_spike import DEFAULT_SEGMENT_TICKS

    return int(min(DEFAULT_SEGMENT_TICKS, max(64, DEFAULT_SEGMENT_PIXEL_TICKS // max(1, n_pixels))))


def _bands(height: int, band_rows: int) -> list[tuple[int, int]]:
    return [(r0, min(height, r0 + band_rows)) for r0 in range(0, height, band_rows)]


def _segment_from_ticks(tick_counts, ticks, anchor0, ref0, start: int, n_ticks: int) -> Segment:
    """The first-spike records of a segment given its spike ticks (what the rest of the reader consumes)."""
    npix = tick_counts.size
    n = ticks.size
    counts = np.empty(npix, np.int64)
    tail_m = np.empty(npix, np.int64)
    tail_g = np.empty(npix, np.int64)
    rec_m, rec_g, rec_o = (np.empty(n, np.int64) for _ in range(3))
    nr = interval_model.records_from_ticks(tick_counts, ticks, anchor0, ref0, counts, rec_m, rec_g, rec_o,
                                           tail_m, tail_g)
    return Segment(start, n_ticks, counts, rec_m[:nr], rec_g[:nr], rec_o[:nr], np.zeros(0, np.int64), tail_m,
                   tail_g, np.zeros(0, np.int64))


class TickSegment:
    """A decoded version-4 segment: per pixel (row-major) its spike ticks, grouped, in time order."""

    def __init__(self, start_tick: int, n_ticks: int, counts: np.ndarray, ticks: np.ndarray):
        self.start_tick, self.n_ticks, self.counts, self.ticks = start_tick, n_ticks, counts, ticks

    @property
    def n_spikes(self) -> int:
        return int(self.ticks.size)

    def dense(self) -> np.ndarray:
        """The segment as bool (T, P)."""
        out = np.empty((self.n_ticks, self.counts.size), np.bool_)
        interval_model.ticks_to_dense(self.counts, self.ticks, self.start_tick, out)
        return out

    def blocks(self, block_ticks: int):
        """Yield ``(first_tick, bool (n, P))`` blocks of at most ``block_ticks`` ticks (bounded memory)."""
        if block_ticks >= self.n_ticks:
            yield self.start_tick, self.dense()
            return
        pixel = np.repeat(np.arange(self.counts.size), self.counts)
        rel = self.ticks - self.start_tick
        for a in range(0, self.n_ticks, block_ticks):
            b = min(a + block_ticks, self.n_ticks)
            out = np.zeros((b - a, self.counts.size), np.bool_)
            sel = (rel >= a) & (rel < b)
            out[rel[sel] - a, pixel[sel]] = True
            yield self.start_tick + a, out


def new_band_probabilities(height: int, band_rows: int) -> np.ndarray:
    """The adaptive probabilities of every band at the start of a stream."""
    return np.stack([interval_model.new_probabilities() for _ in _bands(height, band_rows)])

