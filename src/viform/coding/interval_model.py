"""Per-pixel interval prediction for lossless (strict) coding of spike streams (``.vfc`` version 3).

A spike pixel integrates photo-charge and fires each time it holds Q electrons (seed 000
§3.1, eq. (1)); its spike *times* are the crossing times of a continuous charge clock,
rounded down to the readout tick (seed 000 §4.3: τ̌ is the readout period). Under steady
light the crossings come every μ = Q/(I·η) seconds with a relative spread 1/√Q (the Gamma
interval, seed 000 §5.1), so the tick intervals of a steady pixel take the values ⌊μ⌋ and
⌈μ⌉ in the pattern of the fractional part of μ (successive intervals are anti-correlated,
ρ ≈ −0.5, because rounding error left in one interval is taken back by the next). Coding
each interval as a fresh number ignores all of that; this module instead keeps, per pixel,
a *phase-locked* estimate of the continuous crossing clock and codes each spike's tick as
the residual from its prediction:

* state per pixel (carried from segment to segment, in fixed point, 16 fractional bits):
  the interval estimate μ̂, the phase φ ∈ [0, 1) of the last crossing inside its tick,
  the mean absolute residual (the pixel's own noise level, which is μ/√Q in ticks for a
  shot-noise limited pixel) and the last residual's sign;
* prediction of the next spike tick: t_last + ⌊φ + μ̂⌋; the fractional part of φ + μ̂
  (where the predicted crossing lies inside its tick) is the main context of the
  "residual = 0?" decision — near a tick boundary the spike may fall either side;
* after a spike the phase is the prediction projected into the observed tick, μ̂ moves
  by a fraction of the phase error (a phase-locked loop: fast while the lock is new or
  the errors keep one sign, slow when they alternate), and a residual far beyond the
  pixel's noise (a change of the light) restarts the estimate at the observed interval;
* a pixel that fires for the first time in a segment codes its first full interval
  against the mean interval of its neighbours (left, up, up-right, right, down — whose
  state the decoder already holds), then its first spike's phase as a uniform value
  below that interval (log₂ τ₁ bits);
* per pixel, "another spike in this segment?" is one binary decision whose context is
  where the predicted spike lies relative to the segment end.

Pixels are coded in row-major order, each with all its spikes of the segment. Every value
is coded with the adaptive binary range coder of :mod:`viform.coding.context_model`.
Decoding is bounded: every interval must lie inside the segment, the spike count may not
exceed what the segment states, and running out of data is an error.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from viform.coding._range_coder import (
    decode_bit,
    decode_plain,
    decode_uniform,
    decoder_start,
    encode_bit,
    encode_plain,
    encode_uniform,
    encoder_flush,
    encoder_start,
)
from viform.coding.context_model import _EG, _RB, _rbucket

# Probabilities: per binary context a 16-bit P(bit = 0) and a count; the estimate moves by
# 1/(count + 1.5) of the error (the running frequency while a context is young), down to
# 1/(_LIMIT + 1.5) (then it follows slow drifts of the stream).
_PB = 16
_PMAX = (1 << _PB) - 32
_LIMIT = 30
_RECIP = np.array([int(65536 / (n + 1.5)) for n in range(_LIMIT + 1)], np.int64)
_MAXBITS = 40


@njit(cache=True, inline="always")
def _adapt(probs, i, bit):
    p = probs[2 * i]
    n = probs[2 * i + 1]
    target = 0 if bit else 65536
    p += ((target - p) * _RECIP[n]) >> 16
    probs[2 * i] = min(max(p, np.int64(32)), np.int64(_PMAX))
    if n < _LIMIT:
        probs[2 * i + 1] = n + 1


@njit(cache=True, inline="always")
def _ebit(rc, out, probs, i, bit):
    rc = encode_bit(rc, out, probs[2 * i], _PB, bit)
    _adapt(probs, i, bit)
    return rc


@njit(cache=True, inline="always")
def _dbit(rc, data, probs, i):
    bit, rc = decode_bit(rc, data, probs[2 * i], _PB)
    _adapt(probs, i, bit)
    return bit, rc


@njit(cache=True)
def _euint(rc, out, probs, base, v):
    """Adaptive Elias-gamma code of v ≥ 0 (v < 2**40): unary length, two modelled mantissa bits."""
    x = v + 1
    n = 0
    while (x >> (n + 1)) > 0:
        n += 1
    for i in range(n):
        rc = _ebit(rc, out, probs, base + min(i, 23), 1)
    rc = _ebit(rc, out, probs, base + min(n, 23), 0)
    node = 1
    nb = min(n, 23)
    for k in range(n - 1, -1, -1):
        bit = (x >> k) & 1
        if n - 1 - k < 2:
            rc = _ebit(rc, out, probs, base + 24 + nb * 3 + node - 1, bit)
            node = node * 2 + bit if node == 1 else node
        else:
            rc = encode_plain(rc, out, bit)
    return rc


@njit(cache=True)
def _duint(rc, data, probs, base):
    """Inverse of :func:`_euint`: ``(v, state)``; over-long codes set the state's error flag."""
    n = 0
    while True:
        bit, rc = _dbit(rc, data, probs, base + min(n, 23))
        if bit == 0:
            break
        n += 1
        if n > _MAXBITS:
            return np.int64(0), (rc[0], rc[1], rc[2], np.int64(1))
    x = np.int64(1)
    node = 1
    nb = min(n, 23)
    for k in range(n - 1, -1, -1):
        if n - 1 - k < 2:
            bit, rc = _dbit(rc, data, probs, base + 24 + nb * 3 + node - 1)
            node = node * 2 + bit if node == 1 else node
        else:
            bit, rc = decode_plain(rc, data)
        x = (x << 1) | bit
    return x - 1, rc


