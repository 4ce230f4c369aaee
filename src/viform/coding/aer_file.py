"""The ``.vfc`` file: a first-spike coded viform as an asynchronous (i, j, t, τ) stream (seed 000 §5.2).

Seed 000 §5.2 ends with pixels sharing one asynchronous output channel, each first spike
sent as a quadruple (i, j, t, τ). A ``.vfc`` file stores exactly those quadruples (plus the
repeat counts the strict mode needs to be lossless, see :mod:`viform.coding.first_spike`),
in compact integer form with zstd as the last stage.

Layout (version 2, little-endian)::

    magic   8 bytes  b"VIFC\\x89\\r\\n\\x1a"
    u16 version, u32 header length, u32 CRC-32 of the header, header (UTF-8 JSON:
        height, width, clock_hz, threshold_electrons, start_time_s, mode, k, slack_ticks,
        segment_ticks, metadata)
    segments, each: b"SG", u32 payload length, u32 CRC-32 of the payload, payload
    trailer: b"EN", u64 n_ticks, u64 n_segments, u64 spikes, u32 CRC-32 of the segment CRCs

Version 2 segment payload: u64 start tick, u32 ticks, u32 records, u8 flags (0), u64 spikes,
u32 length + one zstd frame (content checksum on) holding the records range-coded by
:mod:`viform.coding.context_model` (neighbour-predicted first widths, uniform phases,
context-modelled width changes).

Version 1 (still read, and written with ``version=1``): after the same payload head (the
u8 is model·layout) eight columns, each u32 length + one zstd frame: per-pixel record
counts, first offsets of pixels that had not fired, the context-sorted record symbols,
the context table, escapes, span residuals (lossy modes), tail deficits, the first full
widths of pixels (coded against the previous pixel's). Records are coded as one byte
symbol combining the repeat count m and the width change, split by a context (the
previous symbol of the pixel and its current width, or its previous two symbols —
whichever is smaller is kept per segment); contexts are recomputed by the decoder as it
goes, so only the per-context counts are stored. Values that do not fit a symbol go to
the escape column as LEB128 varints.

Corrupt or truncated files raise :class:`~viform._validate.ViformError` with the byte
offset and what was wrong; every length, count, value and spike position is checked
before use, so no input can crash, hang or silently decode to garbage (the CRCs and zstd
checksums catch the rest).
"""

from __future__ import annotations

import io
import json
import math
import os
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import zstandard
from numba import njit

from viform._io import atomic_open
from viform._validate import ViformError, check_int
from viform.coding import context_model, interval_model
from viform.coding.first_spike import (
    CodingParameters,
    FirstSpikeDecoder,
    FirstSpikeEncoder,
    Segment,
)
from viform.stream.container import SpikeSource

#: File magic (PNG-style: catches text-mode and truncation damage).
MAGIC = b"VIFC\x89\r\n\x1a"
#: Format version written (3: per-pixel interval prediction for strict mode, checksummed end record);
#: readers take 1, 2 and 3, refuse others.
VERSION = 4
#: Versions this reader decodes.
SUPPORTED_VERSIONS = (1, 2, 3, 4)
#: File extension of first-spike coded viforms.
EXTENSION = ".vfc"
#: zstd level of the last stage.
ZSTD_LEVEL = 19

_SEG_HEAD = struct.Struct("<2sII")
_TRAILER = struct.Struct("<2sQQQI")
#: version 3 end record: the version-2 fields, then a CRC-32 of them (ticks, segments, spikes, CRC list)
_TRAILER3 = struct.Struct("<2sQQQII")
_PAYLOAD_HEAD = struct.Struct("<QIIBQ")
_NCOLS = 8
_ESC = 255
_NONE = 254
_MAX_HEADER = 1 << 20
#: Most pixels a coded file may have (2²², e.g. 2048 × 2048; the largest spike camera has 1000 × 1000): the
#: decoder keeps ~150 bytes of state per pixel (≤ 0.6 GB), and a header is cheap to forge.
MAX_PIXELS = 1 << 22
#: Pixels per byte of segment data a range-coded file (versions 2 and 3) can hold at most, per segment:
#: every pixel codes at least one binary decision per segment, and the most confident probability of
#: the coders costs ≥ 0.0007 bit (version 3's interval coder: 1 − 32/65536; version 2's record coder:
#: 2043/2048, 0.0035 bit, so even a 5× zstd stage stays inside); checked at open, before anything per
#: pixel is allocated, so a forged header cannot make the reader allocate for pixels the data cannot hold.
PIXELS_PER_BYTE = 11_000
_MAX_COLUMN = 1 << 34


# ---------------------------------------------------------------------------- varints

@njit(cache=True)
def _varint_encode(values, out):
    n = 0
    for v in values:
        v = np.uint64(v)
        while v >= 128:
            out[n] = np.uint8((v & np.uint64(127)) | np.uint64(128))
            n += 1
            v >>= np.uint64(7)
        out[n] = np.uint8(v)
        n += 1
    return n


@njit(cache=True)
def _varint_decode(data, out):
    """Decode up to out.size varints; returns (count, error) — error 1 truncated, 2 too long."""
    n = 0
    i = 0
    size = data.size
    while i < size and n < out.size:
        v = np.int64(0)
        shift = 0
        while True:
            if i >= size:
                return n, 1
            b = np.int64(data[i])
            i += 1
            if shift >= 56:
                return n, 2
            v |= (b & 127) << shift
            if b < 128:
                break
            shift += 7
        out[n] = v
        n += 1
    if i != size:
        return n, 3
    return n, 0


def _varints(values) -> bytes:
    values = np.asarray(values, np.int64)
    if values.size and values.min() < 0:
        raise ViformError("internal: negative varint")
    out = np.empty(values.size * 10, np.uint8)
    return out[:_varint_encode(values, out)].tobytes()


def _unvarints(data: bytes, count: int, what: str) -> np.ndarray:
    out = np.empty(count, np.int64)
    n, err = _varint_decode(np.frombuffer(data, np.uint8), out)
    if err or n != count:
        why = {1: "a value is cut short", 2: "a value is too long", 3: "extra bytes"}.get(err, "too few values")
        raise ViformError(f"column {what!r}: {why} (expected {count} values, read {n})")
    return out


def _zz(x):
    x = np.asarray(x, np.int64)
    return np.where(x >= 0, 2 * x, -2 * x - 1)


@njit(cache=True, inline="always")
def _unzz(v):
    return (v >> 1) if (v & 1) == 0 else -((v + 1) >> 1)


# ---------------------------------------------------------------------------- record model

@njit(cache=True, inline="always")
def _context(model, prev, prev2, ref):
    if model == 0:
        return prev * 256 + min(ref, 255)
    return prev * 256 + prev2


