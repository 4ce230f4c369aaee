"""Interval imaging: the light at instant t is Q/τ of the interval containing t (seed 000 §3.3.2).

For tick k a pixel's interval runs from its last spike at or before k (tick ``prev``) to its
first spike after k (tick ``next``), τ = (next − prev) ticks — the convention of the common
"TFI" reconstruction, so 8-bit results compare with published numbers. For steady light
Q/τ is unbiased: the interval holding a fixed instant is length-biased, Gamma(Q + 1, λ) in
electrons, and E[Q/X] = λ for that law (tested in ``tests/imaging``). The same length bias
makes 1/τ unbiased after tick rounding too: an interval of n ticks is picked with
probability ∝ n, so E[1/τ] = 1/E[n] exactly.

The search for ``prev`` and ``next`` goes as far as the data need: backward and forward, in
chunks of growing length, until every pixel has its spikes or the stream ends, holding only
one chunk at a time (bounded memory). No interval is cut short anywhere but at the stream's
ends (an earlier version cut every interval longer than ≈ 2,048 ticks at a fixed 1,024-tick
lookahead, which read a flat 0.005 lux scene 77 % too bright).

Rule at the stream's ends (documented, no NaN, no division by zero): an interval cut by an
end is measured up to that end, as if a spike stood just outside the stream (tick −1 before
the start, tick T after the end). That τ is a lower bound of the true interval, so the
light is an upper bound; such pixels are flagged ``censored``. A pixel with no spike at all
gets τ = T + 1 ticks.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from viform._validate import ViformError, check_int
from viform.imaging.units import LightImage, light_from_rate
from viform.stream.container import SpikeSource, spike_bytes

#: Ticks read per search step around an instant (the first step; later ones double, up to
#: :data:`MAX_CHUNK_BYTES`). Only speed and memory depend on it, never the result.
DEFAULT_LOOKAHEAD_TICKS = 1024

#: Largest chunk of unpacked spikes (bytes) held while searching for far spikes.
MAX_CHUNK_BYTES = 32 * 2 ** 20


def _chunk_limit(pixels: int) -> int:
    return max(1, MAX_CHUNK_BYTES // max(1, pixels))


@njit(cache=True, parallel=True)
def _spikes_in_words(words, pixels, start, backward, todo, found, count, wanted):  # pragma: no cover - compiled
    """:func:`_collect_spikes` on rows read as 64-bit words (8 pixels a word, one byte each, little-endian)."""
    n, n_words = words.shape
    slab = 512  # words (4,096 pixels) per work item
    full = np.uint64(0xFF)
    for c in prange((n_words + slab - 1) // slab):
        w0 = c * slab
        w1 = min(w0 + slab, n_words)
        # the slab's words with pixels still short of spikes, and those pixels' bytes (0xFF) in each
        index = np.empty(w1 - w0, dtype=np.int64)
        mask = np.empty(w1 - w0, dtype=np.uint64)
        m = 0
        for w in range(w0, w1):
            mk = np.uint64(0)
            for b in range(8):
                j = w * 8 + b
                if j < pixels and todo[j]:
                    mk |= full << np.uint64(8 * b)
            if mk:
                index[m] = w
                mask[m] = mk
                m += 1
        i = 0
        while m > 0 and i < n:
            r = n - 1 - i if backward else i
            k = 0
            while k < m:
                hit = words[r, index[k]] & mask[k]
                if hit:
                    for b in range(8):
                        byte = full << np.uint64(8 * b)
                        if hit & byte:
                            j = index[k] * 8 + b
                            found[count[j], j] = start + r
                            count[j] += 1
                            if count[j] == wanted:
                                todo[j] = False
                                mask[k] &= ~byte
                    if not mask[k]:  # the word's pixels are all done: off the list (its order does not matter)
                        m -= 1
                        index[k] = index[m]
                        mask[k] = mask[m]
                        continue
                k += 1
            i += 1


def _collect_spikes(bits, start, backward, todo, found, count, wanted):
    """Record the spikes of the pixels still to search, in reading order, up to ``wanted`` each.

    ``bits`` (n, P) uint8, one row per tick from ``start`` (nonzero: a spike), read from the last
    row when ``backward``. For each pixel j with ``todo[j]``, each spike met sets
    ``found[count[j], j]`` to its tick and increments ``count[j]``; ``todo[j]`` is cleared when
    ``count[j]`` reaches ``wanted`` (so a search that continues in the next chunk resumes where it
    stopped). Each row reads only the words (8 pixels) that hold a pixel still to search — a list
    that shrinks as they finish — so the work follows the distance each pixel is searched.
    """
    n, pixels = bits.shape
    if pixels % 8 or not bits.flags.c_contiguous:
        padded = np.zeros((n, -(-pixels // 8) * 8), dtype=np.uint8)
        padded[:, :pixels] = bits
        bits = padded
    _spikes_in_words(bits.view(np.uint64), pixels, start, backward, todo, found, count, wanted)


def _search_spikes(source: SpikeSource, tick: int, forward: bool, todo: np.ndarray, found: np.ndarray,
                   count: np.ndarray, wanted: int, chunk_ticks: int) -> None:
    """:func:`_collect_spikes` from ``tick`` on (``forward``) or backward from just before it, in chunks
    of ``chunk_ticks`` that double (up to :data:`MAX_CHUNK_BYTES` of spikes), until every pixel in
    ``todo`` has ``wanted`` spikes or the stream ends: one chunk of spikes held at a time."""
    n_total = source.n_ticks
    pixels = source.height * source.width
    pos = tick
    chunk = min(chunk_ticks, _chunk_limit(pixels))
    while (pos < n_total if forward else pos > 0) and todo.any():
        a, b = (pos, min(n_total, pos + chunk)) if forward else (max(0, pos - chunk), pos)
        _collect_spikes(spike_bytes(source.read_ticks(a, b).reshape(b - a, pixels)), a, not forward, todo, found,
                        count, wanted)
        pos = b if forward else a
        chunk = min(2 * chunk, _chunk_limit(pixels))


def _nearest_spike(source: SpikeSource, tick: int, forward: bool, pixels_left, chunk_ticks: int) -> np.ndarray:
    """Per pixel, the first spike at or after ``tick`` (``forward``; T if none) or the last before it
    (−1 if none), for the pixels ``pixels_left`` (an index or mask; the others keep those markers)."""
    pixels = source.height * source.width
    nearest = np.full(pixels, source.n_ticks if forward else -1, dtype=np.int64)
    todo = np.zeros(pixels, dtype=np.bool_)
    todo[pixels_left] = True
    _search_spikes(source, tick, forward, todo, nearest[None], np.zeros(pixels, np.int64), 1, chunk_ticks)
    return nearest


def interval_ticks(source: SpikeSource, ticks, lookahead_ticks: int | None = None):
    """τ (ticks) of the interval containing each tick in ``ticks``.

    Returns ``(tau, censored)``: int64 and bool arrays of shape (len(ticks), H, W).
    Each pixel's previous and next spikes are searched as far as needed (to the stream's
    ends at most), reading ``lookahead_ticks`` ticks first (default
    :data:`DEFAULT_LOOKAHEAD_TICKS`) and doubling chunks after that, so long streams and
    long intervals are handled exactly in bounded memory. ``censored`` marks intervals cut
    by an end of the stream.
    """
    ticks = np.atleast_1d(np.asarray(ticks, dtype=np.int64))
    if ticks.size and (ticks.min() < 0 or ticks.max() >= source.n_ticks):
        raise ViformError(f"tick {int(ticks.min() if ticks.min() < 0 else ticks.max())} is outside the stream's "
                          f"[0, {source.n_ticks})")
    look = DEFAULT_LOOKAHEAD_TICKS if lookahead_ticks is None else check_int("lookahead_ticks", lookahead_ticks, 1)
    pixels = source.height * source.width
    look = min(look, _chunk_limit(pixels))
    n_total = source.n_ticks
    tau = np.empty((ticks.size, pixels), dtype=np.int64)
    censored = np.empty((ticks.size, pixels), dtype=bool)
    for m, k in enumerate(ticks):
        prev = _nearest_spike(source, int(k) + 1, False, slice(None), look)  # last spike at or before k
        nxt = _nearest_spike(source, int(k) + 1, True, slice(None), look)  # first spike after k
        tau[m] = nxt - prev
        censored[m] = (prev < 0) | (nxt >= n_total)
    shape = (ticks.size, source.height, source.width)
    return tau.reshape(shape), censored.reshape(shape)


def interval_image(source: SpikeSource, t_s: float, sensor_parameters=None,
                   lookahead_ticks: int | None = None) -> LightImage:
    """Light at instant ``t_s`` as Q/τ of the interval containing it (seed 000 §3.3.2).

    Returns a :class:`~viform.imaging.units.LightImage` with the firing rate 1/τ
    (spikes/s), e⁻/s (Q/τ far below saturation; the inverse of the readout's rate law near
    it, τ = 1 tick flagged ``saturated``) and lux when the sensor is known, and the ``censored`` mask
    (intervals cut by an end of the stream — never by the search, which goes as far as the
    data need; ``lookahead_ticks`` only sets the first read).
    """
    k = source.tick_of(t_s)
    tau, censored = interval_ticks(source, [k], lookahead_ticks)
    tau_s = tau[0] / source.clock_hz
    image = light_from_rate(1.0 / tau_s, source, sensor_parameters, censored=censored[0], method="interval",
                            spikes_per_side=1)
    image.info["tau_ticks"] = tau[0]
    return image


# ------------------------------------------------------------------ every tick, streaming

@njit(cache=True, parallel=True)
def _next_after_block(bits, n_block, ahead, buffer_end, out_next):
    """First spike at or after the block's end, where the buffer ``bits`` holds it.

    ``bits`` holds ticks [first, buffer_end); rows ≥ ``n_block`` lie after the block. A pixel
    with no spike there keeps ``ahead`` (the first spike at or after an earlier buffer end)
    when that lies at or beyond ``buffer_end``; otherwise −1 (to be searched further).
    """
    n_avail, p = bits.shape
    for j in prange(p):
        found = -1
        for i in range(n_block, n_avail):
            if bits[i, j]:
                found = i
                break
        if found >= 0:
            out_next[j] = buffer_end - n_avail + found
        elif ahead[j] >= buffer_end:
            out_next[j] = ahead[j]
        else:
            out_next[j] = -1


@njit(cache=True, parallel=True)
def _interval_block(bits, first, n_block, next_after, prev, out, censored, n_total):
    """τ for ticks [first, first + n_block); ``bits`` holds (at least) those ticks.

    ``next_after`` is each pixel's first spike at or after the block's end (T if none);
    ``prev`` (per pixel, carried between blocks) is the last spike before ``first`` (or −1).
    A backward pass finds each tick's next spike, a forward pass its previous one; both
    run ticks outer and pixels inner so the inner loops are contiguous.
    """
    p = bits.shape[1]
    chunk = 4096
    for c in prange((p + chunk - 1) // chunk):
        j0 = c * chunk
        j1 = min(j0 + chunk, p)
        nxt = np.empty(j1 - j0, dtype=np.int64)
        for j in range(j0, j1):
            nxt[j - j0] = next_after[j]
        for i in range(n_block - 1, -1, -1):
            for j in range(j0, j1):
                out[i, j] = nxt[j - j0]  # spike strictly after tick first + i
                if bits[i, j]:
                    nxt[j - j0] = first + i
        for i in range(n_block):
            k = first + i
            for j in range(j0, j1):
                if bits[i, j]:
                    prev[j] = k
                censored[i, j] = prev[j] < 0 or out[i, j] >= n_total
                out[i, j] = out[i, j] - prev[j]


def interval_frames(source: SpikeSource, block_ticks: int = 1024,
                    lookahead_ticks: int = DEFAULT_LOOKAHEAD_TICKS, with_censored: bool = False,
                    dtype=np.int32):
    """τ (ticks) at every tick, streamed: yields ``(first_tick, tau)`` with tau (T, H, W) int32.

    ``dtype=np.int64`` yields the kernel's own array (no conversion copy).

    With ``with_censored`` yields ``(first_tick, tau, censored)``: censored (T, H, W) bool
    marks intervals cut by an end of the stream.

    Exact at any interval length: the last spike before each block is carried, the ticks
    up to ``lookahead_ticks`` after it are read with it (and kept for the next block), and a
    pixel whose next spike lies beyond that is searched further, in chunks, once — the spike
    found is remembered until the stream reaches it. Memory is bounded by (block +
    lookahead) ticks plus one search chunk; the result does not depend on ``block_ticks``
    or ``lookahead_ticks``. Intervals cut by the stream's ends follow the end rule above.
    """
    block_ticks = check_int("block_ticks", block_ticks, 1)
    pixels = source.height * source.width
    # the result does not depend on the lookahead: cap it so the buffer stays ≈ 32 MiB
    look = min(check_int("lookahead_ticks", lookahead_ticks, 1), _chunk_limit(pixels))
    n_total = source.n_ticks
    prev = np.full(pixels, -1, dtype=np.int64)
    ahead = np.full(pixels, -1, dtype=np.int64)  # a known first spike at/after an earlier buffer end
    buffer = np.zeros((0, pixels), dtype=np.uint8)
    buffer_end = 0
    next_after = np.empty(pixels, dtype=np.int64)
    for first in range(0, n_total, block_ticks):
        last = min(first + block_ticks, n_total)
        need = min(n_total, last + look)
        if need > buffer_end:
            fresh = spike_bytes(source.read_ticks(buffer_end, need).reshape(need - buffer_end, pixels))
            buffer = np.concatenate([buffer, fresh]) if buffer.size else np.ascontiguousarray(fresh)
            buffer_end = need
        _next_after_block(buffer, last - first, ahead, buffer_end, next_after)
        far = np.flatnonzero(next_after < 0)
        if far.size:  # next spike beyond the buffer: search on (or the stream ends)
            found = _nearest_spike(source, buffer_end, True, far, max(look, block_ticks))
            next_after[far] = found[far]
            ahead[far] = found[far]
        out = np.empty((last - first, pixels), dtype=np.int64)
        censored = np.empty((last - first, pixels), dtype=np.bool_)
        _interval_block(buffer, first, last - first, next_after, prev, out, censored, n_total)
        buffer = buffer[last - first:]
        shape = (last - first, source.height, source.width)
        tau = out.reshape(shape) if np.dtype(dtype) == np.int64 else out.astype(dtype).reshape(shape)
        if with_censored:
            yield first, tau, censored.reshape(shape)
        else:
            yield first, tau


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