_FB = 16  # fractional bits of the fixed-point state
_ONE = np.int64(1) << _FB
_NBITS = 6  # flags: intervals since the lock began (saturating), then the last residual's sign
_NMASK = (1 << _NBITS) - 1
_SHMAX = 6
_INSET = _ONE >> 4  # a phase pushed out of its tick is put back this far inside

#: per-pixel state (an int64 array (P, 7)): μ̂, φ, mean |residual|, flags (lock age | last sign), the
#: last three intervals
STATE_ROWS = 7

# context sizes
_NS = 7  # noise buckets
_NR = 8  # stop-decision buckets (remaining − predicted)
_NT = 12  # neighbour context (version 3: trend −2..2, unknown; version 4: 12 values)
_NZ = 8 * _NS * 5 * 3 * 3 * _NT  # residual = 0 / sign contexts

_P_NEW = 0  # 2: pixel that never fired: fires in this segment? (left neighbour fired)
_P_TWO = _P_NEW + 2  # _RB + 1: a second spike in the segment?
_P_FWS = _P_TWO + _RB + 1  # _RB + 1: sign of the first-width residual
_P_FW = _P_FWS + _RB + 1  # (_RB + 1)·EG: first-width residual magnitude
_P_PHB = _P_FW + (_RB + 1) * _EG  # 1: phase below the first width?
_P_PH = _P_PHB + 1  # (_RB + 1)·EG: phase (one spike only, or escape)
_P_COLD = _P_PH + (_RB + 1) * _EG  # 2: another spike? (no interval known)
_P_COLDV = _P_COLD + 2  # EG: interval of a pixel with no interval known
_P_STOP = _P_COLDV + _EG  # _NR·_NS·2
_P_Z = _P_STOP + _NR * _NS * 2  # _NZ
_P_SG = _P_Z + _NZ  # _NZ
_P_ONE = _P_SG + _NZ  # _NS·2·5·_NT
_P_MAG = _P_ONE + _NS * 2 * 5 * _NT  # _NS·2·_RB·EG
#: probabilities of the model (the caller keeps them from segment to segment)
NPROB = _P_MAG + _NS * 2 * _RB * _EG

ERRORS = {1: "value out of range", 2: "more spikes than the segment states", 3: "a spike outside the segment",
          4: "stream is cut short", 5: "spike count differs from the header"}


def new_probabilities() -> np.ndarray:
    """The model's adaptive probabilities at the start of a stream (p = ½ everywhere)."""
    probs = np.zeros(2 * NPROB, np.int64)
    probs[0::2] = 1 << (_PB - 1)
    return probs


# ---------------------------------------------------------------------------- model

