"""Auto-exposure by gray-level feedback with a dead band (seed 002 §3.2.4, eq. (6)).

Seed 002 eq. (5): the collected charge Q = η q Δn A T_c is proportional to the integration
time, so with the previous frame's metered gray R_p at exposure T_p the exposure that gives
the target gray R_i is (eq. (6))

    T_i = T_p · R_i / R_p                                                            (A1)

The target is a band, not a value: the exposure is left alone while R_p lies in
[R_i − 15, R_i + 15] (seed: a fixed value would make the loop hunt). The exposure is a whole
number N of clock periods T_H (the AB_n gate), 1 ≤ N < cycles per frame.

Metering. The seed meters the mean gray and notes (§4, §5) that it fails when target and
background differ strongly, proposing a weighted gray as future work. Besides
:class:`MeanMeter` we provide :class:`WeightedMeter` (centre- or region-weighted mean, the
region-weighted metering of the seed's refs. [13-14]) and :class:`PercentileMeter` (meter a
high percentile, which protects small bright targets from saturating).

Saturation (optional, off by default). While most pixels sit at the top level the mean is
≤ 255, so (A1) can cut N by at most R_i/255 ≈ ½ per update, and with the one-frame latency of
the global shutter (§3.2.4: the next frame exposes while this one is read out) a 10× step
takes 4 updates = 8 frames. The true (unclipped) mean is not observable — the full well and
the ADC clip before the FPGA sees the data — so no reading of R_p can do better. The seed's
own histogram (§3.2.2) does give the saturated fraction n_255/N, and the seed asks only that
N be reduced while the gray lies right of the band ("逐渐减小 N"). With ``saturated_cut`` = k
the controller uses

    T_i = T_p · min(k, (R_i − b)/(R_p − b))   while n_255/N ≥ ``saturated_fraction``     (A2)

(k = 1/8 is a 3-bit shift in the FPGA). The frame after such a cut is mostly unsaturated, so
(A1) then lands in the band: a 10× step settles in 4 frames instead of 8; a cut that
overshoots low is undone by one linear (A1) update, with no oscillation.

Black level: (A1) assumes gray ∝ exposure; with a black offset b the controller uses
T_i = T_p · (R_i − b) / (R_p − b) (b = 0 gives the seed's form exactly).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_int, check_non_negative, check_range


class MeanMeter:
    """The seed's feedback signal: the mean gray of the frame."""

    name = "mean"

    def __call__(self, gray8) -> float:
        return float(np.mean(gray8))


class WeightedMeter:
    """Weighted mean gray, Σ w·g / Σ w.

    ``weights`` of the frame's shape, or None for a centre-weighted Gaussian whose width is
    ``sigma_fraction`` of the frame's height and width.
    """

    name = "weighted"

    def __init__(self, weights=None, sigma_fraction: float = 0.12):
        self.weights = None if weights is None else np.asarray(weights, dtype=np.float64)
        if self.weights is not None and (self.weights.min() < 0 or self.weights.sum() <= 0):
            raise ViformError("weights must be ≥ 0 with a positive sum")
        self.sigma_fraction = check_range("sigma_fraction", sigma_fraction, 0, 10, low_open=True)
        self._cache: dict[tuple[int, int], np.ndarray] = {}

    def weights_for(self, shape) -> np.ndarray:
        if self.weights is not None:
            if self.weights.shape != tuple(shape):
                raise ViformError(f"weights shape {self.weights.shape} differs from the frame "
                                  f"{tuple(shape)}")
            return self.weights
        if tuple(shape) not in self._cache:
            h, w = shape
            y = (np.arange(h) - (h - 1) / 2) / (self.sigma_fraction * h)
            x = (np.arange(w) - (w - 1) / 2) / (self.sigma_fraction * w)
            self._cache[tuple(shape)] = np.exp(-0.5 * (y[:, None] ** 2 + x[None, :] ** 2))
        return self._cache[tuple(shape)]

    def __call__(self, gray8) -> float:
        g = np.asarray(gray8, dtype=np.float64)
        w = self.weights_for(g.shape)
        return float((w * g).sum() / w.sum())


class PercentileMeter:
    """The ``percentile``-th percentile of the gray levels (use a high target, e.g. 200)."""

    name = "percentile"

    def __init__(self, percentile: float = 99.0):
        self.percentile = check_range("percentile", percentile, 0, 100)

    def __call__(self, gray8) -> float:
        return float(np.percentile(np.asarray(gray8), self.percentile))


