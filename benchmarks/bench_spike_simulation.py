"""Spike-camera simulation throughput against plain per-tick NumPy loops, in the same process.

Configuration: 400×250 pixels, 40 kHz clock, Q = 100 e⁻, constant light with a ±50 % texture at
mean firing 0.01, 0.1 and 0.5 spikes per tick. viform exact (Gamma intervals) and noise-free, as
the file writers run it (packed ``.dat`` bits, :meth:`SpikeSensor.simulate_packed`), at 1 and 2
numba threads, against three plain loops, each started from the stationary charge (uniform in
[0, Q): no pixel fires in lockstep with another) and each writing packed bits:

* masked, float32: ``acc += frame; fired = acc >= Q; acc[fired] -= Q`` — what public dataset
  generators run; its speed depends on the firing pattern (a random one defeats the branch
  predictor);
* branch-free, float32: ``acc -= fired * Q`` in place of the masked subtraction — the fastest
  plain loop whatever the pattern, the reference of the ratios below;
* Poisson: a Poisson electron count per pixel and tick, fire and subtract Q — the textbook exact
  method.

Rates are pixel-ticks per CPU-second (process time of all threads: less sensitive than wall time
to the other work on a shared machine); the ratios divide viform's by a loop's, measured in the
same process. The branch-free loop, the goals' reference, is run again alternated with each viform
row (best of each over ``--repeats``), so that both see the same load; "its rate" is that figure.
Each stream's mean firing is printed beside it: viform's and the loops' must agree (the same
light), so the ratios compare like with like. The machine's load average is printed
before and after, and the peak resident memory at the end. The real-time factor (simulated
seconds per wall second at 40 kHz) is printed for 400×250 and 1000×1000.
Run: ``python benchmarks/bench_spike_simulation.py [--seconds 0.1] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np
from numba import get_num_threads, set_num_threads

from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor

HEIGHT, WIDTH, CLOCK_HZ, Q = 250, 400, 40_000.0, 100
FIRINGS_PER_TICK = (0.01, 0.1, 0.5)


def masked_loop(rate_e_per_tick: np.ndarray, n_ticks: int, q: float, seed: int) -> np.ndarray:
    """The masked float32 loop from the stationary charge; packed bits (ticks × pixels/8)."""
    rng = np.random.default_rng(seed)
    frame = rate_e_per_tick.astype(np.float32).ravel()
    acc = (rng.random(frame.size) * q).astype(np.float32)
    qf = np.float32(q)
    out = np.empty((n_ticks, frame.size // 8), dtype=np.uint8)
    for k in range(n_ticks):
        acc += frame
        fired = acc >= qf
        acc[fired] -= qf
        out[k] = np.packbits(fired, bitorder="little")
    return out


def branch_free_loop(rate_e_per_tick: np.ndarray, n_ticks: int, q: float, seed: int) -> np.ndarray:
    """The branch-free float32 loop (``acc -= fired * Q``, buffers reused) from the stationary charge."""
    rng = np.random.default_rng(seed)
    frame = rate_e_per_tick.astype(np.float32).ravel()
    acc = (rng.random(frame.size) * q).astype(np.float32)
    qf = np.float32(q)
    fired = np.empty(frame.size, dtype=bool)
    step = np.empty(frame.size, dtype=np.float32)
    out = np.empty((n_ticks, frame.size // 8), dtype=np.uint8)
    for k in range(n_ticks):
        np.add(acc, frame, out=acc)
        np.greater_equal(acc, qf, out=fired)
        np.multiply(fired, qf, out=step)
        np.subtract(acc, step, out=acc)
        out[k] = np.packbits(fired, bitorder="little")
    return out


def poisson_loop(rate_e_per_tick: np.ndarray, n_ticks: int, q: int, seed: int) -> np.ndarray:
    """Poisson electrons per pixel and tick, fire and subtract Q, from the stationary count (uniform
    in 0 … Q − 1: the electron count modulo Q of a pixel exposed long before)."""
    rng = np.random.default_rng(seed)
    rate = rate_e_per_tick.ravel()
    charge = rng.integers(0, q, size=rate.size).astype(np.int64)
    out = np.empty((n_ticks, rate.size // 8), dtype=np.uint8)
    for k in range(n_ticks):
        charge += rng.poisson(rate)
        fired = charge >= q
        charge -= fired * q
        out[k] = np.packbits(fired, bitorder="little")
    return out


LOOPS = {"masked": masked_loop, "branch-free": branch_free_loop, "Poisson": poisson_loop}


def timed(fn, repeats: int):
    """(best wall s, best CPU s of all threads, last result) over ``repeats`` calls."""
    walls, cpus = [], []
    result = None
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        result = fn()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus), result


def still_scene(firing_per_tick: float, height: int = HEIGHT, width: int = WIDTH) -> StillScene:
    probe = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
    lux = firing_per_tick * Q * CLOCK_HZ / probe.parameters.optics.electrons_per_lux_second
    texture = 1.0 + 0.5 * np.sin(np.linspace(0, 20, height * width)).reshape(height, width)
    return StillScene(lux * texture)


def run_packed(sensor, scene, n_ticks):
    """The packed stream's blocks (each ticks × pixels/8), as the file writers take them (no copy into one
    array: the loops' output is not copied either)."""
    return [b for _, b in sensor.simulate_packed(scene, n_ticks / CLOCK_HZ, seed=1)]