@njit(cache=True, inline="always")
def _sbucket(mad):
    # mean |residual| in ticks: < 1/16, 1/8, 1/4, 1/2, 1, 2, ≥ 2
    b = 0
    lim = _ONE >> 4
    while b < _NS - 1 and mad >= lim:
        b += 1
        lim <<= 1
    return b


@njit(cache=True, inline="always")
def _predict(mu, ph, lo):
    """Predicted interval (≥ lo) and the fraction (eighths) of the predicted crossing inside its tick."""
    x = ph + mu
    p = x >> _FB
    f = (x & (_ONE - 1)) >> (_FB - 3)
    if p < lo:
        p = lo
        f = 0
    return p, f


@njit(cache=True, inline="always")
def _update(st, q, iv, p, model):
    """Advance pixel q's state after an interval iv that was predicted as p.

    Version 4 restarts on smaller surprises (3·mean|residual| + 1 tick, was 4· + 2) and its loop
    settles at gain 1/32 (was 1/64): it follows moving scenes faster (−7 % bits on a texture moving
    400 px/s at Q = 10⁴ e⁻, +1 % on static shot-noise-limited pixels at Q = 100 e⁻).
    """
    mu = st[q, 0]
    ph = st[q, 1]
    mad = st[q, 2]
    fl = st[q, 3]
    st[q, 6] = st[q, 5]
    st[q, 5] = st[q, 4]
    st[q, 4] = min(iv, np.int64(1) << 40)
    n = fl & _NMASK
    last = fl >> _NBITS
    r = iv - p
    x = ph + mu  # predicted crossing, relative to the previous spike tick
    ar = r if r >= 0 else -r
    if n == 0:
        st[q, 0] = iv << _FB
        st[q, 1] = _ONE >> 1
        st[q, 2] = _ONE >> 1
        st[q, 3] = 1
        return
    if ar >= 2 and ((ar << _FB) > 3 * mad + _ONE if model >= 4 else (ar << _FB) > 4 * mad + (_ONE << 1)):
        # the light changed: restart at the observed interval
        st[q, 0] = iv << _FB
        st[q, 1] = _ONE >> 1
        st[q, 2] = mad + (((ar << _FB) - mad) >> 2)
        st[q, 3] = 1 | (3 << _NBITS)
        return
    lo = iv << _FB
    hi = lo + _ONE - 1
    xn = x
    if xn < lo:
        xn = lo + _INSET
    elif xn > hi:
        xn = hi - _INSET
    err = xn - x
    # loop gain 1/2, 1/4, ... while the lock is young (the running mean of the phase errors), then
    # 1/2^_SHMAX; errors of ≥ 2 ticks of one sign twice running mean the light drifts: follow faster
    shmax = _SHMAX - 1 if model >= 4 else _SHMAX
    sh = 1
    while sh < shmax and (2 << sh) <= n + 1:
        sh += 1
    sgn = 0 if r == 0 else (1 if r > 0 else 2)
    if sgn != 0 and sgn == last and ar >= 2:
        sh = max(sh - 2, 1)
    mu = mu + (err >> sh) if err >= 0 else mu - ((-err) >> sh)
    if mu < _ONE:
        mu = _ONE
    st[q, 0] = mu
    st[q, 1] = xn - lo
    st[q, 2] = mad + (((ar << _FB) - mad) >> 4)
    st[q, 3] = min(n + 1, _NMASK) | (sgn << _NBITS)


@njit(cache=True, inline="always")
def _stop_ctx(rem, p, sb):
    d = rem - p
    b = min(max(d, -3), 4) + 3
    return _P_STOP + (b * _NS + sb) * 2 + (1 if d > 2 * p else 0)


@njit(cache=True, inline="always")
def _clip(x, lo, hi):
    return min(max(x, lo), hi)


@njit(cache=True, inline="always")
def _nb_iv(n, tau, starts, counts, ticks, last0, ptr, slot):
    """Interval of neighbour n holding tick tau (−1: not known yet); ptr[slot] follows tau."""
    lo = starts[n]
    hi = lo + counts[n]
    k = min(max(ptr[slot], lo), hi)
    while k < hi and ticks[k] <= tau:
        k += 1
    while k > lo and ticks[k - 1] > tau:
        k -= 1
    ptr[slot] = k
    if k >= hi:
        return np.int64(-1)
    prev = ticks[k - 1] if k > lo else last0[n]
    if prev < 0:
        return np.int64(-1)
    return ticks[k] - prev


