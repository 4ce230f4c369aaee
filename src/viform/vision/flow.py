"""Optical flow from a spike stream, scored against a scene's exact truth (seed 000, abstract and §7).

The estimator is classical, so its failures are the sensor's, not a network's. From the
spikes around the two instants t and t + dt:

1. **Images whose time support follows the light.** Each pixel's rate at each instant is the
   multi-interval estimate of :mod:`viform.imaging.multi_interval` (seed 000 §3.3.2: up to K
   spikes on each side, the span growing one interval at a time and stopping at the first
   interval inconsistent with the light so far — so the window is short where the light
   changes, i.e. where something moves past, and long on still light). All instants of a
   call are imaged in **one pass** over the spikes (a ring of each pixel's last 2K spike
   ticks), spikes being looked for at most ``horizon_ticks`` from the instant. Each pixel also
   gets its noise: a span of X ticks holding n intervals of threshold Q has
   var(log rate) ≈ 1/(n·Q) (Gamma arrivals) + 1/(6·X²) (tick rounding at both ends) + 0.02²
   (a floor for pixel-to-pixel gain spread).
2. **Dense flow**: dense inverse search (DIS, Kroeger et al., ECCV 2016, OpenCV's
   ``cv2.DISOpticalFlow``) on both images mapped to one 8-bit scale of log light. With
   ``chain_steps`` > 1 the interval is split, where the flow exceeds ``chain_above_px``, into
   steps whose flows are composed; off by default: DIS's coarse-to-fine search already finds
   large displacements, and composing steps added their errors (textured EPE on the tuning
   scenes: rotating 0.35 chained against 0.20 px; a 24-px translation 0.18 against 0.07).
3. **Layered refinement** (the layered representation of Wang & Adelson, IEEE TIP 3(5), 1994;
   model-based motion as in Bergen et al., ECCV 1992). Uniform regions — a saturated or
   untextured object, whose interior tells nothing about its motion — move as a whole. The
   image at t is cut into regions of similar light (neighbours merged smallest difference
   first, each joining only a region whose mean it matches within the noise, in the spirit of
   Felzenszwalb & Huttenlocher, IJCV 59(2), 2004). Each region whose surroundings changed is
   tested for one motion over a still background: the cost of "this region moved by d, all
   else still" — its pixels compared where they land, the background they uncover unknown, a
   capped (robust) noise-normalized residual — is searched coarse to fine over
   ± ``max_shift_px``; a motion is kept when it lowers the cost by more than
   ``min_gain`` (in units of χ², the squared noise-normalized residual) and leaves less than
   a quarter of its landings unexplained. It is then refined to sub-pixel precision by
   Gauss–Newton (Lucas & Kanade, IJCAI 1981) on lightly smoothed images over the region's rim,
   as an affine motion where that fits significantly better (a rotating blade).
4. **Still background.** Pixels in no moving region whose local change between the two
   images (mean χ² over 5×5) is what the noise gives get zero flow, so the dense flow's
   spill from a moving object does not read as motion of what stands still.
5. **Confidence** per pixel, in [0, 1]: how well the two images resolve the interval —
   min(1, dt / support) for the longer of the two pixel's time supports, times the share of
   the 2K − 1 intervals it found; 0 where a spike was missing (no spike within the horizon).

The result is forward flow in px from t to t + dt, the convention of
:mod:`viform.light.truth` and of flow benchmarks. Scores follow them too: the average endpoint
error (EPE, px) and the KITTI outlier fraction Fl (EPE > 3 px *and* > 5 % of the true flow's
length), over the pixels where the truth is valid; :func:`motion_scores` splits them into the
moving pixels (and each object), with the error relative to the true motion, and the still
background (false motion), each beside the score of predicting zero flow.

Choices made by looking at results were made on the tuning scenes of
``benchmarks/bench_flow.py`` (translating, rotating, multi-object noise seed 0) and are
reported on the others (multi-object seeds 1–2, dilemma, waving-hand).

Files: Middlebury ``.flo`` (what the spike-camera flow sets SPIFT/PHM and SCFlow read: float32
magic 202021.25, width, height, then (H, W, 2) u/v); unknown flow is stored as 1e10, the
format's convention (values above 1e9 mean unknown).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from functools import lru_cache, partial
from pathlib import Path

import numpy as np

from viform._io import atomic_open
from viform._validate import ViformError, check_choice, check_int, check_positive
from viform.light.truth import FlowTruth
from viform.stream.container import spike_bytes

FLO_MAGIC = 202021.25
#: Values above this mean "unknown flow" in a .flo file (Middlebury's UNKNOWN_FLOW_THRESH).
FLO_UNKNOWN_THRESHOLD = 1e9
FLO_UNKNOWN = 1e10
#: Image methods the estimator can use at each instant.
IMAGE_METHODS = ("multi-interval", "interval", "accumulation")
#: DIS presets of OpenCV (speed against accuracy).
DIS_PRESETS = ("ultrafast", "fast", "medium")
#: Refinements after the dense flow: the layered one (module notes, step 3–4) or none.
REFINEMENTS = ("layered", "none")
#: Q assumed for the noise of streams that do not record it (as multi-interval imaging does).
DEFAULT_NOISE_THRESHOLD_ELECTRONS = 1.0e4
#: Relative floor of each pixel's log-light noise (gain spread between pixels, ≈ 2 %).
LOG_NOISE_FLOOR = 0.02
#: True flow above this (px) makes a pixel "moving" in :func:`motion_scores`.
MOVING_ABOVE_PX = 0.5


# ---------------------------------------------------------------------- files

def write_flo(path, flow_px: np.ndarray, valid: np.ndarray | None = None) -> Path:
    """Write forward flow (2, H, W) in px as a Middlebury ``.flo`` file (atomically).

    Pixels where ``valid`` is False (or the flow is not finite) are stored as unknown (1e10).

    Parameters
    ----------
    path : str or Path
        The ``.flo`` file to write.
    flow_px : ndarray (2, H, W)
        Forward flow, px (x, y).
    valid : ndarray of bool (H, W), optional
        Where the flow is known (default: where it is finite).

    Returns
    -------
    Path
        The file written.
    """
    flow = np.asarray(flow_px, dtype=np.float64)
    if flow.ndim != 3 or flow.shape[0] != 2:
        raise ViformError(f"flow must have shape (2, H, W); got {flow.shape}")
    known = np.all(np.isfinite(flow), axis=0)
    if valid is not None:
        known &= np.asarray(valid, bool)
    data = np.where(known[..., None], np.moveaxis(flow, 0, -1), FLO_UNKNOWN).astype("<f4")
    height, width = known.shape
    with atomic_open(path, "wb") as f:
        f.write(struct.pack("<fii", FLO_MAGIC, width, height))
        f.write(data.tobytes())
    return Path(path)


def read_flo(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a Middlebury ``.flo`` file: (flow (2, H, W) float32 px with NaN where unknown, valid (H, W)).

    Parameters
    ----------
    path : str or Path
        The ``.flo`` file.

    Returns
    -------
    flow_px : ndarray of float32 (2, H, W)
        Forward flow, px; NaN where unknown.
    valid : ndarray of bool (H, W)
        Where the flow is known.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ViformError(f"flow file {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    if len(raw) < 12:
        raise ViformError(f"flow file {str(path)!r} is too short for a .flo header")
    magic, width, height = struct.unpack("<fii", raw[:12])
    if magic != FLO_MAGIC:
        raise ViformError(f"flow file {str(path)!r} is not a .flo file (magic {magic!r}, expected {FLO_MAGIC})")
    if not (0 < width <= 1 << 16 and 0 < height <= 1 << 16) or len(raw) != 12 + 8 * width * height:
        raise ViformError(f"flow file {str(path)!r}: header says {width}×{height} px, which does not match its "
                          f"{len(raw)} bytes")
    data = np.frombuffer(raw, "<f4", offset=12).reshape(height, width, 2)
    valid = np.all(np.abs(data) <= FLO_UNKNOWN_THRESHOLD, axis=-1)
    flow = np.moveaxis(data, -1, 0).astype(np.float32)
    flow[:, ~valid] = np.nan
    return flow, valid


# ---------------------------------------------------------------------- scores

@dataclass
class FlowScores:
    """Endpoint error against truth over ``pixels`` scored pixels.

    Attributes
    ----------
    epe_px : float
        Average endpoint error, px.
    fl_outliers : float
        KITTI Fl: fraction of pixels with EPE > 3 px and > 5 % of the true flow's length.
    pixels : int
        Pixels scored (valid truth inside the mask).
    true_flow_px : float
        Mean length of the true flow over them, px.
    """

    epe_px: float
    fl_outliers: float
    pixels: int
    true_flow_px: float

    @property
    def relative_error(self) -> float:
        """EPE as a share of the true flow's mean length (1.0: no better than zero flow); NaN if it is 0."""
        return self.epe_px / self.true_flow_px if self.true_flow_px > 0 else math.nan

    def as_dict(self) -> dict:
        return {"epe_px": self.epe_px, "fl_outliers": self.fl_outliers, "pixels": self.pixels,
                "true_flow_px": self.true_flow_px,
                "relative_error": self.relative_error if math.isfinite(self.relative_error) else None}


