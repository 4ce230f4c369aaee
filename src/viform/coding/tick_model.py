"""The tick model of ``.vfc`` version 6: per-pixel interval prediction with mixed context probabilities.

What it codes is a band's spike ticks, pixel by pixel (row-major), each pixel with all its spikes
of the segment. The predictor is version 4's (:mod:`viform.coding.interval_model`): a pixel's
spike times are the crossings of a continuous charge clock rounded down to the tick (seed 000
§3.1, §4.3), tracked by a phase-locked estimate of the interval μ̂ and of the phase of the last
crossing; each spike is coded as its residual ``d`` against the predicted tick, as binary
decisions: ``d = 0?``, its sign, ``|d| = 1?``, then ``|d| − 2`` (Elias-gamma). What is new:

* **Mixed probabilities.** Version 5 needed three models because one context set never fits every
  stream: a large context (phase inside the tick, noise level, the last three intervals against
  the prediction, the neighbours) is sharp on long steady streams and learns too slowly on short
  or fast-changing ones, where a run-length view (is the interval repeating? which way did the
  last residual go?) wins. Here each residual decision takes the probabilities of three context
  sets and mixes them in the logistic domain with weights learnt online (per decision and noise
  level), the method of the PAQ family of context-mixing coders (M. Mahoney, "Adaptive weighing of
  context models for lossless data compression", Florida Tech. TR CS-2005-16, 2005). The mixed
  probability is coded with 12 bits.
* **Neighbours from row buffers.** The already-coded left and upper neighbours' intervals at the
  predicted tick (what version 4 found by walking their spike lists) are read from per-row
  buffers that hold, for every tick of the segment, the interval in progress of each pixel of
  the current and the previous row: two loads per spike instead of two walks. Their deviation
  from the prediction is a context of every decision, and of the magnitude.
* a pixel's first full interval is predicted from its left and upper neighbours' first full
  intervals in the segment (version 4 used their interval estimates at the segment's end).

Every value decoded is range-checked; damage gives an error code, never a crash or a hang.
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

# ---------------------------------------------------------------------------- layout

_PB = 16  # bits of a context's probability
_PMAX = (1 << _PB) - 32
_LIMIT = 30  # a context learns at 1/(n + 1.5) for its first bits, then at 1/31.5
_RECIP = np.array([int(65536 / (n + 1.5)) for n in range(_LIMIT + 1)], np.int64)
_MAXBITS = 40
_FB = 16  # fractional bits of the fixed-point state
_ONE = np.int64(1) << _FB
_NBITS = 6  # flags: intervals since the lock began (saturating), then the last residual's sign
_NMASK = (1 << _NBITS) - 1
_SHMAX = 6
_INSET = _ONE >> 4
#: per-pixel state (int64 (P, 7)): μ̂, φ, mean |residual|, flags (lock age | last sign), last three intervals
STATE_ROWS = 7

_NS = 7  # noise buckets
_NR = 8  # stop-decision buckets
_NT = 12  # neighbour context
_NK = 6  # neighbours' deviation in the direction of the residual
_NZ = 8 * _NS * 5 * 3 * 3 * _NT
_NRL = 3 * 4  # run of equal intervals (none, 2, 3) × last residual (none, +, −, restart)

_P_NEW = 0
_P_TWO = _P_NEW + 2
_P_FWS = _P_TWO + _RB + 1
_P_FW = _P_FWS + _RB + 1
_P_PHB = _P_FW + (_RB + 1) * _EG
_P_PH = _P_PHB + 1
_P_COLD = _P_PH + (_RB + 1) * _EG
_P_COLDV = _P_COLD + 2
_P_STOP = _P_COLDV + _EG
_P_Z = _P_STOP + _NR * _NS * 2
_P_SG = _P_Z + _NZ
_P_ONE = _P_SG + _NZ
_P_MAG = _P_ONE + _NS * 2 * 5 * _NT
_P_ZB = _P_MAG + _NS * 2 * _NK * _RB * _EG
_P_ZC = _P_ZB + 8 * _NS * 5
_P_SB = _P_ZC + _NRL * 5 * _NT
_P_SC = _P_SB + _NS * 5 * _NT
_P_OB = _P_SC + _NRL * 5 * 8
_P_OC = _P_OB + _NS * 2 * 5
_P_MB = _P_OC + _NRL * 2 * 5 * _NT
_P_MC = _P_MB + 2 * _NK * 12
NPROB = _P_MC + 4 * 2 * _NT * 12
#: mixer weight sets (decision: zero, sign, one, magnitude × noise bucket), three weights each
_NWSET = 4 * _NS
_W0 = int(0.4 * 65536)
_LR = 6

# logistic domain, 12-bit probabilities: stretch(p) = ln(p / (1 − p)) and its inverse, ×256
_ST = np.clip(np.array([round(256 * np.log((p + 0.5) / (4095.5 - p))) for p in range(4096)], np.int64), -2047,
              2047).astype(np.int32)  # int32: the two tables stay in L1 (products are taken in int64)
_SQ = np.array([min(4095, max(1, round(4096 / (1 + np.exp(-x / 256))))) for x in range(-2047, 2048)], np.int32)

ERRORS = {1: "value out of range", 2: "more spikes than the segment states", 3: "a spike outside the segment",
          4: "stream is cut short", 5: "spike count differs from the header"}


def new_probabilities() -> np.ndarray:
    """The model's adaptive state at the start of a stream: every context at p = ½, the mixer's weights."""
    probs = np.zeros(2 * NPROB + 3 * _NWSET, np.int64)
    probs[0:2 * NPROB:2] = 1 << (_PB - 1)
    probs[2 * NPROB:] = _W0
    return probs


# ---------------------------------------------------------------------------- probabilities

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
def _mixed(probs, ia, ib, ic, wset):
    """P(bit = 0) in 1/4096 mixed from contexts ia, ib, ic with weight set wset, and the stretched inputs."""
    s1 = _ST[probs[2 * ia] >> 4]
    s2 = _ST[probs[2 * ib] >> 4]
    s3 = _ST[probs[2 * ic] >> 4]
    w = 2 * NPROB + 3 * wset
    dot = (probs[w] * s1 + probs[w + 1] * s2 + probs[w + 2] * s3) >> 16
    return _SQ[min(max(dot, -2047), 2047) + 2047], s1, s2, s3


@njit(cache=True, inline="always")
def _learn(probs, ia, ib, ic, wset, pm, s1, s2, s3, bit):
    err = ((4096 if bit == 0 else 0) - pm) * _LR
    w = 2 * NPROB + 3 * wset
    probs[w] += (s1 * err + 0x8000) >> 16
    probs[w + 1] += (s2 * err + 0x8000) >> 16
    probs[w + 2] += (s3 * err + 0x8000) >> 16
    _adapt(probs, ia, bit)
    _adapt(probs, ib, bit)
    _adapt(probs, ic, bit)


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


@njit(cache=True, inline="always")
def _emix(rc, out, probs, ia, ib, ic, wset, bit):
    pm, s1, s2, s3 = _mixed(probs, ia, ib, ic, wset)
    rc = encode_bit(rc, out, pm, 12, bit)
    _learn(probs, ia, ib, ic, wset, pm, s1, s2, s3, bit)
    return rc


@njit(cache=True, inline="always")
def _dmix(rc, data, probs, ia, ib, ic, wset):
    pm, s1, s2, s3 = _mixed(probs, ia, ib, ic, wset)
    bit, rc = decode_bit(rc, data, pm, 12)
    _learn(probs, ia, ib, ic, wset, pm, s1, s2, s3, bit)
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


@njit(cache=True)
def _emag(rc, out, probs, ba, bb, bc, wset, v):
    """Elias-gamma code of v ≥ 0 whose unary length bits are mixed from three context sets."""
    x = v + 1
    n = 0
    while (x >> (n + 1)) > 0:
        n += 1
    for i in range(n + 1):
        rc = _emix(rc, out, probs, ba + min(i, 23), bb + min(i, 11), bc + min(i, 11), wset, 1 if i < n else 0)
    node = 1
    nb = min(n, 23)
    for k in range(n - 1, -1, -1):
        bit = (x >> k) & 1
        if n - 1 - k < 2:
            rc = _ebit(rc, out, probs, ba + 24 + nb * 3 + node - 1, bit)
            node = node * 2 + bit if node == 1 else node
        else:
            rc = encode_plain(rc, out, bit)
    return rc


@njit(cache=True)
def _dmag(rc, data, probs, ba, bb, bc, wset):
    n = 0
    while True:
        bit, rc = _dmix(rc, data, probs, ba + min(n, 23), bb + min(n, 11), bc + min(n, 11), wset)
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
            bit, rc = _dbit(rc, data, probs, ba + 24 + nb * 3 + node - 1)
            node = node * 2 + bit if node == 1 else node
        else:
            bit, rc = decode_plain(rc, data)
        x = (x << 1) | bit
    return x - 1, rc


# ---------------------------------------------------------------------------- predictor

def _sbucket_loop(mad):
    # mean |residual| in ticks: < 1/16, 1/8, 1/4, 1/2, 1, 2, ≥ 2
    b = 0
    lim = _ONE >> 4
    while b < _NS - 1 and mad >= lim:
        b += 1
        lim <<= 1
    return b


#: _sbucket_loop(mad) for mad >> (_FB - 4) = 0 … 31 (from 32 on: the top bucket), one load per spike
_SBT = np.array([_sbucket_loop(x << (_FB - 4)) for x in range(32)], np.int64)


@njit(cache=True, inline="always")
def _sbucket(mad):
    """The noise bucket of mean |residual| ``mad`` (fixed point): < 1/16, 1/8, 1/4, 1/2, 1, 2, ≥ 2 ticks."""
    x = mad >> (_FB - 4)
    return 0 if x <= 0 else (_NS - 1 if x >= 32 else _SBT[x])


def _shift_loop(n):
    sh = 1
    while sh < _SHMAX - 1 and (2 << sh) <= n + 1:
        sh += 1
    return sh


#: the phase-lock gain's shift after n intervals (n = 0 … _NMASK): 1 while n < 3, then one more per doubling
_SHT = np.array([_shift_loop(n) for n in range(_NMASK + 1)], np.int64)


@njit(cache=True, inline="always")
def _update(s, iv, p):
    """Pixel state s = (μ̂, φ, mad, flags, i1, i2, i3) after an interval iv predicted as p (version 4's loop)."""
    mu, ph, mad, fl, i1, i2, i3 = s
    i3 = i2
    i2 = i1
    i1 = min(iv, np.int64(1) << 40)
    n = fl & _NMASK
    last = fl >> _NBITS
    r = iv - p
    ar = r if r >= 0 else -r
    if n == 0:
        return (iv << _FB, _ONE >> 1, _ONE >> 1, np.int64(1), i1, i2, i3)
    if ar >= 2 and (ar << _FB) > 3 * mad + _ONE:  # the light changed: restart at the observed interval
        return (iv << _FB, _ONE >> 1, mad + (((ar << _FB) - mad) >> 2), np.int64(1 | (3 << _NBITS)), i1, i2, i3)
    x = ph + mu
    lo = iv << _FB
    hi = lo + _ONE - 1
    xn = lo + _INSET if x < lo else (hi - _INSET if x > hi else x)
    err = xn - x
    sh = _SHT[n]
    sgn = 0 if r == 0 else (1 if r > 0 else 2)
    if sgn != 0 and sgn == last and ar >= 2:
        sh = max(sh - 2, 1)
    mu = mu + (err >> sh) if err >= 0 else mu - ((-err) >> sh)
    mu = max(mu, _ONE)
    return (mu, xn - lo, mad + (((ar << _FB) - mad) >> 4), min(n + 1, _NMASK) | (sgn << _NBITS), i1, i2, i3)


@njit(cache=True, inline="always")
def _clip(x, lo, hi):
    return min(max(x, lo), hi)


@njit(cache=True, inline="always")
def _at(buf, b, col, tau, seg_start, n_ticks):
    """The interval in progress at tick tau of column col of row buffer b (−1: not known).

    The buffers are indexed whole (no per-spike array views: numba counts each view's references).
    """
    return buf[b, col, min(max(tau - seg_start, 0), n_ticks - 1)]


@njit(cache=True, inline="always")
def _fill(buf, b, col, ticks, r, c, prev0, seg_start, n_ticks):
    """Write into ``buf[b, col]`` (one per tick of the segment) the pixel's interval in progress at each tick.

    At tick τ it is the interval that ends at the pixel's first spike after τ (−1 when that spike is
    not in the segment, or when the pixel never fired before it). Returns the first full interval
    (0: none).
    """
    pos = 0
    prev = prev0
    first = np.int64(0)
    big = np.int64(1) << 30
    for j in range(c):
        nxt = ticks[r + j]
        v = min(nxt - prev, big) if prev >= 0 else -1
        if first == 0 and v > 0:
            first = v
        e = nxt - seg_start
        for t in range(pos, e):
            buf[b, col, t] = v
        pos = e
        prev = nxt
    for t in range(pos, n_ticks):
        buf[b, col, t] = -1
    return first


@njit(cache=True, inline="always")
def _first_width(firstw, q, width, has_left, has_up):
    """The mean first full interval of the left and upper neighbours in this segment (0: neither has one)."""
    tot = np.int64(0)
    hv = 0
    if has_left and firstw[q - 1] > 0:
        tot += firstw[q - 1]
        hv += 1
    if has_up and firstw[q - width] > 0:
        tot += firstw[q - width]
        hv += 1
    return (tot + hv // 2) // hv if hv else np.int64(0)


@njit(cache=True)
def _nb_mu(st, q, width, npix):
    """Mean interval estimate (ticks, rounded) of the neighbours (left, up, up-right, right, down) that have one."""
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


@njit(cache=True, inline="always")
def _contexts(s, lo, rem, a, buf, cur, prv, col, has_left, has_up, seg_start, n_ticks):
    """Prediction and contexts of a locked pixel's next spike.

    Returns p (the predicted interval), the stop context, the zero context (large), the zero
    contexts B and C, the noise bucket, h1, the neighbour context tr, the run/last-sign index and
    the neighbours' summed deviation with their count.
    """
    x = s[1] + s[0]
    p = x >> _FB
    f = (x & (_ONE - 1)) >> (_FB - 3)
    if p < lo:
        p = lo
        f = 0
    sb = _sbucket(s[2])
    d = rem - p
    stop = _P_STOP + ((min(max(d, -3), 4) + 3) * _NS + sb) * 2 + (1 if d > 2 * p else 0)
    tp = a + p
    dev = np.int64(0)
    have = 0
    if has_left:
        now = _at(buf, cur, col - 1, tp, seg_start, n_ticks)
        if now > 0:
            dev += now - p
            have += 1
    if has_up:
        now = _at(buf, prv, col, tp, seg_start, n_ticks)
        if now > 0:
            dev += now - p
            have += 1
    tr = 11 if have == 0 else (9 + (0 if dev == 0 else 1) if have == 1 else _clip(dev, -4, 4) + 4)
    h1 = _clip(s[4] - p, -2, 2) + 2
    h2 = _clip(s[5] - p, -1, 1) + 1
    h3 = _clip(s[6] - p, -1, 1) + 1
    zc = ((((f * _NS + sb) * 5 + h1) * 3 + h2) * 3 + h3) * _NT + tr
    rl = 2 if (s[4] == s[5] and s[5] == s[6]) else (1 if s[4] == s[5] else 0)
    rl = rl * 4 + (s[3] >> _NBITS)
    return p, f, stop, zc, sb, h1, tr, rl, dev, have


@njit(cache=True, inline="always")
def _nbk(dev, have, neg):
    """The neighbours' deviation from the prediction in the direction of the residual, bucketed."""
    if have == 0:
        return 0
    rel = (-dev if neg else dev) // have
    return 1 if rel <= 1 else (2 if rel == 2 else (3 if rel <= 4 else (4 if rel <= 8 else 5)))


# ---------------------------------------------------------------------------- encoder

@njit(cache=True, nogil=True)
def encode_band(counts, ticks, last0, st, probs, seg_start, seg_end, width, out):
    """Code one band's spikes of a segment; returns the byte count (> out.size: retry bigger from copies).

    ``counts`` (per pixel, row-major) and ``ticks`` (grouped by pixel, in time order) are the band's
    spikes; ``last0`` each pixel's last spike before the segment (−1: never); ``st`` (P, STATE_ROWS)
    and ``probs`` are advanced in place.
    """
    npix = counts.size
    n_ticks = seg_end - seg_start
    rc = encoder_start()
    buf = np.empty((2, width, n_ticks), np.int32)
    firstw = np.zeros(npix, np.int64)
    r = np.int64(0)
    for q in range(npix):
        c = counts[q]
        a = last0[q]
        row = q // width
        col = q - row * width
        cur = row & 1
        prv = (row - 1) & 1
        has_left = col > 0
        has_up = row > 0
        s = (st[q, 0], st[q, 1], st[q, 2], st[q, 3], st[q, 4], st[q, 5], st[q, 6])
        k = 0
        if a < 0:
            lf = 1 if (has_left and counts[q - 1] > 0) else 0
            rc = _ebit(rc, out, probs, _P_NEW + lf, 1 if c > 0 else 0)
            if c == 0:
                _fill(buf, cur, col, ticks, r, 0, a, seg_start, n_ticks)
                continue
            phase = ticks[r] - (seg_start - 1)
            nb = _first_width(firstw, q, width, has_left, has_up)
            if nb <= 0:
                nb = _nb_mu(st, q, width, npix)
            fb = _RB if nb <= 0 else _rbucket(nb)
            rc = _ebit(rc, out, probs, _P_TWO + fb, 1 if c >= 2 else 0)
            s = (s[0], s[1], s[2], np.int64(0), s[4], s[5], s[6])
            if c >= 2:
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
                s = _update(s, iv, iv)
                a = ticks[r + 1]
                k = 2
            else:
                rc = _euint(rc, out, probs, _P_PH + fb * _EG, phase - 1)
                a = ticks[r]
                k = 1
        while True:
            rem = seg_end - 1 - a
            lo = max(np.int64(1), seg_start - a)
            if rem < lo:
                break
            more = k < c
            if (s[3] & _NMASK) == 0:
                rc = _ebit(rc, out, probs, _P_COLD + (1 if a >= seg_start else 0), 1 if more else 0)
                if not more:
                    break
                iv = ticks[r + k] - a
                rc = _euint(rc, out, probs, np.int64(_P_COLDV), iv - lo)
                s = _update(s, iv, iv)
            else:
                p, f, stop, zc, sb, h1, tr, rl, dev, have = _contexts(s, lo, rem, a, buf, cur, prv, col, has_left,
                                                                      has_up, seg_start, n_ticks)
                rc = _ebit(rc, out, probs, stop, 1 if more else 0)
                if not more:
                    break
                iv = ticks[r + k] - a
                d = iv - p
                rc = _emix(rc, out, probs, _P_Z + zc, _P_ZB + (f * _NS + sb) * 5 + h1, _P_ZC + (rl * 5 + h1) * _NT + tr,
                           sb, 1 if d == 0 else 0)
                if d != 0:
                    neg = 1 if d < 0 else 0
                    rc = _emix(rc, out, probs, _P_SG + zc, _P_SB + (sb * 5 + h1) * _NT + tr,
                               _P_SC + (rl * 5 + h1) * 8 + f, _NS + sb, neg)
                    ad = -d if neg else d
                    rc = _emix(rc, out, probs, _P_ONE + ((sb * 2 + neg) * 5 + h1) * _NT + tr,
                               _P_OB + (sb * 2 + neg) * 5 + h1, _P_OC + ((rl * 2 + neg) * 5 + h1) * _NT + tr,
                               2 * _NS + sb, 1 if ad == 1 else 0)
                    if ad > 1:
                        nk = _nbk(dev, have, neg)
                        ma = _P_MAG + (((sb * 2 + neg) * _NK + nk) * _RB + _rbucket(p)) * _EG
                        rc = _emag(rc, out, probs, ma, _P_MB + (neg * _NK + nk) * 12,
                                   _P_MC + (((s[3] >> _NBITS) * 2 + neg) * _NT + tr) * 12, 3 * _NS + sb, ad - 2)
                s = _update(s, iv, p)
            a = a + iv
            k += 1
        for j in range(STATE_ROWS):
            st[q, j] = s[j]
        firstw[q] = _fill(buf, cur, col, ticks, r, c, last0[q], seg_start, n_ticks)
        r += c
    return encoder_flush(rc, out)


# ---------------------------------------------------------------------------- decoder

@njit(cache=True, nogil=True)
def decode_band(data, npix, last0, st, probs, seg_start, seg_end, width, n_spikes, counts, ticks):
    """Inverse of :func:`encode_band`. Returns (error code, spikes decoded); ``counts``/``ticks`` filled.

    ``ticks`` must hold the spikes: when it is full the code is 2 (the caller may grow it and
    decode again from copies of the state, or give up when the segment states fewer spikes).
    """
    n_ticks = seg_end - seg_start
    rc = decoder_start(data)
    cap = min(n_spikes, ticks.size)
    buf = np.empty((2, width, n_ticks), np.int32)
    firstw = np.zeros(npix, np.int64)
    r = np.int64(0)
    for q in range(npix):
        counts[q] = 0
        a = last0[q]
        if a < -1 or a >= seg_start:
            return 1, r
        row = q // width
        col = q - row * width
        cur = row & 1
        prv = (row - 1) & 1
        has_left = col > 0
        has_up = row > 0
        s = (st[q, 0], st[q, 1], st[q, 2], st[q, 3], st[q, 4], st[q, 5], st[q, 6])
        c = 0
        if a < 0:
            lf = 1 if (has_left and counts[q - 1] > 0) else 0
            fires, rc = _dbit(rc, data, probs, _P_NEW + lf)
            if fires == 0:
                _fill(buf, cur, col, ticks, r, 0, a, seg_start, n_ticks)
                if rc[2] > data.size + 8:
                    return 4, r
                continue
            base = seg_start - 1
            nb = _first_width(firstw, q, width, has_left, has_up)
            if nb <= 0:
                nb = _nb_mu(st, q, width, npix)
            fb = _RB if nb <= 0 else _rbucket(nb)
            two, rc = _dbit(rc, data, probs, _P_TWO + fb)
            s = (s[0], s[1], s[2], np.int64(0), s[4], s[5], s[6])
            if two:
                if r + 2 > cap:
                    return 2, r
                neg, rc = _dbit(rc, data, probs, _P_FWS + fb)
                mag, rc = _duint(rc, data, probs, _P_FW + fb * _EG)
                iv = nb - mag - 1 if neg else nb + mag
                if iv < 1 or iv >= n_ticks or rc[3]:
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
                s = _update(s, iv, iv)
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
                a = base + phase
                c = 1
        while True:
            rem = seg_end - 1 - a
            lo = max(np.int64(1), seg_start - a)
            if rem < lo:
                break
            if (s[3] & _NMASK) == 0:
                more, rc = _dbit(rc, data, probs, _P_COLD + (1 if a >= seg_start else 0))
                if more == 0:
                    break
                iv, rc = _duint(rc, data, probs, np.int64(_P_COLDV))
                iv += lo
                if rc[3] or iv > rem:
                    return 3, r + c
                s = _update(s, iv, iv)
            else:
                p, f, stop, zc, sb, h1, tr, rl, dev, have = _contexts(s, lo, rem, a, buf, cur, prv, col, has_left,
                                                                      has_up, seg_start, n_ticks)
                more, rc = _dbit(rc, data, probs, stop)
                if more == 0:
                    break
                zero, rc = _dmix(rc, data, probs, _P_Z + zc, _P_ZB + (f * _NS + sb) * 5 + h1,
                                 _P_ZC + (rl * 5 + h1) * _NT + tr, sb)
                if zero:
                    d = np.int64(0)
                else:
                    neg, rc = _dmix(rc, data, probs, _P_SG + zc, _P_SB + (sb * 5 + h1) * _NT + tr,
                                    _P_SC + (rl * 5 + h1) * 8 + f, _NS + sb)
                    one, rc = _dmix(rc, data, probs, _P_ONE + ((sb * 2 + neg) * 5 + h1) * _NT + tr,
                                    _P_OB + (sb * 2 + neg) * 5 + h1, _P_OC + ((rl * 2 + neg) * 5 + h1) * _NT + tr,
                                    2 * _NS + sb)
                    if one:
                        ad = np.int64(1)
                    else:
                        nk = _nbk(dev, have, neg)
                        ma = _P_MAG + (((sb * 2 + neg) * _NK + nk) * _RB + _rbucket(p)) * _EG
                        ad, rc = _dmag(rc, data, probs, ma, _P_MB + (neg * _NK + nk) * 12,
                                       _P_MC + (((s[3] >> _NBITS) * 2 + neg) * _NT + tr) * 12, 3 * _NS + sb)
                        ad += 2
                    d = -ad if neg else ad
                iv = p + d
                if rc[3] or iv < lo or iv > rem:
                    return 3, r + c
                s = _update(s, iv, p)
            if r + c >= cap:
                return 2, r + c
            a = a + iv
            ticks[r + c] = a
            c += 1
            if rc[2] > data.size + 8:
                return 4, r + c
        for j in range(STATE_ROWS):
            st[q, j] = s[j]
        counts[q] = c
        firstw[q] = _fill(buf, cur, col, ticks, r, c, last0[q], seg_start, n_ticks)
        r += c
        if rc[2] > data.size + 8:
            return 4, r
    if r != n_spikes:
        return 5, r
    if rc[2] > data.size + 5:
        return 4, r
    return 0, r
