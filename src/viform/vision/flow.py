"""Optical flow from a spike stream, scored against a scene's exact truth (seed 000, abstract and §7).

The estimator is classical and deliberately simple, so its failures are the sensor's, not a
network's:

1. two images of the light, at t and at t + dt, from the spikes around each instant —
   multi-interval imaging by default (seed 000 §3.3.2: the K spikes on each side of the
   instant, light = (2K − 1)·Q / span), which follows each pixel's own time scale;
2. both mapped to the same 8-bit scale of *log* light (one mapping for the pair, so a change
   of brightness is not read as motion, and dim and bright texture both count);
3. dense inverse search (DIS, Kroeger et al., ECCV 2016, as implemented in OpenCV:
   ``cv2.DISOpticalFlow``), a coarse-to-fine patch matcher with variational refinement — the
   fast classical flow of the field. Its ``fast`` preset is the default: on the tuning scene
   (a texture translating at 2,000 px/s, SpikeOne preset, 1 ms) it gave EPE 0.10 px against
   0.36 px for ``medium`` (whose finer refinement follows the images' photon noise); the other
   scenes of ``benchmarks/bench_flow.py`` were not looked at for this choice.

The result is forward flow in px from t to t + dt, the convention of
:mod:`viform.light.truth` and of flow benchmarks. Scores follow them too: the average endpoint
error (EPE, px) and the KITTI outlier fraction Fl (EPE > 3 px *and* > 5 % of the true flow's
length), over the pixels where the truth is valid.

Files: Middlebury ``.flo`` (what the spike-camera flow sets SPIFT/PHM and SCFlow read: float32
magic 202021.25, width, height, then (H, W, 2) u/v); unknown flow is stored as 1e10, the
format's convention (values above 1e9 mean unknown).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viform._io import atomic_open
from viform._validate import ViformError, check_choice, check_int, check_positive
from viform.light.truth import FlowTruth

FLO_MAGIC = 202021.25
#: Values above this mean "unknown flow" in a .flo file (Middlebury's UNKNOWN_FLOW_THRESH).
FLO_UNKNOWN_THRESHOLD = 1e9
FLO_UNKNOWN = 1e10
#: Image methods the estimator can use at each instant.
IMAGE_METHODS = ("multi-interval", "interval", "accumulation")
#: DIS presets of OpenCV (speed against accuracy).
DIS_PRESETS = ("ultrafast", "fast", "medium")


# ---------------------------------------------------------------------- files

def write_flo(path, flow_px: np.ndarray, valid: np.ndarray | None = None) -> Path:
    """Write forward flow (2, H, W) in px as a Middlebury ``.flo`` file (atomically).

    Pixels where ``valid`` is False (or the flow is not finite) are stored as unknown (1e10).
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
    """Read a Middlebury ``.flo`` file: (flow (2, H, W) float32 px with NaN where unknown, valid (H, W))."""
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

    def as_dict(self) -> dict:
        return {"epe_px": self.epe_px, "fl_outliers": self.fl_outliers, "pixels": self.pixels,
                "true_flow_px": self.true_flow_px}


