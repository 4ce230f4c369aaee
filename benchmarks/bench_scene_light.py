"""Scene light against the pixels: described and built-in scenes end to end, per CPU-second, in one process.

Configuration (issues 35 §6 and 38 §2): 400×250 pixels, 40 kHz clock, Q = 100 e⁻, exact photon
statistics (``--noise-free``: the reference's own model, so the light's cost shows without the exact
model's Gamma draw per crossing), packed ``.dat`` bits (:meth:`SpikeSensor.simulate_packed`). Scenes:

* ``four-images``: a described scene (below) — a static photograph behind four moving image layers
  (scikit-image's bundled photographs: an ellipse translating, a rectangle rotating while it
  translates, a rectangle growing, a polygon on a spline path); 1.4 lux on average, firing ≈ 0.1 a tick;
* every built-in scene (its code, at 400×250, its default parameters), at light sampling "auto" and at
  one sample per tick.

For each scene, in the same process:

* viform end to end at the default light sampling ("auto": the hold S the scene chooses is printed)
  and at S = 1;
* the constant-light kernel: the same sensor on a still image of the scene's mean light (same firing);
* the noise-free reference: the scene's own NumPy light per tick (``reference_lux`` for a described
  scene, ``illuminance_lux`` otherwise), electrons per tick in float32, and the branch-free loop
  ``acc += e; fired = acc >= Q; acc -= fired·Q; packbits(fired)`` — the best plain loop of issue 38;
  and the same loop on a constant frame (no light) to show the loop's own cost.

Pixel-ticks per CPU-second (process time of all threads) and the ratios; the goals: described
and built-in scenes, at "auto", ≥ 0.5× the constant-light kernel and ≥ 1× the noise-free reference.
Each row also prints the largest relative difference between the light the simulator used and the
scene's NumPy reference at a few instants (an independent computation: the goal is ≤ 1e-6), and
peak NumPy memory of the end-to-end run (tracemalloc). Load average before and after.
Run: ``python benchmarks/bench_scene_light.py [--ticks 2000] [--reference-ticks 200]``.

``--rolling``: a rolling shutter's exposure instead (each row over its own window, what the seed 003
overflow pixel integrates): ``rolling_mean_illuminance_lux`` of every scene above and of the packaged
scene descriptions, against the plain way in the same process — row r of the whole frame's mean over
row r's window, for ``--rolling-reference-rows`` rows spread over the field (its cost per row times the
height; those rows are checked equal to the bit). CPU-s per exposure, the ratio, peak NumPy memory.
"""

from __future__ import annotations

import argparse
import os
import time
import tracemalloc

import numpy as np

from viform.light.catalog import BUILTIN_SCENES, builtin_scene
from viform.light.description import load_description
from viform.light.layered import DescribedScene
from viform.light.scenes import StillScene
from viform.sensors.spike import SpikeSensor, simulation_threads

HEIGHT, WIDTH, CLOCK_HZ, Q = 250, 400, 40_000.0, 100.0


def four_images_description() -> dict:
    """The benchmark's described scene: a static photograph and four moving image layers."""
    def image(name, size, lux=(0.45, 4.5)):
        return {"image": {"path": f"skimage:{name}", "lux": list(lux), "size_px": list(size)}}

    return {
        "viform_scene": 1, "name": "four-images",
        "summary": "A static photograph behind four moving photographs (benchmark of the compiled light)",
        "canvas": {"width_px": WIDTH, "height_px": HEIGHT, "duration_s": 0.05},
        "background": {"source": image("gravel", (WIDTH, HEIGHT), (0.75, 3.75)), "position_px": [200.0, 125.0]},
        "layers": [
            {"name": "astronaut", "source": image("astronaut", (90, 90)),
             "shape": {"ellipse": {"width_px": 80, "height_px": 86}},
             "position_px": [70.0, 70.0], "motion": {"velocity": {"px_per_s": [900.0, 300.0]}}},
            {"name": "cat", "source": image("chelsea", (96, 64)), "position_px": [300.0, 80.0],
             "motion": {"velocity": {"px_per_s": [-700.0, 200.0], "rad_per_s": 6.0}}},
            {"name": "coffee", "source": image("coffee", (72, 48)), "position_px": [120.0, 180.0],
             "motion": {"velocity": {"px_per_s": [500.0, -150.0], "scale_per_s": 4.0}}},
            {"name": "rocket", "source": image("rocket", (80, 54)),
             "shape": {"polygon": {"points_px": [[-40, -27], [40, -20], [30, 27], [-36, 20]]}},
             "position_px": [320.0, 190.0],
             "motion": {"keyframes": {"interpolation": "spline", "keys": [
                 {"t_s": 0.0, "position_px": [320.0, 190.0]}, {"t_s": 0.02, "position_px": [280.0, 170.0]},
                 {"t_s": 0.04, "position_px": [250.0, 195.0], "angle_rad": 0.3},
                 {"t_s": 0.06, "position_px": [210.0, 180.0]}]}}},
        ],
    }


def cpu_time(fn) -> float:
    start = time.process_time()
    fn()
    return time.process_time() - start


