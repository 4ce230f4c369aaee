"""Sub-threshold quantization readout of a spike camera (seed 000 §4.5).

When the time-sensitivity requirement τ̆ is shorter than the dark limit τ̂, a pixel that has
not reached Q within τ̆ says nothing by its spikes. Seed 000 §4.5 reads its partial
accumulated charge instead, quantized to N levels of Q, extending the dynamic range to
DR = 20·lg(τ̆/τ̌·N) dB.

Model used here (synchronous variant): every τ̆ (``sensitivity_ticks`` readout ticks) each
pixel's partial charge is read and quantized to ``floor(N·n/Q)`` (n electrons since its last
reset). The light of a window is then measured by charge balance:
electrons = Q·(spikes in the window) + n_end − n_start, quantized in steps of Q/N, so the
weakest light seen in one window is Q/(N·τ̆) and the strongest Q/τ̌ — the seed's DR.

The partial charge is exact photon statistics: the spike simulator works in integrated
charge time (time rescaling, :mod:`viform.sensors.spike`), where the electrons of one
interval are a unit-rate Poisson process that reaches its Q-th arrival at the Gamma(Q, 1)
target t; given t, the first Q − 1 arrivals are independent and uniform on (0, t). A pixel
read at rescaled charge c has therefore collected Binomial(Q − 1, c/t) electrons — but
only at the *first* read of an interval. Later reads of the same interval are conditioned
on the earlier ones: having counted n₁ electrons by charge c₁, the pixel holds
n₁ + Binomial(Q − 1 − n₁, (c − c₁)/(t − c₁)) at c (the remaining arrivals are uniform on
(c₁, t)). The read charge is so a non-decreasing counting process within an interval with
exactly Poisson increments, and a window's charge balance Q·spikes + n_end − n_start is
exactly the Poisson number of electrons that arrived in it. (Drawing every read afresh
made the charge go down between reads and, at 2 e⁻ per window, overestimated the light by
69 % with 4× the photon-noise spread.) The stationary initial state (a length-biased
interval) has the same uniform law of its interior arrivals, so the first read is exact
there too; after a tick of heavy saturation (≥ 48·Q e⁻ in one tick, where the pixel fires
every tick and sub-threshold reads carry no information) the first read is this same
binomial approximation. The readout is non-destructive: the spike train is the one the
plain sensor gives with the same seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_int, check_positive
from viform.light.scenes import Scene
from viform.sensors.base import Sensor
from viform.sensors.spike import FIXED_POINT_SCALE, SpikeSensor
from viform.stream.container import SpikeStream


def subthreshold_dynamic_range_db(shortest_s: float, sensitivity_s: float, levels: int) -> float:
    """DR = 20·lg(τ̆/τ̌·N) dB with sub-threshold quantization to N levels (seed 000 §4.5).

    Examples
    --------
    >>> round(subthreshold_dynamic_range_db(10e-9, 10e-3, 100), 6)
    160.0
    """
    shortest = check_positive("shortest_s", shortest_s)
    sens = check_positive("sensitivity_s", sensitivity_s)
    n = check_int("levels", levels, 1)
    if sens < shortest:
        raise ViformError(f"sensitivity_s = {sensitivity_s!r} must be ≥ shortest_s = {shortest_s!r}")
    return 20.0 * math.log10(sens / shortest * n)


@dataclass
class SubthresholdCapture:
    """Spikes plus the sub-threshold levels read at the end of every window.

    Attributes
    ----------
    spikes : SpikeStream
    levels : ndarray (n_windows + 1, H, W) of int
        Quantized partial charge, ``floor(N·n/Q)``, at the start (row 0) and end of each window.
    sensitivity_ticks : int
        τ̆ in ticks.
    levels_n : int
        N.
    """

    spikes: SpikeStream
    levels: np.ndarray
    sensitivity_ticks: int
    levels_n: int

    @property
    def sensitivity_s(self) -> float:
        return self.sensitivity_ticks / self.spikes.clock_hz

    def window_counts(self) -> np.ndarray:
        """Spikes per pixel in each window (n_windows, H, W)."""
        t = self.spikes.spikes
        w = self.sensitivity_ticks
        n = t.shape[0] // w
        return t[: n * w].reshape(n, w, *t.shape[1:]).sum(axis=1)

    def electrons_per_s(self) -> np.ndarray:
        """Light of each window by charge balance, e⁻/s (seed 000 §4.5). Shape (n_windows, H, W)."""
        q = self.spikes.threshold_electrons
        counts = self.window_counts()
        n = counts.shape[0]
        lv = self.levels[: n + 1].astype(np.float64)
        # ≥ 0 by construction: a level only drops at a spike, by less than N levels (Q)
        electrons = q * counts + (lv[1:] - lv[:-1]) * q / self.levels_n
        return electrons / self.sensitivity_s

    def spike_only_electrons_per_s(self) -> np.ndarray:
        """The same windows measured by spike counts alone (no sub-threshold readout)."""
        return self.spikes.threshold_electrons * self.window_counts() / self.sensitivity_s


class SubthresholdSpikeSensor(Sensor):
    """A spike sensor with sub-threshold quantization readout every τ̆ (seed 000 §4.5).

    Parameters
    ----------
    sensor : SpikeSensor
    sensitivity_ticks : int
        τ̆ in readout ticks.
    levels : int
        N, the number of sub-threshold quantization levels of Q.
    """

    name = "spike-subthreshold"

    def __init__(self, sensor: SpikeSensor | None = None, sensitivity_ticks: int = 400, levels: int = 100):
        self.sensor = sensor or SpikeSensor()
        self.sensitivity_ticks = check_int("sensitivity_ticks", sensitivity_ticks, 1)
        self.levels = check_int("levels", levels, 1, 1 << 20)

    def describe(self) -> dict:
        """The spike sensor's parameters plus τ̆ (ticks) and N."""
        return {**self.sensor.describe(), "model": self.name, "sensitivity_ticks": self.sensitivity_ticks,
                "subthreshold_levels": self.levels, "dynamic_range_db": self.dynamic_range_db()}

    def dynamic_range_db(self) -> float:
        """20·lg(τ̆/τ̌·N), τ̌ = one tick (seed 000 §4.5)."""
        p = self.sensor.parameters
        return subthreshold_dynamic_range_db(1 / p.clock_hz, self.sensitivity_ticks / p.clock_hz, self.levels)

    def capture(self, scene: Scene, duration_s: float, *, seed: int = 0) -> SubthresholdCapture:
        check_positive("duration_s", duration_s)
        s = self.sensor
        p = s.parameters
        h, w = s.check_scene(scene, s.height, s.width)
        state = s.initial_state(h, w, seed)
        q = s.threshold_map_electrons(h, w).ravel()
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, 0x5B7])))
        last = _LastRead(state.counter.copy(), np.zeros(q.size), np.zeros(q.size, np.int64), first=True)
        levels = [self._read(state, q, rng, last)]
        blocks = []
        for _, blk in s.simulate(scene, duration_s, seed=seed, block_ticks=self.sensitivity_ticks, state=state):
            blocks.append(blk)
            levels.append(self._read(state, q, rng, last))
        spikes = SpikeStream(np.concatenate(blocks), p.clock_hz, p.threshold_electrons, 0.0,
                             s.capture_metadata(scene, seed, 1) | {"subthreshold_levels": self.levels,
                                                                   "sensitivity_ticks": self.sensitivity_ticks})
        return SubthresholdCapture(spikes, np.stack(levels).reshape(-1, h, w), self.sensitivity_ticks, self.levels)

    def _read(self, state, q, rng, last: _LastRead) -> np.ndarray:
        """Quantized partial charge now; ``last`` (the previous read) is updated in place."""
        c = state.charge / FIXED_POINT_SCALE
        t = state.target / FIXED_POINT_SCALE
        if self.sensor.parameters.photon_noise:
            whole_q = q.astype(np.int64)
            # c < 0: inside the reset dead time, nothing collected yet
            c = np.clip(c, 0.0, t)
            # the same interval as at the last read: no new target drawn since (counter unchanged)
            same = np.zeros(q.size, bool) if last.first else state.counter == last.counter
            base_n = np.where(same, last.n, 0)
            base_c = np.where(same, last.c, 0.0)
            room = np.maximum(t - base_c, 1e-300)
            # the arrivals still to come before the Q-th are uniform on (base_c, t)
            frac = np.clip((c - base_c) / room, 0.0, 1.0)
            n = base_n + rng.binomial(np.maximum(whole_q - 1 - base_n, 0), frac)
            last.counter[:] = state.counter
            last.c[:] = c
            last.n[:] = n
            last.first = False
        else:
            n = np.floor(np.clip(c, 0, q))
        return np.floor(self.levels * n / q).astype(np.int64)


@dataclass
class _LastRead:
    """Per-pixel record of the previous read: interval counter, rescaled charge and electrons."""

    counter: np.ndarray
    c: np.ndarray
    n: np.ndarray
    first: bool = True