@njit(cache=True)
def _model_encode(counts, rec_m, rec_g, rec_o, tail_m, tail_g, anchor0, ref0, seg_end, model, dsym, strict,
                  sym, ctx, esc, ofirst, gres, tdef, tgres, second):
    """Records → symbols, contexts and side columns. Returns the used lengths."""
    n2 = 0
    last_second = np.int64(0)
    ns = 0
    ne = 0
    nf = 0
    ng = 0
    nt = 0
    r = 0
    for p in range(counts.size):
        a = anchor0[p]
        ref = ref0[p]
        prevref = 0
        prev = _NONE
        prev2 = _NONE
        after_first = False
        for _ in range(counts[p]):
            m = rec_m[r]
            g = rec_g[r]
            o = rec_o[r]
            if ref == 0:
                ofirst[nf] = o - 1
                nf += 1
                after_first = True
            elif after_first:
                # the first full width of a pixel: its reference is only the partial first
                # interval, so it is coded against the previous pixel's (neighbours are alike)
                e = o - last_second
                second[n2] = 2 * e if e >= 0 else -2 * e - 1
                second[n2 + 1] = m
                n2 += 2
                last_second = o
                after_first = False
                if not strict and m > 0:
                    e = g - m * ref
                    gres[ng] = 2 * e if e >= 0 else -2 * e - 1
                    ng += 1
            else:
                base = prevref if (model == 1 and prevref > 0) else ref
                d = o - base
                if strict and base == ref:
                    dd = 2 * d - 2 if d > 0 else -2 * d - 1  # o ≠ ref: no zero
                else:
                    dd = 2 * d if d >= 0 else -2 * d - 1
                if m < 225 // dsym and dd < dsym:
                    s = m * dsym + dd
                else:
                    s = _ESC
                    esc[ne] = m
                    esc[ne + 1] = dd
                    ne += 2
                sym[ns] = s
                ctx[ns] = _context(model, prev, prev2, ref)
                ns += 1
                if not strict and m > 0:
                    e = g - m * ref
                    gres[ng] = 2 * e if e >= 0 else -2 * e - 1
                    ng += 1
                prev2 = prev
                prev = s
            a = a + g + o
            prevref = ref
            ref = o
            r += 1
        if ref > 0:
            m = tail_m[p]
            fill = (seg_end - 1 - a) // ref
            e = fill - m
            tdef[nt] = 2 * e if e >= 0 else -2 * e - 1
            nt += 1
            if not strict and m > 0:
                e = tail_g[p] - m * ref
                tgres[ng] = 2 * e if e >= 0 else -2 * e - 1
                ng += 1
    return ns, ne, nf, ng, nt, n2


