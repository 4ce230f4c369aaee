"""Multi-interval imaging: the light at an instant from the K spikes on each side of it (seed 000 §3.3.2).

Interval imaging (Q/τ of the one interval holding the instant) is sharp but noisy: one
interval carries Q electrons' worth of shot noise and ± 1 tick of rounding. Using the
2K − 1 intervals between the K-th spike before the instant (at or before its tick) and the
K-th spike after it averages that noise down while the window still follows the light: a
bright pixel spans few ticks, a dim one many.

Unbiased for steady light — the length bias
-------------------------------------------
For steady light each interval between spikes is Gamma(Q, λ) in time (λ the photo-current,
e⁻/s, photon arrivals Poisson, threshold Q e⁻): E[τ] = Q/λ. The interval that *holds a
given instant* is not a typical one: an instant falls in an interval with probability
proportional to its length (the inspection paradox of renewal theory; e.g. Cox, *Renewal
Theory*, 1962, §1.4, or Feller, *An Introduction to Probability Theory*, vol. II, §XI.4), so
its law is the length-biased density x·g(x)/E[τ] — for the Gamma(Q, λ) density g that is
Gamma(Q + 1, λ). The span X of n = 2K − 1 consecutive intervals that include it is
therefore the sum of n − 1 ordinary intervals and one length-biased one:

    X ~ Gamma(n·Q + 1, λ),   E[1/X] = λ / (n·Q),

and the estimator λ̂ = n·Q / X is exactly unbiased, with relative variance 1/(n·Q − 1).
(Using n intervals that do *not* hold the instant, X ~ Gamma(n·Q, λ) and n·Q/X would read
n·Q/(n·Q − 1) too bright: the hold-the-instant interval is what removes the bias.)

In ticks that is no longer exact. Tick rounding makes successive intervals negatively
correlated (lag-1 correlation → −½ near one tick per spike), so they are not exchangeable,
and n / span read high near saturation: +0.69 % at a mean interval of 1.2 ticks (Q = 100),
+0.43 % at 1.5, +0.06 % at 2.5, +1.1 % at Q = 1,000 and 1.2 ticks. The rate used instead is
exact for *any* stationary sequence of tick intervals. By Palm calculus (the instant falls
in an interval with probability ∝ its length), E f = r·E⁰[Y_c·f], with r the firing rate
per tick and E⁰ the expectation given a spike, Y_c the interval holding the instant. For
a window W of m consecutive intervals, Σ_{j∈W} Y_j/S_W = 1; by stationarity each term
equals E⁰[Y_c/S_{W'}] for the window W' that puts j on c, so Σ over the m windows W' of m
intervals that hold c of E⁰[Y_c/S_{W'}] = 1, and

    r̂ = Σ_{W' ∋ c, |W'| = m} 1 / S_{W'}     (spikes per tick)

has E r̂ = r exactly. With K spikes a side, m = K: the windows run from the i-th spike
before the instant to the (K − 1 − i)-th after it. It weights the 2K − 1 intervals
triangularly (its variance is 0.5–1.3 times that of n / span: lower near saturation, where
the correlations are strongest, up to 27 % higher at Q = 1); K = 1 is interval imaging.
The adaptive span uses it when it grew equally on both sides (always, for steady light
but for a rare stop by chance), and n / span where it stopped on one side first.

Adaptive K (``adaptive=True``): starting from the interval that holds the instant, the
intervals next to the span are added one side at a time while each is consistent with the
span's mean interval μ, and a side stops growing at the first that is not. The test uses
the Wilson–Hilferty cube-root transform (Wilson & Hilferty, PNAS 17, 684, 1931), under
which a Gamma(Q) interval is close to normal even at Q = 1: (τ/μ)^⅓ has mean 1 − 1/(9Q)
and variance 1/(9Q), plus tick rounding (⅙ tick², i.e. 1/(54 μ²)) and the uncertainty of
μ; a side stops when |z| > ``tolerance``. Where the light changes the window shrinks to the intervals that still share
the instant's light; for steady light it is the full K (a stop by chance, at 3σ, is rare).

End rule: as interval imaging; spikes missing because the stream ends are taken at tick −1
or T, and a pixel whose interval holding the instant is cut is flagged ``censored``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from viform._validate import ViformError, check_int, check_positive
from viform.imaging.interval import _search_spikes
from viform.imaging.units import LightImage, light_from_rate
from viform.stream.container import SpikeSource, spike_bytes

#: First chunk read on each side of the instant (later chunks double); speed only.
FIRST_CHUNK_TICKS = 64
#: Spikes on each side of the instant by default (7 intervals; chosen on the REDS clips and
#: simulated scenes of ``benchmarks/bench_reconstruction.py`` together, with adaptive K).
DEFAULT_SPIKES_PER_SIDE = 4
#: Q assumed for the adaptive test's noise when the stream does not say (real recordings
#: show an effective Q of order 10⁴ e⁻; rounding then dominates the interval spread).
DEFAULT_NOISE_THRESHOLD_ELECTRONS = 1.0e4


def spike_ticks_around(source: SpikeSource, tick: int, before: int, after: int,
                       lookahead_ticks: int | None = None, pixels_wanted=None):
    """The ``before`` last spikes at or before ``tick`` and the ``after`` first spikes after it.

    Returns ``(prev, nxt)``: int64 arrays (before, H·W) and (after, H·W), nearest spike first;
    a spike not found because the stream ended is −1 (prev) or T (nxt). The search reads
    chunks of growing length (the first ``lookahead_ticks``), only for pixels still short of
    spikes, so memory stays bounded and no interval is cut before the stream's ends.
    ``pixels_wanted`` (flat indices) limits the search to those pixels (the others keep
    the end markers).
    """
    before = check_int("before", before, 1)
    after = check_int("after", after, 1)
    n_total = source.n_ticks
    pixels = source.height * source.width
    look = FIRST_CHUNK_TICKS if lookahead_ticks is None else check_int("lookahead_ticks", lookahead_ticks, 1)
    prev = np.full((before, pixels), -1, dtype=np.int64)
    nxt = np.full((after, pixels), n_total, dtype=np.int64)
    for found, wanted, forward in ((prev, before, False), (nxt, after, True)):
        count = np.zeros(pixels, dtype=np.int64)
        todo = np.zeros(pixels, dtype=np.bool_)
        todo[slice(None) if pixels_wanted is None else np.asarray(pixels_wanted, dtype=np.int64)] = True
        _search_spikes(source, tick + 1, forward, todo, found, count, wanted, look)
    return prev, nxt


@njit(cache=True, inline="always")
def interval_consistent(interval, mean, n, noise_q, tolerance):
    """Whether one more interval (ticks) agrees with the mean ``mean`` of the ``n`` beside it.

    Wilson–Hilferty: (τ/μ)^(1/3) of a Gamma(Q) interval is near normal, mean 1 − 1/(9Q), variance
    1/(9Q); tick rounding (⅙ tick²) and the uncertainty of μ (from n intervals) add their share of
    variance. |z| ≤ ``tolerance`` ⇔ τ/μ between the cubes of centre ∓ reach (no cube root).
    """
    var = (1.0 / noise_q + 1.0 / (6.0 * mean * mean)) / 9.0
    centre = 1.0 - 1.0 / (9.0 * noise_q)
    reach = tolerance * np.sqrt(var * (1.0 + 1.0 / n))
    low = max(centre - reach, 0.0)
    high = centre + reach
    ratio = interval / mean
    return low * low * low <= ratio <= high * high * high


@njit(cache=True, parallel=True)
def _span_rate(prev, nxt, n_total, adaptive, noise_q, tolerance, rate, used, censored):
    """Rate (spikes per tick) per pixel: Σ 1/span over the windows that hold the instant (module
    notes; intervals / span where an adaptive span grew unequally); adaptive growth when asked."""
    kb = prev.shape[0]
    ka = nxt.shape[0]
    p = prev.shape[1]
    for j in prange(p):
        lo = prev[0, j]
        hi = nxt[0, j]
        cut = lo < 0 or hi >= n_total
        n = 1
        i_b = 1
        i_a = 1
        grow_b = not cut
        grow_a = not cut
        while grow_b or grow_a:
            for side in range(2):
                if side == 0 and grow_b:
                    if i_b >= kb or prev[i_b, j] < 0:
                        grow_b = False
                        continue
                    new = prev[i_b - 1, j] - prev[i_b, j]
                elif side == 1 and grow_a:
                    if i_a >= ka or nxt[i_a, j] >= n_total:
                        grow_a = False
                        continue
                    new = nxt[i_a, j] - nxt[i_a - 1, j]
                else:
                    continue
                if adaptive:
                    if not interval_consistent(new, (hi - lo) / n, n, noise_q, tolerance):
                        if side == 0:
                            grow_b = False
                        else:
                            grow_a = False
                        continue
                if side == 0:
                    lo = prev[i_b, j]
                    i_b += 1
                else:
                    hi = nxt[i_a, j]
                    i_a += 1
                n += 1
        if i_b == i_a:
            # m windows of m intervals hold the instant's interval: Σ 1/span over them is
            # unbiased for any stationary tick sequence (module notes)
            total = 0.0
            for w in range(i_b):
                total += 1.0 / (nxt[i_b - 1 - w, j] - prev[w, j])
            rate[j] = total
        else:
            rate[j] = n / (hi - lo)
        used[j] = n
        censored[j] = cut


def multi_interval_rate(source: SpikeSource, tick: int, spikes_per_side: int = DEFAULT_SPIKES_PER_SIDE, *,
                        adaptive: bool = False, tolerance: float = 3.0,
                        noise_threshold_electrons: float | None = None, lookahead_ticks: int | None = None):
    """Rate per tick at ``tick`` from up to 2·K − 1 intervals; returns ``(rate, intervals, censored)`` (H, W)."""
    k = check_int("spikes_per_side", spikes_per_side, 1)
    check_positive("tolerance", tolerance)
    q = noise_threshold_electrons or source.threshold_electrons or DEFAULT_NOISE_THRESHOLD_ELECTRONS
    check_positive("noise_threshold_electrons", q)
    if not 0 <= tick < source.n_ticks:
        raise ViformError(f"tick {tick} is outside the stream's [0, {source.n_ticks})")
    prev, nxt = spike_ticks_around(source, tick, k, k, lookahead_ticks)
    pixels = source.height * source.width
    rate = np.empty(pixels)
    used = np.empty(pixels, dtype=np.int64)
    censored = np.empty(pixels, dtype=bool)
    _span_rate(prev, nxt, source.n_ticks, adaptive, float(q), float(tolerance), rate, used, censored)
    shape = (source.height, source.width)
    return rate.reshape(shape), used.reshape(shape), censored.reshape(shape)


def spikes_used(intervals, spikes_per_side: int) -> np.ndarray:
    """Spikes a side each pixel's rate used, from its intervals n (2K − 1 when the span grew
    equally on both sides; an adaptive span that stopped early on one side is taken at the
    K of its shorter side and a half, (n + 1) // 2), between 1 and ``spikes_per_side``."""
    return np.clip((np.asarray(intervals) + 1) // 2, 1, spikes_per_side)


def multi_interval_image(source: SpikeSource, t_s: float, spikes_per_side: int = DEFAULT_SPIKES_PER_SIDE, *,
                         adaptive: bool = False, tolerance: float = 3.0, sensor_parameters=None,
                         noise_threshold_electrons: float | None = None,
                         lookahead_ticks: int | None = None) -> LightImage:
    """Light at instant ``t_s`` from the K spikes on each side of it: the rate Σ 1/span over
    the K windows of K intervals that hold the instant, inverted by the readout's rate law.

    The rate is unbiased for steady light, after tick rounding too (see the module text for
    the length-bias derivation).

    Parameters
    ----------
    spikes_per_side : int
        K (default 4: 7 intervals); K = 1 is plain interval imaging.
    adaptive : bool
        Grow the span one interval at a time, each side stopping at the first interval
        inconsistent with the span's light (shrinks K where the light changes).
    tolerance : float
        Adaptive test threshold, standard deviations (default 3).
    noise_threshold_electrons : float, optional
        Q used in the adaptive test's noise (default: the stream's Q, else 10⁴ e⁻).

    Returns
    -------
    LightImage
        Rate, e⁻/s, lux (where known), ``censored``; ``info["intervals"]`` per pixel.
    """
    tick = source.tick_of(t_s)
    rate, used, censored = multi_interval_rate(source, tick, spikes_per_side, adaptive=adaptive,
                                               tolerance=tolerance,
                                               noise_threshold_electrons=noise_threshold_electrons,
                                               lookahead_ticks=lookahead_ticks)
    image = light_from_rate(rate * source.clock_hz, source, sensor_parameters, censored=censored,
                            method="multi-interval", spikes_per_side=spikes_used(used, spikes_per_side),
                            adaptive=adaptive)
    image.info["spikes_per_side"] = spikes_per_side
    image.info["intervals"] = used
    return image


# ------------------------------------------------------------------ many instants, streamed

@njit(cache=True)
def _spike_lists(bits, first):
    """Per-pixel sorted spike ticks of ``bits`` (n, P) as CSR: (offsets (P + 1), ticks)."""
    n, p = bits.shape
    counts = np.zeros(p + 1, dtype=np.int64)
    for i in range(n):
        for j in range(p):
            if bits[i, j]:
                counts[j + 1] += 1
    for j in range(p):
        counts[j + 1] += counts[j]
    ticks = np.empty(counts[p], dtype=np.int32)  # streams longer than 2³¹ ticks are refused below
    fill = counts[:-1].copy()
    for i in range(n):
        for j in range(p):
            if bits[i, j]:
                ticks[fill[j]] = first + i
                fill[j] += 1
    return counts, ticks


@njit(cache=True, parallel=True)
def _around_from_lists(offsets, ticks, tick, lo_tick, hi_tick, n_total, prev, nxt, short, position):
    """The K spikes each side of ``tick`` from the lists (loaded ticks [lo_tick, hi_tick)).

    ``position`` (per pixel, kept between calls with increasing ``tick``) is the index of the
    first listed spike after the previous tick: it only moves forward. A pixel whose lists
    run out before K spikes, where the stream goes on past the loaded ticks, is flagged
    ``short`` (searched further by the caller).
    """
    kb = prev.shape[0]
    ka = nxt.shape[0]
    p = offsets.size - 1
    for j in prange(p):
        a = offsets[j]
        b = offsets[j + 1]
        lo = max(position[j], a)
        while lo < b and ticks[lo] <= tick:  # first index with ticks > tick
            lo += 1
        position[j] = lo
        short[j] = False
        for m in range(kb):
            i = lo - 1 - m
            if i >= a:
                prev[m, j] = ticks[i]
            else:
                prev[m, j] = -1
                if lo_tick > 0:
                    short[j] = True
        for m in range(ka):
            i = lo + m
            if i < b:
                nxt[m, j] = ticks[i]
            else:
                nxt[m, j] = n_total
                if hi_tick < n_total:
                    short[j] = True


def multi_interval_frames(source: SpikeSource, ticks, spikes_per_side: int = DEFAULT_SPIKES_PER_SIDE, *,
                          adaptive: bool = True, tolerance: float = 3.0,
                          noise_threshold_electrons: float | None = None, group_ticks: int | None = None,
                          margin_ticks: int | None = None):
    """Multi-interval rates at many ticks (sorted), streamed: yields ``(tick, rate, intervals, censored)``.

    Ticks are taken in groups of ``group_ticks``; each group reads its ticks plus
    ``margin_ticks`` on each side once, turns them into per-pixel spike lists, and finds
    each instant's K spikes a side by a per-pixel pointer that only moves forward. Pixels whose K spikes lie beyond the
    margin are searched further (:func:`spike_ticks_around`), so the result equals
    :func:`multi_interval_rate` at every tick, in memory bounded by the group and margin.
    """
    k_side = check_int("spikes_per_side", spikes_per_side, 1)
    check_positive("tolerance", tolerance)
    pixels = source.height * source.width
    auto = int(np.clip(2 ** 25 // max(1, pixels), 8, 256))
    group = auto if group_ticks is None else check_int("group_ticks", group_ticks, 1)
    margin = auto if margin_ticks is None else check_int("margin_ticks", margin_ticks, 1)
    if source.n_ticks >= 2 ** 31:
        raise ViformError(f"the stream has {source.n_ticks} ticks: multi-interval streaming handles < 2³¹")
    q = noise_threshold_electrons or source.threshold_electrons or DEFAULT_NOISE_THRESHOLD_ELECTRONS
    ticks = np.asarray(ticks, dtype=np.int64)
    if ticks.size > 1 and np.any(np.diff(ticks) < 0):
        raise ViformError("ticks must be in increasing order for streamed multi-interval imaging")
    n_total = source.n_ticks
    pixels = source.height * source.width
    shape = (source.height, source.width)
    prev = np.empty((k_side, pixels), dtype=np.int64)
    nxt = np.empty((k_side, pixels), dtype=np.int64)
    short = np.empty(pixels, dtype=bool)
    start = 0
    while start < ticks.size:
        stop = int(np.searchsorted(ticks, ticks[start] + group))
        lo_tick = max(0, int(ticks[start]) - margin)
        hi_tick = min(n_total, int(ticks[stop - 1]) + 1 + margin)
        bits = spike_bytes(source.read_ticks(lo_tick, hi_tick).reshape(hi_tick - lo_tick, pixels))
        offsets, spike_ticks = _spike_lists(bits, lo_tick)
        del bits
        position = offsets[:-1].copy()
        for k in ticks[start:stop]:
            _around_from_lists(offsets, spike_ticks, int(k), lo_tick, hi_tick, n_total, prev, nxt, short, position)
            if short.any():
                far = np.flatnonzero(short)
                far_prev, far_nxt = spike_ticks_around(source, int(k), k_side, k_side, pixels_wanted=far)
                prev[:, far] = far_prev[:, far]
                nxt[:, far] = far_nxt[:, far]
            rate = np.empty(pixels)
            used = np.empty(pixels, dtype=np.int64)
            censored = np.empty(pixels, dtype=bool)
            _span_rate(prev, nxt, n_total, adaptive, float(q), float(tolerance), rate, used, censored)
            yield int(k), rate.reshape(shape), used.reshape(shape), censored.reshape(shape)
        start = stop
