"""Compiled kernels of :mod:`viform.vision.flow` (private; the module's notes explain the method).

* :func:`collect_before`, :func:`advance_rates` / :func:`force_rates`: multi-interval rates at
  many instants in one pass over the spikes (a ring of each pixel's last 2K spike ticks; the
  rate by :func:`ring_rate`, the adaptive test by the table of :func:`consistent_limits`);
* :func:`segment_log_light`: regions of similar light (Kruskal-ordered merging);
* :func:`shift_gain`, :func:`best_shift`, :func:`unexplained_share`: the layered cost of one
  region moving over a still background, and its search;
* :func:`gauss_newton_motion`: sub-pixel translation or affine motion of a region (Lucas–Kanade).

The layered-cost kernels compile with ``error_model="numpy"``: no zero-division check before each
float division (their denominators are variances and counts, never zero), the same IEEE results.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numba.cpython.unsafe.numbers import leading_zeros, trailing_zeros

from viform.imaging.multi_interval import interval_consistent
from viform.vision._spike_front import _ctpop

# ---------------------------------------------------------------------- images


@njit(cache=True)
def consistent_limits(n_max, span_max, noise_q, tolerance):
    """The adaptive test's verdicts as ranges: ``limits[n, span]`` = (first, last) whole interval
    (ticks) that :func:`~viform.imaging.multi_interval.interval_consistent` accepts beside n
    intervals spanning ``span`` ticks (mean span / n), for n < ``n_max`` and span < ``span_max``.

    The test accepts τ when τ/μ lies between two bounds; τ/μ rounds monotonically in τ, so the
    accepted whole τ form one range, found here with the test itself at its ends: a table lookup
    gives exactly the test's verdict. (first > last: none accepted.)
    """
    limits = np.zeros((n_max, span_max, 2), np.int64)
    limits[:, :, 0] = 1
    for n in range(1, n_max):
        for span in range(1, span_max):
            mean = span / n
            var = (1.0 / noise_q + 1.0 / (6.0 * mean * mean)) / 9.0
            centre = 1.0 - 1.0 / (9.0 * noise_q)
            reach = tolerance * np.sqrt(var * (1.0 + 1.0 / n))
            low = max(centre - reach, 0.0)
            high = centre + reach
            last = int(math.floor(high * high * high * mean)) + 2
            while last >= 1 and not interval_consistent(last, mean, n, noise_q, tolerance):
                if last / mean < low * low * low:  # below the range: nothing is accepted
                    last = 0
                    break
                last -= 1
            if last < 1:
                limits[n, span, 0] = 1
                limits[n, span, 1] = 0
                continue
            first = min(max(int(math.ceil(low * low * low * mean)) - 2, 1), last)
            while not interval_consistent(first, mean, n, noise_q, tolerance):
                first += 1
            while first > 1 and interval_consistent(first - 1, mean, n, noise_q, tolerance):
                first -= 1
            while interval_consistent(last + 1, mean, n, noise_q, tolerance):
                last += 1
            limits[n, span, 0] = first
            limits[n, span, 1] = last
    return limits


@njit(cache=True, inline="always")
def _accepted(interval, span, n, noise_q, tolerance, limits):
    """Whether the adaptive test accepts ``interval`` (ticks) beside n intervals spanning ``span`` ticks:
    from the table ``limits`` (:func:`consistent_limits`) where it reaches, else the test itself."""
    if n < limits.shape[0] and span < limits.shape[1]:
        return limits[n, span, 0] <= interval <= limits[n, span, 1]
    return interval_consistent(interval, span / n, n, noise_q, tolerance)


@njit(cache=True, inline="always")
def ring_rate(ring, j, count, n_after, k_side, lo_cut, hi_cut, adaptive, noise_q, tolerance, limits):
    """Rate (spikes per tick), intervals used, span (ticks) and censoring of pixel j at one instant,
    from its ring of spike ticks (``ring`` (P, size), size a power of two ≥ 2K; ``count`` spikes seen,
    the ``n_after`` most recent after the instant).

    The spikes at or before the instant (up to K, nearest first) and the ``n_after`` after it are read
    from the ring in place; ``lo_cut``/``hi_cut`` stand for a spike missing on that side (the stream's
    or the search's end). The span grows from the interval holding the instant one interval a side
    at a time, a side stopping at the first interval inconsistent with the span's mean (the
    Wilson–Hilferty test of :mod:`viform.imaging.multi_interval`) when ``adaptive``; ``limits``
    (:func:`consistent_limits`) holds that test's verdicts as ranges of whole intervals for spans up
    to its size (the same verdicts, without the divisions and root). With equal growth on both
    sides the rate is Σ 1/span over the windows of m intervals that hold the instant (unbiased for
    any stationary tick sequence, as there); else intervals / span. Inlined into its callers (no
    arrays passed: a call per pixel and instant would cost more than the arithmetic).
    """
    mask = ring.shape[1] - 1
    a0 = count - n_after  # ring index of the first spike after the instant; before it, the earlier ones
    nb = 0
    for b in range(k_side):
        idx = a0 - 1 - b
        if idx < 0 or idx <= count - ring.shape[1] - 1:
            break
        nb += 1
    na = n_after
    lo = ring[j, (a0 - 1) & mask] if nb > 0 else lo_cut
    hi = ring[j, a0 & mask] if na > 0 else hi_cut
    cut = nb == 0 or na == 0
    n = 1
    i_b = 1
    i_a = 1
    grow_b = not cut and nb > 1
    grow_a = not cut and na > 1
    while grow_b or grow_a:
        if grow_b:
            new = ring[j, (a0 - i_b) & mask] - ring[j, (a0 - 1 - i_b) & mask]
            ok = not adaptive or _accepted(new, hi - lo, n, noise_q, tolerance, limits)
            if ok:
                lo = ring[j, (a0 - 1 - i_b) & mask]
                i_b += 1
                n += 1
                grow_b = i_b < nb
            else:
                grow_b = False
        if grow_a:
            new = ring[j, (a0 + i_a) & mask] - ring[j, (a0 + i_a - 1) & mask]
            ok = not adaptive or _accepted(new, hi - lo, n, noise_q, tolerance, limits)
            if ok:
                hi = ring[j, (a0 + i_a) & mask]
                i_a += 1
                n += 1
                grow_a = i_a < na
            else:
                grow_a = False
    if i_b == i_a and not cut:
        total = 0.0
        for w in range(i_b):  # after[i_b − 1 − w] − before[w]
            total += 1.0 / (ring[j, (a0 + i_b - 1 - w) & mask] - ring[j, (a0 - 1 - w) & mask])
        rate = total
    else:
        rate = n / max(hi - lo, 1)
    return rate, n, hi - lo, cut


@njit(cache=True)
def _pack_ticks(bits8, t0, t1, j0, width, acc, words):
    """Each pixel's spikes of ticks [t0, t1) (t1 − t0 ≤ 64) as one word, tick t0 in bit 0.

    ``bits8`` (n, P8) uint64: 8 pixels' bytes (0 or 1) per word. A shift and an OR per 8 pixels
    and tick put up to 8 ticks of each pixel in its byte of ``acc`` (8, width / 8) uint64; the bytes
    of the 8 groups then make the pixel's word (``words``, the chunk's ``width`` pixels).
    """
    q0 = j0 // 8
    w8 = (width + 7) // 8
    n_groups = (t1 - t0 + 7) // 8
    for g in range(n_groups):
        row_acc = acc[g]
        for q in range(w8):
            row_acc[q] = 0
        for r in range(min(8, t1 - t0 - 8 * g)):
            row = bits8[t0 + 8 * g + r]
            sh = np.uint64(r)
            for q in range(w8):
                row_acc[q] |= row[q0 + q] << sh
    bytes_ = acc.view(np.uint8)  # (8, 8 · w8): byte j of group g holds ticks 8g … 8g + 7 of pixel j
    for jj in range(width):
        words[jj] = 0
    for g in range(n_groups):
        sh = np.uint64(8 * g)
        row_b = bytes_[g]
        for jj in range(width):
            words[jj] |= np.uint64(row_b[jj]) << sh


@njit(cache=True, parallel=True)
def advance_rates(bits8, n, first, ring, count, next_inst, instants, m_all, k_side, adaptive, noise_q, tolerance,
                  limits, lo_cut, out_rate, out_used, out_span, out_cut):
    """Feed ticks [first, first + n) of ``bits8`` to every pixel's ring of spike ticks
    (``ring`` (P, size), size a power of two ≥ 2K; ``count`` the spikes seen per pixel).

    ``bits8`` (n, ⌈P/8⌉) uint64 holds the ticks' bytes (0 or 1, one per pixel, the last word
    padded with zeros). Whenever a pixel has K spikes after its next pending instant, that
    instant's rate is computed and written to slot ``m % n_slots`` of the outputs (n_slots, P).
    A pixel with all ``m_all`` instants of the pass done is left alone (nothing reads its ring
    again). Ticks are taken 64 at a time: each pixel's spikes among them are packed into one
    word (:func:`_pack_ticks`), then walked lowest bit first (LLVM's count of trailing zeros),
    the pixel's ring staying in cache; a word wholly at or before the pixel's next instant only
    leaves its last ``size`` spikes in the ring (the earlier ones would be overwritten), so only
    those are written.
    """
    p = count.size
    m_total = instants.size
    n_slots = out_rate.shape[0]
    size = ring.shape[1]
    mask = size - 1
    chunk = 1024
    one = np.uint64(1)
    for ch in prange((p + chunk - 1) // chunk):
        j0 = ch * chunk
        width = min(j0 + chunk, p) - j0
        pending = False
        for jj in range(width):
            if next_inst[j0 + jj] < m_all:
                pending = True
                break
        if not pending:
            continue
        words = np.empty(chunk, np.uint64)
        acc = np.empty((8, chunk // 8), np.uint64)
        for t0 in range(0, n, 64):
            t1 = min(n, t0 + 64)
            _pack_ticks(bits8, t0, t1, j0, width, acc, words)
            base = first + t0
            for jj in range(width):
                word = words[jj]
                if word == 0:
                    continue
                j = j0 + jj
                m = next_inst[j]
                if m >= m_all:
                    continue
                c = count[j]
                if m >= m_total or base + t1 - t0 - 1 <= instants[m]:
                    # no instant completes within this word: only its last `size` spikes stay in the ring
                    skip = np.int64(_ctpop(word)) - size
                    if skip > 0:
                        c += skip
                        for _ in range(skip):
                            word &= word - one
                    while word != 0:
                        ring[j, c & mask] = base + np.int64(trailing_zeros(word))
                        word &= word - one
                        c += 1
                    count[j] = c
                    continue
                while word != 0:
                    ring[j, c & mask] = base + np.int64(trailing_zeros(word))
                    word &= word - one
                    c += 1
                    while c >= k_side and m < m_total and ring[j, (c - k_side) & mask] > instants[m]:
                        r, used, span, cut = ring_rate(ring, j, c, k_side, k_side, lo_cut, 0, adaptive, noise_q,
                                                       tolerance, limits)
                        s = m % n_slots
                        out_rate[s, j] = r
                        out_used[s, j] = used
                        out_span[s, j] = span
                        out_cut[s, j] = cut
                        m += 1
                    if m >= m_all:
                        break  # the pixel is done: its ring is not read again
                count[j] = c
                next_inst[j] = m


@njit(cache=True, parallel=True)
def collect_before(bits8, n, first, k_side, nearest, found):
    """Ticks [first, first + n) of ``bits8`` read from the last back: each pixel with fewer than
    ``k_side`` spikes ``found`` takes its spikes nearest the end first (``nearest[j, i]``, the i-th
    nearest found), until it has K. Chunks of pixels that all have K are not read.
    """
    p = found.size
    chunk = 1024
    one = np.uint64(1)
    for ch in prange((p + chunk - 1) // chunk):
        j0 = ch * chunk
        width = min(j0 + chunk, p) - j0
        words = np.empty(chunk, np.uint64)
        acc = np.empty((8, chunk // 8), np.uint64)
        t1 = n
        while t1 > 0:
            short = False
            for jj in range(width):
                if found[j0 + jj] < k_side:
                    short = True
                    break
            if not short:
                break
            t0 = max(0, t1 - 64)
            _pack_ticks(bits8, t0, t1, j0, width, acc, words)
            for jj in range(width):
                j = j0 + jj
                c = found[j]
                word = words[jj]
                while word != 0 and c < k_side:
                    high = 63 - np.int64(leading_zeros(word))
                    nearest[j, c] = first + t0 + high
                    word ^= one << np.uint64(high)
                    c += 1
                found[j] = c
            t1 = t0


@njit(cache=True, parallel=True)
def force_rates(ring, count, next_inst, instants, upto, k_side, adaptive, noise_q, tolerance, limits, lo_cut,
                hi_cut,
                out_rate, out_used, out_span, out_cut):
    """Complete every pending instant before index ``upto`` with the spikes seen so far (fewer
    than K after it: the search stopped at ``hi_cut``)."""
    p = count.size
    n_slots = out_rate.shape[0]
    size = ring.shape[1]
    mask = size - 1
    for j in prange(p):
        if next_inst[j] >= upto:
            continue
        c = count[j]
        while next_inst[j] < upto:
            m = next_inst[j]
            k = instants[m]
            n_after = 0
            while n_after < min(k_side, c) and n_after < size and ring[j, (c - 1 - n_after) & mask] > k:
                n_after += 1
            r, used, span, cut = ring_rate(ring, j, c, n_after, k_side, lo_cut, hi_cut, adaptive, noise_q,
                                           tolerance, limits)
            s = m % n_slots
            out_rate[s, j] = r
            out_used[s, j] = used
            out_span[s, j] = span
            out_cut[s, j] = cut
            next_inst[j] = m + 1


# ---------------------------------------------------------------------- regions


@njit(cache=True)
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def segment_log_light(log_light, sigma, tolerance, slack, n_bins):
    """Regions of similar light: 4-neighbours are merged smallest difference first (bucketed), two
    regions joining when each end of the edge lies within ``tolerance``·σ + ``slack`` of the other
    region's mean (so a ramp does not chain unlike regions together). Returns (labels, count)."""
    h, w = log_light.shape
    n = h * w
    flat = log_light.ravel()
    sig = sigma.ravel()
    m = 2 * n - h - w
    ei = np.empty(m, np.int64)
    ej = np.empty(m, np.int64)
    wt = np.empty(m)
    top = 0.0
    for i in range(n):
        top = max(top, tolerance * sig[i] + slack)
    top = 2.0 * top + 1e-12
    k = 0
    for r in range(h):
        for c in range(w):
            i = r * w + c
            if c + 1 < w:
                ei[k] = i
                ej[k] = i + 1
                wt[k] = abs(flat[i] - flat[i + 1])
                k += 1
            if r + 1 < h:
                ei[k] = i
                ej[k] = i + w
                wt[k] = abs(flat[i] - flat[i + w])
                k += 1
    counts = np.zeros(n_bins + 1, np.int64)
    bucket = np.empty(m, np.int64)
    for e in range(m):
        b = min(int(wt[e] / top * n_bins), n_bins)
        bucket[e] = b
        counts[b] += 1
    start = np.zeros(n_bins + 2, np.int64)
    for q in range(n_bins + 1):
        start[q + 1] = start[q] + counts[q]
    order = np.empty(m, np.int64)
    fill = start[:-1].copy()
    for e in range(m):
        order[fill[bucket[e]]] = e
        fill[bucket[e]] += 1
    parent = np.arange(n)
    total = flat.copy()
    size = np.ones(n)
    for t in range(start[n_bins]):  # the top bucket never merges
        e = order[t]
        i = ei[e]
        j = ej[e]
        a = _find(parent, i)
        b = _find(parent, j)
        if a == b:
            continue
        mean_a = total[a] / size[a]
        mean_b = total[b] / size[b]
        if abs(flat[i] - mean_b) <= tolerance * sig[i] + slack and abs(flat[j] - mean_a) <= tolerance * sig[j] + slack:
            if size[a] < size[b]:
                a, b = b, a
            parent[b] = a
            total[a] += total[b]
            size[a] += size[b]
    labels = np.empty(n, np.int32)
    remap = np.full(n, -1, np.int32)
    cnt = 0
    for i in range(n):
        root = _find(parent, i)
        if remap[root] < 0:
            remap[root] = cnt
            cnt += 1
        labels[i] = remap[root]
    return labels.reshape(h, w), cnt


# ---------------------------------------------------------------------- the layered cost


@njit(cache=True, error_model="numpy")
def bilinear(img, y, x):
    h, w = img.shape
    y = min(max(y, 0.0), h - 1.0)
    x = min(max(x, 0.0), w - 1.0)
    y0 = min(int(y), max(h - 2, 0))
    x0 = min(int(x), max(w - 2, 0))
    y1 = min(y0 + 1, h - 1)
    x1 = min(x0 + 1, w - 1)
    fy = y - y0
    fx = x - x0
    return ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x1])
            + fy * ((1 - fx) * img[y1, x0] + fx * img[y1, x1]))