@njit(cache=True, inline="always")
def _trend(model, q, width, a, tp, starts, counts, ticks, last0, ptr):
    """What the already-coded neighbours (left, up) say about the next interval (a context, 0.._NT-1).

    Version 3: how their intervals changed from tick a to the predicted tick tp (0..4, 5 unknown).
    Version 4: their intervals at tp minus this pixel's predicted interval, summed over both
    (−4..4 → 0..8), or one neighbour only: 9 (same) / 10 (differs), 11 unknown — a neighbour
    under nearly the same light fires at nearly the same rate (an edge reaches both alike).
    """
    col = q % width
    tot = np.int64(0)
    have = 0
    if model >= 4:
        p = tp - a
        if col > 0:
            now = _nb_iv(q - 1, tp, starts, counts, ticks, last0, ptr, 1)
            if now > 0:
                tot += now - p
                have += 1
        if q >= width:
            now = _nb_iv(q - width, tp, starts, counts, ticks, last0, ptr, 3)
            if now > 0:
                tot += now - p
                have += 1
        if have == 0:
            return 11
        if have == 1:
            return 9 + (0 if tot == 0 else 1)
        return _clip(tot, -4, 4) + 4
    if col > 0:
        then = _nb_iv(q - 1, a, starts, counts, ticks, last0, ptr, 0)
        now = _nb_iv(q - 1, tp, starts, counts, ticks, last0, ptr, 1)
        if then > 0 and now > 0:
            tot += now - then
            have += 1
    if q >= width:
        then = _nb_iv(q - width, a, starts, counts, ticks, last0, ptr, 2)
        now = _nb_iv(q - width, tp, starts, counts, ticks, last0, ptr, 3)
        if then > 0 and now > 0:
            tot += now - then
            have += 1
    if have == 0:
        return 5
    return _clip(tot, -2, 2) + 2


@njit(cache=True, inline="always")
def _nb_at(lo, hi, prev0, tau, ticks, k):
    """A neighbour's interval holding tick tau (−1: not known) and the index k of its first spike after tau.

    The neighbour's spikes are ``ticks[lo:hi]``, its last spike before the segment ``prev0``;
    ``k`` is the index found for the previous tau of the same pixel (ticks rise: a short walk).
    """
    while k < hi and ticks[k] <= tau:
        k += 1
    while k > lo and ticks[k - 1] > tau:
        k -= 1
    if k >= hi:
        return np.int64(-1), k
    prev = ticks[k - 1] if k > lo else prev0
    if prev < 0:
        return np.int64(-1), k
    return ticks[k] - prev, k


@njit(cache=True, inline="always")
def _neighbour_spans(q, width, starts, counts, last0):
    """Pixel q's left and up neighbours: whether each exists, its spikes ``ticks[lo:hi]`` and its last
    spike before the segment (−1: none), as (has_left, has_up, llo, lhi, lp0, ulo, uhi, up0)."""
    has_left = q % width > 0
    has_up = q >= width
    llo = starts[q - 1] if has_left else 0
    lhi = llo + counts[q - 1] if has_left else 0
    lp0 = last0[q - 1] if has_left else -1
    ulo = starts[q - width] if has_up else 0
    uhi = ulo + counts[q - width] if has_up else 0
    up0 = last0[q - width] if has_up else -1
    return has_left, has_up, llo, lhi, lp0, ulo, uhi, up0


@njit(cache=True, inline="always")
def _neighbours4(has_left, has_up, p, tp, ticks, llo, lhi, lp0, ulo, uhi, up0, kl, ku):
    """Version-4 neighbour context (see :func:`_trend`); the left and up neighbours' spans are hoisted
    out of the spike loop (2× faster than looking them up per spike) and ``kl``, ``ku`` are their walks."""
    tot = np.int64(0)
    have = 0
    if has_left:
        now, kl = _nb_at(llo, lhi, lp0, tp, ticks, kl)
        if now > 0:
            tot += now - p
            have += 1
    if has_up:
        now, ku = _nb_at(ulo, uhi, up0, tp, ticks, ku)
        if now > 0:
            tot += now - p
            have += 1
    if have == 0:
        return 11, kl, ku
    if have == 1:
        return 9 + (0 if tot == 0 else 1), kl, ku
    return _clip(tot, -4, 4) + 4, kl, ku


