"""Light evaluated per light sample in compiled code, with its static part computed once.

Most of a scene's light does not change from one tick to the next: a background, the parts no
object crosses. A :class:`LightSampler` says which pixels can change within a span of time (its
*dirty rectangles*) and renders only those, at the instants asked, as the spike kernels' charge
per tick; every other pixel keeps the light of :meth:`LightSampler.static_lux`. The spike
simulator (kind ``"sampled"`` of :class:`~viform.light.compiled.CompiledLight`) runs the pixels
no dirty rectangle touches in one run of constant light per block — at the constant-light
kernel's speed — and the others in runs of one light sample each.

Time. The light of sample j (ticks j·S … j·S + S − 1, S = ``light_sample_ticks``) is the light at
the middle of the sample, (j + ½)·S / clock, held over its S ticks. Light moving at v px per tick
is then misplaced by at most v·S/2 px at any tick (v/2 at S = 1): :func:`auto_light_sample_ticks`
chooses S from the scene's fastest image speed so that this stays within a stated bound.

Charge. A pixel's charge per tick is rint(a·lux + b) in the kernels' fixed point (per-pixel gain
a and dark charge b, :meth:`~viform.sensors.spike.SpikeSensor._fixed_point_rates`), computed
with the same arithmetic in compiled code, so a sampler whose light equals the scene's NumPy
light gives the same bits.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
from numba import njit, prange

#: The default bound on how far held light may misplace a moving edge, px (see the module notes).
LIGHT_ERROR_PX = 0.25
#: The most ticks a light sample may hold (bounds the time step of slow or still scenes' flicker).
MAX_AUTO_SAMPLE_TICKS = 64


def auto_light_sample_ticks(speed_px_per_s: float, clock_hz: float, error_px: float = LIGHT_ERROR_PX,
                            largest: int = MAX_AUTO_SAMPLE_TICKS) -> int:
    """Ticks per light sample so that light moving at ``speed_px_per_s`` is misplaced by at most
    ``error_px`` at any tick when held over the sample: S = ⌊2·error / v⌋ with v in px per tick,
    between 1 and ``largest``."""
    v = float(speed_px_per_s) / float(clock_hz)
    if not math.isfinite(v) or v <= 0:
        return int(largest)
    return int(max(1, min(largest, math.floor(2.0 * error_px / v))))


class LightSampler(ABC):
    """Light that renders only where it can change (see the module notes). Subclasses implement
    :meth:`static_lux`, :meth:`dirty_rects` and :meth:`render`."""

    height: int
    width: int
    #: An upper bound of the light, lux (for the fixed-point range check).
    lux_max: float

    @abstractmethod
    def static_lux(self) -> np.ndarray:
        """The light (lux, (H, W) float64) of every pixel outside the dirty rectangles, at every instant."""

    @abstractmethod
    def dirty_rects(self, times_s: np.ndarray) -> np.ndarray:
        """Rectangles (k, 4) int64 of (row0, row1, col0, col1), ends exclusive, whose union holds every pixel
        whose light at one of ``times_s`` may differ from :meth:`static_lux`."""

    @abstractmethod
    def render(self, times_s: np.ndarray, starts: np.ndarray, stops: np.ndarray, a: np.ndarray, b: np.ndarray,
               out: np.ndarray) -> None:
        """Fill ``out`` (N, P) with the light at ``times_s`` (N,) of the pixels of the flat ranges
        [starts[k], stops[k]) (row-major pixel indices) laid end to end (P pixels in all): as charge per
        tick rint(a·lux + b) when ``out`` is int64 (``a``, ``b``: the P pixels' factors), as lux when
        ``out`` is float64."""

    def frames(self, times_s) -> np.ndarray:
        """The light at ``times_s`` (N, H, W), lux: the whole field rendered as the simulator sees it."""
        times = np.ascontiguousarray(times_s, dtype=np.float64).ravel()
        pixels = self.height * self.width
        out = np.empty((times.size, pixels))
        one = np.ones(pixels)
        self.render(times, np.array([0], np.int64), np.array([pixels], np.int64), one, one, out)
        return out.reshape(times.size, self.height, self.width)

    def dynamic_fraction(self, times_s) -> float:
        """The fraction of the field the dirty rectangles of ``times_s`` cover (for memory estimates)."""
        rects = self.dirty_rects(np.asarray(times_s, dtype=np.float64))
        mask = np.zeros((self.height, self.width), bool)
        for r0, r1, c0, c1 in rects:
            mask[r0:r1, c0:c1] = True
        return float(mask.mean())


def rects_to_words(rects: np.ndarray, height: int, width: int, lanes: int = 64) -> np.ndarray:
    """Sorted indices of the ``lanes``-pixel words (pixels lanes·w … lanes·w + lanes − 1, row-major)
    that hold a pixel of a rectangle."""
    pixels = height * width
    n_words = (pixels + lanes - 1) // lanes
    if len(rects) == 0:
        return np.zeros(0, np.int64)
    marks = np.zeros(n_words + 1, np.int64)
    _mark_words(np.ascontiguousarray(rects, dtype=np.int64), width, lanes, marks)
    return np.flatnonzero(np.cumsum(marks[:-1]) > 0).astype(np.int64)


@njit(cache=True)
def _mark_words(rects, width, lanes, marks):
    for k in range(rects.shape[0]):
        r0, r1, c0, c1 = rects[k, 0], rects[k, 1], rects[k, 2], rects[k, 3]
        if r1 <= r0 or c1 <= c0:
            continue
        for r in range(r0, r1):
            w0 = (r * width + c0) // lanes
            w1 = (r * width + c1 - 1) // lanes
            marks[w0] += 1
            marks[w1 + 1] -= 1


def word_ranges(words: np.ndarray, pixels: int, lanes: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Flat pixel ranges [starts, stops) of runs of consecutive words."""
    if words.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    breaks = np.flatnonzero(np.diff(words) != 1) + 1
    first = words[np.concatenate(([0], breaks))]
    last = words[np.concatenate((breaks - 1, [words.size - 1]))]
    return first * lanes, np.minimum((last + 1) * lanes, pixels)


def ranges_to_spans(starts: np.ndarray, stops: np.ndarray, width: int):
    """Row spans (row, col0, col1, offset in the laid-out pixels) of flat pixel ranges."""
    rows, c0s, c1s, offs = [], [], [], []
    off = 0
    for s, e in zip(starts.tolist(), stops.tolist(), strict=True):
        p = s
        while p < e:
            r = p // width
            c0 = p - r * width
            c1 = min(width, c0 + (e - p))
            rows.append(r)
            c0s.append(c0)
            c1s.append(c1)
            offs.append(off)
            off += c1 - c0
            p += c1 - c0
    return (np.array(rows, np.int64), np.array(c0s, np.int64), np.array(c1s, np.int64), np.array(offs, np.int64))


@njit(cache=True, parallel=True)
def lux_to_rates(lux, a, b, out):
    """``out[i, p]`` = rint(a[p]·lux[i, p] + b[p]) (the kernels' fixed-point charge per tick)."""
    n, m = lux.shape
    for i in prange(n):
        for p in range(m):
            out[i, p] = np.int64(np.rint(lux[i, p] * a[p] + b[p]))


@njit(cache=True, parallel=True)
def spans_from_static(static, rows, c0s, c1s, offs, width, out):
    """``out[i, off …]`` = the static light of each span, for every sample row i."""
    n = out.shape[0]
    for i in prange(n):
        for s in range(rows.size):
            base = rows[s] * width
            o = offs[s]
            for c in range(c0s[s], c1s[s]):
                out[i, o + c - c0s[s]] = static[base + c]


class PaintedSampler(LightSampler):
    """Light that is a static background with parts painted over it per instant by the scene's own code.

    A scene whose light is ``background`` with a few moving or flickering parts drawn over it (a vehicle,
    propeller blades, objects, an arm: the built-in scenes) hands its drawing to this sampler:

    * ``paint(t_s, canvas)`` draws the light at ``t_s`` into ``canvas`` (a float64 (H, W) array that holds
      ``background``) and returns the boxes (row0, row1, col0, col1), ends exclusive, that it wrote;
    * ``rects(times_s)`` returns boxes (k, 4) whose union holds every pixel ``paint`` may write at any of
      ``times_s`` (a bound: it may be larger).

    The scene's :meth:`~viform.light.scenes.Scene.illuminance_lux` is ``paint`` on a copy of the
    background, so the light rendered here is the scene's light to the bit. Per light sample the sampler
    paints once into one canvas, converts the dirty pixels to charge in compiled code and restores the
    painted boxes from the background: its work is the painted area, never the whole field.
    """

    def __init__(self, background: np.ndarray, paint, rects, lux_max: float):
        self.background = np.ascontiguousarray(background, dtype=np.float64)
        self.height, self.width = self.background.shape
        self._paint = paint
        self._rects = rects
        self.lux_max = float(lux_max)
        self._canvas = self.background.copy()

    def static_lux(self) -> np.ndarray:
        return self.background

    def dirty_rects(self, times_s) -> np.ndarray:
        rects = np.asarray(self._rects(np.asarray(times_s, dtype=np.float64)), dtype=np.int64).reshape(-1, 4)
        rects[:, 0:2] = np.clip(rects[:, 0:2], 0, self.height)
        rects[:, 2:4] = np.clip(rects[:, 2:4], 0, self.width)
        return rects

    def render(self, times_s, starts, stops, a, b, out) -> None:
        canvas, background = self._canvas, self.background
        flat = canvas.reshape(-1)
        starts = np.ascontiguousarray(starts, dtype=np.int64)
        stops = np.ascontiguousarray(stops, dtype=np.int64)
        rates = out.dtype == np.int64
        for i, t in enumerate(np.asarray(times_s, dtype=np.float64).tolist()):
            boxes = self._paint(t, canvas)
            try:
                if rates:
                    _gather_rates(flat, starts, stops, a, b, out[i])
                else:
                    _gather_lux(flat, starts, stops, out[i])
            finally:
                for r0, r1, c0, c1 in boxes:
                    canvas[r0:r1, c0:c1] = background[r0:r1, c0:c1]


@njit(cache=True)
def _gather_rates(flat, starts, stops, a, b, out):
    """``out`` = rint(a·lux + b) of the pixels of the flat ranges laid end to end (as :func:`lux_to_rates`)."""
    o = 0
    for k in range(starts.size):
        for p in range(starts[k], stops[k]):
            out[o] = np.int64(np.rint(flat[p] * a[o] + b[o]))
            o += 1


@njit(cache=True)
def _gather_lux(flat, starts, stops, out):
    o = 0
    for k in range(starts.size):
        for p in range(starts[k], stops[k]):
            out[o] = flat[p]
            o += 1
