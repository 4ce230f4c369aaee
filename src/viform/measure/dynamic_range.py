"""Dynamic range of spike continuous photography (seed 000 §4.2–§4.5).

Formulas (seed 000):

* §4.4: DR = 20·lg(τ̂/τ̌) = 20·lg(Q/(τ̌·I_d)) dB, τ̌ the shortest readout time, τ̂ = Q/I_d the
  longest signal interval (dark current I_d in e⁻/s). τ̌ = 10 ns, τ̂ = 1 s → 160 dB; τ̂ = 10 s
  → 180 dB (§4.5).
* §4.5: with sub-threshold quantization to N levels after a time-sensitivity limit τ̆,
  DR = 20·lg(τ̆/τ̌·N) dB; τ̌ = 10 ns, τ̆ = 10 ms, N = 100 → 160 dB.
* §4.3: the strongest light: τ = Q/(photons/s · QE); Q = 100, 10⁵ lux on a 100 µm² pixel
  (4.09·10¹⁰ photons/s), QE 0.7 → 3.5 ns.

:func:`measure_spike_dynamic_range` measures τ̌ and τ̂ on a simulated
:class:`~viform.sensors.spike.SpikeSensor` (brightest light: one spike per tick; darkness:
the mean dark interval) and compares with the formula for its parameters.
"""

from __future__ import annotations

import math

import numpy as np

from viform._validate import ViformError, check_int, check_positive
from viform.sensors.subthreshold import subthreshold_dynamic_range_db


def dynamic_range_db(shortest_s: float, longest_s: float) -> float:
    """DR = 20·lg(τ̂/τ̌) dB (seed 000 §4.4).

    Parameters
    ----------
    shortest_s : float
        Shortest interval the pixel can give, τ̌, s.
    longest_s : float
        Longest interval, τ̂ (in the dark), s.

    Returns
    -------
    float
        Dynamic range, dB.

    Examples
    --------
    >>> round(dynamic_range_db(10e-9, 1.0), 6), round(dynamic_range_db(10e-9, 10.0), 6)
    (160.0, 180.0)
    """
    shortest = check_positive("shortest_s", shortest_s)
    longest = check_positive("longest_s", longest_s, allow_inf=True)
    if longest < shortest:
        raise ViformError(f"longest_s = {longest_s!r} must be ≥ shortest_s = {shortest_s!r}")
    return 20.0 * math.log10(longest / shortest)


#: Clip lengths, seconds, at which the CLI shows the clip-limited range next to the formula's:
#: ``viform demo``'s 40 ms, one second, ten seconds.
CLIP_LENGTHS_S = (0.04, 1.0, 10.0)


def clip_limited_dynamic_range_db(shortest_s: float, longest_s: float, clip_s: float) -> float:
    """DR that a clip of ``clip_s`` seconds can show: 20·lg(min(τ̂, T)/τ̌) dB.

    The formula of seed 000 §4.4 assumes intervals as long as τ̂ = Q/I_d are measured; in a
    clip of length T no interval longer than T lies wholly inside it, so the darkest light a
    clip can measure is the one with an interval of T (one spike at each end). A SpikeOne-class
    sensor (one 25 µs tick, τ̂ = 812 s, 150 dB) shows at most 64 dB in 40 ms.

    Examples
    --------
    >>> round(clip_limited_dynamic_range_db(25e-6, 812.0, 0.04), 1)
    64.1
    """
    clip = check_positive("clip_s", clip_s)
    longest = check_positive("longest_s", longest_s, allow_inf=True)
    return dynamic_range_db(shortest_s, min(longest, max(clip, shortest_s)))


def clip_limited_lines(shortest_s: float, longest_s: float, formula_db: float) -> list[str]:
    """Lines for a user: the range a clip of each length in :data:`CLIP_LENGTHS_S` can show, beside the formula's."""
    parts = [f"{clip_limited_dynamic_range_db(shortest_s, longest_s, t):.1f} dB in "
             + (f"{t * 1e3:g} ms" if t < 1 else f"{t:g} s") for t in CLIP_LENGTHS_S if t < longest_s]
    if not parts:
        return []
    return [f"within a clip: {', '.join(parts)} (no interval longer than the clip can be measured in it); the "
            f"{formula_db:.1f} dB of the formula needs intervals of {longest_s:.3g} s, a still scene recorded "
            "that long"]


def longest_signal_interval_s(threshold_electrons: float, dark_current_e_per_s: float) -> float:
    """τ̂ = Q / I_d: longer intervals are dark current, not signal (seed 000 §4.4)."""
    q = check_positive("threshold_electrons", threshold_electrons)
    dark = check_positive("dark_current_e_per_s", dark_current_e_per_s)
    return q / dark


def dynamic_range_from_dark_db(threshold_electrons: float, shortest_s: float, dark_current_e_per_s: float) -> float:
    """DR = 20·lg(Q/(τ̌·I_d)) dB (seed 000 §4.4)."""
    return dynamic_range_db(shortest_s, longest_signal_interval_s(threshold_electrons, dark_current_e_per_s))


def levels_for_dynamic_range(shortest_s: float, sensitivity_s: float, target_db: float) -> int:
    """Smallest N with 20·lg(τ̆/τ̌·N) ≥ ``target_db`` (seed 000 §4.5)."""
    shortest = check_positive("shortest_s", shortest_s)
    sens = check_positive("sensitivity_s", sensitivity_s)
    n = 10 ** (target_db / 20.0) * shortest / sens
    return max(1, math.ceil(n * (1 - 1e-12)))