@njit(cache=True, error_model="numpy")
def _shift_gain_whole(log0, log1, var0, var1, still, labels, region, rows, cols, iy, ix, cap, unknown, exception):
    """:func:`shift_gain` for a whole-pixel shift: every landing is a pixel, so no interpolation (the same
    sums: bilinear weights of 0 and 1 reproduce the pixel exactly)."""
    h, w = log0.shape
    total = 0.0
    for k in range(rows.size):
        r = rows[k]
        c = cols[k]
        y = r + iy
        x = c + ix
        if y < 0 or x < 0 or y > h - 1 or x > w - 1:
            continue
        v = log1[y, x] - log0[r, c]
        e = min(v * v / (var0[r, c] + var1[y, x]), cap)
        s = still[y, x]
        total += min(e, s + exception) - s
        sr = r - iy
        sc = c - ix
        if not (0 <= sr < h and 0 <= sc < w and labels[sr, sc] == region):
            total += min(unknown, still[r, c] + exception) - still[r, c]
    return total


@njit(cache=True, error_model="numpy")
def shift_gain(log0, log1, var0, var1, still, labels, region, rows, cols, dy, dx, cap, unknown, exception):
    """Cost of "``region`` moved by (dy, dx), all else still" minus the cost of "nothing moved".

    Only the region's pixels and where they land differ between the two: a pixel x of the
    region lands on x + d (residual log1(x + d) − log0(x), normalized by the noise, capped at
    ``cap``) instead of the still residual there; a region pixel nothing lands on is uncovered
    background of unknown light (cost ``unknown``). Any landing may instead be left still at
    ``exception`` more than the still cost (another object in the way).
    """
    if dy == math.floor(dy) and dx == math.floor(dx):
        return _shift_gain_whole(log0, log1, var0, var1, still, labels, region, rows, cols, int(dy), int(dx), cap,
                                 unknown, exception)
    h, w = log0.shape
    total = 0.0
    for k in range(rows.size):
        r = rows[k]
        c = cols[k]
        y = r + dy
        x = c + dx
        if y < 0.0 or x < 0.0 or y > h - 1 or x > w - 1:
            continue  # it left the field: no evidence either way
        # bilinear (:func:`bilinear`, the same arithmetic) of log1 and still at one landing
        y0 = min(int(y), max(h - 2, 0))
        x0 = min(int(x), max(w - 2, 0))
        y1 = min(y0 + 1, h - 1)
        x1 = min(x0 + 1, w - 1)
        fy = y - y0
        fx = x - x0
        v = ((1 - fy) * ((1 - fx) * log1[y0, x0] + fx * log1[y0, x1])
             + fy * ((1 - fx) * log1[y1, x0] + fx * log1[y1, x1])) - log0[r, c]
        e = min(v * v / (var0[r, c] + var1[int(np.rint(y)), int(np.rint(x))]), cap)
        s = ((1 - fy) * ((1 - fx) * still[y0, x0] + fx * still[y0, x1])
             + fy * ((1 - fx) * still[y1, x0] + fx * still[y1, x1]))
        total += min(e, s + exception) - s
        sr = int(np.rint(r - dy))
        sc = int(np.rint(c - dx))
        if not (0 <= sr < h and 0 <= sc < w and labels[sr, sc] == region):
            total += min(unknown, still[r, c] + exception) - still[r, c]
    return total