@njit(cache=True)
def _model_decode(counts, sym, ctx_start, esc, ofirst, gres, tdef, second, anchor0, ref0, seg_end, model, dsym,
                  strict, rec_m, rec_g, rec_o, tail_m, tail_g):
    """Inverse of :func:`_model_encode`; every read is bounds-checked. Returns an error code (0 ok)."""
    n2 = 0
    last_second = np.int64(0)
    ptr = ctx_start[:-1].copy()
    ne = 0
    nf = 0
    ng = 0
    nt = 0
    r = 0
    big = np.int64(1) << 31
    for p in range(counts.size):
        a = anchor0[p]
        ref = ref0[p]
        prevref = 0
        prev = _NONE
        prev2 = _NONE
        after_first = False
        for _ in range(counts[p]):
            first_record = ref == 0
            if first_record:
                if nf >= ofirst.size:
                    return 1
                m = np.int64(0)
                g = np.int64(0)
                o = ofirst[nf] + 1
                nf += 1
                after_first = True
            elif after_first:
                if n2 + 1 >= second.size:
                    return 11
                o = last_second + _unzz(second[n2])
                m = second[n2 + 1]
                n2 += 2
                last_second = o
                after_first = False
            else:
                c = _context(model, prev, prev2, ref)
                k = ptr[c]
                if k >= ctx_start[c + 1]:
                    return 2
                ptr[c] = k + 1
                s = np.int64(sym[k])
                if s == _ESC:
                    if ne + 1 >= esc.size:
                        return 3
                    m = esc[ne]
                    dd = esc[ne + 1]
                    ne += 2
                elif s < (225 // dsym) * dsym:
                    m = s // dsym
                    dd = s % dsym
                else:
                    return 4
                base = prevref if (model == 1 and prevref > 0) else ref
                if strict and base == ref:
                    d = (dd + 2) // 2 if dd % 2 == 0 else -((dd + 1) // 2)
                else:
                    d = _unzz(dd)
                o = base + d
                prev2 = prev
                prev = s
            if not first_record:
                # a repeat count and a width: check them, then the span of the repeats
                if m > big or o < 1 or o > big:
                    return 5
                if strict:
                    g = m * ref
                elif m > 0:
                    if ng >= gres.size:
                        return 6
                    if gres[ng] > big:
                        return 5
                    g = m * ref + _unzz(gres[ng])
                    ng += 1
                else:
                    g = np.int64(0)
            if ref > big:
                return 5
            rec_m[r] = m
            rec_g[r] = g
            rec_o[r] = o
            a = a + g + o
            if a > seg_end or a < -1:
                return 7
            prevref = ref
            ref = o
            r += 1
        if ref > 0:
            if nt >= tdef.size:
                return 8
            fill = (seg_end - 1 - a) // ref
            m = fill - _unzz(tdef[nt])
            nt += 1
            if m < 0 or m > big:
                return 9
            if strict or m == 0:
                g = m * ref
            else:
                if ng >= gres.size:
                    return 6
                if gres[ng] > big:
                    return 5
                g = m * ref + _unzz(gres[ng])
                ng += 1
            tail_m[p] = m
            tail_g[p] = g
        else:
            tail_m[p] = 0
            tail_g[p] = 0
    if nf != ofirst.size or ne != esc.size or ng != gres.size or nt != tdef.size or n2 != second.size:
        return 10
    for c in range(ptr.size):
        if ptr[c] != ctx_start[c + 1]:
            return 10
    return 0


_MODEL_ERRORS = {1: "first-offset column too short", 2: "symbol context overrun", 3: "escape column too short",
                 4: "invalid symbol", 5: "value out of range", 6: "span column too short",
                 7: "spike outside the segment", 8: "tail column too short", 9: "bad tail count",
                 10: "columns hold unused values", 11: "first-width column too short"}

#: Symbol layouts: a record symbol is m·D + coded width change, D from this list (per segment).
_LAYOUTS = (15, 25, 45, 75, 5, 9)


# ---------------------------------------------------------------------------- segment payload

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


def _segment_columns(seg: Segment, anchor0, ref0, model: int, layout: int, strict: bool) -> tuple[list[bytes], int]:
    n = seg.m.size
    npix = seg.counts.size
    sym = np.empty(n, np.uint8)
    ctx = np.empty(n, np.int64)
    esc = np.empty(2 * n, np.int64)
    ofirst = np.empty(n, np.int64)
    gres = np.empty(n + npix, np.int64)
    tdef = np.empty(npix, np.int64)
    second = np.empty(2 * npix, np.int64)
    seg_end = seg.start_tick + seg.n_ticks
    ns, ne, nf, ng, nt, n2 = _model_encode(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, anchor0, ref0,
                                           seg_end, model, _LAYOUTS[layout], strict, sym, ctx, esc, ofirst, gres,
                                           tdef, gres, second)
    sym, ctx = sym[:ns], ctx[:ns]
    order = np.argsort(ctx, kind="stable")
    used, cnt = np.unique(ctx, return_counts=True)
    table = np.empty(2 * used.size, np.int64)
    table[0::2] = np.diff(used, prepend=0)
    table[1::2] = cnt
    cols = [_varints(seg.counts), _varints(ofirst[:nf]), sym[order].tobytes(), _varints(table),
            _varints(esc[:ne]), _varints(gres[:ng]), _varints(tdef[:nt]), _varints(second[:n2])]
    return cols, ne


def _encode_payload(seg: Segment, anchor0, ref0, strict: bool, zc: _Zstd) -> bytes:
    # choose the symbol layout with the fewest escapes, then the context model by a fast trial
    escapes = [_segment_columns(seg, anchor0, ref0, 0, lay, strict)[1] for lay in range(len(_LAYOUTS))]
    layout = int(np.argmin(escapes))
    fast = zstandard.ZstdCompressor(level=3)
    trials = []
    for model in (0, 1):
        cols, _ = _segment_columns(seg, anchor0, ref0, model, layout, strict)
        trials.append((sum(len(fast.compress(c)) for c in cols), model, cols))
    _, model, cols = min(trials, key=lambda x: x[0])
    packed = [zc.compress(c) for c in cols]
    out = io.BytesIO()
    out.write(_PAYLOAD_HEAD.pack(seg.start_tick, seg.n_ticks, seg.m.size, model + 2 * layout, seg.n_spikes))
    for c in packed:
        out.write(struct.pack("<I", len(c)))
        out.write(c)
    return out.getvalue()


def _decode_payload(payload: bytes, n_pixels: int, anchor0, ref0, strict: bool, zc: _Zstd,
                    expected_start: int, segment_ticks: int) -> Segment:
    if len(payload) < _PAYLOAD_HEAD.size:
        raise ViformError("segment payload is shorter than its header")
    start, n_ticks, n_rec, model, spikes = _PAYLOAD_HEAD.unpack_from(payload)
    if start != expected_start:
        raise ViformError(f"segment starts at tick {start}, expected {expected_start}")
    model, layout = model % 2, model // 2
    if not 1 <= n_ticks <= segment_ticks or layout >= len(_LAYOUTS):
        raise ViformError(f"segment header is invalid (ticks {n_ticks}, model {model})")
    if n_rec > spikes or spikes > n_ticks * n_pixels:
        raise ViformError(f"segment header is invalid ({n_rec} records, {spikes} spikes)")
    pos = _PAYLOAD_HEAD.size
    cols = []
    for c in range(_NCOLS):
        if pos + 4 > len(payload):
            raise ViformError(f"segment payload is cut short in column {c}")
        (length,) = struct.unpack_from("<I", payload, pos)
        pos += 4
        if pos + length > len(payload):
            raise ViformError(f"segment payload is cut short in column {c}")
        cols.append(payload[pos:pos + length])
        pos += length
    if pos != len(payload):
        raise ViformError("segment payload has trailing bytes")
    names = ("counts", "first offsets", "symbols", "contexts", "escapes", "spans", "tails", "first widths")
    limit_rec = 10 * (n_rec + n_pixels) + 64
    raw = [zc.decompress(c, limit_rec, names[i]) for i, c in enumerate(cols)]
    counts = _unvarints(raw[0], n_pixels, "counts")
    if counts.sum() != n_rec or counts.min(initial=0) < 0:
        raise ViformError(f"record counts add up to {int(counts.sum())}, the header says {n_rec}")
    first_known = ref0 > 0
    n_first = int(np.count_nonzero((~first_known) & (counts > 0)))
    ofirst = _unvarints(raw[1], n_first, "first offsets")
    sym = np.frombuffer(raw[2], np.uint8)
    n_second = int(np.count_nonzero((~first_known) & (counts > 1)))
    n_sym = n_rec - n_first - n_second
    if sym.size != n_sym:
        raise ViformError(f"symbol column holds {sym.size} symbols, expected {n_sym}")
    table = _count_varints(raw[3], "contexts")
    if table.size % 2:
        raise ViformError("context table is cut short")
    ids = np.cumsum(table[0::2])
    if table.size and (ids[-1] >= 65536 or (table[2::2] <= 0).any() or (table[1::2] <= 0).any()):
        raise ViformError("context table is invalid")
    ctx_start = np.zeros(65537, np.int64)
    ctx_start[ids + 1] = table[1::2]
    np.cumsum(ctx_start, out=ctx_start)
    if ctx_start[-1] != n_sym:
        raise ViformError(f"context table counts {int(ctx_start[-1])} symbols, expected {n_sym}")
    esc = _count_varints(raw[4], "escapes")
    gres = _count_varints(raw[5], "spans")
    tdef = _count_varints(raw[6], "tails")
    second = _count_varints(raw[7], "first widths")
    rec_m = np.empty(n_rec, np.int64)
    rec_g = np.empty(n_rec, np.int64)
    rec_o = np.empty(n_rec, np.int64)
    tail_m = np.empty(n_pixels, np.int64)
    tail_g = np.empty(n_pixels, np.int64)
    err = _model_decode(counts, sym, ctx_start, esc, ofirst, gres, tdef, second, anchor0, ref0, start + n_ticks,
                        model, _LAYOUTS[layout], strict, rec_m, rec_g, rec_o, tail_m, tail_g)
    if err:
        raise ViformError(f"segment at tick {start} is damaged ({_MODEL_ERRORS[err]})")
    seg = Segment(start, n_ticks, counts, rec_m, rec_g, rec_o, np.zeros(0, np.int64), tail_m, tail_g,
                  np.zeros(0, np.int64))
    return seg, spikes


def _encode_payload_v2(seg: Segment, anchor0, ref0, width: int, strict: bool, zc: _Zstd) -> bytes:
    """Version-2 payload: the segment's records range-coded (:mod:`viform.coding.context_model`), one zstd frame."""
    n_rec, npix = seg.m.size, seg.counts.size
    size = 16 * (n_rec + npix) + 4096
    rec_s = np.empty(n_rec + 1, np.int64)
    while True:
        out = np.empty(size, np.uint8)
        n = context_model.encode_segment(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, anchor0, ref0,
                                         seg.start_tick, seg.start_tick + seg.n_ticks, width, strict, out, rec_s)
        if n <= size:
            break
        size = 2 * n
    if n > _v2_data_limit(n_rec, npix):  # never write what the reader would refuse
        raise ViformError(f"segment at tick {seg.start_tick} codes to {n} bytes, more than the format allows; "
                          "use a shorter segment_ticks")
    frame = zc.compress(out[:n].tobytes())
    return (_PAYLOAD_HEAD.pack(seg.start_tick, seg.n_ticks, n_rec, 0, seg.n_spikes) + struct.pack("<I", len(frame))
            + frame)


def _v2_data_limit(n_rec: int, n_pixels: int) -> int:
    """Most range-coded bytes a version-2 segment of ``n_rec`` records may hold (reader and writer agree)."""
    return 32 * (n_rec + n_pixels) + 4096


def _decode_payload_v2(payload: bytes, n_pixels: int, width: int, anchor0, ref0, strict: bool, zc: _Zstd,
                       expected_start: int, segment_ticks: int):
    if len(payload) < _PAYLOAD_HEAD.size + 4:
        raise ViformError("segment payload is shorter than its header")
    start, n_ticks, n_rec, flags, spikes = _PAYLOAD_HEAD.unpack_from(payload)
    if start != expected_start:
        raise ViformError(f"segment starts at tick {start}, expected {expected_start}")
    if not 1 <= n_ticks <= segment_ticks or flags != 0:
        raise ViformError(f"segment header is invalid (ticks {n_ticks}, flags {flags})")
    if n_rec > spikes or spikes > n_ticks * n_pixels:
        raise ViformError(f"segment header is invalid ({n_rec} records, {spikes} spikes)")
    (length,) = struct.unpack_from("<I", payload, _PAYLOAD_HEAD.size)
    pos = _PAYLOAD_HEAD.size + 4
    if pos + length != len(payload):
        raise ViformError("segment payload length does not match its frame")
    data = np.frombuffer(zc.decompress(payload[pos:], _v2_data_limit(n_rec, n_pixels), "records"), np.uint8)
    return _decode_records(data, n_pixels, width, anchor0, ref0, strict, start, n_ticks, n_rec, spikes)


def _decode_records(data, n_pixels: int, width: int, anchor0, ref0, strict: bool, start: int, n_ticks: int,
                    n_rec: int, spikes: int):
    """Range-coded first-spike records (:mod:`viform.coding.context_model`) → a :class:`Segment`."""
    counts = np.empty(n_pixels, np.int64)
    tail_m = np.empty(n_pixels, np.int64)
    tail_g = np.empty(n_pixels, np.int64)
    # the record arrays grow with the records actually decoded (×4 and decode again when full), never to
    # the stated count up front: a forged count with little data behind it allocates little
    cap = min(n_rec, 4 * data.size + 4096)
    while True:
        rec_m, rec_g, rec_o, rec_s = (np.empty(cap, np.int64) for _ in range(4))
        err = context_model.decode_segment(data, n_pixels, anchor0, ref0, start, start + n_ticks, width, strict,
                                           n_rec, counts, rec_m, rec_g, rec_o, tail_m, tail_g, rec_s)
        if err != context_model.TOO_MANY_RECORDS or cap >= n_rec:
            break
        cap = min(n_rec, 4 * cap)
    if err:
        raise ViformError(f"segment at tick {start} is damaged ({context_model.ERRORS[err]})")
    seg = Segment(start, n_ticks, counts, rec_m, rec_g, rec_o, np.zeros(0, np.int64), tail_m, tail_g,
                  np.zeros(0, np.int64))
    return seg, spikes


#: payload flags of version-3 segments: 0 range-coded records in a zstd frame (lossy modes, as version 2);
#: 1 spikes coded by :mod:`viform.coding.interval_model` (strict); 2 range-coded records, no zstd (strict)
_FLAG_INTERVALS = 1
_FLAG_RECORDS = 2


def _v3_data_limit(n_spikes: int, n_pixels: int) -> int:
    """Most bytes an interval-coded segment of ``n_spikes`` spikes may hold (reader and writer agree).

    A spike costs at most a stop decision, a residual (sign, ≤ 2·31 + 2 Elias-gamma bits) —
    under 9 bytes — and a pixel's first spike a few more.
    """
    return 9 * n_spikes + 16 * n_pixels + 4096


def _encode_payload_v3(seg: Segment, anchor0, ref0, width: int, ivstate: np.ndarray, ivprobs: np.ndarray) -> bytes:
    """Version-3 strict payload: every spike tick coded against its pixel's prediction (no zstd stage).

    ``ivstate`` (the per-pixel predictor, :mod:`viform.coding.interval_model`) and ``ivprobs`` (its
    adaptive probabilities) are advanced in place.
    """
    npix = seg.counts.size
    n_spikes = seg.n_spikes
    ticks = np.empty(n_spikes + 1, np.int64)
    tick_counts = np.empty(npix, np.int64)
    interval_model.ticks_from_records(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, anchor0, ref0,
                                      seg.start_tick, tick_counts, ticks)
    size = 2 * n_spikes + npix // 4 + 4096
    start_state, start_probs = ivstate.copy(), ivprobs.copy()
    while True:
        ivstate[...] = start_state
        ivprobs[...] = start_probs
        out = np.empty(size, np.uint8)
        n = interval_model.encode_segment(tick_counts, ticks, anchor0, ivstate, ivprobs, seg.start_tick,
                                          seg.start_tick + seg.n_ticks, width, out)
        if n <= size:
            break
        size = 2 * n
    flag, body = _FLAG_INTERVALS, out[:n]
    # the run-length record model (version 2's, without its zstd stage) wins on some streams (fast
    # scene changes, few spikes per pixel): keep whichever is smaller; the predictor state above is
    # advanced either way (the reader replays it from the decoded spikes). Below 0.8 bit per spike
    # (steady pixels) it did not win on any benchmark stream (a width change costs it ≥ 1 bit): not tried.
    n_rec = seg.m.size
    size = 16 * (n_rec + npix) + 4096
    rec_s = np.empty(n_rec + 1, np.int64)
    while 8 * n >= 0.8 * n_spikes:
        out2 = np.empty(size, np.uint8)
        n2 = context_model.encode_segment(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, anchor0, ref0,
                                          seg.start_tick, seg.start_tick + seg.n_ticks, width, True, out2, rec_s)
        if n2 <= size:
            if n2 < n:
                flag, body = _FLAG_RECORDS, out2[:n2]
            break
        size = 2 * n2
    if body.size > _v3_data_limit(n_spikes, npix):  # never write what the reader would refuse
        raise ViformError(f"segment at tick {seg.start_tick} codes to {body.size} bytes, more than the format "
                          "allows")
    return _PAYLOAD_HEAD.pack(seg.start_tick, seg.n_ticks, n_rec, flag, n_spikes) + body.tobytes()


def _decode_payload_v3(payload: bytes, n_pixels: int, width: int, anchor0, ref0, ivstate: np.ndarray,
                       ivprobs: np.ndarray, strict: bool,
                       zc: _Zstd, expected_start: int, segment_ticks: int):
    """Decode a version-3 segment: interval-coded (flag 1, strict) or range-coded records (flag 0, as version 2)."""
    if len(payload) < _PAYLOAD_HEAD.size:
        raise ViformError("segment payload is shorter than its header")
    flags = payload[_PAYLOAD_HEAD.size - 9]
    if flags == 0:
        if strict:
            raise ViformError("a strict segment must be interval-coded (flag 1)")
        return _decode_payload_v2(payload, n_pixels, width, anchor0, ref0, strict, zc, expected_start, segment_ticks)
    start, n_ticks, n_rec, flags, spikes = _PAYLOAD_HEAD.unpack_from(payload)
    if start != expected_start:
        raise ViformError(f"segment starts at tick {start}, expected {expected_start}")
    if flags not in (_FLAG_INTERVALS, _FLAG_RECORDS) or not strict:
        raise ViformError(f"segment header is invalid (flags {flags})")
    if not 1 <= n_ticks <= segment_ticks:
        raise ViformError(f"segment header is invalid (ticks {n_ticks})")
    if n_rec > spikes or spikes > n_ticks * n_pixels:
        raise ViformError(f"segment header is invalid ({n_rec} records, {spikes} spikes)")
    data = np.frombuffer(payload, np.uint8)[_PAYLOAD_HEAD.size:]
    if data.size > _v3_data_limit(spikes, n_pixels):
        raise ViformError(f"segment holds {data.size} bytes, more than {spikes} spikes may need")
    if flags == _FLAG_RECORDS:
        seg, _ = _decode_records(data, n_pixels, width, anchor0, ref0, True, start, n_ticks, n_rec, spikes)
        # replay the interval predictor over the decoded spikes (its output is discarded)
        dec = FirstSpikeDecoder(n_pixels)
        dec.anchor, dec.tau_ref, dec.next_tick = anchor0.copy(), ref0.copy(), start
        n_sp = dec.check(seg)
        if n_sp != spikes:
            raise ViformError(f"segment at tick {start} decodes to {n_sp} spikes, its header says {spikes}")
        ticks = np.empty(spikes + 1, np.int64)
        tick_counts = np.empty(n_pixels, np.int64)
        interval_model.ticks_from_records(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, anchor0, ref0,
                                          start, tick_counts, ticks)
        interval_model.encode_segment(tick_counts, ticks, anchor0, ivstate, ivprobs, start, start + n_ticks, width,
                                      np.empty(1, np.uint8))
        return seg, spikes
    tick_counts = np.empty(n_pixels, np.int64)
    # the tick array grows with the spikes actually decoded (×4 and decode again when full), never to the
    # stated count up front: a forged count with little data behind it allocates little
    cap = min(spikes, 64 * data.size + 4096)
    start_state, start_probs = ivstate.copy(), ivprobs.copy()
    while True:
        ivstate[...] = start_state
        ivprobs[...] = start_probs
        ticks = np.empty(cap, np.int64)
        err, _ = interval_model.decode_segment(data, n_pixels, anchor0, ivstate, ivprobs, start, start + n_ticks, width,
                                               spikes, tick_counts, ticks)
        if err != 2 or cap >= spikes:
            break
        cap = min(spikes, 4 * cap)
    if err:
        raise ViformError(f"segment at tick {start} is damaged ({interval_model.ERRORS[err]})")
    seg = _segment_from_ticks(tick_counts, ticks[:spikes], anchor0, ref0, start, n_ticks)
    if seg.m.size != n_rec:
        raise ViformError(f"segment at tick {start} decodes to {seg.m.size} first spikes, its header says {n_rec}")
    return seg, spikes


# ---------------------------------------------------------------------------- version 4: bands in parallel

_FLAG_BANDS = 4
_BAND_HEAD = struct.Struct("<IQ")  # per band: coded bytes, spikes
#: Largest segment a strict version-4 writer holds in memory (pixel-ticks: one byte each, while it is coded).
MAX_SEGMENT_PIXEL_TICKS = 1 << 28
#: Default pixel-ticks of a strict version-4 segment (the segment length shrinks for large sensors).
DEFAULT_SEGMENT_PIXEL_TICKS = 1 << 25
_POOL: ThreadPoolExecutor | None = None
_POOL_PID = -1


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


def _encode_payload_v4(dense: np.ndarray, start: int, last, ivstate: np.ndarray, ivprobs: np.ndarray,
                       band_rows: int) -> tuple[bytes, int]:
    """Version-4 strict payload: each band of ``band_rows`` rows interval-coded on its own, in parallel.

    ``dense`` is the segment's bool array (T, H, W); ``last`` (each pixel's last spike tick, −1
    never), ``ivstate`` (per pixel) and ``ivprobs`` (per band) are advanced in place. Returns the
    payload and its spike count.
    """
    n_ticks, height, width = dense.shape
    bands = _bands(height, band_rows)

    def one(b):
        r0, r1 = bands[b]
        p0, p1 = r0 * width, r1 * width
        counts, ticks = interval_model.band_ticks(dense, r0, r1, start)
        n = ticks.size
        st, probs = ivstate[p0:p1], ivprobs[b]
        st0, probs0 = st.copy(), probs.copy()
        size = 2 * n + (p1 - p0) // 4 + 4096
        while True:
            out = np.empty(size, np.uint8)
            nb = interval_model.encode_segment(counts, ticks, last[p0:p1], st, probs, start, start + n_ticks,
                                               width, out, 4)
            if nb <= size:
                break
            st[...] = st0
            probs[...] = probs0
            size = 2 * nb
        return counts, ticks, out[:nb]

    parts = _map(one, len(bands))
    for (r0, r1), (_, ticks, body) in zip(bands, parts, strict=True):
        if body.size > _v3_data_limit(ticks.size, (r1 - r0) * width):  # never write what the reader refuses
            raise ViformError(f"segment at tick {start} codes to {body.size} bytes, more than the format allows")
    n_spikes = sum(t.size for _, t, _ in parts)
    for (r0, r1), (counts, ticks, _) in zip(bands, parts, strict=True):
        interval_model.advance_last_ticks(counts, ticks, last[r0 * width:r1 * width])
    table = b"".join(_BAND_HEAD.pack(body.size, t.size) for _, t, body in parts)
    payload = (_PAYLOAD_HEAD.pack(start, n_ticks, 0, _FLAG_BANDS, n_spikes)
               + struct.pack("<I", len(bands)) + table + b"".join(body.tobytes() for _, _, body in parts))
    return payload, n_spikes


def _decode_payload_v4(payload: bytes, height: int, width: int, band_rows: int, last,
                       ivstate: np.ndarray, ivprobs: np.ndarray, expected_start: int, segment_ticks: int):
    """Decode a version-4 strict segment (bands decoded in parallel) into a :class:`TickSegment`.

    ``last`` (each pixel's last spike tick), ``ivstate`` and ``ivprobs`` are advanced in place.
    """
    head = _PAYLOAD_HEAD.size
    if len(payload) < head + 4:
        raise ViformError("segment payload is shorter than its header")
    start, n_ticks, n_rec, flags, spikes = _PAYLOAD_HEAD.unpack_from(payload)
    n_pixels = height * width
    if start != expected_start:
        raise ViformError(f"segment starts at tick {start}, expected {expected_start}")
    if flags != _FLAG_BANDS:
        raise ViformError(f"segment header is invalid (flags {flags})")
    if not 1 <= n_ticks <= segment_ticks:
        raise ViformError(f"segment header is invalid (ticks {n_ticks})")
    if n_rec != 0 or spikes > n_ticks * n_pixels:
        raise ViformError(f"segment header is invalid ({n_rec} records, {spikes} spikes)")
    bands = _bands(height, band_rows)
    (n_bands,) = struct.unpack_from("<I", payload, head)
    if n_bands != len(bands):
        raise ViformError(f"segment holds {n_bands} bands, the header's band_rows gives {len(bands)}")
    pos = head + 4 + n_bands * _BAND_HEAD.size
    if len(payload) < pos:
        raise ViformError("segment payload is shorter than its band table")
    spans = []
    total = 0
    for b, (r0, r1) in enumerate(bands):
        nbytes, sp = _BAND_HEAD.unpack_from(payload, head + 4 + b * _BAND_HEAD.size)
        if sp > n_ticks * (r1 - r0) * width or nbytes > _v3_data_limit(sp, (r1 - r0) * width):
            raise ViformError(f"band {b} is invalid ({nbytes} bytes, {sp} spikes)")
        spans.append((pos, nbytes, sp))
        pos += nbytes
        total += sp
    if pos != len(payload):
        raise ViformError(f"segment payload holds {len(payload)} bytes, its band table says {pos}")
    if total != spikes:
        raise ViformError(f"bands hold {total} spikes, the segment header says {spikes}")
    buf = np.frombuffer(payload, np.uint8)

    def one(b):
        r0, r1 = bands[b]
        p0, p1 = r0 * width, r1 * width
        off, nbytes, sp = spans[b]
        data = buf[off:off + nbytes]
        counts = np.empty(p1 - p0, np.int64)
        st, probs = ivstate[p0:p1], ivprobs[b]
        st0, probs0 = st.copy(), probs.copy()
        # the tick array grows with the spikes actually decoded, never to the stated count up front
        cap = min(sp, 64 * nbytes + 4096)
        while True:
            ticks = np.empty(cap, np.int64)
            err, _ = interval_model.decode_segment(data, p1 - p0, last[p0:p1], st, probs, start, start + n_ticks,
                                                   width, sp, counts, ticks, 4)
            if err != 2 or cap >= sp:
                break
            st[...] = st0
            probs[...] = probs0
            cap = min(sp, 4 * cap)
        return err, counts, ticks[:sp]

    parts = _map(one, len(bands))
    for b, (err, _, _) in enumerate(parts):
        if err:
            raise ViformError(f"segment at tick {start}, band {b} is damaged ({interval_model.ERRORS[err]})")
    for (r0, r1), (_, counts, ticks) in zip(bands, parts, strict=True):
        interval_model.advance_last_ticks(counts, ticks, last[r0 * width:r1 * width])
    return TickSegment(start, n_ticks, np.concatenate([c for _, c, _ in parts]),
                       np.concatenate([t for _, _, t in parts]))


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


def new_band_probabilities(height: int, band_rows: int) -> np.ndarray:
    """The adaptive probabilities of every band at the start of a stream."""
    return np.stack([interval_model.new_probabilities() for _ in _bands(height, band_rows)])


def _count_varints(data: bytes, what: str) -> np.ndarray:
    arr = np.frombuffer(data, np.uint8)
    n = int(np.count_nonzero(arr < 128))
    return _unvarints(data, n, what)


# ---------------------------------------------------------------------------- writer

class CodedWriter:
    """Streaming writer of a ``.vfc`` file: ``push`` blocks of ticks, then ``close``.

    The file appears under its name only when ``close`` succeeds (atomic).
    """

    def __init__(self, path, height: int, width: int, clock_hz: float, params: CodingParameters,
                 threshold_electrons: float | None = None, start_time_s: float = 0.0,
                 metadata: dict | None = None, level: int = ZSTD_LEVEL, version: int = VERSION):
        self.path = Path(path)
        if version not in SUPPORTED_VERSIONS:
            raise ViformError(f"version must be one of {SUPPORTED_VERSIONS}; got {version!r}")
        self.version = version
        self.height = check_int("height", height, 1, 1 << 16)
        self.width = check_int("width", width, 1, 1 << 16)
        if self.height * self.width > MAX_PIXELS:
            raise ViformError(f"{height}×{width} pixels: a coded file holds at most {MAX_PIXELS} pixels")
        self.params = params
        self.strict = params.mode == "strict"
        self.encoder = FirstSpikeEncoder(self.height * self.width, params)
        self.state = FirstSpikeDecoder(self.height * self.width)  # mirrors the decoder's state
        self.ivstate = np.zeros((self.height * self.width, interval_model.STATE_ROWS), np.int64)
        self.ivprobs = interval_model.new_probabilities()
        self.zc = _Zstd(level)
        self.header = {
            "format": "viform first-spike coded stream", "version": version,
            "height": self.height, "width": self.width, "clock_hz": float(clock_hz),
            "threshold_electrons": threshold_electrons, "start_time_s": float(start_time_s),
            "mode": params.mode, "k": params.k, "slack_ticks": params.slack_ticks,
            "segment_ticks": params.segment_ticks, "metadata": _json_safe(metadata or {}),
        }
        # version 4, strict: the segment is held as bools and coded in bands of rows, in parallel
        self.banded = version >= 4 and self.strict
        if self.banded:
            pixel_ticks = params.segment_ticks * self.height * self.width
            if pixel_ticks > MAX_SEGMENT_PIXEL_TICKS:
                raise ViformError(f"segment_ticks = {params.segment_ticks} is not allowed for {self.height}×"
                                  f"{self.width} pixels: a segment would hold {pixel_ticks:,} pixel-ticks in memory "
                                  f"(at most {MAX_SEGMENT_PIXEL_TICKS:,}); give at most "
                                  f"{MAX_SEGMENT_PIXEL_TICKS // (self.height * self.width)} ticks")
            coding_threads()  # refuse a bad VIFORM_THREADS before the file is opened
            self.band_rows = default_band_rows(self.height)
            self.header["band_rows"] = self.band_rows
            self.ivprobs = new_band_probabilities(self.height, self.band_rows)
            self._dense = None
            self._fill = 0
            self._next_tick = 0
            self._last = np.full(self.height * self.width, -1, np.int64)  # each pixel's last spike tick
        self._cm = atomic_open(self.path, "wb")
        self.f = self._cm.__enter__()
        head = json.dumps(self.header, sort_keys=True).encode()
        self.f.write(MAGIC + struct.pack("<HII", version, len(head), zlib.crc32(head)) + head)
        self.n_segments = 0
        self.spikes = 0
        self.bytes_written = len(MAGIC) + 10 + len(head)
        self._crcs = 0

    def push(self, block) -> None:
        if not self.banded:
            for seg in self.encoder.push(block):
                self._write(seg)
            return
        block = np.asarray(block)
        if block.ndim not in (2, 3) or block.size != block.shape[0] * self.height * self.width:
            raise ViformError(f"block of shape {block.shape} does not hold {self.height}×{self.width} pixels per tick")
        block = block.reshape(block.shape[0], self.height, self.width)
        seg_ticks = self.params.segment_ticks
        if self._dense is None:
            self._dense = np.zeros((seg_ticks, self.height, self.width), np.bool_)
        pos = 0
        while pos < block.shape[0]:
            take = min(block.shape[0] - pos, seg_ticks - self._fill)
            self._dense[self._fill:self._fill + take] = block[pos:pos + take]
            self._fill += take
            self._next_tick += take
            pos += take
            if self._fill == seg_ticks:
                self._write_banded()

    def _write_banded(self) -> None:
        dense = self._dense[:self._fill]
        payload, n_spikes = _encode_payload_v4(dense, self._next_tick - self._fill, self._last, self.ivstate,
                                               self.ivprobs, self.band_rows)
        self._fill = 0
        self._append(payload, n_spikes)

    def _write(self, seg: Segment) -> None:
        if self.version == 1:
            payload = _encode_payload(seg, self.state.anchor, self.state.tau_ref, self.strict, self.zc)
        elif self.version == 3 and self.strict:
            payload = _encode_payload_v3(seg, self.state.anchor, self.state.tau_ref, self.width, self.ivstate,
                                         self.ivprobs)
        else:
            payload = _encode_payload_v2(seg, self.state.anchor, self.state.tau_ref, self.width, self.strict, self.zc)
        self.state.check(seg, advance=True)  # mirror the reader's state (anchors, widths)
        self._append(payload, seg.n_spikes)

    def _append(self, payload: bytes, n_spikes: int) -> None:
        crc = zlib.crc32(payload)
        self.f.write(_SEG_HEAD.pack(b"SG", len(payload), crc) + payload)
        self._crcs = zlib.crc32(struct.pack("<I", crc), self._crcs)
        self.n_segments += 1
        self.spikes += n_spikes
        self.bytes_written += _SEG_HEAD.size + len(payload)

    def close(self) -> Path:
        if self.banded:
            if self._fill:
                self._write_banded()
            self._dense = None
            n_ticks = self._next_tick
        else:
            for seg in self.encoder.finish():
                self._write(seg)
            n_ticks = self.encoder.next_tick
        if n_ticks == 0:
            self.abort()
            raise ViformError("the stream has no ticks to code")
        if self.version >= 3:
            fields = _TRAILER.pack(b"EN", n_ticks, self.n_segments, self.spikes, self._crcs)
            self.f.write(fields + struct.pack("<I", zlib.crc32(fields[2:])))
            self.bytes_written += _TRAILER3.size
        else:
            self.f.write(_TRAILER.pack(b"EN", self.encoder.next_tick, self.n_segments, self.spikes, self._crcs))
            self.bytes_written += _TRAILER.size
        self._cm.__exit__(None, None, None)
        return self.path

    def abort(self) -> None:
        try:
            raise RuntimeError("aborted")
        except RuntimeError as exc:
            self._cm.__exit__(type(exc), exc, exc.__traceback__)


def _json_safe(d: dict) -> dict:
    return json.loads(json.dumps(d, default=lambda v: v.item() if hasattr(v, "item") else str(v)))


def encode_source(source: SpikeSource, path, mode: str = "strict", *, k: float | None = None,
                  threshold_electrons: float | None = None, slack_ticks: int = 0,
                  segment_ticks: int | None = None, block_ticks: int = 1024, level: int = ZSTD_LEVEL,
                  progress: bool = False, version: int = VERSION) -> dict:
    """Code a viform into a ``.vfc`` file (streaming, bounded memory). Returns a summary.

    ``version`` 1 writes the older column layout (kept so that old readers can be served).
    """
    from viform.coding.first_spike import DEFAULT_K, DEFAULT_SEGMENT_TICKS

    q = threshold_electrons if threshold_electrons is not None else source.threshold_electrons
    if segment_ticks is None:
        segment_ticks = (default_segment_ticks(source.height * source.width) if mode == "strict" and version >= 4
                         else DEFAULT_SEGMENT_TICKS)
    params = CodingParameters(mode, DEFAULT_K if k is None else k, q, slack_ticks, segment_ticks)
    writer = CodedWriter(path, source.height, source.width, source.clock_hz, params, q, source.start_time_s,
                         {k2: v for k2, v in source.metadata.items() if k2 != "sensor"}, level, version)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=source.n_ticks, unit="tick", desc="encode", leave=False, unit_scale=True)
    try:
        for _, block in source.iter_blocks(block_ticks):
            writer.push(block)
            if bar is not None:
                bar.update(block.shape[0])
        writer.close()
    except BaseException:
        if not writer.f.closed:
            writer.abort()
        raise
    finally:
        if bar is not None:
            bar.close()
    raw = source.n_ticks * source.height * source.width / 8
    return {"path": str(path), "mode": mode, "bytes": writer.bytes_written, "raw_bytes": raw,
            "ratio_vs_raw": raw / writer.bytes_written, "spikes": writer.spikes,
            "first_spikes": None, "segments": writer.n_segments}