def flow_scores(estimate_px: np.ndarray, truth: FlowTruth, mask: np.ndarray | None = None) -> FlowScores:
    """EPE and Fl of an estimated flow (2, H, W) against :class:`~viform.light.truth.FlowTruth`.

    Parameters
    ----------
    estimate_px : ndarray (2, H, W)
        Estimated forward flow, px.
    truth : FlowTruth
        The exact flow between the same instants.
    mask : ndarray (H, W) of bool, optional
        Pixels to score.

    Returns
    -------
    FlowScores
        Average endpoint error (px), KITTI Fl outlier fraction and the pixels scored.
    """
    estimate = np.asarray(estimate_px, dtype=np.float64)
    if estimate.shape != truth.flow_px.shape:
        raise ViformError(f"estimated flow {estimate.shape} and truth {truth.flow_px.shape} differ in shape")
    use = truth.valid & np.all(np.isfinite(estimate), axis=0)
    if mask is not None:
        use &= np.asarray(mask, bool)
    if not use.any():
        return FlowScores(math.nan, math.nan, 0, math.nan)
    error = np.hypot(*(estimate[:, use] - truth.flow_px[:, use]))
    length = np.hypot(*truth.flow_px[:, use])
    outliers = (error > 3.0) & (error > 0.05 * length)
    return FlowScores(float(error.mean()), float(outliers.mean()), int(use.sum()), float(length.mean()))


def textured_mask(lux: np.ndarray, window_px: int = 7, min_log_contrast: float = 0.02,
                  margin_px: int = 0) -> np.ndarray:
    """Pixels where the light has texture a patch matcher can lock on to.

    True where the standard deviation of log10(lux) over a ``window_px`` square exceeds
    ``min_log_contrast`` (0.02: ≈ 5 % contrast), at least ``margin_px`` from the border.
    """
    from scipy.ndimage import uniform_filter

    log = np.log10(np.maximum(np.asarray(lux, dtype=np.float64), 1e-12))
    mean = uniform_filter(log, window_px, mode="nearest")
    var = np.maximum(uniform_filter(log * log, window_px, mode="nearest") - mean * mean, 0.0)
    mask = np.sqrt(var) > min_log_contrast
    if margin_px > 0:
        inner = np.zeros_like(mask)
        inner[margin_px:-margin_px or None, margin_px:-margin_px or None] = True
        mask &= inner
    return mask




@dataclass
class MotionScores:
    """Flow scores split where the truth moves and where it stands still (:func:`motion_scores`).

    Attributes
    ----------
    all : FlowScores
        Every pixel with valid truth (inside the mask).
    moving : FlowScores
        Pixels whose true flow exceeds ``moving_above_px``; its ``relative_error`` is the
        error as a share of the true motion (1.0: no better than reading zero flow).
    still_median_px, still_p95_px : float
        Median and 95th percentile of the estimated flow's length on the still pixels (true
        flow exactly 0): false motion, px.
    still_pixels : int
        Still pixels scored.
    objects : dict
        ``"id class"`` → :class:`FlowScores` over each labelled object's pixels.
    moving_above_px : float
        The threshold used, px.
    """

    all: FlowScores
    moving: FlowScores
    still_median_px: float
    still_p95_px: float
    still_pixels: int
    objects: dict = field(default_factory=dict)
    moving_above_px: float = MOVING_ABOVE_PX

    def as_dict(self) -> dict:
        return {"all": self.all.as_dict(), "moving": self.moving.as_dict(),
                "still": {"median_false_motion_px": self.still_median_px,
                          "p95_false_motion_px": self.still_p95_px, "pixels": self.still_pixels},
                "objects": {name: s.as_dict() for name, s in self.objects.items()},
                "moving_above_px": self.moving_above_px}