@njit(cache=True, error_model="numpy")
def shift_gains(log0, log1, var0, var1, still, labels, region, rows, cols, dys, dxs, cap, unknown, exception):
    """:func:`shift_gain` at each shift (``dys[i]``, ``dxs[i]``), none of them whole-pixel in both axes, in
    one pass over the pixels: each entry is the sum :func:`shift_gain` returns, to the last bit (the same
    arithmetic, summed over the pixels in their order)."""
    h, w = log0.shape
    m = dys.size
    out = np.zeros(m)
    for k in range(rows.size):
        r = rows[k]
        c = cols[k]
        a0 = log0[r, c]
        b0 = var0[r, c]
        s0 = still[r, c]
        uncovered = min(unknown, s0 + exception) - s0
        for i in range(m):
            dy = dys[i]
            dx = dxs[i]
            y = r + dy
            x = c + dx
            if y < 0.0 or x < 0.0 or y > h - 1 or x > w - 1:
                continue
            y0 = min(int(y), max(h - 2, 0))
            x0 = min(int(x), max(w - 2, 0))
            y1 = min(y0 + 1, h - 1)
            x1 = min(x0 + 1, w - 1)
            fy = y - y0
            fx = x - x0
            v = ((1 - fy) * ((1 - fx) * log1[y0, x0] + fx * log1[y0, x1])
                 + fy * ((1 - fx) * log1[y1, x0] + fx * log1[y1, x1])) - a0
            e = min(v * v / (b0 + var1[int(np.rint(y)), int(np.rint(x))]), cap)
            s = ((1 - fy) * ((1 - fx) * still[y0, x0] + fx * still[y0, x1])
                 + fy * ((1 - fx) * still[y1, x0] + fx * still[y1, x1]))
            total = out[i] + (min(e, s + exception) - s)
            sr = int(np.rint(r - dy))
            sc = int(np.rint(c - dx))
            if not (0 <= sr < h and 0 <= sc < w and labels[sr, sc] == region):
                total += uncovered
            out[i] = total
    return out