# ---------------------------------------------------------------------------- reader

class CodedFile(SpikeSource):
    """A ``.vfc`` file read as a :class:`SpikeSource` (decoded on the fly, segment by segment).

    Opening reads the header and trailer and walks the segment index (lengths only);
    ``iter_blocks`` decodes sequentially in bounded memory. ``verify()`` decodes everything
    and checks the CRCs and spike counts.
    """

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            raise ViformError(f"coded file {str(self.path)!r} does not exist")
        self.size = self.path.stat().st_size
        with open(self.path, "rb") as f:
            self.header = self._read_header(f)
            self._index = self._read_index(f)
        h = self.header
        self.height, self.width = h["height"], h["width"]
        self.clock_hz = h["clock_hz"]
        self.threshold_electrons = h["threshold_electrons"]
        self.start_time_s = h["start_time_s"]
        self.metadata = dict(h.get("metadata") or {}, coded_mode=h["mode"], source_coded=str(self.path))
        self.mode = h["mode"]
        self.segment_ticks = h["segment_ticks"]
        self._cache = None

    # -- structure
    def _fail(self, what: str, offset: int):
        raise ViformError(f"{str(self.path)!r} is not a valid {EXTENSION} file: {what} (at byte {offset})")

    def _read_header(self, f) -> dict:
        fixed = f.read(len(MAGIC) + 10)
        if len(fixed) < len(MAGIC) or fixed[:len(MAGIC)] != MAGIC:
            self._fail("wrong magic number (not a first-spike coded viform)", 0)
        if len(fixed) < len(MAGIC) + 10:
            self._fail("file is truncated inside the header", len(fixed))
        version, hlen, hcrc = struct.unpack_from("<HII", fixed, len(MAGIC))
        if version not in SUPPORTED_VERSIONS:
            self._fail(f"format version {version} is not supported (this viform reads versions "
                       f"{', '.join(map(str, SUPPORTED_VERSIONS))})", len(MAGIC))
        self.version = version
        if hlen > _MAX_HEADER:
            self._fail(f"header length {hlen} is implausible", len(MAGIC) + 2)
        head = f.read(hlen)
        if len(head) < hlen:
            self._fail("file is truncated inside the header", len(fixed) + len(head))
        if zlib.crc32(head) != hcrc:
            self._fail("header checksum mismatch", len(fixed))
        try:
            h = json.loads(head.decode())
        except Exception as exc:
            self._fail(f"header is invalid ({exc})", len(fixed))
        if not isinstance(h, dict):
            self._fail("header is invalid (not a JSON object)", len(fixed))
        for key in ("height", "width", "clock_hz", "threshold_electrons", "start_time_s", "mode", "k",
                    "segment_ticks"):
            if key not in h:
                self._fail(f"header field {key!r} is missing", len(fixed))
        try:
            for key, typ in (("height", int), ("width", int), ("clock_hz", (int, float)), ("mode", str),
                             ("segment_ticks", int), ("start_time_s", (int, float)), ("k", (int, float))):
                if not isinstance(h[key], typ):
                    raise TypeError(key)
            q = h.get("threshold_electrons")
            if not (1 <= h["height"] <= 1 << 16 and 1 <= h["width"] <= 1 << 16
                    and h["height"] * h["width"] <= MAX_PIXELS
                    and 0 < h["clock_hz"] < math.inf and 1 <= h["segment_ticks"] <= 1 << 30
                    and h["mode"] in ("strict", "statistical", "intensity") and math.isfinite(h["start_time_s"])
                    and 0 <= h["k"] < math.inf and isinstance(h.get("slack_ticks", 0), int)
                    and h.get("slack_ticks", 0) >= 0 and isinstance(h.get("metadata") or {}, dict)
                    and (q is None or (isinstance(q, (int, float)) and 0 < q < math.inf))):
                raise ValueError("a value is out of range")
            if any(isinstance(h[key], bool) for key in ("height", "width", "segment_ticks")):
                raise TypeError("a count is a boolean")
            if version >= 4 and h["mode"] == "strict":
                br = h.get("band_rows")
                if not isinstance(br, int) or isinstance(br, bool) or not 1 <= br <= h["height"]:
                    raise ValueError(f"band_rows {br!r} is not a row count between 1 and the height")
        except Exception as exc:
            self._fail(f"header is invalid ({exc})", len(fixed))
        return h

    def _read_index(self, f) -> list[tuple[int, int, int]]:
        index = []
        pos = f.tell()
        while True:
            head = f.read(_SEG_HEAD.size)
            if len(head) < 2:
                self._fail("file is truncated: the end record is missing", pos)
            if head[:2] == b"EN":
                tr = _TRAILER3 if self.version >= 3 else _TRAILER
                rest = head + f.read(tr.size - len(head))
                if len(rest) < tr.size:
                    self._fail("file is truncated inside the end record", pos)
                _, n_ticks, n_seg, spikes, crcs = _TRAILER.unpack_from(rest)
                if self.version >= 3 and zlib.crc32(rest[2:_TRAILER.size]) != _TRAILER3.unpack(rest)[-1]:
                    self._fail("end record checksum mismatch (its tick or spike count is damaged)", pos)
                if f.read(1):
                    self._fail("bytes after the end record", pos + tr.size)
                break
            if len(head) < _SEG_HEAD.size or head[:2] != b"SG":
                self._fail("expected a segment or the end record", pos)
            _, length, crc = _SEG_HEAD.unpack(head)
            if pos + _SEG_HEAD.size + length > self.size:
                self._fail("file is truncated inside a segment", pos)
            index.append((pos + _SEG_HEAD.size, length, crc))
            pos += _SEG_HEAD.size + length
            f.seek(pos)
        if n_seg != len(index):
            self._fail(f"end record counts {n_seg} segments, the file holds {len(index)}", pos)
        seg = self.header["segment_ticks"]
        if n_ticks < 1 or -(-n_ticks // seg) != n_seg:
            self._fail(f"end record's {n_ticks} ticks do not match {n_seg} segments of {seg} ticks", pos)
        acc = 0
        for _, _, crc in index:
            acc = zlib.crc32(struct.pack("<I", crc), acc)
        if acc != crcs:
            self._fail("segment checksum list mismatch", pos)
        n_pix = self.header["height"] * self.header["width"]
        data_bytes = sum(length for _, length, _ in index)
        if self.version >= 2 and n_pix * n_seg > PIXELS_PER_BYTE * data_bytes:
            self._fail(f"the header's {self.header['height']}×{self.header['width']} pixels cannot be coded in "
                       f"{data_bytes} bytes of {n_seg} segment(s) (a genuine file holds at most "
                       f"{PIXELS_PER_BYTE} pixels per byte per segment)", pos)
        self.n_ticks = int(n_ticks)
        self.spikes_stored = int(spikes)
        if spikes > n_ticks * self.header["height"] * self.header["width"]:
            self._fail("end record's spike count is impossible", pos)
        return index

    # -- decoding
    def iter_segments(self):
        """Yield ``(decoder, segment)`` in order, each validated (CRC, structure, spike count)."""
        n_pixels = self.height * self.width
        dec = FirstSpikeDecoder(n_pixels)
        ivstate = np.zeros((n_pixels, interval_model.STATE_ROWS), np.int64) if self.version >= 3 else None
        ivprobs = interval_model.new_probabilities() if self.version >= 3 else None
        zc = _Zstd()
        strict = self.mode == "strict"
        banded = self.version >= 4 and strict
        if banded:  # version 4: segments of spike ticks; ``dec`` is not used
            coding_threads()  # a bad VIFORM_THREADS is the user's setting, not damage in the file
            ivprobs = new_band_probabilities(self.height, self.header["band_rows"])
            last = np.full(n_pixels, -1, np.int64)
        total = 0
        with open(self.path, "rb") as f:
            for n, (offset, length, crc) in enumerate(self._index):
                f.seek(offset)
                payload = f.read(length)
                if len(payload) != length or zlib.crc32(payload) != crc:
                    self._fail(f"segment {n} checksum mismatch (damaged data)", offset)
                try:
                    if self.version == 1:
                        seg, spikes = _decode_payload(payload, n_pixels, dec.anchor, dec.tau_ref, strict, zc,
                                                      n * self.segment_ticks, self.segment_ticks)
                    elif self.version == 2:
                        seg, spikes = _decode_payload_v2(payload, n_pixels, self.width, dec.anchor, dec.tau_ref,
                                                         strict, zc, n * self.segment_ticks, self.segment_ticks)
                    elif banded:
                        seg = _decode_payload_v4(payload, self.height, self.width, self.header["band_rows"], last,
                                                 ivstate, ivprobs, n * self.segment_ticks, self.segment_ticks)
                        spikes = seg.n_spikes
                    else:
                        seg, spikes = _decode_payload_v3(payload, n_pixels, self.width, dec.anchor, dec.tau_ref,
                                                         ivstate, ivprobs, strict, zc, n * self.segment_ticks,
                                                         self.segment_ticks)
                    expect_ticks = min(self.segment_ticks, self.n_ticks - n * self.segment_ticks)
                    if seg.n_ticks != expect_ticks:
                        raise ViformError(f"segment {n} holds {seg.n_ticks} ticks, expected {expect_ticks}")
                    if not banded and dec.check(seg) != spikes:
                        raise ViformError(f"segment {n} decodes to a different spike count than stored")
                except ViformError as exc:
                    self._fail(str(exc), offset)
                except MemoryError:
                    self._fail(f"segment {n} needs more memory than is available (its stated record count "
                               "is implausible, or the machine is too small for it)", offset)
                total += spikes
                yield dec, seg
        if total != self.spikes_stored:
            self._fail(f"segments hold {total} spikes, the end record says {self.spikes_stored}", self.size)

    def iter_blocks(self, block_ticks: int = 1024, start: int = 0, stop: int | None = None):
        block_ticks = check_int("block_ticks", block_ticks, 1)
        stop = self.n_ticks if stop is None else min(stop, self.n_ticks)
        pending = []
        have = 0
        first = start
        for dec, seg in self.iter_segments():
            s0 = seg.start_tick
            if s0 + seg.n_ticks <= start:
                if not isinstance(seg, TickSegment):
                    dec.check(seg, advance=True)
                continue
            if s0 >= stop:
                break
            parts = ([(s0, seg.dense())] if isinstance(seg, TickSegment)
                     else dec.decode(seg, block_ticks=block_ticks))
            for a, blk in parts:
                lo, hi = max(a, start), min(a + blk.shape[0], stop)
                if lo >= hi:
                    continue
                pending.append(blk[lo - a:hi - a])
                have += hi - lo
                while have >= block_ticks:
                    cat = np.concatenate(pending) if len(pending) > 1 else pending[0]
                    yield first, cat[:block_ticks].reshape(-1, self.height, self.width)
                    first += block_ticks
                    rest = cat[block_ticks:]
                    pending = [rest] if rest.shape[0] else []
                    have = rest.shape[0]
        if have:
            cat = np.concatenate(pending) if len(pending) > 1 else pending[0]
            yield first, cat.reshape(-1, self.height, self.width)

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, start), min(stop, self.n_ticks)
        if stop <= start:
            return np.zeros((0, self.height, self.width), bool)
        return np.concatenate([b for _, b in self.iter_blocks(stop - start, start, stop)])

    def verify(self) -> int:
        """Decode everything; raise on any damage. Returns the spike count."""
        n = 0
        for dec, seg in self.iter_segments():
            if isinstance(seg, TickSegment):  # decoding checked every tick against its segment
                n += seg.n_spikes
                continue
            for _, blk in dec.decode(seg, block_ticks=256):
                n += int(np.count_nonzero(blk))
        return n

    def quadruples(self) -> np.ndarray:
        """The stored first spikes as (i, j, t, τ) quadruples (ticks)."""
        from viform.coding.first_spike import quadruples

        segs = []
        records = FirstSpikeDecoder(self.height * self.width)
        for dec, seg in self.iter_segments():
            if isinstance(seg, TickSegment):  # version 4 stores ticks: its first spikes are derived here
                seg = _segment_from_ticks(seg.counts, seg.ticks, records.anchor, records.tau_ref, seg.start_tick,
                                          seg.n_ticks)
                dec = records
            segs.append(seg)
            dec.check(seg, advance=True)
        return quadruples(segs, self.height, self.width)


