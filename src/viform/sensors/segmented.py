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
        # checked before the order, so a barrier above the well is named as such
        if b > full_well_electrons * (1 + 1e-12):
            raise ViformError(
                f"clamp_levels_electrons[{i}] = {b:g} exceeds the full well {full_well_electrons:g} e⁻; "
                "a barrier can be at most the full well"
            )
    if n > 1 and not np.all(np.diff(levels) > 0):
        raise ViformError(
            f"clamp_levels_electrons = {levels.tolist()} must increase strictly from "
            "segment to segment (seed 001: the Rpd barrier rises, V2 > V3 > V4)"
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


def soft_clamp_electrons(q_start, rate_e_per_s, duration_s: float, barrier_electrons, softness_electrons: float,
                         reference_e_per_s: float) -> np.ndarray:
    """Charge left after a segment behind a *soft* (sub-threshold) Rpd barrier (seed 001 §3.1).

    Below threshold the Rpd drain carries I(Q) = I_0·exp((Q − B)/Q_T): I_0 at the nominal
    barrier B, growing e-fold every Q_T = n·(kT/q)·C_PD/q electrons (≈ 560 e⁻ for n = 1.3 at
    60 µV/e⁻, 300 K). With photo-rate r the charge obeys dQ/dt = r − I(Q); in u = e^{−(Q−B)/Q_T}
    this is linear, du/dt = (I_0 − r·u)/Q_T, so exactly (a = r·t/Q_T)::

        u(t) = u_0·e^{−a} + (I_0·t/Q_T)·(1 − e^{−a})/a,    Q(t) = B − Q_T·ln u(t)

    The clamp therefore depends on the light and the time: in equilibrium (a ≫ 1) it sits at
    B + Q_T·ln(r/I_0), above B for r > I_0 and below it for dim light held long enough.
    ``softness_electrons = 0`` is the hard clamp min(Q_0 + r·t, B).
    """
    q0 = np.asarray(q_start, dtype=np.float64)
    r = np.broadcast_to(np.asarray(rate_e_per_s, dtype=np.float64), np.broadcast_shapes(q0.shape,
                                                                                          np.shape(rate_e_per_s)))
    b = np.asarray(barrier_electrons, dtype=np.float64)
    if softness_electrons == 0:
        return np.minimum(q0 + r * duration_s, b)
    qt = float(softness_electrons)
    a = r * duration_s / qt
    # (1 − e^{−a})/a → 1 as a → 0; all in logs: u_0 = e^{(B − Q_0)/Q_T} may be astronomically large
    frac = np.where(a > 1e-12, -np.expm1(-a) / np.where(a > 1e-12, a, 1.0), 1.0)
    log_u = np.logaddexp((b - q0) / qt - a, np.log(reference_e_per_s * duration_s / qt * frac))
    return np.maximum(b - qt * log_u, 0.0)  # the drain cannot take more than the photodiode holds


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
    barrier_spread_fraction : float
        Pixel-to-pixel spread (std / mean, Gaussian, fixed pattern) of every barrier: the Rpd
        threshold varies across the array, so above a knee the clamped charge — and the output
        — differs from pixel to pixel (fixed-pattern noise above the knees). Default 0.
    barrier_softness_electrons : float
        Q_T of a sub-threshold (soft) Rpd barrier, e⁻ (:func:`soft_clamp_electrons`): the clamp
        level then depends on the photocurrent and the time. Default 0 (hard clamp); typical
        n·(kT/q)·C_PD/q ≈ 560 e⁻ for this pixel.
    barrier_reference_e_per_s : float
        I_0, the Rpd drain current (e⁻/s) at which the charge sits at the nominal barrier.
        Default 1e7 e⁻/s (1.6 pA); used only when the barrier is soft.
    clamp_noise_electrons : float
        Temporal noise of the charge a binding barrier leaves, e⁻ rms (Gaussian, drawn at the
        end of each segment whose barrier binds): the drain is a sub-threshold transistor,
        whose equilibrium spread is of order √(n·kT·C_PD)/q ≈ 24 e⁻ here. Default 0.

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
        barrier_spread_fraction: float = 0.0,
        barrier_softness_electrons: float = 0.0,
        barrier_reference_e_per_s: float = 1e7,
        clamp_noise_electrons: float = 0.0,
    ):
        parameters = parameters or FramePixelParameters(full_well_electrons=10_000.0)
        self.barrier_spread_fraction = check_non_negative("barrier_spread_fraction", barrier_spread_fraction)
        self.barrier_softness_electrons = check_non_negative("barrier_softness_electrons",
                                                             barrier_softness_electrons)
        self.barrier_reference_e_per_s = check_positive("barrier_reference_e_per_s", barrier_reference_e_per_s)
        self.clamp_noise_electrons = check_non_negative("clamp_noise_electrons", clamp_noise_electrons)
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
        self._barrier_maps: dict = {}

    def barrier_map_electrons(self, height: int, width: int) -> np.ndarray:
        """Per-pixel barriers (N, H, W), e⁻: the nominal ones times 1 + s·N(0, 1) (fixed
        pattern, seeded by ``fixed_pattern_seed``), clipped to [0, full well]."""
        key = (height, width)
        if key not in self._barrier_maps:
            base = np.asarray(self.clamp_levels_electrons)[:, None, None]
            if self.barrier_spread_fraction > 0:
                rng = np.random.default_rng([self.fixed_pattern_seed, 0xB44])
                spread = 1 + self.barrier_spread_fraction * rng.standard_normal((len(base), height, width))
                m = np.clip(base * spread, 0.0, self.parameters.full_well_electrons)
            else:
                m = np.broadcast_to(base, (len(base), height, width))
            self._barrier_maps[key] = m
        return self._barrier_maps[key]

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
        n_seg = len(self.segment_times_s)
        for i, (t, b) in enumerate(zip(
            self.scaled_segments_s(exposure_s), self.barrier_map_electrons(height, width), strict=True
        )):
            lux = scene.mean_illuminance_lux(t0, t0 + t)
            collected = pixels.collect_electrons(lux, float(t), rng, self.noise)
            if self.barrier_softness_electrons > 0 and i < n_seg - 1:
                # Sub-threshold drain: the kept charge follows the exact soft-clamp law with the
                # segment's collected charge as its mean rate (Poisson count kept below the clamp).
                soft = soft_clamp_electrons(q, collected / float(t), float(t), b, self.barrier_softness_electrons,
                                            self.barrier_reference_e_per_s)
                free = q + collected
                new_q = np.minimum(free, soft)
            else:
                # Excess above the barrier is drained over Rpd (seed 001, §3.1).
                new_q = np.minimum(q + collected, b)
            if self.clamp_noise_electrons > 0 and self.noise:
                bound = new_q < q + collected - 0.5  # the barrier drained something: the drain sets Q
                new_q = new_q + np.where(bound, self.clamp_noise_electrons * rng.standard_normal(q.shape), 0.0)
            q = np.maximum(new_q, 0.0)
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
        # the 5T global shutter's storage node waits for its row to be read (PLS, leakage)
        q = q + pixels.storage_electrons(scene, start_s + exposure_s, rng, self.noise)
        if self.parameters.black_sun_fraction > 0:
            q = pixels.black_sun_electrons(q, scene.mean_illuminance_lux(start_s, start_s + exposure_s))
        return pixels.digitize(q, rng, self.noise)

    def expected_charge_electrons(self, lux, exposure_s: float | None = None) -> np.ndarray:
        """Noise-free kept charge for a constant illuminance (no PRNU), e⁻ (soft barriers included)."""
        exposure_s = self.exposure_s if exposure_s is None else exposure_s
        p = self.parameters
        rate = p.optics.electrons_per_s(lux) + p.dark_current_e_per_s
        times = self.scaled_segments_s(exposure_s)
        if self.barrier_softness_electrons == 0:
            return segmented_charge_electrons(rate, times, self.clamp_levels_electrons)
        q = np.zeros_like(np.asarray(rate, dtype=np.float64))
        for i, (t, b) in enumerate(zip(times, self.clamp_levels_electrons, strict=True)):
            if i < len(times) - 1:
                q = soft_clamp_electrons(q, rate, float(t), b, self.barrier_softness_electrons,
                                         self.barrier_reference_e_per_s)
            else:
                q = np.minimum(q + rate * t, b)
        return q

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
            barrier_spread_fraction=self.barrier_spread_fraction,
            barrier_softness_electrons=self.barrier_softness_electrons,
            barrier_reference_e_per_s=self.barrier_reference_e_per_s,
            clamp_noise_electrons=self.clamp_noise_electrons,
        )
        return d


