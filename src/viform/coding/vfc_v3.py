"""``.vfc`` version 3 segments: strict segments coded spike by spike against a per-pixel interval prediction.

Strict payload: the payload head, then (flag 1) the spike ticks coded by
:mod:`viform.coding.interval_model` (its version-3 predictor, one model for the whole image), or
(flag 2) the first-spike records range-coded as in version 2 without the zstd stage, whichever is
smaller; the interval predictor's state advances either way (the reader replays it from the
decoded spikes). Lossy modes: version 2's payload (flag 0).
"""

from __future__ import annotations

import numpy as np

from viform._validate import ViformError
from viform.coding import context_model, interval_model
from viform.coding.first_spike import FirstSpikeDecoder, Segment
from viform.coding.vfc_common import _PAYLOAD_HEAD, _interval_data_limit, _segment_from_ticks, _Zstd
from viform.coding.vfc_v2 import _decode_payload_v2, _decode_records

#: 1 spikes coded by :mod:`viform.coding.interval_model` (strict); 2 range-coded records, no zstd (strict)
_FLAG_INTERVALS = 1
_FLAG_RECORDS = 2


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
                                          seg.start_tick + seg.n_ticks, width, out, 3)
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
                                          seg.start_tick, seg.start_tick + seg.n_ticks, width, True, out2, rec_s,
                                          False)
        if n2 <= size:
            if n2 < n:
                flag, body = _FLAG_RECORDS, out2[:n2]
            break
        size = 2 * n2
    if body.size > _interval_data_limit(n_spikes, npix):  # never write what the reader would refuse
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
    if data.size > _interval_data_limit(spikes, n_pixels):
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
                                      np.empty(1, np.uint8), 3)
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
                                               spikes, tick_counts, ticks, 3)
        if err != 2 or cap >= spikes:
            break
        cap = min(spikes, 4 * cap)
    if err:
        raise ViformError(f"segment at tick {start} is damaged ({interval_model.ERRORS[err]})")
    seg = _segment_from_ticks(tick_counts, ticks[:spikes], anchor0, ref0, start, n_ticks)
    if seg.m.size != n_rec:
        raise ViformError(f"segment at tick {start} decodes to {seg.m.size} first spikes, its header says {n_rec}")
    return seg, spikes

