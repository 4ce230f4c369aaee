"""Cost of the global shutter's storage-node light (parasitic light while rows wait to be read) in
the LUX13HS-like high-speed camera, and its agreement with a plain per-row reference.

Three runs in the same process on a moving catalogue scene: the camera without parasitic light
(PLS = 0: the exposure alone), the camera as published (PLS = 0.01, readout 576 µs: the readout's
light sampled ``scene_samples`` times per frame by ``FramePixelArray.storage_light_lux``), and a
plain reference that averages the light over each row's own wait with the scene's midpoint rule
(one call per row, 32 points each). Printed: frames/s of each, the ratios, peak traced memory, and
the mean and largest difference between the fast and the reference row light relative to the mean
light (an independent computation of the same integral).

Run: ``python benchmarks/bench_storage_light.py [--height 18 --width 32 --frames 40]``.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

from viform.light.catalog import load_scene
from viform.sensors.frame import FrameSensor
from viform.sensors.highspeed import HighSpeedCamera, lux13hs_pixel_parameters


def reference_light(pixels, scene, end_s, samples=32):
    """Each row's mean light over its own wait, one midpoint-rule average per row."""
    wait = pixels.storage_wait_s()
    out = np.empty((pixels.height, pixels.width))
    for r in range(pixels.height):
        out[r] = scene.mean_illuminance_lux(end_s, end_s + float(wait[r, 0]), samples=samples)[r]
    return out


def frames_per_s(camera, scene, n):
    t0 = time.perf_counter()
    camera.capture_frames(scene, n, seed=1)
    return n / (time.perf_counter() - t0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="rotating")
    ap.add_argument("--height", type=int, default=18)
    ap.add_argument("--width", type=int, default=32)
    ap.add_argument("--frames", type=int, default=40)
    a = ap.parse_args()
    scene = load_scene(a.scene, a.height, a.width, max_lux=2000.0)
    off = HighSpeedCamera(lux13hs_pixel_parameters(parasitic_light_sensitivity=0.0))
    on = HighSpeedCamera()
    fps_off = frames_per_s(off, scene, a.frames)
    tracemalloc.start()
    fps_on = frames_per_s(on, scene, a.frames)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    pixels = FrameSensor(on.parameters, exposure_s=on.frame_period_s / 2,
                         frame_rate_hz=on.frame_rate_hz).pixel_array(a.height, a.width)
    n_ref = max(2, a.frames // 10)
    ends = (np.arange(n_ref) + 1) * on.frame_period_s
    t0 = time.perf_counter()
    ref = [reference_light(pixels, scene, float(t)) for t in ends]
    t_ref = (time.perf_counter() - t0) / n_ref
    t0 = time.perf_counter()
    fast = [pixels.storage_light_lux(scene, float(t), samples=on.scene_samples) for t in ends]
    t_fast = (time.perf_counter() - t0) / n_ref
    t0 = time.perf_counter()
    fine = [pixels.storage_light_lux(scene, float(t), samples=32) for t in ends]
    t_fine = (time.perf_counter() - t0) / n_ref
    mean = float(np.mean(ref))

    def difference(got):
        d = np.abs(np.stack(got) - np.stack(ref)) / mean
        return f"mean {d.mean():.1e}, largest {d.max():.1e} (a pixel an edge crosses)"

    print(f"scene {a.scene} {a.height}x{a.width}, {a.frames} frames")
    print(f"camera, PLS 0 (exposure only)      : {fps_off:8.1f} frames/s")
    print(f"camera, PLS 0.01, readout 576 us    : {fps_on:8.1f} frames/s  ({fps_off / fps_on:.2f}x the exposure-only "
          f"time; peak traced memory {peak / 2**20:.1f} MiB)")
    print(f"storage light, {on.scene_samples} samples (camera)  : {1 / t_fast:8.1f} frames/s; "
          f"per-row reference {1 / t_ref:.1f} frames/s (ratio {t_ref / t_fast:.0f}x); "
          f"|fast - reference| / mean light: {difference(fast)}")
    print(f"storage light, 32 samples          : {1 / t_fine:8.1f} frames/s (ratio {t_ref / t_fine:.0f}x); "
          f"|fast - reference| / mean light: {difference(fine)}")


if __name__ == "__main__":
    main()