def open_coded(path) -> CodedFile:
    """Open a ``.vfc`` file as a :class:`SpikeSource`."""
    return CodedFile(path)


def is_coded_file(path) -> bool:
    """True when ``path`` starts with the ``.vfc`` magic number."""
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


def describe_coded_file(path) -> dict:
    """Summary of a ``.vfc`` file for ``viform info`` (header, size, ratio; every checksum checked, no decode)."""
    cf = CodedFile(path)
    _check_segment_crcs(cf)
    h = cf.header
    raw = cf.n_ticks * cf.height * cf.width / 8
    return {
        "format": f"first-spike coded viform ({EXTENSION}, version {cf.version})",
        "height": cf.height, "width": cf.width, "n_ticks": cf.n_ticks, "clock_hz": cf.clock_hz,
        "duration_s": cf.n_ticks / cf.clock_hz, "start_time_s": cf.start_time_s,
        "threshold_electrons": cf.threshold_electrons, "mode": h["mode"], "k": h["k"],
        "slack_ticks": h.get("slack_ticks", 0), "segment_ticks": h["segment_ticks"],
        **({"band_rows": h["band_rows"]} if "band_rows" in h else {}), "segments": len(cf._index),
        "spike_count": cf.spikes_stored, "file_bytes": cf.size, "raw_bytes": raw,
        "ratio_vs_raw": raw / cf.size, "bits_per_spike": 8 * cf.size / max(1, cf.spikes_stored),
        "metadata": h.get("metadata", {}),
        "verified": True,
        "verification": ("header, end-record and every segment's checksum checked (not decoded: viform verify "
                         "decodes everything)" if cf.version >= 3 else
                         "header and every segment's checksum checked (not decoded: viform verify decodes "
                         f"everything; version {cf.version} has no checksum over the end record's counts)"),
    }


