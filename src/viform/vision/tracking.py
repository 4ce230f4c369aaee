"""Detection and tracking of moving objects on spike streams (and on frames), in bounded memory.

Seed 000 (abstract, §7) claims detection and tracking far faster than a frame camera from the
spike stream itself. This module is that pipeline, one stage per function:

1. **Change front end** — a pixel is *foreground* when its light differs from its own
   background level, so static texture never responds, only a change of light does:

   * spikes (:class:`SpikeChangeDetector`): each spike gives the pixel's current interval
     τ (the mean of its last two intervals, seed 000 §3.3: light ∝ Q/τ; of its last four
     where two span fewer than 8 ticks, since the one-tick readout quantization dominates
     there); the background level is a running mean of τ (time constant ``background_ticks``)
     updated only while the pixel agrees with it, so an object passing by does not leak into
     it; a pixel that stays different for longer than ``hold_ticks`` is absorbed (a stopped
     object). Between spikes, a silence longer than the background interval times
     e^threshold flags a pixel that got darker, without waiting for its next spike. A pixel
     with no interval yet starts from the censored bound "at least as long as the stream so
     far", so a bright object is seen from its first interval even at a high threshold Q.
     Objects already in view at the start would be learned as background (and leave a
     "ghost" where they stood): after ``seed_ticks`` the background of pixels that stand out
     from the background around them is interpolated from their surroundings
     (:func:`seed_background`).
   * frames (:class:`FrameChangeDetector`): the same rule on log light per frame.

2. **Grouping** (:func:`detect_boxes`): foreground pixels of one output step whose squares of
   half-width ``merge_px`` touch form one detection (connected components by union–find,
   compiled: scipy.ndimage's dilation + label + find_objects did the same at ~10× the cost per
   step); its box (x, y, w, h) over its own pixels is the detection.

3. **Association** (:class:`Tracker`): a constant-velocity Kalman filter per track predicts
   its box, detections are assigned to predictions by the Hungarian method
   (``scipy.optimize.linear_sum_assignment``) on 1 − IoU with a centre-distance fallback for
   small fast objects; a track is confirmed after ``min_hits`` matched steps, coasts on its
   prediction through up to ``max_coast_ticks`` without detections (short occlusions) and is
   then dropped. Results report confirmed tracks at the steps where a detection supports them
   (coasted positions are predictions, not measurements).

:func:`track_spikes` runs 1–3 on any :class:`~viform.stream.container.SpikeSource` block by
block (memory bounded whatever the stream length); :func:`track_frames` on a frame sequence.
Both return MOTChallenge-style rows (:mod:`viform.vision.motchallenge`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange
from scipy.ndimage import binary_dilation, gaussian_filter, median_filter
from scipy.optimize import linear_sum_assignment

from viform._validate import ViformError, check_int, check_non_negative, check_positive


@dataclass(frozen=True)
class TrackerParameters:
    """Parameters of the change front end and the association (units in the names).

    Attributes
    ----------
    threshold_log : float
        |ln(light / background)| above which a pixel is foreground (0.4: ×1.5 either way).
    background_ticks : float
        Time constant of the background level, in ticks (spike) — frames use the same
        time in seconds, converted with the stream's clock.
    hold_ticks : int
        Foreground longer than this (ticks) is absorbed into the background (an object that
        stopped; 2,000 ticks = 50 ms at 40 kHz).
    merge_px : int
        Foreground pixels closer than this (px) belong to one detection.
    min_pixels : int
        Smallest detection, foreground pixels (isolated noise is dropped).
    min_hits : int
        Matched steps before a track is confirmed (reported).
    max_coast_ticks : int
        Longest gap without a detection (ticks) a track survives, coasting on its prediction.
    gate_px : float
        Largest distance (px) between a prediction's and a detection's centres for a match,
        on top of the two boxes' half-diagonals.
    min_speed_px_per_s, still_ticks : float, int
        A track whose box centre moved slower than this over the last ``still_ticks`` ticks is
        not reported (a ghost, or an object that stopped). 0 (the default) reports every track:
        with the start-up seeding there are few ghosts left, and slow objects (100 px/s) count.
    merged_keep_alive : bool
        A confirmed track with no detection whose predicted box lies at least half inside a
        detection matched to another track is merged with (or hidden by) that object: it does
        not age while that lasts (the ball behind the truck keeps its id), and is not reported.
    seed_ticks, seed_measured_fraction : int, float
        When to seed: at the first of ``seed_ticks``·2^k ticks (k = 0, 1, …; 0: never), up to
        ``hold_ticks``, at which at least this fraction of the pixels has measured an interval
        (later at a high threshold Q).
    seed_window_px, seed_threshold_log, seed_unsure : int, float, bool
        Objects already in view when tracking starts: when seeded,
        a pixel whose learned light differs (|ln ratio| > ``seed_threshold_log``) from the median
        over ``seed_window_px`` px around it (wider than any object, on the assumption that the
        background is smoother than the objects on it) takes the background interpolated from
        the pixels around it, so the object is foreground at once and the place it leaves is not
        a ghost (:func:`seed_background`); with ``seed_unsure``, pixels that differ from that
        background by more than ``threshold_log`` only may return to it without being flagged.
        Frames apply it to their first frame.
    """

    threshold_log: float = 0.4
    background_ticks: float = 80.0
    hold_ticks: int = 2000
    merge_px: int = 2
    min_pixels: int = 12
    min_hits: int = 2
    max_coast_ticks: int = 600
    gate_px: float = 8.0
    min_speed_px_per_s: float = 0.0
    still_ticks: int = 400
    seed_ticks: int = 20
    seed_window_px: int = 96
    seed_threshold_log: float = 0.7
    seed_unsure: bool = True
    seed_measured_fraction: float = 0.9
    merged_keep_alive: bool = True

    def __post_init__(self):
        check_positive("threshold_log", self.threshold_log)
        check_positive("background_ticks", self.background_ticks)
        check_int("hold_ticks", self.hold_ticks, 1)
        check_int("merge_px", self.merge_px, 0)
        check_int("min_pixels", self.min_pixels, 1)
        check_int("min_hits", self.min_hits, 1)
        check_int("max_coast_ticks", self.max_coast_ticks, 0)
        check_positive("gate_px", self.gate_px)
        check_non_negative("min_speed_px_per_s", self.min_speed_px_per_s)
        check_int("still_ticks", self.still_ticks, 1)
        check_int("seed_ticks", self.seed_ticks, 0)
        check_int("seed_window_px", self.seed_window_px, 1)
        check_positive("seed_threshold_log", self.seed_threshold_log)
        if not 0.0 <= self.seed_measured_fraction <= 1.0:
            raise ViformError(f"seed_measured_fraction = {self.seed_measured_fraction!r} must be within 0 … 1")


# --------------------------------------------------------------------------- spike front end

#: Two intervals spanning fewer ticks than this are averaged over four instead (bright pixels).
_SHORT_SPAN_TICKS = 8

@njit(parallel=True, cache=True)
def _spike_change_block(spikes, first_tick, step_ticks, last1, last2, last3, last4, ref, prev, censored,
                        flag_since, pending, out, k_lo, k_hi, k_seed, background_ticks, hold_ticks):  # pragma: no cover
    # Intervals in ticks, compared by ratio (k_lo = e^−threshold, k_hi = e^threshold): no logarithm
    # per spike. The background interval follows an exponential mean with weight τ/(T + τ) per
    # interval τ (time constant T ticks).
    T, H, W = spikes.shape
    for r in prange(H):
        step = 0
        l1, l2, l3, l4, rf, pv = last1[r], last2[r], last3[r], last4[r], ref[r], prev[r]
        cs, fs, pd = censored[r], flag_since[r], pending[r]
        for t in range(T):
            tick = first_tick + t
            row = spikes[t, r]
            for c in range(W):
                if not row[c]:
                    continue
                p1 = l1[c]
                if p1 < 0:  # first spike: the interval is at least the stream so far (censored)
                    rf[c] = tick + 1.0
                    cs[c] = True
                    l1[c] = tick
                    continue
                p2 = l2[c]
                p4 = l4[c]
                if p4 >= 0 and tick - p2 < _SHORT_SPAN_TICKS:
                    # intervals of a few ticks: the one-tick quantization dominates, so average four of
                    # them (a saturated object spiking every tick is told from a background every 2 ticks)
                    n = 4.0
                    span = float(tick - p4)
                else:
                    n = 2.0 if p2 >= 0 else 1.0
                    span = float(tick - p2) if p2 >= 0 else float(tick - p1)
                tau = span / n
                b = rf[c]
                # the readout knows each spike to a tick: the span of n intervals is (span − 1, span + 1)
                # ticks, so only a change beyond that slack counts (short intervals are coarse)
                brighter = (span + 1.0) / n < b * k_lo
                darker = (span - 1.0) / n > b * k_hi
                if cs[c]:
                    flagged = brighter  # only "brighter" is known against a lower bound
                    if not flagged:  # the first measured interval replaces the bound
                        q = pv[c]
                        if q > 0.0 and ((span - 1.0) / n > q * k_seed or (span + 1.0) / n < q / k_seed):
                            # no interval yet when the background was seeded, and far from the background
                            # seeded around it: on an object since the start (seed_background)
                            rf[c] = q
                            pv[c] = 0.0
                            pd[c] = True
                            fs[c] = tick
                        else:
                            rf[c] = tau
                            fs[c] = -1
                        cs[c] = False
                        l4[c] = l3[c]
                        l3[c] = p2
                        l2[c] = p1
                        l1[c] = tick
                        continue
                else:
                    flagged = brighter or darker
                q = pv[c]
                if flagged and q > 0.0 and q * k_lo <= tau <= q * k_hi:
                    # back to the background it had before something stayed on it: not an object's trail
                    rf[c] = q
                    pv[c] = 0.0
                    flagged = False
                    b = q
                if flagged:
                    if fs[c] < 0:
                        fs[c] = tick
                    if tick - fs[c] > hold_ticks:  # stayed different: it is the background now
                        if q <= 0.0:
                            pv[c] = b
                        rf[c] = b + tau / (background_ticks + tau) * (tau - b)
                        cs[c] = False
                    pd[c] = True
                else:
                    fs[c] = -1
                    rf[c] = b + tau / (background_ticks + tau) * (tau - b)
                l4[c] = l3[c]
                l3[c] = p2
                l2[c] = p1
                l1[c] = tick
            if (tick + 1) % step_ticks == 0:  # end of an output step: darker pixels, then emit
                for c in range(W):
                    p1 = l1[c]
                    if p1 >= 0 and not cs[c]:
                        silence = float(tick - p1)  # the interval in progress is longer (one tick of slack)
                        q = pv[c]
                        if silence > rf[c] * k_hi and not (q > 0.0 and silence <= q * k_hi):
                            pd[c] = True
                            if fs[c] < 0:
                                fs[c] = tick
                    out[step, r, c] = pd[c]
                    pd[c] = False
                step += 1


class SpikeChangeDetector:
    """Foreground masks from a spike stream, one per output step of ``step_ticks`` ticks.

    Feed blocks of consecutive ticks to :meth:`feed`; it returns the masks of the steps
    completed by the block (a step may span blocks: the state carries over), so the same
    masks come out whatever the block size.
    """

    def __init__(self, height: int, width: int, step_ticks: int, parameters: TrackerParameters | None = None):
        self.parameters = parameters or TrackerParameters()
        self.step_ticks = check_int("step_ticks", step_ticks, 1)
        shape = (check_int("height", height, 1), check_int("width", width, 1))
        self.last1 = np.full(shape, -1, np.int64)
        self.last2 = np.full(shape, -1, np.int64)
        self.last3 = np.full(shape, -1, np.int64)
        self.last4 = np.full(shape, -1, np.int64)
        self.ref = np.zeros(shape, np.float64)  # background interval, ticks
        self.prev = np.zeros(shape, np.float64)  # the background before the last absorption (0: none)
        self.censored = np.zeros(shape, np.bool_)
        self.flag_since = np.full(shape, -1, np.int64)
        self.pending = np.zeros(shape, np.bool_)
        self.next_tick = 0
        self.seeded = False

    def feed(self, spikes: np.ndarray) -> np.ndarray:
        """Process the next ``spikes`` block (T, H, W) bool; returns (steps completed, H, W) bool masks."""
        spikes = np.ascontiguousarray(spikes, dtype=np.bool_)
        outs, start = [], 0
        while True:  # split at the seeding checks: the same ticks whatever the blocks
            check = self._next_seed_check()
            end = spikes.shape[0] if check is None else min(spikes.shape[0], start + check - self.next_tick)
            outs.append(self._feed(spikes[start:end]))
            start = end
            if check is not None and self.next_tick == check:
                self._seed()
            if start >= spikes.shape[0]:
                return np.concatenate(outs)

    def _feed(self, spikes):
        first = self.next_tick
        n_out = (first + spikes.shape[0]) // self.step_ticks - first // self.step_ticks
        out = np.zeros((n_out,) + self.ref.shape, np.bool_)
        p = self.parameters
        _spike_change_block(spikes, first, self.step_ticks, self.last1, self.last2, self.last3, self.last4, self.ref,
                            self.prev, self.censored,
                            self.flag_since, self.pending, out, math.exp(-p.threshold_log),
                            math.exp(p.threshold_log), math.exp(p.seed_threshold_log), p.background_ticks,
                            p.hold_ticks)
        self.next_tick += spikes.shape[0]
        return out

    def _next_seed_check(self):
        """The next tick (``seed_ticks``·2^k) at which to try seeding the background, or None."""
        every = self.parameters.seed_ticks
        if every <= 0 or self.seeded:
            return None
        check = every
        while check <= self.next_tick:  # checks at seed_ticks·2^k: a handful, whatever the threshold Q
            check *= 2
        return check if check <= self.parameters.hold_ticks else None  # past that, give up

    def _seed(self):
        """Seed the background (:func:`seed_background`) once enough pixels have measured an interval."""
        p = self.parameters
        measured = ~self.censored & (self.last1 >= 0)
        if measured.mean() < p.seed_measured_fraction:
            return  # a high threshold Q or dim light: wait for more intervals
        self.seeded = True
        # intervals are inverse light: the same test on ln τ
        log_ref = np.log(np.where(measured, self.ref, 1.0))
        seeded, unsure, around, weight = seed_background(log_ref, measured, p.seed_threshold_log,
                                                         p.seed_window_px, p.threshold_log, weights=True)
        self.ref[seeded] = np.exp(around)[seeded]
        self.prev[seeded] = 0.0
        self.flag_since[seeded] = -1
        if p.seed_unsure:
            self.prev[unsure] = np.exp(around)[unsure]
        # no interval yet (dim pixels): their first one is compared with the background seeded around them,
        # where enough pixels around were measured
        later = ~measured & (weight > 0.5)
        self.prev[later] = np.exp(around)[later]


class FrameChangeDetector:
    """Foreground masks from frames (any unit proportional to light), one per frame.

    The rule of :class:`SpikeChangeDetector` on ln(light): a pixel is foreground where
    |ln(E / background)| > threshold; the background follows unflagged pixels with time
    constant ``background_s`` and absorbs pixels flagged for longer than ``hold_s``.
    ``floor`` (same unit as the frames) keeps the logarithm finite in the dark.
    """

    def __init__(self, background_s: float, hold_s: float, parameters: TrackerParameters | None = None,
                 floor: float = 1e-3):
        self.parameters = parameters or TrackerParameters()
        self.background_s = check_positive("background_s", background_s)
        self.hold_s = check_positive("hold_s", hold_s)
        self.floor = check_positive("floor", floor)
        self.ref = None
        self.flag_since = None
        self.last_t = None

    def feed(self, frame: np.ndarray, t_s: float) -> np.ndarray:
        """One frame (H, W) seen at ``t_s``: its foreground mask (all False for the first frame)."""
        cur = np.log(np.maximum(np.asarray(frame, dtype=np.float64), self.floor))
        if self.ref is None:
            self.ref, self.flag_since, self.last_t = cur.copy(), np.full(cur.shape, np.nan), t_s
            p = self.parameters
            if p.seed_ticks > 0:  # objects in the first frame: the background around them, as for spikes
                seeded, _, around = seed_background(cur, np.ones(cur.shape, bool), p.seed_threshold_log,
                                                    p.seed_window_px, p.threshold_log)
                self.ref[seeded] = around[seeded]
            return np.zeros(cur.shape, bool)
        d = cur - self.ref
        flagged = np.abs(d) > self.parameters.threshold_log
        self.flag_since[flagged & np.isnan(self.flag_since)] = t_s
        self.flag_since[~flagged] = np.nan
        gain = 1.0 - math.exp(-max(t_s - self.last_t, 0.0) / self.background_s)
        update = ~flagged | (t_s - np.nan_to_num(self.flag_since, nan=t_s) > self.hold_s)
        self.ref[update] += gain * d[update]
        self.last_t = t_s
        return flagged


# --------------------------------------------------------------------------- start-up background

_SEED_BLOCK_PX = 4  # the robust background is computed on blocks of 4×4 px (the background is smooth)


def _robust_background(log_light: np.ndarray, valid: np.ndarray, window_px: int) -> np.ndarray:
    """Median of ``log_light`` over valid pixels in a ``window_px`` square around each pixel (blocks of 4 px)."""
    H, W = log_light.shape
    b = _SEED_BLOCK_PX
    hb, wb = -(-H // b), -(-W // b)
    pad = np.full((hb * b, wb * b), np.nan)
    pad[:H, :W] = np.where(valid, log_light, np.nan)
    blocks = pad.reshape(hb, b, wb, b).transpose(0, 2, 1, 3).reshape(hb, wb, b * b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN blocks: filled below
        med = np.nanmedian(blocks, axis=2)
    fill = np.nanmedian(med) if np.isfinite(med).any() else 0.0
    med = np.where(np.isfinite(med), med, fill)
    size = max(1, window_px // b) | 1  # odd, in blocks
    smooth = median_filter(med, size=size, mode="nearest")
    return np.repeat(np.repeat(smooth, b, axis=0), b, axis=1)[:H, :W]


def seed_background(log_light: np.ndarray, valid: np.ndarray, threshold_log: float, window_px: int,
                    unsure_log: float | None = None, weights: bool = False):
    """Objects in view at the start: pixels that stand out from the background around them, and that background.

    A change detector that learns its background from the first light it sees learns the objects
    already in view as background: they stay invisible until they move off and leave a "ghost"
    where they stood. Assuming the background is smoother than the objects on it, a pixel more
    than ``threshold_log`` from the median of ln(light) over ``window_px`` px (wider than twice
    any object) is on an object (*seeded*). The background under and near it is then
    interpolated from the pixels around that are not seeded (normalised Gaussian smoothing,
    σ = ``window_px``/8: the local background, not the window's median), which is what the
    pixel shows once the object has moved off.

    Parameters
    ----------
    log_light : ndarray (H, W)
        ln of the light (or of the spike interval, its inverse: the test is symmetric).
    valid : ndarray (H, W) bool
        Pixels with a measurement (spike pixels that have no interval yet are left out).
    threshold_log, window_px : float, int
    unsure_log : float, optional
        Pixels not seeded but more than this from the local background are returned as *unsure*.

    Returns
    -------
    seeded, unsure : ndarray (H, W) bool
    background : ndarray (H, W) float
        The estimated ln(light) of the background (same unit as ``log_light``).
    weight : ndarray (H, W) float
        With ``weights``: the Gaussian-weighted fraction of clear measured pixels the background
        was interpolated from (0 … 1).
    """
    window_px = check_int("window_px", window_px, 1)
    coarse = _robust_background(log_light, valid, window_px)
    seeded = valid & (np.abs(log_light - coarse) > threshold_log)
    # the local background from the pixels that are not on an object (their anti-aliased edges excluded)
    clear = (valid & ~binary_dilation(seeded, iterations=2)).astype(np.float64)
    sigma = max(window_px / 8.0, 1.0)
    weight = gaussian_filter(clear, sigma, mode="nearest")
    total = gaussian_filter(np.where(clear > 0, log_light, 0.0), sigma, mode="nearest")
    background = np.where(weight > 1e-3, total / np.maximum(weight, 1e-3), coarse)
    unsure = np.zeros_like(seeded)
    if unsure_log is not None:
        unsure = valid & ~seeded & (np.abs(log_light - background) > unsure_log)
    return (seeded, unsure, background, weight) if weights else (seeded, unsure, background)


# --------------------------------------------------------------------------- grouping

@njit(cache=True)
def _find(parent, i):  # pragma: no cover - compiled
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def _components(mask, reach, min_pixels):  # pragma: no cover - compiled
    """Union–find over the foreground pixels; pixels within Chebyshev distance ``reach`` join."""
    H, W = mask.shape
    n = 0
    for y in range(H):
        for x in range(W):
            if mask[y, x]:
                n += 1
    ys = np.empty(n, np.int64)
    xs = np.empty(n, np.int64)
    index = np.full((H, W), -1, np.int64)
    parent = np.arange(n)
    k = 0
    for y in range(H):
        for x in range(W):
            if not mask[y, x]:
                continue
            ys[k], xs[k] = y, x
            index[y, x] = k
            for yy in range(max(0, y - reach), y + 1):  # earlier pixels in scan order only
                hi = min(W - 1, x + reach) if yy < y else x - 1
                for xx in range(max(0, x - reach), hi + 1):
                    j = index[yy, xx]
                    if j >= 0:
                        a, b = _find(parent, k), _find(parent, j)
                        if a != b:
                            parent[max(a, b)] = min(a, b)
            k += 1
    box = np.empty((n, 4), np.int64)  # x0, y0, x1, y1 per root
    count = np.zeros(n, np.int64)
    for k in range(n):
        r = _find(parent, k)
        if count[r] == 0:
            box[r, 0], box[r, 1], box[r, 2], box[r, 3] = xs[k], ys[k], xs[k], ys[k]
        else:
            box[r, 0], box[r, 1] = min(box[r, 0], xs[k]), min(box[r, 1], ys[k])
            box[r, 2], box[r, 3] = max(box[r, 2], xs[k]), max(box[r, 3], ys[k])
        count[r] += 1
    m = 0
    for k in range(n):
        if count[k] >= min_pixels:
            m += 1
    boxes = np.empty((m, 4), np.float64)
    counts = np.empty(m, np.int64)
    m = 0
    for k in range(n):  # roots in scan order of their first pixel: a deterministic order
        if count[k] >= min_pixels:
            boxes[m, 0], boxes[m, 1] = box[k, 0], box[k, 1]
            boxes[m, 2], boxes[m, 3] = box[k, 2] - box[k, 0] + 1, box[k, 3] - box[k, 1] + 1
            counts[m] = count[k]
            m += 1
    return boxes, counts


def detect_boxes(mask: np.ndarray, merge_px: int = 2, min_pixels: int = 4):
    """Detections of one foreground mask: boxes (N, 4) of (x, y, w, h) px, 0-based, and pixel counts.

    Foreground pixels whose squares of half-width ``merge_px`` touch (Chebyshev distance
    ≤ 2·``merge_px`` + 1; 0 = 8-connected) join one detection — the components of the mask
    dilated by ``merge_px`` — by union–find, compiled; each box spans the detection's own pixels.
    Detections with fewer than ``min_pixels`` pixels are dropped.

    Returns
    -------
    boxes : ndarray, shape (N, 4), float64
    counts : ndarray, shape (N,), int64
    """
    mask = np.ascontiguousarray(mask, dtype=np.bool_)
    if mask.ndim != 2:
        raise ViformError(f"mask must be 2-D (H, W); got shape {mask.shape}")
    return _components(mask, 2 * check_int("merge_px", merge_px, 0) + 1, check_int("min_pixels", min_pixels, 1))


def iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union of every box of ``a`` (N, 4) with every box of ``b`` (M, 4), (x, y, w, h)."""
    a = np.asarray(a, np.float64).reshape(-1, 4)
    b = np.asarray(b, np.float64).reshape(-1, 4)
    ix = np.clip(np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2])
                 - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    iy = np.clip(np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3])
                 - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = ix * iy
    union = (a[:, 2] * a[:, 3])[:, None] + (b[:, 2] * b[:, 3])[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


# --------------------------------------------------------------------------- association

@dataclass
class _Track:
    track_id: int
    state: np.ndarray  # (cx, cy, vx, vy): px and px per second
    cov: np.ndarray
    size: np.ndarray  # (w, h), px
    last_t: float
    last_seen_t: float
    hits: int = 1
    confirmed: bool = False
    trail: list = field(default_factory=list)


class Tracker:
    """Constant-velocity Kalman tracks, Hungarian assignment, birth and death with hysteresis.

    Parameters
    ----------
    parameters : TrackerParameters
    tick_s : float
        Duration of a tick, s (turns ``max_coast_ticks`` into seconds).
    position_noise_px : float
        Measurement noise of a detection's centre, px (std).
    acceleration_px_per_s2 : float
        Process noise: unmodelled acceleration, px/s² (std).
    """

    def __init__(self, parameters: TrackerParameters | None = None, tick_s: float = 1 / 40_000,
                 position_noise_px: float = 1.0, acceleration_px_per_s2: float = 2e6):
        self.parameters = parameters or TrackerParameters()
        self.tick_s = check_positive("tick_s", tick_s)
        self.r = position_noise_px ** 2
        self.q = acceleration_px_per_s2 ** 2
        self.tracks: list[_Track] = []
        self.next_id = 1

    def _predict(self, track: _Track, t_s: float) -> np.ndarray:
        dt = t_s - track.last_t
        f = np.eye(4)
        f[0, 2] = f[1, 3] = dt
        g = np.array([[dt * dt / 2, 0], [0, dt * dt / 2], [dt, 0], [0, dt]])
        track.state = f @ track.state
        track.cov = f @ track.cov @ f.T + self.q * (g @ g.T)
        track.last_t = t_s
        return track.state

    def _box(self, track: _Track) -> np.ndarray:
        (cx, cy), (w, h) = track.state[:2], track.size
        return np.array([cx - w / 2, cy - h / 2, w, h])

    def update(self, boxes: np.ndarray, t_s: float) -> list[tuple[int, np.ndarray]]:
        """One step: detections ``boxes`` (N, 4) seen at ``t_s``; returns [(track id, box)] reported now."""
        p = self.parameters
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        for track in self.tracks:
            self._predict(track, t_s)
        predicted = np.array([self._box(tr) for tr in self.tracks]).reshape(-1, 4)
        matches = []
        unmatched = set(range(len(boxes)))
        if len(self.tracks) and len(boxes):
            iou = iou_matrix(predicted, boxes)
            pc = predicted[:, :2] + predicted[:, 2:] / 2
            bc = boxes[:, :2] + boxes[:, 2:] / 2
            dist = np.hypot(pc[:, None, 0] - bc[None, :, 0], pc[:, None, 1] - bc[None, :, 1])
            reach = (np.hypot(*predicted[:, 2:].T)[:, None] + np.hypot(*boxes[:, 2:].T)[None, :]) / 2 + p.gate_px
            cost = np.where(iou > 0, 1.0 - iou, 1.0 + dist / reach)
            cost = np.where(dist <= reach, cost, 1e6)
            rows, cols = linear_sum_assignment(cost)
            for i, j in zip(rows, cols, strict=True):
                if cost[i, j] < 1e6:
                    matches.append((i, j))
                    unmatched.discard(j)
        reported = []
        matched_tracks = set()
        for i, j in matches:
            track = self.tracks[i]
            self._correct(track, boxes[j], t_s)
            matched_tracks.add(i)
            if track.confirmed or track.hits >= p.min_hits:
                track.confirmed = True
                if self._moving(track, t_s):
                    reported.append((track.track_id, boxes[j].copy()))
        if p.merged_keep_alive and matches:
            # a confirmed track without a detection whose prediction lies inside another track's detection
            # is merged with (or hidden by) that object: it coasts on as long as that lasts
            matched_boxes = boxes[[j for _, j in matches]]
            for i, track in enumerate(self.tracks):
                if i in matched_tracks or not track.confirmed:
                    continue
                pb = predicted[i]
                ix = np.clip(np.minimum(pb[0] + pb[2], matched_boxes[:, 0] + matched_boxes[:, 2])
                             - np.maximum(pb[0], matched_boxes[:, 0]), 0, None)
                iy = np.clip(np.minimum(pb[1] + pb[3], matched_boxes[:, 1] + matched_boxes[:, 3])
                             - np.maximum(pb[1], matched_boxes[:, 1]), 0, None)
                inside = ix * iy / max(pb[2] * pb[3], 1e-9)
                if inside.max() >= 0.5:
                    track.last_seen_t = t_s  # not reported: its box is a prediction, not a measurement
        coast_s = p.max_coast_ticks * self.tick_s
        self.tracks = [tr for i, tr in enumerate(self.tracks)
                       if i in matched_tracks or (tr.confirmed and t_s - tr.last_seen_t <= coast_s)]
        for j in sorted(unmatched):
            b = boxes[j]
            state = np.array([b[0] + b[2] / 2, b[1] + b[3] / 2, 0.0, 0.0])
            cov = np.diag([self.r, self.r, 1e8, 1e8])  # unknown velocity: up to 10,000 px/s
            track = _Track(self.next_id, state, cov, b[2:].copy(), t_s, t_s, trail=[(t_s, state[:2].copy())])
            self.next_id += 1
            self.tracks.append(track)
            if p.min_hits <= 1:
                track.confirmed = True
                reported.append((track.track_id, b.copy()))
        return reported

    def _moving(self, track: _Track, t_s: float) -> bool:
        """Whether the track's measured centre moved at least ``min_speed`` over the last ``still_ticks``."""
        window_s = self.parameters.still_ticks * self.tick_s
        while len(track.trail) > 2 and track.trail[1][0] <= t_s - window_s:
            track.trail.pop(0)  # keep one point at or before the window's start
        (t0, c0), (t1, c1) = track.trail[0], track.trail[-1]
        if t1 - t0 < window_s:
            return True  # too young to judge
        return math.hypot(*(c1 - c0)) >= self.parameters.min_speed_px_per_s * (t1 - t0)

    def _correct(self, track: _Track, box: np.ndarray, t_s: float) -> None:
        h = np.zeros((2, 4))
        h[0, 0] = h[1, 1] = 1.0
        z = box[:2] + box[2:] / 2
        s = h @ track.cov @ h.T + self.r * np.eye(2)
        k = track.cov @ h.T @ np.linalg.inv(s)
        track.state = track.state + k @ (z - h @ track.state)
        track.cov = (np.eye(4) - k @ h) @ track.cov
        track.size = 0.5 * track.size + 0.5 * box[2:]
        track.hits += 1
        track.last_seen_t = t_s
        track.trail.append((t_s, z.copy()))


# --------------------------------------------------------------------------- pipelines

@dataclass
class TrackingResult:
    """What a tracking run produced.

    Attributes
    ----------
    rows : ndarray, shape (N, 7)
        MOTChallenge result rows (frame, id, x, y, w, h, conf), x and y 0-based.
    times_s : ndarray, shape (n_frames,)
        Instant of each frame (frame k = ``times_s[k − 1]``), s.
    step_ticks : int or None
        Ticks per frame (spike streams), None for frame cameras.
    detections : int
        Detections found over the run.
    """

    rows: np.ndarray
    times_s: np.ndarray
    step_ticks: int | None
    detections: int


def _rows(frame: int, reported) -> list:
    return [(frame, tid, *box, 1.0) for tid, box in reported]


def track_spikes(source, step_ticks: int, parameters: TrackerParameters | None = None,
                 block_ticks: int = 1024, on_step=None) -> TrackingResult:
    """Track moving objects in a spike stream, reporting every ``step_ticks`` ticks.

    Parameters
    ----------
    source : SpikeSource
        Any spike stream (file, store, in memory, simulated on the fly); read block by block.
    step_ticks : int
        Output step N, ticks: frame k covers ticks [(k − 1)·N, k·N) and is reported at its end.
    parameters : TrackerParameters, optional
    block_ticks : int
        Ticks read at a time (bounds memory; the result does not depend on it).
    on_step : callable, optional
        Called as ``on_step(frame, t_s, mask, reported)`` after each step (overlays, progress).

    Returns
    -------
    TrackingResult
    """
    step_ticks = check_int("step_ticks", step_ticks, 1)
    if source.n_ticks < step_ticks:
        raise ViformError(f"the stream has {source.n_ticks} ticks, fewer than one output step of {step_ticks}")
    p = parameters or TrackerParameters()
    detector = SpikeChangeDetector(source.height, source.width, step_ticks, p)
    tracker = Tracker(p, tick_s=1.0 / source.clock_hz)
    rows, times, n_det = [], [], 0
    block = max(step_ticks, (check_int("block_ticks", block_ticks, 1) // step_ticks) * step_ticks)
    n_usable = (source.n_ticks // step_ticks) * step_ticks
    for _, spikes in source.iter_blocks(block, 0, n_usable):
        for mask in detector.feed(spikes):
            frame = len(times) + 1
            t_s = source.start_time_s + frame * step_ticks / source.clock_hz
            boxes, _ = detect_boxes(mask, p.merge_px, p.min_pixels)
            n_det += len(boxes)
            reported = tracker.update(boxes, t_s)
            rows += _rows(frame, reported)
            times.append(t_s)
            if on_step is not None:
                on_step(frame, t_s, mask, reported)
    return TrackingResult(np.array(rows, np.float64).reshape(-1, 7), np.array(times), step_ticks, n_det)


def track_frames(frames, times_s, parameters: TrackerParameters | None = None, tick_s: float = 1 / 40_000,
                 floor: float = 1e-3) -> TrackingResult:
    """The same back end on a frame camera's images (frame k = ``frames[k − 1]`` seen at ``times_s[k − 1]``).

    Time constants in ticks (``background_ticks``, ``hold_ticks``, ``max_coast_ticks``) become
    seconds with ``tick_s`` — the spike camera's tick — so every sensor runs with the same
    settings in seconds; nothing is tuned per sensor.

    Parameters
    ----------
    frames : iterable of ndarray (H, W)
        Light estimates (lux, or anything proportional to light).
    times_s : array_like
        The instant each frame reports (end of its exposure: the earliest it can be read), s.
    """
    p = parameters or TrackerParameters()
    times = np.asarray(times_s, np.float64).ravel()
    detector = FrameChangeDetector(p.background_ticks * tick_s, p.hold_ticks * tick_s, p, floor)
    tracker = Tracker(p, tick_s=tick_s)
    rows, n_det, n = [], 0, 0
    for frame, (image, t_s) in enumerate(zip(frames, times, strict=False), start=1):
        mask = detector.feed(image, float(t_s))
        boxes, _ = detect_boxes(mask, p.merge_px, p.min_pixels)
        n_det += len(boxes)
        rows += _rows(frame, tracker.update(boxes, float(t_s)))
        n = frame
    if n != times.size:
        raise ViformError(f"{n} frames were given for {times.size} instants")
    return TrackingResult(np.array(rows, np.float64).reshape(-1, 7), times, None, n_det)
