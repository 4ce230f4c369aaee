"""Spike simulation on a CUDA GPU (numba-cuda) against the CPU kernel, in the same run.

For 1000×1000 and 400×250 pixels at 40 kHz, Q = 100 e⁻, exact photon statistics, constant
light with a ±50 % texture at mean firing 0.01, 0.1 and 0.5 spikes per tick:

* GPU kernel alone: :meth:`SpikeSensor.simulate_packed` with ``device="cuda"``, blocks copied
  to pinned host memory (what every consumer gets), nothing written;
* GPU end to end: the same into a ``.dat`` file with its sidecar (``viform.stream.dat.write_dat``);
* the CPU kernel on the same scene and sensor (a shorter run), per wall second;
* bit identity: the first ticks from both devices compared bit for bit (the number of differing
  bits is printed; see :mod:`viform.sensors.spike_cuda` on why it can be non-zero on a GPU);
* peak device memory (numba-cuda's memory info, sampled after each run) and peak host memory
  (tracemalloc of the end-to-end run).

Pixel-ticks per second and the real-time factor (simulated seconds per wall second) are
printed. Without numba-cuda or a GPU it prints "no GPU" and exits 0 (the CUDA simulator is
not a GPU: this benchmark refuses it too).
Run: ``python benchmarks/bench_gpu.py [--seconds 0.25] [--cpu-seconds 0.005]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

CLOCK_HZ, Q = 40_000.0, 100
FIRINGS_PER_TICK = (0.01, 0.1, 0.5)


def gpu_present() -> bool:
    if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0"):
        return False
    try:
        from numba import cuda
    except ImportError:
        return False
    try:
        return bool(cuda.is_available())
    except Exception:
        return False


def still_scene(firing_per_tick: float, height: int, width: int):
    from viform.light.scenes import StillScene
    from viform.sensors.spike import SpikeSensor

    probe = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0)
    lux = firing_per_tick * Q * CLOCK_HZ / probe.parameters.optics.electrons_per_lux_second
    texture = 1.0 + 0.5 * np.sin(np.linspace(0, 20, height * width)).reshape(height, width)
    return StillScene(lux * texture)


def device_used_bytes() -> int:
    from numba import cuda

    try:
        free, total = cuda.current_context().get_memory_info()
    except Exception:
        return 0
    used = total - free
    return int(used) if np.isfinite(used) else 0  # the simulator has no device memory


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=0.25, help="simulated seconds per GPU run")
    parser.add_argument("--cpu-seconds", type=float, default=0.005, help="simulated seconds per CPU run")
    parser.add_argument("--check-ticks", type=int, default=400, help="ticks compared bit for bit")
    parser.add_argument("--sizes", default="1000x1000,400x250", help="WIDTHxHEIGHT,... to run")
    parser.add_argument("--simulator", action="store_true",
                        help="run under numba-cuda's simulator (NUMBA_ENABLE_CUDASIM=1; tiny sizes: checks the script)")
    args = parser.parse_args(argv)
    sizes = [tuple(int(v) for v in size.split("x"))[::-1] for size in args.sizes.split(",")]
    if not (gpu_present() or (args.simulator and os.environ.get("NUMBA_ENABLE_CUDASIM") == "1")):
        print("no GPU: numba-cuda finds no CUDA device here (install viform[cuda] on a machine with an NVIDIA GPU)")
        return 0

    from viform.sensors.spike import SpikeSensor, simulation_threads
    from viform.sensors.spike_cuda import device_description
    from viform.stream.dat import write_dat

    print(f"device: {device_description()}; CPU: {simulation_threads()} numba threads on {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'size':>9} {'firing':>6} {'GPU kernel':>11} {'real time':>9} {'GPU → .dat':>11} {'real time':>9} "
          f"{'CPU kernel':>11} {'GPU/CPU':>7} {'bits differ':>11} {'device MB':>9} {'host MB':>8}")
    rows = []
    for height, width in sizes:
        pixels = height * width
        for firing in FIRINGS_PER_TICK:
            scene = still_scene(firing, height, width)
            sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, dark_current_e_per_s=0.0,
                                 height=height, width=width)
            for _ in sensor.simulate_packed(scene, 64 / CLOCK_HZ, seed=1, device="cuda"):  # compile
                pass
            baseline = device_used_bytes()
            ticks = int(round(args.seconds * CLOCK_HZ))
            started = time.perf_counter()
            for _ in sensor.simulate_packed(scene, args.seconds, seed=1, device="cuda"):
                pass
            kernel_s = time.perf_counter() - started
            device_mb = max(device_used_bytes(), baseline) / 1e6
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "clip.dat"
                tracemalloc.start()
                started = time.perf_counter()
                write_dat(out, sensor.stream(scene, args.seconds, seed=1, device="cuda"))
                e2e_s = time.perf_counter() - started
                host_mb = tracemalloc.get_traced_memory()[1] / 1e6
                tracemalloc.stop()
            cpu_ticks = max(1, int(round(args.cpu_seconds * CLOCK_HZ)))
            started = time.perf_counter()
            for _ in sensor.simulate_packed(scene, cpu_ticks / CLOCK_HZ, seed=1):
                pass
            cpu_s = time.perf_counter() - started
            check = min(args.check_ticks, ticks)
            gpu_bits = np.concatenate([b for _, b in sensor.simulate_packed(scene, check / CLOCK_HZ, seed=1,
                                                                           device="cuda")])
            cpu_bits = np.concatenate([b for _, b in sensor.simulate_packed(scene, check / CLOCK_HZ, seed=1)])
            differ = int(np.unpackbits(gpu_bits ^ cpu_bits).sum())
            kernel_rate, e2e_rate = ticks * pixels / kernel_s, ticks * pixels / e2e_s
            cpu_rate = cpu_ticks * pixels / cpu_s
            real_time = pixels * CLOCK_HZ  # pixel-ticks per second of scene
            row = {"height": height, "width": width, "firing_per_tick": firing,
                   "gpu_kernel_pixel_ticks_per_s": kernel_rate, "gpu_kernel_real_time": kernel_rate / real_time,
                   "gpu_dat_pixel_ticks_per_s": e2e_rate, "gpu_dat_real_time": e2e_rate / real_time,
                   "cpu_kernel_pixel_ticks_per_s": cpu_rate, "bits_compared": check * pixels, "bits_differ": differ,
                   "device_mb": device_mb, "host_peak_mb": host_mb}
            rows.append(row)
            print(f"{width:>4}x{height:<4} {firing:>6g} {kernel_rate:>11.3g} {row['gpu_kernel_real_time']:>9.2f} "
                  f"{e2e_rate:>11.3g} {row['gpu_dat_real_time']:>9.2f} {cpu_rate:>11.3g} "
                  f"{kernel_rate / cpu_rate:>7.1f} {differ:>5}/{check * pixels:<.2g} {device_mb:>9.0f} "
                  f"{host_mb:>8.1f}", flush=True)
    print("rates in pixel-ticks per wall second; real time: simulated seconds per wall second at 40 kHz; "
          "bits differ: GPU vs CPU over the first ticks, same seed.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
