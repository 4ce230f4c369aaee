"""``.vfc`` version 6 segments: bands of rows, each coded by the tick model (run-length records where smaller).

Version 5 coded every band of every strict segment with three models and kept the smallest (the
encoder did three times the work of one model). Version 6 codes each band with
:mod:`viform.coding.tick_model` (the per-pixel phase-locked interval predictor of version 4 with
the neighbours' intervals read from row buffers, and the probabilities of its residual decisions
mixed from several context sets), which is smaller than both of version 5's interval models on
the streams of ``benchmarks/bench_coding.py --corpus``; only where it needs at least
:data:`RECORDS_TRIAL_BITS_PER_SPIKE` does the writer also code the band's first-spike records
(version 5's model 1, :mod:`viform.coding.context_model`) and keep them when smaller — on noisy
streams whose pixels hold one width for long runs (the second shared REDS clip) the records are
smaller than any interval prediction.

Both models' states advance with every segment, as in version 5: the records' anchors always; the
tick model's by its own bands, and after a records band it restarts, for every pixel that fired,
at the pixel's last interval (its adaptive probabilities keep what they had learnt).

Strict payload (all integers LEB128 varints)::

    u8 flag 6, start tick, ticks, spikes,
    per band (the header's ``band_rows``): coded bytes, 4 · spikes + model (0: the tick model,
    1: records) and for a records band its record count,
    then each band's range-coder bytes.

Lossy modes: version 2's payload (flag 0), as in versions 3 to 5. The header of a version-6 file is
its JSON compressed with zlib (:func:`pack_header`).
"""

from __future__ import annotations

import zlib

import numpy as np

from viform._validate import ViformError
from viform.coding import interval_model, tick_model, vfc_v5
from viform.coding.vfc_common import TickSegment, _bands, _check_band_totals, _interval_data_limit, _map
from viform.coding.vfc_v5 import _read_varint, _varint

_FLAG_BANDS6 = 6
MODEL_TICKS = 0
MODEL_RECORDS = 1
MODEL_NAMES = ("tick model", "run-length records")
#: The records model is tried on a band only when the tick model needs at least this many bits per spike.
#: Chosen on the tuning half of the corpus (every band of every segment coded both ways): of 36 bands,
#: records won 8, all at ≥ 1.65 bit/spike but one (0.54 bit/spike, 136 bytes smaller); trying from 1.5
#: codes records for 6.1 M of the half's 26 M spikes, from 0.8 (version 5's rule) for 15.7 M.
RECORDS_TRIAL_BITS_PER_SPIKE = 1.5
#: largest decompressed header (the container's limit on a header)
MAX_HEADER_BYTES = 1 << 20


def pack_header(head: bytes) -> bytes:
    """The stored form of a version-6 header: its JSON, zlib-compressed (level 9)."""
    return zlib.compress(head, 9)


def unpack_header(stored: bytes) -> bytes:
    """The JSON of a stored version-6 header; damage or more than :data:`MAX_HEADER_BYTES` is refused."""
    d = zlib.decompressobj()
    try:
        head = d.decompress(stored, MAX_HEADER_BYTES)
    except zlib.error as exc:
        raise ViformError(f"header is invalid (zlib: {exc})") from None
    if d.unconsumed_tail or not d.eof or d.unused_data:
        raise ViformError("header is invalid (its zlib stream is cut short, too long, or followed by bytes)")
    return head


class BandState:
    """What a version-6 strict reader or writer carries from segment to segment.

    ``last`` (each pixel's last spike tick, −1: never fired) and ``ref`` (its last width, ticks; 0:
    never) anchor the records; ``ivstate`` is the tick model's state per pixel, ``ivprobs`` its
    adaptive probabilities, one set per band. ``records``: whether the writer may try the records.
    """

    def __init__(self, height: int, width: int, band_rows: int, records: bool = True):
        n = height * width
        self.height, self.width, self.band_rows = height, width, band_rows
        self.records = records
        self.bands = _bands(height, band_rows)
        self.last = np.full(n, -1, np.int64)
        self.ref = np.zeros(n, np.int64)
        self.ivstate = np.zeros((n, tick_model.STATE_ROWS), np.int64)
        self.ivprobs = np.stack([tick_model.new_probabilities() for _ in self.bands])


