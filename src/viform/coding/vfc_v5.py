"""``.vfc`` version 5 segments: bands of rows, each coded by whichever of three models is smaller.

Version 4 coded every band with the interval predictor, tuned on one REDS clip; on streams whose
pixels hold one interval for long runs (noise-free simulations, slow real scenes) version 3's
run-length records were smaller (up to 9 % on the second shared REDS clip). Version 5 codes each
band of each strict segment every way and keeps the smallest, so no stream codes larger than the
smaller of its version-3 and version-4 files (measured on the corpus of
``benchmarks/bench_coding.py``, tuning and held-out halves):

* model 0 — the spike ticks against each pixel's interval prediction
  (:mod:`viform.coding.interval_model`, its version-4 predictor and contexts); model 2 — the same
  with version 3's predictor (slower loop, neighbours' interval trends as context), which is
  smaller on some streams (night scenes at Q = 10³, high-Q scenes at 40 kHz: up to 1 %);
* model 1 — the first-spike records of the band (seed 000 §5.2: a spike only where the width
  changes, repeat counts between) range-coded by :mod:`viform.coding.context_model`, whose young
  contexts learn at their running frequency (``young``: a band learns its probabilities on its
  own, so learning speed is what banding costs; it made the banded records 1.2-1.6 % smaller than
  version 3's whole-image records on the shared files).

Both models' states advance with every segment, whichever was kept: the records' anchors (each
pixel's last spike tick and last width) always; the interval predictor's by the interval model's
bands, and after a records band it restarts, for every pixel that fired, at the pixel's last
interval (a restart as after a change of the light, cheap for the reader: no second pass over the
spikes; its adaptive probabilities keep what they had learnt).

Strict payload: the payload head (flags 5, records 0), then per band (their count is the header's
``band_rows``') LEB128 varints: coded bytes, 4·spikes + model, and for a records band its record
count; then the bands' bytes. Lossy modes: version 2's payload (flag 0), as in versions 3 and 4.
The header JSON is written without spaces (version 5): with the smaller band table, a file is
never larger than version 3's for the container alone (version 4 added 33 bytes to a one-band
file), so the choice of model decides.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from viform._validate import ViformError
from viform.coding import context_model, interval_model
from viform.coding.first_spike import _check_segment
from viform.coding.vfc_common import (
    _PAYLOAD_HEAD,
    TickSegment,
    _bands,
    _check_band_totals,
    _interval_data_limit,
    _map,
    _segment_from_ticks,
)

_FLAG_BANDS5 = 5
MODEL_INTERVALS = 0
MODEL_RECORDS = 1
MODEL_INTERVALS_V3 = 2
MODEL_NAMES = ("interval prediction", "run-length records", "interval prediction (version 3)")
#: the interval model's predictor version of each interval model
_PREDICTOR = {MODEL_INTERVALS: 4, MODEL_INTERVALS_V3: 3}
#: The records model is tried on a band only when the interval model needs at least this many bits per
#: spike: below it (pixels locked on steady light) the records model never won on the tuning half.
RECORDS_TRIAL_BITS_PER_SPIKE = 0.8
_MAX_VARINT_BYTES = 10
#: the models a writer tries per band: all (smallest file), or the interval model only (``fast``: version 4's speed)
ALL_MODELS = (MODEL_INTERVALS, MODEL_INTERVALS_V3, MODEL_RECORDS)
FAST_MODELS = (MODEL_INTERVALS,)


def _varint(v: int) -> bytes:
    out = bytearray()
    while v >= 128:
        out.append((v & 127) | 128)
        v >>= 7
    out.append(v)
    return bytes(out)


def _read_varint(payload: bytes, pos: int, what: str) -> tuple[int, int]:
    """A LEB128 value at ``pos`` and the position after it; cut short or over-long is damage."""
    v = 0
    for k in range(_MAX_VARINT_BYTES):
        if pos + k >= len(payload):
            raise ViformError(f"segment payload is cut short in {what}")
        byte = payload[pos + k]
        v |= (byte & 127) << (7 * k)
        if byte < 128:
            return v, pos + k + 1
    raise ViformError(f"{what} is too long")


class BandState:
    """What a version-5 strict reader or writer carries from segment to segment.

    ``last`` (each pixel's last spike tick, −1 never) and ``ref`` (its last width, ticks; 0 never
    fired) anchor the records model; ``ivstate`` and ``ivprobs`` (per band) are the interval
    predictor's state and adaptive probabilities.
    """

    def __init__(self, height: int, width: int, band_rows: int, models: tuple | None = None):
        n = height * width
        self.models = ALL_MODELS if models is None else models  # what the writer tries (the reader reads any)
        self.height, self.width, self.band_rows = height, width, band_rows
        self.bands = _bands(height, band_rows)
        self.last = np.full(n, -1, np.int64)
        self.ref = np.zeros(n, np.int64)
        self.ivstate = np.zeros((n, interval_model.STATE_ROWS), np.int64)
        self.ivprobs = np.stack([interval_model.new_probabilities() for _ in self.bands])


@njit(cache=True, nogil=True)
def _restart_predictor(counts, last0, ref, st):
    """After a records band: the interval predictor of each pixel that fired restarts at its last interval.

    ``last0`` is each pixel's last spike before the segment, ``ref`` its last width after it
    (:func:`_advance_anchors`). A pixel whose only spike ever is in this segment has no interval
    yet: its state stays empty.
    """
    one = np.int64(1) << 16
    for q in range(counts.size):
        c = counts[q]
        if c == 0 or (c == 1 and last0[q] < 0):
            continue
        iv = ref[q]
        st[q, 0] = iv << 16
        st[q, 1] = one >> 1
        st[q, 2] = one >> 1
        st[q, 3] = 1
        st[q, 4] = iv
        st[q, 5] = iv
        st[q, 6] = iv


@njit(cache=True, nogil=True)
def _advance_anchors(counts, ticks, last, ref):
    """Each pixel's last spike tick and last width after a segment (as the records model counts them)."""
    r = 0
    for q in range(counts.size):
        c = counts[q]
        r += c
        if c > 0:
            prev = ticks[r - 2] if c >= 2 else last[q]
            ref[q] = ticks[r - 1] - prev
            last[q] = ticks[r - 1]


