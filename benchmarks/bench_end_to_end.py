"""End-to-end spike simulation: scene → packed spikes (.dat bytes), against the plain per-frame loop.

Configuration (issue 10 §3): 400×250 pixels, 40 kHz clock, Q = 100 e⁻, exact photon statistics.
For an image-folder video (PNG frames written to a temporary folder, 1 kHz, hold and linear
interpolation) and for each built-in scene, this runs in one process:

* viform end to end: ``SpikeSensor.simulate_packed`` (light evaluated in compiled code when the
  scene describes itself, else by NumPy; the kernels write the .dat bits), not written to disk;
* the plain noise-free per-frame loop public spike-dataset generators use, on precomputed
  float32 frames of the same light in electrons per tick (``integral += frame; fire =
  integral >= threshold; integral[fire] -= threshold``), no packing;
* the constant-light kernel: the same sensor on a still image of the scene's mean light
  (spikes only, no packing) — the kernel's own speed, the ceiling for scene-driven runs.

Printed per scene: pixel-ticks/s (wall and per CPU-second of all threads, which is less
sensitive to other work on the machine), peak NumPy memory of the end-to-end run
(tracemalloc), the ratio to the loop and to the constant-light kernel. On a shared machine
read the ratios (both runs see the same load); ``uptime`` load is printed.
Run: ``python benchmarks/bench_end_to_end.py [--ticks 2000] [--loop-ticks 400]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from viform.light.catalog import BUILTIN_SCENES, builtin_scene
from viform.light.scenes import StillScene, VideoScene, texture
from viform.sensors.spike import SpikeSensor, simulation_threads
from viform.stream.dat import pack_frames

HEIGHT, WIDTH, CLOCK_HZ, Q = 250, 400, 40_000.0, 100.0
VIDEO_FPS, VIDEO_FRAMES, VIDEO_MAX_LUX = 1000.0, 120, 4.0


def make_video_folder(folder: Path) -> Path:
    """PNG frames of the texture translating at 2,000 px/s, 8-bit, 1 kHz (a high-speed clip)."""
    import imageio.v3 as iio

    y, x = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    for k in range(VIDEO_FRAMES):
        value = texture(x - 2000.0 * k / VIDEO_FPS, y)
        iio.imwrite(folder / f"frame_{k:04d}.png", np.round(value * 255).astype(np.uint8))
    return folder


def timed(fn) -> tuple[float, float]:
    """(wall s, CPU s of all threads) of one call."""
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


def best(fn, repeats: int) -> tuple[float, float]:
    runs = [timed(fn) for _ in range(repeats)]
    return min(r[0] for r in runs), min(r[1] for r in runs)


def end_to_end(sensor, scene, n_ticks) -> int:
    """Scene → packed .dat bytes (rows bottom-up), block by block, as ``viform simulate`` writes them:
    the kernels produce the packed bits themselves (``simulate_packed``)."""
    size = 0
    for _, frames in sensor.simulate_packed(scene, n_ticks / CLOCK_HZ, seed=1, flip=True):
        size += frames.nbytes
    return size


def end_to_end_bool(sensor, scene, n_ticks) -> int:
    """The same through bool frames and ``pack_frames`` (the path before the kernels packed bits)."""
    size = 0
    for _, block in sensor.simulate(scene, n_ticks / CLOCK_HZ, seed=1, reuse_buffer=True):
        size += len(pack_frames(block))
    return size


def kernel_only(sensor, scene, n_ticks) -> None:
    for _ in sensor.simulate_packed(scene, n_ticks / CLOCK_HZ, seed=1):
        pass


def reference_loop(frames: np.ndarray, threshold: float) -> np.ndarray:
    """The plain per-frame integrate-and-fire loop (noise-free), one frame per tick."""
    integral = np.zeros(frames.shape[1:], dtype=frames.dtype)
    out = np.empty(frames.shape, dtype=bool)
    for k in range(frames.shape[0]):
        integral += frames[k]
        fire = integral >= threshold
        integral[fire] -= threshold
        out[k] = fire
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=2000, help="ticks simulated end to end per scene")
    parser.add_argument("--loop-ticks", type=int, default=400, help="precomputed frames run by the plain loop")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--scenes", default=None, help="comma-separated subset of scene labels")
    args = parser.parse_args(argv)
    sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ)
    pixels = HEIGHT * WIDTH
    print(f"{HEIGHT}x{WIDTH} pixels, {CLOCK_HZ:g} Hz, Q = {Q:g} e-, exact photon statistics; "
          f"{args.ticks} ticks end to end, {args.loop_ticks} for the loop; numba threads {simulation_threads()}; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as tmp:
        folder = make_video_folder(Path(tmp))
        scenes = {
            "video-folder-hold": VideoScene.from_file(folder, VIDEO_FPS, VIDEO_MAX_LUX, "hold"),
            "video-folder-linear": VideoScene.from_file(folder, VIDEO_FPS, VIDEO_MAX_LUX, "linear"),
        }
        for name in BUILTIN_SCENES:
            try:
                scenes[name] = builtin_scene(name, HEIGHT, WIDTH)
            except Exception as exc:  # a scene that needs other sizes or options
                print(f"  (skipped {name}: {exc})")
        if args.scenes:
            wanted = set(args.scenes.split(","))
            scenes = {k: v for k, v in scenes.items() if k in wanted}
        header = (f"{'scene':>22} {'light':>9} {'end-to-end':>11} {'per CPU-s':>10} {'loop':>10} {'× loop':>7} "
                  f"{'kernel':>10} {'÷ kernel':>8} {'peak MB':>8} {'firing':>7}")
        print(header)
        print(f"{'':>22} {'':>9} {'px-tick/s':>11} {'px-tick/s':>10} {'px-tick/s':>10} {'(CPU)':>7} "
              f"{'px-tick/s':>10} {'(CPU)':>8} {'':>8} {'/tick':>7}")
        rows = []
        for label, scene in scenes.items():
            compiled = scene.compiled_light()
            kind = "numpy" if compiled is None else compiled.kind.replace("-modulated", "×m").replace("video-", "")
            end_to_end(sensor, scene, 64)  # compile
            tracemalloc.start()
            end_to_end(sensor, scene, args.ticks)
            peak_mb = tracemalloc.get_traced_memory()[1] / 1e6
            tracemalloc.stop()
            wall, cpu = best(lambda s=scene: end_to_end(sensor, s, args.ticks), args.repeats)
            # the loop's frames: the same light, in electrons per tick, as float32, spread over the run
            times = (np.linspace(0, args.ticks - 1, args.loop_ticks).round() + 0.5) / CLOCK_HZ
            lux = scene.illuminance_lux_many(times)
            frames = sensor.electrons_per_tick(lux).astype(np.float32)
            loop_wall, loop_cpu = best(lambda f=frames: reference_loop(f, Q), args.repeats)
            # the constant-light kernel: a still image of the scene's mean light over the run
            still = StillScene(lux.mean(axis=0))
            del lux
            kernel_only(sensor, still, 64)
            k_wall, k_cpu = best(lambda s=still: kernel_only(sensor, s, args.ticks), args.repeats)
            del frames
            firing = sensor.capture(scene, 200 / CLOCK_HZ, seed=1).spikes.mean()
            work, loop_work = args.ticks * pixels, args.loop_ticks * pixels
            rate, rate_cpu = work / wall, work / cpu
            loop_rate, loop_rate_cpu = loop_work / loop_wall, loop_work / loop_cpu
            kernel_rate, kernel_cpu = work / k_wall, work / k_cpu
            rows.append({"scene": label, "light": kind, "pixel_ticks_per_s": rate, "per_cpu_s": rate_cpu,
                         "loop_pixel_ticks_per_s": loop_rate, "ratio_to_loop_cpu": rate_cpu / loop_rate_cpu,
                         "ratio_to_loop_wall": rate / loop_rate, "kernel_pixel_ticks_per_s": kernel_rate,
                         "ratio_to_kernel_cpu": rate_cpu / kernel_cpu, "peak_mb": peak_mb, "firing": firing})
            print(f"{label:>22} {kind:>9} {rate:>11.3g} {rate_cpu:>10.3g} {loop_rate:>10.3g} "
                  f"{rate_cpu / loop_rate_cpu:>7.2f} {kernel_rate:>10.3g} {rate_cpu / kernel_cpu:>8.2f} "
                  f"{peak_mb:>8.1f} {firing:>7.3f}", flush=True)
    print("× loop: end-to-end pixel-ticks per CPU-second over the loop's (the loop is single-threaded; "
          "wall-clock ratios are in the returned rows); ÷ kernel: over the constant-light kernel's.")
    return rows


if __name__ == "__main__":
    main()