def verify_coded_file(path) -> dict:
    """Check a ``.vfc`` file completely: every checksum, then a full decode with every spike count compared.

    Returns what was checked (for ``viform verify``); damage raises :class:`ViformError` naming the
    byte offset and what is wrong.
    """
    cf = CodedFile(path)
    spikes = cf.verify()
    checks = ["header checksum", "end-record checksum" if cf.version >= 3 else "end record (version "
              f"{cf.version}: its counts have no checksum of their own)",
              f"{len(cf._index)} segment checksums", f"every segment decoded ({spikes} spikes, "
              f"{cf.n_ticks} ticks), spike counts match the segment headers and the end record"]
    return {"format_version": cf.version, "mode": cf.mode, "segments": len(cf._index), "n_ticks": cf.n_ticks,
            "spike_count": spikes, "checks": checks}


def _check_segment_crcs(cf: CodedFile) -> None:
    """Read every segment and compare its CRC-32 (no decoding; bounded memory)."""
    with open(cf.path, "rb") as f:
        for n, (offset, length, crc) in enumerate(cf._index):
            f.seek(offset)
            acc = 0
            left = length
            while left:
                chunk = f.read(min(left, 1 << 20))
                if not chunk:
                    break
                acc = zlib.crc32(chunk, acc)
                left -= len(chunk)
            if left or acc != crc:
                cf._fail(f"segment {n} checksum mismatch (damaged data)", offset)