def motion_scores(estimate_px: np.ndarray, truth: FlowTruth, labels: np.ndarray | None = None,
                  names: dict | None = None, mask: np.ndarray | None = None,
                  moving_above_px: float = MOVING_ABOVE_PX) -> MotionScores:
    """Scores of an estimated flow (2, H, W) on the moving pixels, each object and the still background.

    Parameters
    ----------
    estimate_px : ndarray (2, H, W)
        Estimated forward flow, px.
    truth : FlowTruth
        The exact flow between the same instants.
    labels : ndarray (H, W) of int, optional
        Object id per pixel at the first instant (0: background); each id > 0 is scored apart.
    names : dict, optional
        id → class name, for the keys of ``objects``.
    mask : ndarray (H, W) of bool, optional
        Pixels to score (all others left out of every figure).
    moving_above_px : float
        True flow (px) above which a pixel counts as moving (0.5).

    Returns
    -------
    MotionScores
        Scores over all pixels, the moving ones, each object and the still background.
    """
    estimate = np.asarray(estimate_px, dtype=np.float64)
    if estimate.shape != truth.flow_px.shape:
        raise ViformError(f"estimated flow {estimate.shape} and truth {truth.flow_px.shape} differ in shape")
    moving_above_px = check_positive("moving_above_px", moving_above_px)
    use = truth.valid & np.all(np.isfinite(estimate), axis=0)
    if mask is not None:
        use &= np.asarray(mask, bool)
    length = np.hypot(*truth.flow_px)
    moving = use & (length > moving_above_px)
    still = use & (length == 0)
    false_motion = np.hypot(*estimate[:, still]) if still.any() else np.empty(0)
    objects = {}
    if labels is not None:
        labels = np.asarray(labels)
        for obj in np.unique(labels[labels > 0]):
            name = f"{int(obj)} {(names or {}).get(int(obj), 'object')}"
            objects[name] = flow_scores(estimate, truth, use & (labels == obj))
    return MotionScores(flow_scores(estimate, truth, use), flow_scores(estimate, truth, moving),
                        float(np.median(false_motion)) if false_motion.size else math.nan,
                        float(np.percentile(false_motion, 95)) if false_motion.size else math.nan,
                        int(still.sum()), objects, moving_above_px)


# ---------------------------------------------------------------------- images


@dataclass
class RateImage:
    """A firing-rate image at one instant with the support behind each pixel's value.

    Attributes
    ----------
    rate : ndarray (H, W), float32
        Spikes per tick.
    intervals : ndarray (H, W), int16
        Intervals between spikes the rate was taken over (1 … 2K − 1).
    span_ticks : ndarray (H, W), int32
        Ticks those intervals span: the pixel's time support.
    censored : ndarray (H, W), bool
        No spike on one side of the instant within the search (the rate is a bound).
    """

    rate: np.ndarray
    intervals: np.ndarray
    span_ticks: np.ndarray
    censored: np.ndarray
    _derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def log_light(self) -> np.ndarray:
        """log(rate), with pixels of no measurable rate at the lowest the span allows (read-only:
        computed once, shared by the two fields an image bounds)."""
        if "log" not in self._derived:
            log = np.log(np.maximum(self.rate, 1.0 / np.maximum(self.span_ticks, 1) / 4)).astype(np.float64)
            log.setflags(write=False)
            self._derived["log"] = log
        return self._derived["log"]

    def log_variance(self, threshold_electrons: float) -> np.ndarray:
        """var(log rate) per pixel (module notes): 1/(n·Q) + 1/(6·X²) + floor²; 1 where censored
        (read-only, computed once per Q)."""
        key = ("var", float(threshold_electrons))
        if key not in self._derived:
            n = np.maximum(self.intervals, 1).astype(np.float64)
            span = np.maximum(self.span_ticks, 1).astype(np.float64)
            var = 1.0 / (n * threshold_electrons) + 1.0 / (6.0 * span * span) + LOG_NOISE_FLOOR ** 2
            var = np.where(self.censored, 1.0, var)
            var.setflags(write=False)
            self._derived[key] = var
        return self._derived[key]