@njit(cache=True, error_model="numpy")
def grid_gains(log0, log1, var0, var1, still, labels, region, rows, cols, shifts_y, shifts_x, cap, unknown,
               exception):
    """:func:`shift_gain` at every whole-pixel shift (``shifts_y[i]``, ``shifts_x[j]``): (ny, nx).

    The pixels are the outer loop (each pixel's landings for neighbouring shifts are neighbours
    in memory) and every shift's sum runs over the pixels in their order, so each entry is the
    sum :func:`shift_gain` returns for that shift, to the last bit.
    """
    h, w = log0.shape
    ny = shifts_y.size
    nx = shifts_x.size
    out = np.zeros((ny, nx))
    for k in range(rows.size):
        r = rows[k]
        c = cols[k]
        a0 = log0[r, c]
        b0 = var0[r, c]
        s0 = still[r, c]
        uncovered = min(unknown, s0 + exception) - s0
        for i in range(ny):
            y = r + shifts_y[i]
            if y < 0 or y > h - 1:
                continue
            sr = r - shifts_y[i]
            row_in = 0 <= sr < h
            for j in range(nx):
                x = c + shifts_x[j]
                if x < 0 or x > w - 1:
                    continue
                v = log1[y, x] - a0
                e = min(v * v / (b0 + var1[y, x]), cap)
                s = still[y, x]
                g = out[i, j] + (min(e, s + exception) - s)
                sc = c - shifts_x[j]
                if not (row_in and 0 <= sc < w and labels[sr, sc] == region):
                    g += uncovered
                out[i, j] = g
    return out