def best(fn, repeats: int) -> float:
    return min(cpu_time(fn) for _ in range(repeats))


def end_to_end(sensor, scene, n_ticks, sample="auto"):
    for _ in sensor.simulate_packed(scene, n_ticks / CLOCK_HZ, seed=1, light_sample_ticks=sample):
        pass


def reference_loop(sensor, light, n_ticks: int, seed: int = 0) -> None:
    """The noise-free reference: light per tick by ``light(t)`` (lux, (H, W)), best plain loop, packed bits."""
    rng = np.random.default_rng(seed)
    factor = sensor.electrons_per_tick(np.ones((HEIGHT, WIDTH)))
    acc = rng.uniform(0.0, Q, (HEIGHT, WIDTH)).astype(np.float32)  # the stationary phase
    e = np.empty((HEIGHT, WIDTH), np.float32)
    q = np.float32(Q)
    for k in range(n_ticks):
        np.multiply(light((k + 0.5) / CLOCK_HZ), factor, out=e, casting="same_kind")
        acc += e
        fired = acc >= q
        acc -= fired * q
        np.packbits(fired, bitorder="little")


def light_error(scene, times) -> float:
    """Largest |simulator's light − NumPy reference| / reference over ``times``."""
    compiled = scene.compiled_light()
    reference = scene.reference_lux if isinstance(scene, DescribedScene) else scene.illuminance_lux
    if compiled is None:  # the simulator uses the scene's NumPy light itself: nothing to compare
        return float("nan")
    if compiled.kind == "sampled":
        got = compiled.sampler.frames(times)
    else:
        from viform.light.compiled import evaluate

        got = evaluate(compiled, times)
    worst = 0.0
    for g, t in zip(got, times, strict=True):
        ref = reference(float(t))
        worst = max(worst, float(np.max(np.abs(g - ref) / np.maximum(np.abs(ref), 1e-300))))
    return worst


