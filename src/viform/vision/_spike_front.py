"""Compiled kernels of the spike tracker: the change front end on packed bits, and grouping.

The front end reads spikes as packed bits (64 pixels a word, least significant bit first, the
``.dat`` layout): per tick it visits only the words that hold a spike, and per spike it touches
three numbers of that pixel (its last spike, the start of its open window, the intervals
counted in it); a word that fires densely (most pixels every few ticks, at a low threshold Q)
is instead transposed over a run of up to 64 ticks, so each pixel's spikes in the run are one
word whose bit counts give the same numbers at once. Once per output step every pixel's window
is turned into an interval estimate and compared with its background (:func:`_evaluate`); the
foreground comes out as packed bits again. Pixels are independent, so the words are split into
chunks run in parallel, each chunk runs groups of words through all of a block's ticks in turn
(a group's state stays in cache), and the result depends neither on the chunking nor on the
grouping.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.extending import intrinsic

#: A window of fewer intervals than this, spanning fewer ticks than :data:`MIN_SPAN_TICKS`, is
#: joined with the previous step's: short intervals are dominated by the one-tick quantization.
MIN_INTERVALS = 4
MIN_SPAN_TICKS = 8

#: Columns of the per-spike state ``spk`` (n_pixels, 4) int64.
LAST, BEFORE, FIRST, COUNT = 0, 1, 2, 3


@intrinsic
def _cttz(typingctx, x):  # pragma: no cover - compiled
    """Count of trailing zero bits of a uint64 (LLVM's cttz; x ≠ 0)."""
    sig = types.uint64(types.uint64)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(i64, [i64, ir.IntType(1)])
        fn = builder.module.declare_intrinsic("llvm.cttz", [i64], fnty)
        return builder.call(fn, [args[0], ir.Constant(ir.IntType(1), 1)])

    return sig, codegen


@intrinsic
def _ctlz(typingctx, x):  # pragma: no cover - compiled
    """Count of leading zero bits of a uint64 (LLVM's ctlz; x ≠ 0)."""
    sig = types.uint64(types.uint64)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(i64, [i64, ir.IntType(1)])
        fn = builder.module.declare_intrinsic("llvm.ctlz", [i64], fnty)
        return builder.call(fn, [args[0], ir.Constant(ir.IntType(1), 1)])

    return sig, codegen


@intrinsic
def _ctpop(typingctx, x):  # pragma: no cover - compiled
    """Count of set bits of a uint64 (LLVM's ctpop)."""
    sig = types.uint64(types.uint64)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fn = builder.module.declare_intrinsic("llvm.ctpop", [i64], ir.FunctionType(i64, [i64]))
        return builder.call(fn, [args[0]])

    return sig, codegen


@njit(cache=True, inline="always")
def _transpose64(a):  # pragma: no cover - compiled
    """Transpose a 64 × 64 bit matrix in place: bit j of ``a[k]`` becomes bit k of ``a[j]`` (block swaps,
    Warren, *Hacker's Delight*, 2nd ed., §7-3)."""
    j = 32
    m = np.uint64(0x00000000FFFFFFFF)
    while j != 0:
        k = 0
        while k < 64:
            t = ((a[k] >> np.uint64(j)) ^ a[k + j]) & m
            a[k + j] ^= t
            a[k] ^= t << np.uint64(j)
            k = (k + j + 1) & ~j
        j >>= 1
        m ^= m << np.uint64(j)


#: A word that held at least this many spikes per tick over the last run of at least ``DENSE_RUN_TICKS`` ticks
#: (the ticks up to a step's end, 64 at most) is ingested pixel by pixel over the next (its 64 × T bits
#: transposed: each pixel's spikes in one word) rather than spike by spike; both give the same state.
DENSE_SPIKES_PER_TICK = 1.0
DENSE_RUN_TICKS = 24


@njit(cache=True, inline="always")
def _ingest_spike(s, tick, spk, total, anchor, bg, censored):  # pragma: no cover - compiled
    """One spike of pixel ``s`` at ``tick``."""
    lt = spk[s, LAST]
    if lt < 0:  # the first spike opens the first interval; the one it ends reaches
        anchor[s] = tick  # back before the stream: the background is at least tick + 1
        if bg[s] <= 0.0:
            bg[s] = tick + 1.0
            censored[s] = True
    else:
        if spk[s, COUNT] == 0:
            spk[s, FIRST] = tick  # the end of the step's first interval
        spk[s, COUNT] += 1
    spk[s, BEFORE] = lt
    spk[s, LAST] = tick
    total[s] += 1


@njit(cache=True, inline="always")
def _ingest_pixel(s, t0, m, spk, total, anchor, bg, censored):  # pragma: no cover - compiled
    """All spikes of pixel ``s`` in the ticks t0 … t0 + 63 at once (bit k of ``m``: a spike at t0 + k): the
    state :func:`_ingest_spike` leaves after them one by one."""
    c = _ctpop(m)
    k_last = 63 - _ctlz(m)
    lt = spk[s, LAST]
    ending = m  # the spikes that end an interval
    if lt < 0:
        first = t0 + _cttz(m)
        anchor[s] = first
        if bg[s] <= 0.0:
            bg[s] = first + 1.0
            censored[s] = True
        ending &= m - np.uint64(1)  # (the first spike ends none)
    if ending:
        if spk[s, COUNT] == 0:
            spk[s, FIRST] = t0 + _cttz(ending)
        spk[s, COUNT] += _ctpop(ending)
    if c >= 2:
        spk[s, BEFORE] = t0 + 63 - _ctlz(m & ~(np.uint64(1) << np.uint64(k_last)))
    else:
        spk[s, BEFORE] = lt
    spk[s, LAST] = t0 + k_last
    total[s] += c


@njit(cache=True, inline="always")
def _evaluate(s, tick, spk, anchor, span1, n1, win_span, win_n, mixed, bg, censored, fg, flag_since, prev, due,
              k_lo, k_hi, k_prime, k_left, background_ticks, hold_ticks):  # pragma: no cover - compiled
    """One pixel at the end of tick ``tick``: update its window and background; its foreground state (−1, 0, +1).

    Also sets ``due[s]``: the tick from which its silence alone could change that state (a pixel
    neither fired nor flagged is evaluated again only then).
    """
    lt = spk[s, LAST]
    q = prev[s]
    due[s] = np.inf
    if lt < 0:  # never fired: darker than the background primed around it, if silent for long enough
        f = 0
        if q > 0.0:
            if tick > q * k_prime:
                f = -1
                if flag_since[s] < 0:
                    flag_since[s] = tick
            else:
                due[s] = q * k_prime
        fg[s] = f
        return f
    n = spk[s, COUNT]
    drop = False
    if n > 0:  # new intervals since the last evaluation
        a = anchor[s]
        span = lt - a
        if n >= 2:
            # the step's first interval against the others: far apart, it belongs to the light before a change
            # (an object arrived or left during it), and the later ones are the light now
            head = spk[s, FIRST] - a
            inner = lt - spk[s, FIRST]
            if head * (n - 1) > (inner + 1.0) * k_left + (n - 1) or (head + 1.0) * (n - 1) * k_left < inner - 1.0:
                span = inner
                n -= 1
        p_span = span1[s]
        p_n = n1[s]
        # one interval far longer than the last step's: the light fell during it (an object left), so it
        # mixes two levels and says nothing of the light now
        drop = n == 1 and p_n > 0 and span * p_n > p_span * k_left
        tail = lt - spk[s, BEFORE]
        if n >= 2 and (tail - 1.0) * (n - 1) > (span - tail + 1.0) * k_left:
            # the step's last interval far longer than its others (one tick of slack each): the light fell
            # at the end of the step
            span = tail
            n = 1
            drop = True
        mixed[s] = drop
        # few short intervals: joined with the last step's, where the two agree (one tick of slack each)
        agree = p_n > 0 and (span - 1.0) * p_n <= (p_span + 1.0) * n * k_left \
            and (span + 1.0) * p_n * k_left >= (p_span - 1.0) * n
        if n < MIN_INTERVALS and span < MIN_SPAN_TICKS and agree:
            S = span + p_span
            N = n + p_n
        else:
            S = span
            N = n
        span1[s] = span
        n1[s] = n
        anchor[s] = lt
        spk[s, COUNT] = 0
        win_span[s] = S
        win_n[s] = N
    else:
        span = 0
        S = win_span[s]
        N = win_n[s]
        drop = mixed[s]
    silence = tick - lt  # the interval in progress is longer than this
    b = bg[s]
    if N == 0:  # one spike so far: the interval in progress only (silent objects since the start)
        f = 0
        if q > 0.0:
            if silence > q * k_prime:
                f = -1
                if flag_since[s] < 0:
                    flag_since[s] = tick
            else:
                due[s] = lt + q * k_prime
        fg[s] = f
        return f
    tau = S / N
    win_bright = (S + 1.0) / N < b * k_lo  # beyond the one-tick slack of the window's span
    win_dark = (S - 1.0) / N > b * k_hi
    # brighter while the interval in progress is still short: neither past the background's bound nor
    # past what the window's light allows (the object has gone)
    bright = win_bright and not drop and silence < b * k_lo and silence <= (S + 1.0) / N * k_left + 1.0
    if censored[s]:
        # the background is a lower bound (the first interval reaches back before the stream, or it was
        # primed from bounds): only "brighter" is known against it; a new interval that is not brighter
        # measures it
        f = 1 if bright else 0
        if n > 0 and drop:  # a mixed interval is shorter than the background's: a better lower bound
            bg[s] = max(b, tau)
        elif n > 0 and not win_bright:
            if q > 0.0 and ((S - 1.0) / N > q * k_prime or (S + 1.0) / N < q / k_prime):
                # far from the background primed around it: on an object since the start
                bg[s] = q
                prev[s] = 0.0
                f = 1 if tau < q else -1
            else:
                bg[s] = max(b, tau)  # a window straddling an object's departure must not lower the bound
            censored[s] = False
        if f != 0:
            if flag_since[s] < 0:
                flag_since[s] = tick
        else:
            flag_since[s] = -1
        fg[s] = f
        return f
    f = 0
    if bright:
        f = 1
    elif win_dark or silence - 1.0 > b * k_hi:
        f = -1
    if f != 0 and q > 0.0 and n > 0 and q * k_lo <= tau <= q * k_hi:
        # back to the background it had before something stayed on it: not an object's trail
        bg[s] = q
        prev[s] = 0.0
        f = 0
        b = q
        win_bright = win_dark = False
    if f != 0:
        fs = flag_since[s]
        if fs < 0:
            flag_since[s] = tick
        elif tick - fs > hold_ticks:  # stayed different: it is the background now
            if q <= 0.0:
                prev[s] = b
            if n > 0 and span > 0:
                t_step = span / n
                bg[s] = b + span / (background_ticks + span) * (t_step - b)
            elif f < 0:
                bg[s] = max(b, float(silence))
    else:
        flag_since[s] = -1
    if f == 0 and n > 0 and span > 0 and not win_bright and not win_dark:
        t_step = span / n  # the background follows the pixel only while they agree
        bg[s] = b + span / (background_ticks + span) * (t_step - b)
    if f == 0:
        due[s] = lt + bg[s] * k_hi + 1.0  # darker from then on, if silent
    fg[s] = f
    return f


# Without numba's reference counting (``_nrt=False``: it allocates nothing; the caller gives its scratch):
# each inlined helper's array arguments would otherwise be counted in and out atomically at every spike
# (4× slower), which the parallel loop's own body does not do.
# error_model="numpy", as numba compiles a parallel loop's body: a division by zero gives inf/nan, no check
@njit(cache=True, nogil=True, _nrt=False, error_model="numpy")
def _front_chunk(ch, bits, dense, count, words, first_tick, step_ticks, evaluate_at_end, chunk_lo, chunk_hi,
                 group_words, dense_run_ticks, dense_spikes_per_tick, n_pixels,
                 spk, total, fired, fg_bits, word_due, anchor, span1, n1, win_span, win_n, mixed, bg, censored,
                 fg, flag_since, prev, due, out, k_lo, k_hi, k_prime, k_left, background_ticks,
                 hold_ticks):  # pragma: no cover - compiled
    """Chunk ``ch`` of :func:`spike_front_block` (its scratch ``bits`` (64,), ``dense`` and ``count``
    (``group_words``,)): the work item of its parallel loop, compiled on its own (numba's parallel passes
    over so large a loop body were most of the front end's first compile)."""
    T = words.shape[0]
    # pixels are independent: a group of ``group_words`` words is run through all the block's ticks
    # before the next, so its pixels' state stays in cache; a run of ticks up to a step's end (64 at
    # most) at a time: words that held many spikes in the last run pixel by pixel, the others spike
    # by spike (the same state either way)
    for g0 in range(chunk_lo[ch], chunk_hi[ch], group_words):
        g1 = min(g0 + group_words, chunk_hi[ch])
        dense[:] = False
        step = 0
        t = 0
        while t < T:
            t0 = first_tick + t
            n = min(step_ticks - t0 % step_ticks, T - t, 64)
            long_run = n >= dense_run_ticks
            if long_run:
                count[:] = 0
            some_dense = False
            for i in range(g1 - g0):
                some_dense |= dense[i]
            for k in range(n):  # spike by spike
                for i in range(g0, g1):
                    if some_dense and dense[i - g0]:
                        continue
                    w = words[t + k, i]
                    if not w:
                        continue
                    fired[i] |= w
                    if long_run:
                        count[i - g0] += _ctpop(w)
                    while w:
                        s = i * 64 + _cttz(w)
                        w &= w - np.uint64(1)
                        _ingest_spike(s, t0 + k, spk, total, anchor, bg, censored)
            for i in range(g0, g1):
                if some_dense and dense[i - g0]:
                    # pixel by pixel: bit k of bits[j] is pixel j's spike at tick t0 + k
                    any_ = np.uint64(0)
                    for k in range(n):
                        w = words[t + k, i]
                        bits[k] = w
                        any_ |= w
                    for k in range(n, 64):
                        bits[k] = 0
                    fired[i] |= any_
                    _transpose64(bits)
                    while any_:
                        j = _cttz(any_)
                        any_ &= any_ - np.uint64(1)
                        m = bits[j]
                        count[i - g0] += _ctpop(m)
                        _ingest_pixel(i * 64 + j, t0, m, spk, total, anchor, bg, censored)
                dense[i - g0] = long_run and count[i - g0] >= n * dense_spikes_per_tick
            t += n
            tick = first_tick + t - 1
            if (tick + 1) % step_ticks == 0 or (evaluate_at_end and t == T):
                for i in range(g0, g1):
                    _evaluate_word(i, tick, n_pixels, spk, fired, fg_bits, word_due, anchor, span1, n1,
                                   win_span, win_n, mixed, bg, censored, fg, flag_since, prev, due, k_lo, k_hi,
                                   k_prime, k_left, background_ticks, hold_ticks)
                    out[step, i] = fg_bits[i]
                step += 1


@njit(parallel=True, cache=True, nogil=True)  # without the GIL: the next block is read meanwhile
def spike_front_block(words, first_tick, step_ticks, evaluate_at_end, chunk_lo, chunk_hi, group_words,
                      dense_run_ticks, dense_spikes_per_tick, n_pixels,
                      spk, total, fired, fg_bits, word_due, anchor, span1, n1, win_span, win_n, mixed, bg, censored,
                      fg, flag_since, prev, due, out, k_lo, k_hi, k_prime, k_left, background_ticks,
                      hold_ticks):  # pragma: no cover - compiled
    """Feed ticks ``first_tick`` … of ``words`` (T, n_words) uint64; write each completed step's foreground bits.

    Per spike only the pixel's row of ``spk`` (last spike, the one before, the step's first,
    intervals counted) and its spike total change; a word dense with spikes is ingested pixel by
    pixel over a run of ticks (:func:`_ingest_pixel`: the same state). At the end of a step, only the pixels of words
    that fired, hold foreground, or reached a pixel's ``due`` tick are evaluated (:func:`_evaluate`).
    ``out`` has one row per step ending in the block (plus one when ``evaluate_at_end`` and the block
    does not end on a step: the state is then evaluated at the block's last tick, and that row is
    scratch).
    """
    for ch in prange(chunk_lo.size):
        bits = np.zeros(64, np.uint64)
        dense = np.zeros(group_words, np.bool_)
        count = np.zeros(group_words, np.int64)
        # (a prange index may be unsigned: int64 keeps _front_chunk to one signature, one compile)
        _front_chunk(np.int64(ch), bits, dense, count, words, first_tick, step_ticks, evaluate_at_end, chunk_lo,
                     chunk_hi, group_words, dense_run_ticks, dense_spikes_per_tick, n_pixels,
                     spk, total, fired, fg_bits, word_due, anchor, span1, n1, win_span, win_n, mixed, bg, censored,
                     fg, flag_since, prev, due, out, k_lo, k_hi, k_prime, k_left, background_ticks,
                     hold_ticks)


@njit(cache=True, inline="always")
def _evaluate_word(i, tick, n_pixels, spk, fired, fg_bits, word_due, anchor, span1, n1, win_span, win_n, mixed, bg,
                   censored, fg, flag_since, prev, due, k_lo, k_hi, k_prime, k_left, background_ticks,
                   hold_ticks):  # pragma: no cover - compiled
    """Evaluate word ``i`` at the end of tick ``tick``: the pixels that fired, hold foreground or are due."""
    cand = fired[i] | fg_bits[i]
    whole = tick >= word_due[i]
    if whole:  # some pixel's silence may change it: the whole word (and its soonest due anew)
        top = min(64, n_pixels - i * 64)
        cand = ~np.uint64(0) if top == 64 else (np.uint64(1) << np.uint64(top)) - np.uint64(1)
    if cand:
        bits = fg_bits[i] & ~cand
        soonest = np.inf if whole else word_due[i]  # (a bound: a spike may only delay a due)
        while cand:
            j = _cttz(cand)
            cand &= cand - np.uint64(1)
            s = i * 64 + j
            if _evaluate(s, tick, spk, anchor, span1, n1, win_span, win_n, mixed, bg, censored,
                         fg, flag_since, prev, due, k_lo, k_hi, k_prime, k_left,
                         background_ticks, hold_ticks) != 0:
                bits |= np.uint64(1) << j
            if due[s] < soonest:
                soonest = due[s]
        fg_bits[i] = bits
        word_due[i] = soonest
        fired[i] = np.uint64(0)


@njit(cache=True)
def foreground_pixels(bits, height, width, stored_width, flip):  # pragma: no cover - compiled
    """Rows and columns (upright, in scan order) of the set bits of one step's packed foreground."""
    n = 0
    for i in range(bits.size):
        w = bits[i]
        while w:
            w &= w - np.uint64(1)
            n += 1
    ys = np.empty(n, np.int64)
    xs = np.empty(n, np.int64)
    k = 0
    for y in range(height):  # upright rows in order: stored row y, or H − 1 − y when stored bottom-up
        r = height - 1 - y if flip else y
        lo = r * stored_width
        hi = lo + width
        i = lo // 64
        while i * 64 < hi:
            w = bits[i]
            if w:
                base = i * 64
                if base < lo:
                    w &= ~np.uint64(0) << np.uint64(lo - base)
                if base + 64 > hi:
                    w &= (np.uint64(1) << np.uint64(hi - base)) - np.uint64(1)
                while w:
                    ys[k] = y
                    xs[k] = base + _cttz(w) - lo
                    w &= w - np.uint64(1)
                    k += 1
            i += 1
    return ys[:k], xs[:k]


@njit(cache=True)
def _find(parent, i):  # pragma: no cover - compiled
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def components_of_pixels(ys, xs, height, width, reach, min_pixels, index):  # pragma: no cover - compiled
    """Union–find over foreground pixels given in scan order; pixels within Chebyshev ``reach`` join.

    ``index`` is an (H, W) int64 scratch image holding −1 everywhere; it is left so.
    Returns boxes (N, 4) x, y, w, h; pixel counts (N,); and each pixel's component (−1: too small).
    """
    n = ys.size
    parent = np.arange(n)
    for k in range(n):
        y, x = ys[k], xs[k]
        index[y, x] = k
        left = index[y, x - 1] if x > 0 else -1
        if left >= 0:
            # the pixel to the left has met every earlier pixel within reach of it: only the column
            # x + reach above is new (and the left pixel itself)
            a, b = _find(parent, k), _find(parent, left)
            if a != b:
                parent[max(a, b)] = min(a, b)
            xx = x + reach
            if xx < width:
                for yy in range(max(0, y - reach), y):
                    j = index[yy, xx]
                    if j >= 0:
                        a, b = _find(parent, k), _find(parent, j)
                        if a != b:
                            parent[max(a, b)] = min(a, b)
            continue
        for yy in range(max(0, y - reach), y + 1):  # earlier pixels in scan order only
            hi = min(width - 1, x + reach) if yy < y else x - 1
            for xx in range(max(0, x - reach), hi + 1):
                j = index[yy, xx]
                if j >= 0:
                    a, b = _find(parent, k), _find(parent, j)
                    if a != b:
                        parent[max(a, b)] = min(a, b)
    for k in range(n):
        index[ys[k], xs[k]] = -1
    box = np.empty((n, 4), np.int64)  # x0, y0, x1, y1 per root
    count = np.zeros(n, np.int64)
    root = np.empty(n, np.int64)
    for k in range(n):
        r = _find(parent, k)
        root[k] = r
        if count[r] == 0:
            box[r, 0], box[r, 1], box[r, 2], box[r, 3] = xs[k], ys[k], xs[k], ys[k]
        else:
            box[r, 0], box[r, 1] = min(box[r, 0], xs[k]), min(box[r, 1], ys[k])
            box[r, 2], box[r, 3] = max(box[r, 2], xs[k]), max(box[r, 3], ys[k])
        count[r] += 1
    label = np.full(n, -1, np.int64)
    m = 0
    for k in range(n):
        if count[k] >= min_pixels:
            label[k] = m
            m += 1
    boxes = np.empty((m, 4), np.float64)
    counts = np.empty(m, np.int64)
    for k in range(n):  # roots in scan order of their first pixel: a deterministic order
        if count[k] >= min_pixels:
            c = label[k]
            boxes[c, 0], boxes[c, 1] = box[k, 0], box[k, 1]
            boxes[c, 2], boxes[c, 3] = box[k, 2] - box[k, 0] + 1, box[k, 3] - box[k, 1] + 1
            counts[c] = count[k]
    pixel_label = np.empty(n, np.int64)
    for k in range(n):
        pixel_label[k] = label[root[k]]
    return boxes, counts, pixel_label


@njit(cache=True)
def box_overlaps(a, b, iou):  # pragma: no cover - compiled
    """Intersection areas (or with ``iou``, intersection over union: 0 where the union is empty) of every box
    of ``a`` (N, 4) with every box of ``b`` (M, 4), (x, y, w, h)."""
    out = np.empty((a.shape[0], b.shape[0]))
    for i in range(a.shape[0]):
        ax, ay, aw, ah = a[i, 0], a[i, 1], a[i, 2], a[i, 3]
        for j in range(b.shape[0]):
            ix = min(ax + aw, b[j, 0] + b[j, 2]) - max(ax, b[j, 0])
            iy = min(ay + ah, b[j, 1] + b[j, 3]) - max(ay, b[j, 1])
            inter = max(ix, 0.0) * max(iy, 0.0)
            if iou:
                union = aw * ah + b[j, 2] * b[j, 3] - inter
                inter = inter / union if union > 0 else 0.0
            out[i, j] = inter
    return out


@njit(cache=True)
def regroup_tables(boxes, counts, predicted, live, grow, min_pixels, with_multi):  # pragma: no cover - compiled
    """The tables of :meth:`~viform.vision.tracking.Tracker._regroup` for detections ``boxes`` (N, 4) with pixel
    ``counts`` (N,) and the predicted boxes (M, 4) of the tracks ``live`` (L,), in one pass:

    * ``cover`` (N, L): the share of each live prediction, grown by ``grow`` px on every side, that each
      detection's box covers; 0 where another detection of at least ``min_pixels`` pixels fits that
      prediction best (highest IoU, the first of equals; kept where no such detection overlaps it);
    * ``inside`` (N, L): the share of each detection's box inside each live prediction (not grown);
    * ``multi``: with ``with_multi``, the detections covering at least half of two or more grown predictions.

    The same IEEE operations in the same order as the NumPy expressions they replace (exact)."""
    n, m = boxes.shape[0], live.size
    pred = np.empty((m, 4))
    fitted = np.empty((m, 4))
    for j in range(m):
        for c in range(4):
            fitted[j, c] = predicted[live[j], c]
        pred[j, 0] = fitted[j, 0] - grow
        pred[j, 1] = fitted[j, 1] - grow
        pred[j, 2] = fitted[j, 2] + 2 * grow
        pred[j, 3] = fitted[j, 3] + 2 * grow
    cover = box_overlaps(boxes, pred, np.bool_(False))  # (typed, not literal: one signature)
    for j in range(m):
        area = max(pred[j, 2] * pred[j, 3], 1e-9)
        for i in range(n):
            cover[i, j] = cover[i, j] / area
    fit = box_overlaps(boxes, fitted, np.bool_(True))
    for j in range(m):  # the detection (over min_pixels) that fits each prediction best, if any overlaps it
        best = -1
        top = 0.0
        for i in range(n):
            if counts[i] >= min_pixels and (best < 0 or fit[i, j] > top):
                best, top = i, fit[i, j]
        if top > 0:
            for i in range(n):
                if i != best:
                    cover[i, j] = 0.0
    inside = box_overlaps(boxes, fitted, np.bool_(False))
    for i in range(n):
        area = max(boxes[i, 2] * boxes[i, 3], 1e-9)
        for j in range(m):
            inside[i, j] = inside[i, j] / area
    multi = np.zeros(n if with_multi else 0, np.int64)
    k = 0
    if with_multi:
        for i in range(n):
            held = 0
            for j in range(m):
                held += cover[i, j] >= 0.5
            if held >= 2:
                multi[k] = i
                k += 1
    return cover, inside, multi[:k]


@njit(cache=True)
def regroup_owner(inside, used, counts, min_pixels):  # pragma: no cover - compiled
    """Per detection of :meth:`~viform.vision.tracking.Tracker._regroup`, the live prediction it lies mostly
    (≥ 60 % of its box) inside of, when that is the only one and the detection is not ``used``; −1 otherwise,
    and −1 too for a detection of at least ``min_pixels`` pixels that is the only such piece of its prediction
    (an ordinary detection). The same comparisons as the NumPy expressions it replaces (exact)."""
    n, m = inside.shape
    owner = np.full(n, -1, np.int64)
    pieces = np.zeros(m, np.int64)
    for i in range(n):
        if used[i]:
            continue
        first = -1
        held = 0
        for j in range(m):
            if inside[i, j] >= 0.6:
                held += 1
                if first < 0:
                    first = j
        if held == 1:
            owner[i] = first
            pieces[first] += 1
    for i in range(n):
        if owner[i] >= 0 and pieces[owner[i]] == 1 and counts[i] >= min_pixels:
            owner[i] = -1
    return owner


@njit(cache=True, error_model="numpy")  # (a zero reach divides as NumPy does: NaN or inf, no exception)
def assignment_cost(pr, bx, gate_px):  # pragma: no cover - compiled
    """The cost of assigning detections ``bx`` (N, 4) to predictions ``pr`` (M, 4) in
    :meth:`~viform.vision.tracking.Tracker.update`, (M, N): 1 − IoU where they overlap, else 1 + the centre
    distance over the reach (the mean of the two diagonals, plus ``gate_px``); 1e6 (never) past the reach.
    The same IEEE operations in the same order as the NumPy expressions it replaces (exact)."""
    iou = box_overlaps(pr, bx, np.bool_(True))  # (typed, not literal: one signature)
    m, n = pr.shape[0], bx.shape[0]
    cost = np.empty((m, n))
    for a in range(m):
        pcx, pcy = pr[a, 0] + pr[a, 2] / 2, pr[a, 1] + pr[a, 3] / 2
        pd = np.hypot(pr[a, 2], pr[a, 3])
        for b in range(n):
            dist = np.hypot(pcx - (bx[b, 0] + bx[b, 2] / 2), pcy - (bx[b, 1] + bx[b, 3] / 2))
            reach = (pd + np.hypot(bx[b, 2], bx[b, 3])) / 2 + gate_px
            if not dist <= reach:
                cost[a, b] = 1e6
            elif iou[a, b] > 0:
                cost[a, b] = 1.0 - iou[a, b]
            else:
                cost[a, b] = 1.0 + dist / reach
    return cost


@njit(cache=True)
def theil_sen(ts, xs, ys):  # pragma: no cover - compiled
    """Velocity (vx, vy) of points (ts, xs, ys): the median over pairs of (Δx/Δt, Δy/Δt) (Theil–Sen)."""
    n = ts.size
    m = n * (n - 1) // 2
    vx = np.empty(m)
    vy = np.empty(m)
    k = 0
    for a in range(n):
        for b in range(a + 1, n):
            dt = ts[b] - ts[a]
            if dt != 0.0:
                vx[k] = (xs[b] - xs[a]) / dt
                vy[k] = (ys[b] - ys[a]) / dt
                k += 1
    if k == 0:
        return 0.0, 0.0
    return np.median(vx[:k]), np.median(vy[:k])


# --------------------------------------------------------------------------- start-up checks

@njit(cache=True)
def _dilate_rows(mask, px, out):  # pragma: no cover - compiled
    """``out[y, x]`` = any of ``mask[y, x − px … x + px]`` (outside the image: False)."""
    H, W = mask.shape
    for y in range(H):
        run = 0  # set pixels in the window
        for x in range(min(px, W)):
            run += mask[y, x]
        for x in range(W):
            if x + px < W:
                run += mask[y, x + px]
            if x - px - 1 >= 0:
                run -= mask[y, x - px - 1]
            out[y, x] = run > 0


@njit(cache=True)
def _dilate_cols(mask, px, out):  # pragma: no cover - compiled
    """``out[y, x]`` = any of ``mask[y − px … y + px, x]`` (outside the image: False)."""
    H, W = mask.shape
    run = np.zeros(W, np.int64)
    for y in range(min(px, H)):
        for x in range(W):
            run[x] += mask[y, x]
    for y in range(H):
        for x in range(W):
            if y + px < H:
                run[x] += mask[y + px, x]
            if y - px - 1 >= 0:
                run[x] -= mask[y - px - 1, x]
            out[y, x] = run[x] > 0


@njit(cache=True)
def dilate_square(mask, px):  # pragma: no cover - compiled
    """``mask`` (H, W) bool dilated by the (2·px + 1)² square, outside the image False
    (``scipy.ndimage.maximum_filter(mask, 2·px + 1, mode="constant")``, exactly: whole booleans)."""
    tmp = np.empty(mask.shape, np.bool_)
    out = np.empty(mask.shape, np.bool_)
    _dilate_rows(mask, px, tmp)
    _dilate_cols(tmp, px, out)
    return out


@njit(cache=True)
def erode_square(mask, px):  # pragma: no cover - compiled
    """``mask`` eroded by the (2·px + 1)² square, outside the image False (so the image's edges erode):
    ``scipy.ndimage.binary_erosion`` with its default border, exactly."""
    return ~dilate_square(~mask, px) & _inner(mask.shape, px)


@njit(cache=True)
def _inner(shape, px):  # pragma: no cover - compiled
    """Pixels at least ``px`` from the image's edge."""
    H, W = shape
    out = np.zeros((H, W), np.bool_)
    for y in range(px, H - px):
        for x in range(px, W - px):
            out[y, x] = True
    return out


@njit(cache=True)
def opened_closed(mask):  # pragma: no cover - compiled
    """``mask & opening(closing(mask))`` with the 3 × 3 square and scipy.ndimage's borders (outside False)."""
    one = np.int64(1)  # not a literal 1: the dilation compiled for the int px the trackers pass serves
    closed = erode_square(dilate_square(mask, one), one)
    return mask & dilate_square(erode_square(closed, one), one)


@njit(cache=True, inline="always")
def _prime_value(lt, n, s, t, k_hi):  # pragma: no cover - compiled
    """One pixel's :func:`prime_values`: measured, bound, value, upper, lower."""
    nn = float(max(n, 1))
    tau = s / nn if n > 0 else 0.0
    silence = t - lt
    m = n > 0 and silence <= tau * k_hi + 1.0
    b = t + 1.0 if lt < 0 else max(lt + 1.0, float(silence))
    v = tau if m else max(b, tau)
    return m, b, max(v, 1e-3), (s + 1.0) / nn, max((s - 1.0) / nn if m else b, 1e-3)


@njit(cache=True)
def prime_values(last, n_win, s_win, t, k_hi):  # pragma: no cover - compiled
    """Per pixel at tick ``t``, from its last spike and its window (``s_win`` ticks over ``n_win`` intervals):
    whether the interval is measured, the lower bound of an unmeasured one, and the arguments of the
    logarithms the start-up check takes: the interval (≥ 10⁻³), its longest and shortest values (ticks).

    The same IEEE operations in the same order as the NumPy expressions of
    :meth:`~viform.vision.tracking.SpikeChangeDetector._prime` (whose logarithms stay NumPy's).
    """
    H, W = last.shape
    measured = np.empty((H, W), np.bool_)
    bound = np.empty((H, W))
    value = np.empty((H, W))
    upper = np.empty((H, W))
    lower = np.empty((H, W))
    for y in range(H):
        for x in range(W):
            (measured[y, x], bound[y, x], value[y, x], upper[y, x],
             lower[y, x]) = _prime_value(last[y, x], n_win[y, x], s_win[y, x], t, k_hi)
    return measured, bound, value, upper, lower


@njit(cache=True)
def prime_values_stored(spk, n_win, s_win, height, width, stored_width, flip, t,
                        k_hi):  # pragma: no cover - compiled
    """:func:`prime_values` read straight from the detector's stored layout (no upright copies first):
    ``spk`` (n, 4) per-spike state (its :data:`LAST` column), ``n_win`` and ``s_win`` (n,) per stored
    pixel, rows stored ``stored_width`` apart and bottom-up with ``flip``; returns upright (H, W) arrays."""
    H, W = height, width
    measured = np.empty((H, W), np.bool_)
    bound = np.empty((H, W))
    value = np.empty((H, W))
    upper = np.empty((H, W))
    lower = np.empty((H, W))
    last = np.empty(W, np.int64)
    for y in range(H):
        row = (H - 1 - y if flip else y) * stored_width
        for x in range(W):  # the row's last spikes gathered first: the loop below then vectorizes
            last[x] = spk[row + x, LAST]
        nw, sw = n_win[row:row + W], s_win[row:row + W]
        for x in range(W):
            (measured[y, x], bound[y, x], value[y, x], upper[y, x],
             lower[y, x]) = _prime_value(last[x], nw[x], sw[x], t, k_hi)
    return measured, bound, value, upper, lower


@njit(cache=True)
def block_medians(a, block):  # pragma: no cover - compiled
    """Median of each ``block`` × ``block`` block of ``a`` (H, W) float64, the edges padded with the edge
    values (as ``np.pad(mode="edge")``): (⌈H/b⌉, ⌈W/b⌉). An even count's median is the mean of its two
    middle values, (a + b) / 2, as NumPy's."""
    H, W = a.shape
    hb, wb = -(-H // block), -(-W // block)
    out = np.empty((hb, wb))
    buf = np.empty(block * block)
    for by in range(hb):
        for bx in range(wb):
            k = 0
            for y in range(by * block, (by + 1) * block):
                yy = min(y, H - 1)
                for x in range(bx * block, (bx + 1) * block):
                    buf[k] = a[yy, min(x, W - 1)]
                    k += 1
            out[by, bx] = np.median(buf)
    return out



@njit(cache=True)
def block_low_fractions(measured, log_v, med_b, block):  # pragma: no cover - compiled
    """Per ``block`` × ``block`` block of (H, W) images, the edges padded with the edge values (as
    ``np.pad(mode="edge")``): the fraction of its pixels not ``measured`` whose ``log_v`` is under their
    block's value of ``med_b`` (⌈H/b⌉, ⌈W/b⌉), a whole count over b², so it equals the NumPy expression
    ``_blocks(~measured & (log_v < _nearest(med_b, H, W, b)), block=b).mean(axis=2)`` exactly."""
    H, W = log_v.shape
    hb, wb = med_b.shape
    out = np.empty((hb, wb))
    for by in range(hb):
        for bx in range(wb):
            m = med_b[by, bx]
            c = 0
            for y in range(by * block, (by + 1) * block):
                yy = min(y, H - 1)
                for x in range(bx * block, (bx + 1) * block):
                    xx = min(x, W - 1)
                    c += (not measured[yy, xx]) & (log_v[yy, xx] < m)
            out[by, bx] = c / (block * block)
    return out


@njit(cache=True)
def prime_candidates(measured, mixed, upper_log, lower_log, med_b, mm_b, block, known, log_bg, back,
                     thr):  # pragma: no cover - compiled
    """The start-up check's pixels before their opening, in one pass (H, W each): brighter (measured, not a
    falling transition, longest interval under ``median - thr``), darker (shortest interval over
    ``median + thr`` where the median is measured) and stale (a learned background beyond those bounds).
    The median and whether it is measured are per ``block`` × ``block`` block (``med_b``, ``mm_b``).

    The same IEEE comparisons of the same differences as the NumPy expressions of
    :meth:`~viform.vision.tracking.SpikeChangeDetector._prime` they replace, on the blocks' values
    repeated to pixels (exact).
    """
    H, W = measured.shape
    bright = np.empty((H, W), np.bool_)
    dark = np.empty((H, W), np.bool_)
    stale = np.empty((H, W), np.bool_)
    for y in range(H):
        by = y // block
        for bx in range(med_b.shape[1]):
            lo = med_b[by, bx] - thr
            hi = med_b[by, bx] + thr
            mm = mm_b[by, bx]
            for x in range(bx * block, min((bx + 1) * block, W)):
                # (bitwise, not short-circuit: no branches)
                bright[y, x] = measured[y, x] & (not mixed[y, x]) & (upper_log[y, x] < lo)
                dark[y, x] = mm & (lower_log[y, x] > hi)
                lb = log_bg[y, x]
                stale[y, x] = known[y, x] & (not back[y, x]) & ((lb < lo) | (mm & (lb > hi)))
    return bright, dark, stale


@njit(cache=True)
def prime_apply(bright, dark, stale, measured, back, log_v, around, level, around_measured_b, weight_b, block,
                known, log_bg, unsure_log, with_unsure, bg, censored, prev, flag_since):  # pragma: no cover - compiled
    """The start-up check's new state, in place, in one pass (H, W each; the state arrays may be views in
    any layout); returns the pixels *later* (no interval yet, not primed, with a measured level around of
    weight over 0.5 per ``block`` × ``block`` block: ``around_measured_b``, ``weight_b``).

    A primed pixel (``bright | dark | stale``) takes the ``level`` around as its background, a lower
    bound (``censored``) unless that level is measured and the pixel is not brighter; its previous
    background is cleared (``prev`` 0), or, darker with no interval yet, is that level (a silence
    longer than it allows is darker); its flag is cleared. A pixel not primed and not given back
    (``back``) whose level around is measured keeps that level as ``prev`` when it is *unsure* (with
    ``with_unsure``: measured, or with a learned background, more than ``unsure_log`` from the level
    around) or *later*. The same IEEE operations, and the same final state, as the NumPy assignments
    of :meth:`~viform.vision.tracking.SpikeChangeDetector._prime` in their order (exact).
    """
    H, W = measured.shape
    later = np.empty((H, W), np.bool_)
    for y in range(H):
        by = y // block
        for x in range(W):
            bx = x // block
            am = around_measured_b[by, bx]
            b_, d_ = bright[y, x], dark[y, x]
            primed = b_ | d_ | stale[y, x]
            m = measured[y, x]
            lv = level[y, x]
            if primed:
                bg[y, x] = lv
                censored[y, x] = (not am) | b_
                prev[y, x] = lv if d_ and not m else 0.0
                flag_since[y, x] = -1
            free = (not primed) and (not back[y, x]) and am
            a = around[y, x]
            unsure = with_unsure and free and ((m and abs(log_v[y, x] - a) > unsure_log)
                                               or (known[y, x] and abs(log_bg[y, x] - a) > unsure_log))
            lt = free and (not m) and weight_b[by, bx] > 0.5
            later[y, x] = lt
            if unsure or lt:
                prev[y, x] = lv
    return later


@njit(cache=True)
def group_medians(values, order, cuts):  # pragma: no cover - compiled
    """The median of ``values[order[cuts[k]:cuts[k + 1]]]`` for each k (as ``np.median``: an even count's
    is the mean of its two middle values)."""
    out = np.empty(cuts.size - 1)
    for k in range(cuts.size - 1):
        out[k] = np.median(values[order[cuts[k]:cuts[k + 1]]])
    return out


@njit(cache=True)
def clear_block_sums(values, clear, also):  # pragma: no cover - compiled
    """Per 8 × 8 block of (H, W) images (⌈H/8⌉, ⌈W/8⌉): the sum of ``values`` over the ``clear`` pixels, the
    count of clear pixels and the count of those also ``also``, in one pass (no padded or transposed copies).

    The sum takes the block's 64 values (0 where not clear or outside the image) in row-major order as
    NumPy's pairwise sum of 64 contiguous float64 does (eight running sums, element j into sum j mod 8,
    combined as ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))), so it equals
    ``_blocks(np.where(clear, values, 0.0), 0.0).sum(axis=2)`` exactly; the counts are whole numbers.
    """
    H, W = values.shape
    hb, wb = -(-H // 8), -(-W // 8)
    total = np.empty((hb, wb))
    n = np.empty((hb, wb))
    n_also = np.empty((hb, wb))
    r = np.empty(8)
    for by in range(hb):
        for bx in range(wb):
            r[:] = 0.0
            c = 0
            ca = 0
            for dy in range(8):
                y = by * 8 + dy
                for dx in range(8):
                    x = bx * 8 + dx
                    v = 0.0
                    if y < H and x < W and clear[y, x]:
                        v = values[y, x]
                        c += 1
                        ca += also[y, x]
                    r[dx] = v if dy == 0 else r[dx] + v
            total[by, bx] = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
            n[by, bx] = c
            n_also[by, bx] = ca
    return total, n, n_also


@njit(cache=True)
def blend_columns(rows, x0, x1, w0, w1):  # pragma: no cover - compiled
    """``rows[:, x0] * w0 + rows[:, x1] * w1`` (H, W) for rows (H, n) float64 and per-column indices and weights
    (W,): each product and the sum rounded once, in that order, as NumPy's (no fused multiply–add)."""
    H, W = rows.shape[0], x0.size
    out = np.empty((H, W))
    for y in range(H):
        for x in range(W):
            out[y, x] = rows[y, x0[x]] * w0[x] + rows[y, x1[x]] * w1[x]
    return out
