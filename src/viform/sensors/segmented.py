"""Segmented-exposure HDR pixel (seed 001: 5T global-shutter pixel with a stepped Rpd barrier).

The exposure is split into N segments of durations T1..TN (seed 001, §2, fig. 3). During
segment i the reset gate Rpd is held at a voltage that sets a barrier φi on the
photodiode: charge above the barrier spills over Rpd to the supply (seed 001, §3.1,
fig. 4). The barriers rise from segment to segment (V2 > V3 > V4 ⇒ φ1 < φ2 < φ3), the
last one being the photodiode's own full well.

Because photo-charge only ever grows during a segment, draining the excess continuously
leaves exactly ``min(Q_start + collected, barrier)`` at the segment's end, so the model
clamps once per segment::

    Q_0 = 0,   Q_i = min(Q_{i-1} + n_i, B_i)   (i = 1..N, B_N ≤ full well)

where n_i is the Poisson photo + dark charge collected in segment i (exact at small
counts). A small signal never reaches B_1, so its output is identical to the normal
mode over the whole exposure (seed 001, §3.3, curve 3 of fig. 6). A large signal loses
the excess at each knee; after the last knee its output grows with slope T_N / T until
Q_{N-1} + r·T_N reaches the full well, which extends the saturating photo-rate from
FW/T to (FW − B_{N−1})/T_N (seed 001, §3.3, curve 2 of fig. 6).

Knees of the noise-free response (photo-rate r in e⁻/s, T = ΣT_i): segment k's barrier
is first reached at r_k where Q_k = B_k, with Q_{k−1} already clamped at B_{k−1};
i.e. r_1 = B_1/T_1 and r_k = (B_k − B_{k−1})/T_k for later knees (when they are ordered,
as in the seed's figures). The output at a knee equals the normal-mode output, since
below it the pixel has lost nothing.
"""

from __future__ import annotations

import numpy as np

from viform._validate import ViformError, check_non_negative, check_positive
from viform.light.scenes import Scene
from viform.sensors.frame import FramePixelParameters, FrameSensor