def _advance(state: BandState, p0: int, p1: int, model: int, counts, ticks) -> None:
    """Move a band's anchors (and after a records band, its interval predictor) past a segment."""
    last0 = state.last[p0:p1].copy() if model == MODEL_RECORDS else None
    _advance_anchors(counts, ticks, state.last[p0:p1], state.ref[p0:p1])
    if model == MODEL_RECORDS:
        _restart_predictor(counts, last0, state.ref[p0:p1], state.ivstate[p0:p1])


def _records_bytes(counts, ticks, last, ref, start: int, end: int, width: int):
    """Model 1: the band's first-spike records, range-coded (young contexts). Returns (bytes, records)."""
    seg = _segment_from_ticks(counts, ticks, last, ref, start, end - start)
    n_rec, npix = seg.m.size, counts.size
    rec_s = np.empty(n_rec + 1, np.int64)
    size = 2 * ticks.size + npix // 4 + 4096
    while True:
        out = np.empty(size, np.uint8)
        n = context_model.encode_segment(seg.counts, seg.m, seg.g, seg.o, seg.tail_m, seg.tail_g, last, ref, start,
                                         end, width, True, out, rec_s, True)
        if n <= size:
            return out[:n], n_rec
        size = 2 * n


def encode_payload(dense: np.ndarray, start: int, state: BandState) -> tuple[bytes, int]:
    """Version-5 strict payload of the segment ``dense`` (bool (T, H, W)); ``state`` advances in place.

    Each band is coded by both models on the coding threads; the smaller is kept (the interval
    model on a tie). Returns the payload and its spike count.
    """
    n_ticks, height, width = dense.shape
    end = start + n_ticks

    def one(b):
        r0, r1 = state.bands[b]
        p0, p1 = r0 * width, r1 * width
        counts, ticks = interval_model.band_ticks(dense, r0, r1, start)
        n = ticks.size
        st, probs = state.ivstate[p0:p1], state.ivprobs[b]
        st0, probs0 = st.copy(), probs.copy()
        best = None
        for model in (MODEL_INTERVALS, MODEL_INTERVALS_V3):
            if model not in state.models:
                continue
            st[...] = st0
            probs[...] = probs0
            size = 2 * n + (p1 - p0) // 4 + 4096
            while True:
                out = np.empty(size, np.uint8)
                nb = interval_model.encode_segment(counts, ticks, state.last[p0:p1], st, probs, start, end, width,
                                                   out, _PREDICTOR[model])
                if nb <= size:
                    break
                st[...] = st0
                probs[...] = probs0
                size = 2 * nb
            if best is None or nb < best[1].size:
                best = (model, out[:nb], 0, st.copy(), probs.copy())
        if MODEL_RECORDS in state.models and 8 * best[1].size >= RECORDS_TRIAL_BITS_PER_SPIKE * n:
            rec, n_rec = _records_bytes(counts, ticks, state.last[p0:p1], state.ref[p0:p1], start, end, width)
            if rec.size < best[1].size:  # the reader does not run the interval model over a records band
                best = (MODEL_RECORDS, rec, n_rec, st0, probs0)
        model, body, n_rec, st_end, probs_end = best
        st[...] = st_end
        probs[...] = probs_end
        return model, counts, ticks, body, n_rec

    parts = _map(one, len(state.bands))
    for (r0, r1), (_, _, ticks, body, _) in zip(state.bands, parts, strict=True):
        if body.size > _interval_data_limit(ticks.size, (r1 - r0) * width):  # never write what the reader refuses
            raise ViformError(f"segment at tick {start} codes to {body.size} bytes, more than the format allows")
    for (r0, r1), (model, counts, ticks, _, _) in zip(state.bands, parts, strict=True):
        _advance(state, r0 * width, r1 * width, model, counts, ticks)
    n_spikes = sum(t.size for _, _, t, _, _ in parts)
    table = b"".join(_varint(body.size) + _varint(4 * t.size + model) + (_varint(n_rec) if model == MODEL_RECORDS
                                                                          else b"")
                     for model, _, t, body, n_rec in parts)
    payload = (_PAYLOAD_HEAD.pack(start, n_ticks, 0, _FLAG_BANDS5, n_spikes) + table
               + b"".join(p[3].tobytes() for p in parts))
    return payload, n_spikes