@njit(cache=True, error_model="numpy")
def best_shift(log0, log1, var0, var1, still, labels, region, rows, cols, coarse_rows, coarse_cols, radius, cap,
               unknown, exception):
    """The shift with the lowest :func:`shift_gain`: an integer grid of step 2 within ``radius``
    on the ``coarse_*`` pixels (a sample weighted to the region's rim, where a uniform region's
    motion shows), then steps 1 and 0.5 around the best on all of the region's pixels
    (Gauss–Newton refines further). Returns (dy, dx, gain). Whole-pixel shifts are summed
    pixel by pixel for many shifts at once (:func:`grid_gains`), the eight half-pixel ones likewise
    (:func:`shift_gains`)."""
    grid = np.arange(-radius, radius + 1, 2)
    coarse = grid_gains(log0, log1, var0, var1, still, labels, region, coarse_rows, coarse_cols, grid, grid, cap,
                        unknown, exception)
    best = 0.0
    by = 0
    bx = 0
    for i in range(grid.size):
        for j in range(grid.size):
            if coarse[i, j] < best:
                best = coarse[i, j]
                by = grid[i]
                bx = grid[j]
    near = np.arange(-2, 3)
    block = grid_gains(log0, log1, var0, var1, still, labels, region, rows, cols, by + near, bx + near, cap,
                       unknown, exception)
    best = block[2, 2]
    if by != 0 or bx != 0:
        if abs(by) <= 2 and abs(bx) <= 2:
            zero = block[2 - by, 2 - bx]
        else:
            zero = shift_gain(log0, log1, var0, var1, still, labels, region, rows, cols, 0.0, 0.0, cap, unknown,
                              exception)
        if zero <= best:
            best = zero
            by = 0
            bx = 0
            block = grid_gains(log0, log1, var0, var1, still, labels, region, rows, cols, near, near, cap, unknown,
                               exception)
    # step 1 (the 5×5 around the best), then step 0.5 (its 8 neighbours)
    cy = by
    cx = bx
    fy = float(by)
    fx = float(bx)
    for i in range(-2, 3):
        for j in range(-2, 3):
            if i == 0 and j == 0:
                continue
            if block[i + 2, j + 2] < best:
                best = block[i + 2, j + 2]
                fy = float(cy + i)
                fx = float(cx + j)
    cyf = fy
    cxf = fx
    dys = np.empty(8)
    dxs = np.empty(8)
    n = 0
    for i in range(-1, 2):
        for j in range(-1, 2):
            if i == 0 and j == 0:
                continue
            dys[n] = cyf + i * 0.5
            dxs[n] = cxf + j * 0.5
            n += 1
    half = shift_gains(log0, log1, var0, var1, still, labels, region, rows, cols, dys, dxs, cap, unknown, exception)
    for n in range(8):
        if half[n] < best:
            best = half[n]
            fy = dys[n]
            fx = dxs[n]
    return fy, fx, best