@njit(cache=True, inline="always")
def _zctx(st, q, p, f, sb, tr):
    h1 = _clip(st[q, 4] - p, -2, 2) + 2
    h2 = _clip(st[q, 5] - p, -1, 1) + 1
    h3 = _clip(st[q, 6] - p, -1, 1) + 1
    return (((((f * _NS + sb) * 5 + h1) * 3 + h2) * 3 + h3) * _NT + tr), h1


@njit(cache=True)
def _nb_mu(st, q, width, npix):
    """Mean interval estimate (ticks, rounded) of the neighbours that have one; 0 if none."""
    row = q // width
    col = q - row * width
    tot = np.int64(0)
    cnt = 0
    for k in range(5):
        if k == 0:
            if col == 0:
                continue
            n = q - 1
        elif k == 1:
            if row == 0:
                continue
            n = q - width
        elif k == 2:
            if row == 0 or col + 1 >= width:
                continue
            n = q - width + 1
        elif k == 3:
            if col + 1 >= width:
                continue
            n = q + 1
        else:
            n = q + width
            if n >= npix:
                continue
        if (st[n, 3] & _NMASK) > 0:
            tot += st[n, 0]
            cnt += 1
    if cnt == 0:
        return np.int64(0)
    return (tot // cnt + (_ONE >> 1)) >> _FB


# ---------------------------------------------------------------------------- encoder

@njit(cache=True, nogil=True)
def encode_segment(counts, ticks, last0, st, probs, seg_start, seg_end, width, out, model):
    """Code one segment: per pixel (row-major) its spike ticks ``ticks`` (grouped by pixel, ``counts`` each).

    ``last0``: each pixel's last spike tick before the segment (−1: never fired); ``st``: the
    predictor state (P, STATE_ROWS) and ``probs`` the adaptive probabilities, both advanced in
    place; ``model``: the predictor, 3 (version 3's) or 4 (versions 4 and later), an int, always
    passed (numba compiles an omitted or literal argument as another specialisation).
    Returns the byte count (> out.size: retry bigger from copies of the state).
    """
    npix = counts.size
    rc = encoder_start()
    starts = np.zeros(npix + 1, np.int64)
    for q in range(npix):
        starts[q + 1] = starts[q] + counts[q]
    ptr = np.zeros(4, np.int64)
    for q in range(npix):
        c = counts[q]
        r = starts[q]
        a = last0[q]
        k = 0
        ptr[:] = 0
        has_left, has_up, llo, lhi, lp0, ulo, uhi, up0 = _neighbour_spans(q, width, starts, counts, last0)
        kl = llo
        ku = ulo
        if a < 0:
            col = q % width
            lf = 1 if (col > 0 and counts[q - 1] > 0) else 0
            rc = _ebit(rc, out, probs, _P_NEW + lf, 1 if c > 0 else 0)
            if c == 0:
                continue
            base = seg_start - 1
            phase = ticks[r] - base
            nb = _nb_mu(st, q, width, npix)
            fb = _RB if nb <= 0 else _rbucket(nb)
            two = c >= 2
            rc = _ebit(rc, out, probs, _P_TWO + fb, 1 if two else 0)
            if two:
                iv = ticks[r + 1] - ticks[r]
                e = iv - nb
                rc = _ebit(rc, out, probs, _P_FWS + fb, 1 if e < 0 else 0)
                rc = _euint(rc, out, probs, _P_FW + fb * _EG, e if e >= 0 else -e - 1)
                below = phase <= iv
                rc = _ebit(rc, out, probs, _P_PHB, 1 if below else 0)
                if below:
                    rc = encode_uniform(rc, out, phase - 1, iv)
                else:
                    rc = _euint(rc, out, probs, _P_PH + _rbucket(iv) * _EG, phase - iv - 1)
                st[q, 3] = 0
                _update(st, q, iv, iv, model)
                a = ticks[r + 1]
                k = 2
            else:
                rc = _euint(rc, out, probs, _P_PH + fb * _EG, phase - 1)
                st[q, 3] = 0
                a = ticks[r]
                k = 1
        while True:
            rem = seg_end - 1 - a
            lo = max(np.int64(1), seg_start - a)
            if rem < lo:
                break
            more = k < c
            fl = st[q, 3]
            if (fl & _NMASK) == 0:
                rc = _ebit(rc, out, probs, _P_COLD + (1 if a >= seg_start else 0), 1 if more else 0)
                if not more:
                    break
                iv = ticks[r + k] - a
                rc = _euint(rc, out, probs, np.int64(_P_COLDV), iv - lo)
                _update(st, q, iv, iv, model)
            else:
                p, f = _predict(st[q, 0], st[q, 1], lo)
                sb = _sbucket(st[q, 2])
                rc = _ebit(rc, out, probs, _stop_ctx(rem, p, sb), 1 if more else 0)
                if not more:
                    break
                iv = ticks[r + k] - a
                d = iv - p
                if model >= 4:
                    tr, kl, ku = _neighbours4(has_left, has_up, p, a + p, ticks, llo, lhi, lp0, ulo, uhi, up0,
                                              kl, ku)
                else:
                    tr = _trend(model, q, width, a, a + p, starts, counts, ticks, last0, ptr)
                zc, h1 = _zctx(st, q, p, f, sb, tr)
                rc = _ebit(rc, out, probs, _P_Z + zc, 1 if d == 0 else 0)
                if d != 0:
                    neg = 1 if d < 0 else 0
                    rc = _ebit(rc, out, probs, _P_SG + zc, neg)
                    ad = -d if neg else d
                    rc = _ebit(rc, out, probs, _P_ONE + ((sb * 2 + neg) * 5 + h1) * _NT + tr, 1 if ad == 1 else 0)
                    if ad > 1:
                        rc = _euint(rc, out, probs, _P_MAG + ((sb * 2 + neg) * _RB + _rbucket(p)) * _EG, ad - 2)
                _update(st, q, iv, p, model)
            a = a + iv
            k += 1
    return encoder_flush(rc, out)


# ---------------------------------------------------------------------------- decoder

@njit(cache=True, nogil=True)
def decode_segment(data, npix, last0, st, probs, seg_start, seg_end, width, n_spikes, counts, ticks, model):
    """Inverse of :func:`encode_segment`. Returns (error code, spikes decoded); arrays filled in place.

    ``data``: the coded bytes as a read-only uint8 array (``np.frombuffer`` of the payload), as every
    reader passes them: a writable array would be another compiled specialisation.

    ``ticks`` must hold the spikes: when it is full the code is 2 (the caller may grow it and
    decode again from copies of the state, or give up when the segment states fewer spikes).
    """
    rc = decoder_start(data)
    cap = min(n_spikes, ticks.size)
    starts = np.zeros(npix + 1, np.int64)
    ptr = np.zeros(4, np.int64)
    r = 0
    for q in range(npix):
        starts[q] = r
        counts[q] = 0
        ptr[:] = 0
        has_left, has_up, llo, lhi, lp0, ulo, uhi, up0 = _neighbour_spans(q, width, starts, counts, last0)
        kl = llo
        ku = ulo
        a = last0[q]
        if a < -1 or a >= seg_start:
            return 1, r
        c = 0
        if a < 0:
            col = q % width
            lf = 1 if (col > 0 and counts[q - 1] > 0) else 0
            fires, rc = _dbit(rc, data, probs, _P_NEW + lf)
            if fires == 0:
                if rc[2] > data.size + 8:
                    return 4, r
                continue
            base = seg_start - 1
            nb = _nb_mu(st, q, width, npix)
            fb = _RB if nb <= 0 else _rbucket(nb)
            two_bit, rc = _dbit(rc, data, probs, _P_TWO + fb)
            two = two_bit == 1
            if two:
                if r + 2 > cap:
                    return 2, r
                neg, rc = _dbit(rc, data, probs, _P_FWS + fb)
                mag, rc = _duint(rc, data, probs, _P_FW + fb * _EG)
                iv = nb - mag - 1 if neg else nb + mag
                if iv < 1 or iv >= seg_end - seg_start or rc[3]:
                    return 1, r
                below, rc = _dbit(rc, data, probs, _P_PHB)
                if below:
                    phase, rc = decode_uniform(rc, data, iv)
                    phase += 1
                else:
                    phase, rc = _duint(rc, data, probs, _P_PH + _rbucket(iv) * _EG)
                    phase += iv + 1
                t0 = base + phase
                if rc[3] or phase > seg_end or t0 + iv >= seg_end:
                    return 3, r
                ticks[r] = t0
                ticks[r + 1] = t0 + iv
                st[q, 3] = 0
                _update(st, q, iv, iv, model)
                a = t0 + iv
                c = 2
            else:
                if r + 1 > cap:
                    return 2, r
                phase, rc = _duint(rc, data, probs, _P_PH + fb * _EG)
                phase += 1
                if rc[3] or phase > seg_end - base - 1:
                    return 3, r
                ticks[r] = base + phase
                st[q, 3] = 0
                a = base + phase
                c = 1
        counts[q] = c
        while True:
            rem = seg_end - 1 - a
            lo = max(np.int64(1), seg_start - a)
            if rem < lo:
                break
            fl = st[q, 3]
            if (fl & _NMASK) == 0:
                more, rc = _dbit(rc, data, probs, _P_COLD + (1 if a >= seg_start else 0))
                if more == 0:
                    break
                iv, rc = _duint(rc, data, probs, np.int64(_P_COLDV))
                iv += lo
                if rc[3] or iv > rem:
                    return 3, r + c
                _update(st, q, iv, iv, model)
            else:
                p, f = _predict(st[q, 0], st[q, 1], lo)
                sb = _sbucket(st[q, 2])
                more, rc = _dbit(rc, data, probs, _stop_ctx(rem, p, sb))
                if more == 0:
                    break
                # the pixel's own spikes so far are visible to _trend only through its neighbours
                if model >= 4:
                    tr, kl, ku = _neighbours4(has_left, has_up, p, a + p, ticks, llo, lhi, lp0, ulo, uhi, up0,
                                              kl, ku)
                else:
                    tr = _trend(model, q, width, a, a + p, starts, counts, ticks, last0, ptr)
                zc, h1 = _zctx(st, q, p, f, sb, tr)
                zero, rc = _dbit(rc, data, probs, _P_Z + zc)
                if zero:
                    d = np.int64(0)
                else:
                    neg, rc = _dbit(rc, data, probs, _P_SG + zc)
                    one, rc = _dbit(rc, data, probs, _P_ONE + ((sb * 2 + neg) * 5 + h1) * _NT + tr)
                    if one:
                        ad = np.int64(1)
                    else:
                        ad, rc = _duint(rc, data, probs, _P_MAG + ((sb * 2 + neg) * _RB + _rbucket(p)) * _EG)
                        ad += 2
                    d = -ad if neg else ad
                iv = p + d
                if rc[3] or iv < lo or iv > rem:
                    return 3, r + c
                _update(st, q, iv, p, model)
            if r + c >= cap:
                return 2, r + c
            a = a + iv
            ticks[r + c] = a
            c += 1
            if rc[2] > data.size + 8:
                return 4, r + c
        counts[q] = c
        r += c
        if rc[2] > data.size + 8:
            return 4, r
    if r != n_spikes:
        return 5, r
    if rc[2] > data.size + 5:
        return 4, r
    return 0, r


# ---------------------------------------------------------------------------- records ↔ ticks

@njit(cache=True, nogil=True)
def ticks_from_records(counts, rec_m, rec_g, rec_o, tail_m, tail_g, anchor0, ref0, seg_start, tick_counts, ticks):
    """Spike ticks per pixel (grouped, time order) of a strict segment's first-spike records."""
    r = 0
    n = 0
    for p in range(counts.size):
        a = anchor0[p]
        ref = ref0[p]
        n0 = n
        for q in range(counts[p] + 1):
            if q < counts[p]:
                m = rec_m[r]
            else:
                m = tail_m[p]
            for _ in range(m):
                a += ref
                ticks[n] = a
                n += 1
            if q < counts[p]:
                a += rec_o[r]
                ref = rec_o[r]
                ticks[n] = a
                n += 1
                r += 1
        tick_counts[p] = n - n0
    return n


@njit(cache=True, nogil=True)
def records_from_ticks(tick_counts, ticks, anchor0, ref0, counts, rec_m, rec_g, rec_o, tail_m, tail_g):
    """Strict first-spike records of a segment from its spike ticks (the inverse of :func:`ticks_from_records`).

    Returns the record count.
    """
    r = 0
    n = 0
    for p in range(tick_counts.size):
        a = anchor0[p]
        ref = ref0[p]
        m = 0
        r0 = r
        for _ in range(tick_counts[p]):
            w = ticks[n] - a
            n += 1
            if ref > 0 and w == ref:
                m += 1
            else:
                rec_m[r] = m
                rec_g[r] = m * ref
                rec_o[r] = w
                r += 1
                m = 0
                ref = w
            a += w
        counts[p] = r - r0
        tail_m[p] = m
        tail_g[p] = m * ref
    return r


# ---------------------------------------------------------------------------- dense ↔ ticks (version 4 bands)

# de Bruijn table: the index of the lowest set bit of a 64-bit word
_DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
_LOWBIT = np.array([0, 1, 48, 2, 57, 49, 28, 3, 61, 58, 50, 42, 38, 29, 17, 4, 62, 55, 59, 36, 53, 51, 43, 22, 45,
                    39, 33, 30, 24, 18, 12, 5, 63, 47, 56, 27, 60, 41, 37, 16, 54, 35, 52, 21, 44, 32, 23, 11, 46,
                    26, 40, 15, 34, 20, 31, 10, 25, 14, 19, 9, 13, 8, 7, 6], np.int64)


@njit(cache=True, nogil=True)
def band_ticks(dense, row0, row1, seg_start):
    """Spike ticks of rows ``row0:row1`` of a segment's bool array ``dense`` (T, H, W), C-ordered.

    Returns ``counts`` (one per pixel of the band, row-major) and ``ticks`` (absolute ticks,
    grouped by pixel, in time order; ``seg_start`` is the tick of ``dense[0]``). Pixels are taken
    64 at a time: per tick, which of them fired is gathered into one word and only its set bits
    are visited (their 64 write cursors stay in cache).
    """
    n_ticks = dense.shape[0]
    width = dense.shape[2]
    npix = (row1 - row0) * width
    flat = dense.reshape(n_ticks, dense.shape[1] * width).view(np.uint8)
    p0 = row0 * width
    counts = np.zeros(npix, np.int64)
    for k in range(n_ticks):
        row = flat[k, p0:p0 + npix]
        for q in range(npix):
            counts[q] += row[q]
    cur = np.empty(npix, np.int64)
    total = np.int64(0)
    for q in range(npix):
        cur[q] = total
        total += counts[q]
    ticks = np.empty(total, np.int64)
    for g0 in range(0, npix, 64):
        n = min(npix - g0, 64)
        b = p0 + g0
        for k in range(n_ticks):
            row = flat[k]
            m = np.uint64(0)
            for j in range(n):
                m |= np.uint64(row[b + j]) << np.uint64(j)
            while m:
                low = m & (~m + np.uint64(1))
                q = g0 + _LOWBIT[np.int64((low * _DEBRUIJN) >> np.uint64(58))]
                ticks[cur[q]] = seg_start + k
                cur[q] += 1
                m ^= low
    return counts, ticks


@njit(cache=True, nogil=True)
def ticks_to_dense(counts, ticks, seg_start, out):
    """Fill ``out`` (T, P) bool — zeroed here — with the spikes of a segment given per pixel (grouped ticks)."""
    out[:] = False
    r = 0
    for q in range(counts.size):
        for _ in range(counts[q]):
            out[ticks[r] - seg_start, q] = True
            r += 1


@njit(cache=True, nogil=True)
def advance_last_ticks(counts, ticks, last):
    """Set ``last`` (per pixel) to each pixel's last spike tick of the segment, where it fired."""
    r = 0
    for q in range(counts.size):
        r += counts[q]
        if counts[q] > 0:
            last[q] = ticks[r - 1]