METERS = {"mean": MeanMeter, "weighted": WeightedMeter, "percentile": PercentileMeter}


def make_meter(name: str):
    from viform._validate import check_choice

    return METERS[check_choice("meter", name, tuple(METERS))]()


@dataclass
class AutoExposure:
    """Dead-band proportional exposure control in clock cycles (seed 002 §3.2.4, (A1)).

    Parameters
    ----------
    max_exposure_cycles : int
        Upper bound on N: cycles per frame − 1 (``ReadoutTiming.max_exposure_cycles``).
    target_gray : float
        R_i, 0–255.
    band_gray : float
        Half-width of the dead band (15 in the seed).
    meter : callable
        gray8 image → metered gray (default :class:`MeanMeter`).
    black_level_gray : float
        Gray of a dark frame, subtracted before (A1).
    min_exposure_cycles : int
    saturated_cut : float or None
        k of (A2), 0 < k < 1; None (default) is the seed's (A1) alone.
    saturated_fraction : float
        Fraction of pixels at ``saturation_gray`` that triggers (A2).
    saturation_gray : float
        Gray level counted as saturated (255: the top of the 8-bit path).
    """

    max_exposure_cycles: int
    target_gray: float = 128.0
    band_gray: float = 15.0
    meter: object = None
    black_level_gray: float = 0.0
    min_exposure_cycles: int = 1
    saturated_cut: float | None = None
    saturated_fraction: float = 0.5
    saturation_gray: float = 255.0

    def __post_init__(self):
        check_int("max_exposure_cycles", self.max_exposure_cycles, 1)
        self.target_gray = check_range("target_gray", self.target_gray, 0, 255)
        self.band_gray = check_non_negative("band_gray", self.band_gray)
        self.black_level_gray = check_range("black_level_gray", self.black_level_gray, 0, 255)
        if self.target_gray <= self.black_level_gray:
            raise ViformError(f"target_gray = {self.target_gray:g} must exceed the black level "
                              f"{self.black_level_gray:g}")
        check_int("min_exposure_cycles", self.min_exposure_cycles, 1, self.max_exposure_cycles)
        if self.meter is None:
            self.meter = MeanMeter()
        if self.saturated_cut is not None:
            self.saturated_cut = check_range("saturated_cut", self.saturated_cut, 0, 1, low_open=True,
                                             high_open=True)
        self.saturated_fraction = check_range("saturated_fraction", self.saturated_fraction, 0, 1,
                                              low_open=True)
        self.saturation_gray = check_range("saturation_gray", self.saturation_gray, 1, 255)

    def in_band(self, metered_gray: float) -> bool:
        return abs(metered_gray - self.target_gray) <= self.band_gray

    def next_exposure(self, metered_gray: float, exposure_cycles: int) -> int:
        """N for a later frame from the metered gray of a frame exposed for ``exposure_cycles``."""
        n = check_int("exposure_cycles", exposure_cycles, 1)
        if self.in_band(metered_gray):
            return n
        b = self.black_level_gray
        # Half a level floor: a black frame must not divide by zero; it lengthens N at most ×2R_i.
        ratio = (self.target_gray - b) / max(metered_gray - b, 0.5)
        return int(np.clip(round(n * ratio), self.min_exposure_cycles, self.max_exposure_cycles))

    def update(self, gray8, exposure_cycles: int) -> tuple[float, int]:
        """Meter ``gray8`` and return (metered gray, next exposure cycles): (A1), or (A2) when
        ``saturated_cut`` is set and the frame is mostly saturated."""
        r = self.meter(gray8)
        nxt = self.next_exposure(r, exposure_cycles)
        if self.saturated_cut is not None and r > self.target_gray + self.band_gray:
            saturated = float(np.mean(np.asarray(gray8) >= self.saturation_gray))
            if saturated >= self.saturated_fraction:
                cut = int(np.clip(round(exposure_cycles * self.saturated_cut), self.min_exposure_cycles,
                                  self.max_exposure_cycles))
                nxt = min(nxt, cut)
        return r, nxt


def settle_frames(metered_gray, target_gray: float, band_gray: float, start: int) -> int | None:
    """Frames from ``start`` until the metered gray enters the band and stays (None: never)."""
    g = np.asarray(metered_gray, dtype=np.float64)[start:]
    inside = np.abs(g - target_gray) <= band_gray
    if not inside.any() or not inside[-1]:
        return None
    outside = np.flatnonzero(~inside)
    return 0 if outside.size == 0 else int(outside[-1] + 1)