def band_models(payload: bytes, n_bands: int) -> list[int]:
    """The model of each band of a version-5 strict payload (for reports)."""
    pos = _PAYLOAD_HEAD.size
    models = []
    for _ in range(n_bands):
        _, pos = _read_varint(payload, pos, "the band table")
        field, pos = _read_varint(payload, pos, "the band table")
        models.append(field % 4)
        if field % 4 == MODEL_RECORDS:
            _, pos = _read_varint(payload, pos, "the band table")
    return models


def _decode_intervals(data, counts, st, probs, last, start, end, width, sp, predictor):
    st0, probs0 = st.copy(), probs.copy()
    # the tick array grows with the spikes actually decoded, never to the stated count up front
    cap = min(sp, 64 * data.size + 4096)
    while True:
        ticks = np.empty(cap, np.int64)
        err, _ = interval_model.decode_segment(data, counts.size, last, st, probs, start, end, width, sp, counts,
                                               ticks, predictor)
        if err != 2 or cap >= sp:
            break
        st[...] = st0
        probs[...] = probs0
        cap = min(sp, 4 * cap)
    return (interval_model.ERRORS[err] if err else ""), ticks[:sp]


def _decode_records(data, counts, last, ref, start, end, width, sp, n_rec, out=None):
    """A records band's spike ticks (``counts`` filled): ``(why, ticks)``, ``why`` empty unless damaged.

    ``out`` (optional, ``sp`` int64) receives the ticks (else a new array does).
    """
    npix = counts.size
    tail_m, tail_g = np.empty(npix, np.int64), np.empty(npix, np.int64)
    rec_counts = np.empty(npix, np.int64)
    # the record arrays grow with the records actually decoded, never to the stated count up front
    cap = min(n_rec, 4 * data.size + 4096)
    while True:
        rec_m, rec_g, rec_o, rec_s = (np.empty(cap, np.int64) for _ in range(4))
        err = context_model.decode_segment(data, npix, last, ref, start, end, width, True, n_rec, rec_counts,
                                           rec_m, rec_g, rec_o, tail_m, tail_g, rec_s, True)
        if err != context_model.TOO_MANY_RECORDS or cap >= n_rec:
            break
        cap = min(n_rec, 4 * cap)
    if err:
        return context_model.ERRORS[err], None
    # the records must regenerate exactly the stated spikes inside the segment before ticks are written
    err, n_sp = _check_segment(rec_counts, rec_m[:n_rec], rec_g[:n_rec], rec_o[:n_rec], tail_m, tail_g, last.copy(),
                               ref.copy(), start, end)
    if err or n_sp != sp:
        return f"its records give {n_sp} spikes, the band table says {sp}" if not err else "inconsistent records", None
    # _check_segment found exactly sp spikes in the records: that many ticks are written
    ticks = np.empty(sp, np.int64) if out is None else out
    interval_model.ticks_from_records(rec_counts, rec_m, rec_g, rec_o, tail_m, tail_g, last, ref, start, counts,
                                      ticks)
    return "", ticks