def rolling(scenes: str, reference_rows: int, t0_s: float = 0.004, exposure_s: float = 1e-3,
            row_offset_s: float = 1.3e-4) -> list:
    """``--rolling``: each scene's rolling exposure against the plain way (see the module notes)."""
    from pathlib import Path

    import viform.light as light_package
    from viform.light.catalog import described_scene

    def plain(scene, rows):  # row r of the whole frame's mean over row r's window
        return np.stack([scene.mean_illuminance_lux(t0_s + r * row_offset_s, t0_s + r * row_offset_s + exposure_s)[r]
                         for r in rows])

    entries = []
    for name in scenes.split(","):
        if name == "four-images":
            entries.append((name, DescribedScene(load_description(four_images_description()))))
        else:
            entries.append((name, builtin_scene(name, HEIGHT, WIDTH)))
    for path in sorted((Path(light_package.__file__).parent / "descriptions").glob("*.yaml")):
        entries.append((path.name, described_scene(str(path), HEIGHT, WIDTH)))
    print(f"rolling exposure, {HEIGHT}x{WIDTH} px: rows over [{t0_s:g} s + r·{row_offset_s:g} s, + {exposure_s:g} s]; "
          f"the plain way timed on {reference_rows} rows and scaled to {HEIGHT}; load average {load()}")
    print(f"{'scene':>20} {'viform CPU-s':>13} {'plain CPU-s':>12} {'ratio':>7} {'peak MB':>8}  same bits")
    rows_out = []
    rows = np.linspace(0, HEIGHT - 1, min(reference_rows, HEIGHT)).round().astype(int)
    for name, scene in entries:
        scene.rolling_mean_illuminance_lux(t0_s, exposure_s, row_offset_s)  # compile, and one-off set-up
        tracemalloc.start()
        got = scene.rolling_mean_illuminance_lux(t0_s, exposure_s, row_offset_s)
        peak = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
        fast = best(lambda s=scene: s.rolling_mean_illuminance_lux(t0_s, exposure_s, row_offset_s), 2)
        start = time.process_time()
        want = plain(scene, rows)
        slow = (time.process_time() - start) * HEIGHT / rows.size
        same = bool(np.array_equal(got[rows], want))
        rows_out.append({"scene": name, "cpu_s": fast, "plain_cpu_s": slow, "same": same, "peak_mb": peak})
        print(f"{name:>20} {fast:>13.3f} {slow:>12.3f} {slow / fast:>7.1f} {peak:>8.1f}  {'yes' if same else 'NO'}",
              flush=True)
    print(f"load average after: {load()}")
    return rows_out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=2000, help="ticks simulated end to end")
    parser.add_argument("--reference-ticks", type=int, default=200, help="ticks of the noise-free reference")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--scenes", default=",".join(["four-images", *BUILTIN_SCENES]),
                        help="comma-separated: four-images and built-in scene names (default: all)")
    parser.add_argument("--noise-free", action="store_true",
                        help="simulate without photon noise (the reference's model): the light's cost alone, "
                             "without the exact model's Gamma draw per crossing")
    parser.add_argument("--rolling", action="store_true",
                        help="a rolling shutter's exposure per scene against the plain way, instead")
    parser.add_argument("--rolling-reference-rows", type=int, default=25,
                        help="rows the plain way is timed and checked on (--rolling)")
    args = parser.parse_args(argv)
    if args.rolling:
        return rolling(args.scenes, args.rolling_reference_rows)
    sensor = SpikeSensor(threshold_electrons=Q, clock_hz=CLOCK_HZ, photon_noise=not args.noise_free)
    pixels = HEIGHT * WIDTH
    model = "noise-free" if args.noise_free else "exact"
    print(f"{HEIGHT}x{WIDTH} px, {CLOCK_HZ:g} Hz, Q = {Q:g} e-, {model}; {args.ticks} ticks end to end, "
          f"{args.reference_ticks} for the reference; numba threads {simulation_threads()} on {os.cpu_count()} "
          f"CPUs; load average (1, 5, 15 min) {load()}")
    print(f"{'scene':>13} {'S':>3} {'viform':>8} {'kernel':>8} {'ref':>8} {'loop':>8} {'÷kernel':>8} {'×ref':>6} "
          f"{'firing':>7} {'light err':>9} {'peak MB':>8}")
    print(f"{'':>13} {'':>3} {'Mpx-tick per CPU-s':>35}")
    rows = []
    for name in args.scenes.split(","):
        if name == "four-images":
            scene = DescribedScene(load_description(four_images_description()))
            reference_light = scene.reference_lux
        else:
            scene = builtin_scene(name, HEIGHT, WIDTH)
            reference_light = scene.illuminance_lux
        duration = args.ticks / CLOCK_HZ
        auto = sensor.light_sample_ticks_for(scene, "auto", duration)
        samples = sorted({auto, 1})
        times = (np.arange(args.ticks, step=max(1, args.ticks // 8)) + 0.5) / CLOCK_HZ
        err = light_error(scene, times[::2])
        lux = scene.illuminance_lux_many(times)
        still = StillScene(lux.mean(axis=0))
        firing = float(sensor.expected_firing_rate_per_tick(lux).mean())
        end_to_end(sensor, still, 64)
        kernel = args.ticks * pixels / best(lambda s=still: end_to_end(sensor, s, args.ticks), args.repeats)
        ref = args.reference_ticks * pixels / best(
            lambda light=reference_light: reference_loop(sensor, light, args.reference_ticks), args.repeats)
        frame = lux[0]
        loop = args.reference_ticks * pixels / best(
            lambda f=frame: reference_loop(sensor, lambda t, f=f: f, args.reference_ticks), args.repeats)
        for sample in samples:
            end_to_end(sensor, scene, 64, sample)  # compile, and the scene's one-off set-up
            tracemalloc.start()
            end_to_end(sensor, scene, args.ticks, sample)
            peak = tracemalloc.get_traced_memory()[1] / 1e6
            tracemalloc.stop()
            rate = args.ticks * pixels / best(lambda s=scene, k=sample: end_to_end(sensor, s, args.ticks, k),
                                              args.repeats)
            row = {"scene": name, "light_sample_ticks": sample, "auto": sample == auto, "per_cpu_s": rate,
                   "kernel_per_cpu_s": kernel, "reference_per_cpu_s": ref, "loop_per_cpu_s": loop,
                   "ratio_kernel": rate / kernel, "ratio_reference": rate / ref, "firing": firing,
                   "light_error": err, "peak_mb": peak}
            rows.append(row)
            err_text = "numpy" if np.isnan(err) else f"{err:.1e}"
            print(f"{name:>13} {sample:>3} {rate / 1e6:>8.1f} {kernel / 1e6:>8.1f} {ref / 1e6:>8.1f} "
                  f"{loop / 1e6:>8.1f} {rate / kernel:>8.2f} {rate / ref:>6.2f} {firing:>7.3f} {err_text:>9} "
                  f"{peak:>8.1f}" + ("  (auto)" if sample == auto else ""), flush=True)
    print(f"load average after (1, 5, 15 min): {load()}. S: ticks per light sample; ÷kernel: over the "
          "constant-light kernel on the scene's mean light; ×ref: over the noise-free reference with the scene's "
          "NumPy light per tick; loop: that reference on a constant frame (the loop alone); light err: simulator's "
          "light vs the NumPy reference, max relative ('numpy': the simulator uses the scene's NumPy light); "
          "peak MB: NumPy allocations (tracemalloc; compiled code's scratch is not counted).")
    for row in rows:
        if not row["auto"]:
            continue
        goals = [("÷kernel ≥ 0.5", row["ratio_kernel"] >= 0.5), ("×ref ≥ 1", row["ratio_reference"] >= 1.0)]
        if not np.isnan(row["light_error"]):
            goals.append(("light err ≤ 1e-6", row["light_error"] <= 1e-6))
        verdicts = [f"{what} {'met' if ok else 'NOT met'}" for what, ok in goals]
        print(f"goals, {row['scene']} at S = {row['light_sample_ticks']}: " + "; ".join(verdicts))
    return rows


def load() -> str:
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


if __name__ == "__main__":
    main()
