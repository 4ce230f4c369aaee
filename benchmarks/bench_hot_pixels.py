"""Hot-pixel detection of ``viform calibrate`` on simulated recordings with realistic texture.

Each scene is shot with the spike camera (``SpikeSensor``, exact photon statistics, 2 % PRNU)
at Q = 1,000 and 16,250 e⁻, 400 ticks at 40 kHz, its light spanning 0.01–0.30 spikes per tick,
twice per seed: a twin with no hot pixels, and one where 1 % of the pixels (placed at random
by the sensor's fixed pattern) hold a dark current of 0.1 spikes per tick (4·10⁶ e⁻/s at
Q = 1,000; the figure the shared 400×250 recording gave at Q = 16,250). The truth is the
sensor's own dark-current map, independent of the detector.

Scenes: ``ramp`` (smooth), ``strip`` (a 3.4-px bright strip under a dark edge, edges at
sub-pixel positions), and scikit-image's data images, area-sampled to the sensor. The
detector's constants (``HOT_SIGMAS``, ``HOT_EDGE_FRACTION``) were chosen on the TUNING
scenes; the REPORT scenes were not looked at while choosing them.

Printed per scene and Q, over the seeds: reports per 10⁵ pixels on the twin without hot
pixels (goal ≤ 1), the share of the true hot pixels found (all; and among the pixels the
calibration says can show them), the share of reports that are false (goal ≤ 5 %), how many
seeds give a measured hot fraction and in how many its 95 % range (Wilson's) holds the twin's
true hot fraction (goal ≥ 90 %; beside it, how often it holds the 1 % the sensor's fixed
pattern was drawn with, which each twin misses by its own binomial draw), the fitted dark
current / the true one.

Run: ``python benchmarks/bench_hot_pixels.py [--seeds 20] [--scenes ramp,camera]``; with
``PYTHONPATH=<an older checkout>/src`` the same harness scores that version's detector.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from viform.light.scenes import StillScene
from viform.measure import calibration as cal
from viform.sensors.spike import SpikeSensor

TUNING = ("ramp", "strip", "camera", "brick", "astronaut")
REPORT = ("coins", "moon", "text", "page", "clock", "gravel", "grass")
RATE_MIN, RATE_MAX = 0.01, 0.30
HOT_RATE = 0.1
CLOCK_HZ = 40e3


def scene_image(kind: str, height: int, width: int) -> np.ndarray:
    """Relative light in [0, 1] of a scene, (height, width)."""
    if kind == "ramp":
        return np.repeat(np.linspace(0.0, 1.0, width)[None], height, 0)
    if kind == "strip":
        y = np.arange(height)[:, None].astype(float)
        top = height * 0.4 + 0.3 * np.sin(np.arange(width)[None] / 17.0)
        bottom = top + 3.4

        def inside(a, b):  # the share of each pixel's row span [y, y + 1) inside [a, b)
            return np.clip(np.minimum(b, y + 1) - np.maximum(a, y), 0.0, 1.0)

        dark = inside(-np.inf, top)
        bright = inside(top, bottom)
        return 0.45 * (1 - dark - bright) + 0.03 * dark + 1.0 * bright
    from skimage import data, transform

    img = getattr(data, kind)()
    if img.ndim == 3:
        img = img[..., :3].mean(axis=2)
    return transform.resize(img.astype(float) / 255.0, (height, width), anti_aliasing=True, order=1)


def recording(kind: str, q: float, hot_fraction: float, seed: int, height: int = 128, width: int = 160,
              ticks: int = 400, prnu: float = 0.02):
    """(spike stream, true hot-pixel map) of one scene and seed."""
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=20.0, hot_pixel_fraction=hot_fraction,
                         hot_pixel_dark_current_e_per_s=HOT_RATE * q * CLOCK_HZ, gain_spread_fraction=prnu,
                         fixed_pattern_seed=1000 + seed, clock_hz=CLOCK_HZ)
    rate = RATE_MIN + (RATE_MAX - RATE_MIN) * scene_image(kind, height, width)
    lux = sensor.parameters.optics.lux_from_electrons_per_s(rate * q * CLOCK_HZ)
    rec = sensor.capture(StillScene(lux), ticks / CLOCK_HZ, seed=seed)
    truth = sensor.dark_current_map_e_per_s(height, width) > 0.5 * HOT_RATE * q * CLOCK_HZ
    return rec, truth


def score(kind: str, q: float, seeds) -> dict:
    null_reports = null_pixels = found = false = true_hot = found_s = true_s = 0
    measured = covered = covered_parameter = 0
    ratios = []
    for seed in seeds:
        rec, _ = recording(kind, q, 0.0, seed)
        d, hot, _ = cal._hot_dead(cal.interval_statistics(rec), q)
        null_reports += int(hot.sum())
        null_pixels += hot.size
        rec, truth = recording(kind, q, 0.01, seed)
        st = cal.interval_statistics(rec)
        d, hot, dead = cal._hot_dead(st, q)
        found += int((hot & truth).sum())
        false += int((hot & ~truth).sum())
        true_hot += int(truth.sum())
        level = d.get("hot_pixel_dark_current_e_per_s")
        if level and hasattr(cal, "hot_pixel_statistics"):
            limit = cal.hot_pixel_statistics(st, q)["limit"] * q * CLOCK_HZ
            searchable = (limit <= cal.HOT_SEARCH_MARGIN * level) & ~dead
            found_s += int((hot & truth & searchable).sum())
            true_s += int((truth & searchable).sum())
        fraction, span = d.get("hot_pixel_fraction"), d.get("hot_pixel_fraction_range")
        if fraction and not span and d.get("hot_pixel_fraction_standard_error"):  # an older version: ± 1.96 SE
            span = [fraction - 1.96 * d["hot_pixel_fraction_standard_error"],
                    fraction + 1.96 * d["hot_pixel_fraction_standard_error"]]
        if fraction and span:
            measured += 1
            covered += span[0] <= truth.mean() <= span[1]  # this twin's own hot fraction
            covered_parameter += span[0] <= 0.01 <= span[1]  # the sensor parameter it was drawn with
        if level:
            ratios.append(level / (HOT_RATE * q * CLOCK_HZ))
    return {"null_per_1e5": 1e5 * null_reports / null_pixels, "recall": found / max(true_hot, 1),
            "recall_searchable": found_s / true_s if true_s else float("nan"), "true_searchable": true_s,
            "false_share": false / max(found + false, 1), "measured": measured, "covered": covered,
            "covered_parameter": covered_parameter,
            "dark_current_ratio": float(np.mean(ratios)) if ratios else float("nan")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--scenes", default=",".join(TUNING + REPORT))
    args = parser.parse_args()
    print(f"{'scene':<11}{'set':<7}{'Q':>7} {'null/1e5':>9} {'found':>7} {'in S':>12} {'false':>7} "
          f"{'measured':>9} {'covered':>8} {'(1 %)':>6} {'D/true':>7} {'s':>5}")
    for kind in args.scenes.split(","):
        for q in (1000.0, 16250.0):
            started = time.perf_counter()
            r = score(kind, q, range(args.seeds))
            print(f"{kind:<11}{'tune' if kind in TUNING else 'report':<7}{q:>7.0f} {r['null_per_1e5']:>9.2f} "
                  f"{r['recall']:>7.3f} {r['recall_searchable']:>6.3f} ({r['true_searchable']:>4d}) "
                  f"{r['false_share']:>7.3f} {r['measured']:>5d}/{args.seeds:<3d} {r['covered']:>8d} "
                  f"{r['covered_parameter']:>6d} "
                  f"{r['dark_current_ratio']:>7.3f} {time.perf_counter() - started:>5.0f}", flush=True)


if __name__ == "__main__":
    main()