def firing(packed) -> float:
    """Mean spikes per pixel-tick of packed bits (one array, or a list of blocks)."""
    blocks = packed if isinstance(packed, list) else [packed]
    ones = sum(int(np.unpackbits(b).sum()) for b in blocks)
    return ones / sum(b.size * 8 for b in blocks)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.1, help="simulated seconds for viform")
    parser.add_argument("--reference-ticks", type=int, default=400, help="ticks run by the NumPy loops")
    parser.add_argument("--poisson-ticks", type=int, default=40, help="ticks run by the (slow) Poisson loop")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="numba threads for viform")
    parser.add_argument("--megapixel-seconds", type=float, default=0.01,
                        help="simulated seconds for the 1000×1000 real-time figure (0 skips it)")
    args = parser.parse_args(argv)
    n_ticks = int(round(args.seconds * CLOCK_HZ))
    pixels = HEIGHT * WIDTH
    threads_before = get_num_threads()
    threads = [t for t in args.threads if 1 <= t <= threads_before]
    print(f"{HEIGHT}x{WIDTH} pixels, {CLOCK_HZ:g} Hz, Q = {Q} e-, viform {n_ticks} ticks, loops "
          f"{args.reference_ticks} (Poisson {args.poisson_ticks}); {os.cpu_count()} CPUs; "
          f"load average {os.getloadavg()[0]:.1f}")
    print("rates in M pixel-ticks per CPU-second; ratios = viform / loop, same process; firing = mean spikes/tick")
    rows = []
    for firing_target in FIRINGS_PER_TICK:
        scene = still_scene(firing_target)
        probe = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
        rate = probe.electrons_per_tick(scene.illuminance_lux(0.0))
        loops = {}
        for name, loop in LOOPS.items():
            ticks = args.poisson_ticks if name == "Poisson" else args.reference_ticks
            _, cpu, bits = timed(lambda lp=loop, t=ticks, r=rate: lp(r, t, Q, 1), args.repeats)
            loops[name] = (ticks * pixels / cpu, firing(bits))
        print(f"\nfiring {firing_target:g}: loops " + ", ".join(f"{name} {r / 1e6:.0f} (firing {f:.3f})"
                                                           for name, (r, f) in loops.items()))
        print(f"  {'model':>10} {'threads':>7} {'per CPU-s':>9} {'wall':>8} {'firing':>7} {'× masked':>8} "
              f"{'× branch-free':>13} {'(its rate)':>10} {'× Poisson':>9} {'real time':>9}")
        for noise in (True, False):
            sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0,
                                 photon_noise=noise)
            for n_threads in threads:
                set_num_threads(n_threads)
                try:
                    run_packed(sensor, scene, 64)  # compile / load the cached kernels
                    # viform alternated with the branch-free loop (the goals' reference), best of each: both
                    # see the same load on a shared machine
                    walls, cpus, reference = [], [], []
                    for _ in range(args.repeats):
                        time.sleep(0.01)  # numba's idle OpenMP workers spin ≈ 1 ms after a kernel: not the loop's CPU
                        _, ref_cpu, _ = timed(lambda r=rate: branch_free_loop(r, args.reference_ticks, Q, 1), 1)
                        reference.append(ref_cpu)
                        wall, cpu, bits = timed(lambda s=sensor, sc=scene: run_packed(s, sc, n_ticks), 1)
                        walls.append(wall)
                        cpus.append(cpu)
                    wall, cpu = min(walls), min(cpus)
                finally:
                    set_num_threads(threads_before)
                work = n_ticks * pixels
                per_cpu = work / cpu
                row = {"firing_per_tick": firing_target, "model": "exact" if noise else "noise-free",
                       "threads": n_threads, "per_cpu_s": per_cpu, "pixel_ticks_per_s": work / wall,
                       "firing": firing(bits), "real_time_factor": work / wall / (pixels * CLOCK_HZ)}
                for name, (r, _) in loops.items():
                    if name == "branch-free":
                        r = args.reference_ticks * pixels / min(reference)
                    row[f"ratio_{name}"] = per_cpu / r
                    row[f"{name}_per_cpu_s"] = r
                rows.append(row)
                print(f"  {row['model']:>10} {n_threads:>7} {per_cpu / 1e6:>9.0f} {work / wall / 1e6:>8.0f} "
                      f"{row['firing']:>7.3f} {row['ratio_masked']:>8.2f} {row['ratio_branch-free']:>13.2f} "
                      f"{row['branch-free_per_cpu_s'] / 1e6:>10.0f} {row['ratio_Poisson']:>9.1f} "
                      f"{row['real_time_factor']:>9.3f}", flush=True)
    if args.megapixel_seconds > 0:
        scene = still_scene(0.1, 1000, 1000)
        sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
        run_packed(sensor, scene, 16)
        ticks = max(1, int(round(args.megapixel_seconds * CLOCK_HZ)))
        wall, cpu, _ = timed(lambda: run_packed(sensor, scene, ticks), 1)
        print(f"\n1000x1000 exact at firing 0.1, {threads_before} threads: {ticks * 1e6 / wall / 1e6:.0f} M "
              f"pixel-ticks/s wall ({ticks * 1e6 / cpu / 1e6:.0f} per CPU-s), real-time factor "
              f"{ticks / CLOCK_HZ / wall:.4f}")
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"load average after: {os.getloadavg()[0]:.1f}; peak resident memory {peak_mib:.0f} MiB. "
          "Real time: simulated seconds per wall second at 40 kHz.")
    return rows


if __name__ == "__main__":
    main()
