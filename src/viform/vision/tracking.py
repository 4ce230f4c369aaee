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
     "ghost" where they stood): after ``prime_ticks`` the background of pixels that stand out
     from the background around them is interpolated from their surroundings
     (:func:`prime_background`).
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

import contextlib
import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter, median_filter
from scipy.optimize import linear_sum_assignment

from viform._validate import ViformError, check_int, check_positive
from viform.vision import _spike_front as _front


@dataclass(frozen=True)
class TrackerParameters:
    """Parameters of the change front end and the association (units in the names).

    Attributes
    ----------
    threshold_log : float
        |ln(light / background)| above which a pixel is foreground (0.4: ×1.5 either way).
    left_log : float
        A foreground pixel brighter than its background stops being so once its silence passes
        e^``left_log`` times the intervals it had (the object has left it), and a pixel's last
        interval that long against its others reads as light that fell.
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
    min_hits, confirm_pixels : int
        Matched steps before a track is confirmed (reported); a track born on a detection of at
        least ``confirm_pixels`` pixels is confirmed at once (no noise makes one that large).
    max_coast_ticks : int
        Longest gap without a detection (ticks) a track survives, coasting on its prediction.
    gate_px : float
        Largest distance (px) between a prediction's and a detection's centres for a match,
        on top of the two boxes' half-diagonals.
    merged_keep_alive, report_merged : bool
        A confirmed track whose prediction lies inside another object's foreground (merged with
        it, or hidden by it) does not age while that lasts, so the ball behind the truck keeps its
        id; ``report_merged``: where the foreground holding both is split (:meth:`Tracker._regroup`),
        it is reported at its prediction.
    prime_ticks, prime_measured_fraction : int, float
        Priming checks at ``prime_ticks``·2^k ticks (k = 0, 1, …; 0: never), up to ``hold_ticks``,
        until at least this fraction of the pixels has measured an interval (later at a high
        threshold Q).
    prime_window_px, prime_threshold_log, prime_unsure : int, float, bool
        Objects already in view when tracking starts: at each check, a pixel whose light
        differs (|ln ratio| > ``prime_threshold_log``) from the median over ``prime_window_px``
        px around it (wider than any object, on the assumption that the background is smoother
        than the objects on it) takes the background interpolated from the pixels around it,
        so the object is foreground at once and the place it leaves is not a ghost
        (:meth:`SpikeChangeDetector._prime`, :func:`prime_background`); with ``prime_unsure``,
        pixels that differ from that background by more than ``threshold_log`` only may return
        to it without being flagged. Frames apply it to their starting background. Both give a
        primed group none of whose pixels changes within ``prime_confirm_ticks`` (spikes: or two of
        its intervals, when longer) its own light back for good (objects in view move; a sunlit
        window, a lamp, static texture that a dim 8-bit image shows strongly do not), unless it
        touches foreground of its sign that is not its own (a long object in view whose front moves on).
    """

    threshold_log: float = 0.4
    left_log: float = 0.4
    background_ticks: float = 400.0
    hold_ticks: int = 2000
    merge_px: int = 2
    min_pixels: int = 12
    min_hits: int = 2
    confirm_pixels: int = 48
    max_coast_ticks: int = 600
    gate_px: float = 8.0
    merged_keep_alive: bool = True
    report_merged: bool = True
    prime_ticks: int = 8
    prime_window_px: int = 96
    prime_threshold_log: float = 0.7
    prime_unsure: bool = True
    prime_measured_fraction: float = 0.9
    prime_confirm_ticks: int = 200

    def __post_init__(self):
        check_positive("threshold_log", self.threshold_log)
        check_positive("left_log", self.left_log)
        check_positive("background_ticks", self.background_ticks)
        check_int("hold_ticks", self.hold_ticks, 1)
        check_int("merge_px", self.merge_px, 0)
        check_int("min_pixels", self.min_pixels, 1)
        check_int("min_hits", self.min_hits, 1)
        check_int("confirm_pixels", self.confirm_pixels, 1)
        check_int("max_coast_ticks", self.max_coast_ticks, 0)
        check_positive("gate_px", self.gate_px)
        check_int("prime_ticks", self.prime_ticks, 0)
        check_int("prime_window_px", self.prime_window_px, 1)
        check_positive("prime_threshold_log", self.prime_threshold_log)
        if not 0.0 <= self.prime_measured_fraction <= 1.0:
            raise ViformError(f"prime_measured_fraction = {self.prime_measured_fraction!r} must be within 0 … 1")


# --------------------------------------------------------------------------- spike front end

def pack_spikes(spikes: np.ndarray) -> np.ndarray:
    """Spike bits (T, H, W) as packed words (T, ⌈H·W/64⌉) uint64: pixel r·W + c is bit k mod 64 of word k // 64."""
    spikes = np.asarray(spikes, dtype=np.bool_)
    t = spikes.shape[0]
    packed = np.packbits(spikes.reshape(t, -1), axis=1, bitorder="little")
    return _words(packed)