# ----------------------------------------------------------------------------- Rpd drive

#: Seed 001 Fig. 7: exposure counted in periods of the 48 MHz clock Iclk (20.83 ns).
ICLK_HZ = 48e6
#: Seed 001 Fig. 7: Rpd mid (segment) voltage set in 0.025 V steps, codes 40…96 = 1…2.4 V.
RPD_STEP_V = 0.025


def rpd_voltage_v(code: int) -> float:
    """Rpd segment voltage of a DAC code (seed 001 Fig. 7: "28" hex = 40 → 1.000 V)."""
    return float(code) * RPD_STEP_V


def exposure_s_from_iclk(counts) -> np.ndarray:
    """Exposure in seconds from Iclk counts (48 MHz, seed 001 Fig. 7)."""
    return np.asarray(counts, dtype=np.float64) / ICLK_HZ


class RpdBarrier:
    """Clamp level of the photodiode set by the Rpd gate's segment voltage (seed 001 §3.1, Fig. 7).

    The barrier under Rpd is the gate's channel potential, which follows the gate voltage
    linearly (a constant body factor); the photodiode holds charge until its potential falls
    to that barrier. So the clamp charge falls linearly with the voltage — a higher voltage
    lowers the barrier and the clamp (seed 001: "the larger Rpd's middle voltage, the lower
    the barrier … the less full-well charge") — and is clipped at 0 and at the full well:

        B(V) = FW · clip((V_zero − V) / (V_zero − V_full), 0, 1)

    Two numbers pin it; the seed gives neither. Defaults (assumptions): V_full = 0.9 V (a
    gate this low no longer limits the well) and V_zero = 2.5 V (the barrier is below the
    empty photodiode's potential), so the seed's 1.0–2.4 V sweep spans clamps of 94 % down to
    6 % of the full well and the Fig. 8 barrier (5/12 FW) sits at 1.833 V (code 73).
    """

    def __init__(self, v_full_well_v: float = 0.9, v_zero_v: float = 2.5):
        if not v_zero_v > v_full_well_v:
            raise ViformError(f"v_zero_v = {v_zero_v!r} must be above v_full_well_v = {v_full_well_v!r} "
                              "(a higher Rpd voltage lowers the barrier)")
        self.v_full_well_v = float(v_full_well_v)
        self.v_zero_v = float(v_zero_v)

    def clamp_fraction(self, voltage_v) -> np.ndarray:
        """Clamp level as a fraction of the full well."""
        v = np.asarray(voltage_v, dtype=np.float64)
        return np.clip((self.v_zero_v - v) / (self.v_zero_v - self.v_full_well_v), 0.0, 1.0)

    def voltage_for_fraction(self, fraction) -> np.ndarray:
        """Rpd voltage whose clamp is ``fraction`` of the full well."""
        f = np.asarray(fraction, dtype=np.float64)
        return self.v_zero_v - f * (self.v_zero_v - self.v_full_well_v)


