"""``.vfc`` version 4 segments: strict segments coded in bands of rows, on parallel threads.

Strict payload: the payload head (flags 4, records 0), u32 band count, per band u32 coded bytes
and u64 spikes, then each band's spike ticks coded by :mod:`viform.coding.interval_model` (its
version-4 predictor: neighbours' current intervals against the prediction as context) with its
own adaptive probabilities; the bands are fixed by the header's ``band_rows``, so the bytes never
depend on the thread count. Lossy modes: version 2's payload (flag 0).
"""

from __future__ import annotations

import struct

import numpy as np

from viform._validate import ViformError
from viform.coding import interval_model
from viform.coding.vfc_common import (
    _PAYLOAD_HEAD,
    TickSegment,
    _bands,
    _check_band_totals,
    _interval_data_limit,
    _map,
)

_FLAG_BANDS = 4
_BAND_HEAD = struct.Struct("<IQ")  # per band: coded bytes, spikes


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
        if body.size > _interval_data_limit(ticks.size, (r1 - r0) * width):  # never write what the reader refuses
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
        if sp > n_ticks * (r1 - r0) * width or nbytes > _interval_data_limit(sp, (r1 - r0) * width):
            raise ViformError(f"band {b} is invalid ({nbytes} bytes, {sp} spikes)")
        spans.append((pos, nbytes, sp))
        pos += nbytes
        total += sp
    _check_band_totals(payload, pos, total, spikes)
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
