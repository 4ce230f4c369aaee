"""Bias of the light (e⁻/s) that multi-interval and interval imaging give, before and after the
unbiased estimator of ``viform.imaging.rate_law``.

For each case a uniform field is simulated with ``SpikeSensor`` (exact photon statistics, the
case's Q, reset and dead time) at the light λ whose steady firing rate is the case's; images are
taken at instants far enough apart to share no interval, and the mean light over pixels and
instants is compared with λ. Printed per case: the plain inverse of the law r⁻¹(r̂) ("before",
what the images gave) and the image's light now, each as relative bias ± its standard error
(from the spread of the per-instant means), the bias the estimator states for that light, and
the share of pixels it flags ``unresolved``. The truth λ is the simulator's input, independent
of the estimator; the "before" column is the plain baseline computed from the same rates.

Run: ``python benchmarks/bench_light_bias.py [--quick]``.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from viform.imaging import interval_image
from viform.imaging.rate_law import electrons_per_tick_from_rate, light_estimator
from viform.imaging.sequence import reconstruct_ticks
from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor

CLOCK_HZ = 40e3
#: (Q, spikes per tick as a share of the ceiling, dead time in ticks, reset, K); the issue's two
#: figures first (Q = 100 at 1.2 ticks per interval, Q = 1 at 3 ticks), then a grid
CASES = [(100, 1 / 1.2, 0.0, "self", 4), (1, 1 / 3, 0.0, "self", 4)] + [
    (q, r, d, reset, 4) for q in (1, 4, 30, 1000) for r in (0.1, 0.33, 0.6, 0.9)
    for d, reset in ((0.0, "self"), (0.4, "readout"))] + [
    (q, r, 0.0, "self", 1) for q in (1, 10, 100) for r in (0.2, 0.5)]


def measure(q, share, dead_ticks, reset, k, count, side):
    ceiling = 1.0 if reset == "self" else 1.0 / (math.floor(dead_ticks) + 1)
    r = share * ceiling
    lam = float(electrons_per_tick_from_rate(r, q, dead_ticks, reset)[0])
    spacing = int(math.ceil((2 * k + 2) / r)) + 2
    ticks = spacing * (1 + np.arange(count))
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, dead_time_s=dead_ticks / CLOCK_HZ,
                         reset=reset)
    lux = sensor.parameters.optics.lux_from_electrons_per_s(np.full((side, side), lam * CLOCK_HZ))
    stream = sensor.capture(StillScene(lux), spacing * (count + 1) / CLOCK_HZ, seed=11)
    if k == 1:
        images = [interval_image(stream, (t + 0.5) / CLOCK_HZ) for t in ticks]
    else:
        images = [im for _, im in reconstruct_ticks(stream, "multi-interval", ticks, spikes_per_side=k,
                                                    adaptive=False)]
    rates = np.stack([im.spikes_per_s / CLOCK_HZ for im in images]).reshape(count, -1)
    new = np.stack([im.electrons_per_s / CLOCK_HZ for im in images]).reshape(count, -1)
    plain = electrons_per_tick_from_rate(np.minimum(rates, ceiling * (1 - 1e-9)), q, dead_ticks, reset)[0]
    out = {}
    for name, light in (("before", plain), ("after", new)):
        per = light.mean(axis=1) / lam - 1
        out[name] = (float(per.mean()), float(per.std(ddof=1) / math.sqrt(count)))
    est = light_estimator(float(q), dead_ticks, reset, k)
    out["stated"] = float(est.bias_at(lam)) if lam < est.unresolved_from_electrons_per_tick else None
    out["unresolved"] = float(np.mean([im.unresolved.mean() for im in images]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the issue's two cases only")
    args = parser.parse_args()
    print(f"{'Q':>5} {'r/ceil':>6} {'dead':>5} {'reset':>7} {'K':>2} {'before %':>16} {'after %':>16} "
          f"{'stated %':>9} {'flagged':>8} {'s':>4}")
    for q, share, d, reset, k in CASES[:2] if args.quick else CASES:
        started = time.perf_counter()
        m = measure(q, share, d, reset, k, count=40 if q < 30 else 24, side=48 if q < 30 else 32)
        b, a = m["before"], m["after"]
        stated = "flagged" if m["stated"] is None else f"{100 * m['stated']:+.3f}"
        print(f"{q:>5} {share:>6.3f} {d:>5.2f} {reset:>7} {k:>2} {100 * b[0]:>+8.3f} ± {100 * b[1]:<5.3f} "
              f"{100 * a[0]:>+8.3f} ± {100 * a[1]:<5.3f} {stated:>9} {100 * m['unresolved']:>7.1f}% "
              f"{time.perf_counter() - started:>4.0f}", flush=True)


if __name__ == "__main__":
    main()