def check_segments(
    segment_times_s,
    clamp_levels_electrons,
    full_well_electrons: float,
    frame_period_s: float | None = None,
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Validate segment durations and barriers; return them as tuples (N times, N levels).

    ``clamp_levels_electrons`` may have N − 1 entries (the last segment is then capped by the
    full well) or N entries (the last must not exceed the full well). Levels must increase
    strictly (seed 001, §2: V2 > V3 > V4, so φ1 < φ2 < φ3).
    """
    times = np.atleast_1d(np.asarray(segment_times_s, dtype=np.float64))
    if times.ndim != 1 or times.size < 1:
        raise ViformError("segment_times_s must be a non-empty list of durations in seconds")
    for i, t in enumerate(times):
        check_positive(f"segment_times_s[{i}]", t)
    if frame_period_s is not None and times.sum() > frame_period_s * (1 + 1e-9):
        raise ViformError(
            f"segment_times_s sum to {times.sum():g} s, which exceeds the frame period "
            f"{frame_period_s:g} s; shorten the segments or lower frame_rate_hz"
        )
    levels = np.atleast_1d(np.asarray(clamp_levels_electrons, dtype=np.float64))
    n = times.size
    if levels.size == n - 1:
        levels = np.append(levels, full_well_electrons)
    elif levels.size != n:
        raise ViformError(
            f"clamp_levels_electrons has {levels.size} entries; give one per segment "
            f"({n}) or one per segment but the last ({n - 1}, the last is the full well)"
        )
    for i, b in enumerate(levels):
        check_positive(f"clamp_levels_electrons[{i}]", b)
    if n > 1 and not np.all(np.diff(levels) > 0):
        raise ViformError(
            f"clamp_levels_electrons = {levels.tolist()} must increase strictly from "
            "segment to segment (seed 001: the Rpd barrier rises, V2 > V3 > V4)"
        )
    if levels[-1] > full_well_electrons * (1 + 1e-12):
        raise ViformError(
            f"clamp_levels_electrons[-1] = {levels[-1]:g} exceeds the full well "
            f"{full_well_electrons:g} e⁻"
        )
    return tuple(float(t) for t in times), tuple(float(b) for b in levels)


def segmented_charge_electrons(rate_e_per_s, segment_times_s, clamp_levels_electrons) -> np.ndarray:
    """Noise-free charge kept at the end of the exposure (seed 001, §3.2–3.3, fig. 6).

    ``Q_i = min(Q_{i-1} + r·T_i, B_i)``; ``rate_e_per_s`` is the photo + dark electron rate.
    """
    q = np.zeros_like(np.asarray(rate_e_per_s, dtype=np.float64))
    for t, b in zip(segment_times_s, clamp_levels_electrons, strict=True):
        q = np.minimum(q + np.asarray(rate_e_per_s, dtype=np.float64) * t, b)
    return q


def knee_rates_e_per_s(segment_times_s, clamp_levels_electrons) -> np.ndarray:
    """Photo-rates (e⁻/s) at which the noise-free response bends, in order (seed 001, fig. 9).

    Found exactly from the piecewise-linear response: the k-th knee is where segment k's
    barrier starts to bind. The last entry is the saturating rate.
    """
    times = np.asarray(segment_times_s, dtype=np.float64)
    levels = np.asarray(clamp_levels_electrons, dtype=np.float64)
    knees = []
    for k in range(times.size):
        # Charge at the end of segment k is min over j ≤ k of B_j + r·Σ_{j<i≤k} T_i (and r·Σ T_i);
        # barrier k binds from the rate where its term becomes the minimum.
        lo, hi = 0.0, levels[k] / times[: k + 1].sum() * 1e6 + 1.0

        def binds(r, k=k):
            q = segmented_charge_electrons(np.array([r]), times[: k + 1], levels[: k + 1])[0]
            return q >= levels[k] * (1 - 1e-12)

        if not binds(hi):
            continue
        for _ in range(200):  # bisection on a monotone predicate
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if binds(mid) else (mid, hi)
        knees.append(hi)
    return np.array(knees)


class SegmentedExposureSensor(FrameSensor):
    """Global-shutter frame camera with a segmented, barrier-clamped exposure (seed 001).

    Parameters
    ----------
    parameters : FramePixelParameters
        The pixel (QE, full well, noise, ADC …), shared with the normal-mode camera.
    segment_times_s : sequence of float
        Segment durations T1..TN, seconds (seed 001, fig. 3). Their sum is the exposure.
    clamp_levels_electrons : sequence of float
        Barrier B_i kept at the end of each segment, e⁻ (N − 1 values, the last segment
        being capped by the full well, or N values). Must increase strictly.
    frame_rate_hz, height, width, noise, fixed_pattern_seed
        As :class:`~viform.sensors.frame.FrameSensor`.

    Notes
    -----
    ``capture_frame(scene, start_s, exposure_s)`` scales every segment by
    ``exposure_s / ΣT_i`` (barriers unchanged), so exposure sweeps keep the segment ratios
    — the seed notes the extension depends only on those ratios (seed 001, §4).
    Each segment integrates the scene's mean illuminance over its own window, so
    time-varying scenes are handled.
    """

    name = "segmented"

    def __init__(
        self,
        parameters: FramePixelParameters | None = None,
        segment_times_s=(108.333e-6, 21.667e-6),
        clamp_levels_electrons=(4166.7,),
        frame_rate_hz: float = 60.0,
        height: int | None = None,
        width: int | None = None,
        noise: bool = True,
        fixed_pattern_seed: int = 1288,
    ):
        parameters = parameters or FramePixelParameters(full_well_electrons=10_000.0)
        check_positive("frame_rate_hz", frame_rate_hz)
        times, levels = check_segments(
            segment_times_s,
            clamp_levels_electrons,
            parameters.full_well_electrons,
            1.0 / float(frame_rate_hz),
        )
        super().__init__(
            parameters,
            exposure_s=sum(times),
            frame_rate_hz=frame_rate_hz,
            height=height,
            width=width,
            noise=noise,
            fixed_pattern_seed=fixed_pattern_seed,
        )
        self.segment_times_s = times
        self.clamp_levels_electrons = levels

    @property
    def n_segments(self) -> int:
        return len(self.segment_times_s)

    def scaled_segments_s(self, exposure_s: float) -> np.ndarray:
        """Segment durations scaled to a total of ``exposure_s``."""
        check_non_negative("exposure_s", exposure_s)
        times = np.asarray(self.segment_times_s)
        return times * (exposure_s / times.sum())

    def charge_electrons(
        self,
        scene: Scene,
        start_s: float,
        exposure_s: float,
        rng: np.random.Generator,
        height: int,
        width: int,
    ) -> np.ndarray:
        """Charge kept after the last segment (before the full-well clip of the readout)."""
        pixels = self.pixel_array(height, width)
        q = np.zeros((height, width))
        t0 = float(start_s)
        for t, b in zip(
            self.scaled_segments_s(exposure_s), self.clamp_levels_electrons, strict=True
        ):
            lux = scene.mean_illuminance_lux(t0, t0 + t)
            # Excess above the barrier is drained over Rpd (seed 001, §3.1).
            q = np.minimum(q + pixels.collect_electrons(lux, float(t), rng, self.noise), b)
            t0 += float(t)
        return q

    def capture_frame(
        self,
        scene: Scene,
        start_s: float,
        exposure_s: float | None = None,
        *,
        seed: int = 0,
        frame_index: int = 0,
    ) -> np.ndarray:
        """One frame whose exposure [start_s, start_s + exposure_s] is split into the segments."""
        exposure_s = self.exposure_s if exposure_s is None else exposure_s
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = self.pixel_array(height, width)
        rng = pixels.rng(seed, frame_index)
        q = self.charge_electrons(scene, start_s, exposure_s, rng, height, width)
        return pixels.digitize(q, rng, self.noise)

    def expected_charge_electrons(self, lux, exposure_s: float | None = None) -> np.ndarray:
        """Noise-free kept charge for a constant illuminance (no PRNU), e⁻."""
        exposure_s = self.exposure_s if exposure_s is None else exposure_s
        p = self.parameters
        rate = p.optics.electrons_per_s(lux) + p.dark_current_e_per_s
        return segmented_charge_electrons(
            rate, self.scaled_segments_s(exposure_s), self.clamp_levels_electrons
        )

    def knee_lux(self) -> np.ndarray:
        """Illuminances (lux) of the response's knees; the last is the saturating illuminance."""
        p = self.parameters
        rates = knee_rates_e_per_s(self.segment_times_s, self.clamp_levels_electrons)
        return np.maximum(rates - p.dark_current_e_per_s, 0.0) / p.optics.electrons_per_lux_second

    def describe(self) -> dict:
        d = super().describe()
        d.update(
            model=self.name,
            segment_times_s=list(self.segment_times_s),
            clamp_levels_electrons=list(self.clamp_levels_electrons),
        )
        return d