def encode_payload(dense: np.ndarray, start: int, state: BandState) -> tuple[bytes, int]:
    """Version-6 strict payload of the segment ``dense`` (bool (T, H, W), C order); ``state`` advances.

    Each band is coded by the tick model (and by the records where it needs at least
    :data:`RECORDS_TRIAL_BITS_PER_SPIKE`; the smaller is kept, the tick model on a tie), the bands on
    the coding threads. Returns the payload and its spike count.
    """
    n_ticks, height, width = dense.shape
    end = start + n_ticks

    def one(b):
        r0, r1 = state.bands[b]
        p0, p1 = r0 * width, r1 * width
        counts, ticks = interval_model.band_ticks(dense, r0, r1, start)
        st, probs = state.ivstate[p0:p1], state.ivprobs[b]
        st0, probs0 = st.copy(), probs.copy()
        size = ticks.size // 2 + (p1 - p0) // 2 + 4096
        while True:
            out = np.empty(size, np.uint8)
            nb = tick_model.encode_band(counts, ticks, state.last[p0:p1], st, probs, start, end, width, out)
            if nb <= size:
                break
            st[...] = st0
            probs[...] = probs0
            size = 2 * nb
        model, body, n_rec = MODEL_TICKS, out[:nb], 0
        if state.records and 8 * nb >= RECORDS_TRIAL_BITS_PER_SPIKE * ticks.size:
            rec, n_rec = vfc_v5._records_bytes(counts, ticks, state.last[p0:p1], state.ref[p0:p1], start, end, width)
            if rec.size < nb:  # the reader does not run the tick model over a records band
                model, body = MODEL_RECORDS, rec
                st[...] = st0
                probs[...] = probs0
        if body.size > _interval_data_limit(ticks.size, p1 - p0):  # never write what the reader refuses
            raise ViformError(f"segment at tick {start} codes to {body.size} bytes, more than the format allows")
        return model, counts, ticks, body, n_rec

    parts = _map(one, len(state.bands))
    for (r0, r1), (model, counts, ticks, _, _) in zip(state.bands, parts, strict=True):
        vfc_v5._advance(state, r0 * width, r1 * width, model, counts, ticks)
    n_spikes = sum(t.size for _, _, t, _, _ in parts)
    head = bytes([_FLAG_BANDS6]) + _varint(start) + _varint(n_ticks) + _varint(n_spikes)
    table = b"".join(_varint(body.size) + _varint(4 * t.size + model) + (_varint(n_rec) if model == MODEL_RECORDS
                                                                          else b"")
                     for model, _, t, body, n_rec in parts)
    return head + table + b"".join(body.tobytes() for _, _, _, body, _ in parts), n_spikes


def band_models(payload: bytes, n_bands: int) -> list[int]:
    """The model of each band of a version-6 strict payload (for reports)."""
    pos = 1
    for what in ("start", "ticks", "spikes"):
        _, pos = _read_varint(payload, pos, f"the segment's {what}")
    models = []
    for _ in range(n_bands):
        _, pos = _read_varint(payload, pos, "the band table")
        field, pos = _read_varint(payload, pos, "the band table")
        models.append(field % 4)
        if field % 4 == MODEL_RECORDS:
            _, pos = _read_varint(payload, pos, "the band table")
    return models


