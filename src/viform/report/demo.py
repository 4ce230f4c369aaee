"""``viform demo``: the built-in default scene through the whole chain, measured against the truth.

scene (analytic light, lux) → spike camera (exact photon statistics) → viform file →
images at several instants by accumulation (a short and a long window) and by interval
imaging → PSNR/SSIM against the scene's ground truth at the same instants, an animation,
and a summary.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from viform._io import atomic_path, save_image, write_json
from viform.imaging import accumulation_image, interval_image
from viform.light.scenes import builtin_scene
from viform.sensors.spike import SpikeSensor
from viform.stream.io import save_spikes


def compare_to_truth(estimate_lux: np.ndarray, truth_lux: np.ndarray, data_range_lux: float) -> dict:
    """PSNR (dB) and SSIM of a reconstruction against the true illuminance, both in lux."""
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    estimate = np.clip(estimate_lux, 0, data_range_lux)
    return {"psnr_db": float(peak_signal_noise_ratio(truth_lux, estimate, data_range=data_range_lux)),
            "ssim": float(structural_similarity(truth_lux, estimate, data_range=data_range_lux))}


def to_8bit(lux: np.ndarray, full_scale_lux: float) -> np.ndarray:
    return np.clip(np.rint(lux / full_scale_lux * 255.0), 0, 255).astype(np.uint8)


def run_demo(out_dir, scene: str = "translating", duration_s: float = 0.05, seed: int = 0,
             height: int = 250, width: int = 400, accumulation_window_s: float = 1e-3,
             long_window_s: float = 10e-3, light_sample_ticks: int = 2, echo=print) -> dict:
    """Run the demo; write files to ``out_dir`` and return the summary dict."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    light = builtin_scene(scene, height, width)
    sensor = SpikeSensor()
    echo(f"scene '{scene}' {height}×{width}, {duration_s:g} s; spike camera Q = "
         f"{sensor.parameters.threshold_electrons:g} e-, clock {sensor.parameters.clock_hz:g} Hz")
    started = time.perf_counter()
    stream = sensor.capture(light, duration_s, seed=seed, light_sample_ticks=light_sample_ticks, progress=True)
    simulate_s = time.perf_counter() - started
    save_spikes(out / "spikes.dat", stream)
    info = stream.summary()

    full_scale = float(max(light.illuminance_lux(t).max() for t in (0.0, duration_s / 2, duration_s)))
    instants = np.round(np.linspace(0.3, 0.9, 4) * duration_s, 6)
    scores = {"accumulation": [], "accumulation_long": [], "interval": []}
    for t in instants:
        truth = light.illuminance_lux(float(t))
        acc = accumulation_image(stream, float(t), accumulation_window_s)
        long = accumulation_image(stream, float(t), long_window_s)
        itv = interval_image(stream, float(t))
        scores["accumulation"].append(compare_to_truth(acc.lux, truth, full_scale))
        scores["accumulation_long"].append(compare_to_truth(long.lux, truth, full_scale))
        scores["interval"].append(compare_to_truth(itv.lux, truth, full_scale))
        panel = np.concatenate([to_8bit(truth, full_scale), to_8bit(acc.lux, full_scale),
                                to_8bit(long.lux, full_scale), to_8bit(itv.lux, full_scale)], axis=1)
        save_image(out / f"instant_{t * 1e3:.2f}ms_truth_acc{accumulation_window_s * 1e3:g}ms_"
                         f"acc{long_window_s * 1e3:g}ms_interval.png", panel)

    frames = []
    for t in np.linspace(0.1, 0.95, 24) * duration_s:
        truth = light.illuminance_lux(float(t))
        itv = interval_image(stream, float(t))
        acc = accumulation_image(stream, float(t), accumulation_window_s)
        frames.append(np.concatenate([to_8bit(truth, full_scale), to_8bit(acc.lux, full_scale),
                                      to_8bit(itv.lux, full_scale)], axis=1))
    import imageio.v3 as iio

    with atomic_path(out / "animation.gif") as tmp:
        iio.imwrite(tmp, np.stack(frames), extension=".gif", duration=120, loop=0)

    def mean_of(method, key):
        return float(np.mean([s[key] for s in scores[method]]))

    summary = {
        "scene": scene, "height": height, "width": width, "duration_s": duration_s,
        "threshold_electrons": sensor.parameters.threshold_electrons, "clock_hz": sensor.parameters.clock_hz,
        "spikes_per_s": info["spikes_per_s"], "mean_firing_rate_per_tick": info["mean_firing_rate_per_tick"],
        "raw_data_rate_mb_per_s": info["raw_data_rate_mb_per_s"],
        "simulation_pixel_ticks_per_s": stream.n_ticks * height * width / simulate_s,
        "accumulation_window_s": accumulation_window_s,
        "accumulation_psnr_db": mean_of("accumulation", "psnr_db"),
        "accumulation_ssim": mean_of("accumulation", "ssim"),
        "long_window_s": long_window_s,
        "accumulation_long_psnr_db": mean_of("accumulation_long", "psnr_db"),
        "accumulation_long_ssim": mean_of("accumulation_long", "ssim"),
        "interval_psnr_db": mean_of("interval", "psnr_db"),
        "interval_ssim": mean_of("interval", "ssim"),
    }
    write_json(out / "summary.json", {"summary": summary, "instants_s": instants, "scores": scores,
                                      "stream": info})
    echo(f"wrote {out}/spikes.dat, {len(instants)} instant panels (truth | accumulation "
         f"{accumulation_window_s * 1e3:g} ms | accumulation {long_window_s * 1e3:g} ms | interval), "
         "animation.gif, summary.json")
    return {"summary": summary, "scores": scores}
