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
charge time (time rescaling, :mod:`viform.sensors.spike`), where a pixel holding rescaled
charge c below its Gamma(Q, 1) target t has collected Binomial(Q − 1, c/t) electrons (the
first Q − 1 arrivals of a Poisson process are uniform before the Q-th). The readout is
non-destructive: the spike train is the one the plain sensor gives with the same seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viform._validate import check_int, check_positive
from viform.light.scenes import Scene
from viform.sensors.spike import FIXED_POINT_SCALE, SpikeSensor
from viform.stream.container import SpikeStream


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
        electrons = q * counts + (lv[1:] - lv[:-1]) * q / self.levels_n
        return np.maximum(electrons, 0.0) / self.sensitivity_s

    def spike_only_electrons_per_s(self) -> np.ndarray:
        """The same windows measured by spike counts alone (no sub-threshold readout)."""
        return self.spikes.threshold_electrons * self.window_counts() / self.sensitivity_s


class SubthresholdSpikeSensor:
    """A spike sensor with sub-threshold quantization readout every τ̆ (seed 000 §4.5).

    Parameters
    ----------
    sensor : SpikeSensor
    sensitivity_ticks : int
        τ̆ in readout ticks.
    levels : int
        N, the number of sub-threshold quantization levels of Q.
    """

    def __init__(self, sensor: SpikeSensor | None = None, sensitivity_ticks: int = 400, levels: int = 100):
        self.sensor = sensor or SpikeSensor()
        self.sensitivity_ticks = check_int("sensitivity_ticks", sensitivity_ticks, 1)
        self.levels = check_int("levels", levels, 1, 1 << 20)

    def dynamic_range_db(self) -> float:
        """20·lg(τ̆/τ̌·N), τ̌ = one tick (seed 000 §4.5)."""
        from viform.measure.dynamic_range import subthreshold_dynamic_range_db

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
        levels = [self._read(state, q, rng)]
        blocks = []
        for _, blk in s.simulate(scene, duration_s, seed=seed, block_ticks=self.sensitivity_ticks, state=state):
            blocks.append(blk)
            levels.append(self._read(state, q, rng))
        spikes = SpikeStream(np.concatenate(blocks), p.clock_hz, p.threshold_electrons, 0.0,
                             s.capture_metadata(scene, seed, 1) | {"subthreshold_levels": self.levels,
                                                                   "sensitivity_ticks": self.sensitivity_ticks})
        return SubthresholdCapture(spikes, np.stack(levels).reshape(-1, h, w), self.sensitivity_ticks, self.levels)

    def _read(self, state, q, rng) -> np.ndarray:
        c = state.charge / FIXED_POINT_SCALE
        t = state.target / FIXED_POINT_SCALE
        if self.sensor.parameters.photon_noise:
            # electrons collected so far: the first Q−1 arrivals are uniform before the Q-th
            frac = np.clip(c / np.maximum(t, 1e-300), 0.0, 1.0)
            n = rng.binomial(np.maximum(q.astype(np.int64) - 1, 0), frac)
        else:
            n = np.floor(np.clip(c, 0, q))
        return np.floor(self.levels * n / q).astype(np.int64)
