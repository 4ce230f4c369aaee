"""Sampled light (:mod:`viform.light.sampled`) through the runs-of-constant-light kernel.

A block is cut into stretches of about :data:`STRETCH_TICKS` ticks (whole light samples). In each
stretch, the words (64 pixels) that no dirty rectangle of the stretch's samples touches keep the
static light: they run as one run of constant light (the constant-light kernel's speed). The other
words run one run per light sample, their charge rendered by the sampler. Each group runs through
:func:`~viform.sensors._spike_kernels._run_block` on its pixels' state gathered into compact arrays
and scattered back: every pixel's integrate-and-fire depends only on its own state, light and draw
stream, so the bits are those of one call over the whole field with every run's full light.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from viform.light.sampled import lux_to_rates, rects_to_words, word_ranges
from viform.sensors import _spike_kernels
from viform.sensors._spike_kernels import _LANES, SPARSE_FIRING, _run_block

#: Ticks per stretch whose dirty words are found together (rounded to whole light samples).
STRETCH_TICKS = 256
#: Bytes of rendered charge a call may hold (the stretch is split into chunks of samples below it).
RATES_BYTES = 24 << 20
#: Above this fraction of dirty words the whole field runs per sample (gathering would cost more).
WHOLE_FIELD_FRACTION = 0.7


_NEVER_LAZY = np.iinfo(np.int64).max  # a saturation bound no charge per tick reaches


@njit(cache=True)
def _varying_pixels(rates, varying):
    """``varying[p]`` = True where pixel p's charge per tick differs between the rows (samples) of ``rates``."""
    for i in range(1, rates.shape[0]):
        for p in range(rates.shape[1]):
            if rates[i, p] != rates[0, p]:
                varying[p] = True