@njit(cache=True, error_model="numpy")
def unexplained_share(log0, log1, var0, var1, still, rows, cols, dy, dx, cap, exception):
    """Share of the region's in-field landings that the shift leaves unexplained (kept still)."""
    h, w = log0.shape
    bad = 0
    n = 0
    for k in range(rows.size):
        r = rows[k]
        c = cols[k]
        y = r + dy
        x = c + dx
        if y < 0.0 or x < 0.0 or y > h - 1 or x > w - 1:
            continue
        v = bilinear(log1, y, x) - log0[r, c]
        e = min(v * v / (var0[r, c] + var1[int(np.rint(y)), int(np.rint(x))]), cap)
        n += 1
        if e > bilinear(still, y, x) + exception:
            bad += 1
    return bad / max(n, 1)


@njit(cache=True, error_model="numpy")
def gauss_newton_motion(smooth0, smooth1, grad_x1, grad_y1, weight, fractions, rows, cols, params, affine,
                        iterations, cap, ridge):
    """Gauss–Newton (Lucas–Kanade) on Σ_j Σ_x w_j·(s1_j(x + f_j·d(x)) − s0(x))² over the listed pixels.

    ``smooth1``, ``grad_*1`` and ``weight`` are stacks (J, H, W) of later images, their
    gradients and weights; frame j lies at the fraction f_j = ``fractions[j]`` of the interval,
    so a constant velocity moves a pixel by f_j·d by then (one frame at 1.0: the plain pair).
    ``params`` (tx, ty, a, b, c, e): d(x) = (tx + a·X + b·Y, ty + c·X + e·Y), X and Y the pixel's
    offset from the pixels' centroid in units of their largest offset; a translation when not
    ``affine``; the affine terms cost ``ridge``·term² (a term of 1 moves the region's far edge
    by 1 px), so directions the data leave open stay a translation. Pixels whose weighted
    residual² exceeds ``cap`` sit out each step (and count ``cap`` in the cost). Returns
    (params, capped cost before the last step, pixel-frames used, centroid y, centroid x, scale).
    """
    n_frames, h, w = smooth1.shape
    n = rows.size
    cy = 0.0
    cx = 0.0
    for k in range(n):
        cy += rows[k]
        cx += cols[k]
    cy /= max(n, 1)
    cx /= max(n, 1)
    scale = 1.0
    for k in range(n):
        scale = max(scale, abs(rows[k] - cy), abs(cols[k] - cx))
    # each pixel's offset from the centroid, computed once (the same divisions every step made)
    xs = np.empty(n)
    ys = np.empty(n)
    for k in range(n):
        xs[k] = (cols[k] - cx) / scale
        ys[k] = (rows[k] - cy) / scale
    m = 6 if affine else 2
    cost = 0.0
    used = 0
    hess = np.zeros((m, m))
    grad = np.zeros(m)
    jac = np.zeros(6)
    for _ in range(iterations):
        hess[:] = 0.0
        grad[:] = 0.0
        cost = 0.0
        used = 0
        for f in range(n_frames):
            frac = fractions[f]
            for k in range(n):
                r = rows[k]
                c = cols[k]
                xx = xs[k]
                yy = ys[k]
                y = r + frac * (params[1] + params[4] * xx + params[5] * yy)
                x = c + frac * (params[0] + params[2] * xx + params[3] * yy)
                if y < 0.0 or x < 0.0 or y > h - 1 or x > w - 1:
                    continue
                # :func:`bilinear` of the image and its two gradients at one point (the same arithmetic)
                yc = min(max(y, 0.0), h - 1.0)
                xc = min(max(x, 0.0), w - 1.0)
                y0 = min(int(yc), max(h - 2, 0))
                x0 = min(int(xc), max(w - 2, 0))
                y1 = min(y0 + 1, h - 1)
                x1 = min(x0 + 1, w - 1)
                fy = yc - y0
                fx = xc - x0
                res = ((1 - fy) * ((1 - fx) * smooth1[f, y0, x0] + fx * smooth1[f, y0, x1])
                       + fy * ((1 - fx) * smooth1[f, y1, x0] + fx * smooth1[f, y1, x1])) - smooth0[r, c]
                ww = weight[f, r, c]
                if res * res * ww > cap:
                    cost += cap
                    continue
                gx = frac * ((1 - fy) * ((1 - fx) * grad_x1[f, y0, x0] + fx * grad_x1[f, y0, x1])
                             + fy * ((1 - fx) * grad_x1[f, y1, x0] + fx * grad_x1[f, y1, x1]))
                gy = frac * ((1 - fy) * ((1 - fx) * grad_y1[f, y0, x0] + fx * grad_y1[f, y0, x1])
                             + fy * ((1 - fx) * grad_y1[f, y1, x0] + fx * grad_y1[f, y1, x1]))
                jac[0] = gx
                jac[1] = gy
                if affine:
                    jac[2] = gx * xx
                    jac[3] = gx * yy
                    jac[4] = gy * xx
                    jac[5] = gy * yy
                for i in range(m):
                    wj = ww * jac[i]  # (ww·jac_i)·…, as the products were always grouped
                    grad[i] += wj * res
                    for j in range(m):
                        hess[i, j] += wj * jac[j]
                cost += res * res * ww
                used += 1
        for i in range(2, m):
            hess[i, i] += ridge
            grad[i] += ridge * params[i]
            cost += ridge * params[i] * params[i]
        for i in range(m):
            hess[i, i] += 1e-9 + 1e-3 * hess[i, i]
        step = np.linalg.solve(hess, -grad)
        for i in range(m):
            params[i] += step[i]
        if abs(step[0]) + abs(step[1]) < 1e-3:
            break
    return params, cost, used, cy, cx, scale


