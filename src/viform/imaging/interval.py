"""Interval imaging: the light at instant t is Q/τ of the interval containing t (seed 000 §3.3.2).

For tick k a pixel's interval runs from its last spike at or before k (tick ``prev``) to its
first spike after k (tick ``next``), τ = (next − prev) ticks — the convention of the common
"TFI" reconstruction, so 8-bit results compare with published numbers. For steady light
Q/τ is unbiased: the interval holding a fixed instant is length-biased, Gamma(Q + 1, λ) in
electrons, and E[Q/X] = λ for that law (tested in ``tests/imaging``).

Rule at the stream's ends (documented, no NaN, no division by zero): an interval cut by an
end is measured up to that end, as if a spike stood just outside the stream (tick −1 before
the start, tick T after the end). That τ is a lower bound of the true interval, so the
light is an upper bound; such pixels are flagged ``censored``. A pixel with no spike at all
gets τ = T + 1 ticks. With a ``lookahead_ticks`` limit (streaming over long files) an
interval longer than the limit is cut the same way at the limit.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from viform._validate import ViformError, check_int
from viform.imaging.units import LightImage, light_from_rate
from viform.stream.container import SpikeSource

#: How far interval imaging looks back and ahead of an instant by default, ticks (memory:
#: (block + lookahead) ticks of bits are held when streaming every tick).
DEFAULT_LOOKAHEAD_TICKS = 1024


@njit(cache=True, parallel=True)
def _intervals_at(block, offset, ticks, lo, hi, prev_out, next_out):
    # block holds ticks [offset, offset + n); for each requested tick find prev ≤ tick < next
    n, p = block.shape
    for j in prange(p):
        for m in range(ticks.size):
            k = ticks[m] - offset
            prev = lo[m] - 1
            i = k
            while i >= lo[m] - offset and i >= 0:
                if block[i, j]:
                    prev = i + offset
                    break
                i -= 1
            nxt = hi[m]
            i = k + 1
            while i < hi[m] - offset and i < n:
                if block[i, j]:
                    nxt = i + offset
                    break
                i += 1
            prev_out[m, j] = prev
            next_out[m, j] = nxt


def interval_ticks(source: SpikeSource, ticks, lookahead_ticks: int | None = None):
    """τ (ticks) of the interval containing each tick in ``ticks``.

    Returns ``(tau, censored)``: int64 and bool arrays of shape (len(ticks), H, W).
    Reads only ticks within ``lookahead_ticks`` of the requested ones (all of the stream
    when None), so long streams are handled in bounded memory.
    """
    ticks = np.atleast_1d(np.asarray(ticks, dtype=np.int64))
    if ticks.size and (ticks.min() < 0 or ticks.max() >= source.n_ticks):
        raise ViformError(f"tick {int(ticks.min() if ticks.min() < 0 else ticks.max())} is outside the stream's "
                          f"[0, {source.n_ticks})")
    look = source.n_ticks if lookahead_ticks is None else check_int("lookahead_ticks", lookahead_ticks, 1)
    pixels = source.height * source.width
    tau = np.empty((ticks.size, pixels), dtype=np.int64)
    censored = np.empty((ticks.size, pixels), dtype=bool)
    for m, k in enumerate(ticks):
        lo = max(0, int(k) - look + 1)  # earliest tick searched for the previous spike
        hi = min(source.n_ticks, int(k) + look + 1)  # first tick not searched for the next spike
        block = source.read_ticks(lo, hi).reshape(hi - lo, pixels).view(np.uint8)
        prev = np.empty((1, pixels), np.int64)
        nxt = np.empty((1, pixels), np.int64)
        _intervals_at(block, lo, np.array([k]), np.array([lo]), np.array([hi]), prev, nxt)
        tau[m] = nxt[0] - prev[0]
        censored[m] = (prev[0] < lo) | (nxt[0] >= hi)
    shape = (ticks.size, source.height, source.width)
    return tau.reshape(shape), censored.reshape(shape)


def interval_image(source: SpikeSource, t_s: float, sensor_parameters=None,
                   lookahead_ticks: int | None = DEFAULT_LOOKAHEAD_TICKS) -> LightImage:
    """Light at instant ``t_s`` as Q/τ of the interval containing it (seed 000 §3.3.2).

    Returns a :class:`~viform.imaging.units.LightImage` with the firing rate 1/τ
    (spikes/s), e⁻/s (Q/τ) and lux when the sensor is known, and the ``censored`` mask.
    """
    k = source.tick_of(t_s)
    tau, censored = interval_ticks(source, [k], lookahead_ticks)
    tau_s = tau[0] / source.clock_hz
    image = light_from_rate(1.0 / tau_s, source, sensor_parameters, censored=censored[0], method="interval")
    image.info["tau_ticks"] = tau[0]
    return image


# ------------------------------------------------------------------ every tick, streaming

@njit(cache=True, parallel=True)
def _interval_block(bits, first, n_block, lookahead, n_total, prev, out):
    """τ for ticks [first, first + n_block); ``bits`` holds ticks [first, first + len(bits)).

    ``prev`` (per pixel, carried between blocks) is the last spike before ``first`` (or −1).
    A backward pass finds each tick's next spike, a forward pass its previous one; both
    run ticks outer and pixels inner so the inner loops are contiguous.
    """
    n_avail, p = bits.shape
    chunk = 4096
    for c in prange((p + chunk - 1) // chunk):
        j0 = c * chunk
        j1 = min(j0 + chunk, p)
        nxt = np.empty(j1 - j0, dtype=np.int64)
        # first spike at or after the block's end, within the lookahead read
        for j in range(j0, j1):
            nxt[j - j0] = first + n_avail
            for i in range(n_block, n_avail):
                if bits[i, j]:
                    nxt[j - j0] = first + i
                    break
        for i in range(n_block - 1, -1, -1):
            for j in range(j0, j1):
                out[i, j] = nxt[j - j0]  # spike strictly after tick first + i
                if bits[i, j]:
                    nxt[j - j0] = first + i
        for i in range(n_block):
            k = first + i
            lo = max(0, k - lookahead + 1)
            hi = min(n_total, k + lookahead + 1)
            for j in range(j0, j1):
                if bits[i, j]:
                    prev[j] = k
                a = prev[j] if prev[j] >= lo else lo - 1
                b = out[i, j] if out[i, j] < hi else hi
                out[i, j] = b - a


def interval_frames(source: SpikeSource, block_ticks: int = 1024,
                    lookahead_ticks: int = DEFAULT_LOOKAHEAD_TICKS):
    """τ (ticks) at every tick, streamed: yields ``(first_tick, tau)`` with tau (T, H, W) int32.

    Intervals are searched up to ``lookahead_ticks`` before and after each tick (longer ones
    are cut there, the end rule above). Each tick is read once: the lookahead read for one
    block is kept for the next, and the last spike before a block is carried, so memory is
    bounded by (block + lookahead) ticks and the result does not depend on ``block_ticks``.
    """
    block_ticks = check_int("block_ticks", block_ticks, 1)
    look = check_int("lookahead_ticks", lookahead_ticks, 1)
    pixels = source.height * source.width
    n_total = source.n_ticks
    prev = np.full(pixels, -1, dtype=np.int64)
    buffer = np.zeros((0, pixels), dtype=np.uint8)
    buffer_end = 0
    for first in range(0, n_total, block_ticks):
        last = min(first + block_ticks, n_total)
        need = min(n_total, last + look)
        if need > buffer_end:
            fresh = source.read_ticks(buffer_end, need).reshape(need - buffer_end, pixels).view(np.uint8)
            buffer = np.concatenate([buffer, fresh]) if buffer.size else np.ascontiguousarray(fresh)
            buffer_end = need
        out = np.empty((last - first, pixels), dtype=np.int64)
        _interval_block(buffer, first, last - first, look, n_total, prev, out)
        buffer = buffer[last - first:]
        yield first, out.astype(np.int32).reshape(last - first, source.height, source.width)


# ------------------------------------------------------------------ display mappings

def tau_display_8bit(tau_ticks, percentiles=(1.0, 99.0)) -> np.ndarray:
    """The seed's display mapping: τ normalised to [0, 255], shown as 255 − τ (seed 000 §6, Fig. 4(b)).

    τ is normalised linearly between two percentiles of the image (1 % and 99 % by default;
    ``(0, 100)`` is plain min–max) and clipped, so a few very long (dark or censored)
    intervals do not wash the picture out. The inversion acts like a gamma curve that
    "simulates the eye's nonlinear perception" (seed 000 §6).
    """
    tau = np.asarray(tau_ticks, dtype=np.float64)
    lo, hi = (float(v) for v in np.percentile(tau, percentiles))
    norm = np.zeros_like(tau) if hi == lo else np.clip((tau - lo) / (hi - lo), 0.0, 1.0) * 255.0
    return np.rint(255.0 - norm).astype(np.uint8)


def inverse_tau_display_8bit(tau_ticks) -> np.ndarray:
    """Linear-light display: 1/τ scaled so the brightest pixel is 255."""
    inv = 1.0 / np.asarray(tau_ticks, dtype=np.float64)
    return np.rint(inv / inv.max() * 255.0).astype(np.uint8)


def interval_8bit(tau_ticks, scale: float = 1.0) -> np.ndarray:
    """The common 8-bit "TFI" image: 255 / (τ·scale) clipped to [0, 255] (τ in ticks).

    ``scale`` is the full-scale firing rate per tick (e.g. 0.6 for REDS simulations).
    """
    if not scale > 0:
        raise ViformError(f"scale = {scale!r} is not allowed: it must be > 0")
    tau = np.asarray(tau_ticks, dtype=np.float64)
    return np.clip(np.rint(255.0 / (tau * scale)), 0, 255).astype(np.uint8)
