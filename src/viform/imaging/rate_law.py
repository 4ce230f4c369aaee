"""The spike camera's rate law: firing probability per tick against light, and its inverse.

A pixel under steady light λ (e⁻ per tick, signal + dark) crosses its threshold Q at the
points of a renewal process (seed 000 §5.1: in integrated-charge time the intervals are
Gamma(Q, 1)), but the readout gives one bit per tick (seed 000 §4.3), so a tick with two
crossings shows one spike. The firing rate per tick r is therefore *not* λ/Q near
saturation, and light taken as Q·r reads low: −36 % at Q = 1 and one e⁻ per tick, −4.1 %
at Q = 100 and a mean interval of one tick, −2.5 % at Q = 1 even at 20 ticks. The exact
laws, with a reset dead time t_d (d ticks, D = λ·d e⁻ of charge time lost per reset):

* self-reset (the charge past a crossing is kept): in charge time the crossings are a
  renewal process with cycles G + D, G ~ Gamma(Q, 1); a tick (λ of charge time) holds a
  crossing when the forward recurrence time is below λ, whose density is S(x)/(Q + D)
  (S the survival function of G + D), so

      r(λ) = E[min(G + D, λ)] / (Q + D)
           = (D + Q·P(Q + 1, λ − D) + (λ − D)·(1 − P(Q, λ − D))) / (Q + D)   for λ > D,
           = λ / (Q + D)                                                     otherwise,

  (P the regularized lower incomplete gamma function); without photon noise G = Q and
  r = min(λ/(Q + D), 1). At d = 0, Q = 1 this is 1 − e^(−λ).
* reset at readout (the charge is drained at the tick that reads the spike): a cycle is
  N = ⌈(G + D)/λ⌉ whole ticks and r = 1/E[N], E[N] = Σ_{m ≥ 0} P(G + D > m·λ). Without
  photon noise N is a whole number and r a staircase; its inverse is taken at the middle
  of each step (N − ½ ticks per cycle).

:func:`electrons_per_tick_from_rate` inverts the law (monotone in λ) by interpolating a
table of r on a log grid of λ. Where the measured rate reaches the law's supremum (one
spike every tick: every tick of an accumulation window fired, an interval of one tick)
the light cannot be inverted; the pixel is flagged ``saturated`` and given the lower
bound Q·r/(1 − r·d) (any law loses crossings, never adds them: r ≤ λ/(Q + λ·d)).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from scipy import special

from viform._validate import ViformError, check_choice, check_non_negative, check_positive

#: Light grid of the inversion table, in units of Q e⁻ per tick (from far below to far above saturation).
_GRID_FROM, _GRID_TO, _GRID_POINTS = 1e-9, 1e7, 32001
#: Above this many terms the readout-reset sum is taken by Euler–Maclaurin (error ~ λ³·|f''|/720).
_DIRECT_TERMS = 200


def firing_rate_per_tick(electrons_per_tick, threshold_electrons: float, dead_time_ticks: float = 0.0,
                         reset: str = "self", photon_noise: bool = True) -> np.ndarray:
    """Steady firing probability per tick r(λ) of a pixel collecting ``electrons_per_tick`` (module notes)."""
    lam = np.asarray(electrons_per_tick, dtype=np.float64)
    q = float(check_positive("threshold_electrons", threshold_electrons))
    d = float(check_non_negative("dead_time_ticks", dead_time_ticks))
    check_choice("reset", reset, ("self", "readout"))
    dead = lam * d
    with np.errstate(divide="ignore", invalid="ignore"):
        if reset == "self":
            if not photon_noise:
                return np.minimum(lam / (q + dead), 1.0)
            x = np.maximum(lam - dead, 0.0)
            mean_min = np.where(lam > dead, dead + q * special.gammainc(q + 1, x) + x * special.gammaincc(q, x), lam)
            return np.where(lam > 0, mean_min / (q + dead), 0.0)
        if not photon_noise:
            return np.where(lam > 0, 1.0 / np.ceil((q + dead) / np.where(lam > 0, lam, 1.0)), 0.0)
        return np.where(lam > 0, 1.0 / _mean_cycle_ticks(lam, q, d), 0.0)


def _mean_cycle_ticks(lam: np.ndarray, q: float, d: float) -> np.ndarray:
    """E[N], N = ⌈(G + D)/λ⌉ ticks, G ~ Gamma(Q): Σ_{m ≥ 0} S(m·λ − D), S the survival of G.

    The m₀ = ⌊D/λ⌋ + 1 terms with m·λ ≤ D are 1; the rest, S(φ + j·λ) with φ = m₀·λ − D,
    are summed directly when few, else by Euler–Maclaurin:
    (1/λ)·∫_φ^∞ S + S(φ)/2 + (λ/12)·f(φ), ∫_φ^∞ S = Q·S_{Q+1}(φ) − φ·S_Q(φ), f the density.
    """
    out = np.full(lam.shape, np.inf)
    ok = lam > 0
    v = lam[ok]
    dead = v * d
    m0 = np.floor(dead / v) + 1.0
    phi = m0 * v - dead
    tail = q * special.gammaincc(q + 1, phi) - phi * special.gammaincc(q, phi)
    density = np.exp((q - 1) * np.log(phi) - phi - special.gammaln(q))
    total = m0 + tail / v + 0.5 * special.gammaincc(q, phi) + v / 12.0 * density
    reach = q + 12.0 * math.sqrt(q) + 40.0  # G beyond this: P < 1e-30
    for i in np.flatnonzero(reach / v < _DIRECT_TERMS):
        j = np.arange(int(reach / v[i]) + 2)
        total[i] = m0[i] + float(np.sum(special.gammaincc(q, phi[i] + j * v[i])))
    out[ok] = total
    return out


def _logit(r):
    return np.log(r) - np.log1p(-r)


@functools.lru_cache(maxsize=32)
def _inverse_table(q: float, d: float, reset: str, photon_noise: bool):
    """(logit r, log λ) on the strictly increasing part of the law, and the largest r there.

    logit r = ln r − ln(1 − r) spreads the approach to one spike per tick, where λ grows
    fast, so linear interpolation stays accurate there.
    """
    lam = q * np.geomspace(_GRID_FROM, _GRID_TO, _GRID_POINTS)
    r = firing_rate_per_tick(lam, q, d, reset, photon_noise)
    keep = np.concatenate([[True], r[1:] > np.maximum.accumulate(r)[:-1] * (1 + 1e-13)])
    keep &= r < 1.0
    return _logit(r[keep]), np.log(lam[keep]), float(r[keep][-1])


def electrons_per_tick_from_rate(rate_per_tick, threshold_electrons: float, dead_time_ticks: float = 0.0,
                                 reset: str = "self", photon_noise: bool = True):
    """Light λ (e⁻ per tick) whose steady firing rate is ``rate_per_tick``: the inverse of
    :func:`firing_rate_per_tick`.

    Returns ``(electrons_per_tick, saturated)``. ``saturated`` marks rates at or beyond the
    law's supremum (the readout fires every tick it can): the light there is only bounded
    from below, and that bound, Q·r/(1 − r·d), is returned for those pixels.
    """
    r = np.asarray(rate_per_tick, dtype=np.float64)
    if r.size and np.any(r < 0):
        raise ViformError(f"firing rate {float(np.min(r))!r} per tick is not allowed: rates must be ≥ 0")
    unknown = ~np.isfinite(r)
    if unknown.any():  # NaN in, NaN out
        lam, saturated = electrons_per_tick_from_rate(np.where(unknown, 0.0, r), threshold_electrons,
                                                      dead_time_ticks, reset, photon_noise)
        return np.where(unknown, np.nan, lam), saturated & ~unknown
    q = float(check_positive("threshold_electrons", threshold_electrons))
    d = float(check_non_negative("dead_time_ticks", dead_time_ticks))
    check_choice("reset", reset, ("self", "readout"))
    with np.errstate(divide="ignore", invalid="ignore"):
        lower = q * r / np.maximum(1.0 - r * d, 1e-300)
    if reset == "self" and not photon_noise:
        saturated = r >= 1.0
        return np.where(saturated, q * r, lower), saturated
    if reset == "readout" and not photon_noise:
        sup = 1.0 / (math.floor(d) + 1.0)
        saturated = r >= sup * (1 - 1e-12)
        with np.errstate(divide="ignore", invalid="ignore"):
            cycle = 1.0 / r - 0.5  # the middle of the staircase's step
            lam = np.where(r > 0, q / np.maximum(cycle - d, 0.5), 0.0)
        return np.where(saturated, np.maximum(lower, lam), lam), saturated
    log_r, log_lam, top = _inverse_table(q, d, reset, bool(photon_noise))
    saturated = r >= top
    inside = (r > 0) & ~saturated
    lam = np.exp(np.interp(_logit(np.where(inside, r, 0.5)), log_r, log_lam))
    # below the table the law is linear, λ = Q·r/(1 − r·d) to within the grid's 1e-9
    lam = np.where(r <= 0, 0.0, np.where(_logit(np.where(inside, r, 0.5)) < log_r[0], lower, lam))
    lam = np.where(saturated, np.where(np.isfinite(lower), np.maximum(lower, q * r), q * r), lam)
    return lam, saturated


# ----------------------------------------------------------------- unbiased light from intervals
#
# The interval estimators give an unbiased *rate* r̂ (:mod:`viform.imaging.multi_interval`), but
# the light is λ = r⁻¹(r̂)'s convex inverse of it, so λ̂ = r⁻¹(r̂) reads high (Jensen): +4.8 % at
# Q = 1, 0.33 spikes per tick with K = 4. The estimator used instead is the function h of r̂
# whose expectation is λ over the law's range, h(r̂) = r⁻¹(r̂)·(1 + Σ_j c_j φ_j(logit r̂)) (φ_j
# hat functions on a grid of logit r̂), with one free value for the outcome "every interval one
# tick" (r̂ at the ceiling, where r⁻¹ is infinite). E_λ h(r̂) is linear in the c_j, so the c_j
# that make E_λ h(r̂) = λ on a grid of λ are a linear least-squares problem (rows divided by
# λ: relative bias; a small second-difference penalty keeps h smooth where no row reaches).
# The expectations are taken over the tick process itself, simulated exactly for the light
# (:func:`_tick_train`: Gamma(Q) charge per crossing, dead charge time, tick rounding, lost
# crossings, both resets), with each window weighted by the length of the interval it is
# centred on (an instant falls in an interval with probability ∝ its length, Palm calculus),
# and with r̂ − r, whose mean is exactly 0, as a control variate. Where no h can be unbiased
# — few intervals at the law's flat end, where the ceiling outcome's probability grows
# with λ while its value cannot — the fit's residual bias is kept (:class:`LightEstimator`)
# and the pixels whose estimate falls there are flagged.

#: Relative bias above which a pixel's light is flagged ``unresolved`` (the goal of the estimator).
UNRESOLVED_BIAS = 0.003
_FIT_RATES = 64      # rows: rates from 1 % of the ceiling to 0.985 of it (logit-spaced)
_FIT_NODES = 40      # hat functions on logit r̂ (fewer than the rows: the bias between rows stays small)
_FIT_SPIKES = 120_000  # simulated spikes per row (the control variate does the rest)
_FIT_SEED = 20_240_611
_FIT_MAX_CEILING_SHARE = 0.05  # rows fitted in full: instants at the ceiling at most this often
_FIT_FLAT_END_WEIGHT = 0.02  # weight of the other rows
_FIT_SMOOTHING = 0.02  # weight of the second differences of the c_j against the rows (relative bias)


@njit(cache=True)
def _ticks_from_draws(draws, phase, lam, dead_ticks, readout, n):
    """Spike ticks of one pixel under steady light ``lam`` e⁻ per tick, from the charge each crossing
    needs (``draws``: Gamma(Q), or Q without photon noise) and a uniform start ``phase`` in [0, 1).

    Self-reset: crossings at charge times C_k = Σ (G_i + λ·d), registered at tick ⌈C_k/λ⌉; two
    crossings in one tick are one spike. Readout reset: the tick that reads the spike drains the
    charge, the pixel waits d ticks, so successive spikes are ⌈d + G/λ⌉ ticks apart. Stops at n
    spikes or when the draws run out (the result may be shorter). The same draws serve every
    light (common random numbers: the fit's rows then differ only by the light).
    """
    ticks = np.empty(n, np.int64)
    m = draws.size
    if readout:
        t = 0
        for i in range(min(n, m)):
            t += int(np.ceil(dead_ticks + draws[i] / lam))
            ticks[i] = t
        return ticks[:min(n, m)]
    charge = phase * (draws[0] + lam * dead_ticks)  # stationary phase (burn-in removes the rest)
    last = np.int64(-1)
    i = 0
    j = 0
    while i < n and j < m:
        charge += draws[j]
        j += 1
        k = np.int64(np.ceil(charge / lam))
        if k != last:
            ticks[i] = k
            last = k
            i += 1
        charge += lam * dead_ticks
    return ticks[:i]


def _draws(q: float, n: int, seed: int) -> tuple[np.ndarray, float]:
    """n Gamma(Q) charges (a Generator's vectorized draws) and a uniform start phase."""
    rng = np.random.default_rng(seed)
    return rng.gamma(q, size=n), float(rng.random())


def _tick_train(lam, q, dead_ticks, readout, noise, n, seed):
    """n spike ticks of one pixel under steady light ``lam`` e⁻ per tick (:func:`_ticks_from_draws`),
    drawn afresh from ``seed``; enough charges are drawn for the crossings a tick merges."""
    per_spike = 1 if readout else 2 + int(math.ceil(lam / q))
    draws, phase = _draws(q, n * per_spike, seed) if noise else (np.full(n * per_spike, float(q)), 0.5)
    return _ticks_from_draws(draws, phase, float(lam), float(dead_ticks), bool(readout), int(n))


@njit(cache=True)
def _window_rates(ticks, k, burn):
    """The multi-interval rate Σ_w 1/span_w over the K windows of K intervals that hold interval
    c, for every c, and the interval's length (the Palm weight of an instant falling in it)."""
    n = ticks.size
    lo = burn + k - 1
    hi = n - k
    m = max(hi - lo, 0)
    rate = np.empty(m)
    weight = np.empty(m)
    for j in range(m):
        c = lo + j
        total = 0.0
        for w in range(k):
            s = c - w
            total += 1.0 / (ticks[s + k] - ticks[s])
        rate[j] = total
        weight[j] = ticks[c + 1] - ticks[c]
    return rate, weight


@njit(cache=True)
def _row_expectations(r_hat, w, r, ceiling, u0, du, base, n0, dn, n_nodes):
    """One row of the fit: the Palm-weighted means of h₀(r̂), h₀(r̂)·φ_j(logit r̂) (j < n_nodes) and
    of the ceiling outcome, each with r̂ − r as control variate (its mean is exactly 0); and the
    ceiling outcome's share. h₀ is ``base`` on the uniform logit grid (u0, du); φ_j hat
    functions on the uniform grid (n0, dn)."""
    m = r_hat.size
    total_w = 0.0
    mean_x = 0.0
    for i in range(m):
        total_w += w[i]
        mean_x += w[i] * (r_hat[i] - r)
    mean_x /= total_w
    sums = np.zeros(n_nodes + 2)
    covs = np.zeros(n_nodes + 2)
    var_x = 0.0
    nb = base.size
    for i in range(m):
        wi = w[i] / total_w
        xc = r_hat[i] - r - mean_x
        var_x += wi * xc * xc
        if r_hat[i] >= ceiling * (1 - 1e-12):
            sums[n_nodes + 1] += wi
            covs[n_nodes + 1] += wi * xc
            continue
        p = r_hat[i] / ceiling
        u = np.log(p) - np.log1p(-p)
        f = (u - u0) / du
        if f <= 0:
            h0 = base[0] * r_hat[i] / (ceiling / (1 + np.exp(-u0)))  # linear law below the table
        elif f >= nb - 1:
            h0 = base[nb - 1]
        else:
            a = int(f)
            h0 = base[a] + (f - a) * (base[a + 1] - base[a])
        v = wi * h0
        sums[0] += v
        covs[0] += v * xc
        g = (u - n0) / dn
        if g <= 0:
            j, t = 0, 0.0
        elif g >= n_nodes - 1:
            j, t = n_nodes - 2, 1.0
        else:
            j = int(g)
            t = g - j
        sums[1 + j] += v * (1 - t)
        covs[1 + j] += v * (1 - t) * xc
        sums[2 + j] += v * t
        covs[2 + j] += v * t * xc
    out = np.empty(n_nodes + 2)
    for c in range(n_nodes + 2):
        out[c] = sums[c] - covs[c] / max(var_x, 1e-300) * mean_x
    return out, sums[n_nodes + 1]


def _ceiling_rate(dead_ticks: float, reset: str) -> float:
    """The largest firing rate the readout can show: one spike a tick, or one per ⌊d⌋ + 1 ticks
    after a readout reset with d ticks of dead time."""
    return 1.0 if reset == "self" else 1.0 / (math.floor(dead_ticks) + 1.0)


class LightEstimator:
    """The unbiased light of a rate from K spikes a side, for one (Q, dead time, reset) (module notes).

    Attributes
    ----------
    electrons_per_tick_grid, residual_bias, ceiling_probability : ndarray
        The light grid of the fit, the relative bias E h(r̂)/λ − 1 left there, and the share of
        instants whose K spikes a side all lie one ceiling interval apart.
    unresolved_from_electrons_per_tick : float
        From this light up the bias may exceed :data:`UNRESOLVED_BIAS` (inf if nowhere). Below
        it, ``residual_bias`` is the bias left; above, it is only sampled on the grid (where the
        intervals take few values — few spikes, or a readout reset at large Q, a near-staircase —
        it swings between the grid's lights), so flagged pixels carry no stated bias.
    """

    def __init__(self, q, dead_ticks, reset, spikes_per_side, nodes, coef, ceiling_value, grid, residual, ceiling_p,
                 u_fine, base_fine):
        self._u_fine = u_fine
        self._base_fine = base_fine
        self._parts = (nodes, coef, ceiling_value, grid, residual, ceiling_p, u_fine, base_fine)
        self.threshold_electrons = q
        self.dead_time_ticks = dead_ticks
        self.reset = reset
        self.spikes_per_side = spikes_per_side
        self._nodes = nodes
        self._coef = coef
        self._ceiling_value = ceiling_value
        self.electrons_per_tick_grid = grid
        self.residual_bias = residual
        self.ceiling_probability = ceiling_p
        bad = np.flatnonzero(np.abs(residual) > UNRESOLVED_BIAS)
        # from the grid light before the first where the bias exceeds the goal (between two grid
        # lights the bias is only interpolated)
        self.unresolved_from_electrons_per_tick = float(grid[max(bad[0] - 1, 0)]) if bad.size else math.inf

    def _factor(self, u):
        return 1.0 + np.interp(u, self._nodes, self._coef, left=self._coef[0], right=self._coef[-1]) \
            if self._coef.size else np.ones_like(u)

    def electrons_per_tick(self, rate_per_tick):
        """(light e⁻ per tick, at the ceiling, unresolved) for rates ``rate_per_tick``."""
        r = np.asarray(rate_per_tick, dtype=np.float64)
        q, d, reset = self.threshold_electrons, self.dead_time_ticks, self.reset
        plain, saturated = electrons_per_tick_from_rate(r, q, d, reset, True)
        ceiling = _ceiling_rate(d, reset)
        top = r >= ceiling * (1 - 1e-12)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = _logit(np.clip(r / ceiling, 1e-300, 1 - 1e-16))
            # below the fine table's first rate the law is linear and the delta term negligible
            base = np.where(u < self._u_fine[0], plain, np.interp(u, self._u_fine, self._base_fine))
            lam = np.where(top, self._ceiling_value, base * self._factor(u))
        lam = np.where(r > 0, lam, 0.0)
        lam = np.where(np.isfinite(r), lam, np.nan)
        unresolved = (lam >= self.unresolved_from_electrons_per_tick) | top
        return lam, saturated | top, unresolved & np.isfinite(r)

    def bias_at(self, electrons_per_tick):
        """Relative bias left at the given light (interpolated on the fit's grid)."""
        return np.interp(np.log(electrons_per_tick), np.log(self.electrons_per_tick_grid), self.residual_bias)


def _variance_by_rate(q, d, reset, k, ceiling):
    """var r̂ (Palm-weighted) of the K-a-side rate on a logit grid of r: (logit r / ceiling, var)."""
    rates = ceiling / (1 + np.exp(-np.linspace(_logit(0.003), _logit(0.997), 24)))
    lam = electrons_per_tick_from_rate(rates, q, d, reset, True)[0]
    var = np.empty(rates.size)
    readout = reset == "readout"
    draws, phase = _draws(q, 40_000 * (1 if readout else 2 + int(math.ceil(lam[-1] / q))), _FIT_SEED + 1)
    for i, (v, r) in enumerate(zip(lam, rates, strict=True)):
        r_hat, w = _window_rates(_ticks_from_draws(draws, phase, float(v), d, readout, 40_000), k, 64)
        var[i] = (w / w.sum()) @ (r_hat - r) ** 2
    return _logit(rates / ceiling), var


def _delta_table(q, d, reset, k, ceiling):
    """The second-order (delta-method) light on a fine logit grid of r̂: r⁻¹(r̂) − ½·(r⁻¹)''(r̂)·var r̂,
    the correction held to at most 20 % of r⁻¹(r̂). The fit corrects what it leaves."""
    u_var, var = _variance_by_rate(q, d, reset, k, ceiling)
    u = np.linspace(_logit(1e-4), _logit(1 - 1e-4), 4001)
    r = ceiling / (1 + np.exp(-u))
    lam = electrons_per_tick_from_rate(r, q, d, reset, True)[0]
    second = np.gradient(np.gradient(lam, r), r)
    v = np.exp(np.interp(u, u_var, np.log(np.maximum(var, 1e-300))))
    correction = np.clip(0.5 * second * v, -0.2 * lam, 0.2 * lam)
    return u, lam - correction


#: Bumped whenever the fit changes, so that estimators cached on disk by an older version are not used.
_ESTIMATOR_VERSION = 4
_ESTIMATOR_FIELDS = ("nodes", "coef", "ceiling_value", "grid", "residual", "ceiling_p", "u_fine", "base_fine")


def _cache_file(q, d, reset, k):
    import hashlib
    import os
    from pathlib import Path

    root = os.environ.get("VIFORM_CACHE_DIR") or os.path.join(os.environ.get("XDG_CACHE_HOME")
                                                              or os.path.expanduser("~/.cache"), "viform")
    key = hashlib.sha1(repr((_ESTIMATOR_VERSION, _FIT_RATES, _FIT_NODES, _FIT_SPIKES, _FIT_SEED, q, d, reset,
                             k)).encode()).hexdigest()[:20]
    return Path(root) / "light-estimators" / f"{key}.npz"


@functools.lru_cache(maxsize=64)
def light_estimator(threshold_electrons: float, dead_time_ticks: float = 0.0, reset: str = "self",
                    spikes_per_side: int = 4) -> LightEstimator:
    """The unbiased light estimator for rates from ``spikes_per_side`` spikes a side (photon noise on).

    Fitted once per (Q, dead time, reset, K) on the simulated tick process (module notes; one to a
    few seconds) and cached: for the process, and on disk (``$VIFORM_CACHE_DIR``, else
    ``~/.cache/viform``; a cache that cannot be read or written is skipped).
    """
    q = float(check_positive("threshold_electrons", threshold_electrons))
    d = float(check_non_negative("dead_time_ticks", dead_time_ticks))
    check_choice("reset", reset, ("self", "readout"))
    k = int(spikes_per_side)
    if k < 1:
        raise ViformError(f"spikes_per_side = {spikes_per_side!r} is not allowed: it must be ≥ 1")
    path = _cache_file(q, d, reset, k)
    try:
        with np.load(path) as z:
            parts = [z[name] for name in _ESTIMATOR_FIELDS]
        return LightEstimator(q, d, reset, k, parts[0], parts[1], float(parts[2]), *parts[3:])
    except (OSError, KeyError, ValueError, TypeError):
        pass
    estimator = _fit_light_estimator(q, d, reset, k)
    try:
        from viform._io import atomic_open

        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path, output=False) as f:  # (a cache, not an output)
            np.savez(f, **{name: np.asarray(part) for name, part in zip(_ESTIMATOR_FIELDS, estimator._parts,
                                                                          strict=True)})
    except (OSError, ViformError):
        pass
    return estimator


def _fit_light_estimator(q: float, d: float, reset: str, k: int) -> LightEstimator:
    """Fit :class:`LightEstimator` (module notes)."""
    ceiling = _ceiling_rate(d, reset)
    rates = ceiling / (1 + np.exp(-np.linspace(_logit(0.01), _logit(0.985), _FIT_RATES)))
    grid = electrons_per_tick_from_rate(rates, q, d, reset, True)[0]
    nodes = np.linspace(_logit(0.005), _logit(0.995), _FIT_NODES)
    u_fine, base_fine = _delta_table(q, d, reset, k, ceiling)
    readout = reset == "readout"
    rows, ceiling_p = [], []
    n_nodes = nodes.size
    per_spike = 1 if readout else 2 + int(math.ceil(grid[-1] / q))
    # few electrons and few intervals make r̂ noisy: up to 4× the spikes where Q·K < 4
    n_spikes = int(_FIT_SPIKES * min(4.0, max(1.0, 4.0 / (q * k))))
    draws, phase = _draws(q, n_spikes * per_spike, _FIT_SEED)
    for lam, r in zip(grid, rates, strict=True):
        ticks = _ticks_from_draws(draws, phase, float(lam), d, readout, n_spikes)
        r_hat, w = _window_rates(ticks, k, 64)
        mean, ceiling_share = _row_expectations(r_hat, w, r, ceiling, u_fine[0], u_fine[1] - u_fine[0], base_fine,
                                                nodes[0], nodes[1] - nodes[0], n_nodes)
        rows.append(mean / lam)
        ceiling_p.append(ceiling_share)
    a = np.array(rows)
    ceiling_p = np.array(ceiling_p)
    design = a[:, 1:].copy()
    scale_sat = grid[-1]
    design[:, -1] *= scale_sat  # the ceiling value in units of the largest light of the grid
    # fitted in full where an unbiased h can exist (rows whose instants rarely see every interval at
    # the ceiling); beyond, at a low weight (the least bias there), and the residual is reported
    fit = np.where(ceiling_p <= _FIT_MAX_CEILING_SHARE, 1.0, _FIT_FLAT_END_WEIGHT)
    penalty = np.zeros((n_nodes - 2, n_nodes + 1))
    for j in range(n_nodes - 2):
        penalty[j, j:j + 3] = (1.0, -2.0, 1.0)
    penalty *= _FIT_SMOOTHING
    ridge = np.zeros((1, n_nodes + 1))
    ridge[0, -1] = 1e-3
    lhs = np.vstack([design * fit[:, None], penalty, ridge])
    rhs = np.concatenate([(1.0 - a[:, 0]) * fit, np.zeros(n_nodes - 1)])
    sol, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
    coef, ceiling_value = sol[:-1], float(sol[-1] * scale_sat)
    residual = a[:, 0] + design @ sol - 1.0
    return LightEstimator(q, d, reset, k, nodes, coef, ceiling_value, grid, residual, ceiling_p, u_fine, base_fine)


def unbiased_electrons_per_tick(rate_per_tick, threshold_electrons: float, dead_time_ticks: float = 0.0,
                                reset: str = "self", photon_noise: bool = True, spikes_per_side=4):
    """Light λ (e⁻ per tick) from interval rates r̂, unbiased where it can be (module notes).

    ``rate_per_tick``: rates from ``spikes_per_side`` spikes a side (K; one value, or one per
    pixel: K = 1 is interval imaging; the multi-interval rate Σ 1/span over its K windows).
    Returns ``(electrons_per_tick, saturated, unresolved)``: ``saturated`` as
    :func:`electrons_per_tick_from_rate` (every interval at the ceiling: the light there is
    the fit's value for that outcome, not a measurement); ``unresolved`` marks pixels whose
    light lies where no function of r̂ is unbiased to :data:`UNRESOLVED_BIAS` (the law's flat
    end with K spikes a side; :meth:`LightEstimator.bias_at` gives the bias left there).
    Without photon noise the pixel is deterministic and the plain inverse is returned
    (nothing flagged).
    """
    r = np.asarray(rate_per_tick, dtype=np.float64)
    if not photon_noise:
        lam, saturated = electrons_per_tick_from_rate(r, threshold_electrons, dead_time_ticks, reset, False)
        return lam, saturated, np.zeros(r.shape, bool)
    k = np.broadcast_to(np.asarray(spikes_per_side, dtype=np.int64), r.shape)
    if r.size and np.any(r[np.isfinite(r)] < 0):
        raise ViformError(f"firing rate {float(np.nanmin(r))!r} per tick is not allowed: rates must be ≥ 0")
    lam = np.empty(r.shape)
    saturated = np.zeros(r.shape, bool)
    unresolved = np.zeros(r.shape, bool)
    for kk in np.unique(k):
        if kk < 1:
            raise ViformError(f"spikes_per_side = {int(kk)} is not allowed: it must be ≥ 1")
        at = k == kk
        lam[at], saturated[at], unresolved[at] = light_estimator(float(threshold_electrons), float(dead_time_ticks),
                                                                 reset, int(kk)).electrons_per_tick(r[at])
    return lam, saturated, unresolved


@functools.lru_cache(maxsize=64)
def _count_variance(q: float, d: float, reset: str):
    """var of the spike count in n ticks ≈ a(r) + b(r)·n, tabulated on a logit grid of r (simulated
    tick process, windows of 32 and 256 ticks): (logit r/ceiling, a, b)."""
    ceiling = _ceiling_rate(d, reset)
    rates = ceiling / (1 + np.exp(-np.linspace(_logit(0.003), _logit(0.997), 24)))
    lam = electrons_per_tick_from_rate(rates, q, d, reset, True)[0]
    a, b = np.empty(rates.size), np.empty(rates.size)
    readout = reset == "readout"
    draws, phase = _draws(q, 60_000 * (1 if readout else 2 + int(math.ceil(lam[-1] / q))), _FIT_SEED + 2)
    for i, v in enumerate(lam):
        ticks = _ticks_from_draws(draws, phase, float(v), d, readout, 60_000)
        ticks = ticks[64:] - ticks[64]
        var = []
        for n in (32, 256):
            counts = np.bincount(ticks // n)[:-1]  # whole windows
            var.append(float(counts.var()))
        b[i] = (var[1] - var[0]) / (256 - 32)
        a[i] = var[0] - 32 * b[i]
    return _logit(rates / ceiling), a, b


def accumulation_electrons_per_tick(rate_per_tick, window_ticks, threshold_electrons: float,
                                    dead_time_ticks: float = 0.0, reset: str = "self", photon_noise: bool = True):
    """Light from the spike count of a window of n ticks (rate = count/n), to second order unbiased.

    λ̂ = r⁻¹(r̂) − ½·(r⁻¹)''(r̂)·var(r̂), var(r̂) = var(count in n ticks)/n² of the tick process at
    that rate (simulated once per (Q, dead time, reset): a + b·n). The correction is held to 20 %
    of r⁻¹(r̂) (near the ceiling); returns ``(electrons_per_tick, saturated)``.
    """
    r = np.asarray(rate_per_tick, dtype=np.float64)
    q, d = float(threshold_electrons), float(dead_time_ticks)
    lam, saturated = electrons_per_tick_from_rate(r, q, d, reset, photon_noise)
    if not photon_noise:
        return lam, saturated
    n = np.broadcast_to(np.asarray(window_ticks, dtype=np.float64), r.shape)
    ceiling = _ceiling_rate(d, reset)
    u_grid, a, b = _count_variance(q, d, reset)
    inside = (r > 0) & ~saturated & np.isfinite(r) & (n > 0)
    if not inside.any():
        return lam, saturated
    ri, ni = r[inside], n[inside]
    u = _logit(np.clip(ri / ceiling, 1e-300, 1 - 1e-16))
    var = np.maximum(np.interp(u, u_grid, a) + np.interp(u, u_grid, b) * ni, 0.0) / ni**2
    step = 1e-3 * np.minimum(ri, ceiling - ri)
    lo = electrons_per_tick_from_rate(ri - step, q, d, reset, True)[0]
    hi = electrons_per_tick_from_rate(ri + step, q, d, reset, True)[0]
    second = (hi - 2 * lam[inside] + lo) / step**2
    out = lam.copy()
    out[inside] = lam[inside] - np.clip(0.5 * second * var, -0.2 * lam[inside], 0.2 * lam[inside])
    return out, saturated
