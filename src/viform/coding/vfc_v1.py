"""``.vfc`` version 1 segments: first-spike records in eight zstd-compressed columns (read and written).

After the payload head (its u8 is model + 2·layout) eight columns, each u32 length + one zstd
frame: per-pixel record counts, first offsets of pixels that had not fired, the context-sorted
record symbols, the context table, escapes, span residuals (lossy modes), tail deficits, the
first full widths of pixels (coded against the previous pixel's). Records are coded as one byte
symbol combining the repeat count m and the width change, split by a context (the previous symbol
of the pixel and its current width, or its previous two symbols — whichever is smaller is kept
per segment); contexts are recomputed by the decoder as it goes, so only the per-context counts
are stored. Values that do not fit a symbol go to the escape column as LEB128 varints.
"""

from __future__ import annotations

import io
import struct

import numpy as np
import zstandard
from numba import njit

from viform._validate import ViformError
from viform.coding.first_spike import Segment
from viform.coding.vfc_common import _PAYLOAD_HEAD, _Zstd

_NCOLS = 8
_ESC = 255
_NONE = 254


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


def _count_varints(data: bytes, what: str) -> np.ndarray:
    arr = np.frombuffer(data, np.uint8)
    n = int(np.count_nonzero(arr < 128))
    return _unvarints(data, n, what)

