"""``.vfc`` version 2 segments: first-spike records range-coded by :mod:`viform.coding.context_model`.

Payload: the payload head (flags 0), then u32 length + one zstd frame (content checksum on) holding
the records range-coded with neighbour-predicted first widths, uniform phases and context-modelled
width changes. Versions 3 to 5 code their lossy-mode segments this way too.
"""

from __future__ import annotations

import struct

import numpy as np

from viform._validate import ViformError
from viform.coding import context_model
from viform.coding.first_spike import Segment
from viform.coding.vfc_common import _PAYLOAD_HEAD, _Zstd


def _encode_payload_v2(seg: Segment, anchor0, ref0, width: int, strict: bool, zc: _Zstd) -> bytes:
    """Version-2 payload: the segment's records range-coded (:mod:`viform.coding.context_model`), one zstd frame."""
    n_rec, npix = seg.m.size, seg.counts.size
    size = 16 * (n_rec + npix) + 4096
    rec_s = np.empty(n_rec + 1, np.int64)
    while True:
        out = np.empty(size, np.uint8)
        n = context_model.encode_segment(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, anchor0, ref0,
                                         seg.start_tick, seg.start_tick + seg.n_ticks, width, strict, out, rec_s,
                                         False)
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
                                           n_rec, counts, rec_m, rec_g, rec_o, tail_m, tail_g, rec_s, False)
        if err != context_model.TOO_MANY_RECORDS or cap >= n_rec:
            break
        cap = min(n_rec, 4 * cap)
    if err:
        raise ViformError(f"segment at tick {start} is damaged ({context_model.ERRORS[err]})")
    seg = Segment(start, n_ticks, counts, rec_m, rec_g, rec_o, np.zeros(0, np.int64), tail_m, tail_g,
                  np.zeros(0, np.int64))
    return seg, spikes


