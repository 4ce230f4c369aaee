"""First-spike coding of a viform (seed 000 §5.2, Fig. 1(d)), in three modes.

Per pixel the spike train is cut into *runs*: a run starts with a **first spike** — a spike
whose width τ (ticks since the pixel's previous spike) differs from the current width — and
continues with the spikes that repeat that width. Only first spikes are output, as
(t, τ) pairs (seed 000 §5.2); "no output means repeat". The stream's first spike of a pixel
is always a first spike; its width is measured from the start of the stream (tick −1, the
partial first interval, exactly as Fig. 1 measures pulse 1 "from the origin").

Modes
-----
``strict``
    A width is a repeat only when it is equal to the current width (in ticks). The
    decoded stream is bit-identical to the input.
``statistical``
    A width τᵢ is a repeat when |τᵢ − τ| ≤ k·τ/√Q + slack (seed 000 §5.1: the Gamma
    interval has RSD = 1/√Q, so smaller fluctuations carry no signal). Lossy.
``intensity``
    Intensity only (seed 000 §5.2, last paragraph): *transitional* first spikes — a first
    spike immediately followed by another first spike (pulses 5 and 12 of Fig. 1) — are
    dropped: they are absorbed as one more repeat of the run before them. The repeat rule
    is the strict one unless a tolerance k is given.

What is stored (exactly enough for strict losslessness)
-------------------------------------------------------
For each first spike a record ``(m, g, o)``: the previous run had ``m`` repeats spread
over ``g`` ticks after its first spike (strict: g = m·τ), then the new first spike comes
``o`` ticks after the previous run's last spike; its width τ = o. The decoder places the
m repeats evenly over g (``anchor + round(i·g/m)``), which for the strict mode is exactly
every τ ticks and for the lossy modes spreads the run at its mean width, keeping spike
counts and first-spike times exact. Time is cut into fixed *segments* of
``segment_ticks`` ticks; at each segment end every pixel stores a *tail* ``(m, g)`` — the
repeats of its open run inside the segment, the last one pinned at its true tick — so the
stream's end and the trailing spikes are exact and every segment decodes from the state
left by the previous one. The records and the file bytes depend only on the stream and
``segment_ticks``, never on the block size used to feed the encoder.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from viform._validate import ViformError, check_choice, check_int, check_non_negative, check_positive

#: Coding modes (seed 000 §5.1–§5.2).
MODES = ("strict", "statistical", "intensity")

#: Default tolerance factor k of the statistical mode (|Δτ| ≤ k·τ/√Q).
DEFAULT_K = 2.0

#: Largest tolerance factor k (a coded file's header may not state more).
MAX_K = 1e6

#: Default segment length, ticks.
DEFAULT_SEGMENT_TICKS = 4096

#: dtype of the first-spike quadruples (i, j, t, τ) of seed 000 §5.2 (t, τ in ticks).
QUAD_DTYPE = np.dtype([("i", np.int32), ("j", np.int32), ("t", np.int64), ("tau", np.int64)])


@dataclass(frozen=True)
class CodingParameters:
    """How first spikes are chosen.

    Attributes
    ----------
    mode : {"strict", "statistical", "intensity"}
    k : float
        Tolerance factor of the repeat rule, |Δτ| ≤ k·τ/√Q (statistical; intensity when > 0).
    threshold_electrons : float or None
        Q used for the tolerance; required for the statistical mode.
    slack_ticks : int
        Extra tolerance in ticks added to k·τ/√Q (tick quantization of the widths).
    segment_ticks : int
        Segment length of the coded stream.
    """

    mode: str = "strict"
    k: float = DEFAULT_K
    threshold_electrons: float | None = None
    slack_ticks: int = 0
    segment_ticks: int = DEFAULT_SEGMENT_TICKS

    def __post_init__(self):
        check_choice("mode", self.mode, MODES)
        check_non_negative("k", self.k)
        if self.k > MAX_K:
            raise ViformError(f"k = {self.k:g} is not allowed: it must be in [0, {MAX_K:g}] (standard deviations)")
        check_int("slack_ticks", self.slack_ticks, 0, 1 << 20)
        check_int("segment_ticks", self.segment_ticks, 1, 1 << 30)
        if self.threshold_electrons is not None:  # k/√Q: zero, negative or absurd Q has no tolerance
            from viform.stream.sidecar import MAX_THRESHOLD_ELECTRONS

            q = check_positive("threshold_electrons", self.threshold_electrons)
            if q > MAX_THRESHOLD_ELECTRONS:
                raise ViformError(f"threshold_electrons = {q:g} is not allowed: it must be in (0, "
                                  f"{MAX_THRESHOLD_ELECTRONS:g}] electrons")
        if self.mode == "statistical" and self.k > 0 and self.threshold_electrons is None:
            raise ViformError("the statistical mode needs the threshold Q (threshold_electrons) for its "
                              "tolerance k·τ/√Q; the stream does not say it: give --threshold")

    @property
    def relative_tolerance(self) -> float:
        """k/√Q (0 in strict mode, and in intensity mode unless Q is known)."""
        if self.mode == "strict" or self.threshold_electrons is None:
            return 0.0
        return self.k / math.sqrt(self.threshold_electrons)

    @property
    def slack(self) -> int:
        return 0 if self.mode == "strict" else int(self.slack_ticks)

    @property
    def drop_transitional(self) -> bool:
        return self.mode == "intensity"


# ---------------------------------------------------------------------------- kernels

@njit(cache=True, inline="always")
def _emit_pending(p, pend, pend_m, pend_g, pend_o, pend_ref, out_pix, out_m, out_g, out_o, out_ref, n_out):
    """Output pixel p's pending (intensity mode: held back) first-spike record; returns the new count."""
    out_pix[n_out] = p
    out_m[n_out] = pend_m[p]
    out_g[n_out] = pend_g[p]
    out_o[n_out] = pend_o[p]
    out_ref[n_out] = pend_ref[p]
    pend[p] = False
    return n_out + 1


