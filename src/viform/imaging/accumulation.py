"""Accumulation imaging: a virtual exposure over any window of the spike stream (seed 000 §3.3.1).

The image counts the spikes in a window [T1, T2); more spikes mean more light. Each spike
stands for Q electrons, so the mean photo-current over the window is count·Q / (T2 − T1)
electrons per second — far below saturation; near one spike per tick the light is the
inverse of the readout's exact rate law (:mod:`viform.imaging.rate_law`), and pixels that
fired every tick are flagged ``saturated``. T1 and T2 are free: sliding the window gives continuous imaging,
widening it trades motion blur for noise.

Window alignment: the seed's eq. has the window end at the instant (``align="end"``); the
spike-camera literature's "TFP" image (texture from playback, e.g. Spike-Zoo, SpikeCV and
the published REDS figures) centres it on the instant, which is what sharpens the image of
a moving scene at that instant. viform's default is ``"centre"``, the published
convention; ``"end"`` (causal, for live use) and ``"start"`` are available.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from viform._validate import ViformError, check_choice, check_int, check_positive
from viform.imaging.units import LightImage, light_from_rate
from viform.stream.container import SpikeSource, spike_bytes

#: Window alignments: the window is centred on the instant's tick, ends with it, or starts with it.
ALIGNMENTS = ("centre", "end", "start")
DEFAULT_ALIGN = "centre"


def check_align(align: str, name: str = "align") -> str:
    """``align`` validated (``"center"`` accepted as a spelling of ``"centre"``)."""
    if align == "center":
        return "centre"
    return check_choice(name, align, ALIGNMENTS)


def window_bounds(tick: int, n: int, n_ticks: int, align: str = DEFAULT_ALIGN) -> tuple[int, int]:
    """Ticks [k0, k1) of an ``n``-tick window aligned on ``tick``, clipped to [0, ``n_ticks``).

    ``centre``: ticks tick − ⌊n/2⌋ … (odd n is symmetric: 41 ticks = the instant ± 20);
    ``end``: the n ticks up to and including ``tick``; ``start``: the n ticks from ``tick`` on.
    """
    align = check_align(align)
    k0 = {"centre": tick - n // 2, "end": tick - n + 1, "start": tick}[align]
    return max(0, k0), min(n_ticks, k0 + n)


def window_ticks(source: SpikeSource, t_s: float, window_s: float, align: str = DEFAULT_ALIGN) -> tuple[int, int]:
    """Ticks [k0, k1) of the window of length ``window_s`` aligned on the tick of instant ``t_s``."""
    check_positive("window_s", window_s)
    n = max(1, int(round(window_s * source.clock_hz)))
    return window_bounds(source.tick_of(t_s), n, source.n_ticks, align)


def spike_counts(source: SpikeSource, start_tick: int, stop_tick: int, block_ticks: int = 4096) -> np.ndarray:
    """Spikes per pixel in ticks [start_tick, stop_tick), read block by block (bounded memory)."""
    if not 0 <= start_tick < stop_tick <= source.n_ticks:
        raise ViformError(f"tick window [{start_tick}, {stop_tick}) is outside the stream's [0, {source.n_ticks})")
    counts = np.zeros((source.height, source.width), dtype=np.int64)
    for _, block in source.iter_blocks(block_ticks, start_tick, stop_tick):
        counts += block.sum(axis=0, dtype=np.int64)
    return counts


def accumulation_image(source: SpikeSource, t_s: float, window_s: float,
                       sensor_parameters=None, align: str = DEFAULT_ALIGN) -> LightImage:
    """Light at instant ``t_s`` from the spikes of a ``window_s`` window (seed 000 §3.3.1).

    ``align``: ``"centre"`` (default; the window is centred on the instant, the convention
    of published TFP figures), ``"end"`` (the window ends at the instant, as in the seed:
    causal) or ``"start"``. The window is clipped at the stream's ends; the rate uses the
    window's actual length.
    Returns a :class:`~viform.imaging.units.LightImage` (spikes/s, e⁻/s and lux when Q and
    the sensor are known).
    """
    k0, k1 = window_ticks(source, t_s, window_s, align)
    counts = spike_counts(source, k0, k1)
    duration = (k1 - k0) / source.clock_hz
    return light_from_rate(counts / duration, source, sensor_parameters, method="accumulation",
                           window_ticks=k1 - k0, first_tick=k0, align=check_align(align))


def accumulation_8bit(source: SpikeSource, tick: int, half_window_ticks: int = 20, scale: float = 1.0) -> np.ndarray:
    """The common 8-bit "TFP" (texture from playback) image used in spike-camera papers.

    Mean firing over the 2·h + 1 ticks centred on ``tick`` (clipped at the ends), times
    255 / ``scale``, clipped to [0, 255] (``scale`` is the clip's full-scale firing rate,
    e.g. 0.6 for the REDS simulations).
    """
    h = check_int("half_window_ticks", half_window_ticks, 0)
    check_positive("scale", scale)
    k0, k1 = max(0, tick - h), min(source.n_ticks, tick + h + 1)
    mean = spike_counts(source, k0, k1) / (k1 - k0)
    return np.clip(np.rint(mean * 255.0 / scale), 0, 255).astype(np.uint8)


@njit(cache=True, parallel=True)
def _sliding_counts(block, carry, window, out):
    # carry: the `window` ticks before the block (zeros before the stream starts).
    # Ticks outer, pixels inner (contiguous, vectorizable); pixel chunks in parallel.
    n, p = block.shape
    chunk = 4096
    for c in prange((p + chunk - 1) // chunk):
        j0 = c * chunk
        j1 = min(j0 + chunk, p)
        running = np.zeros(j1 - j0, dtype=np.int32)
        for i in range(window):
            for j in range(j0, j1):
                running[j - j0] += carry[i, j]
        for k in range(n):
            for j in range(j0, j1):
                old = carry[k, j] if k < window else block[k - window, j]
                running[j - j0] += block[k, j] - old
                out[k, j] = running[j - j0]


def sliding_accumulation(source: SpikeSource, window_ticks: int, block_ticks: int = 1024):
    """Counts over a sliding window of ``window_ticks`` ending at every tick, in blocks.

    Yields ``(first_tick, counts)`` with counts (T, H, W) int32; the window of tick k is
    ticks (k − window, k]. Near the start the window is clipped (fewer ticks counted).
    The previous ``window_ticks`` ticks are carried between blocks, so the result does not
    depend on ``block_ticks``.
    """
    window = check_int("window_ticks", window_ticks, 1)
    pixels = source.height * source.width
    carry = np.zeros((window, pixels), dtype=np.uint8)
    for first, block in source.iter_blocks(block_ticks):
        flat = spike_bytes(block.reshape(block.shape[0], pixels))
        out = np.empty(flat.shape, dtype=np.int32)
        _sliding_counts(flat, carry, window, out)
        if flat.shape[0] >= window:
            carry = np.ascontiguousarray(flat[-window:])
        else:
            carry = np.concatenate([carry[flat.shape[0]:], flat])
        yield first, out.reshape(block.shape)