def _block_ticks(pixels: int) -> int:
    """Ticks per read: 256, fewer on large sensors (a block stays ≈ 8 MiB of bools)."""
    return int(np.clip(2 ** 23 // max(1, pixels), 8, 256))


def _byte_words(block, pixels: int) -> np.ndarray:
    """Ticks (n, …) of spikes as (n, ⌈P/8⌉) uint64: each word 8 pixels' bytes (0 or 1), the last
    padded with zeros; a view of the block where its layout allows, else an aligned copy."""
    n = block.shape[0]
    flat = spike_bytes(np.ascontiguousarray(block).reshape(n, pixels))
    if pixels % 8 or flat.ctypes.data % 8:
        padded = np.zeros((n, -(-pixels // 8) * 8), np.uint8)
        padded[:, :pixels] = flat
        flat = padded
    return flat.view(np.uint64)


#: Spans (ticks) up to which the adaptive test's verdicts are tabled (:func:`_test_limits`).
TABLED_SPAN_TICKS = 2048


@lru_cache(maxsize=8)
def _test_limits(k_side: int, noise_q: float, tolerance: float) -> np.ndarray:
    """The adaptive test's verdicts as interval ranges per (intervals, span), read-only (shared by calls)."""
    from viform.vision._flow_kernels import consistent_limits

    limits = consistent_limits(2 * k_side, TABLED_SPAN_TICKS, float(noise_q), float(tolerance))
    limits.setflags(write=False)
    return limits


def spike_rate_images(source, ticks, *, spikes_per_side: int = 4, adaptive: bool = True, tolerance: float = 3.0,
                      horizon_ticks: int = 1024, noise_threshold_electrons: float | None = None):
    """Multi-interval rate images at many instants, in one pass over the spikes: yields ``(tick, RateImage)``.

    Parameters
    ----------
    source : SpikeSource
        Any spike stream.
    ticks : sequence of int
        Instants (ticks, increasing; repeats allowed).
    spikes_per_side : int
        K: up to K spikes on each side of the instant (2K − 1 intervals).
    adaptive : bool
        Stop the span's growth at the first interval inconsistent with the light so far (the
        test of :func:`viform.imaging.multi_interval.multi_interval_image`): short support
        where the light changes, long where it is steady.
    tolerance : float
        That test's threshold, standard deviations.
    horizon_ticks : int
        Spikes are looked for at most this far from the instant; a pixel with none on a side
        within it is ``censored`` (its rate a bound from the span searched).
    noise_threshold_electrons : float, optional
        Q in the adaptive test (default: the stream's, else 10⁴ e⁻).

    Notes
    -----
    The stream is read once, in blocks: backwards from the first instant until every pixel has
    K spikes at or before it (or ``horizon_ticks`` back), each pixel keeping its K nearest, then
    forwards to where every instant is complete; each pixel keeps its last 2K spike ticks, and
    an instant's rate is computed as soon as the pixel has K spikes after it (the adaptive
    test's verdicts looked up in a table of the test's own). Memory: the instants pending within
    the horizon.
    """
    from viform.vision._flow_kernels import advance_rates, collect_before, force_rates

    k_side = check_int("spikes_per_side", spikes_per_side, 1)
    check_positive("tolerance", tolerance)
    horizon = check_int("horizon_ticks", horizon_ticks, 1)
    q = noise_threshold_electrons or source.threshold_electrons or DEFAULT_NOISE_THRESHOLD_ELECTRONS
    check_positive("noise_threshold_electrons", q)
    instants = np.asarray([int(k) for k in np.atleast_1d(ticks)], dtype=np.int64)
    if instants.size == 0:
        raise ViformError("ticks is empty: give at least one instant")
    if np.any(np.diff(instants) < 0):
        raise ViformError("ticks must be in increasing order")
    n_total = source.n_ticks
    if instants[0] < 0 or instants[-1] >= n_total:
        bad = instants[0] if instants[0] < 0 else instants[-1]
        raise ViformError(f"ticks: {bad} is outside the stream's [0, {n_total})")
    h, w = source.height, source.width
    pixels = h * w
    block = _block_ticks(pixels)
    # where to start: every pixel's K spikes before the first instant, or the horizon. The blocks
    # read back to there are read once: each pixel's K spikes nearest the instant are kept (what a
    # forward pass from the start would leave in its ring), and the forward pass starts after it.
    first = int(instants[0])
    start = first + 1
    ring = np.zeros((pixels, 1 << (2 * k_side - 1).bit_length()), np.int64)  # a power of two ≥ 2K per pixel
    count = np.zeros(pixels, np.int64)
    floor = max(0, first + 1 - horizon)
    while start > floor and count.min() < k_side:
        a = max(floor, start - block)
        collect_before(_byte_words(source.read_ticks(a, start), pixels), start - a, a, k_side, ring, count)
        start = a
        block = min(2 * block, _block_ticks(pixels) * 8)
    # nearest first → oldest first, as a forward pass leaves its ring (count: the spikes it holds)
    nearest = np.clip(count[:, None] - 1 - np.arange(k_side), 0, None)
    ring[:, :k_side] = np.take_along_axis(ring[:, :k_side], nearest, axis=1)
    block = _block_ticks(pixels)
    lo_cut = start - 1  # a spike missing before the instant: taken just before the first tick read
    span = max(int(instants[-1] - instants[0]), 1)
    steps = np.diff(instants)
    min_step = int(steps[steps > 0].min()) if np.any(steps > 0) else span
    n_slots = int(min(instants.size, (horizon + block) // max(min_step, 1) + 2 + np.max(
        np.bincount(instants - instants[0]))))
    out_rate = np.empty((n_slots, pixels), np.float32)
    out_used = np.empty((n_slots, pixels), np.int16)
    out_span = np.empty((n_slots, pixels), np.int32)
    out_cut = np.empty((n_slots, pixels), np.bool_)
    next_inst = np.zeros(pixels, np.int64)
    emitted = 0
    position = start
    args = (k_side, bool(adaptive), float(q), float(tolerance), _test_limits(k_side, q, tolerance))

    def ready(upto):
        nonlocal emitted
        while emitted < upto:
            s = emitted % n_slots
            image = RateImage(out_rate[s].reshape(h, w).copy(), out_used[s].reshape(h, w).copy(),
                              out_span[s].reshape(h, w).copy(), out_cut[s].reshape(h, w).copy())
            yield int(instants[emitted]), image
            emitted += 1

    while emitted < instants.size:
        if position >= n_total:
            force_rates(ring, count, next_inst, instants, instants.size, *args, lo_cut, n_total,
                        out_rate, out_used, out_span, out_cut)
            yield from ready(instants.size)
            break
        stop = min(n_total, position + block)
        if emitted + n_slots < instants.size:
            # instants past the slots are not pending yet: read no further than the first of them
            # (a pixel's ring holds only the spikes its pending instants need)
            stop = min(stop, max(int(instants[emitted + n_slots]) + 1, position + 1))
        # ticks up to the first instant were read already (above); the blocks stay where they were
        read_from = max(position, first + 1)
        if stop > read_from:
            bits8 = _byte_words(source.read_ticks(read_from, stop), pixels)
            advance_rates(bits8, stop - read_from, read_from, ring, count, next_inst, instants[: emitted + n_slots],
                          instants.size, *args, lo_cut, out_rate, out_used, out_span, out_cut)
        position = stop
        # instants whose horizon has passed are completed with what was found
        late = int(np.searchsorted(instants, position - horizon, side="left"))
        late = min(late, emitted + n_slots)
        if late > 0:
            force_rates(ring, count, next_inst, instants, late, *args, lo_cut, position,
                        out_rate, out_used, out_span, out_cut)
        done = int(next_inst.min())
        yield from ready(min(done, instants.size))


def rate_images(source, ticks, method: str = "multi-interval", spikes_per_side: int = 4, window_ticks: int = 41):
    """Firing-rate images (spikes per tick) at ``ticks`` (sorted), yielded as ``(tick, rate)``.

    ``multi-interval``: :func:`spike_rate_images` (one pass); ``accumulation``: the spikes of a
    ``window_ticks`` window centred on each instant, counted directly; ``interval``: K = 1.
    """
    check_choice("method", method, IMAGE_METHODS)
    if method == "accumulation":
        from viform.imaging.accumulation import spike_counts, window_bounds

        window_ticks = check_int("window_ticks", window_ticks, 1)
        for k in ticks:
            k0, k1 = window_bounds(int(k), window_ticks, source.n_ticks, "centre")
            yield int(k), spike_counts(source, k0, k1) / (k1 - k0)
        return
    k_side = spikes_per_side if method == "multi-interval" else 1
    for k, image in spike_rate_images(source, ticks, spikes_per_side=k_side):
        yield k, image.rate.astype(np.float64)


def _rate_image_of(source, ticks, method, spikes_per_side, window_ticks, horizon_ticks):
    """RateImages at ``ticks`` for any method (accumulation: count n over the window)."""
    if method == "accumulation":
        for k, rate in rate_images(source, ticks, "accumulation", window_ticks=window_ticks):
            counts = np.rint(rate * window_ticks)
            yield k, RateImage(rate.astype(np.float32), np.maximum(counts, 1).astype(np.int16),
                               np.full(rate.shape, window_ticks, np.int32), counts == 0)
        return
    k_side = spikes_per_side if method == "multi-interval" else 1
    yield from spike_rate_images(source, ticks, spikes_per_side=k_side, horizon_ticks=horizon_ticks)


# ---------------------------------------------------------------------- the estimator

@dataclass
class FlowEstimate:
    """Flow estimated from spikes between two instants.

    Attributes
    ----------
    flow_px : ndarray (2, H, W), float32
        Forward flow (u, v) from ``t0_s`` to ``t1_s``, px.
    t0_s, t1_s : float
        The two instants, s (the middles of the ticks they fall in).
    confidence : ndarray (H, W), float32
        In [0, 1]: how well the spikes resolve the interval at each pixel (module notes, step 5).
    images : tuple of ndarray
        The two 8-bit log-light images the dense flow was computed on.
    info : dict
        Image method, DIS preset, log-light range, the moving regions found (``regions``).
    """

    flow_px: np.ndarray
    t0_s: float
    t1_s: float
    confidence: np.ndarray | None = None
    images: tuple = ()
    info: dict = field(default_factory=dict)


def _check_dis(preset: str):
    try:
        import cv2
    except ImportError:  # pragma: no cover - opencv is a dependency
        raise ViformError("optical flow needs OpenCV: pip install opencv-python") from None
    check_choice("preset", preset, DIS_PRESETS)
    return cv2


def log_light_pair_8bit(rate0: np.ndarray, rate1: np.ndarray, floor: float | None = None):
    """Two light images on one 8-bit scale of log light (0.5th–99.5th percentile of both).

    ``floor`` (same unit as the rates) bounds the dark end: pixels without a measurement
    (rate 0) sit at it instead of at −∞.
    """
    # the scale's ends from a strided sample (≥ 16k pixels): the same to a grey level, 8× cheaper
    step = max(1, rate0.size // 16384)
    both = np.concatenate([rate0.ravel()[::step], rate1.ravel()[::step]])
    positive = both[both > 0]
    if positive.size == 0:
        zero = np.zeros(rate0.shape, np.uint8)
        return zero, zero.copy(), (math.nan, math.nan)
    floor = float(np.percentile(positive, 0.5)) if floor is None else floor
    lo = math.log(max(floor, positive.min()))
    hi = math.log(max(float(np.percentile(positive, 99.5)), math.exp(lo) * 1.0001))

    def scale(rate):
        log = np.log(np.maximum(rate, math.exp(lo)))
        return np.clip(np.rint((log - lo) / (hi - lo) * 255.0), 0, 255).astype(np.uint8)

    return scale(rate0), scale(rate1), (lo, hi)


def flow_between_images(image0: np.ndarray, image1: np.ndarray, preset: str = "fast") -> np.ndarray:
    """Forward flow (2, H, W) px from ``image0`` to ``image1`` (8-bit) by OpenCV's DIS.

    A new matcher each call: one reused across image sizes carries state that changes its result.
    """
    cv2 = _check_dis(preset)
    dis = cv2.DISOpticalFlow_create({"ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
                                     "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
                                     "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}[preset])
    flow = dis.calc(np.ascontiguousarray(image0), np.ascontiguousarray(image1), None)
    return np.moveaxis(flow, -1, 0)


def compose_flows(first_px: np.ndarray, second_px: np.ndarray) -> np.ndarray:
    """Flow of two steps in a row: first(x) + second(x + first(x)) (second sampled bilinearly)."""
    from scipy.ndimage import map_coordinates

    h, w = first_px.shape[1:]
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    where = [rows + first_px[1], cols + first_px[0]]
    second = np.stack([map_coordinates(second_px[i], where, order=1, mode="nearest") for i in range(2)])
    return (first_px + second).astype(np.float32)


def check_interval(source, t_s: float, dt_s: float, names=("t_s", "dt_s")) -> tuple[int, int]:
    """The ticks of t and t + dt in ``source``; refuses dt ≤ 0 and instants outside the stream.

    ``names`` are the two parameters' names in the messages (the CLI passes its flags).
    """
    at_name, dt_name = names
    if not (isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0):
        raise ViformError(f"{dt_name} = {dt_s!r} is not allowed: the flow interval must be a time > 0 seconds")
    if source.n_ticks < 2:
        raise ViformError(f"the stream holds {source.n_ticks} tick(s): optical flow needs two instants")
    duration = source.n_ticks / source.clock_hz
    start = source.start_time_s
    if not (isinstance(t_s, (int, float)) and start <= t_s < start + duration):
        raise ViformError(f"{at_name} = {t_s!r} is outside the stream [{start:g}, {start + duration:g}) s")
    if t_s + dt_s >= start + duration:
        raise ViformError(f"{dt_name} = {dt_s!r}: {at_name} + {dt_name} = {t_s + dt_s:g} s is past the stream's end "
                          f"({start + duration:g} s); give a shorter interval or an earlier instant")
    tick0, tick1 = source.tick_of(t_s), source.tick_of(t_s + dt_s)
    if tick1 == tick0:
        raise ViformError(f"{dt_name} = {dt_s!r} is shorter than one tick ({1 / source.clock_hz:g} s): "
                          "the two instants fall in the same tick")
    return tick0, tick1


@dataclass(frozen=True)
class LayeredOptions:
    """Settings of the layered refinement (module notes, steps 3–4); defaults tuned on the tuning scenes.

    Attributes
    ----------
    max_shift_px : int
        Largest displacement searched for a region, px.
    min_region_px, max_region_share : int, float
        Regions tested: at least this many pixels and at most this share of the image.
    min_gain : float
        Cost decrease (χ² units) a region's motion must give over "still".
    tolerance, slack : float
        Region merging: within ``tolerance``·σ + ``slack`` (log light) of the other region's mean.
    cap, unknown, exception : float
        Robust cost: cap on a pixel's χ², cost of uncovered background, extra cost of leaving a
        landing still (another object in the way).
    max_unexplained : float
        Largest share of a region's landings its motion may leave unexplained.
    smooth_px : float
        Gaussian σ of the images the sub-pixel (Gauss–Newton) step works on, px.
    rim_px : int
        Width of the rim of a region the sub-pixel step uses, px (its flat interior tells nothing).
    still_chi2, still_below_px : float
        A pixel outside moving regions is still where its mean χ² over 5×5 is below
        ``still_chi2`` and the dense flow moves it less than ``still_below_px`` (a moving
        texture's flat parts change little in the interval, yet move with the rest).
    """

    max_shift_px: int = 14
    min_region_px: int = 12
    max_region_share: float = 0.2
    min_gain: float = 25.0
    tolerance: float = 3.0
    slack: float = 0.3
    cap: float = 9.0
    unknown: float = 3.0
    exception: float = 2.0
    max_unexplained: float = 0.25
    smooth_px: float = 1.0
    rim_px: int = 4
    still_chi2: float = 2.0
    still_below_px: float = 0.3


def _gaussian(image, sigma_px):
    """Gaussian smoothing of σ px, edges repeated: scipy's ``gaussian_filter(mode="nearest")`` (kernel
    to 4σ) by OpenCV's separable filter (the same weights; equal to ~1e-16, 2-3× faster)."""
    import cv2

    radius = int(4.0 * sigma_px + 0.5)
    return cv2.GaussianBlur(np.ascontiguousarray(image, dtype=np.float64), (2 * radius + 1, 2 * radius + 1),
                            sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REPLICATE)


def layered_refinement(log0: np.ndarray, log1: np.ndarray, var0: np.ndarray, var1: np.ndarray,
                       dense_px: np.ndarray, options: LayeredOptions | None = None, frames=()):
    """Refine a dense flow where regions move as wholes over a still background (module notes, 3–4).

    Parameters
    ----------
    log0, log1 : ndarray (H, W)
        Log light at the two instants (any log unit; the same for both).
    var0, var1 : ndarray (H, W)
        Their noise variances.
    dense_px : ndarray (2, H, W)
        The dense flow to refine, px.
    options : LayeredOptions, optional
    frames : sequence of (fraction, log light, variance)
        Images between the two instants, at their fraction of the interval: the sub-pixel step
        fits one constant velocity to all of them (more edges crossed, more spikes, and the
        light's own pixel grid averaged out).

    Returns
    -------
    flow : ndarray (2, H, W), float32
    regions : list of dict
        The moving regions kept: pixels, centre, motion (px; ``affine`` when it varies across
        the region), gain (χ²).
    info : dict
        Regions tested, rejected (by reason), share of pixels set still.
    """
    from scipy import ndimage as ndi

    from viform.vision._flow_kernels import (
        best_shift,
        gauss_newton_motion,
        inner_depth,
        rim_mean_exceeds,
        segment_log_light,
        unexplained_share,
        warp_costs_at,
    )

    o = options or LayeredOptions()
    log0 = np.ascontiguousarray(log0, dtype=np.float64)
    log1 = np.ascontiguousarray(log1, dtype=np.float64)
    var0 = np.ascontiguousarray(var0, dtype=np.float64)
    var1 = np.ascontiguousarray(var1, dtype=np.float64)
    h, w = log0.shape
    labels, n = segment_log_light(log0, np.sqrt(var0), o.tolerance, o.slack, 64)
    chi2 = (log1 - log0) ** 2 / (var0 + var1)
    still = np.minimum(chi2, o.cap)
    changed = chi2 > 16.0
    sizes = np.bincount(labels.ravel(), minlength=n)
    boxes = ndi.find_objects(labels + 1)
    flow = np.asarray(dense_px, dtype=np.float32).copy()
    moving = np.zeros((h, w), bool)
    smooth = partial(_gaussian, sigma_px=o.smooth_px)
    s0 = smooth(log0)
    # the later images the sub-pixel step fits a constant velocity to: those between the two
    # instants (``frames``, at their fraction of the interval), and the second instant's
    later = [(f, np.asarray(lg, np.float64), np.asarray(vr, np.float64)) for f, lg, vr in (frames or ())] + [
        (1.0, log1, var1)]
    fractions = np.array([f for f, _, _ in later])
    stack1 = np.stack([smooth(lg) for _, lg, _ in later])
    grad_y1, grad_x1 = np.gradient(stack1, axis=(1, 2))
    # Σ g² of a 2-D Gaussian of σ px is 1/(4πσ²): the smoothed images' noise variance
    smooth_var0 = smooth(var0)
    weight = np.stack([(4 * np.pi * o.smooth_px ** 2) / (smooth_var0 + smooth(vr)) for _, _, vr in later])
    inverse_var = 1.0 / (var0 + var1)
    # 1. every region whose surroundings changed: its best motion over a still background
    candidates = []
    tested = 0
    for region in np.flatnonzero((sizes >= o.min_region_px) & (sizes <= o.max_region_share * h * w)):
        box = boxes[region]
        grown = (slice(max(0, box[0].start - 2), box[0].stop + 2), slice(max(0, box[1].start - 2), box[1].stop + 2))
        if np.count_nonzero(changed[grown]) < 3:
            continue  # nothing changed around it: still
        tested += 1
        inside = labels[box] == region
        rows, cols = np.nonzero(inside)
        rows = (rows + box[0].start).astype(np.int64)
        cols = (cols + box[1].start).astype(np.int64)
        # the coarse search's sample: up to 384 pixels of the rim (2 px) and 128 of the interior
        depth = inner_depth(inside)
        core = depth[inside] > 2
        rim_i, core_i = np.flatnonzero(~core), np.flatnonzero(core)
        sample = np.concatenate([rim_i[::max(1, rim_i.size // 384)], core_i[::max(1, core_i.size // 128)]])
        coarse = (rows[sample].copy(), cols[sample].copy())
        dy, dx, gain = best_shift(log0, log1, var0, var1, still, labels, int(region), rows, cols, *coarse,
                                  int(o.max_shift_px), o.cap, o.unknown, o.exception)
        if -gain > o.min_gain and not dy == dx == 0.0:
            candidates.append((-gain, int(region), box, depth, rows, cols, coarse, (dy, dx, gain)))
    # 2. strongest first; what a kept motion explains (where its pixels land, what they uncover) is
    # no longer a change for the others, so a region beside a moving one is not read as moving too
    regions = []
    rejected = {"explained by others": 0, "unexplained landings": 0, "dense flow as good": 0}
    touched = np.zeros((h, w), bool)  # where kept motions changed the still costs
    reach = int(o.max_shift_px) + 2
    for _, region, box, depth, rows, cols, coarse, first in sorted(candidates, key=lambda c: -c[0]):
        near = (slice(max(0, box[0].start - reach), box[0].stop + reach),
                slice(max(0, box[1].start - reach), box[1].stop + reach))
        if touched[near].any():  # else the search would find what it found before
            first = best_shift(log0, log1, var0, var1, still, labels, region, rows, cols, *coarse,
                               int(o.max_shift_px), o.cap, o.unknown, o.exception)
        dy, dx, gain = first
        if -gain <= o.min_gain or dy == dx == 0.0:
            rejected["explained by others"] += 1
            continue
        if unexplained_share(log0, log1, var0, var1, still, rows, cols, dy, dx, o.cap, o.exception) \
                >= o.max_unexplained:
            rejected["unexplained landings"] += 1
            continue
        # sub-pixel: Gauss–Newton on the rim (the interior of a uniform region tells nothing)
        rim_r, rim_c = np.nonzero((depth > 0) & (depth <= o.rim_px))
        rim_r = (rim_r + box[0].start).astype(np.int64)
        rim_c = (rim_c + box[1].start).astype(np.int64)
        start = np.array([dx, dy, 0, 0, 0, 0], float)
        params, cost, used, cy, cx, scale = gauss_newton_motion(
            s0, stack1, grad_x1, grad_y1, weight, fractions, rim_r, rim_c, start, False, 20, o.cap, 0.0)
        affine, cost_a, _, _, _, _ = gauss_newton_motion(
            s0, stack1, grad_x1, grad_y1, weight, fractions, rim_r, rim_c, params.copy(), True, 20, o.cap,
            o.min_gain)
        # an affine motion (a rotating blade) must lower the cost by min_gain and spread the motion by
        # half a pixel or more across the region (less is within a translation's own error)
        spread = np.abs(affine[2:]).reshape(2, 2).sum(axis=1).max()
        if cost_a < cost - o.min_gain and spread >= 0.5 and abs(affine[0] - params[0]) + abs(
                affine[1] - params[1]) < 1.0:
            params = affine
        if not (abs(params[0] - dx) <= 1.0 and abs(params[1] - dy) <= 1.0 and np.all(np.isfinite(params))):
            params = np.array([dx, dy, 0, 0, 0, 0], float)  # the step wandered: keep the search's shift
        xx = (cols - cx) / scale
        yy = (rows - cy) / scale
        u = params[0] + params[2] * xx + params[3] * yy
        v = params[1] + params[4] * xx + params[5] * yy
        # the region's motion replaces the dense flow where it explains the region's rim better by
        # min_gain (a dense flow that already follows a textured region is kept), except at rim
        # pixels the dense flow explains clearly better (another object's motion); judged on the
        # images themselves (smoothing would mix in the other side of the region's edge)
        at_rim = depth[depth > 0] <= o.rim_px  # the region's pixels (row-major, as rows/cols) on its rim
        u32 = u.astype(np.float32)
        v32 = v.astype(np.float32)
        fit_cost = warp_costs_at(log0, log1, inverse_var, rows[at_rim], cols[at_rim], u32[at_rim], v32[at_rim],
                                 o.cap)
        dense_cost = warp_costs_at(log0, log1, inverse_var, rows[at_rim], cols[at_rim], flow[0, rows[at_rim],
                                   cols[at_rim]], flow[1, rows[at_rim], cols[at_rim]], o.cap)
        if np.sum(dense_cost - np.minimum(fit_cost, dense_cost + o.exception)) <= o.min_gain:
            rejected["dense flow as good"] += 1
            continue
        # rim pixels the dense flow explains clearly better, over 5×5 of the rim (another object's motion,
        # not one noisy pixel), keep it
        keep_rim = rim_mean_exceeds(rows[at_rim], cols[at_rim], fit_cost - dense_cost, h, w, 2, o.exception)
        take = np.ones(rows.size, bool)
        take[np.flatnonzero(at_rim)[keep_rim]] = False
        flow[0, rows[take], cols[take]] = u32[take]
        flow[1, rows[take], cols[take]] = v32[take]
        moving[rows[take], cols[take]] = True
        land_r = np.rint(rows + v).astype(np.int64)
        land_c = np.rint(cols + u).astype(np.int64)
        inside_field = (land_r >= 0) & (land_r < h) & (land_c >= 0) & (land_c < w)
        # what it explains: where it lands, and its own place (landed on, or uncovered)
        for er, ec in ((land_r[inside_field], land_c[inside_field]), (rows, cols)):
            still[er, ec] = np.minimum(still[er, ec], 1.0)
            touched[er, ec] = True
        regions.append({"pixels": int(rows.size), "centre_px": [float(cols.mean()), float(rows.mean())],
                        "shift_px": [float(params[0]), float(params[1])],
                        "affine": bool(params[2:].any()), "gain": float(-gain)})
    quiet = ~moving & (ndi.uniform_filter(chi2, 5, mode="nearest") < o.still_chi2) & (
        np.hypot(flow[0], flow[1]) < o.still_below_px)
    flow[:, quiet] = 0.0
    return flow, regions, {"regions_tested": tested, "regions_rejected": rejected,
                           "still_share": float(quiet.mean())}


def flow_confidence(image0: RateImage, image1: RateImage, dt_ticks: int, spikes_per_side: int) -> np.ndarray:
    """Confidence in [0, 1] per pixel (module notes, step 5)."""
    support = np.maximum(np.maximum(image0.span_ticks, image1.span_ticks), 1)
    found = np.minimum(image0.intervals, image1.intervals) / max(2 * spikes_per_side - 1, 1)
    conf = np.minimum(1.0, dt_ticks / support) * np.minimum(1.0, found)
    return np.where(image0.censored | image1.censored, 0.0, conf).astype(np.float32)


def _flow_from_images(images, ticks, q, preset, refine, options, chain_above_px, spikes_per_side):
    """Flow from the first to the last of ``images`` (RateImages at ``ticks``), chained through the others."""
    first, last = images[0], images[-1]
    image0, image1, (lo, hi) = log_light_pair_8bit(first.rate, last.rate)
    dense = flow_between_images(image0, image1, preset)
    chained = 1
    if len(images) > 2 and chain_above_px is not None and np.percentile(np.hypot(*dense), 99) > chain_above_px:
        dense = None
        for a, b in zip(images[:-1], images[1:], strict=True):
            pa, pb, _ = log_light_pair_8bit(a.rate, b.rate)
            step = flow_between_images(pa, pb, preset)
            dense = step.astype(np.float32) if dense is None else compose_flows(dense, step)
        chained = len(images) - 1
    flow = dense.astype(np.float32)
    info = {"log_rate_range": [lo, hi], "chained_steps": chained}
    if refine == "layered":
        # the intermediate images are not fitted (frames=()): on the tuning scenes a constant velocity
        # through them read saturated edges, which move in whole pixels, worse than the two instants
        flow, regions, extra = layered_refinement(first.log_light(), last.log_light(), first.log_variance(q),
                                                  last.log_variance(q), flow, options)
        info.update(extra)
        info["regions"] = regions
    confidence = flow_confidence(first, last, int(ticks[-1] - ticks[0]), spikes_per_side)
    return flow, confidence, (image0, image1), info


def estimate_flow(source, t_s: float, dt_s: float, *, method: str = "multi-interval", spikes_per_side: int = 4,
                  window_ticks: int = 41, preset: str = "fast", refine: str = "layered",
                  options: LayeredOptions | None = None, chain_steps: int = 1, chain_above_px: float = 6.0,
                  horizon_ticks: int = 1024) -> FlowEstimate:
    """Forward optical flow (px) from ``t_s`` to ``t_s + dt_s`` estimated from a spike stream.

    Parameters
    ----------
    source : SpikeSource
        Any spike stream viform reads (no truth needed).
    t_s, dt_s : float
        First instant and flow interval, s (both instants inside the stream).
    method : {"multi-interval", "interval", "accumulation"}
        How the light at each instant is imaged (module notes, step 1; ``interval`` is K = 1).
    spikes_per_side : int
        Multi-interval K (4: up to 7 intervals).
    window_ticks : int
        Accumulation window, ticks.
    preset : {"ultrafast", "fast", "medium"}
        OpenCV DIS preset of the dense flow.
    refine : {"layered", "none"}
        The layered refinement and still background (module notes, steps 3–4), or DIS alone.
    options : LayeredOptions, optional
        The refinement's settings.
    chain_steps : int
        Steps the interval is split into where the dense flow exceeds ``chain_above_px`` (1: no
        chaining, the default; module notes, step 2).
    chain_above_px : float
        99th percentile of the dense flow's length (px) above which it is chained.
    horizon_ticks : int
        How far from each instant spikes are looked for (:func:`spike_rate_images`).

    Returns
    -------
    FlowEstimate
        The flow is measured between the middles of the two instants' ticks.
    """
    check_choice("method", method, IMAGE_METHODS)
    check_choice("refine", refine, REFINEMENTS)
    _check_dis(preset)
    spikes_per_side = check_int("spikes_per_side", spikes_per_side, 1)
    window_ticks = check_int("window_ticks", window_ticks, 1)
    chain_steps = check_int("chain_steps", chain_steps, 1)
    chain_above_px = check_positive("chain_above_px", chain_above_px)
    horizon_ticks = check_int("horizon_ticks", horizon_ticks, 1)
    tick0, tick1 = check_interval(source, t_s, dt_s, names=("t_s", "dt_s"))
    steps = min(chain_steps, tick1 - tick0)
    ticks = sorted({int(round(tick0 + i * (tick1 - tick0) / steps)) for i in range(steps + 1)})
    images = [image for _, image in _rate_image_of(source, ticks, method, spikes_per_side, window_ticks,
                                                   horizon_ticks)]
    q = source.threshold_electrons or DEFAULT_NOISE_THRESHOLD_ELECTRONS
    flow, confidence, pair, info = _flow_from_images(images, ticks, q, preset, refine, options, chain_above_px,
                                                     spikes_per_side if method == "multi-interval" else 1)
    # each image stands for the middle of its tick
    t0 = source.start_time_s + (tick0 + 0.5) / source.clock_hz
    t1 = source.start_time_s + (tick1 + 0.5) / source.clock_hz
    info.update({"method": method, "spikes_per_side": spikes_per_side, "preset": preset, "refine": refine,
                 "ticks": [tick0, tick1]})
    return FlowEstimate(flow, t0, t1, confidence, pair, info)


def flow_sequence(source, step_ticks: int, *, method: str = "multi-interval", spikes_per_side: int = 4,
                  window_ticks: int = 41, preset: str = "fast", refine: str = "layered",
                  options: LayeredOptions | None = None, start_tick: int = 0, stop_tick: int | None = None,
                  horizon_ticks: int = 1024):
    """Yield ``(tick0, tick1, flow (2, H, W))`` between instants ``step_ticks`` apart over a stream.

    The images of all instants come from one pass over the spikes (:func:`spike_rate_images`)
    and each is used by the two fields it bounds, so N instants cost N images and N − 1
    fields; each field equals :func:`estimate_flow` between its instants without chaining.

    Parameters
    ----------
    source : SpikeSource
        The spike stream.
    step_ticks : int
        Ticks between consecutive instants.
    method, spikes_per_side, window_ticks, preset, refine, options, horizon_ticks
        As for :func:`estimate_flow`.
    start_tick : int
        First instant, tick.
    stop_tick : int, optional
        Last instant, tick (default: the stream's end).

    Yields
    ------
    tick0, tick1 : int
        The two instants of the field, ticks.
    flow : ndarray of float (2, H, W)
        Forward flow from ``tick0`` to ``tick1``, px (x, y).
    """
    check_choice("method", method, IMAGE_METHODS)
    check_choice("refine", refine, REFINEMENTS)
    _check_dis(preset)
    step_ticks = check_int("step_ticks", step_ticks, 1)
    stop = source.n_ticks if stop_tick is None else min(check_int("stop_tick", stop_tick, 1), source.n_ticks)
    ticks = list(range(check_int("start_tick", start_tick, 0), stop, step_ticks))
    if len(ticks) < 2:
        raise ViformError(f"the stream has fewer than two instants {step_ticks} ticks apart")
    q = source.threshold_electrons or DEFAULT_NOISE_THRESHOLD_ELECTRONS
    k_side = spikes_per_side if method == "multi-interval" else 1
    previous = None
    for tick, image in _rate_image_of(source, ticks, method, spikes_per_side, window_ticks, horizon_ticks):
        if previous is not None:
            flow, _, _, _ = _flow_from_images([previous[1], image], [previous[0], tick], q, preset, refine, options,
                                              None, k_side)
            yield previous[0], tick, flow
        previous = (tick, image)


# ---------------------------------------------------------------------- pictures

def flow_to_rgb(flow_px: np.ndarray, max_flow_px: float | None = None) -> tuple[np.ndarray, float]:
    """Colour-wheel picture of a flow field (the Middlebury convention: hue = direction,
    saturation = length / ``max_flow_px``); unknown flow is black. Returns (RGB float, max_flow_px)."""
    from matplotlib.colors import hsv_to_rgb

    u, v = np.asarray(flow_px[0], float), np.asarray(flow_px[1], float)
    known = np.isfinite(u) & np.isfinite(v)
    length = np.where(known, np.hypot(u, v), 0.0)
    if max_flow_px is None:
        max_flow_px = float(np.percentile(length[known], 99)) if known.any() else 1.0
    max_flow_px = max(max_flow_px, 1e-9)
    hue = (np.arctan2(np.where(known, v, 0.0), np.where(known, u, 0.0)) / (2 * np.pi)) % 1.0
    hsv = np.stack([hue, np.clip(length / max_flow_px, 0, 1), np.where(known, 1.0, 0.0)], axis=-1)
    return hsv_to_rgb(hsv), max_flow_px


def flow_figure(path, estimate_px: np.ndarray, *, truth: FlowTruth | None = None, title: str = "",
                scores: FlowScores | MotionScores | None = None) -> Path:
    """PNG: the estimated flow on a colour wheel, the truth beside it on the same scale, the wheel as legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from viform._io import save_figure

    panels = [("estimated from spikes", estimate_px)]
    if truth is not None:
        shown = np.where(truth.valid, truth.flow_px, np.nan)
        panels.append(("truth (black: occluded or leaving)", shown))
    scale = max(flow_to_rgb(f)[1] for _, f in panels)
    height, width = estimate_px.shape[1:]
    fig_w = 4.2 * len(panels) + 1.8
    fig = plt.figure(figsize=(fig_w, 3.6 * max(0.5, height / width) + 1.2))
    grid = fig.add_gridspec(1, len(panels) + 1, width_ratios=[4.2] * len(panels) + [1.6])
    for i, (name, flow) in enumerate(panels):
        ax = fig.add_subplot(grid[0, i])
        ax.imshow(flow_to_rgb(flow, scale)[0], interpolation="nearest")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
    wheel = fig.add_subplot(grid[0, -1])
    yy, xx = np.mgrid[-1:1:201j, -1:1:201j]
    disc = np.where(np.hypot(xx, yy) <= 1, 1.0, np.nan)
    wheel.imshow(flow_to_rgb(np.stack([xx * disc * scale, yy * disc * scale]), scale)[0],
                 extent=(-scale, scale, scale, -scale))
    wheel.set_title(f"legend: flow (px)\nrim = {scale:.3g} px", fontsize=8)
    wheel.set_xlabel("u (px, right +)", fontsize=8)
    wheel.set_ylabel("v (px, down +)", fontsize=8)
    wheel.tick_params(labelsize=7)
    text = title
    if isinstance(scores, MotionScores):
        if scores.moving.pixels:
            text += (f"\nmoving pixels: EPE {scores.moving.epe_px:.3g} px = {100 * scores.moving.relative_error:.0f} % "
                     f"of their motion ({scores.moving.true_flow_px:.3g} px)")
        if scores.still_pixels:
            text += f"; still background: median false motion {scores.still_median_px:.3g} px"
    elif scores is not None and scores.pixels:
        text += f"\nEPE {scores.epe_px:.3g} px, Fl {100 * scores.fl_outliers:.3g} % over {scores.pixels:,} px"
    fig.suptitle(text, fontsize=10)
    fig.tight_layout()
    save_figure(path, fig)
    plt.close(fig)
    return Path(path)


def check_dt(dt_s, name: str = "dt_s") -> float:
    """A flow interval > 0 s (``name``: the parameter's name in the message)."""
    return check_positive(name, dt_s)
