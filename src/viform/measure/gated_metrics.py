"""Contrast-to-noise of gated-imaging targets and the pulses a target needs (seed 004).

"Stands out of the background" (seed 004, field test: glints "distinguishable and not
masked by the background") is made quantitative here as

    CNR = (S_target − S̄_bg) / σ_bg ≥ k,   k = 5 by default (Rose criterion),

with S_target the brightest pixel of the target's image, S̄_bg the mean of a ring of
background pixels around it (radius 4–8 px) and σ_bg the noise of one background pixel:
temporal (Poisson + read noise + quantization, per readout) and spatial (DSNU, PRNU on the
background signal, and the variation of the expected background over the ring).

:func:`pulses_needed` searches the smallest X with expected CNR(X) ≥ k (doubling, then
bisection — CNR grows monotonically with X until the well fills), never fitted to the
seed's counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_int, check_positive
from viform.light.active import ActiveScene

#: Default detection threshold on CNR (Rose criterion).
CNR_THRESHOLD = 5.0


def ring_mask(shape, row: float, col: float, inner_px: float = 4.0, outer_px: float = 8.0) -> np.ndarray:
    """Boolean mask of pixels whose centre lies in the ring inner ≤ d < outer around (row, col)."""
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    d = np.hypot(yy - row, xx - col)
    return (d >= inner_px) & (d < outer_px)


def target_pixel(row: float, col: float) -> tuple[int, int]:
    return int(round(row)), int(round(col))


def measured_cnr(image, row: float, col: float, inner_px: float = 4.0, outer_px: float = 8.0) -> float:
    """CNR of the target at (row, col) in one image (any linear units)."""
    img = np.asarray(image, dtype=np.float64)
    ring = ring_mask(img.shape, row, col, inner_px, outer_px)
    bg = img[ring]
    sd = bg.std(ddof=1)
    r, c = target_pixel(row, col)
    return float((img[r, c] - bg.mean()) / sd) if sd > 0 else math.inf


@dataclass(frozen=True)
class CNRResult:
    cnr: float
    signal_electrons: float
    background_electrons: float
    noise_electrons: float


def expected_cnr(
    sensor,
    scene: ActiveScene,
    row: float,
    col: float,
    pulses: int | None = None,
    per_pulse: dict | None = None,
    mode: str | None = None,
    inner_px: float = 4.0,
    outer_px: float = 8.0,
) -> CNRResult:
    """Expected CNR of the target at (row, col) for ``sensor`` (a GatedInterlineCCD) with X pulses."""
    b = sensor.electron_budget(scene, per_pulse=per_pulse, pulses=pulses, mode=mode)
    mean, var = sensor.expected_frame_stats(budget=b)
    p = sensor.parameters.pixel
    ring = ring_mask(scene.shape, row, col, inner_px, outer_px)
    r, c = target_pixel(row, col)
    bg_mean = float(mean[ring].mean())
    photo_bg = float((b["photo"][ring]).mean())
    spatial = b["readouts"] * p.dsnu_electrons**2 + (p.prnu_fraction * photo_bg) ** 2 + float(mean[ring].var())
    noise = math.sqrt(float(var[ring].mean()) + spatial)
    return CNRResult(
        cnr=(float(mean[r, c]) - bg_mean) / noise,
        signal_electrons=float(mean[r, c]),
        background_electrons=bg_mean,
        noise_electrons=noise,
    )


def pulses_needed(
    sensor,
    scene: ActiveScene,
    row: float,
    col: float,
    threshold: float = CNR_THRESHOLD,
    max_pulses: int = 100_000,
    mode: str | None = None,
) -> int | None:
    """Smallest X with expected CNR ≥ ``threshold``; None if not reached by ``max_pulses``.

    The frame-rate limit is not applied here: compare the answer with
    ``sensor.max_pulses(frame_rate_hz)``.
    """
    check_positive("threshold", threshold)
    check_int("max_pulses", max_pulses, 1)
    pp = sensor.per_pulse_electrons(scene)

    def ok(x):
        return expected_cnr(sensor, scene, row, col, pulses=x, per_pulse=pp, mode=mode).cnr >= threshold

    lo, hi = 0, 1
    while not ok(hi):
        lo = hi
        if hi >= max_pulses:
            return None
        hi = min(2 * hi, max_pulses)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ok(mid):
            hi = mid
        else:
            lo = mid
    return hi


def field_test_table(
    gate_range_m: float = 150.0,
    pulses: int = 20,
    ambient_lux: float = 1e5,
    threshold: float = CNR_THRESHOLD,
    **sensor_kw,
) -> list[dict]:
    """Seed 004 field test: expected CNR of the reflectors at 50/100/200/300 m, gate at 150 m."""
    from viform.light.active import field_test_scene
    from viform.sensors.gated_ccd import GatedInterlineCCD

    scene = field_test_scene(ambient_lux=ambient_lux)
    ccd = GatedInterlineCCD(pulses=pulses, gate_range_m=gate_range_m, **sensor_kw)
    pp = ccd.per_pulse_electrons(scene)
    rows = []
    for r in scene.retroreflectors:
        res = expected_cnr(ccd, scene, r.row, r.col, per_pulse=pp)
        rows.append(
            {
                "range_m": r.range_m,
                "cnr": res.cnr,
                "visible": bool(res.cnr >= threshold),
                "signal_electrons": res.signal_electrons,
                "background_electrons": res.background_electrons,
            }
        )
    return rows


def pulses_needed_vs_ambient(
    ranges_m=(300.0, 800.0),
    ambients_lux=(1e5, 1e4, 1e3, 1.0, 1e-3),
    threshold: float = CNR_THRESHOLD,
    gate_offset_m: float = 50.0,
    frame_rate_hz: float = 25.0,
    retro: dict | None = None,
    **sensor_kw,
) -> list[dict]:
    """Pulses needed for one reflector at each range (gate opened ``gate_offset_m`` before it).

    Returns rows with the range, ambient lux, X needed, whether X fits at ``frame_rate_hz``
    and the output frame rate at that X.
    """
    from viform.light.active import field_test_scene
    from viform.sensors.gated_ccd import GatedInterlineCCD

    if threshold <= 0:
        raise ViformError(f"threshold = {threshold!r} must be > 0")
    rows = []
    for rng in ranges_m:
        gate = max(0.0, rng - gate_offset_m)
        ccd = GatedInterlineCCD(pulses=1, gate_range_m=gate, frame_rate_hz=frame_rate_hz, **sensor_kw)
        for lux in ambients_lux:
            scene = field_test_scene(ranges_m=(rng,), ambient_lux=lux, background_range_m=rng + 700.0, retro=retro)
            rr = scene.retroreflectors[0]
            x = pulses_needed(ccd, scene, rr.row, rr.col, threshold)
            rows.append(
                {
                    "range_m": rng,
                    "ambient_lux": lux,
                    "gate_range_m": gate,
                    "pulses_needed": x,
                    "max_pulses_at_frame_rate": ccd.max_pulses(frame_rate_hz),
                    "fits_frame_rate": x is not None and x <= ccd.max_pulses(frame_rate_hz),
                    "frame_rate_hz_at_x": None if x is None else 1.0 / ccd.frame_time_s(x),
                }
            )
    return rows