class SampledRuns:
    """Runs a block of ticks with sampled light (see the module notes)."""

    def __init__(self, sensor, light, sample: int, height: int, width: int, plan, bounds):
        self.sampler = light.sampler
        self.sample = int(sample)
        self.clock_hz = sensor.parameters.clock_hz
        self.height, self.width = height, width
        self.pixels = height * width
        self.plan, self.bounds = plan, bounds
        self.fixed_tables = sensor._fixed_point_tables(height, width)  # the kernels' common-case tables
        self.a, self.b = plan.a, plan.b
        static = np.ascontiguousarray(self.sampler.static_lux(), dtype=np.float64).reshape(1, -1)
        self.static_rates = np.empty(static.shape, np.int64)
        lux_to_rates(static, self.a, self.b, self.static_rates)
        self.static_rates = self.static_rates[0]
        self.n_words = (self.pixels + _LANES - 1) // _LANES
        self.stretch = self.sample * max(1, round(STRETCH_TICKS / self.sample))
        self._groups = {}

    # ------------------------------------------------------------------ pixel groups
    def _group(self, words: np.ndarray) -> dict:
        """Pixel indices, per-pixel tables and flat ranges of a set of words (cached for the last sets)."""
        key = words.tobytes()
        group = self._groups.get(key)
        if group is None:
            pix = (words[:, None] * _LANES + np.arange(_LANES)).ravel()
            pix = pix[pix < self.pixels]
            starts, stops = word_ranges(words, self.pixels, _LANES)
            plan = self.plan
            group = {"words": words, "pix": pix, "starts": starts, "stops": stops, "q": plan.q[pix],
                     "index": plan.index[pix], "bounds": self.bounds[pix], "a": self.a[pix], "b": self.b[pix],
                     "static": self.static_rates[pix]}
            if len(self._groups) > 8:
                self._groups.clear()
            self._groups[key] = group
        return group

    # ------------------------------------------------------------------ running
    def run(self, out: np.ndarray, first: int, last: int, state) -> None:
        """Fill ``out`` (ticks first … last − 1, packed rows) and advance ``state``."""
        words = out.view(np.uint64)
        k = first
        while k < last:
            end = min(last, ((k // self.stretch) + 1) * self.stretch)
            self._stretch(words[k - first:end - first], k, end, state)
            k = end

    def _stretch(self, words, first, last, state):
        s = self.sample
        j0, j1 = first // s, -(-last // s)
        times = (np.arange(j0, j1) + 0.5) * (s / self.clock_hz)
        seg_end = (np.arange(j0, j1, dtype=np.int64) + 1) * s
        dirty = rects_to_words(self.sampler.dirty_rects(times), self.height, self.width, _LANES)
        if dirty.size == 0:
            self._call(words, self.static_rates[None], np.array([last], np.int64), first, state, None)
            return
        if dirty.size >= WHOLE_FIELD_FRACTION * self.n_words:
            everything = np.arange(self.n_words, dtype=np.int64)
            self._dynamic(words, times, seg_end, first, last, state, self._group(everything), whole=True)
            return
        still = np.setdiff1d(np.arange(self.n_words, dtype=np.int64), dirty, assume_unique=True)
        static_group = self._group(still)
        sub = np.empty((words.shape[0], still.size), np.uint64)
        self._call(sub, static_group["static"][None], np.array([last], np.int64), first, state, static_group)
        words[:, still] = sub
        self._dynamic(words, times, seg_end, first, last, state, self._group(dirty), whole=False)

    def _dynamic(self, words, times, seg_end, first, last, state, group, whole):
        n_pixels = group["pix"].size
        chunk = max(1, RATES_BYTES // (8 * max(1, n_pixels)))
        sub = words if whole else np.empty((words.shape[0], group["words"].size), np.uint64)
        for c0 in range(0, times.size, chunk):
            c1 = min(times.size, c0 + chunk)
            k0 = max(first, int(seg_end[c0]) - self.sample)
            k1 = min(last, int(seg_end[c1 - 1]))
            rates = np.empty((c1 - c0, n_pixels), np.int64)
            self.sampler.render(times[c0:c1], group["starts"], group["stops"], group["a"], group["b"], rates)
            # the saturation shortcut of _run_block defers a saturated pixel's draws until its light changes,
            # then replays them one pixel at a time (_settle): for pixels whose light changes within the chunk
            # it saves nothing, so they run tick by tick — the same draws in the same order, the same bits
            bounds = self.bounds if whole else group["bounds"]
            varying = np.zeros(n_pixels, np.bool_)
            _varying_pixels(rates, varying)
            bounds = np.where(varying, _NEVER_LAZY, bounds)
            self._call(sub[k0 - first:k1 - first], rates, seg_end[c0:c1], k0, state, None if whole else group,
                       bounds)
        if not whole:
            words[:, group["words"]] = sub

    def _call(self, words, rates, seg_end, first, state, group, bounds=None):
        """One kernel call over the whole field (``group`` None) or over a group's gathered state; ``bounds``:
        the saturation bounds of the call's pixels (default: the sensor's)."""
        p = self.plan.p
        plan = self.plan
        if bounds is None:
            bounds = self.bounds if group is None else group["bounds"]
        if group is None:
            _run_block(words.view(np.uint8), rates, seg_end, first, state.charge, state.target, state.counter,
                       plan.q, plan.index, *plan.tables, *self.fixed_tables, state.keys, p.photon_noise,
                       plan.reset_readout, plan.dead_ticks, plan.mode, bounds, state.pending_ticks,
                       state.pending_rate, SPARSE_FIRING, _spike_kernels.VECTOR_MIN_SPIKES)
            return
        pix = group["pix"]
        charge, target, counter = state.charge[pix], state.target[pix], state.counter[pix]
        keys, pending_ticks, pending_rate = state.keys[pix], state.pending_ticks[pix], state.pending_rate[pix]
        _run_block(words.view(np.uint8), rates, seg_end, first, charge, target, counter, group["q"],
                   group["index"], *plan.tables, *self.fixed_tables, keys, p.photon_noise, plan.reset_readout,
                   plan.dead_ticks, plan.mode, bounds, pending_ticks, pending_rate, SPARSE_FIRING,
                   _spike_kernels.VECTOR_MIN_SPIKES)
        state.charge[pix], state.target[pix], state.counter[pix] = charge, target, counter
        state.pending_ticks[pix], state.pending_rate[pix] = pending_ticks, pending_rate