@njit(cache=True)
def _encode_block(block, first_tick, rel_tol, slack, drop, last_spike, anchor, tau_ref, run_m,
                  pend, pend_m, pend_g, pend_o, pend_a0, pend_t, pend_ref,
                  out_pix, out_m, out_g, out_o, out_ref, n_out):
    """Run the first-spike rule over a block (n, P) of ticks; append records in time order.

    ``out_ref`` holds the current width before each record (the decoder's prediction
    context). Returns the new record count.
    """
    n, npix = block.shape
    for kk in range(n):
        s = first_tick + kk
        row = block[kk]
        for p in range(npix):
            if row[p] == 0:
                continue
            w = s - last_spike[p]
            ref = tau_ref[p]
            if ref > 0 and abs(w - ref) <= rel_tol * ref + slack:
                run_m[p] += 1
                if pend[p]:  # the pending first spike is followed by a repeat: not transitional
                    n_out = _emit_pending(p, pend, pend_m, pend_g, pend_o, pend_ref, out_pix, out_m, out_g,
                                          out_o, out_ref, n_out)
            else:
                if pend[p]:
                    # the pending first spike was transitional (a repeat would have flushed it, so its
                    # run is empty): absorb it as one more repeat of the run before
                    pend_m[p] += 1
                    pend_g[p] = pend_t[p] - pend_a0[p]
                    pend_o[p] = s - pend_t[p]
                    pend_t[p] = s
                else:
                    g = last_spike[p] - anchor[p] if run_m[p] > 0 else 0
                    if drop and ref > 0:
                        pend[p] = True
                        pend_m[p] = run_m[p]
                        pend_g[p] = g
                        pend_o[p] = w
                        pend_a0[p] = anchor[p]
                        pend_t[p] = s
                        pend_ref[p] = ref
                    else:
                        out_pix[n_out] = p
                        out_m[n_out] = run_m[p]
                        out_g[n_out] = g
                        out_o[n_out] = w
                        out_ref[n_out] = ref
                        n_out += 1
                anchor[p] = s
                tau_ref[p] = w
                run_m[p] = 0
            last_spike[p] = s
    return n_out


@njit(cache=True)
def _flush_pending(pend, pend_m, pend_g, pend_o, pend_ref, out_pix, out_m, out_g, out_o, out_ref, n_out):
    for p in range(pend.size):
        if pend[p]:
            n_out = _emit_pending(p, pend, pend_m, pend_g, pend_o, pend_ref, out_pix, out_m, out_g, out_o,
                                  out_ref, n_out)
    return n_out