def response_vs_exposure_dn(rate_e_per_s, exposure_s, first_fraction: float, clamp_electrons: float,
                            full_well_electrons: float, gain_dn_per_e: float) -> np.ndarray:
    """Seed 001 Fig. 7: noise-free output (DN above black) against the exposure at a fixed
    light, two segments (the first ``first_fraction`` of the exposure clamped at
    ``clamp_electrons``), clipped at the full well."""
    t = np.asarray(exposure_s, dtype=np.float64)
    q = segmented_charge_electrons(np.full(t.shape, float(rate_e_per_s)), [], [])  # zeros
    q = np.minimum(q + rate_e_per_s * first_fraction * t, clamp_electrons)
    q = np.minimum(q + rate_e_per_s * (1 - first_fraction) * t, full_well_electrons)
    return q * gain_dn_per_e


def three_segment_family(f3_values, knee1_fw: float = 348 / 748, knee2_fw: float = 669.8 / 748,
                         extension: float = 440 / 35) -> list[dict]:
    """The three-segment fits of seed 001 Fig. 9, one per last-segment fraction f3.

    The seed gives three numbers for the three-segment curve: first knee at 348 DN, second
    at 669.8 DN (of 748 DN full scale) and saturation at 12.57 × the normal mode's. The
    model has four unknowns (f1, f2 with f3 = 1 − f1 − f2; barriers b1, b2 in full wells),
    so the fits form a one-parameter family. Noise-free, with r in full wells per exposure:

    * knee 1 where b1 binds: output b1/f1 = knee1  →  b1 = knee1 · f1;
    * saturation: (1 − b2)/f3 = extension  →  b2 = 1 − extension · f3;
    * knee 2 where b2 binds: output b2 + (b2 − b1) f3/f2 = knee2, solved for f1.

    Each member's second knee falls at a different illuminance, 35 (b2 − b1)/f2 in the
    seed's units: reading that knee's intensity off Fig. 9 would pin f3. Members with
    f1, f2 > 0 and 0 < b1 < b2 < 1 are returned.
    """
    rows = []
    for f3 in np.atleast_1d(np.asarray(f3_values, dtype=np.float64)):
        b2 = 1.0 - extension * f3
        # b2 + (b2 − knee1·f1)·f3/(1 − f1 − f3) = knee2  →  linear in f1
        a = knee2_fw - b2
        # a·(1 − f3 − f1) = (b2 − knee1·f1)·f3  →  f1 (a − knee1 f3) = a(1 − f3) − b2 f3
        den = a - knee1_fw * f3
        if den == 0:
            continue
        f1 = (a * (1 - f3) - b2 * f3) / den
        f2 = 1 - f1 - f3
        b1 = knee1_fw * f1
        if not (f1 > 0 and f2 > 0 and 0 < b1 < b2 < 1):
            continue
        rows.append({"fractions": (float(f1), float(f2), float(f3)), "barriers_fw": (float(b1), float(b2)),
                     "knee2_intensity_units": float(35.0 * (b2 - b1) / f2),
                     "knee1_intensity_units": float(35.0 * knee1_fw)})
    return rows


