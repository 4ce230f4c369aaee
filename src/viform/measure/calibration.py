"""Calibrate a spike-sensor model from a recording of a (mostly) static scene.

What a spike recording of steady light tells about the sensor (seed 000 §5.1, §4.4):

**Effective threshold Q_eff.** A self-reset pixel under steady light λ e⁻/tick fires at the
crossings of a renewal process whose intervals, in continuous time, are X = G/λ with
G ~ Gamma(Q): mean μ = Q/λ ticks, variance σ² = μ²/Q (seed 000 §5.1: RSD = 1/√Q). Every
other per-spike charge noise (reset, comparator) adds variance ∝ μ² too, so the measured
Q_eff lumps them. The readout rounds each crossing up to its tick, so the observed
interval is Y_k = X_k + e_k − e_{k−1} (e = rounding of a crossing time). Derivation of the
rounding correction: write T_k = ⌈t_k⌉ for the spike ticks. Given an n-interval span S of
continuous length x that starts at a uniformly distributed tick phase,
⌈u + x⌉ − ⌈u⌉ = ⌊x⌋ + Bernoulli(frac x), so E[T_{k+n} − T_k | S = x] = x exactly and the
rounding adds variance g(x) = frac(x)(1 − frac(x)). Hence the spike-time variogram

    V(n) = var(T_{k+n} − T_k) = n·σ² + G_n,   G_n = E g(S_n),

and for the intervals γ₀ = V(1), γ₁ = (V(2) − 2V(1))/2. The mean-free statistic used here,
D₁ = E(Y_k − Y_{k+1})²/2 = γ₀ − γ₁, is therefore

    D₁ = σ² + 2·G₁ − G₂/2.

With g's Fourier series g(x) = 1/6 − Σ_k cos(2πkx)/(π²k²) and S_n ≈ Normal(nμ, nσ²),
G_n = 1/6 − Σ_k cos(2πknμ)·exp(−2π²k²nσ²)/(π²k²), evaluated per pixel from its own mean
interval (:func:`rounding_variance`). When the phases frac(μ) are spread over a tick or
the interval jitter exceeds ~0.5 tick, G₁ = G₂ = 1/6 and D₁ = σ² + 1/4, γ₁ = −1/12, and
successive intervals of a regular pixel have lag-1 correlation γ₁/γ₀ → −1/2 — what real
recordings show. Q_eff = μ²/σ² is fitted over all pixels (weighted least squares of σ² on
μ²; since G depends on σ, 1/Q_eff is the first root of fit(x) = x). The fit uses the second
differences of the intervals, E(Y_k − 2Y_{k+1} + Y_{k+2})² = 6σ² + 15G₁ − 6G₂ + G₃ (same
variogram algebra), in which light that changes linearly over three intervals cancels;
D₁ gives a check. Each G is made unbiased for the noise of the pixel's own mean interval,
which matters when all pixels share one tick phase (a uniform field without PRNU).

**Static or not.** A stationary pixel has D₂ − D₁ = γ₁ − γ₂ < 0 (≈ −1/12); light that
changes over the recording (motion, flicker) makes successive intervals positively
correlated and D₂ − D₁ > 0. The image is cut into tiles, each tile split like a
checkerboard: a tile's black pixels are used when the *white* pixels' D₂ − D₁ lies below
minus its standard error, and vice versa, so no pixel is selected by its own fluctuations
(that would bias Q_eff up). Then every interval bin's lag-1 correlation must agree with a
steady pixel's at the fitted Q_eff (±0.15); if not, the light changed (slowly: γ₁ too high;
faster than an interval: below any steady pixel's) and, since changing light only adds
interval variance, the fit is reported as a lower bound of Q_eff. Too few static pairs:
no figure.

**Gain spread (PRNU).** In a tile, the pixel rates 1/μ_p around a fitted plane (scene
gradients removed) spread by the gain spread plus the finite-window noise of μ_p,
var(μ_p) = σ²/(n_p − 1) + 1/(6(n_p − 1)²) (interval noise and the rounding of the first and
last spikes), which is subtracted. Scene texture at the pixel scale cannot be told from
PRNU in one static recording, so the flattest quarter of the tiles is used and the figure
is an upper bound wherever texture remains.

**Dark current, hot and dead pixels.** Dark current shows only as spikes of pixels
without light, at I_d/Q per second: in a recording much shorter than Q/I_d (seconds to
minutes for Q ~ 10⁴ e⁻) it is not measurable, and only a bound is given. Hot pixels: counts
far above their neighbourhood's median (by 5σ of the photon noise, σ² = m/Q + 1) in BOTH
halves of the recording, by the same excess, so that moving light, which lifts a pixel
only while a bright feature passes it, gives none; dead pixels: silent where the
neighbourhood fires often.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from viform._validate import ViformError, check_int, size_text
from viform.stream.container import SpikeSource

#: Shortest mean interval (ticks) used for Q_eff: below it the rounding dominates σ² by far.
MIN_INTERVAL_TICKS = 4.0
#: Pixels need this many intervals inside the recording (so the window selects no interval lengths).
MIN_INTERVALS_PER_PIXEL = 5
#: Static pairs needed before Q_eff is reported.
MIN_PAIRS_FOR_Q = 2000
#: Tile side (pixels) for the static test and the flat-field spread.
TILE = 8
_FOURIER_TERMS = 12


def rounding_variance(mean_ticks, jitter_var_ticks2, mean_var_ticks2=0.0, mean_spread_ticks=0.0) -> np.ndarray:
    """G = E[frac(S)(1 − frac(S))] for S ~ Normal(mean, var): variance that tick rounding adds.

    Fourier series of the periodic parabola, g(x) = 1/6 − Σ_k cos(2πkx)/(π²k²); each term is
    damped by the characteristic function of the jitter, exp(−2π²k²·var). Tends to 1/6 as
    the jitter grows past ~0.5 tick (module notes).

    ``mean_var_ticks2``: when ``mean_ticks`` is itself an estimate, unbiased with this
    variance, E cos(2πk·estimate) = cos(2πk·mean)·exp(−2π²k²·mean_var); each term is then
    undamped by that factor (down to no damping at all), so that G averaged over pixels is
    unbiased. Where every pixel shares nearly the same interval (a uniform field) the
    rounding phases are coherent and this matters: without it Q_eff read 30–90 % low there.

    ``mean_spread_ticks``: when the light drifts, the mean moves over the recording; G is
    then averaged over a mean spread uniformly over this width, which multiplies term k by
    the characteristic function of the uniform law, sinc(k·width) (sin(πx)/(πx)). Without it,
    2 % of linear drift over a uniform field (coherent phases) read Q_eff 30 % low.
    """
    mean = np.asarray(mean_ticks, dtype=np.float64)
    var = np.asarray(jitter_var_ticks2, dtype=np.float64)
    excess = np.maximum(var - np.asarray(mean_var_ticks2, dtype=np.float64), 0.0)
    mean, excess, spread = np.broadcast_arrays(mean, excess, np.asarray(mean_spread_ticks, dtype=np.float64))
    out = np.empty(mean.shape)
    _rounding_series(np.ascontiguousarray(mean).ravel(), np.ascontiguousarray(excess).ravel(),
                     np.ascontiguousarray(spread).ravel(), out.reshape(-1))
    return out


@njit(cache=True)
def _rounding_series(mean, excess, spread, out):
    """1/6 − Σ_k cos(2πk·frac μ)·e^(−2π²k²·v)·sinc(k·w)/(π²k²), element by element (see
    :func:`rounding_variance`); stops where the damping falls below 1e-12."""
    for i in range(mean.size):
        phase = 2.0 * np.pi * (mean[i] - np.floor(mean[i]))
        damping = np.exp(-2.0 * np.pi * np.pi * excess[i])
        g = 1.0 / 6.0
        dk = 1.0
        step = damping  # damping^(2k − 1): dk runs through damping^(k²)
        # cos(kφ) and sin(kπw) by the Chebyshev recurrence f_k = 2·cos(a)·f_(k−1) − f_(k−2)
        c1 = np.cos(phase)
        c_prev, c_k = 1.0, c1
        x = np.pi * spread[i]
        s1 = np.cos(x)
        s_prev, s_k = 0.0, np.sin(x)
        for k in range(1, _FOURIER_TERMS + 1):
            dk *= step
            step *= damping * damping
            term = c_k * dk / (np.pi * np.pi * k * k)
            if x > 0:
                term *= s_k / (k * x)
            g -= term
            if dk < 1e-12:
                break
            c_prev, c_k = c_k, 2.0 * c1 * c_k - c_prev
            s_prev, s_k = s_k, 2.0 * s1 * s_k - s_prev
        out[i] = g


@dataclass
class PixelIntervals:
    """Spike intervals of every pixel of a recording (ticks).

    Attributes
    ----------
    height, width, n_ticks : int
    clock_hz : float
    n_spikes, first_tick, last_tick : ndarray (H·W,)
    intervals : ndarray of float
        Complete intervals, pixel by pixel in time order.
    pixel : ndarray of int
        Pixel index of each interval.
    """

    height: int
    width: int
    n_ticks: int
    clock_hz: float
    n_spikes: np.ndarray
    first_tick: np.ndarray
    last_tick: np.ndarray
    intervals: np.ndarray
    pixel: np.ndarray
    #: Per-pixel spike counts in the first half of the ticks read (``n_ticks // 2``).
    n_spikes_first_half: np.ndarray | None = None

    @property
    def mean_interval(self) -> np.ndarray:
        """Per-pixel mean interval (last − first)/(n − 1), ticks; NaN below two spikes."""
        n = self.n_spikes
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n >= 2, (self.last_tick - self.first_tick) / np.maximum(n - 1, 1), np.nan)

    def lagged(self, lag: int):
        """Pairs (Y_k, Y_{k+lag}) of the same pixel: (first, second, pixel)."""
        ok = self.pixel[lag:] == self.pixel[:-lag]
        return self.intervals[:-lag][ok], self.intervals[lag:][ok], self.pixel[lag:][ok]


#: Spikes read at most (≈ 24 bytes each while sorting): calibration memory stays bounded.
MAX_SPIKES = 20_000_000


def pixel_intervals(source: SpikeSource, *, max_ticks: int | None = None, block_ticks: int | None = None,
                    max_spikes: int = MAX_SPIKES) -> PixelIntervals:
    """Read a spike stream block by block and collect every pixel's intervals.

    Reading stops at ``max_ticks`` or at the block where ``max_spikes`` spikes have been
    read (``n_ticks`` of the result says how far it got), so memory is bounded whatever
    the recording's length.
    """
    h, w = source.height, source.width
    n_ticks = source.n_ticks if max_ticks is None else min(source.n_ticks, check_int("max_ticks", max_ticks, 2))
    if block_ticks is None:
        block_ticks = max(1, min(256, (8 << 20) // max(1, h * w)))  # ≈ 8 MB of bits a block
    ticks, pixels = [], []
    read, end = 0, n_ticks
    for first, block in source.iter_blocks(block_ticks, 0, n_ticks):
        t, p = np.nonzero(block.reshape(block.shape[0], -1))
        ticks.append((t + first).astype(np.int64))
        pixels.append(p.astype(np.int64))
        read += t.size
        if read >= max_spikes:
            end = first + block.shape[0]
            break
    t = np.concatenate(ticks) if ticks else np.zeros(0, np.int64)
    p = np.concatenate(pixels) if pixels else np.zeros(0, np.int64)
    order = np.lexsort((t, p))
    t, p = t[order], p[order]
    npx = h * w
    n_spikes = np.bincount(p, minlength=npx)
    first_tick = np.full(npx, -1, np.int64)
    last_tick = np.full(npx, -1, np.int64)
    first_tick[p[::-1]] = t[::-1]
    last_tick[p] = t
    same = p[1:] == p[:-1]
    intervals = np.diff(t)[same].astype(np.float64)
    first_half = np.bincount(p[t < end // 2], minlength=npx)
    return PixelIntervals(h, w, end, float(source.clock_hz), n_spikes, first_tick, last_tick, intervals,
                          p[1:][same], first_half)


@dataclass
class IntervalStatistics:
    """Per-pixel sums of a recording's spike intervals: all that calibration uses (bounded memory).

    For pixel p with intervals Y_0 … Y_{n−1} (ticks, in time order): ``n_intervals``,
    ``sum_k``, ``sum_kk`` (interval indices k), ``sum_y``, ``sum_yy``, ``sum_ky``; over its
    successive pairs ``n_pairs`` and ``sum_lag1`` = Σ (Y_k − Y_{k+1})²/2; over its triples
    ``n_triples``, ``sum_second`` = Σ (Y_k − 2Y_{k+1} + Y_{k+2})², ``sum_d`` and ``sum_dd``
    (d = ((Y_k − Y_{k+2})² − (Y_k − Y_{k+1})²)/2, the static test's statistic), ``sum_lag2``
    = Σ (Y_k − Y_{k+2})²/2. Plus the spike
    counts, first and last spike ticks and the count in the first half of the ticks read.
    """

    height: int
    width: int
    n_ticks: int
    clock_hz: float
    n_spikes: np.ndarray
    first_tick: np.ndarray
    last_tick: np.ndarray
    n_spikes_first_half: np.ndarray
    n_intervals: np.ndarray
    sum_k: np.ndarray
    sum_kk: np.ndarray
    sum_y: np.ndarray
    sum_yy: np.ndarray
    sum_ky: np.ndarray
    n_pairs: np.ndarray
    sum_lag1: np.ndarray
    n_triples: np.ndarray
    sum_second: np.ndarray
    sum_d: np.ndarray
    sum_dd: np.ndarray
    #: Σ (Y_k − Y_{k+2})²/2 over the triples (D₂, mean-free).
    sum_lag2: np.ndarray

    @property
    def mean_interval(self) -> np.ndarray:
        """Per-pixel mean interval (last − first)/(n − 1), ticks; NaN below two spikes."""
        n = self.n_spikes
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n >= 2, (self.last_tick - self.first_tick) / np.maximum(n - 1, 1), np.nan)


_N_INT_SUMS, _N_FLOAT_SUMS = 8, 11  # int64: spikes, first, last, first half, prev1, prev2, intervals, pairs/triples


@njit(cache=True)
def _accumulate_block(bits, first, half, ints, floats):
    """Add the spikes of ticks [first, first + n) (``bits`` (n, P) uint8) to the per-pixel sums.

    ``ints`` rows: 0 spikes, 1 first tick, 2 last tick, 3 spikes before ``half``, 4 previous
    interval, 5 the one before, 6 intervals, 7 pairs; ``floats`` rows: 0 triples, 1 Σk,
    2 Σk², 3 Σy, 4 Σy², 5 Σky, 6 Σ lag-1 statistic, 7 Σ second-difference statistic, 8 Σd,
    9 Σd², 10 Σ lag-2 statistic. Pixels in chunks (their sums stay in cache), rows of ticks inside.
    One thread: the work is light (a test per pixel and tick) next to reading the file.
    """
    n, p = bits.shape
    chunk = 4096
    for c in range((p + chunk - 1) // chunk):
        j0 = c * chunk
        j1 = min(j0 + chunk, p)
        for i in range(n):
            tick = first + i
            for j in range(j0, j1):
                if not bits[i, j]:
                    continue
                ints[0, j] += 1
                if tick < half:
                    ints[3, j] += 1
                last = ints[2, j]
                if last < 0:
                    ints[1, j] = tick
                else:
                    y = float(tick - last)
                    k = float(ints[6, j])
                    floats[1, j] += k
                    floats[2, j] += k * k
                    floats[3, j] += y
                    floats[4, j] += y * y
                    floats[5, j] += k * y
                    ints[6, j] += 1
                    b = float(ints[4, j])
                    if ints[4, j] > 0:
                        ints[7, j] += 1
                        floats[6, j] += (b - y) * (b - y) / 2
                        if ints[5, j] > 0:
                            a = float(ints[5, j])
                            floats[0, j] += 1.0
                            floats[7, j] += (a - 2 * b + y) ** 2
                            d = ((a - y) ** 2 - (a - b) ** 2) / 2
                            floats[8, j] += d
                            floats[9, j] += d * d
                            floats[10, j] += (a - y) ** 2 / 2
                    ints[5, j] = ints[4, j]
                    ints[4, j] = tick - last
                ints[2, j] = tick


def interval_statistics(source: SpikeSource, *, max_ticks: int | None = None, block_ticks: int | None = None,
                        max_spikes: int = MAX_SPIKES) -> IntervalStatistics:
    """Read a spike stream block by block into per-pixel interval sums (:class:`IntervalStatistics`).

    Memory: one block of bits (about 8 MB) and 19 numbers per pixel, whatever the
    recording's length. Reading stops at ``max_ticks`` or at the block where ``max_spikes``
    spikes have been read (``n_ticks`` says how far it got; the same ticks as
    :func:`pixel_intervals`), found by a first counting pass so that the first half of the
    ticks read is known while the sums are made.
    """
    h, w = source.height, source.width
    n_ticks = source.n_ticks if max_ticks is None else min(source.n_ticks, check_int("max_ticks", max_ticks, 2))
    npx = h * w
    if block_ticks is None:
        block_ticks = max(1, min(256, (8 << 20) // max(1, npx)))  # ≈ 8 MB of bits a block
    end, read = n_ticks, 0
    for first, block in source.iter_blocks(block_ticks, 0, n_ticks):
        read += int(np.count_nonzero(block))
        if read >= max_spikes:
            end = first + block.shape[0]
            break
    ints = np.zeros((_N_INT_SUMS, npx), np.int64)
    ints[1:3] = -1
    floats = np.zeros((_N_FLOAT_SUMS, npx), np.float64)
    for first, block in source.iter_blocks(block_ticks, 0, end):
        bits = np.ascontiguousarray(block.reshape(block.shape[0], npx)).view(np.uint8)
        _accumulate_block(bits, first, end // 2, ints, floats)
    return IntervalStatistics(h, w, end, float(source.clock_hz), ints[0], ints[1], ints[2], ints[3], ints[6],
                              floats[1], floats[2], floats[3], floats[4], floats[5], ints[7].astype(np.float64),
                              floats[6], floats[0], floats[7], floats[8], floats[9], floats[10])


def statistics_of(iv: PixelIntervals) -> IntervalStatistics:
    """The same per-pixel sums as :func:`interval_statistics`, from collected intervals."""
    npx = iv.height * iv.width
    y, px_of = iv.intervals, iv.pixel
    n_int = np.bincount(px_of, minlength=npx)
    start = np.concatenate([[0], np.cumsum(n_int)[:-1]]).astype(np.int64)
    k = (np.arange(y.size) - start[px_of]).astype(np.float64)
    a, b, pp = iv.lagged(1)
    ok3 = iv.pixel[2:] == iv.pixel[:-2]
    y0, y1, y2, p3 = iv.intervals[:-2][ok3], iv.intervals[1:-1][ok3], iv.intervals[2:][ok3], iv.pixel[2:][ok3]
    d = ((y0 - y2) ** 2 - (y0 - y1) ** 2) / 2
    first_half = iv.n_spikes_first_half if iv.n_spikes_first_half is not None else iv.n_spikes // 2
    return IntervalStatistics(
        iv.height, iv.width, iv.n_ticks, iv.clock_hz, iv.n_spikes, iv.first_tick, iv.last_tick, first_half, n_int,
        np.bincount(px_of, k, npx), np.bincount(px_of, k * k, npx), np.bincount(px_of, y, npx),
        np.bincount(px_of, y * y, npx), np.bincount(px_of, k * y, npx),
        np.bincount(pp, minlength=npx).astype(np.float64), np.bincount(pp, (a - b) ** 2 / 2, npx),
        np.bincount(p3, minlength=npx).astype(np.float64), np.bincount(p3, (y0 - 2 * y1 + y2) ** 2, npx),
        np.bincount(p3, d, npx), np.bincount(p3, d * d, npx), np.bincount(p3, (y0 - y2) ** 2 / 2, npx))


def _checkerboard_static(st: IntervalStatistics, tile: int) -> tuple[np.ndarray, dict]:
    """Per pixel: is its tile static, judged by the other checkerboard colour (module notes)?

    Statistic per (tile, colour): mean of d = ((Y_k − Y_{k+2})² − (Y_k − Y_{k+1})²)/2 over
    the colour's interval triples; static when mean(d) < its standard error (a stationary
    pixel has E d = γ₁ − γ₂ ≈ −1/12 < 0).
    """
    h, w = st.height, st.width
    y, x = np.divmod(np.arange(h * w), w)
    ty, tx = y // tile, x // tile
    n_tx = (w + tile - 1) // tile
    colour = (y + x) % 2
    group = (ty * n_tx + tx) * 2 + colour
    n_groups = 2 * ((h + tile - 1) // tile) * n_tx  # both colours of every tile
    cnt = np.bincount(group, st.n_triples, n_groups)
    s1 = np.bincount(group, st.sum_d, n_groups)
    s2 = np.bincount(group, st.sum_dd, n_groups)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s1 / cnt
        se = np.sqrt(np.maximum(s2 / cnt - mean**2, 0) / np.maximum(cnt - 1, 1))
    judged = cnt >= 8
    static_group = judged & (mean < -se)
    # a pixel is judged by the other colour of its own tile
    other = group ^ 1
    static = static_group[other] & judged[other]
    info = {"tiles_judged": int(judged.sum()), "tiles_static": int(static_group.sum()),
            "static_fraction_of_judged": float(static_group.sum() / judged.sum()) if judged.any() else None}
    return static, info


def _rounding_term(mu, s2, statistic: str, mu_var=0.0, spread=0.0):
    """Rounding part of a statistic's expectation (module notes), from G_n = G(n·μ, n·σ²).

    ``mu_var``: variance of the per-pixel estimate μ; ``spread``: the width over which the
    pixel's mean interval drifts during the recording (see :func:`rounding_variance`).
    """
    g1 = rounding_variance(mu, s2, mu_var, spread)
    g2 = rounding_variance(2 * mu, 2 * s2, 4 * mu_var, 2 * spread)
    if statistic == "lag1":
        return 2 * g1 - g2 / 2
    g3 = rounding_variance(3 * mu, 3 * s2, 9 * mu_var, 3 * spread)
    return 15 * g1 - 6 * g2 + g3


#: σ² coefficient of each statistic: D₁ = σ² + …, E(Y_k − 2Y_{k+1} + Y_{k+2})² = 6σ² + …
_SIGMA_COEFFICIENT = {"lag1": 1.0, "second": 6.0}


def _drift_spread(st: IntervalStatistics, use: np.ndarray, tile: int | None = None) -> tuple[np.ndarray, dict]:
    """Per pixel: the width (ticks) over which its mean interval drifts during the recording.

    Light that drifts changes every pixel's interval in proportion to it: Y_k ≈ μ·(1 + δ·(k −
    k̄)) with δ the relative change per interval, shared by the whole image (a lamp, the sun,
    the lens; ``tile``: by each tile of that many pixels a side instead, noisier — with 64
    pixels a tile the noise of δ biases the rounding term on coherent tick phases). Light that
    changes locally (motion) is caught by the static test instead.
    δ is fitted by least squares over the pixels' interval trends (Σ μ·sxy / Σ μ²·sxx,
    sxy and sxx each pixel's sums about its means); its noise variance (Σ μ²·sxx·s²/(Σ μ²·sxx)²,
    s² the residual variance of the pixel's intervals) is removed from δ² so a steady
    recording gets no spread on average. The width is |δ|·μ·N for N intervals.
    """
    h, w = st.height, st.width
    if tile is None:
        group = np.zeros(h * w, np.int64)
    else:
        y, x = np.divmod(np.arange(h * w), w)
        group = (y // tile) * ((w + tile - 1) // tile) + x // tile
    n = st.n_intervals.astype(np.float64)
    mu = st.mean_interval
    ok = use & (n >= 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        sxx = st.sum_kk - st.sum_k ** 2 / n
        sxy = st.sum_ky - st.sum_k * st.sum_y / n
        ss = st.sum_yy - st.sum_y ** 2 / n
        resid = (ss - np.where(sxx > 0, sxy * sxy / sxx, 0.0)) / (n - 2)
    m = np.where(ok, mu, 0.0)
    den = np.bincount(group, np.where(ok, m * m * sxx, 0.0))
    num = np.bincount(group, np.where(ok, m * sxy, 0.0))
    noise = np.bincount(group, np.where(ok, m * m * sxx * resid, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.where(den > 0, num / den, 0.0)
        delta2 = np.where(den > 0, np.maximum(delta * delta - noise / (den * den), 0.0), 0.0)
    spread = np.where(ok, np.sqrt(delta2[group]) * np.where(ok, mu, 0.0) * n, 0.0)
    change = np.sqrt(delta2[group]) * n  # relative change of the light over the pixel's intervals
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.where(den > 0, np.sqrt(noise) / den, 0.0)  # standard error of δ
        relative_se = float(np.max(np.where(delta2 > 0, sd / np.sqrt(np.where(delta2 > 0, delta2, 1.0)), 0.0)))
    info = {"median_relative_drift_over_recording": float(np.median(change[ok])) if ok.any() else None,
            "drift_relative_standard_error": relative_se}
    return spread, info


def _fit_inverse_q(mu_pix, count, total, statistic: str, n_intervals, spread=None):
    """Weighted least squares of (stat − rounding)/k = σ² on μ²: returns (1/Q, its standard error).

    The rounding term depends on σ itself (through the jitter that blurs the tick phase),
    so 1/Q is the root x of fit(x) = x, found by bracketing (a plain fixed-point iteration
    diverges near half-tick phases, where the rounding term falls faster than σ² grows).
    Pairs come summed per pixel so the standard error (ratio estimator over pixels)
    allows for the pairs of one pixel sharing intervals; it is divided by |1 − fit'(x)|.
    """
    k = _SIGMA_COEFFICIENT[statistic]
    # μ, the weight and the rounding term are per pixel: each pixel's pairs are summed (``count``
    # statistics, total ``total``)
    count = np.asarray(count, dtype=np.float64)
    has = count > 0
    spread = np.zeros(count.shape) if spread is None else np.asarray(spread, dtype=np.float64)
    count, total, mu_pix, spread = count[has], total[has], mu_pix[has], spread[has]
    n_iv = np.maximum(np.asarray(n_intervals, dtype=np.float64)[has], 1.0)
    floor_term = _rounding_term(mu_pix, np.ones_like(mu_pix), statistic)  # the rounding of wide jitter

    def fit_many(xs):
        """fit(x) for each x of ``xs`` at once (rows of x × pixels, in chunks that bound memory)."""
        xs = np.maximum(np.atleast_1d(np.asarray(xs, dtype=np.float64)), 0.0)
        values = np.empty(xs.size)
        rows = max(1, int(250_000 // max(mu_pix.size, 1)))
        for r0 in range(0, xs.size, rows):
            x = xs[r0:r0 + rows, None]
            s2 = mu_pix * mu_pix * x
            # μ_p = (last − first)/N: an N-interval span plus the rounding of its two ends
            mu_var = (n_iv * s2 + 1.0 / 6.0) / (n_iv * n_iv)
            corr = _rounding_term(mu_pix, s2, statistic, mu_var, spread)
            wgt = 1.0 / (k * s2 + floor_term) ** 2  # var of one pair's statistic ∝ its mean²
            num = wgt * (total - count * corr) / k * mu_pix**2
            den = wgt * count * mu_pix**4
            values[r0:r0 + rows] = num.sum(axis=1) / den.sum(axis=1)
        return values

    def fit(x):
        s2 = mu_pix * mu_pix * max(x, 0.0)
        mu_var = (n_iv * s2 + 1.0 / 6.0) / (n_iv * n_iv)
        corr = _rounding_term(mu_pix, s2, statistic, mu_var, spread)
        wgt = 1.0 / (k * s2 + floor_term) ** 2
        num = wgt * (total - count * corr) / k * mu_pix**2
        den = wgt * count * mu_pix**4
        value = float(num.sum() / den.sum())
        return value, float(np.sqrt(np.sum((num - den * value) ** 2)) / den.sum())

    # Beyond x_hi every pixel's jitter exceeds 3 ticks: the rounding term is flat there.
    # Scan a log grid from the smallest jitter up and take the first root: where every pixel
    # has the same tick phase (a uniform field) fit(x) − x can cross zero more than once
    # (near half-tick phases the rounding term falls about as fast as σ² grows), and the
    # first crossing is the one that matches the data (checked on simulated uniform fields).
    x_hi = 9.0 / float(np.min(mu_pix)) ** 2
    grid = np.geomspace(x_hi * 1e-7, x_hi, 29)
    h = fit_many(grid) - grid
    crossing = np.nonzero(np.sign(h[:-1]) != np.sign(h[1:]))[0]
    if crossing.size:
        i = int(crossing[0])
        lo, hi, h_lo = grid[i], grid[i + 1], h[i]
        while hi - lo > 1e-5 * hi:  # bisection in log x (the bracket spans a factor ≈ 1.6)
            mid = math.sqrt(lo * hi)
            h_mid = fit(mid)[0] - mid
            if np.sign(h_mid) == np.sign(h_lo):
                lo, h_lo = mid, h_mid
            else:
                hi = mid
        root = math.sqrt(lo * hi)
    elif h[0] > 0:
        root = fit(x_hi)[0]
    else:
        root = 0.0
    value, se = fit(root)
    step = max(abs(root), 1e-9) * 1e-3
    slope = (fit(root + step)[0] - fit(max(root - step, 0.0))[0]) / (root + step - max(root - step, 0.0))
    return root, se / max(abs(1.0 - slope), 0.1)


#: Relative error allowed for the width of the drift of each pixel's mean interval (the drift need not
#: be linear, and its estimate is noisy): propagated into the standard error of 1/Q_eff.
DRIFT_MODEL_TOLERANCE = 0.10

#: Largest difference between a bin's lag-1 correlation and a steady pixel's that still counts as static.
LAG1_TOLERANCE = 0.15


def _bins(lo: float, hi: float) -> np.ndarray:
    edges = [lo]
    while edges[-1] * 1.5 < hi:
        edges.append(edges[-1] * 1.5)
    edges.append(hi)
    return np.array(edges)


def interval_table(iv, use_pixel: np.ndarray, edges, inv_q: float | None = None) -> list[dict]:
    """Per mean-interval bin: pixels, pairs, RSD of the intervals (rounding included), lag-1 correlation.

    ``rsd`` = √γ₀/μ with γ₀ the pooled within-pixel variance of the intervals (n − 1
    divisor); ``rsd_detrended`` the same after removing each pixel's linear trend of the
    intervals over the recording (n − 2 divisor), so light that drifts slowly does not count
    as noise; ``lag1_correlation`` = 1 − D₁/D₂ = (γ₁ − γ₂)/(γ₀ − γ₂) with D_m = E(Y_k −
    Y_{k+m})²/2, free of each pixel's mean and so of its finite-window bias (γ₂ ≈ 0: −1/2 for
    a tick-rounded regular pixel, module notes). With ``inv_q`` (1/Q_eff) each bin also gets
    the value a steady pixel would show, from γ₀ = σ² + G₁, γ₁ = (G₂ − 2G₁)/2,
    γ₂ = (G₃ − 2G₂ + G₁)/2 and each pixel's own rounding terms, and ``static_consistent``:
    whether the lag-1 correlation about each pixel's own mean (which light that drifts
    raises) agrees within :data:`LAG1_TOLERANCE` with a steady pixel's, its finite-window
    bias included.
    """
    st = iv if isinstance(iv, IntervalStatistics) else statistics_of(iv)
    mu_p = st.mean_interval
    n_int = st.n_intervals.astype(np.float64)
    s1, s2, sy, sky, syy = st.sum_k, st.sum_kk, st.sum_y, st.sum_ky, st.sum_yy
    with np.errstate(invalid="ignore", divide="ignore"):
        ss = syy - sy * sy / n_int  # within-pixel sum of squares about the mean
        sxx = s2 - s1 * s1 / n_int
        sxy = sky - s1 * sy / n_int
        rss = ss - np.where(sxx > 0, sxy * sxy / sxx, 0.0)  # about the pixel's linear trend
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        px = use_pixel & (mu_p >= lo) & (mu_p < hi) & (n_int >= MIN_INTERVALS_PER_PIXEL - 1)
        if px.sum() < 20:
            continue
        gamma0 = ss[px].sum() / (n_int[px] - 1).sum()
        gamma0_detrended = rss[px].sum() / (n_int[px] - 2).sum()
        n_pairs = float(st.n_pairs[px].sum())
        d1 = float(st.sum_lag1[px].sum() / n_pairs) if n_pairs else math.nan
        n_triples = float(st.n_triples[px].sum())
        d2 = float(st.sum_lag2[px].sum() / n_triples) if n_triples else math.nan
        mean_mu = float(np.mean(mu_p[px]))
        row = {"interval_from_ticks": float(lo), "interval_to_ticks": float(hi),
               "mean_interval_ticks": mean_mu, "pixels": int(px.sum()), "pairs": int(n_pairs),
               "rsd": float(math.sqrt(gamma0) / mean_mu),
               "rsd_detrended": float(math.sqrt(max(gamma0_detrended, 0.0)) / mean_mu),
               # mean-free: 1 − D₁/D₂ = (γ₁ − γ₂)/(γ₀ − γ₂); (γ₀ − D₁)/γ₀ with γ₀ about each pixel's
               # own mean read −0.32 for −0.45 in 200 ticks (γ₀ is overestimated by ≈ (1/6)/(n − 1))
               "lag1_correlation": float(1.0 - d1 / d2) if d2 > 0 else math.nan,
               "lag1_correlation_about_pixel_means": float((gamma0 - d1) / gamma0)}
        if inv_q is not None:
            m, n = mu_p[px], n_int[px]
            s2 = m * m * max(inv_q, 0.0)
            mv = (n * s2 + 1.0 / 6.0) / (n * n)
            g1 = rounding_variance(m, s2, mv)
            g2 = rounding_variance(2 * m, 2 * s2, 4 * mv)
            g3 = rounding_variance(3 * m, 3 * s2, 9 * mv)
            w = n - 1
            gamma0, gamma1, gamma2 = s2 + g1, (g2 - 2 * g1) / 2, (g3 - 2 * g2 + g1) / 2
            row["expected_lag1_correlation"] = float(np.sum(w * (gamma1 - gamma2)) / np.sum(w * (gamma0 - gamma2)))
            # about each pixel's own mean, the n − 1 divisor does not make γ₀ unbiased for these
            # anti-correlated intervals: E ss = n·γ₀ − V(n)/n, V(n) = var(T_last − T_first) = n·σ² + ⅙
            expected_ss = np.sum(n * gamma0 - (n * s2 + 1.0 / 6.0) / n) / np.sum(w)
            rho = float(1.0 - np.sum(w * (gamma0 - gamma1)) / np.sum(w) / expected_ss)
            row["expected_lag1_correlation_about_pixel_means"] = rho
            # light that changes slowly raises γ₁ about the pixels' means (the mean-free figure
            # does not see it); light that changes within an interval can also push it below
            # any steady pixel's
            row["static_consistent"] = bool(abs(row["lag1_correlation_about_pixel_means"] - rho) <= LAG1_TOLERANCE)
        rows.append(row)
    return rows


#: Shortest mean interval (ticks) of a pixel used for the flat-field spread: at one spike a tick
#: every pixel reads the same whatever its gain.
MIN_GAIN_INTERVAL_TICKS = 2.0


def _gain_spread(iv: PixelIntervals, sigma2_per_mu2: float, tile: int, min_spikes: int):
    """Flat-field relative spread of the pixel rates after the finite-window noise (module notes)."""
    h, w = iv.height, iv.width
    mu = iv.mean_interval
    n = iv.n_spikes
    # a pixel near the one-bit ceiling (a spike nearly every tick) no longer follows its light
    valid = (n >= min_spikes) & np.isfinite(mu) & (mu >= MIN_GAIN_INTERVAL_TICKS)
    rate = np.where(valid, 1.0 / np.where(valid, mu, 1.0), np.nan)
    # relative variance of 1/μ_p from its finite window (interval noise + end rounding)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.maximum(n - 1, 1)
        noise_rel = (sigma2_per_mu2 / k) + 1.0 / (6.0 * k * k * np.where(valid, mu, 1.0) ** 2)
    spreads, dof, tile_mu = [], [], []
    for y0 in range(0, h - tile + 1, tile):
        for x0 in range(0, w - tile + 1, tile):
            ys, xs = np.mgrid[y0:y0 + tile, x0:x0 + tile]
            idx = (ys * w + xs).ravel()
            ok = valid[idx]
            m = int(ok.sum())
            if m < 0.75 * tile * tile:
                continue
            r = rate[idx][ok]
            design = np.column_stack([np.ones(m), (ys.ravel()[ok] - y0), (xs.ravel()[ok] - x0)])
            coef, *_ = np.linalg.lstsq(design, r, rcond=None)
            fit = design @ coef
            rel = (r - fit) / fit
            total = float(np.sum(rel**2) / (m - 3))
            spreads.append(total - float(np.mean(noise_rel[idx][ok])))
            dof.append(m - 3)
            tile_mu.append(float(np.mean(mu[idx][ok])))
    if len(spreads) < 8:
        return None, {"tiles": len(spreads)}
    spreads = np.array(spreads)
    order = np.sort(spreads)
    quarter = order[: max(1, len(order) // 4)]
    # The lower quartile of χ²_ν/ν tiles sits below 1 by ≈ 0.674·√(2/ν): undo that so a
    # uniform flat field is unbiased; the mean of the lowest quarter sits ≈ 1.27·√(2/ν) below.
    nu = float(np.median(dof))
    factor = 1 - 1.27 * math.sqrt(2 / nu)
    var = float(np.mean(quarter)) / factor
    info = {"tiles": int(len(spreads)), "median_tile_spread": float(math.sqrt(max(np.median(spreads), 0.0))),
            "flattest_quarter_spread": float(math.sqrt(max(var, 0.0)))}
    # how the spread depends on the light: a gain spread is the same at every level, an
    # offset (e.g. dark-current) spread grows as the light falls
    tile_mu = np.array(tile_mu)
    by_level = []
    edges = np.quantile(tile_mu, [0, 0.25, 0.5, 0.75, 1.0])
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        inside = (tile_mu >= lo) & (tile_mu <= hi)
        if inside.sum() >= 4:
            by_level.append({"mean_interval_ticks": float(np.mean(tile_mu[inside])), "tiles": int(inside.sum()),
                             "median_spread": float(math.sqrt(max(np.median(spreads[inside]), 0.0)))})
    info["spread_by_level"] = by_level
    return (math.sqrt(var) if var > 0 else 0.0), info


#: A pixel is hot when its *directional excess* (below) exceeds this many local texture scales.
#: Chosen on the tuning scenes of ``benchmarks/bench_hot_pixels.py`` (a ramp, the strip under a
#: dark edge, skimage's camera and brick, Q = 1,000 and 16,250): the smallest whole number with
#: no false report in 20 seeds of any of them; reported on the other scenes there.
HOT_SIGMAS = 10.0
#: How much of the disagreement between the four lines through a pixel (:func:`_line_disagreement`)
#: its prediction can miss by, added to the texture scale: near an edge or a corner no line predicts
#: the pixel well. Chosen on the tuning scenes (the smallest that removes the false reports at the
#: corners of bright shapes in skimage's astronaut); ≤ 1/(2·HOT_SIGMAS), so that two adjacent hot
#: pixels, each raising one line of the other by half its excess, can still be found.
HOT_EDGE_FRACTION = 0.05
#: Side (pixels) of the window whose mirror statistic gives a pixel's local texture scale.
HOT_WINDOW = 11
#: A pixel counts as able to show the hot pixels found when its detection limit is at most this
#: fraction of their dark current (so a hot pixel there is found with near certainty).
HOT_SEARCH_MARGIN = 0.5
#: The hot fraction is measured only when the mirror statistic (dark specks as strong as the
#: reports) expects at most this fraction of the reports to be texture, and ≥ 5 are found.
HOT_MAX_MIRROR_FRACTION = 0.1
#: Hot-pixel positions listed in the result at most.
MAX_LISTED_HOT_PIXELS = 1000

# the four lines through a pixel: pairs of opposite neighbours
_LINES = (((0, 1), (0, -1)), ((1, 0), (-1, 0)), ((1, 1), (-1, -1)), ((1, -1), (-1, 1)))


def _neighbour(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """a[y + dy, x + dx], reflected at the borders."""
    p = np.pad(a, 1, mode="reflect") if min(a.shape) > 1 else np.pad(a, 1, mode="edge")
    h, w = a.shape
    return p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]


def _line_means(log_rate: np.ndarray) -> np.ndarray:
    """(4, H, W): log of the mean rate of the two opposite neighbours on each line through a pixel."""
    rate = np.exp(log_rate)
    return np.stack([np.log((_neighbour(rate, *a) + _neighbour(rate, *b)) / 2) for a, b in _LINES])


def directional_excess(log_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far a pixel stands above (and, mirrored, below) *every* line through it, in log rate.

    ``bright = y − max_d m_d`` and ``dark = min_d m_d − y``, where m_d = log((r[p + d] +
    r[p − d])/2) is the light a line d through the pixel predicts from its two opposite
    neighbours (horizontal, vertical, both diagonals; r = e^y, the rate). A dark current is
    added to one pixel and to none of its neighbours, so a hot pixel stands above all four
    lines; scene texture that is not a single-pixel point — an edge, a line, a strip, a
    gradient — lies on at least one line through the pixel (along the edge or the line) and
    gives ``bright`` ≤ its noise. The arithmetic mean of the two rates (not of their logs)
    keeps a pixel beside a strong edge from standing above the geometric mean across it.
    ``dark`` is the same statistic for a single dark pixel, which no dark current makes: it
    measures the texture's own single-pixel points.
    """
    means = _line_means(log_rate)
    return log_rate - means.max(axis=0), means.min(axis=0) - log_rate


