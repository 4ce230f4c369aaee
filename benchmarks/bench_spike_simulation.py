"""Spike-camera simulation throughput against plain per-tick NumPy loops, in the same process.

Configuration (issue 2 §8): 400×250 pixels, 40 kHz clock, mean firing ≈ 0.1 per tick.

* full photon statistics: viform's exact Gamma-interval simulator vs a per-tick
  ``numpy.random.poisson`` integrate-and-fire loop;
* noise-free: viform's deterministic model vs a per-tick NumPy accumulate-and-compare loop.

Absolute times on a shared machine are noisy; the ratio, measured in one process, is the
figure to read. Run: ``python benchmarks/bench_spike_simulation.py [--seconds 0.25]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor, simulation_threads

HEIGHT, WIDTH, CLOCK_HZ, Q, FIRING_PER_TICK = 250, 400, 40_000.0, 100, 0.1


def reference_poisson(rate_e_per_tick: np.ndarray, n_ticks: int, q: int, seed: int) -> np.ndarray:
    """Plain per-tick loop: Poisson electrons each tick, fire and reset at Q (the textbook way)."""
    rng = np.random.default_rng(seed)
    charge = np.zeros(rate_e_per_tick.shape, dtype=np.int64)
    out = np.empty((n_ticks,) + rate_e_per_tick.shape, dtype=bool)
    for k in range(n_ticks):
        charge += rng.poisson(rate_e_per_tick)
        fired = charge >= q
        charge[fired] -= q
        out[k] = fired
    return out


def reference_deterministic(rate_e_per_tick: np.ndarray, n_ticks: int, q: float) -> np.ndarray:
    """Plain per-tick loop without noise: accumulate the expected charge, fire and subtract Q."""
    charge = np.zeros(rate_e_per_tick.shape)
    out = np.empty((n_ticks,) + rate_e_per_tick.shape, dtype=bool)
    for k in range(n_ticks):
        charge += rate_e_per_tick
        fired = charge >= q
        charge[fired] -= q
        out[k] = fired
    return out


def best_time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        started = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - started)
    return best


def best_cpu_time(fn, repeats: int) -> float:
    """CPU seconds of all threads: less sensitive than wall time to other work on the machine."""
    best = np.inf
    for _ in range(repeats):
        started = time.process_time()
        fn()
        best = min(best, time.process_time() - started)
    return best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.25, help="simulated seconds for viform")
    parser.add_argument("--reference-ticks", type=int, default=200, help="ticks run by the reference loops")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)

    probe = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
    lux = FIRING_PER_TICK * Q * CLOCK_HZ / probe.parameters.optics.electrons_per_lux_second
    # a little texture so pixels differ (0.05–0.15 spikes per tick, mean 0.1)
    texture = 1.0 + 0.5 * np.sin(np.linspace(0, 20, HEIGHT * WIDTH)).reshape(HEIGHT, WIDTH)
    scene = StillScene(lux * texture)
    n_ticks = int(round(args.seconds * CLOCK_HZ))
    pixels = HEIGHT * WIDTH
    rate = probe.electrons_per_tick(scene.illuminance_lux(0.0))
    print(f"{HEIGHT}x{WIDTH} pixels, {CLOCK_HZ:g} Hz, Q = {Q} e-, mean rate {rate.mean():.2f} e-/tick, "
          f"numba threads: {simulation_threads()}")

    rows = []
    for noise in (True, False):
        sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0,
                             photon_noise=noise)

        def run_viform(sensor=sensor, reuse=True):
            # a streaming consumer (as `viform simulate` writing .dat/.zarr): one reused block buffer
            for _ in sensor.simulate(scene, n_ticks / CLOCK_HZ, seed=1, light_sample_ticks=n_ticks,
                                     reuse_buffer=reuse):
                pass

        sensor.capture(scene, 0.001, seed=1)  # compile
        t_viform = best_time(run_viform, args.repeats)
        cpu_viform = best_cpu_time(run_viform, args.repeats)
        t_fresh = best_time(lambda sensor=sensor: run_viform(sensor, reuse=False), args.repeats)
        if noise:
            t_ref = best_time(lambda: reference_poisson(rate, args.reference_ticks, Q, 1), args.repeats)
        else:
            t_ref = best_time(lambda: reference_deterministic(rate, args.reference_ticks, Q), args.repeats)
        firing = sensor.capture(scene, 0.005, seed=1, light_sample_ticks=200).spikes.mean()
        viform_rate = n_ticks * pixels / t_viform
        ref_rate = args.reference_ticks * pixels / t_ref
        label = "full photon statistics" if noise else "noise-free"
        rows.append((label, viform_rate, ref_rate))
        print(f"{label:>24}: viform {viform_rate:.3g} pixel-ticks/s ({viform_rate / (pixels * CLOCK_HZ):.2f}× "
              f"real time; {n_ticks * pixels / cpu_viform:.3g} per core of CPU time), "
              f"reference {ref_rate:.3g} pixel-ticks/s, ratio {viform_rate / ref_rate:.1f}×, "
              f"firing {firing:.3f}/tick; with a fresh buffer per block (as capture() keeps them) "
              f"{n_ticks * pixels / t_fresh:.3g}")
    return rows


if __name__ == "__main__":
    main()