@njit(cache=True, error_model="numpy")
def warp_costs(smooth0, smooth1, weight, rows, cols, flow_u, flow_v, cap):
    """min(w·(s1(x + f(x)) − s0(x))², cap) at each listed pixel, f a per-pixel flow (px); a pixel
    sent out of the field costs ``cap``."""
    h, w = smooth0.shape
    out = np.empty(rows.size)
    for k in range(rows.size):
        r = rows[k]
        c = cols[k]
        y = r + flow_v[r, c]
        x = c + flow_u[r, c]
        if y < 0.0 or x < 0.0 or y > h - 1 or x > w - 1 or not (math.isfinite(y) and math.isfinite(x)):
            out[k] = cap
            continue
        res = bilinear(smooth1, y, x) - smooth0[r, c]
        out[k] = min(res * res * weight[r, c], cap)
    return out


@njit(cache=True, error_model="numpy")
def warp_costs_at(smooth0, smooth1, weight, rows, cols, flow_u, flow_v, cap):
    """:func:`warp_costs` with the flow given per listed pixel (``flow_u[k]``, ``flow_v[k]``, px)."""
    h, w = smooth0.shape
    out = np.empty(rows.size)
    for k in range(rows.size):
        r = rows[k]
        c = cols[k]
        y = r + flow_v[k]
        x = c + flow_u[k]
        if y < 0.0 or x < 0.0 or y > h - 1 or x > w - 1 or not (math.isfinite(y) and math.isfinite(x)):
            out[k] = cap
            continue
        res = bilinear(smooth1, y, x) - smooth0[r, c]
        out[k] = min(res * res * weight[r, c], cap)
    return out


