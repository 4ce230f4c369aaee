"""Reconstruction quality and speed of every imaging method, against truth.

Datasets: the shared REDS spike clips (``reds_sim_400x250``, ``reds_sim2_400x250``; ground
truth is the 8-bit frame at index 150; images are compared in the common 8-bit convention,
firing rate × 255 / 0.6) and simulated scenes with analytic truth (400×250, 40 kHz,
Q = 10⁴ e⁻ as real chips, peak ≈ 0.55 spikes/tick): a texture translating at 400 … 20,000
px/s, rotating at 5 and 20 rev/s, and a static 3-decade HDR scene (200×125, 20,001 ticks,
scored on log₁₀ lux).
Truth for the simulated scenes is the scene's illuminance at the middle of the instant's
tick; PSNR uses the truth's peak (lux, or decades for HDR) as the data range.

Methods: TFP (41-tick centred accumulation), interval (TFI), multi-interval (K = 4,
adaptive) and motion-compensated accumulation, all with their default options. Speed: frames/s
of whole-stream reconstruction of the REDS clip (``reconstruct_ticks``; every tick for
accumulation, interval and multi-interval, 3 instants for motion), and the ratio
to a plain NumPy TFP (mean of 41 ticks) run in the same process. Peak RSS is printed.

Run: ``python benchmarks/bench_reconstruction.py`` (``--sweep`` also prints a parameter
sweep over all datasets; ``--quick`` skips the speed runs).
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
from skimage.io import imread
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from viform.imaging import reconstruct_ticks
from viform.imaging.motion import motion_compensated_image
from viform.imaging.multi_interval import multi_interval_rate
from viform.light.scenes import HDRScene, RotatingScene, TranslatingScene
from viform.sensors.spike import SpikeSensor
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "spike"
CLIPS = ("reds_sim_400x250", "reds_sim2_400x250")
CLOCK_HZ = 40_000.0
Q = 10_000.0
SIM_TICKS = 321
SIM_TICK = 160
HDR_TICKS = 20_001


def reds(name):
    source = open_spikes(DATA / f"{name}.dat", 250, 400)
    stream = SpikeStream(source.read_ticks(0, source.n_ticks), source.clock_hz)
    truth = imread(DATA / f"{name}_gt.png").astype(np.float64)
    return stream, 150, truth


def simulated():
    sensor = SpikeSensor(threshold_electrons=Q)
    top = 0.55 * CLOCK_HZ * Q / sensor.parameters.optics.electrons_per_lux_second
    scenes = [(f"translate {v} px/s", TranslatingScene(250, 400, velocity_px_per_s=(0.8 * v, 0.6 * v),
                                                        min_lux=top / 20, max_lux=top))
              for v in (400, 2000, 8000, 20000)]
    scenes += [(f"rotate {r} rev/s", RotatingScene(250, 400, angular_speed_rad_per_s=2 * np.pi * r,
                                                   min_lux=top / 20, max_lux=top)) for r in (5, 20)]
    for name, scene in scenes:
        stream = sensor.capture(scene, SIM_TICKS / CLOCK_HZ, seed=1)
        yield name, stream, SIM_TICK, scene.illuminance_lux((SIM_TICK + 0.5) / CLOCK_HZ), sensor
    # HDR: 3 decades down to 5.5e-4 spikes/tick (an interval of 1,800 ticks) need a long
    # stream: 20,001 ticks at 200×125, written to a .dat and read back (bounded memory)
    scene = HDRScene(125, 200, min_lux=top / 1e3, decades=3)
    with tempfile.TemporaryDirectory() as folder:
        path = save_spikes(Path(folder) / "hdr.dat", sensor.stream(scene, HDR_TICKS / CLOCK_HZ, seed=1))
        stream = open_spikes(path, 125, 200, clock_hz=CLOCK_HZ, threshold_electrons=Q)
        yield "HDR 3 decades (log)", stream, HDR_TICKS // 2, scene.illuminance_lux(0.0), sensor


def score(rate_per_tick, truth, sensor, hdr):
    """PSNR (dB) and SSIM of a firing-rate image against the truth (8-bit REDS, lux, or log-lux)."""
    if sensor is None:  # REDS: the common 8-bit convention
        image = np.clip(np.rint(rate_per_tick * 255 / 0.6), 0, 255)
        return (peak_signal_noise_ratio(truth, image, data_range=255),
                structural_similarity(truth, image, data_range=255))
    p = sensor.parameters
    lux = np.maximum(rate_per_tick * CLOCK_HZ * Q - p.dark_current_e_per_s, 0) / p.optics.electrons_per_lux_second
    if hdr:
        truth, lux = np.log10(truth), np.log10(np.maximum(lux, truth.min() / 10))
        span = truth.max() - truth.min()
        return (peak_signal_noise_ratio(truth - truth.min(), lux - truth.min(), data_range=span),
                structural_similarity(truth, lux, data_range=span))
    lux = np.clip(lux, 0, truth.max())
    return (peak_signal_noise_ratio(truth, lux, data_range=truth.max()),
            structural_similarity(truth, lux, data_range=truth.max()))


METHODS = {
    "TFP 41": lambda s, k, **kw: s.read_ticks(k - 20, k + 21).mean(axis=0),
    "interval": lambda s, k, **kw: multi_interval_rate(s, k, 1, **kw)[0],
    "multi-interval": lambda s, k, **kw: multi_interval_rate(s, k, kw.pop("spikes_per_side", 4),
                                                             adaptive=kw.pop("adaptive", True), **kw)[0],
    "motion": lambda s, k, **kw: motion_compensated_image(s, (k + 0.5) / s.clock_hz, **kw).spikes_per_s
    / s.clock_hz,
}


def datasets():
    for name in CLIPS:
        if (DATA / f"{name}.dat").exists():
            stream, k, truth = reds(name)
            yield f"REDS {name.split('_')[1]} (8-bit)", stream, k, truth, None
    yield from simulated()


def quality_table(sweep=False):
    rows = []
    header = f"{'dataset':<24}" + "".join(f"{m:>22}" for m in METHODS)
    print("PSNR dB / SSIM against truth (instant: REDS frame 150; simulated tick 160)")
    print(header)
    variants = [("motion", dict(multi_interval_weight=0.0)), ("motion", dict(multi_interval_weight=0.3)),
                ("motion", dict(half_span_ticks=120)), ("motion", dict(flow_window_ticks=21)),
                ("motion", dict(flow="tvl1")), ("motion", dict(anchor_step_ticks=30)),
                ("multi-interval", dict(spikes_per_side=3)), ("multi-interval", dict(spikes_per_side=5)),
                ("multi-interval", dict(adaptive=False))] if sweep else []
    extra = {}
    for name, stream, k, truth, sensor in datasets():
        hdr = name.startswith("HDR")
        cells = {m: score(fn(stream, k), truth, sensor, hdr) for m, fn in METHODS.items()}
        rows.append((name, cells))
        print(f"{name:<24}" + "".join(f"{p:>14.2f} / {s:.3f}" for p, s in cells.values()), flush=True)
        for method, kw in variants:
            extra.setdefault((method, str(kw)), []).append(
                score(METHODS[method](stream, k, **dict(kw)), truth, sensor, hdr)[0] - cells[method][0])
    print("gain over TFP 41 (dB): " + ", ".join(
        f"{m} mean {np.mean([c[m][0] - c['TFP 41'][0] for _, c in rows]):+.2f}, "
        f"min {np.min([c[m][0] - c['TFP 41'][0] for _, c in rows]):+.2f}" for m in list(METHODS)[1:]))
    for (method, kw), gains in extra.items():
        print(f"sweep {method} {kw}: mean {np.mean(gains):+.2f} dB vs default, per dataset "
              + " ".join(f"{g:+.2f}" for g in gains))
    return rows


def speed_table():
    stream, _, _ = reds(CLIPS[0])
    pixels = stream.height * stream.width

    def plain_tfp():
        out = np.empty((stream.n_ticks - 40, stream.height, stream.width), np.float32)
        for k in range(20, stream.n_ticks - 20):
            out[k - 20] = stream.spikes[k - 20:k + 21].mean(axis=0)
        return out.shape[0]

    started, cpu = time.perf_counter(), time.process_time()
    frames = plain_tfp()
    reference = frames / (time.perf_counter() - started)
    reference_cpu = frames / (time.process_time() - cpu)
    runs = {"accumulation": range(stream.n_ticks), "interval": range(stream.n_ticks),
            "multi-interval": range(stream.n_ticks), "motion": (120, 150, 180)}
    print(f"\nspeed, whole-stream reconstruction of a 400×250 REDS clip ({os.cpu_count()} CPUs, "
          f"load {os.getloadavg()[0]:.1f}):")
    print("(frames/CPU-s: frames per second of CPU time used, all threads; less sensitive to load)")
    print(f"{'method':<16}{'frames/s':>10}{'Mpixel/s':>10}{'× plain TFP':>13}{'frames/CPU-s':>14}")
    print(f"{'plain TFP':<16}{reference:>10.4g}{reference * pixels / 1e6:>10.4g}{1.0:>13.3g}{reference_cpu:>14.4g}")
    for method, ticks in runs.items():
        # compile (or load from the cache) every kernel the timed run uses: instants near both ends
        # (windows cut by the stream's ends are counted directly) and in the middle (sliding count)
        ticks = list(ticks)
        list(reconstruct_ticks(stream, method, sorted({ticks[0], ticks[len(ticks) // 2], ticks[-1]})))
        list(reconstruct_ticks(stream, method, ticks[:max(1, len(ticks) // 4)]))
        started, cpu = time.perf_counter(), time.process_time()
        n = sum(1 for _ in reconstruct_ticks(stream, method, list(ticks)))
        rate = n / (time.perf_counter() - started)
        rate_cpu = n / (time.process_time() - cpu)
        print(f"{method:<16}{rate:>10.4g}{rate * pixels / 1e6:>10.4g}{rate / reference:>13.3g}{rate_cpu:>14.4g}",
              flush=True)
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB; load after "
          f"{os.getloadavg()[0]:.1f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep", action="store_true", help="also sweep the methods' parameters")
    parser.add_argument("--quick", action="store_true", help="quality only, no speed runs")
    parser.add_argument("--speed", action="store_true", help="speed only, no quality table")
    args = parser.parse_args(argv)
    rows = [] if args.speed else quality_table(args.sweep)
    if not args.quick:
        speed_table()
    return rows


if __name__ == "__main__":
    main()