def snr_knee_dips_db(segment_times_s) -> np.ndarray:
    """SNR lost at each knee, dB (noise-free clamp, shot-noise limited).

    Above knee k the kept charge is the clamp B_k (no noise: the excess drained) plus the
    Poisson charge of the segments after k, so the input-referred SNR is √(r·T_after)
    instead of √(r·T_before), with T_before the integration that counted just below the
    knee: a drop of 10·lg(T_before/T_after) — 10·lg(1/(f2 + f3)) = 5.85 dB and
    10·lg((f2 + f3)/f3) = 14.1 dB for the 0.74 : 0.25 : 0.01 fit. Seed 001 (§1.2) claims no
    SNR loss; that holds below the first knee only.
    """
    t = np.asarray(segment_times_s, dtype=np.float64)
    tails = np.cumsum(t[::-1])[::-1]  # T, T − T1, …
    return 10 * np.log10(tails[:-1] / tails[1:])


def expected_snr(rate_e_per_s, segment_times_s, clamp_levels_electrons, read_noise_electrons: float = 0.0,
                 barrier_spread_fraction: float = 0.0, full_well_electrons: float | None = None) -> np.ndarray:
    """Input-referred SNR of the segmented pixel against the photo-rate (noise-free clamps).

    Below every knee: signal r·T, noise √(r·T + σ_r²) → SNR = r·T/√(r·T + σ_r²). Above knee
    k (the last barrier that binds): the output is B_k + r·T_after with slope T_after and
    noise √(r·T_after + σ_r² + (s·B_k)²), s the pixel-to-pixel barrier spread (fixed
    pattern), so SNR = r·T_after / noise. NaN past saturation (where it means nothing).
    """
    r = np.atleast_1d(np.asarray(rate_e_per_s, dtype=np.float64))
    t = np.asarray(segment_times_s, dtype=np.float64)
    b = np.asarray(clamp_levels_electrons, dtype=np.float64)
    q = np.zeros_like(r)
    t_after = np.full_like(r, t.sum())
    bound = np.zeros_like(r)
    for i, (ti, bi) in enumerate(zip(t, b, strict=True)):
        q = q + r * ti
        hit = q >= bi
        q = np.minimum(q, bi)
        # a binding barrier resets the count: what follows is all that adds noise
        t_after = np.where(hit, t[i + 1:].sum(), t_after)
        bound = np.where(hit, bi, bound)
    noise = np.sqrt(r * t_after + read_noise_electrons ** 2 + (barrier_spread_fraction * bound) ** 2)
    snr = np.where(noise > 0, r * t_after / np.where(noise > 0, noise, 1.0), 0.0)
    fw = b[-1] if full_well_electrons is None else full_well_electrons
    return np.where((t_after > 0) & (q < fw * (1 - 1e-12)), snr, np.nan)
