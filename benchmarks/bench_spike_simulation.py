"""Spike-camera simulation throughput against plain per-tick NumPy loops, in the same process.

Configuration (issues 2 §8 and 30): 400×250 pixels, 40 kHz clock, Q = 100 e⁻, constant light
with a ±50 % texture at mean firing 0.01, 0.1 and 0.5 spikes per tick. For each firing rate,
viform exact (Gamma intervals) and noise-free, as the file writers run it (packed ``.dat`` bits,
:meth:`SpikeSensor.simulate_packed`) and as bool frames (:meth:`SpikeSensor.simulate`), against:

* the plain noise-free NumPy loop, float32 (``integral += frame; fire = integral >= Q;
  integral[fire] -= Q``) — what public dataset generators run;
* the NumPy per-tick Poisson loop (the textbook exact method);
* a Spike-Zoo-style generator, written out below (random initial integral in [0, Q), the same
  accumulate-and-fire per frame, spikes stored as uint8 through ``nonzero``).

Rates are pixel-ticks per second of wall time and per CPU-second (process time of all threads,
less sensitive to the other work on a shared machine); ratios are per CPU-second, measured in
the same process. The machine's load average is printed before and after. The real-time
factor (simulated seconds per wall second at 40 kHz) is printed for 400×250 and 1000×1000.
Run: ``python benchmarks/bench_spike_simulation.py [--seconds 0.1] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor, simulation_threads

HEIGHT, WIDTH, CLOCK_HZ, Q = 250, 400, 40_000.0, 100
FIRINGS_PER_TICK = (0.01, 0.1, 0.5)


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


def reference_float32(rate_e_per_tick: np.ndarray, n_ticks: int, q: float) -> np.ndarray:
    """The plain noise-free loop in float32: accumulate the expected charge, fire and subtract Q."""
    frame = rate_e_per_tick.astype(np.float32)
    integral = np.zeros(frame.shape, dtype=np.float32)
    out = np.empty((n_ticks,) + frame.shape, dtype=bool)
    for k in range(n_ticks):
        integral += frame
        fire = integral >= q
        integral[fire] -= q
        out[k] = fire
    return out


def spike_zoo_style(frames: np.ndarray, q: float, seed: int = 0) -> np.ndarray:
    """A Spike-Zoo-style generator: random initial integral, per-frame accumulate and fire, uint8 spikes."""
    rng = np.random.default_rng(seed)
    integral = rng.random(frames.shape[1:]) * q
    spikes = np.zeros(frames.shape, dtype=np.uint8)
    for k in range(frames.shape[0]):
        integral += frames[k]
        fire = (integral - q) >= 0
        positions = fire.nonzero()
        integral[positions] -= q
        spikes[k][positions] = 1
    return spikes


def timed(fn, repeats: int) -> tuple[float, float]:
    """Best (wall s, CPU s of all threads) over ``repeats`` calls."""
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus)


def still_scene(firing_per_tick: float, height: int = HEIGHT, width: int = WIDTH) -> StillScene:
    probe = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
    lux = firing_per_tick * Q * CLOCK_HZ / probe.parameters.optics.electrons_per_lux_second
    texture = 1.0 + 0.5 * np.sin(np.linspace(0, 20, height * width)).reshape(height, width)
    return StillScene(lux * texture)


def run_packed(sensor, scene, n_ticks):
    for _ in sensor.simulate_packed(scene, n_ticks / CLOCK_HZ, seed=1):
        pass


def run_bool(sensor, scene, n_ticks):
    for _ in sensor.simulate(scene, n_ticks / CLOCK_HZ, seed=1, reuse_buffer=True):
        pass


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.1, help="simulated seconds for viform")
    parser.add_argument("--reference-ticks", type=int, default=200, help="ticks run by the reference loops")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--megapixel-seconds", type=float, default=0.01,
                        help="simulated seconds for the 1000×1000 real-time figure (0 skips it)")
    args = parser.parse_args(argv)
    n_ticks = int(round(args.seconds * CLOCK_HZ))
    pixels = HEIGHT * WIDTH
    print(f"{HEIGHT}x{WIDTH} pixels, {CLOCK_HZ:g} Hz, Q = {Q} e-, {n_ticks} ticks; numba threads "
          f"{simulation_threads()} on {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f}")
    print(f"{'firing':>6} {'model':>10} {'viform .dat bits':>26} {'viform bool':>12} {'float32 loop':>13} "
          f"{'Poisson loop':>13} {'Spike-Zoo':>10} {'× f32':>6} {'× Poisson':>9} {'× Zoo':>6} {'real time':>9}")
    print(f"{'/tick':>6} {'':>10} {'wall':>8} {'per CPU-s':>9} {'CPU/wall':>8} {'per CPU-s':>12} {'per CPU-s':>13} "
          f"{'per CPU-s':>13} {'per CPU-s':>10} {'(CPU)':>6} {'(CPU)':>9} {'(CPU)':>6} {'(wall)':>9}")
    rows = []
    for firing in FIRINGS_PER_TICK:
        scene = still_scene(firing)
        probe = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
        rate = probe.electrons_per_tick(scene.illuminance_lux(0.0))
        _, cpu_f32 = timed(lambda r=rate, n=args.reference_ticks: reference_float32(r, n, Q), args.repeats)
        _, cpu_zoo = timed(lambda r=rate, n=args.reference_ticks:
                           spike_zoo_style(np.broadcast_to(r, (n,) + r.shape), Q), args.repeats)
        _, cpu_poisson = timed(lambda r=rate, n=args.reference_ticks: reference_poisson(r, n, Q, 1), args.repeats)
        f32 = args.reference_ticks * pixels / cpu_f32
        zoo = args.reference_ticks * pixels / cpu_zoo
        poisson = args.reference_ticks * pixels / cpu_poisson
        for noise in (True, False):
            sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0,
                                 photon_noise=noise)
            run_packed(sensor, scene, 64)  # compile
            run_bool(sensor, scene, 64)
            wall, cpu = timed(lambda s=sensor, sc=scene: run_packed(s, sc, n_ticks), args.repeats)
            _, cpu_bool = timed(lambda s=sensor, sc=scene: run_bool(s, sc, n_ticks), args.repeats)
            work = n_ticks * pixels
            viform_wall, viform_cpu = work / wall, work / cpu
            row = {"firing_per_tick": firing, "model": "exact" if noise else "noise-free",
                   "pixel_ticks_per_s": viform_wall, "per_cpu_s": viform_cpu, "cpu_over_wall": cpu / wall,
                   "bool_per_cpu_s": work / cpu_bool, "float32_loop_per_cpu_s": f32,
                   "poisson_loop_per_cpu_s": poisson, "spike_zoo_per_cpu_s": zoo,
                   "ratio_float32": viform_cpu / f32, "ratio_poisson": viform_cpu / poisson,
                   "ratio_spike_zoo": viform_cpu / zoo, "real_time_factor": viform_wall / (pixels * CLOCK_HZ)}
            rows.append(row)
            print(f"{firing:>6g} {row['model']:>10} {viform_wall:>8.3g} {viform_cpu:>9.3g} {cpu / wall:>8.2f} "
                  f"{work / cpu_bool:>12.3g} {f32:>13.3g} {poisson:>13.3g} {zoo:>10.3g} "
                  f"{row['ratio_float32']:>6.2f} {row['ratio_poisson']:>9.1f} {row['ratio_spike_zoo']:>6.2f} "
                  f"{row['real_time_factor']:>9.3f}", flush=True)
    if args.megapixel_seconds > 0:
        scene = still_scene(0.1, 1000, 1000)
        sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
        run_packed(sensor, scene, 16)
        ticks = max(1, int(round(args.megapixel_seconds * CLOCK_HZ)))
        wall, cpu = timed(lambda: run_packed(sensor, scene, ticks), 1)
        print(f"1000x1000 exact at firing 0.1: {ticks * 1e6 / wall:.3g} pixel-ticks/s wall "
              f"({ticks * 1e6 / cpu:.3g} per CPU-s), real-time factor {ticks / CLOCK_HZ / wall:.4f}")
    print(f"load average after: {os.getloadavg()[0]:.1f}. × f32 / × Poisson / × Zoo: viform .dat bits per "
          "CPU-second over the loop's; real time: simulated seconds per wall second at 40 kHz.")
    return rows


if __name__ == "__main__":
    main()