def _pixel_rates(iv, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel firing rate (spikes per tick) and the relative variance of its noise.

    From the spike intervals where a pixel has ≥ 3 spikes: (n − 1)/(last − first), relative
    variance 1/(Q·(n − 1)) (Gamma law of n − 1 intervals, seed 000 §5.1) + 1/(6·span²)
    (rounding of the two end spikes); otherwise (n + ½)/T with a count's relative variance
    1/(n + ½).
    """
    n = iv.n_spikes.astype(np.float64)
    span = np.maximum((iv.last_tick - iv.first_tick).astype(np.float64), 1.0)
    many = n >= 3
    with np.errstate(divide="ignore", invalid="ignore"):
        rate = np.where(many, (n - 1) / span, (n + 0.5) / iv.n_ticks)
        rel_var = np.where(many, 1.0 / (q * np.maximum(n - 1, 1)) + 1.0 / (6.0 * span**2), 1.0 / (n + 0.5))
    shape = (iv.height, iv.width)
    return rate.reshape(shape), rel_var.reshape(shape)


def _texture_scale(dark: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Robust location and scale (median, 1.4826 × median absolute deviation) of the mirror
    statistic in a window around each pixel, the pixel's own 3×3 left out (a hot pixel does not
    raise its neighbours' mirror statistic)."""
    from scipy import ndimage

    window = max(3, min(window, 2 * (min(dark.shape) // 2) + 1))
    foot = np.ones((window, window), bool)
    c = window // 2
    foot[c - 1:c + 2, c - 1:c + 2] = window <= 3
    loc = ndimage.median_filter(dark, footprint=foot, mode="mirror")
    scale = 1.4826 * ndimage.median_filter(np.abs(dark - loc), footprint=foot, mode="mirror")
    return loc, scale


#: The 8 neighbours (dy, dx) and the line of :data:`_LINES` each lies on.
_NEIGHBOURS = tuple((d, i) for i, pair in enumerate(_LINES) for d in pair)


def hot_pixel_statistics(iv, q_electrons: float | None, window: int = HOT_WINDOW) -> dict:
    """The per-pixel maps behind hot-pixel detection (:func:`_hot_dead`), as arrays (H, W).

    ``z`` (bright) and ``z_mirror`` (dark): the directional excess of the log rate
    (:func:`directional_excess`) about its local median, in units of the local texture scale
    (the mirror statistic's robust spread in the window, combined with the pixel's own rate
    noise and :data:`HOT_EDGE_FRACTION` of the disagreement between the four lines);
    ``z_pair``: the same over the three lines that miss the pixel's brightest neighbour
    (``brightest``: its index in :data:`_NEIGHBOURS`), for two adjacent hot pixels, each of which
    raises one line of the other; ``baseline`` the light a pixel would show without its own
    excess (spikes per tick, from its neighbours); ``limit`` the smallest added rate (spikes per
    tick) that would put the pixel above :data:`HOT_SIGMAS`.
    """
    from scipy import ndimage

    q = max(float(q_electrons or 1.0), 1.0)
    rate, rel_var = _pixel_rates(iv, q)
    y = np.log(rate)
    means = _line_means(y)
    bright, dark = y - means.max(axis=0), means.min(axis=0) - y
    loc, scale = _texture_scale(dark, window)
    ring = np.ones((3, 3), bool)
    ring[1, 1] = False
    noise_var = ndimage.median_filter(rel_var, footprint=ring, mode="mirror")  # at the neighbours' light
    edge = (HOT_EDGE_FRACTION * (means.max(axis=0) - means.min(axis=0))) ** 2
    s = np.sqrt(scale**2 + np.maximum(rel_var, 0.0) + edge)
    s_limit = np.sqrt(scale**2 + noise_var + edge)
    baseline = np.exp(ndimage.median_filter(y, footprint=ring, mode="mirror"))
    with np.errstate(over="ignore"):
        limit = baseline * np.expm1(np.maximum(loc + HOT_SIGMAS * s_limit, 0.0))
    # the three lines that miss the brightest neighbour
    brightest = np.argmax(np.stack([_neighbour(y, *d) for d, _ in _NEIGHBOURS]), axis=0)
    line_of = np.array([line for _, line in _NEIGHBOURS])[brightest]
    other = np.arange(len(_LINES))[:, None, None] != line_of[None]
    hi = np.where(other, means, -np.inf).max(axis=0)
    lo = np.where(other, means, np.inf).min(axis=0)
    s_pair = np.sqrt(scale**2 + np.maximum(rel_var, 0.0) + (HOT_EDGE_FRACTION * (hi - lo)) ** 2)
    return {"rate": rate, "z": (bright - loc) / s, "z_mirror": (dark - loc) / s, "baseline": baseline,
            "limit": limit, "texture_scale": scale, "z_pair": (y - hi - loc) / s_pair, "brightest": brightest}


def _hot_pairs(stats: dict, candidates: np.ndarray, single: np.ndarray) -> np.ndarray:
    """Pairs of adjacent pixels, each the other's brightest neighbour, each above the three lines
    that miss the other (``z_pair`` > :data:`HOT_SIGMAS`), and each with the excess of the single
    hot pixels (``single``): within 3 robust standard deviations of their median excess (at least
    10 % of it). A dark current adds the same charge whatever the light; a two-pixel point of the
    scene has its own brightness."""
    excess = stats["rate"] - stats["baseline"]
    level = float(np.median(excess[single]))
    spread = max(3 * 1.4826 * float(np.median(np.abs(excess[single] - level))), 0.1 * level)
    ok = candidates & (stats["z_pair"] > HOT_SIGMAS) & (np.abs(excess - level) <= spread)
    pair = np.zeros_like(ok)
    for k, (d, _) in enumerate(_NEIGHBOURS):
        # p's brightest neighbour is p + d, and that one's brightest neighbour is p (index of −d)
        back = next(j for j, (e, _) in enumerate(_NEIGHBOURS) if e == (-d[0], -d[1]))
        partner_ok = _neighbour(ok.astype(np.int8), *d).astype(bool)
        partner_back = _neighbour(stats["brightest"], *d) == back
        pair |= ok & (stats["brightest"] == k) & partner_ok & partner_back
    return pair


def _steady_in_both_halves(iv, hot: np.ndarray, excess_rate: np.ndarray, q: float) -> np.ndarray:
    """Whether each candidate's excess is there, the same, in both halves of the recording.

    A dark current is steady; light that moves past a pixel lifts it in one half only. Each
    half's excess is its count minus the median of its 8 neighbours' counts; it must be
    within 5σ (count noise, σ² = m/Q + 1/3 per pixel) + 25 % of the whole recording's excess
    scaled to the half.
    """
    from scipy import ndimage

    ring = np.ones((3, 3), bool)
    ring[1, 1] = False
    h, w = iv.height, iv.width
    first = (iv.n_spikes_first_half if iv.n_spikes_first_half is not None else iv.n_spikes // 2)
    first = first.reshape(h, w).astype(np.float64)
    counts = iv.n_spikes.reshape(h, w).astype(np.float64)
    ok = np.ones((h, w), bool)
    for part, ticks in ((first, iv.n_ticks // 2), (counts - first, iv.n_ticks - iv.n_ticks // 2)):
        local = ndimage.median_filter(part, footprint=ring, mode="mirror")
        expected = excess_rate * ticks
        sigma = np.sqrt(np.maximum(local, 0.0) / q + 1.0 / 3.0 + np.maximum(part, 0.0) / q)
        ok &= np.abs(part - local - expected) <= 5.0 * sigma + 0.25 * np.abs(expected)
    return ok & hot


def _wilson_95(k: int, n: int) -> list[float]:
    """Wilson's 95 % score interval of a binomial proportion k/n (Wilson, JASA 22, 209, 1927):
    it keeps its coverage at the small counts where ± 1.96 standard errors of k/n do not."""
    z2 = 1.96**2
    p = k / n
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) * 1.96 / (1 + z2 / n)
    return [max(centre - half, 0.0), min(centre + half, 1.0)]


def _poisson_upper_95(k: int) -> float:
    """One-sided 95 % upper limit of a Poisson mean after k events (Garwood)."""
    from scipy import stats

    return float(stats.chi2.ppf(0.95, 2 * (k + 1)) / 2)


def _hot_dead(iv, q_electrons: float | None):
    """Hot pixels (by dark current), dead pixels and the darkest pixels' counts.

    Hot: a dark current adds the same charge to one pixel whatever its light and adds none to
    its neighbours; scene texture scales with the light and is shared with neighbours along
    some line (an edge, a strip, a gradient). A pixel is reported when its directional excess
    over every line through it (:func:`directional_excess`) exceeds :data:`HOT_SIGMAS` local
    texture scales (measured on the mirror statistic, single dark pixels, which no dark current
    makes), the excess is steady over both halves of the recording (light that moves past a
    pixel lifts it in one half), and it is not part of a cluster of ≥ 3 reports (a structure).

    What is stated: the dark current of the hot pixels (median excess × Q / duration, with its
    standard error) and their fraction among the pixels able to show them (detection limit ≤
    :data:`HOT_SEARCH_MARGIN` × that dark current), with its binomial error — *measured* only
    when ≥ 5 are found and the mirror statistic expects ≤ :data:`HOT_MAX_MIRROR_FRACTION` of
    them to be texture; otherwise an upper bound (Garwood 95 %). When none is found: none with
    ≥ L e⁻/s (the median detection limit) among the pixels with that limit, fewer than 3/n (95 %).
    The fraction of reported pixels with another report within 1.5 px is given beside what
    random placement gives (hot pixels are placed at random; texture reports cluster).
    """
    from scipy import ndimage

    h, w = iv.height, iv.width
    counts = iv.n_spikes.reshape(h, w).astype(np.float64)
    local = ndimage.median_filter(counts, size=3, mode="nearest")
    dead = (counts == 0) & (local >= 10)  # silent where the neighbours give ≥ 10 (P(0) < e^-10)
    q = max(float(q_electrons or 1.0), 1.0)
    out: dict = {"dead_pixels": int(dead.sum()), "dead_pixel_fraction": float(dead.mean())}
    if h < 3 or w < 3:
        hot = np.zeros((h, w), bool)
        stats = None
    else:
        stats = hot_pixel_statistics(iv, q_electrons)
        excess_rate = np.maximum(stats["rate"] - stats["baseline"], 0.0)
        hot = (stats["z"] > HOT_SIGMAS) & ~dead
        hot = _steady_in_both_halves(iv, hot, excess_rate, q)
        if hot.sum() >= 5:  # adjacent pairs, whose excess must match the single ones'
            pairs = _hot_pairs(stats, ~dead & ~hot, hot)
            hot |= _steady_in_both_halves(iv, pairs, excess_rate, q)
        labels, n_labels = ndimage.label(hot, structure=np.ones((3, 3), bool))
        sizes = np.bincount(labels.ravel(), minlength=n_labels + 1)
        clustered = (sizes[labels] >= 3) & hot
        out["hot_candidates_in_clusters"] = int(clustered.sum())
        hot &= ~clustered
    n_hot = int(hot.sum())
    out.update({"hot_pixels": n_hot, "hot_pixel_fraction_of_all": float(hot.mean()), "hot_pixel_sigmas": HOT_SIGMAS,
                "hot_pixel_detection": "directional excess over every line through the pixel"})
    ys, xs = np.nonzero(hot)
    out["hot_pixel_positions"] = [[int(y), int(x)] for y, x in zip(ys[:MAX_LISTED_HOT_PIXELS],
                                                                     xs[:MAX_LISTED_HOT_PIXELS], strict=True)]
    if n_hot:
        with_neighbour = ndimage.convolve(hot.astype(np.int32), np.ones((3, 3), np.int32), mode="constant") - 1
        out["hot_pixels_with_reported_neighbour_fraction"] = float(np.mean(with_neighbour[hot] > 0))
        out["hot_pixels_with_reported_neighbour_if_random"] = float(1 - (1 - n_hot / (h * w)) ** 8)
    if stats is None:
        out["hot_pixel_fraction"] = float(hot.mean())
        out["hot_pixel_reason"] = ("the image is too small (fewer than 3 rows or columns) to tell a pixel from its "
                                   "neighbours")
        out["darkest_percentile_spikes"] = float(np.percentile(counts[~dead], 1)) if (~dead).any() else 0.0
        return out, hot, dead
    rate_to_e = q * iv.clock_hz  # spikes per tick → e⁻/s
    valid = ~dead & np.isfinite(stats["limit"])
    out["hot_pixel_detection_limit_median_e_per_s"] = (float(np.median(stats["limit"][valid]) * rate_to_e)
                                                       if q_electrons and valid.any() else None)
    if n_hot and q_electrons is not None:
        currents = excess_rate[hot] * rate_to_e
        level = float(np.median(currents))
        searchable = valid & (stats["limit"] * rate_to_e <= HOT_SEARCH_MARGIN * level)
        n_search = int(searchable.sum())
        found = int(np.count_nonzero(hot & searchable))
        mirror = int(np.count_nonzero((stats["z_mirror"] > HOT_SIGMAS) & searchable))
        out["hot_pixel_dark_current_e_per_s"] = level
        out["hot_pixel_dark_current_standard_error_e_per_s"] = (float(1.2533 * np.std(currents) / math.sqrt(n_hot))
                                                                if n_hot > 1 else None)
        out["hot_pixel_searchable_pixels"] = n_search
        out["hot_pixels_in_searchable"] = found
        out["hot_pixel_texture_reports_expected"] = mirror  # single dark specks as strong: texture's own points
        if n_search and found >= 5 and mirror <= HOT_MAX_MIRROR_FRACTION * found:
            fraction = found / n_search
            out["hot_pixel_fraction"] = fraction
            out["hot_pixel_fraction_standard_error"] = math.sqrt(fraction * (1 - fraction) / n_search)
            out["hot_pixel_fraction_range"] = _wilson_95(found, n_search)
        else:
            upper = _poisson_upper_95(found) / max(n_search, 1)
            out["hot_pixel_fraction"] = None
            out["hot_pixel_fraction_upper_bound"] = min(upper, 1.0)
            out["hot_pixel_reason"] = (
                f"{found} reports among the {n_search} pixels able to show them, and the scene's own single bright "
                f"points cannot be told from them (as many dark ones: {mirror})" if n_search and found >= 5 else
                f"only {found} reports among the {n_search} pixels dark or smooth enough to show them")
    elif not n_hot and q_electrons is not None and valid.any():
        limit = float(np.median(stats["limit"][valid]) * rate_to_e)
        n_search = int(np.count_nonzero(valid & (stats["limit"] * rate_to_e <= limit)))
        out["hot_pixel_fraction"] = 0.0
        out["hot_pixel_bound"] = {"dark_current_at_least_e_per_s": limit, "searchable_pixels": n_search,
                                  "fraction_upper_bound": 3.0 / max(n_search, 1)}
    else:
        out["hot_pixel_fraction"] = None
        out["hot_pixel_reason"] = "no threshold is known, so no dark current follows from the excess"
    live = counts[~dead]
    out["darkest_percentile_spikes"] = float(np.percentile(live, 1)) if live.size else 0.0
    return out, hot, dead


def calibrate(source: SpikeSource, *, max_ticks: int | None = None, tile: int = TILE) -> dict:
    """Estimate Q_eff, the flat-field gain spread, hot/dead pixels and a dark-current bound.

    Returns a JSON-ready dict; every figure that the recording cannot support is ``None``
    with a ``reason`` (and a bound where one exists) — never a made-up value.

    Parameters
    ----------
    source : SpikeSource
        A recording of a flat, still, unchanging scene.
    max_ticks : int, optional
        Ticks used (default: all).
    tile : int
        Side of the tiles of the gain-spread map, pixels.

    Returns
    -------
    dict
        ``threshold`` (Q_eff, e⁻), ``gain_spread``, ``defects`` (hot and dead pixels),
        ``dark_current``, ``interval_table`` and ``static`` (the check that the scene held still),
        each figure with how it was found, or ``None`` with a ``reason``.
    """
    tile = check_int("tile", tile, 2, 64)
    iv = interval_statistics(source, max_ticks=max_ticks)
    if iv.n_ticks < 20:
        raise ViformError(f"the recording has {iv.n_ticks} ticks; calibration needs at least 20")
    npx = iv.height * iv.width
    mu_p = iv.mean_interval
    n_int = iv.n_intervals
    duration_s = iv.n_ticks / iv.clock_hz
    result: dict = {"height": iv.height, "width": iv.width, "n_ticks": iv.n_ticks,
                    "recording_ticks": int(source.n_ticks), "clock_hz": iv.clock_hz,
                    "duration_s": duration_s, "spikes": int(iv.n_spikes.sum()),
                    "recorded_threshold_electrons": (None if source.threshold_electrons is None
                                                     else float(source.threshold_electrons)),
                    "mean_firing_rate_per_tick": float(iv.n_spikes.sum() / (npx * iv.n_ticks))}
    static, sinfo = _checkerboard_static(iv, tile)
    result["static"] = sinfo

    # ---- Q_eff
    mu_hi = iv.n_ticks / (MIN_INTERVALS_PER_PIXEL + 1)
    use = static & (n_int >= MIN_INTERVALS_PER_PIXEL) & (mu_p >= MIN_INTERVAL_TICKS) & (mu_p <= mu_hi)
    pairs = np.where(use, iv.n_pairs, 0.0)
    triples = np.where(use, iv.n_triples, 0.0)
    mu_use = np.where(use, mu_p, 1.0)
    q_info: dict = {"pairs": int(pairs.sum()), "triples": int(triples.sum()), "pixels": int(use.sum()),
                    "mean_interval_range_ticks": [MIN_INTERVAL_TICKS, float(mu_hi)]}
    q_eff = None
    edges = _bins(2.0, max(3.0, mu_hi))
    table_pixels = static & (n_int >= MIN_INTERVALS_PER_PIXEL - 1)
    table = interval_table(iv, table_pixels, edges)
    if mu_hi <= MIN_INTERVAL_TICKS:
        q_info["reason"] = (f"recording too short: {iv.n_ticks} ticks hold fewer than {MIN_INTERVALS_PER_PIXEL} "
                            f"intervals of ≥ {MIN_INTERVAL_TICKS:g} ticks")
    elif triples.sum() < MIN_PAIRS_FOR_Q:
        q_info["reason"] = (f"too few steady interval triples ({int(triples.sum())} < {MIN_PAIRS_FOR_Q}) in pixels "
                            f"whose mean interval lies in {MIN_INTERVAL_TICKS:g}–{mu_hi:.3g} ticks: the recording is "
                            "too short, too small, too dark or too bright, or not steady")
    else:
        # drift-robust: second differences of the intervals cancel light that changes linearly
        # light that drifts moves each pixel's tick phase over the recording: the rounding term
        # is averaged over that drift (:func:`_drift_spread`)
        spread, drift_info = _drift_spread(iv, use)
        q_info.update(drift_info)
        second = (mu_use, triples, np.where(use, iv.sum_second, 0.0), "second", n_int)
        inv_q, se = _fit_inverse_q(*second, spread)
        rel = drift_info["drift_relative_standard_error"]
        drift_fragile = False
        if spread.any():
            # the drift is estimated, and its width only approximately (the light need not drift
            # linearly): its error moves the rounding term, and so 1/Q_eff. ±10 % at least.
            rel = max(rel, DRIFT_MODEL_TOLERANCE)
            shifted = [_fit_inverse_q(*second, spread * max(1 + sign * rel, 0.0))[0] for sign in (-1, 1)]
            drift_se = abs(shifted[1] - shifted[0]) / 2
            q_info["inverse_q_drift_standard_error"] = drift_se
            se = math.hypot(se, drift_se)
            # where the pixels' tick phases are coherent (a uniform field), a drift of the light
            # moves the rounding term so much that the fit has no root within that tolerance
            drift_fragile = min(inv_q, *shifted) <= 0
        # check: successive-interval differences, which linear drift inflates
        inv_q1, se1 = _fit_inverse_q(mu_use, pairs, np.where(use, iv.sum_lag1, 0.0), "lag1", n_int, spread)
        q_info.update(inverse_q=inv_q, inverse_q_standard_error=se, inverse_q_lag1=inv_q1,
                      inverse_q_lag1_standard_error=se1)
        q_info["drift_free"] = bool(abs(inv_q1 - inv_q) <= 2 * math.hypot(se, se1))
        table = interval_table(iv, table_pixels, edges, max(inv_q, 0.0))
        pairs_ok = sum(r["pairs"] for r in table if r["static_consistent"])
        pairs_all = sum(r["pairs"] for r in table) or 1
        q_info["static_consistent_pair_fraction"] = pairs_ok / pairs_all
        lower = 1.0 / (max(inv_q, 0.0) + 2 * se)
        if drift_fragile:
            drifted = 100 * drift_info["median_relative_drift_over_recording"]
            q_info["reason"] = (f"the light drifted by {drifted:.2g} % over the recording while most pixels "
                                "fired in step with the readout clock (a uniform scene): the rounding to ticks then "
                                "depends on the drift more than the data can tell, so no figure (record a steadier "
                                "or more varied scene)")
        elif pairs_ok / pairs_all < 0.5:
            # light that changes only adds interval variance: the fit bounds Q_eff from below
            q_info["reason"] = ("not static enough: successive intervals are not anti-correlated as a steady "
                                "pixel's are (see the interval table), so the light changed during the recording; "
                                "the fitted value is a lower bound")
            q_info["q_eff_lower_bound_electrons"] = lower
            q_info["q_eff_fit_electrons"] = 1.0 / inv_q if inv_q > 0 else None
        elif inv_q - 2 * se <= 0:
            q_info["reason"] = ("interval noise not resolved above tick rounding: the intervals are as regular as "
                                "rounding allows")
            q_info["q_eff_lower_bound_electrons"] = lower
        else:
            q_eff = 1.0 / inv_q
            q_info["q_eff_range_electrons"] = [1.0 / (inv_q + 2 * se), 1.0 / (inv_q - 2 * se)]
    q_info["q_eff_electrons"] = q_eff
    result["threshold"] = q_info
    result["interval_table"] = table

    # ---- gain spread
    s2_rel = 1.0 / q_eff if q_eff else (1.0 / q_info.get("q_eff_lower_bound_electrons", math.inf)
                                        if q_info.get("q_eff_lower_bound_electrons") else 0.0)
    spread, ginfo = _gain_spread(iv, s2_rel, tile, MIN_INTERVALS_PER_PIXEL + 1)
    if spread is None:
        ginfo["reason"] = f"fewer than 8 {tile}×{tile} tiles with ≥ {MIN_INTERVALS_PER_PIXEL + 1} spikes a pixel"
    ginfo["gain_spread_fraction"] = spread
    ginfo["note"] = "upper bound where scene texture at the pixel scale remains (cannot be told from PRNU)"
    result["gain_spread"] = ginfo

    # ---- hot / dead / dark
    # hot-pixel dark current at the threshold a preset would use (the estimate, else its bound)
    q_hot = q_eff or q_info.get("q_eff_lower_bound_electrons") or result["recorded_threshold_electrons"]
    hd, _, _ = _hot_dead(iv, q_hot)
    dark: dict = {"dark_current_e_per_s": None}
    darkest_rate_per_s = hd["darkest_percentile_spikes"] / duration_s
    if q_eff:
        bound = max(darkest_rate_per_s, 1.0 / duration_s) * q_eff
        dark["dark_current_upper_bound_e_per_s"] = bound
    dark["reason"] = (f"the recording ({duration_s * 1e3:.3g} ms) is far shorter than the time a pixel takes to "
                      "fire in the dark (threshold / dark current); "
                      "its darkest pixels still see light, so only an upper bound follows")
    result["dark_current"] = dark
    result["defects"] = hd
    return result


def preset_from_calibration(result: dict, name: str = "calibrated", *, fallback_threshold_electrons=None):
    """A :class:`~viform.sensors.spike_presets.SpikePreset` from :func:`calibrate`'s result.

    The measured figures go into the sensor, bounds as their bound; a figure the recording
    could not give keeps the chip preset's value, and the preset's ``calibration`` record
    says which (``measured``, ``bounds``, ``recorded``, ``assumed``). The threshold, when
    neither measured nor bounded, is the one the recording's own metadata states (a
    simulator's sidecar: ``recorded``), else ``fallback_threshold_electrons`` (``assumed``);
    with neither, :class:`~viform._validate.ViformError` is raised: a preset that measured
    no threshold would silently repeat a chip default.

    Parameters
    ----------
    result : dict
        What :func:`calibrate` returned.
    name : str
        The preset's name.
    fallback_threshold_electrons : float, optional
        Threshold Q, e⁻, to assume when neither measured nor recorded.

    Returns
    -------
    SpikePreset
        The preset, with its ``calibration`` record.
    """
    from viform.sensors.spike_presets import SpikePreset, _chip_parameters

    # measured: an estimate with its error in the result; bounds: {field: {"value", "kind", "why"}},
    # the value the preset simulates with; assumed: the chip preset's value
    measured, assumed, bounds = {}, {}, {}

    def bound(name, value, kind, why):
        bounds[name] = {"value": float(value), "kind": kind, "why": why}

    recorded = {}  # figures the recording's own metadata states (a simulator's sidecar), not measured
    q = result["threshold"].get("q_eff_electrons")
    q_low = result["threshold"].get("q_eff_lower_bound_electrons")
    q_file = result.get("recorded_threshold_electrons")
    if q:
        measured["threshold_electrons"] = float(round(q))
    elif q_low:
        # the recording bounds Q_eff from below: the least regular sensor it allows
        bound("threshold_electrons", round(q_low), "lower bound", "the recording is not steady enough for an estimate")
    elif q_file:
        recorded["threshold_electrons"] = float(q_file)
    elif fallback_threshold_electrons:
        assumed["threshold_electrons"] = float(fallback_threshold_electrons)
    else:
        raise ViformError("the recording gives no threshold (" + str(result["threshold"].get("reason") or
                                                                  "not estimated") + ") and does not record one: "
                          "no preset written (a preset that measured nothing would only repeat a chip default)")
    g = result["gain_spread"].get("gain_spread_fraction")
    if g is not None:
        bound("gain_spread_fraction", g, "upper bound", "scene texture at the pixel scale cannot be told from the "
              "pixels' gain spread in one static recording")
    d = result["defects"]
    if d.get("hot_pixels") and d.get("hot_pixel_fraction") and d.get("hot_pixel_dark_current_e_per_s"):
        measured["hot_pixel_fraction"] = d["hot_pixel_fraction"]
        if q:
            measured["hot_pixel_dark_current_e_per_s"] = d["hot_pixel_dark_current_e_per_s"]
        else:
            bound("hot_pixel_dark_current_e_per_s", d["hot_pixel_dark_current_e_per_s"], "lower bound",
                  "from the lower bound of the threshold")
    elif d.get("hot_pixel_fraction_upper_bound") is not None:
        bound("hot_pixel_fraction", d["hot_pixel_fraction_upper_bound"], "upper bound",
              f"{d['hot_pixels']} reported, but {d.get('hot_pixel_reason', 'they cannot be told from texture')}: "
              "a bound (95 %), not a measurement")
    elif d.get("hot_pixels") == 0 and d.get("hot_pixel_bound"):
        hb = d["hot_pixel_bound"]
        bound("hot_pixel_fraction", hb["fraction_upper_bound"], "upper bound",
              f"none found with a dark current ≥ {hb['dark_current_at_least_e_per_s']:.3g} e⁻/s in "
              f"{hb['searchable_pixels']} pixels dark or smooth enough to show one (95 %); hot pixels with less dark "
              "current hide under the light")
    params = _chip_parameters(result["clock_hz"])
    import dataclasses

    fields = {f.name for f in dataclasses.fields(params)}
    values = {**measured, **recorded, **assumed, **{k: v["value"] for k, v in bounds.items()}}
    if "hot_pixel_fraction" in bounds and "hot_pixel_fraction" not in measured:
        values["hot_pixel_fraction"] = 0.0  # simulate none: the bound only says how many could hide
    params = dataclasses.replace(params, **{k: v for k, v in values.items() if k in fields})
    what = ", ".join(f"{k} = {v:.4g}" for k, v in measured.items()) or "nothing"
    description = f"calibrated from a {size_text(result['height'], result['width'])} recording: measured {what}"
    if bounds:
        description += "; bounds " + ", ".join(f"{k} {'≥' if v['kind'] == 'lower bound' else '≤'} {v['value']:.4g}"
                                               for k, v in bounds.items())
    if recorded:
        description += "; from the recording's metadata (not measured) " + ", ".join(
            f"{k} = {v:.4g}" for k, v in recorded.items())
    if assumed:
        description += "; assumed " + ", ".join(f"{k} = {v:.4g}" for k, v in assumed.items())
    calibration = {"measured": measured, "recorded": recorded, "assumed": assumed, "bounds": bounds,
                   "threshold": {k: v for k, v in result["threshold"].items()},
                   "gain_spread": result["gain_spread"], "defects": result["defects"],
                   "dark_current": result["dark_current"], "static": result["static"],
                   "interval_table": result["interval_table"]}
    if "source" in result:
        calibration["source"] = result["source"]
    return SpikePreset(name, description, result["height"], result["width"], params, None, calibration)
