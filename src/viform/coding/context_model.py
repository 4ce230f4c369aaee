"""Context-modelled binary range coding of first-spike segments (``.vfc`` version 2).

The records of a segment (see :mod:`viform.coding.first_spike`: per pixel, first spikes
``(m, g, o)`` plus a tail ``(m, g)``; seed 000 §5.2) are coded with an adaptive binary
range coder (LZMA-style carry handling, byte output; each context holds a fast- and a
slow-adapting probability estimate, averaged) whose contexts use what the decoder already
knows:

* the pixel's own history — its current width τ (bucketed), its last width change and
  last repeat count;
* its already-decoded neighbours (left, up, up-right; pixels are coded in row-major
  order, each with all its records of the segment) — the neighbours' width at the time
  of the pixel's next spike predicts whether the width grows or shrinks (a moving edge
  reaches neighbouring pixels at nearly the same time), and the neighbours' first full
  widths predict a new pixel's first full width;
* the structure of the stream: a pixel's first spike (its phase) is uniform in
  ``[1, τ₁]`` given its first full width τ₁, so it is coded after τ₁ as a uniform value
  (log₂ τ₁ bits, no byte rounding); whether another first spike follows is coded as one
  binary decision whose context is the time left in the segment in units of τ (no
  per-pixel record counts are stored).

Integers are binarized Elias-gamma style (adaptive unary bit length, adaptive top two
mantissa bits, plain lower bits). Every decoding loop is bounded and every value
range-checked: a damaged stream gives an error code, never a crash or a hang.
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

_PBITS = 11
_PONE = 1 << _PBITS
# two estimates per context, a fast (shift 4) and a slow (shift 7) one, averaged (15-bit each)
_QONE = 1 << 15
_FAST = 4
_SLOW = 7

#: Probabilities per adaptive integer (Elias-gamma) context: 24 unary + 24·3 mantissa tree.
_EG = 96
_MAXBITS = 40

# context counts
_RB = 20  # width buckets
_NB = 10  # neighbour-trend buckets (9 + none)
_DP = 5  # previous width change: none, -big, -1, +1, +big
_MB = 4  # previous repeat count: none, 0, 1-3, ≥4
_MORE = 2 + 8 * 4 * 2

# layout of the probability table
_P_MORE = 0
_P_MORE2 = _P_MORE + _MORE
_P_SIGN = _P_MORE2 + _RB
_P_ZERO = _P_SIGN + _NB * _DP * _RB
_P_PLT = _P_ZERO + _NB * _DP * _RB
_P_PHASE = _P_PLT + _RB
_P_D = _P_PHASE + 2
_P_M = _P_D + _NB * _DP * _RB * _EG
_P_FW = _P_M + _MB * _RB * _EG
_P_FWS = _P_FW + (_RB + 1) * _EG
_P_M2 = _P_FWS + (_RB + 1)
_P_PH = _P_M2 + _EG
_P_TAIL = _P_PH + (_RB + 1) * _EG
_P_GRES = _P_TAIL + 2 * 8 * _EG
_P_GSIGN = _P_GRES + 4 * _EG
_NPROB = _P_GSIGN + 4

# error codes (0 ok); TOO_MANY_RECORDS also means "the record arrays are full" (the caller may grow them)
TOO_MANY_RECORDS = 2
ERRORS = {1: "value out of range", 2: "too many records", 3: "a first spike after the segment end",
          4: "stream is cut short", 5: "record count differs from the header", 6: "repeats without a width"}


# ---------------------------------------------------------------------------- bits with adaptive probabilities

#: version 5: a young context learns at the running frequency 1/(n + 1.5) of its first n bits, then the
#: two estimates settle at their fixed shifts (fast after 2^_FAST bits, slow after 2^_SLOW); older versions
#: start every count at _OLD (saturated), which gives exactly their fixed-shift estimates.
_OLD = 255
_RECIP = np.array([int(65536 / (n + 1.5)) for n in range(1 << _SLOW)], np.int64)


@njit(cache=True, inline="always")
def _adapt(probs, i, bit):
    a = probs[3 * i]
    b = probs[3 * i + 1]
    n = probs[3 * i + 2]
    if n >= (1 << _SLOW):
        if bit == 0:
            probs[3 * i] = a + ((_QONE - a) >> _FAST)
            probs[3 * i + 1] = b + ((_QONE - b) >> _SLOW)
        else:
            probs[3 * i] = a - (a >> _FAST)
            probs[3 * i + 1] = b - (b >> _SLOW)
        return
    target = np.int64(0) if bit else np.int64(_QONE)
    if n < (1 << _FAST):
        a += ((target - a) * _RECIP[n]) >> 16
    elif bit == 0:
        a += (_QONE - a) >> _FAST
    else:
        a -= a >> _FAST
    b += ((target - b) * _RECIP[n]) >> 16
    probs[3 * i] = min(max(a, np.int64(32)), np.int64(_QONE - 32))
    probs[3 * i + 1] = min(max(b, np.int64(32)), np.int64(_QONE - 32))
    probs[3 * i + 2] = n + 1


@njit(cache=True, inline="always")
def _p(probs, i):
    """P(bit = 0) of context i in 1/2^_PBITS: the mean of its fast and slow estimates."""
    return (probs[3 * i] + probs[3 * i + 1]) >> 5


@njit(cache=True, inline="always")
def _ebit(rc, out, probs, i, bit):
    rc = encode_bit(rc, out, _p(probs, i), _PBITS, bit)
    _adapt(probs, i, bit)
    return rc


@njit(cache=True, inline="always")
def _dbit(rc, data, probs, i):
    bit, rc = decode_bit(rc, data, _p(probs, i), _PBITS)
    _adapt(probs, i, bit)
    return bit, rc


@njit(cache=True)
def _euint(rc, out, probs, base, v):
    """Adaptive Elias-gamma code of v ≥ 0 (v < 2**40)."""
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


# ---------------------------------------------------------------------------- contexts

@njit(cache=True, inline="always")
def _rbucket(ref):
    if ref <= 8:
        return max(ref, 1) - 1
    e = 0
    while (ref >> (e + 1)) > 0:
        e += 1
    half = (ref >> (e - 1)) & 1
    return min(8 + (e - 3) * 2 + half, _RB - 1)


@njit(cache=True, inline="always")
def _mbucket(m):
    if m < 0:
        return 0
    if m == 0:
        return 1
    if m < 4:
        return 2
    return 3


@njit(cache=True, inline="always")
def _dbucket(d, have):
    if not have:
        return 0
    if d < -1:
        return 1
    if d < 0:
        return 2
    if d <= 1:
        return 3
    return 4


@njit(cache=True, inline="always")
def _nb_width(n, q, rec_start, counts, rec_s, rec_o, ref0, ptr, slot):
    """Width of neighbour pixel n's interval holding tick q (−1 unknown); ptr[slot] walks forward.

    Callers pass ``slot`` as ``np.int64(k)``, not a literal ``k``: numba would compile one copy per literal.
    """
    lo = rec_start[n] + (1 if ref0[n] == 0 and counts[n] > 0 else 0)
    hi = rec_start[n] + counts[n]
    k = max(ptr[slot], lo)
    while k < hi and rec_s[k] < q:
        k += 1
    ptr[slot] = k
    if k > lo:
        return rec_o[k - 1]
    if ref0[n] > 0:
        return ref0[n]
    if lo < hi:
        return rec_o[lo]
    return np.int64(-1)


@njit(cache=True, inline="always")
def _nb_mean(p, width, q, rec_start, counts, rec_s, rec_o, ref0, ptr):
    """Mean width (×4, rounded) of the decoded neighbours left, up, up-right at tick q; −1 if none."""
    row = p // width
    col = p - row * width
    tot = np.int64(0)
    cnt = 0
    if col > 0:
        w = _nb_width(p - 1, q, rec_start, counts, rec_s, rec_o, ref0, ptr, np.int64(0))
        if w > 0:
            tot += w
            cnt += 1
    if row > 0:
        w = _nb_width(p - width, q, rec_start, counts, rec_s, rec_o, ref0, ptr, np.int64(1))
        if w > 0:
            tot += w
            cnt += 1
        if col + 1 < width:
            w = _nb_width(p - width + 1, q, rec_start, counts, rec_s, rec_o, ref0, ptr, np.int64(2))
            if w > 0:
                tot += w
                cnt += 1
    if cnt == 0:
        return np.int64(-1)
    return (4 * tot + cnt // 2) // cnt


@njit(cache=True, inline="always")
def _nbctx(nb4, ref):
    if nb4 < 0:
        return _NB - 1
    # relative trend (nb − τ)/τ in eighths, rounded, clipped to ±4
    den = 4 * ref
    c = (16 * (nb4 - den) + den) // (2 * den)
    return min(max(c, -4), 4) + 4


@njit(cache=True, inline="always")
def _dctx(nbc, dp, rb):
    return (nbc * _DP + dp) * _RB + rb


@njit(cache=True, inline="always")
def _more_ctx(remaining, ref, mb, first):
    r = min(remaining // ref, 7)
    return 2 + ((r * 4 + mb) * 2 + first)


@njit(cache=True, inline="always")
def _nb_first(p, width, rec_start, counts, rec_s, rec_o, ref0, ptr, seg_start):
    ptr[0] = 0
    ptr[1] = 0
    ptr[2] = 0
    return _nb_mean(p, width, seg_start, rec_start, counts, rec_s, rec_o, ref0, ptr)


@njit(cache=True)
def new_probabilities(young):
    """Every context at p = ½: young (version 5) or with the fixed-shift estimates of versions 2-4."""
    probs = np.full(3 * _NPROB, _QONE // 2, np.int64)
    probs[2::3] = 0 if young else _OLD
    return probs


# ---------------------------------------------------------------------------- encoder

@njit(cache=True, nogil=True)
def encode_segment(counts, rec_m, rec_g, rec_o, tail_m, tail_g, anchor0, ref0, seg_start, seg_end, width, strict,
                   out, rec_s, young):
    """Code one segment's records into ``out``; returns the byte count (> out.size: retry bigger).

    ``young`` (a bool, True for version 5, always passed: an omitted argument is another compiled
    specialisation): young contexts learn at their running frequency (see :func:`_adapt`).
    """
    npix = counts.size
    probs = new_probabilities(young)
    rc = encoder_start()
    rec_start = np.zeros(npix + 1, np.int64)
    for p in range(npix):
        rec_start[p + 1] = rec_start[p] + counts[p]
    ptr = np.zeros(3, np.int64)
    for p in range(npix):
        a = anchor0[p]
        ref = ref0[p]
        r = rec_start[p]
        r_end = r + counts[p]
        mb = 0
        dp = 0
        have_d = False
        first = 1
        ptr[0] = 0
        ptr[1] = 0
        ptr[2] = 0
        if ref == 0:
            col = p % width
            lf = 1 if (col > 0 and counts[p - 1] > 0) else 0
            rc = _ebit(rc, out, probs, _P_MORE + lf, 1 if r < r_end else 0)
            if r == r_end:
                continue
            off = seg_start - 1 - a  # a pixel that never fired: a = -1; code its first tick within the segment
            phase = rec_o[r] - off
            rec_s[r] = a
            nb4 = _nb_first(p, width, rec_start, counts, rec_s, rec_o, ref0, ptr, seg_start)
            fb = _RB if nb4 < 0 else _rbucket((nb4 + 2) // 4)
            two = r + 1 < r_end
            rc = _ebit(rc, out, probs, _P_MORE2 + min(fb, _RB - 1), 1 if two else 0)
            if two:
                m2 = rec_m[r + 1]
                o2 = rec_o[r + 1]
                rc = _euint(rc, out, probs, np.int64(_P_M2), m2)
                pred = (nb4 + 2) // 4 if nb4 > 0 else 0
                e = o2 - pred
                rc = _ebit(rc, out, probs, _P_FWS + fb, 1 if e < 0 else 0)
                rc = _euint(rc, out, probs, _P_FW + fb * _EG, abs(e) - (1 if e < 0 else 0))
                # the phase given the first full width: uniform below it (strict: never equal when m2 = 0)
                lim = o2 - 1 if (strict and m2 == 0) else o2
                below = phase <= lim
                rc = _ebit(rc, out, probs, _P_PHASE + (1 if m2 > 0 else 0), 1 if below else 0)
                if below:
                    rc = encode_uniform(rc, out, phase - 1, lim)
                else:
                    rc = _euint(rc, out, probs, _P_PH + _rbucket(o2) * _EG, phase - lim - 1)
                a = a + off + phase
                ref = off + phase
                r += 1
                # the second record (m2 repeats of the phase width, then o2)
                g = rec_g[r]
                if not strict and m2 > 0:
                    e = g - m2 * ref
                    rc = _ebit(rc, out, probs, _P_GSIGN, 1 if e < 0 else 0)
                    rc = _euint(rc, out, probs, np.int64(_P_GRES), abs(e) - (1 if e < 0 else 0))
                rec_s[r] = a + g
                a = a + g + o2
                ref = o2
                mb = _mbucket(m2)
                r += 1
                first = 0
            else:
                rc = _euint(rc, out, probs, _P_PH + fb * _EG, phase - 1)
                a = a + off + phase
                ref = off + phase
                r += 1
        while True:
            remaining = seg_end - 1 - a
            more = r < r_end
            if remaining >= 1:
                rc = _ebit(rc, out, probs, _P_MORE + _more_ctx(remaining, ref, mb, first), 1 if more else 0)
            if not more:
                break
            first = 0
            m = rec_m[r]
            g = rec_g[r]
            o = rec_o[r]
            rb = _rbucket(ref)
            rc = _euint(rc, out, probs, _P_M + (mb * _RB + rb) * _EG, m)
            if not strict and m > 0:
                e = g - m * ref
                rc = _ebit(rc, out, probs, _P_GSIGN + 1, 1 if e < 0 else 0)
                rc = _euint(rc, out, probs, np.int64(_P_GRES + _EG), abs(e) - (1 if e < 0 else 0))
            s = a + g
            rec_s[r] = s
            nb4 = _nb_mean(p, width, s + (ref + 1) // 2, rec_start, counts, rec_s, rec_o, ref0, ptr)
            c = _dctx(_nbctx(nb4, ref), _dbucket(dp, have_d), rb)
            d = o - ref
            if not strict:
                rc = _ebit(rc, out, probs, _P_ZERO + c, 1 if d == 0 else 0)
            if d != 0 or strict:
                rc = _ebit(rc, out, probs, _P_SIGN + c, 1 if d < 0 else 0)
                rc = _euint(rc, out, probs, _P_D + c * _EG, abs(d) - 1)
            dp = d
            have_d = True
            mb = _mbucket(m)
            a = s + o
            ref = o
            r += 1
        if ref > 0:
            m = tail_m[p]
            fill = (seg_end - 1 - a) // ref
            e = fill - m
            tc = (0 if strict else 8) + min(fill, 7)
            rc = _euint(rc, out, probs, _P_TAIL + tc * _EG, 2 * e if e >= 0 else -2 * e - 1)
            if not strict and m > 0:
                e = tail_g[p] - m * ref
                rc = _ebit(rc, out, probs, _P_GSIGN + 2, 1 if e < 0 else 0)
                rc = _euint(rc, out, probs, np.int64(_P_GRES + 2 * _EG), abs(e) - (1 if e < 0 else 0))
    return encoder_flush(rc, out)


# ---------------------------------------------------------------------------- decoder

@njit(cache=True, nogil=True)
def decode_segment(data, npix, anchor0, ref0, seg_start, seg_end, width, strict, n_rec,
                   counts, rec_m, rec_g, rec_o, tail_m, tail_g, rec_s, young):
    """Inverse of :func:`encode_segment`. Returns an error code (0 ok); arrays are filled in place.

    ``data``: the coded bytes as a read-only uint8 array (``np.frombuffer``), as every reader passes
    them (a writable array would be another compiled specialisation); ``young`` as for encoding.

    ``rec_m, rec_g, rec_o, rec_s`` must hold at least ``n_rec`` records.
    """
    probs = new_probabilities(young)
    rc = decoder_start(data)
    big = np.int64(1) << 31
    cap = min(n_rec, rec_m.size)
    rec_start = np.zeros(npix + 1, np.int64)
    ptr = np.zeros(3, np.int64)
    r = 0
    for p in range(npix):
        rec_start[p] = r
        counts[p] = 0
        a = anchor0[p]
        ref = ref0[p]
        mb = 0
        dp = 0
        have_d = False
        first = 1
        ptr[0] = 0
        ptr[1] = 0
        ptr[2] = 0
        if ref < 0 or ref > big or a < -1 or a >= seg_end:
            return 1
        if ref == 0:
            col = p % width
            lf = 1 if (col > 0 and counts[p - 1] > 0) else 0
            fires, rc = _dbit(rc, data, probs, _P_MORE + lf)
            if fires == 0:
                tail_m[p] = 0
                tail_g[p] = 0
                if rc[2] > data.size + 8:
                    return 4
                continue
            if r >= cap:
                return 2
            off = seg_start - 1 - a
            if off < 0:
                return 1
            nb4 = _nb_first(p, width, rec_start, counts, rec_s, rec_o, ref0, ptr, seg_start)
            fb = _RB if nb4 < 0 else _rbucket((nb4 + 2) // 4)
            two_bit, rc = _dbit(rc, data, probs, _P_MORE2 + min(fb, _RB - 1))
            two = two_bit == 1
            m2 = np.int64(0)
            o2 = np.int64(0)
            if two:
                if r + 1 >= cap:
                    return 2
                m2, rc = _duint(rc, data, probs, np.int64(_P_M2))
                pred = (nb4 + 2) // 4 if nb4 > 0 else 0
                neg, rc = _dbit(rc, data, probs, _P_FWS + fb)
                mag, rc = _duint(rc, data, probs, _P_FW + fb * _EG)
                o2 = pred - mag - 1 if neg else pred + mag
                if o2 < 1 or o2 > big or m2 > big or rc[3]:
                    return 1
                lim = o2 - 1 if (strict and m2 == 0) else o2
                below, rc = _dbit(rc, data, probs, _P_PHASE + (1 if m2 > 0 else 0))
                if below:
                    if lim < 1:
                        return 1
                    phase, rc = decode_uniform(rc, data, lim)
                    phase += 1
                else:
                    phase, rc = _duint(rc, data, probs, _P_PH + _rbucket(o2) * _EG)
                    phase += lim + 1
                phase += off
            else:
                phase, rc = _duint(rc, data, probs, _P_PH + fb * _EG)
                phase += 1 + off
            if phase > big or rc[3]:
                return 1
            # the pixel's first spike: its phase record
            rec_m[r] = 0
            rec_g[r] = 0
            rec_o[r] = phase
            rec_s[r] = a
            a = a + phase
            ref = phase
            if a >= seg_end:
                return 3
            r += 1
            if two:
                g = m2 * ref
                if not strict and m2 > 0:
                    neg, rc = _dbit(rc, data, probs, _P_GSIGN)
                    mag, rc = _duint(rc, data, probs, np.int64(_P_GRES))
                    g += -mag - 1 if neg else mag
                if g < m2 or g > big:
                    return 1
                rec_m[r] = m2
                rec_g[r] = g
                rec_o[r] = o2
                rec_s[r] = a + g
                a = a + g + o2
                ref = o2
                if a >= seg_end:
                    return 3
                mb = _mbucket(m2)
                r += 1
                first = 0
        while True:
            remaining = seg_end - 1 - a
            if remaining < 1:
                break
            more, rc = _dbit(rc, data, probs, _P_MORE + _more_ctx(remaining, ref, mb, first))
            if more == 0:
                break
            if rc[2] > data.size + 8:
                return 4
            if r >= cap:
                return 2
            first = 0
            rb = _rbucket(ref)
            m, rc = _duint(rc, data, probs, _P_M + (mb * _RB + rb) * _EG)
            if m > big or rc[3]:
                return 1
            g = m * ref
            if not strict and m > 0:
                neg, rc = _dbit(rc, data, probs, _P_GSIGN + 1)
                mag, rc = _duint(rc, data, probs, np.int64(_P_GRES + _EG))
                g += -mag - 1 if neg else mag
            if g < m or g > big:
                return 1
            s = a + g
            if s >= seg_end:
                return 3
            rec_s[r] = s
            nb4 = _nb_mean(p, width, s + (ref + 1) // 2, rec_start, counts, rec_s, rec_o, ref0, ptr)
            c = _dctx(_nbctx(nb4, ref), _dbucket(dp, have_d), rb)
            d = np.int64(0)
            zero = False
            if not strict:
                zero_bit, rc = _dbit(rc, data, probs, _P_ZERO + c)
                zero = zero_bit == 1
            if not zero:
                neg, rc = _dbit(rc, data, probs, _P_SIGN + c)
                mag, rc = _duint(rc, data, probs, _P_D + c * _EG)
                d = -(mag + 1) if neg else mag + 1
            o = ref + d
            if o < 1 or o > big or rc[3]:
                return 1
            rec_m[r] = m
            rec_g[r] = g
            rec_o[r] = o
            a = s + o
            if a >= seg_end:
                return 3
            dp = d
            have_d = True
            mb = _mbucket(m)
            ref = o
            r += 1
        counts[p] = r - rec_start[p]
        if ref > 0:
            fill = (seg_end - 1 - a) // ref
            tc = (0 if strict else 8) + min(fill, 7)
            e, rc = _duint(rc, data, probs, _P_TAIL + tc * _EG)
            m = fill - ((e >> 1) if (e & 1) == 0 else -((e + 1) >> 1))
            if m < 0 or m > big or rc[3]:
                return 1
            g = m * ref
            if not strict and m > 0:
                neg, rc = _dbit(rc, data, probs, _P_GSIGN + 2)
                mag, rc = _duint(rc, data, probs, np.int64(_P_GRES + 2 * _EG))
                g += -mag - 1 if neg else mag
            if g < m or g > big:
                return 1
            tail_m[p] = m
            tail_g[p] = g
        else:
            tail_m[p] = 0
            tail_g[p] = 0
        if rc[2] > data.size + 8:
            return 4
    if r != n_rec:
        return 5
    if rc[2] > data.size + 5:
        return 4
    return 0