@njit(cache=True)
def _close_segment(last_spike, anchor, tau_ref, run_m, tail_m, tail_g, tail_ref):
    """Tails of the open runs at a segment end; the run is pinned at its last spike."""
    for p in range(anchor.size):
        tail_ref[p] = tau_ref[p]
        if run_m[p] > 0:
            tail_m[p] = run_m[p]
            tail_g[p] = last_spike[p] - anchor[p]
            anchor[p] = last_spike[p]
            run_m[p] = 0
        else:
            tail_m[p] = 0
            tail_g[p] = 0


@njit(cache=True, nogil=True)
def _check_segment(counts, rec_m, rec_g, rec_o, tail_m, tail_g, anchor, tau_ref, seg_start, seg_end):
    """Validate a segment's records against the decoder state; advance the state.

    Returns (error code, spikes in segment). Codes: 0 ok, 1 negative or inconsistent m/g,
    2 repeats without a width, 3 spike before the segment, 4 spike after the segment,
    5 bad offset, 6 record count overflow.
    """
    r = 0
    nrec = rec_m.size
    spikes = 0
    for p in range(counts.size):
        a = anchor[p]
        ref = tau_ref[p]
        c = counts[p]
        if c < 0 or r + c > nrec:
            return 6, spikes
        for q in range(c + 1):
            if q < c:
                m = rec_m[r]
                g = rec_g[r]
            else:
                m = tail_m[p]
                g = tail_g[p]
            if m < 0 or g < m or (m == 0 and g != 0) or g > (1 << 40) or ref > (1 << 40):
                return 1, spikes
            if m > 0:
                if ref <= 0:
                    return 2, spikes
                if a + g - max(a, seg_start - 1) < m:
                    return 3, spikes
                if a + g >= seg_end:
                    return 4, spikes
                spikes += m
            if q < c:
                o = rec_o[r]
                if o < 1 or o > (1 << 40):
                    return 5, spikes
                t = a + g + o
                if t < seg_start:
                    return 3, spikes
                if t >= seg_end:
                    return 4, spikes
                a = t
                ref = o
                spikes += 1
                r += 1
            else:
                a = a + g
        anchor[p] = a
        tau_ref[p] = ref
    if r != nrec:
        return 6, spikes
    return 0, spikes


@njit(cache=True)
def _decode_block(out, seg_start, a_tick, b_tick, rec_start, counts, rec_m, rec_g, rec_o, tail_m, tail_g,
                  anchor, tau_ref, cur_rec, cur_rep, stage):
    """Write the spikes of ticks [a_tick, b_tick) of a validated segment into ``out`` (n, P).

    Per-pixel cursors (record index, next repeat, stage 0 records / 1 tail / 2 done) make
    the segment decodable in any sub-blocks with the same result.
    """
    npix = counts.size
    for p in range(npix):
        a = anchor[p]
        while stage[p] < 2:
            r = cur_rec[p]
            in_rec = r < rec_start[p] + counts[p]
            if in_rec:
                m = rec_m[r]
                g = rec_g[r]
            else:
                m = tail_m[p]
                g = tail_g[p]
            i = cur_rep[p]
            stop = False
            base = a
            span = g
            if m > 0 and a + (2 * g + m) // (2 * m) < seg_start:
                # a lossy run carried over from the previous segment: spread it inside this one
                base = seg_start - 1
                span = a + g - base
            while i <= m:
                t = base + (2 * i * span + m) // (2 * m)
                if t >= b_tick:
                    stop = True
                    break
                out[t - a_tick, p] = 1
                i += 1
            cur_rep[p] = i
            if stop:
                break
            if in_rec:
                t = a + g + rec_o[r]
                if t >= b_tick:
                    break
                out[t - a_tick, p] = 1
                a = t
                tau_ref[p] = rec_o[r]
                cur_rec[p] = r + 1
                cur_rep[p] = 1
            else:
                a = a + g
                stage[p] = 2
        anchor[p] = a


# ---------------------------------------------------------------------------- encoder

@dataclass
class Segment:
    """The records of one segment, grouped by pixel in time order.

    ``counts[p]`` records per pixel; ``m, g, o, ref`` per record (``ref``: the pixel's width
    before the record, the prediction context); ``tail_m, tail_g, tail_ref`` per pixel.
    """

    start_tick: int
    n_ticks: int
    counts: np.ndarray
    m: np.ndarray
    g: np.ndarray
    o: np.ndarray
    ref: np.ndarray
    tail_m: np.ndarray
    tail_g: np.ndarray
    tail_ref: np.ndarray

    @property
    def n_records(self) -> int:
        return int(self.m.size)

    @property
    def n_spikes(self) -> int:
        return int(self.m.sum() + self.m.size + self.tail_m.sum())