def decode_payload(payload: bytes, state: BandState, expected_start: int, segment_ticks: int) -> TickSegment:
    """Decode a version-5 strict segment (bands in parallel) into a :class:`TickSegment`; ``state`` advances."""
    head = _PAYLOAD_HEAD.size
    if len(payload) < head:
        raise ViformError("segment payload is shorter than its header")
    start, n_ticks, n_rec, flags, spikes = _PAYLOAD_HEAD.unpack_from(payload)
    height, width = state.height, state.width
    if start != expected_start:
        raise ViformError(f"segment starts at tick {start}, expected {expected_start}")
    if flags != _FLAG_BANDS5:
        raise ViformError(f"segment header is invalid (flags {flags})")
    if not 1 <= n_ticks <= segment_ticks:
        raise ViformError(f"segment header is invalid (ticks {n_ticks})")
    if n_rec != 0 or spikes > n_ticks * height * width:
        raise ViformError(f"segment header is invalid ({n_rec} records, {spikes} spikes)")
    bands = state.bands
    table = []
    pos = head
    for b, (r0, r1) in enumerate(bands):
        nbytes, pos = _read_varint(payload, pos, f"band {b}'s entry of the band table")
        field, pos = _read_varint(payload, pos, f"band {b}'s entry of the band table")
        model, sp = field % 4, field // 4
        recs = 0
        if model == MODEL_RECORDS:
            recs, pos = _read_varint(payload, pos, f"band {b}'s entry of the band table")
        npix = (r1 - r0) * width
        if (model not in (MODEL_INTERVALS, MODEL_RECORDS, MODEL_INTERVALS_V3) or sp > n_ticks * npix
                or nbytes > _interval_data_limit(sp, npix) or recs > sp):
            raise ViformError(f"band {b} is invalid (model {model}, {nbytes} bytes, {sp} spikes, {recs} records)")
        table.append((model, nbytes, sp, recs))
    spans = []
    total = 0
    for model, nbytes, sp, recs in table:
        spans.append((model, pos, nbytes, sp, recs))
        pos += nbytes
        total += sp
    _check_band_totals(payload, pos, total, spikes)
    buf = np.frombuffer(payload, np.uint8)
    end = start + n_ticks

    def one(b):
        r0, r1 = bands[b]
        p0, p1 = r0 * width, r1 * width
        model, off, nbytes, sp, recs = spans[b]
        data = buf[off:off + nbytes]
        counts = np.empty(p1 - p0, np.int64)
        st, probs, last = state.ivstate[p0:p1], state.ivprobs[b], state.last[p0:p1]
        if model != MODEL_RECORDS:
            why, ticks = _decode_intervals(data, counts, st, probs, last, start, end, width, sp, _PREDICTOR[model])
        else:
            why, ticks = _decode_records(data, counts, last, state.ref[p0:p1], start, end, width, sp, recs)
        return why, model, counts, ticks

    parts = _map(one, len(bands))
    for b, (why, _, _, _) in enumerate(parts):
        if why:
            raise ViformError(f"segment at tick {start}, band {b} is damaged ({why})")
    for (r0, r1), (_, model, counts, ticks) in zip(bands, parts, strict=True):
        _advance(state, r0 * width, r1 * width, model, counts, ticks)
    return TickSegment(start, n_ticks, np.concatenate([p[2] for p in parts]), np.concatenate([p[3] for p in parts]))