@njit(cache=True)
def inner_depth(inside):
    """City-block (L1) distance of each pixel of the mask ``inside`` to the nearest pixel outside it,
    the frame around the array counting as outside (0 outside the mask). A pixel survives n
    erosions by the 4-neighbour cross (padded with False) exactly where its depth exceeds n."""
    h, w = inside.shape
    big = h + w + 2
    depth = np.empty((h, w), np.int64)
    for r in range(h):
        for c in range(w):
            if not inside[r, c]:
                depth[r, c] = 0
                continue
            up = depth[r - 1, c] if r > 0 else 0
            left = depth[r, c - 1] if c > 0 else 0
            depth[r, c] = min(min(up, left) + 1, big)
    for r in range(h - 1, -1, -1):
        for c in range(w - 1, -1, -1):
            if depth[r, c] == 0:
                continue
            down = depth[r + 1, c] if r < h - 1 else 0
            right = depth[r, c + 1] if c < w - 1 else 0
            depth[r, c] = min(depth[r, c], min(down, right) + 1)
    return depth


@njit(cache=True)
def rim_mean_exceeds(rim_r, rim_c, values, h, w, half, threshold):
    """For each listed pixel: whether the mean of ``values`` over the listed pixels within its
    (2·half + 1)² square exceeds ``threshold`` (the 5×5 mean of a quantity known on the rim only)."""
    n = rim_r.size
    out = np.zeros(n, np.bool_)
    if n == 0:
        return out
    r0 = rim_r.min()
    c0 = rim_c.min()
    bh = rim_r.max() - r0 + 1
    bw = rim_c.max() - c0 + 1
    total = np.zeros((bh, bw))
    count = np.zeros((bh, bw))
    for k in range(n):
        total[rim_r[k] - r0, rim_c[k] - c0] += values[k]
        count[rim_r[k] - r0, rim_c[k] - c0] += 1.0
    for k in range(n):
        r = rim_r[k] - r0
        c = rim_c[k] - c0
        s = 0.0
        m = 0.0
        for i in range(max(0, r - half), min(bh, r + half + 1)):
            for j in range(max(0, c - half), min(bw, c + half + 1)):
                s += total[i, j]
                m += count[i, j]
        out[k] = s / max(m, 1e-9) > threshold
    return out