class FirstSpikeEncoder:
    """Streaming first-spike encoder: feed blocks of ticks, get whole segments back.

    Parameters
    ----------
    n_pixels : int
    params : CodingParameters

    Examples
    --------
    >>> enc = FirstSpikeEncoder(4, CodingParameters())
    >>> segs = enc.push(np.zeros((10, 4), bool)) + enc.finish()
    >>> sum(s.n_spikes for s in segs)
    0
    """

    def __init__(self, n_pixels: int, params: CodingParameters):
        self.n_pixels = check_int("n_pixels", n_pixels, 1)
        self.params = params
        n = self.n_pixels
        self.last_spike = np.full(n, -1, np.int64)
        self.anchor = np.full(n, -1, np.int64)
        self.tau_ref = np.zeros(n, np.int64)
        self.run_m = np.zeros(n, np.int64)
        self.pend = np.zeros(n, np.bool_)
        self.pend_m = np.zeros(n, np.int64)
        self.pend_g = np.zeros(n, np.int64)
        self.pend_o = np.zeros(n, np.int64)
        self.pend_a0 = np.zeros(n, np.int64)
        self.pend_t = np.zeros(n, np.int64)
        self.pend_ref = np.zeros(n, np.int64)
        self.next_tick = 0
        self.segment_start = 0
        self._parts: list[tuple[np.ndarray, ...]] = []
        self.total_spikes = 0

    def push(self, block) -> list[Segment]:
        """Encode the next ticks (bool (n, P) or (n, H, W)); returns the segments completed."""
        block = np.asarray(block)
        block = block.reshape(block.shape[0], -1)
        if block.shape[1] != self.n_pixels:
            raise ViformError(f"block has {block.shape[1]} pixels; the encoder was made for {self.n_pixels}")
        block = np.ascontiguousarray(block.astype(np.bool_, copy=False)).view(np.uint8)
        done = []
        seg = self.params.segment_ticks
        pos = 0
        while pos < block.shape[0]:
            seg_end = self.segment_start + seg
            take = min(block.shape[0] - pos, seg_end - self.next_tick)
            self._encode(block[pos:pos + take])
            pos += take
            if self.next_tick == seg_end:
                done.append(self._close())
        return done

    def finish(self) -> list[Segment]:
        """Close the last (partial) segment."""
        if self.next_tick > self.segment_start:
            return [self._close()]
        return []

    def _encode(self, block):
        cap = int(np.count_nonzero(block)) + 1
        pix = np.empty(cap, np.int32)
        m, g, o, ref = (np.empty(cap, np.int64) for _ in range(4))
        p = self.params
        n = _encode_block(block, self.next_tick, p.relative_tolerance, p.slack, p.drop_transitional,
                          self.last_spike, self.anchor, self.tau_ref, self.run_m, self.pend, self.pend_m,
                          self.pend_g, self.pend_o, self.pend_a0, self.pend_t, self.pend_ref,
                          pix, m, g, o, ref, 0)
        self._parts.append((pix[:n], m[:n], g[:n], o[:n], ref[:n]))
        self.next_tick += block.shape[0]

    def _close(self) -> Segment:
        cap = int(self.pend.sum()) + 1
        pix = np.empty(cap, np.int32)
        m, g, o, ref = (np.empty(cap, np.int64) for _ in range(4))
        n = _flush_pending(self.pend, self.pend_m, self.pend_g, self.pend_o, self.pend_ref, pix, m, g, o, ref, 0)
        self._parts.append((pix[:n], m[:n], g[:n], o[:n], ref[:n]))
        cols = [np.concatenate([part[i] for part in self._parts]) for i in range(5)]
        self._parts = []
        order = np.argsort(cols[0], kind="stable")
        pix, m, g, o, ref = (c[order] for c in cols)
        counts = np.bincount(pix, minlength=self.n_pixels).astype(np.int64)
        tail_m = np.empty(self.n_pixels, np.int64)
        tail_g = np.empty(self.n_pixels, np.int64)
        tail_ref = np.empty(self.n_pixels, np.int64)
        _close_segment(self.last_spike, self.anchor, self.tau_ref, self.run_m, tail_m, tail_g, tail_ref)
        segment = Segment(self.segment_start, self.next_tick - self.segment_start, counts, m, g, o, ref,
                          tail_m, tail_g, tail_ref)
        self.total_spikes += segment.n_spikes
        self.segment_start = self.next_tick
        return segment