def flow_scores(estimate_px: np.ndarray, truth: FlowTruth, mask: np.ndarray | None = None) -> FlowScores:
    """EPE and Fl of an estimated flow (2, H, W) against :class:`~viform.light.truth.FlowTruth`."""
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
    images : tuple of ndarray
        The two 8-bit log-light images the flow was computed on.
    info : dict
        Image method, DIS preset, log-light range.
    """

    flow_px: np.ndarray
    t0_s: float
    t1_s: float
    images: tuple = ()
    info: dict = field(default_factory=dict)


def _check_dis(preset: str):
    try:
        import cv2
    except ImportError:  # pragma: no cover - opencv is a dependency
        raise ViformError("optical flow needs OpenCV: pip install opencv-python-headless") from None
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
    """Forward flow (2, H, W) px from ``image0`` to ``image1`` (8-bit) by OpenCV's DIS."""
    cv2 = _check_dis(preset)
    dis = cv2.DISOpticalFlow_create({"ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
                                     "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
                                     "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}[preset])
    flow = dis.calc(np.ascontiguousarray(image0), np.ascontiguousarray(image1), None)
    return np.moveaxis(flow, -1, 0)


def rate_images(source, ticks, method: str = "multi-interval", spikes_per_side: int = 4, window_ticks: int = 41):
    """Firing-rate images (spikes per tick) at ``ticks`` (sorted), yielded as ``(tick, rate)``.

    Accumulation windows are counted directly around each instant (a window per instant, not
    the every-tick sliding count a video needs); the other methods stream through
    :func:`viform.imaging.sequence.reconstruct_ticks`.
    """
    if method == "accumulation":
        from viform.imaging.accumulation import spike_counts, window_bounds

        for k in ticks:
            k0, k1 = window_bounds(int(k), window_ticks, source.n_ticks, "centre")
            yield int(k), spike_counts(source, k0, k1) / (k1 - k0)
        return
    from viform.imaging.sequence import reconstruct_ticks

    kw = {"spikes_per_side": spikes_per_side} if method == "multi-interval" else {}
    for k, image in reconstruct_ticks(source, method, ticks, **kw):
        yield k, image.spikes_per_s / source.clock_hz


def check_interval(source, t_s: float, dt_s: float, names=("--at", "--dt")) -> tuple[int, int]:
    """The ticks of t and t + dt in ``source``; refuses dt ≤ 0 and instants outside the stream."""
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


def estimate_flow(source, t_s: float, dt_s: float, *, method: str = "multi-interval", spikes_per_side: int = 4,
                  window_ticks: int = 41, preset: str = "fast") -> FlowEstimate:
    """Forward optical flow (px) from ``t_s`` to ``t_s + dt_s`` estimated from a spike stream.

    Parameters
    ----------
    source : SpikeSource
        Any spike stream viform reads (no truth needed).
    t_s, dt_s : float
        First instant and flow interval, s (both instants inside the stream).
    method : {"multi-interval", "interval", "accumulation"}
        How the light at each instant is imaged (see :mod:`viform.imaging`).
    spikes_per_side : int
        Multi-interval K (4: 7 intervals).
    window_ticks : int
        Accumulation window, ticks.
    preset : {"ultrafast", "fast", "medium"}
        OpenCV DIS preset (``fast``: see the module notes).

    Returns
    -------
    FlowEstimate
        The flow is measured between the middles of the two instants' ticks.
    """
    check_choice("method", method, IMAGE_METHODS)
    spikes_per_side = check_int("spikes_per_side", spikes_per_side, 1)
    window_ticks = check_int("window_ticks", window_ticks, 1)
    tick0, tick1 = check_interval(source, t_s, dt_s, names=("t_s", "dt_s"))
    (_, rate0), (_, rate1) = rate_images(source, [tick0, tick1], method, spikes_per_side, window_ticks)
    image0, image1, (lo, hi) = log_light_pair_8bit(rate0, rate1)
    flow = flow_between_images(image0, image1, preset).astype(np.float32)
    # each image stands for the middle of its tick
    t0 = source.start_time_s + (tick0 + 0.5) / source.clock_hz
    t1 = source.start_time_s + (tick1 + 0.5) / source.clock_hz
    return FlowEstimate(flow, t0, t1, (image0, image1),
                        {"method": method, "spikes_per_side": spikes_per_side, "preset": preset,
                         "log_rate_range": [lo, hi], "ticks": [tick0, tick1]})


def flow_sequence(source, step_ticks: int, *, method: str = "multi-interval", spikes_per_side: int = 4,
                  window_ticks: int = 41, preset: str = "fast", start_tick: int = 0, stop_tick: int | None = None):
    """Yield ``(tick0, tick1, flow (2, H, W))`` between instants ``step_ticks`` apart over a stream.

    Images are reconstructed once each (consecutive pairs share one), so a stream of N
    instants costs N images and N − 1 flow fields.
    """
    check_choice("method", method, IMAGE_METHODS)
    step_ticks = check_int("step_ticks", step_ticks, 1)
    stop = source.n_ticks if stop_tick is None else min(stop_tick, source.n_ticks)
    ticks = list(range(check_int("start_tick", start_tick, 0), stop, step_ticks))
    if len(ticks) < 2:
        raise ViformError(f"the stream has fewer than two instants {step_ticks} ticks apart")
    previous = None
    for tick, rate in rate_images(source, ticks, method, spikes_per_side, window_ticks):
        if previous is not None:
            image0, image1, _ = log_light_pair_8bit(previous[1], rate)
            yield previous[0], tick, flow_between_images(image0, image1, preset)
        previous = (tick, rate)


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
                scores: FlowScores | None = None) -> Path:
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
    if scores is not None and scores.pixels:
        text += f"\nEPE {scores.epe_px:.3g} px, Fl {100 * scores.fl_outliers:.3g} % over {scores.pixels:,} px"
    fig.suptitle(text, fontsize=10)
    fig.tight_layout()
    save_figure(path, fig)
    plt.close(fig)
    return Path(path)


def check_dt(dt_s, name: str = "--dt") -> float:
    """A flow interval > 0 s."""
    return check_positive(name, dt_s)