def decode_payload(payload: bytes, state: BandState, expected_start: int, segment_ticks: int) -> TickSegment:
    """Decode a version-6 strict segment (bands in parallel) into a :class:`TickSegment`; ``state`` advances."""
    height, width = state.height, state.width
    if not payload or payload[0] != _FLAG_BANDS6:
        raise ViformError(f"segment header is invalid (flags {payload[0] if payload else None})")
    start, pos = _read_varint(payload, 1, "the segment's start tick")
    n_ticks, pos = _read_varint(payload, pos, "the segment's tick count")
    spikes, pos = _read_varint(payload, pos, "the segment's spike count")
    if start != expected_start:
        raise ViformError(f"segment starts at tick {start}, expected {expected_start}")
    if not 1 <= n_ticks <= segment_ticks:
        raise ViformError(f"segment header is invalid (ticks {n_ticks})")
    if spikes > n_ticks * height * width:
        raise ViformError(f"segment header is invalid ({spikes} spikes)")
    bands = state.bands
    spans = []
    for b, (r0, r1) in enumerate(bands):
        nbytes, pos = _read_varint(payload, pos, f"band {b}'s entry of the band table")
        field, pos = _read_varint(payload, pos, f"band {b}'s entry of the band table")
        model, sp = field % 4, field // 4
        recs = 0
        if model == MODEL_RECORDS:
            recs, pos = _read_varint(payload, pos, f"band {b}'s entry of the band table")
        npix = (r1 - r0) * width
        if (model not in (MODEL_TICKS, MODEL_RECORDS) or sp > n_ticks * npix or nbytes > _interval_data_limit(sp, npix)
                or recs > sp):
            raise ViformError(f"band {b} is invalid (model {model}, {nbytes} bytes, {sp} spikes, {recs} records)")
        spans.append((model, nbytes, sp, recs))
    offsets = []
    total = 0
    for _, nbytes, sp, _ in spans:
        offsets.append(pos)
        pos += nbytes
        total += sp
    _check_band_totals(payload, pos, total, spikes)
    buf = np.frombuffer(payload, np.uint8)
    end = start + n_ticks
    # the tick arrays grow with the spikes actually decoded, never to the stated count up front; where
    # every tick-model band may hold its stated count and the segment's count is within what its bytes
    # can hold as tick-model data (a records band's stated count is not bounded by its bytes: a forged
    # one must not allocate it), the bands decode into one array (no copy after)
    caps = [sp if model == MODEL_RECORDS else min(sp, 64 * nbytes + 4096) for model, nbytes, sp, _ in spans]
    whole = None
    if total <= 64 * len(payload) + 4096 and all(cap == sp for cap, (_, _, sp, _) in zip(caps, spans, strict=True)):
        whole = np.empty(total, np.int64)
        firsts = np.cumsum([0] + [sp for _, _, sp, _ in spans])
    counts_all = np.empty(height * width, np.int64)

    def one(b):
        r0, r1 = bands[b]
        p0, p1 = r0 * width, r1 * width
        model, nbytes, sp, recs = spans[b]
        data = buf[offsets[b]:offsets[b] + nbytes]
        counts = counts_all[p0:p1]
        if model == MODEL_RECORDS:
            why, ticks = vfc_v5._decode_records(data, counts, state.last[p0:p1], state.ref[p0:p1], start, end, width,
                                                sp, recs, None if whole is None else whole[firsts[b]:firsts[b + 1]])
            return why, counts, ticks
        st, probs = state.ivstate[p0:p1], state.ivprobs[b]
        st0, probs0 = st.copy(), probs.copy()
        cap = caps[b]
        while True:
            ticks = whole[firsts[b]:firsts[b + 1]] if whole is not None else np.empty(cap, np.int64)
            err, _ = tick_model.decode_band(data, p1 - p0, state.last[p0:p1], st, probs, start, end, width, sp,
                                            counts, ticks)
            if err != 2 or cap >= sp:
                break
            st[...] = st0
            probs[...] = probs0
            cap = min(sp, 4 * cap)
        return (tick_model.ERRORS[err] if err else ""), counts, ticks[:sp]

    parts = _map(one, len(bands))
    for b, (why, _, _) in enumerate(parts):
        if why:
            raise ViformError(f"segment at tick {start}, band {b} is damaged ({why})")
    for (r0, r1), (_, counts, ticks), (model, _, _, _) in zip(bands, parts, spans, strict=True):
        vfc_v5._advance(state, r0 * width, r1 * width, model, counts, ticks)
    ticks = whole if whole is not None else np.concatenate([p[2] for p in parts])
    return TickSegment(start, n_ticks, counts_all, ticks)