# ---------------------------------------------------------------------------- decoder

class FirstSpikeDecoder:
    """Regenerate the spike stream from segments (in order), block by block."""

    def __init__(self, n_pixels: int):
        self.n_pixels = check_int("n_pixels", n_pixels, 1)
        self.anchor = np.full(self.n_pixels, -1, np.int64)
        self.tau_ref = np.zeros(self.n_pixels, np.int64)
        self.next_tick = 0

    def check(self, segment: Segment, advance: bool = False) -> int:
        """Validate ``segment`` against the current state; returns its spike count.

        With ``advance`` the state moves past the segment (as if decoded, without output).
        """
        if segment.start_tick != self.next_tick:
            raise ViformError(f"segment starts at tick {segment.start_tick}, expected {self.next_tick}")
        if segment.counts.size != self.n_pixels or segment.tail_m.size != self.n_pixels:
            raise ViformError("segment does not match the number of pixels")
        if int(segment.counts.sum()) != segment.m.size:
            raise ViformError("segment record counts do not add up")
        a, r = self.anchor.copy(), self.tau_ref.copy()
        err, spikes = _check_segment(segment.counts, segment.m, segment.g, segment.o, segment.tail_m,
                                     segment.tail_g, a, r, segment.start_tick,
                                     segment.start_tick + segment.n_ticks)
        if err:
            raise ViformError(f"segment at tick {segment.start_tick} is inconsistent ({_ERRORS[err]})")
        if advance:
            self.anchor, self.tau_ref = a, r
            self.next_tick = segment.start_tick + segment.n_ticks
        return spikes

    def decode(self, segment: Segment, block_ticks: int | None = None):
        """Yield ``(first_tick, bool (n, P))`` blocks covering the segment."""
        self.check(segment)
        rec_start = np.zeros(self.n_pixels, np.int64)
        np.cumsum(segment.counts[:-1], out=rec_start[1:])
        cur_rec = rec_start.copy()
        cur_rep = np.ones(self.n_pixels, np.int64)
        stage = np.zeros(self.n_pixels, np.int64)
        block_ticks = segment.n_ticks if block_ticks is None else block_ticks
        start, end = segment.start_tick, segment.start_tick + segment.n_ticks
        for a in range(start, end, block_ticks):
            b = min(a + block_ticks, end)
            out = np.zeros((b - a, self.n_pixels), np.uint8)
            _decode_block(out, start, a, b, rec_start, segment.counts, segment.m, segment.g, segment.o,
                          segment.tail_m, segment.tail_g, self.anchor, self.tau_ref, cur_rec, cur_rep, stage)
            yield a, out.view(np.bool_)
        self.next_tick = end


_ERRORS = {1: "negative or inconsistent repeat count/span", 2: "repeats before any width",
           3: "a spike before the segment start", 4: "a spike after the segment end",
           5: "bad first-spike offset", 6: "record count mismatch"}


# ---------------------------------------------------------------------------- conveniences

def encode_array(spikes, params: CodingParameters | None = None, block_ticks: int = 1024) -> list[Segment]:
    """First-spike segments of an in-memory bool array (T, H, W) or (T, P).

    Parameters
    ----------
    spikes : ndarray of bool (T, H, W) or (T, P)
        One frame of spikes per tick.
    params : CodingParameters, optional
        Mode and tolerances (default: strict, lossless).
    block_ticks : int
        Ticks fed to the encoder at a time.

    Returns
    -------
    list of Segment
        The coded segments, in time order.
    """
    spikes = np.asarray(spikes)
    params = params or CodingParameters()
    enc = FirstSpikeEncoder(int(np.prod(spikes.shape[1:])), params)
    segs = []
    for a in range(0, spikes.shape[0], block_ticks):
        segs += enc.push(spikes[a:a + block_ticks])
    return segs + enc.finish()