def _words(packed: np.ndarray) -> np.ndarray:
    """Packed bytes (T, n_bytes) as little-endian uint64 words (T, ⌈n_bytes/8⌉), zero-padded."""
    t, n_bytes = packed.shape
    n_words = -(-n_bytes // 8)
    if n_bytes != n_words * 8:
        padded = np.empty((t, n_words * 8), np.uint8)
        padded[:, :n_bytes] = packed
        padded[:, n_bytes:] = 0
        packed = padded
    return np.ascontiguousarray(packed).view("<u8").astype(np.uint64, copy=False)


#: Words of packed pixels the front end runs through a block's ticks together (their state stays in cache).
GROUP_WORDS = 64

#: Read a ``.dat`` file's next block of ticks in a second thread while the tracker works on the current one.
PREFETCH_BLOCKS = True

#: Run the front end on a ``.dat`` file's next block in a second thread while the current block's steps are
#: associated.
PIPELINE_FRONT_END = True


class SpikeChangeDetector:
    """Foreground from a spike stream, one mask per output step of ``step_ticks`` ticks.

    Per pixel the detector keeps its last spike, the window of intervals since the last step
    and a background interval; per spike it touches only that pixel's window (the spikes come
    as packed bits, 64 pixels a word); once per step each pixel's window becomes its interval
    estimate, compared with the background (module notes). Feed consecutive blocks of ticks to
    :meth:`feed` (bool arrays) or :meth:`feed_words` (packed): the state carries over, so the
    same masks come out whatever the block size.

    Parameters
    ----------
    height, width : int
        Image size.
    step_ticks : int
        Output step, ticks.
    parameters : TrackerParameters, optional
    stored_width : int, optional
        Pixels per row in the packed words (≥ ``width``; wider rows hold padding).
    flip : bool
        The packed rows are stored bottom-up (the ``.dat`` layout of the cameras).
    """

    def __init__(self, height: int, width: int, step_ticks: int, parameters: TrackerParameters | None = None,
                 stored_width: int | None = None, flip: bool = False):
        from numba import get_num_threads

        self.parameters = parameters or TrackerParameters()
        self.step_ticks = check_int("step_ticks", step_ticks, 1)
        self.height, self.width = check_int("height", height, 1), check_int("width", width, 1)
        self.stored_width = self.width if stored_width is None else check_int("stored_width", stored_width, self.width)
        self.flip = bool(flip)
        self.n_pixels = self.height * self.stored_width
        self.n_words = -(-self.n_pixels // 64)
        n = self.n_words * 64
        self.spk = np.zeros((n, 4), np.int64)  # per spike: last spike, the one before, step's first, intervals
        self.spk[:, _front.LAST] = -1
        self.spk[:, _front.BEFORE] = -1
        self.total = np.zeros(n, np.int64)  # spikes so far
        self.fired = np.zeros(self.n_words, np.uint64)  # pixels that fired in the current step
        self.fg_bits = np.zeros(self.n_words, np.uint64)
        self.word_due = np.full(self.n_words, -np.inf)  # the soonest due tick in each word
        self.anchor = np.full(n, -1, np.int64)
        self.span1 = np.zeros(n, np.int64)
        self.n1 = np.zeros(n, np.int64)
        self.win_span = np.zeros(n, np.int64)
        self.win_n = np.zeros(n, np.int64)
        self.mixed = np.zeros(n, np.bool_)  # the window is one interval during which the light fell
        self.bg = np.zeros(n, np.float64)  # background interval, ticks
        self.censored = np.zeros(n, np.bool_)  # bg is a lower bound
        self.fg = np.zeros(n, np.int8)
        self.flag_since = np.full(n, -1, np.int64)
        self.prev = np.zeros(n, np.float64)  # the background before the last absorption, or primed (0: none)
        self.due = np.full(n, np.inf)  # the tick from which silence alone could change the pixel's state
        chunks = max(1, min(get_num_threads(), self.n_words))
        edges = np.linspace(0, self.n_words, chunks + 1).round().astype(np.int64)
        self._chunks = (edges[:-1].copy(), edges[1:].copy())
        self.group_words = GROUP_WORDS
        self.dense_run_ticks, self.dense_spikes_per_tick = _front.DENSE_RUN_TICKS, _front.DENSE_SPIKES_PER_TICK
        self.next_tick = 0
        self.primed = False
        self._primed_ever = None
        self._index = None
        # primed groups still to confirm: (deadline tick, stored pixel indices, sign, prior lower and upper
        # interval bounds in ticks, priming tick); pixels given back (static: never primed again)
        self._groups = []
        self._given_back = np.zeros(n, np.bool_)
        self._prime_index = None  # the priming's scratch image, made at its first group

    def upright(self, flat: np.ndarray) -> np.ndarray:
        """A per-pixel state array (stored order) as an upright (H, W) view."""
        grid = flat[: self.n_pixels].reshape(self.height, self.stored_width)[:, : self.width]
        return grid[::-1] if self.flip else grid

    def feed(self, spikes: np.ndarray) -> np.ndarray:
        """Process the next ``spikes`` block (T, H, W) bool; returns (steps completed, H, W) bool masks."""
        if self.flip or self.stored_width != self.width:
            raise ViformError("feed() takes upright (T, H, W) spikes; this detector reads a stored layout: "
                              "use feed_words()")
        bits = self.feed_words(pack_spikes(spikes))
        return np.stack([self.mask(b) for b in bits]) if len(bits) else np.zeros((0, self.height, self.width), bool)

    def mask(self, bits: np.ndarray) -> np.ndarray:
        """One step's packed foreground as an upright (H, W) bool mask."""
        ys, xs = self.pixels(bits)
        m = np.zeros((self.height, self.width), bool)
        m[ys, xs] = True
        return m

    def pixels(self, bits: np.ndarray):
        """Rows and columns (upright, scan order) of one step's foreground pixels."""
        return _front.foreground_pixels(bits, self.height, self.width, self.stored_width, self.flip)

    def components(self, bits: np.ndarray, merge_px: int, min_pixels: int):
        """Detections of one step: boxes (N, 4), pixel counts (N,), and the pixels (ys, xs, component)."""
        ys, xs = self.pixels(bits)
        if self._index is None:
            self._index = np.full((self.height, self.width), -1, np.int64)
        boxes, counts, labels = _front.components_of_pixels(ys, xs, self.height, self.width, 2 * merge_px + 1,
                                                            min_pixels, self._index)
        return boxes, counts, (ys, xs, labels)

    def feed_words(self, words: np.ndarray) -> np.ndarray:
        """Process the next block of packed ticks (T, n_words) uint64; returns (steps completed, n_words) bits."""
        words = np.ascontiguousarray(words, dtype=np.uint64)
        if words.ndim != 2 or words.shape[1] != self.n_words:
            raise ViformError(f"packed spikes must have shape (T, {self.n_words}); got {words.shape}")
        # a read-only view whatever the caller holds (spikes read from a file are read-only): the kernel
        # is compiled once, for read-only words, not once for each kind of array
        words = words.view()
        words.flags.writeable = False
        outs, start = [], 0
        while True:  # split at the priming checks and the primed groups' deadlines: the same ticks whatever the blocks
            prime_at = self._next_prime_check()
            confirm_at = min((g[0] for g in self._groups), default=None)
            check = min((c for c in (prime_at, confirm_at) if c is not None), default=None)
            end = words.shape[0] if check is None else min(words.shape[0], start + check - self.next_tick)
            at_check = check is not None and self.next_tick + (end - start) == check
            outs.append(self._feed(words[start:end], at_check))
            start = end
            if at_check and check == confirm_at:
                self._confirm()
            if at_check and check == prime_at:
                self._prime()
            if start >= words.shape[0]:
                return np.concatenate(outs)

    def _feed(self, words, evaluate_at_end=False):
        first = self.next_tick
        t = words.shape[0]
        n_out = (first + t) // self.step_ticks - first // self.step_ticks
        extra = evaluate_at_end and t > 0 and (first + t) % self.step_ticks != 0
        out = np.zeros((n_out + extra, self.n_words), np.uint64)
        if t:
            p = self.parameters
            _front.spike_front_block(words, first, self.step_ticks, bool(extra), self._chunks[0], self._chunks[1],
                                     self.group_words, self.dense_run_ticks, self.dense_spikes_per_tick,
                                     self.n_pixels, self.spk, self.total, self.fired, self.fg_bits,
                                     self.word_due, self.anchor, self.span1, self.n1, self.win_span, self.win_n,
                                     self.mixed, self.bg,
                                     self.censored, self.fg, self.flag_since, self.prev, self.due, out,
                                     math.exp(-p.threshold_log), math.exp(p.threshold_log),
                                     math.exp(p.prime_threshold_log), math.exp(p.left_log),
                                     float(p.background_ticks), int(p.hold_ticks))
        self.next_tick += t
        return out[:n_out]

    def _next_prime_check(self):
        """The next tick (``prime_ticks``·2^k) at which to try priming the background, or None."""
        every = self.parameters.prime_ticks
        if every <= 0 or self.primed:
            return None
        check = every
        while check <= self.next_tick:  # checks at prime_ticks·2^k: a handful, whatever the threshold Q
            check *= 2
        return check if check <= self.parameters.hold_ticks else None  # past that, give up

    def _prime(self):
        """Objects in view since the start: set the background of pixels that stand out from their surroundings.

        Run at the priming checks (the state is evaluated at the check's tick). Each pixel's
        current interval is measured (a window of intervals) or only bounded from below (no
        complete interval yet: at least the time since the stream started, or since its only
        spike). A pixel whose interval is more than ×e^``prime_threshold_log`` shorter than the
        robust median over ``prime_window_px`` around it is on a brighter object (valid even
        where that median is only a lower bound): its background becomes the level interpolated
        from the clear pixels around it, kept as a lower bound, so only "brighter" is tested
        against it until its first interval after the object has gone replaces it. A pixel longer
        by that factor than a *measured* median is on a darker object: it takes the measured
        level around it. Repeated at every check until ``prime_measured_fraction`` of the pixels
        are measured.
        """
        p = self.parameters
        t = self.next_tick - 1  # the state was evaluated at this tick
        up = self.upright
        bg, censored, prev, flag_since = up(self.bg), up(self.censored), up(self.prev), up(self.flag_since)
        # per pixel, in one compiled pass: measured or not, the bound an unmeasured interval is longer than,
        # the interval (or that bound), and the longest and shortest the measured interval can be
        # (read from the stored layout, upright arrays out: no copies of the upright views first)
        measured, bound, value, upper, lower = _front.prime_values_stored(
            self.spk, self.win_n, self.win_span, self.height, self.width, self.stored_width, self.flip, t,
            math.exp(p.threshold_log))
        log_v = np.log(value)
        H, W = log_v.shape
        # the robust median around, and whether it is measured: bounds above the median do not move it
        # (on 16-px blocks: the window is 96 px)
        b = 2 * _PRIME_BLOCK_PX
        size = max(1, p.prime_window_px // b) | 1
        # (per block: a block's pixels share its median and whether it is measured)
        med_b = median_filter(_front.block_medians(log_v, b), size=size, mode="nearest")
        low_frac = median_filter(_front.block_low_fractions(measured, log_v, med_b, b), size=size, mode="nearest")
        median_measured = low_frac < 0.1
        thr = float(p.prime_threshold_log)
        upper, lower = np.log(upper), np.log(lower)
        # objects are at least 3 px across (an opening removes thin lines of static texture)
        back = np.ascontiguousarray(up(self._given_back))  # static, given back: not an object
        # a background learned from an object that has since moved on (its current light may agree)
        known = ~censored & (bg > 0)
        log_bg = np.log(np.where(known, bg, 1.0))
        # in one compiled pass (exact): brighter (not a falling transition), darker, and stale, before opening
        bright, dark, stale = _front.prime_candidates(measured, np.ascontiguousarray(up(self.mixed)), upper, lower,
                                                      med_b, median_measured, b, known, log_bg, back, thr)
        bright = _opened(bright) & ~back
        dark = _opened(dark) & ~back
        # ... kept where wide enough to be an object, or at the edge of where one stood (anti-aliased edges)
        if self._primed_ever is None:
            self._primed_ever = np.zeros(stale.shape, bool)
        self._primed_ever |= bright | dark
        stale &= _opened(stale) | _grown(self._primed_ever)
        clear = ~_grown(bright | dark | back) & ~stale  # (static regions that stand out are no background either)
        around, weight_b, measured_around_b = _interpolate_clear_blocks(log_v, clear, p.prime_window_px, measured)
        level = np.exp(around)
        # in one compiled pass (exact), in place: primed pixels take the level around as background, a lower
        # bound unless measured around (only "brighter" is tested against it until the pixel's first interval
        # replaces it) and always under a brighter object; a darker one with no interval yet is darker once
        # silent for longer than that level allows; pixels more than threshold_log from the level around
        # (with prime_unsure) and those with no interval yet whose level around is measured (later) keep it
        later = _front.prime_apply(bright, dark, stale, measured, back, log_v, around, level,
                                   measured_around_b > 0.9, weight_b, _PRIME_BLOCK_PX, known, log_bg,
                                   float(p.threshold_log), bool(p.prime_unsure), bg, censored, prev, flag_since)
        self._new_groups(bright, dark | later, upper, lower, level, t)
        self.word_due[:] = -np.inf  # every pixel evaluated at the next step, against its new background
        if measured.mean() >= p.prime_measured_fraction:
            self.primed = True

    def _new_groups(self, bright, dark, upper_log, lower_log, level, t):
        """Pixels primed at tick ``t`` as groups to confirm: grouped as detections are (``merge_px``), brighter
        and darker apart (``upper_log``, ``lower_log``: the logarithms of their longest and shortest intervals).

        A group's deadline is ``prime_confirm_ticks`` after priming, or two of its typical intervals
        (its own for a brighter group, the background's around for a darker one) when longer: no
        change can be measured sooner; it falls at the end of an output step.
        """
        p = self.parameters
        pending = np.zeros(self.spk.shape[0], np.bool_)
        for g in self._groups:
            pending[g[1]] = True
        for sign, part in ((1, bright), (-1, dark)):
            part = part & ~self.upright(pending)
            if not part.any():
                continue
            ys, xs = np.nonzero(part)  # scan order
            upper, lower = np.exp(upper_log[ys, xs]), np.exp(lower_log[ys, xs])  # (only the groups' pixels)
            typical = upper if sign > 0 else level[ys, xs]
            # (contiguous: np.nonzero's columns are strided views, and the kernels take contiguous ones, one
            # compiled signature)
            ys, xs = np.ascontiguousarray(ys, dtype=np.int64), np.ascontiguousarray(xs, dtype=np.int64)
            stored = ((self.height - 1 - ys) if self.flip else ys) * self.stored_width + xs  # (as upright's layout)
            if self._prime_index is None:
                self._prime_index = np.full((self.height, self.width), -1, np.int64)
            # as detections group them (the priming's own scratch image: detections are grouped meanwhile)
            _, _, label = _front.components_of_pixels(ys, xs, self.height, self.width, 2 * int(p.merge_px) + 1, 1,
                                                      self._prime_index)
            # each group's pixels in scan order, from one stable sort (not one comparison per group)
            order = np.argsort(label, kind="stable")
            cuts = np.searchsorted(label[order], np.arange(int(label.max()) + 2))
            medians = _front.group_medians(typical, order, cuts)
            for k in range(cuts.size - 1):
                sel = order[cuts[k]:cuts[k + 1]]
                wait = max(float(p.prime_confirm_ticks), 2.0 * float(medians[k]))
                self._groups.append((self._step_end(t + 1 + wait), stored[sel], sign, lower[sel], upper[sel], t))

    def _touching(self, s: np.ndarray, px: int, sign: int) -> int:
        """Pixels within ``px`` of the stored pixels ``s`` (not theirs) whose foreground state is ``sign``."""
        r, c = np.divmod(s, self.stored_width)
        y = self.height - 1 - r if self.flip else r
        y0, y1 = max(int(y.min()) - px, 0), min(int(y.max()) + px + 1, self.height)  # the part that can touch
        x0, x1 = max(int(c.min()) - px, 0), min(int(c.max()) + px + 1, self.width)
        mine = np.zeros((y1 - y0, x1 - x0), np.bool_)
        mine[y - y0, c - x0] = True
        fg = self.upright(self.fg)[y0:y1, x0:x1]
        return int((_grown(mine, px) & ~mine & (fg == sign)).sum())

    def _step_end(self, tick: float) -> int:
        """The first end of an output step at or after ``tick`` (a check there adds no evaluation)."""
        return int(math.ceil(tick / self.step_ticks)) * self.step_ticks

    def _confirm(self):
        """Primed groups at their deadline: a group none of whose pixels has changed is static (a bright
        window, a lamp, a dark corner: an object in view moves) and gets its own light back for good.

        A pixel of a brighter group has changed when its interval now lies outside its interval at
        priming (one tick of slack, ×e^``threshold_log``) or it has been silent for longer than that
        allows (the object left it); one of a darker group when an interval ending since the priming is
        shorter than its interval then allowed.
        """
        p = self.parameters
        t = self.next_tick - 1  # the state was evaluated at this tick
        k = math.exp(p.threshold_log)
        due, keep = [g for g in self._groups if g[0] <= self.next_tick], [g for g in self._groups
                                                                          if g[0] > self.next_tick]
        self._groups = keep
        for _, s, sign, lower0, upper0, t0 in due:
            last = self.spk[s, _front.LAST]
            S, N = self.win_span[s].astype(np.float64), self.win_n[s]
            has = N > 0
            lo = np.where(has, (S - 1.0) / np.maximum(N, 1), 0.0)
            hi = np.where(has, (S + 1.0) / np.maximum(N, 1), np.inf)
            silence = t - last
            if sign > 0:
                changed = (has & ((lo > upper0 * k) | (hi * k < lower0))) | (silence - 1.0 > np.maximum(upper0, hi) * k)
            else:
                changed = has & (last > t0) & (hi * k < lower0)
            if changed.sum() > 0.01 * s.size:  # (a stray pixel of a large group is noise)
                continue
            touching = self._touching(s, max(p.merge_px, 1), sign)
            if touching >= p.min_pixels:
                # still, but joined to foreground of the same sign that is not (the part of a long object in
                # view since the start that it has not left, while its front moves on): decided later
                self._groups.append((self._step_end(self.next_tick + p.prime_confirm_ticks), s, sign, lower0, upper0,
                                     t0))
                continue
            if sign > 0:
                self.bg[s] = np.where(has, S / np.maximum(N, 1), 0.5 * (lower0 + upper0))
                self.censored[s] = False
            else:
                self.bg[s] = np.maximum(lower0, np.where(last >= 0, silence, t + 1.0))
                self.censored[s] = True
            self.prev[s] = 0.0
            self.flag_since[s] = -1
            self._given_back[s] = True
            self.word_due[:] = -np.inf

#: A frame pixel counts as changed only beyond this many standard deviations of its own noise.
NOISE_SIGMAS = 4.0
#: ... and is taken for an object in view at the start only beyond this many median absolute
#: deviations of the background's texture around it.
TEXTURE_SIGMAS = 3.0


class FrameChangeDetector:
    """Foreground masks from frames (any unit proportional to light), one per frame.

    The rule of :class:`SpikeChangeDetector` on ln(light): a pixel is foreground where
    |ln(E / background)| > ``threshold_log``; the background follows unflagged pixels with time
    constant ``background_s`` and absorbs pixels flagged for longer than ``hold_s``.

    A frame carries, besides its light, which pixels it measured: a pixel under its noise floor
    or saturated says only that the light is below (or above) some level, and a camera whose
    auto-exposure is still settling delivers frames where many pixels are such. Unmeasured pixels
    are never flagged and never move the background. The background is not learned from one
    frame: it starts from the per-pixel median of the first ``init_frames`` frames that measure at
    least ``prime_measured_fraction`` of the pixels, so no single frame — an auto-exposure start-up, a frame that
    blinked — sets it; the masks of those first frames are given once it is known. Objects in view
    there are primed as for spikes (:func:`prime_background`), a saturated pixel counting as at least
    as bright as its value (a bright object saturates most of its pixels). Primed pixels are grouped
    (touching, brighter and darker than the background apart); a group none of whose pixels changes
    within ``prime_confirm_ticks`` gets its own light back (static texture), and a primed pixel whose
    light has left its starting level and holds still over two frames, nearer the background around
    than that level, has been uncovered: that light is its background. A pixel unmeasured there
    takes the light around it (an object in view) or its first measured light.
    Each pixel also learns its noise (the spread of ln light while it agrees with the background;
    at first its spread over those frames, at least the typical one): a change must exceed
    :data:`NOISE_SIGMAS` standard deviations too, so the quantization of dim 8-bit pixels is not
    read as motion. A frame that reads fewer than ``prime_measured_fraction`` of its pixels
    (measured, or saturated: at least their value) gives an empty mask; a sunlit window that
    saturates does not blind the camera to the rest of the frame.

    Parameters
    ----------
    background_s, hold_s : float
        Time constant of the background and time after which a change is absorbed, s.
    parameters : TrackerParameters, optional
    floor : float
        Smallest light kept (same unit as the frames): it keeps the logarithm finite in the dark.
    init_frames : int
        Frames the starting background is the median of.
    """

    def __init__(self, background_s: float, hold_s: float, parameters: TrackerParameters | None = None,
                 floor: float = 1e-3, init_frames: int = 3):
        self.parameters = parameters or TrackerParameters()
        self.background_s = check_positive("background_s", background_s)
        self.hold_s = check_positive("hold_s", hold_s)
        self.floor = check_positive("floor", floor)
        self.init_frames = check_int("init_frames", init_frames, 1)
        self.ref = None
        self.known = None
        self.flag_since = None
        self.last_t = None
        self._pending = []  # frames seen before the background is known: (log light, measured, t, saturated)
        self._group = None  # primed groups still to confirm (labels), their light before priming, which moved
        self.confirm_s = self.parameters.prime_confirm_ticks * self.hold_s / self.parameters.hold_ticks

    def feed(self, frame: np.ndarray, t_s: float, measured: np.ndarray | None = None,
             saturated: np.ndarray | None = None) -> list[np.ndarray]:
        """One frame (H, W) seen at ``t_s``.

        ``measured``: its pixels with a measurement (default all); ``saturated``: pixels whose
        light is at least the frame's value (a saturated pixel is brighter than a background
        below that, and never moves it). Returns the foreground masks now decided, in order: none
        while the starting background is gathered, then those of every frame held back, then one
        per frame.
        """
        cur = np.log(np.maximum(np.asarray(frame, dtype=np.float64), self.floor))
        ok = np.ones(cur.shape, bool) if measured is None else np.asarray(measured, bool)
        sat = np.zeros(cur.shape, bool) if saturated is None else np.asarray(saturated, bool)
        ok = ok & ~sat
        if self.ref is None:
            self._pending.append((cur, ok, float(t_s), sat))
            usable = [f for f in self._pending if (f[1] | f[3]).mean() >= self.parameters.prime_measured_fraction]
            if len(usable) < self.init_frames:
                return []
            self._start(usable)
            held, self._pending = self._pending, []
            return [self._step(*f) for f in held]
        return [self._step(cur, ok, float(t_s), sat)]

    def finish(self) -> list[np.ndarray]:
        """The masks of frames still held back when the frames end (the background from what was seen)."""
        if self.ref is not None or not self._pending:
            return []
        usable = [f for f in self._pending if (f[1] | f[3]).mean() >= self.parameters.prime_measured_fraction]
        self._start(usable or self._pending)
        held, self._pending = self._pending, []
        return [self._step(*f) for f in held]

    def _start(self, frames):
        stack = np.stack([np.where(f[1], f[0], np.nan) for f in frames])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # pixels never measured: all-NaN
            ref = np.nanmedian(stack, axis=0)
            # what each pixel showed, saturated values included (lower bounds of their light)
            seen = np.nanmedian(np.stack([np.where(f[1] | f[3], f[0], np.nan) for f in frames]), axis=0)
        self.known = np.isfinite(ref)
        self.ref = np.where(self.known, ref, 0.0)
        # each pixel's noise (ln light): its spread over those frames, at least the typical one
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            var = np.nanmean((stack - ref) ** 2, axis=0)
        typical = float(np.nanmedian(var)) if np.isfinite(var).any() else 0.0
        self.var = np.where(np.isfinite(var), np.maximum(var, typical), typical)
        noise = NOISE_SIGMAS * math.sqrt(typical)  # (a pixel's own spread over the frames counts motion too)
        self.flag_since = np.full(ref.shape, np.nan)
        self.last_t = frames[0][2]
        p = self.parameters
        if p.prime_ticks > 0 and self.known.any():  # objects in view: the background around them, as for spikes
            # a saturated pixel is at least as bright as its value: one that stands out above the background
            # around is on an object for sure (a bright object in view saturates most of its pixels, and seen
            # only through its unsaturated edges it would be learned as background and leave a ghost)
            shown = np.isfinite(seen)
            seen = np.where(self.known, self.ref, np.where(shown, seen, 0.0))
            primed, _, around, weight = prime_background(seen, self.known | shown, max(p.prime_threshold_log, noise),
                                                        p.prime_window_px, p.threshold_log, weights=True,
                                                        min_pixels=p.min_pixels, texture_sigmas=TEXTURE_SIGMAS)
            # an object in view moves: a group of primed pixels none of which changes within confirm_s is
            # background after all (static texture the image shows strongly), and gets its own light back
            if primed.any():
                # groups of touching pixels, brighter and darker than the background apart (a dark strip of
                # background beside a bright object in view is not that object, and it does not move)
                self._group = np.full(primed.shape, -1, np.int64)
                n = 0
                for part in (primed & (seen > around), primed & (seen <= around)):
                    if part.any():
                        ys, xs = np.nonzero(part)
                        _, _, label = _components_of_mask(part, 0, 1)  # touching pixels only
                        self._group[ys, xs] = label + n
                        n += int(label.max()) + 1
                self._moved = np.zeros(n, bool)
                self._prior = seen  # (saturated pixels: their lower bound)
                self._around = around
                self._last = None  # the previous frame (log light, measured)
                self._confirm_at = self.last_t + self.confirm_s
            self.ref[primed] = around[primed]
            # pixels never measured (saturated, or under the floor, on an object in view): the background around
            fill = ~self.known & (primed | (weight > 0.5))
            self.ref[fill] = around[fill]
            self.known |= fill

    def _confirm(self, cur, ok, t_s, limit):
        """Primed pixels: note the groups that changed; past ``confirm_s``, give the still ones their own light
        back; a primed pixel whose light has left its starting level and holds still (two frames alike) nearer
        the background around it than that level has been uncovered: that light is its background."""
        g = self._group
        moved = ok & (g >= 0) & (np.abs(cur - self._prior) > limit)
        self._moved[g[moved]] = True
        steady = np.zeros_like(moved) if self._last is None else self._last[1] & (np.abs(cur - self._last[0]) < limit)
        uncovered = moved & steady & (np.abs(cur - self._around) < np.abs(cur - self._prior))
        self._last = (cur, ok)
        self.ref[uncovered] = cur[uncovered]
        self.flag_since[uncovered] = np.nan
        g[uncovered] = -1
        if self._confirm_at is not None and t_s >= self._confirm_at:
            still = (g >= 0) & ~self._moved[np.maximum(g, 0)]
            self.ref[still] = self._prior[still]
            self.flag_since[still] = np.nan
            g[still] = -1
            self._confirm_at = None
        if not (g >= 0).any():
            self._group = None

    def _step(self, cur, ok, t_s, sat):
        if (ok | sat).mean() < self.parameters.prime_measured_fraction:
            # a frame that measures too few pixels (auto-exposure still settling): nothing is read from it
            return np.zeros(cur.shape, bool)
        new = ok & ~self.known  # first measurement of a pixel unmeasured so far: its background
        self.ref[new] = cur[new]
        self.known |= new
        # beyond the change threshold and beyond the pixel's own noise (NOISE_SIGMAS standard deviations)
        limit = np.maximum(self.parameters.threshold_log, NOISE_SIGMAS * np.sqrt(self.var))
        if self._group is not None:
            self._confirm(cur, ok, t_s, limit)
        d = cur - self.ref
        flagged = ok & ~new & (np.abs(d) > limit)
        flagged |= sat & self.known & (d > limit)  # at least that bright
        self.flag_since[flagged & np.isnan(self.flag_since)] = t_s
        self.flag_since[ok & ~flagged] = np.nan
        gain = 1.0 - math.exp(-max(t_s - self.last_t, 0.0) / self.background_s)
        update = ok & ~new & (~flagged | (t_s - np.nan_to_num(self.flag_since, nan=t_s) > self.hold_s))
        quiet = update & ~flagged
        self.var[quiet] += gain * (d[quiet] ** 2 - self.var[quiet])
        self.ref[update] += gain * d[update]
        self.last_t = max(self.last_t, t_s)
        return flagged


# --------------------------------------------------------------------------- start-up background

_PRIME_BLOCK_PX = 8  # the start-up background is computed on blocks of 8×8 px (the background is smooth)


def _blocks(a: np.ndarray, fill=None, block: int = _PRIME_BLOCK_PX) -> np.ndarray:
    """(H, W) → (H/b, W/b, b²) blocks of b × b px (edges padded with ``fill``, or the edge values)."""
    H, W = a.shape
    b = block
    hb, wb = -(-H // b), -(-W // b)
    if fill is None:
        pad = np.pad(a, ((0, hb * b - H), (0, wb * b - W)), mode="edge")
    else:
        pad = np.full((hb * b, wb * b), fill, dtype=np.result_type(a.dtype, np.asarray(fill).dtype))
        pad[:H, :W] = a
    return pad.reshape(hb, b, wb, b).transpose(0, 2, 1, 3).reshape(hb, wb, b * b)


def _block_counts(mask: np.ndarray, block: int = _PRIME_BLOCK_PX) -> np.ndarray:
    """Set pixels of a bool (H, W) image per b × b block (hb, wb), float64 (whole numbers: exact in any order)."""
    H, W = mask.shape
    hb, wb = -(-H // block), -(-W // block)
    pad = np.zeros((hb * block, wb * block), np.uint8)
    pad[:H, :W] = mask
    return pad.reshape(hb, block, wb, block).sum(axis=(1, 3), dtype=np.int64).astype(np.float64)


def _nearest(blocks: np.ndarray, H: int, W: int, block: int = _PRIME_BLOCK_PX) -> np.ndarray:
    """Block values (hb, wb) of b × b px back to pixels, each pixel its block's value."""
    return blocks[np.arange(H) // block][:, np.arange(W) // block]


def _grown(mask: np.ndarray, px: int = 2) -> np.ndarray:
    """``mask`` grown by ``px`` in every direction (a (2·px + 1)² maximum filter, on the part that holds it)."""
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    out = np.zeros_like(mask)
    if rows.size:
        r0, r1 = max(rows[0] - px, 0), min(rows[-1] + px + 1, mask.shape[0])
        c0, c1 = max(cols[0] - px, 0), min(cols[-1] + px + 1, mask.shape[1])
        # a contiguous copy of the part: one compiled form whatever the part's layout
        out[r0:r1, c0:c1] = _front.dilate_square(np.ascontiguousarray(mask[r0:r1, c0:c1]), px)
    return out


def _upsample(blocks: np.ndarray, H: int, W: int) -> np.ndarray:
    """Block values (hb, wb) back to pixels, bilinear between block centres."""
    b = _PRIME_BLOCK_PX

    def axis(n, nb):
        u = np.clip((np.arange(n) + 0.5) / b - 0.5, 0.0, nb - 1.0)
        i0 = np.minimum(np.floor(u).astype(np.intp), nb - 1)
        i1 = np.minimum(i0 + 1, nb - 1)
        return i0, i1, u - i0

    y0, y1, fy = axis(H, blocks.shape[0])
    x0, x1, fx = axis(W, blocks.shape[1])
    rows = blocks[y0] * (1 - fy)[:, None] + blocks[y1] * fy[:, None]
    # the full-size blend in one compiled pass (the same two products and sum per pixel, exactly)
    return _front.blend_columns(np.ascontiguousarray(rows, np.float64), x0, x1, 1 - fx, fx)


def _robust_background(log_light: np.ndarray, valid: np.ndarray, window_px: int) -> np.ndarray:
    """Median of ``log_light`` over valid pixels in a ``window_px`` square around each pixel, per 8×8 block."""
    blocks = _blocks(np.where(valid, log_light, np.nan), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN blocks: filled below
        med = np.nanmedian(blocks, axis=2)
    fill = np.nanmedian(med) if np.isfinite(med).any() else 0.0
    med = np.where(np.isfinite(med), med, fill)
    size = max(1, window_px // _PRIME_BLOCK_PX) | 1  # odd, in blocks
    return median_filter(med, size=size, mode="nearest")


def _interpolate_clear(values: np.ndarray, clear: np.ndarray, window_px: int, also=None):
    """Normalised Gaussian smoothing (σ = ``window_px``/8) of ``values`` over the ``clear`` pixels.

    Works on 8×8 blocks (sums and counts), so it costs a fraction of a full-resolution filter;
    returns the smoothed values (bilinear between blocks) and the weight (Gaussian fraction of
    clear pixels, 0 … 1) per pixel, and with ``also`` (a bool image) the clear-weighted fraction
    of its pixels around each pixel (per block).
    """
    H, W = values.shape
    return tuple(v if k == 0 else _nearest(v, H, W)
                 for k, v in enumerate(_interpolate_clear_blocks(values, clear, window_px, also)))


def _interpolate_clear_blocks(values: np.ndarray, clear: np.ndarray, window_px: int, also=None):
    """:func:`_interpolate_clear` with the weight (and the fraction of ``also``) per 8×8 block, not per pixel."""
    H, W = values.shape
    # per 8×8 block, in one compiled pass: the sum over the clear pixels (as NumPy's sum of the padded blocks,
    # exactly), the clear pixels, and those also ``also``
    total, n, n_also = _front.clear_block_sums(np.ascontiguousarray(values, np.float64),
                                               np.ascontiguousarray(clear, np.bool_),
                                               np.ascontiguousarray(clear if also is None else also, np.bool_))
    sigma = max(window_px / 8.0 / _PRIME_BLOCK_PX, 0.5)
    weight = gaussian_filter(n, sigma, mode="nearest")
    smooth = gaussian_filter(total, sigma, mode="nearest")
    level = np.where(weight > 1e-3, smooth / np.maximum(weight, 1e-3), np.nan)
    if np.isfinite(level).any():
        level = np.where(np.isfinite(level), level, np.nanmedian(level))
    else:
        level = np.zeros_like(level)
    out = (_upsample(level, H, W), weight / _PRIME_BLOCK_PX ** 2)
    if also is not None:
        part = gaussian_filter(n_also, sigma, mode="nearest")
        out += (part / np.maximum(weight, 1e-9),)
    return out


def _opened(mask: np.ndarray) -> np.ndarray:
    """``mask`` without the parts narrower than 3 px once its gaps are closed (lines, specks of texture)."""
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    out = np.zeros_like(mask)
    if rows.size == 0:
        return out
    r0, r1 = max(rows[0] - 3, 0), min(rows[-1] + 4, mask.shape[0])  # only the part that holds the mask
    c0, c1 = max(cols[0] - 3, 0), min(cols[-1] + 4, mask.shape[1])
    out[r0:r1, c0:c1] = _front.opened_closed(np.ascontiguousarray(mask[r0:r1, c0:c1]))  # one compiled form
    return out


def prime_background(log_light: np.ndarray, valid: np.ndarray, threshold_log, window_px: int,
                    unsure_log: float | None = None, weights: bool = False, min_pixels: int = 1,
                    texture_sigmas: float = 0.0):
    """Objects in view at the start: pixels that stand out from the background around them, and that background.

    A change detector that learns its background from the first light it sees learns the objects
    already in view as background: they stay invisible until they move off and leave a "ghost"
    where they stood. Assuming the background is smoother than the objects on it, a pixel more
    than ``threshold_log`` from the median of ln(light) over ``window_px`` px (wider than twice
    any object) is on an object (*primed*). The background under and near it is then
    interpolated from the pixels around that are not primed (normalised Gaussian smoothing,
    σ = ``window_px``/8, on 8×8-px blocks: the local background, not the window's median),
    which is what the pixel shows once the object has moved off.

    Parameters
    ----------
    log_light : ndarray (H, W)
        ln of the light (or of the spike interval, its inverse: the test is symmetric).
    valid : ndarray (H, W) bool
        Pixels with a measurement (spike pixels that have no interval yet are left out).
    threshold_log : float or ndarray (H, W)
        How far from the median around (|ln ratio|) marks a pixel: one value, or one per pixel
        (beyond its own noise).
    window_px : int
    unsure_log : float, optional
        Pixels not primed but more than this from the local background are returned as *unsure*.
    min_pixels : int
        Smallest object: marked groups of fewer pixels (within 5 px of each other) are left alone.
    texture_sigmas : float
        With > 0, a pixel must also stand out by this many times the median absolute deviation
        of ln light around it (a background whose texture an image shows strongly — the coarse
        steps of a dim 8-bit frame — is not taken for objects).

    Returns
    -------
    primed, unsure : ndarray (H, W) bool
    background : ndarray (H, W) float
        The estimated ln(light) of the background (same unit as ``log_light``).
    weight : ndarray (H, W) float
        With ``weights``: the Gaussian-weighted fraction of clear measured pixels the background
        was interpolated from (0 … 1).
    """
    window_px = check_int("window_px", window_px, 1)
    H, W = log_light.shape
    coarse = _upsample(_robust_background(log_light, valid, window_px), H, W)
    deviation = np.abs(log_light - coarse)
    if texture_sigmas:  # beyond the background's own texture: its median absolute deviation around
        spread = _upsample(_robust_background(deviation, valid, window_px), H, W)
        threshold_log = np.maximum(threshold_log, texture_sigmas * spread)
    # objects are ≥ 3 px across and hold at least min_pixels (specks of texture are not objects)
    primed = _opened(valid & (deviation > threshold_log))
    if min_pixels > 1 and primed.any():
        ys, xs = np.nonzero(primed)
        _, counts, label = _components_of_mask(primed, 2, 1)
        primed[ys[counts[label] < min_pixels], xs[counts[label] < min_pixels]] = False
    # the local background from the pixels that are not on an object (their anti-aliased edges excluded)
    clear = valid & ~_grown(primed)
    background, weight = _interpolate_clear(log_light, clear, window_px)
    background = np.where(weight > 1e-3, background, coarse)
    unsure = np.zeros_like(primed)
    if unsure_log is not None:
        unsure = valid & ~primed & (np.abs(log_light - background) > unsure_log)
    return (primed, unsure, background, weight) if weights else (primed, unsure, background)


# --------------------------------------------------------------------------- grouping

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
    mask = np.asarray(mask, dtype=np.bool_)
    if mask.ndim != 2:
        raise ViformError(f"mask must be 2-D (H, W); got shape {mask.shape}")
    boxes, counts, _ = _components_of_mask(mask, merge_px, min_pixels)
    return boxes, counts


def _components_of_mask(mask, merge_px, min_pixels):
    ys, xs = np.nonzero(mask)  # scan order
    index = np.full(mask.shape, -1, np.int64)
    return _front.components_of_pixels(ys.astype(np.int64), xs.astype(np.int64), mask.shape[0], mask.shape[1],
                                       2 * check_int("merge_px", merge_px, 0) + 1,
                                       check_int("min_pixels", min_pixels, 1), index)


def _intersection(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Area of the intersection of every box of ``a`` (N, 4) with every box of ``b`` (M, 4), (x, y, w, h)."""
    return _front.box_overlaps(np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64), False)


def iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union of every box of ``a`` (N, 4) with every box of ``b`` (M, 4), (x, y, w, h)."""
    a = np.ascontiguousarray(np.asarray(a, np.float64).reshape(-1, 4))
    b = np.ascontiguousarray(np.asarray(b, np.float64).reshape(-1, 4))
    return _front.box_overlaps(a, b, True)


# --------------------------------------------------------------------------- association

_TRAIL = 24  # measured centres kept per track (for its velocity) ...
_TRAIL_SPACING_TICKS = 10  # ... at least this far apart (24 of them span 240 ticks or more)


@dataclass
class _Track:
    track_id: int
    cx: float  # centre (px) at last_t
    cy: float
    vx: float  # px/s
    vy: float
    w: float  # size, px
    h: float
    last_t: float
    last_seen_t: float
    hits: int = 1
    confirmed: bool = False
    merged: bool = False
    trail_t: np.ndarray = field(default_factory=lambda: np.zeros(_TRAIL))
    trail_x: np.ndarray = field(default_factory=lambda: np.zeros(_TRAIL))
    trail_y: np.ndarray = field(default_factory=lambda: np.zeros(_TRAIL))
    n_trail: int = 0

    def box_at(self, t_s: float) -> np.ndarray:
        return np.array(self.box_tuple(t_s))

    def box_tuple(self, t_s: float) -> tuple[float, float, float, float]:
        """The predicted box (x, y, w, h) at ``t_s``: the last centre moved at the fitted velocity."""
        dt = t_s - self.last_t
        cx, cy = self.cx + self.vx * dt, self.cy + self.vy * dt
        return cx - self.w / 2, cy - self.h / 2, self.w, self.h

    def add(self, t_s: float, cx: float, cy: float, spacing_s: float = 0.0) -> None:
        """Keep a measured centre; one closer than ``spacing_s`` to the one before replaces it (the trail
        spans the same time whatever the output step)."""
        if self.n_trail >= 2 and t_s - self.trail_t[(self.n_trail - 2) % _TRAIL] < spacing_s:
            self.n_trail -= 1
        k = self.n_trail % _TRAIL
        self.trail_t[k], self.trail_x[k], self.trail_y[k] = t_s, cx, cy
        self.n_trail += 1


class Tracker:
    """Tracks of detections: predicted boxes, Hungarian assignment, birth and death with hysteresis.

    Each track predicts its box at the next step from its last measured centre and a velocity
    fitted to its recent measured centres (Theil–Sen: the median of the velocities between pairs
    of them, so a few jumps of the box — an object entering, foreground growing — do not throw
    it). Detections are assigned to predictions by the Hungarian method
    (``scipy.optimize.linear_sum_assignment``) on 1 − IoU, with a centre-distance fallback for
    small fast objects. Before that, a detection holding the predictions of several tracks is
    split and pieces inside one prediction are joined (:meth:`_regroup`).

    Parameters
    ----------
    parameters : TrackerParameters
    tick_s : float
        Duration of a tick, s (turns ``max_coast_ticks`` into seconds).
    """

    def __init__(self, parameters: TrackerParameters | None = None, tick_s: float = 1 / 40_000):
        self.parameters = parameters or TrackerParameters()
        self.tick_s = check_positive("tick_s", tick_s)
        self.tracks: list[_Track] = []
        self.next_id = 1

    def update(self, boxes: np.ndarray, t_s: float, pixels=None, counts=None) -> list[tuple[int, np.ndarray]]:
        """One step: detections seen at ``t_s``; returns [(track id, box)] reported now.

        Parameters
        ----------
        boxes : ndarray (N, 4)
            Detections (x, y, w, h), px: with ``counts``, every connected component of the step's
            foreground, those under ``min_pixels`` only as pieces a track may join.
        t_s : float
            The step's instant, s.
        pixels : tuple (ys, xs, component), optional
            The foreground pixels and the component each belongs to. With them, a component
            holding the predictions of several tracks is split between them (:meth:`_regroup`).
        counts : ndarray (N,), optional
            Foreground pixels of each component (default: every box is a detection, counted by its
            area). A new track on at least ``confirm_pixels`` of them is confirmed at once.
        """
        p = self.parameters
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        counts = boxes[:, 2] * boxes[:, 3] if counts is None else np.asarray(counts, np.float64).ravel()
        predicted = np.array([tr.box_tuple(t_s) for tr in self.tracks], np.float64).reshape(-1, 4)
        boxes, counts, forced, merged = self._regroup(boxes, counts, pixels, predicted, t_s)
        matches = list(forced.items())
        unmatched = set(range(len(boxes))) - set(forced.values())
        free_tracks = [i for i in range(len(self.tracks)) if i not in forced and i not in merged]
        free_boxes = sorted(unmatched)
        if free_tracks and free_boxes:
            # 1 − IoU where a prediction and a detection overlap, else 1 + their centre distance over the reach
            # (the mean of their diagonals plus gate_px); never past the reach (compiled, exact)
            cost = _front.assignment_cost(np.ascontiguousarray(predicted[free_tracks]),
                                          np.ascontiguousarray(boxes[free_boxes]), float(p.gate_px))
            rows, cols = linear_sum_assignment(cost)
            for a, b in zip(rows, cols, strict=True):
                if cost[a, b] < 1e6:
                    matches.append((free_tracks[a], free_boxes[b]))
                    unmatched.discard(free_boxes[b])
        reported = []
        matched_tracks = set()
        for i, j in matches:
            track = self.tracks[i]
            self._correct(track, boxes[j], t_s)
            matched_tracks.add(i)
            if track.confirmed or track.hits >= p.min_hits:
                track.confirmed = True
                reported.append((track.track_id, boxes[j].copy()))
        for i, track in enumerate(self.tracks):
            if i in merged and not track.merged and track.n_trail >= 3:
                track.vx, track.vy = _trail_velocity(track)
            track.merged = i in merged
        for i in sorted(merged):  # inside another object's foreground: reported where predicted
            track = self.tracks[i]
            track.last_seen_t = t_s
            if p.report_merged:
                reported.append((track.track_id, predicted[i].copy()))
        if p.merged_keep_alive and matches:
            # a confirmed track without a detection whose prediction lies inside another track's detection
            # is merged with (or hidden by) that object: it coasts on as long as that lasts
            matched_boxes = boxes[[j for _, j in matches]]
            idle = [i for i, tr in enumerate(self.tracks) if i not in matched_tracks and tr.confirmed]
            if idle:
                pb = predicted[idle]
                inside = _intersection(pb, matched_boxes) / np.maximum(pb[:, 2] * pb[:, 3], 1e-9)[:, None]
                for i in np.asarray(idle)[inside.max(axis=1) >= 0.5]:
                    self.tracks[i].last_seen_t = t_s  # not reported: its box is a prediction, not a measurement
        coast_s = p.max_coast_ticks * self.tick_s
        self.tracks = [tr for i, tr in enumerate(self.tracks)
                       if i in matched_tracks or (tr.confirmed and t_s - tr.last_seen_t <= coast_s)]
        for j in sorted(unmatched):
            if counts[j] < p.min_pixels:
                continue
            b = boxes[j]
            track = _Track(self.next_id, b[0] + b[2] / 2, b[1] + b[3] / 2, 0.0, 0.0, b[2], b[3], t_s, t_s)
            track.add(t_s, track.cx, track.cy)
            self.next_id += 1
            self.tracks.append(track)
            if p.min_hits <= 1 or counts[j] >= p.confirm_pixels:  # a large detection is no noise
                track.confirmed = True
                reported.append((track.track_id, b.copy()))
        return reported

    def _regroup(self, boxes, counts, pixels, predicted, t_s):
        """Split components that hold several tracks' predictions; join pieces inside one track's prediction.

        Only confirmed tracks seen within ``max_coast_ticks`` take part. A component covering at
        least half of the predicted boxes of two or more of them (an object passing in front of
        another merges their foreground) is measured for the largest of them (the occluder, or
        what the others cross) without the pixels that lie only inside the others' predictions;
        the others go on at their predictions (a box measured from shared pixels would drag a
        partly hidden object along with its occluder). Pieces of foreground that lie mostly
        (≥ 60 % of their box) inside one track's predicted box and inside no other's are joined
        into one detection for it, within that box (a textured or partly hidden object whose
        foreground breaks up). Components under ``min_pixels`` that join nothing are dropped.

        Returns the detections' boxes and pixel counts, {track index: detection index} for the
        detections made for a track, and the set of tracks that go on at their predictions.
        """
        p = self.parameters
        big = counts >= p.min_pixels
        coast_s = p.max_coast_ticks * self.tick_s
        live = np.array([i for i, tr in enumerate(self.tracks) if tr.confirmed and t_s - tr.last_seen_t <= coast_s],
                        np.int64)
        if live.size == 0 or len(boxes) == 0:
            return boxes[big], counts[big], {}, set()
        n_comp = len(boxes)
        grow = float(p.merge_px)
        # in one compiled pass (exact): how much of each live prediction (grown by merge_px) each component covers,
        # with a track held only by the component that matches its prediction best (a large sparse component
        # whose box spans a track that has a detection of its own does not swallow it); how much of each
        # component lies inside each prediction; and the components holding two or more predictions
        cover, inside, multi = _front.regroup_tables(np.ascontiguousarray(boxes), np.ascontiguousarray(counts),
                                                     np.ascontiguousarray(predicted), live, grow,
                                                     float(p.min_pixels), pixels is not None)
        out_boxes, out_counts, forced, merged = [], [], {}, set()
        used = np.zeros(n_comp, bool)
        taken = set()
        if multi.size:
            pred = predicted[live]  # the grown predictions
            pred[:, :2] -= grow
            pred[:, 2:] += 2 * grow
            ys, xs, comp = pixels
        for j in multi:
            holders = [h for h in np.nonzero(cover[j] >= 0.5)[0] if live[h] not in taken]
            if len(holders) < 2:
                continue
            used[j] = True
            sel = comp == j
            px, py = xs[sel] + 0.5, ys[sel] + 0.5
            hb = pred[holders]
            member = ((px[:, None] >= hb[None, :, 0]) & (px[:, None] < hb[None, :, 0] + hb[None, :, 2])
                      & (py[:, None] >= hb[None, :, 1]) & (py[:, None] < hb[None, :, 1] + hb[None, :, 3]))
            primary = int(np.argmax(hb[:, 2] * hb[:, 3]))
            own = member[:, primary] | ~member.any(axis=1)
            for k, h in enumerate(holders):
                taken.add(int(live[h]))
                if k != primary:
                    merged.add(int(live[h]))
            if own.any():
                x0, y0 = px[own].min() - 0.5, py[own].min() - 0.5
                forced[int(live[holders[primary]])] = len(out_boxes)
                out_boxes.append((x0, y0, px[own].max() + 0.5 - x0, py[own].max() + 0.5 - y0))
                out_counts.append(float(own.sum()))
        # pieces inside one track's prediction only (compiled, exact); one piece alone in a prediction, large
        # enough, is an ordinary detection (-1)
        owner = _front.regroup_owner(inside, used, np.ascontiguousarray(counts), float(p.min_pixels))
        owned = owner[owner >= 0]
        for h in np.unique(owned) if owned.size else ():
            if int(live[h]) in taken:
                owner[owner == h] = -1
                continue
            parts = np.nonzero(owner == h)[0]
            size = counts[parts].sum()
            if len(parts) < 2 and size >= p.min_pixels:
                owner[parts] = -1  # one piece, large enough: an ordinary detection
                continue
            if size < p.min_pixels:
                continue  # (dropped with the other small pieces)
            pb = boxes[parts]
            g = predicted[live[h]]  # the union, within the prediction (pieces may hang over it)
            x0, y0 = max(pb[:, 0].min(), g[0]), max(pb[:, 1].min(), g[1])
            x1 = min((pb[:, 0] + pb[:, 2]).max(), g[0] + g[2])
            y1 = min((pb[:, 1] + pb[:, 3]).max(), g[1] + g[3])
            forced[int(live[h])] = len(out_boxes)
            taken.add(int(live[h]))
            out_boxes.append((x0, y0, x1 - x0, y1 - y0))
            out_counts.append(float(size))
            used[parts] = True
        rest = ~used & (owner < 0) & big
        boxes_out = np.concatenate([np.array(out_boxes, np.float64).reshape(-1, 4), boxes[rest]])
        counts_out = np.concatenate([np.array(out_counts, np.float64), counts[rest]])
        return boxes_out, counts_out, forced, merged

    def _correct(self, track: _Track, box: np.ndarray, t_s: float) -> None:
        """A measured box: the track's centre is the box's, its velocity refitted, its size smoothed."""
        cx, cy = box[0] + box[2] / 2, box[1] + box[3] / 2
        track.add(t_s, cx, cy, _TRAIL_SPACING_TICKS * self.tick_s)
        track.cx, track.cy, track.last_t = cx, cy, t_s
        if track.n_trail >= 2:
            track.vx, track.vy = _trail_velocity(track)
        track.w, track.h = 0.5 * (track.w + box[2]), 0.5 * (track.h + box[3])
        track.hits += 1
        track.last_seen_t = t_s


def _trail_velocity(track: _Track) -> tuple[float, float]:
    n = min(track.n_trail, _TRAIL)
    return _front.theil_sen(track.trail_t[:n], track.trail_x[:n], track.trail_y[:n])


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
    spike_counts : ndarray (H, W) or None
        Spikes per pixel over the ticks tracked (spike streams; the overlay's background).
    """

    rows: np.ndarray
    times_s: np.ndarray
    step_ticks: int | None
    detections: int
    spike_counts: np.ndarray | None = None


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
    layout = _packed_layout(source)
    detector = SpikeChangeDetector(source.height, source.width, step_ticks, p, *layout)
    tracker = Tracker(p, tick_s=1.0 / source.clock_hz)
    rows, times, n_det = [], [], 0
    block = max(step_ticks, (check_int("block_ticks", block_ticks, 1) // step_ticks) * step_ticks)
    n_usable = (source.n_ticks // step_ticks) * step_ticks

    def associate(steps):
        nonlocal rows, n_det
        for bits in steps:
            frame = len(times) + 1
            t_s = source.start_time_s + frame * step_ticks / source.clock_hz
            boxes, counts, pixels = detector.components(bits, p.merge_px, 1)
            n_det += int(np.count_nonzero(counts >= p.min_pixels))
            reported = tracker.update(boxes, t_s, pixels, counts)
            rows += _rows(frame, reported)
            times.append(t_s)
            if on_step is not None:
                on_step(frame, t_s, detector.mask(bits), reported)

    # closed on the way out, an error included: its read-ahead thread and block do not outlive the call
    with contextlib.closing(_packed_blocks(source, block, n_usable, layout)) as blocks:
        _run_pipeline(detector, blocks, associate, callable(getattr(source, "read_packed", None)))
    return TrackingResult(np.array(rows, np.float64).reshape(-1, 7), np.array(times), step_ticks, n_det,
                          detector.upright(detector.total).copy())


def _run_pipeline(detector, blocks, associate, from_file: bool) -> None:
    """Feed ``blocks`` to ``detector`` and ``associate`` the steps of each, in turn or pipelined."""
    if not (PIPELINE_FRONT_END and from_file):
        for words in blocks:
            associate(detector.feed_words(words))
    else:
        # a file's blocks: the front end (compiled, without the GIL) runs on the next block in a second thread
        # while this block's steps are grouped and associated here; nothing flows back from the association
        # to the front end, so the steps are the same. (A source that simulates or converts its spikes may
        # run parallel kernels of its own: it is read in turn.)
        # numba's thread count is per thread: the front end's thread runs with the caller's
        from concurrent.futures import ThreadPoolExecutor

        from numba import get_num_threads

        threads = get_num_threads()
        with ThreadPoolExecutor(1, thread_name_prefix="viform-front",
                                initializer=_set_numba_threads, initargs=(threads,)) as pool:
            done = None
            for words in blocks:
                running = pool.submit(detector.feed_words, words)
                if done is not None:
                    associate(done)
                done = running.result()
            if done is not None:
                associate(done)


def _set_numba_threads(n: int) -> None:
    from numba import set_num_threads

    set_num_threads(n)


def _packed_layout(source) -> tuple[int, bool]:
    """(stored width, rows bottom-up) of the packed words :func:`_packed_blocks` hands out for ``source``."""
    if callable(getattr(source, "read_packed", None)):
        return int(source.stored_width), bool(source.flip)
    return int(source.width), False


def _packed_blocks(source, block_ticks: int, stop: int, layout):
    """Ticks [0, stop) of ``source`` as packed words (T, n_words) uint64, ``block_ticks`` at a time.

    A ``.dat`` file hands its stored bytes as they are (no unpacking); other sources are packed here.
    """
    from viform.stream.container import block_ticks_for

    direct = callable(getattr(source, "read_packed", None))
    # a block of packed words is an eighth of the unpacked bytes: the reader's budget allows 8× the ticks
    block_ticks = max(1, min(block_ticks, 8 * block_ticks_for(source.height, layout[0], block_ticks)))
    if not direct:
        for first in range(0, stop, block_ticks):
            yield pack_spikes(source.read_ticks(first, min(first + block_ticks, stop)))
        return

    # two buffers of words in turn: a block is read into the one the block before last used, whose front end
    # is done by then (the front end takes block k before block k + 2 is read, whether read ahead or not), so
    # a long stream reuses the same memory (fresh pages cost more than the copy into them here)
    buffers: list = []

    def read(first):
        last = min(first + block_ticks, stop)
        if callable(getattr(source, "read_packed_words", None)):  # the checked bytes copied once, into words
            if len(buffers) < 2:
                buffers.append(np.empty((min(block_ticks, stop), -(-source.frame_bytes // 8)), np.uint64))
            else:
                buffers.append(buffers.pop(0))
            return source.read_packed_words(first, last, out=buffers[-1])
        return _words(source.read_packed(first, last))

    firsts = range(0, stop, block_ticks)
    if not PREFETCH_BLOCKS or len(firsts) < 2:
        for first in firsts:
            yield read(first)
        return
    # a file's next block is read (positioned reads and CRC-32 checks, which release the GIL) while the
    # tracker works on this one: the same blocks in the same order, one more held. The first is read here,
    # so that a warning about the file comes from the caller's thread
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1, thread_name_prefix="viform-read") as pool:
        ahead = None
        for k, first in enumerate(firsts):
            words = read(first) if ahead is None else ahead.result()
            ahead = pool.submit(read, firsts[k + 1]) if k + 1 < len(firsts) else None
            yield words


def track_frames(frames, times_s, parameters: TrackerParameters | None = None, tick_s: float = 1 / 40_000,
                 floor: float = 1e-3, measured=None, saturated=None) -> TrackingResult:
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
    parameters : TrackerParameters, optional
        The tracker's settings (default: the same as :func:`track_spikes`'s).
    tick_s : float
        Length of the spike camera's tick, s: the settings' times in ticks become seconds with it.
    floor : float
        Smallest light kept (same unit as the frames).
    measured, saturated : iterable of ndarray (H, W) bool, optional
        Per frame, the pixels it measured (not under the noise floor) and those saturated (their
        light at least the frame's value); default all measured, none saturated.
        See :class:`FrameChangeDetector`.

    Returns
    -------
    TrackingResult
        MOTChallenge result rows (frame, id, box) and the instant of each frame.
    """
    p = parameters or TrackerParameters()
    times = np.asarray(times_s, np.float64).ravel()
    detector = FrameChangeDetector(p.background_ticks * tick_s, p.hold_ticks * tick_s, p, floor)
    tracker = Tracker(p, tick_s=tick_s)
    rows, n_det = [], 0
    frames = list(frames)
    if len(frames) != times.size:
        raise ViformError(f"{len(frames)} frames were given for {times.size} instants")
    measured = [None] * len(frames) if measured is None else list(measured)
    saturated = [None] * len(frames) if saturated is None else list(saturated)
    if len(measured) != len(frames) or len(saturated) != len(frames):
        raise ViformError(f"{len(measured)} measured and {len(saturated)} saturated masks were given for "
                          f"{len(frames)} frames")
    done = 0

    def track(masks):
        nonlocal done, n_det, rows
        for mask in masks:
            t_s = float(times[done])
            done += 1
            boxes, counts, labels = _components_of_mask(mask, p.merge_px, 1)
            n_det += int(np.count_nonzero(counts >= p.min_pixels))
            ys, xs = np.nonzero(mask)
            rows += _rows(done, tracker.update(boxes, t_s, (ys, xs, labels), counts))

    for image, t_s, ok, sat in zip(frames, times, measured, saturated, strict=True):
        track(detector.feed(image, float(t_s), ok, sat))
    track(detector.finish())
    return TrackingResult(np.array(rows, np.float64).reshape(-1, 7), times, None, n_det)