def shortest_interval_s(threshold_electrons: float, lux: float, optics=None) -> float:
    """Time to collect Q electrons at ``lux`` (seed 000 §4.3): τ = Q/(photons/s·QE).

    ``optics`` defaults to the seed's pixel: 100 µm², QE 0.7.

    Examples
    --------
    >>> round(shortest_interval_s(100, 1e5) * 1e9, 1)
    3.5
    """
    from viform.light.radiometry import PixelOptics

    q = check_positive("threshold_electrons", threshold_electrons)
    check_positive("lux", lux)
    optics = optics or PixelOptics(pixel_pitch_m=10e-6, quantum_efficiency=0.7)
    return q / float(optics.electrons_per_s(lux))


def seed_examples() -> list[dict]:
    """The seed's worked examples with the value computed here next to the seed's."""
    return [
        {"example": "τ̌ = 10 ns, τ̂ = 1 s (§4.4)", "seed_db": 160.0,
         "computed_db": dynamic_range_db(10e-9, 1.0)},
        {"example": "τ̌ = 10 ns, τ̂ = 10 s (§4.5)", "seed_db": 180.0,
         "computed_db": dynamic_range_db(10e-9, 10.0)},
        {"example": "sub-threshold: τ̌ = 10 ns, τ̆ = 10 ms, N = 100 (§4.5)", "seed_db": 160.0,
         "computed_db": subthreshold_dynamic_range_db(10e-9, 10e-3, 100)},
        {"example": "strongest light: Q = 100, 1e5 lux, 100 µm², QE 0.7 (§4.3)", "seed_ns": 3.5,
         "computed_ns": shortest_interval_s(100, 1e5) * 1e9},
    ]


def measure_spike_dynamic_range(sensor=None, *, dark_duration_s: float | None = None, size: int = 16,
                                seed: int = 0) -> dict:
    """Measure τ̌, τ̂ and the DR of a simulated spike sensor and compare with the formula.

    τ̌: the shortest interval seen under light far above saturation (one spike per tick).
    τ̂: the mean interval in darkness (dark current only), estimated as pixels·time/spikes.
    The formula value is 20·lg(Q/(τ̌·I_d)) with τ̌ = 1/clock (seed 000 §4.4). The relative
    standard error of the measured τ̂ is 1/√(spikes) (Poisson count), reported as
    ``tolerance_db`` (3σ).

    Parameters
    ----------
    sensor : SpikeSensor, optional
        The sensor (default: :class:`~viform.sensors.SpikeSensor` with 2,000 e⁻/s dark current).
    dark_duration_s : float, optional
        Length of the dark capture, s (default: 50 expected dark intervals, at most 2·10⁶ ticks).
    size : int
        Side of the square pixel array, pixels.
    seed : int
        Seed of the sensor's noise.

    Returns
    -------
    dict
        τ̌ and τ̂ (formula and measured, s), the dark spikes, the DR by formula and measured (dB) and
        ``tolerance_db``, the measurement's 3σ.
    """
    from viform.light.scenes import StillScene
    from viform.sensors.spike import SpikeSensor

    sensor = sensor or SpikeSensor(dark_current_e_per_s=2000.0)
    p = sensor.parameters
    if p.dark_current_e_per_s <= 0:
        raise ViformError("the sensor has no dark current: τ̂ and the dynamic range are infinite")
    size = check_int("size", size, 1, 512)
    tau_hat = p.threshold_electrons / p.dark_current_e_per_s
    if dark_duration_s is None:
        dark_duration_s = min(50 * tau_hat, 2e6 / p.clock_hz)
    # ten thresholds per tick: far above saturation, still inside the simulator's fixed point
    lux_bright = float(p.optics.lux_from_electrons_per_s(10 * p.threshold_electrons * p.clock_hz))
    bright = SpikeSensor(p).capture(StillScene(np.full((size, size), lux_bright)), 64 / p.clock_hz, seed=seed)
    ticks = np.nonzero(bright.spikes.reshape(bright.n_ticks, -1).T)
    shortest_ticks = int(np.diff(ticks[1])[np.diff(ticks[0]) == 0].min())
    dark_spikes = 0
    n_ticks = 0
    for _, blk in SpikeSensor(p, random_initial_charge=True).simulate(
            StillScene(np.zeros((size, size))), dark_duration_s, seed=seed + 1):
        dark_spikes += int(np.count_nonzero(blk))
        n_ticks += blk.shape[0]
    if dark_spikes == 0:
        raise ViformError("no dark spike was seen: lengthen dark_duration_s")
    measured_shortest = shortest_ticks / p.clock_hz
    measured_longest = size * size * n_ticks / p.clock_hz / dark_spikes
    formula = dynamic_range_from_dark_db(p.threshold_electrons, 1.0 / p.clock_hz, p.dark_current_e_per_s)
    measured = dynamic_range_db(measured_shortest, measured_longest)
    return {
        "threshold_electrons": p.threshold_electrons, "clock_hz": p.clock_hz,
        "dark_current_e_per_s": p.dark_current_e_per_s,
        "shortest_s_formula": 1.0 / p.clock_hz, "shortest_s_measured": measured_shortest,
        "longest_s_formula": tau_hat, "longest_s_measured": measured_longest,
        "dark_spikes": dark_spikes, "dr_formula_db": formula, "dr_measured_db": measured,
        "tolerance_db": 20 * math.log10(1 + 3 / math.sqrt(dark_spikes)),
    }