def decode_segments(segments, shape) -> np.ndarray:
    """Bool array of ``shape`` (T, H, W) or (T, P) regenerated from segments.

    Parameters
    ----------
    segments : sequence of Segment
        Segments of :func:`encode_array` (or a coded file).
    shape : tuple of int
        (T, H, W) or (T, P) of the array to regenerate.

    Returns
    -------
    ndarray of bool
        The spikes; in strict mode, bit-identical to the coded array.
    """
    n_pixels = int(np.prod(shape[1:]))
    dec = FirstSpikeDecoder(n_pixels)
    out = np.zeros((shape[0], n_pixels), bool)
    for seg in segments:
        for a, blk in dec.decode(seg):
            out[a:a + blk.shape[0]] = blk
    return out.reshape(shape)


def first_spikes(spikes, mode: str = "strict", *, k: float = DEFAULT_K, threshold_electrons: float | None = None,
                 slack_ticks: int = 0, segment_ticks: int = DEFAULT_SEGMENT_TICKS) -> np.ndarray:
    """The first-spike quadruples (i, j, t, τ) of a stream (seed 000 §5.2), sorted by time then pixel.

    ``spikes`` is a bool array (T, H, W) (or (T, W) for one row) or a SpikeSource. t is the
    tick of the first spike, τ its width in ticks (for a pixel's first spike: t + 1, the
    interval from the start of the stream).

    Parameters
    ----------
    spikes : ndarray of bool or SpikeSource
        The stream.
    mode : {"strict", "statistical", "intensity"}
        The repeat rule (:class:`CodingParameters`).
    k : float
        Tolerance factor of the repeat rule, |Δτ| ≤ k·τ/√Q.
    threshold_electrons : float, optional
        Q, e⁻, used for the tolerance; required for the statistical mode.
    slack_ticks : int
        Extra tolerance, ticks, added to k·τ/√Q.
    segment_ticks : int
        Segment length, ticks.

    Returns
    -------
    ndarray of QUAD_DTYPE
        Fields ``i``, ``j`` (row, column), ``t`` (tick) and ``tau`` (width, ticks).

    Examples
    --------
    The seed's Fig. 1: widths 4,4,4,4, 3, 2×6, 3, 4,4 → first spikes 1, 5, 6, 12, 13.

    >>> w = [4, 4, 4, 4, 3, 2, 2, 2, 2, 2, 2, 3, 4, 4]
    >>> train = np.zeros(sum(w), bool); train[np.cumsum(w) - 1] = True
    >>> q = first_spikes(train[:, None, None])
    >>> [int(np.searchsorted(np.cumsum(w) - 1, t)) + 1 for t in q["t"]]
    [1, 5, 6, 12, 13]
    """
    from viform.stream.container import SpikeSource

    params = CodingParameters(mode, k, threshold_electrons, slack_ticks, segment_ticks)
    if isinstance(spikes, SpikeSource):
        h, w = spikes.height, spikes.width
        enc = FirstSpikeEncoder(h * w, params)
        segs = []
        for _, blk in spikes.iter_blocks(1024):
            segs += enc.push(blk)
        segs += enc.finish()
    else:
        spikes = np.asarray(spikes)
        if spikes.ndim == 2:
            spikes = spikes[:, None, :]
        if spikes.ndim != 3:
            raise ViformError(f"spikes must have shape (T, H, W); got {spikes.shape}")
        h, w = spikes.shape[1:]
        segs = encode_array(spikes, params)
    return quadruples(segs, h, w)


def quadruples(segments, height: int, width: int) -> np.ndarray:
    """(i, j, t, τ) of the first spikes held by ``segments`` (time order, then pixel)."""
    n = height * width
    dec_anchor = np.full(n, -1, np.int64)
    parts = []
    for seg in segments:
        pix = np.repeat(np.arange(n), seg.counts)
        t = np.empty(seg.m.size, np.int64)
        _first_times(seg.counts, seg.g, seg.o, seg.tail_g, dec_anchor, t)
        q = np.empty(seg.m.size, QUAD_DTYPE)
        q["i"], q["j"] = np.divmod(pix, width)
        q["t"], q["tau"] = t, seg.o
        parts.append(q)
    q = np.concatenate(parts) if parts else np.empty(0, QUAD_DTYPE)
    return q[np.lexsort((q["j"], q["i"], q["t"]))]


@njit(cache=True)
def _first_times(counts, rec_g, rec_o, tail_g, anchor, t_out):
    r = 0
    for p in range(counts.size):
        a = anchor[p]
        for _ in range(counts[p]):
            a = a + rec_g[r] + rec_o[r]
            t_out[r] = a
            r += 1
        anchor[p] = a + tail_g[p]
