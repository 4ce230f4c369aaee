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
